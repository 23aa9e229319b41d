//! Measured-data logs in the project's CSV format (`shared/DATA-FORMAT.md`): strict reading with
//! errors that name file, line and column; writing in the same format.
//!
//! A bad file never panics and never yields a partial result: `read_log` returns either the
//! whole log or the first error found. The CSV reader ([`csv`]) streams the file and accepts
//! the bench-tool dialects; every reader (CSV, MF4, in memory) runs the same checks
//! ([`check`], entry point [`log_from_columns`]). What is guaranteed: docs/reliability.md.

pub mod check;
mod clock;
mod column_units;
pub mod csv;
mod lines;
mod sparse;
pub mod units;

use std::collections::BTreeMap;
use std::fmt;
use std::fs;
use std::io::BufReader;
use std::path::Path;

pub use check::log_from_columns;
pub use csv::read_csv;

use crate::mf4::ChannelMap;

/// The plants a log can belong to, and their columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Plant {
    Vacuum,
    Ehvva,
    Evvt,
    Positioner,
}

/// A column's role for its plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Input,
    OptionalInput,
    /// The output whose error the diagnosis reports.
    PrimaryOutput,
    OptionalOutput,
}

impl Plant {
    pub const ALL: [Plant; 4] = [Plant::Vacuum, Plant::Ehvva, Plant::Evvt, Plant::Positioner];

    pub fn name(self) -> &'static str {
        match self {
            Plant::Vacuum => "vacuum",
            Plant::Ehvva => "ehvva",
            Plant::Evvt => "evvt",
            Plant::Positioner => "positioner",
        }
    }

    pub fn from_name(name: &str) -> Option<Plant> {
        Plant::ALL.into_iter().find(|p| p.name() == name.trim())
    }

    /// The plant's columns (DATA-FORMAT.md, "Plants and their columns").
    pub fn columns(self) -> &'static [(&'static str, Role)] {
        use Role::*;
        match self {
            Plant::Vacuum => &[
                ("duty_pct", Input),
                ("u_batt_V", Input),
                ("p_amb_kPa", Input),
                ("p_tank_kPa", Input),
                ("x_pct", PrimaryOutput),
                ("p_act_kPa", OptionalOutput),
            ],
            Plant::Ehvva => &[
                ("u_pilot", Input),
                ("p_supply_MPa", Input),
                ("p_back_MPa", Input),
                ("temp_C", Input),
                ("lift_high", Input),
                ("snubber_on", Input),
                ("lift_mm", PrimaryOutput),
            ],
            Plant::Evvt => &[
                ("motor_cmd_rpm", Input),
                ("engine_rpm", Input),
                ("u_batt_V", Input),
                ("phase_ref_deg", OptionalInput),
                ("phase_deg", PrimaryOutput),
            ],
            Plant::Positioner => &[("force_N", Input), ("ref_m", OptionalInput), ("pos_m", PrimaryOutput)],
        }
    }

    /// Every column name a log of this plant can have: `t_s`, then [`Plant::columns`].
    pub fn column_names(self) -> impl Iterator<Item = &'static str> {
        std::iter::once("t_s").chain(self.columns().iter().map(|(n, _)| *n))
    }

    /// The columns a log of this plant must have besides `t_s`: its inputs and primary output.
    pub fn required_columns(self) -> impl Iterator<Item = &'static str> {
        self.columns()
            .iter()
            .filter(|(_, role)| matches!(role, Role::Input | Role::PrimaryOutput))
            .map(|(n, _)| *n)
    }

    pub fn primary_output(self) -> &'static str {
        self.columns()
            .iter()
            .find(|(_, r)| *r == Role::PrimaryOutput)
            .map(|(n, _)| *n)
            .unwrap_or("")
    }
}

impl fmt::Display for Plant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The columns that are 0/1 flags (no unit suffix).
pub const FLAGS: [&str; 3] = ["u_pilot", "lift_high", "snubber_on"];

/// A 0/1 flag written as a word (a CSV's LabVIEW booleans, an MF4 channel's value-to-text
/// conversion): `true`, `on`, `high` are 1; `false`, `off`, `low` are 0 (any case). `None` for
/// another word.
pub(crate) fn flag_word(cell: &str) -> Option<f64> {
    let w = cell.trim();
    let is = |words: [&str; 3]| words.iter().any(|x| w.eq_ignore_ascii_case(x));
    if is(["true", "on", "high"]) {
        Some(1.0)
    } else if is(["false", "off", "low"]) {
        Some(0.0)
    } else {
        None
    }
}

/// The accepted range of a column (DATA-FORMAT.md range table), `None` when unconstrained.
pub fn column_range(name: &str) -> Option<(f64, f64)> {
    if FLAGS.contains(&name) {
        return Some((0.0, 1.0));
    }
    let exact = match name {
        "duty_pct" => Some((0.0, 100.0)),
        "x_pct" => Some((-5.0, 105.0)),
        "u_batt_V" => Some((0.0, 32.0)),
        "temp_C" => Some((-60.0, 200.0)),
        "lift_mm" => Some((-1.0, 12.0)),
        "phase_deg" | "phase_ref_deg" => Some((-30.0, 90.0)),
        "engine_rpm" => Some((0.0, 12000.0)),
        "motor_cmd_rpm" => Some((-20000.0, 20000.0)),
        "force_N" => Some((-1e6, 1e6)),
        "pos_m" | "ref_m" => Some((-10.0, 10.0)),
        _ => None,
    };
    exact.or_else(|| {
        if name.starts_with("p_") && name.ends_with("_kPa") {
            Some((0.0, 400.0))
        } else if name.starts_with("p_") && name.ends_with("_MPa") {
            Some((0.0, 40.0))
        } else {
            None
        }
    })
}

/// What went wrong, and where.
#[derive(Clone, Debug, PartialEq)]
pub struct LogError {
    pub file: String,
    /// 1-based line in the file, when the problem is on one line.
    pub line: Option<usize>,
    /// Column name (or 1-based index when the header is the problem).
    pub column: Option<String>,
    pub message: String,
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        if let Some(c) = &self.column {
            write!(f, ", column {c}")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for LogError {}

/// A log read whole: metadata, columns, and the sample rate it was checked against.
#[derive(Clone, Debug)]
pub struct Log {
    pub file: String,
    pub plant: Plant,
    /// `# key: value` lines in file order (unknown keys kept).
    pub meta: Vec<(String, String)>,
    /// Column name to samples; only the plant's known columns plus `t_s`.
    pub columns: BTreeMap<String, Vec<f64>>,
    /// Column names in file order (known ones only).
    pub order: Vec<String>,
    /// Sample period from the time column.
    pub dt_s: f64,
    /// Largest deviation of a time step from `dt_s`, in % of `dt_s`.
    pub jitter_pct: f64,
    /// Things the user should know that are not errors (ignored columns, jitter, unknown keys).
    pub notices: Vec<String>,
}

impl Log {
    pub fn len(&self) -> usize {
        // Every column has the log's length; `t_s` may have been dropped (`without_time_stamps`).
        self.columns
            .get("t_s")
            .or_else(|| self.columns.values().next())
            .map_or(0, Vec::len)
    }
    /// The log without its time column, for a reader of the sample period only: the reader
    /// checked the time stamps uniform to `dt_s`, and the diagnosis's fits use `dt_s` alone.
    /// It saves 8 B a row of a long estimation log.
    pub fn without_time_stamps(mut self) -> Log {
        self.columns.remove("t_s");
        self.order.retain(|n| n != "t_s");
        self
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn col(&self, name: &str) -> Option<&[f64]> {
        self.columns.get(name).map(Vec::as_slice)
    }
    /// Splits the log into its head and the held-out tail (`tail` fraction of the samples),
    /// moving the samples instead of copying them: the peak stays at one log's columns plus
    /// the tail's (for EHVVA 64 B a row and 19 B a row for a 30 % tail). Files are named
    /// as `diagnose` names them.
    pub fn split_tail(self, tail: f64) -> (Log, Log) {
        let n = self.len();
        let cut = ((n as f64) * (1.0 - tail.clamp(0.0, 1.0))).round() as usize;
        let mut head = self;
        let mut back = head.clone_empty();
        for (name, v) in head.columns.iter_mut() {
            let rest = v.split_off(cut.min(v.len()));
            v.shrink_to_fit();
            back.columns.insert(name.clone(), rest);
        }
        back.file = format!("{} (last {:.0} %, held out)", head.file, 100.0 * tail);
        head.file = format!("{} (first {:.0} %)", head.file, 100.0 * (1.0 - tail));
        (head, back)
    }

    /// The rows in `ranges` (in that order) as a log of their own, named `label`: a part of a
    /// long record that a fit uses. Metadata, notices and the sample period are kept; the
    /// time column is cut like the others, so it jumps where the ranges meet.
    pub fn select_rows(&self, ranges: &[std::ops::Range<usize>], label: String) -> Log {
        let mut part = self.clone_empty();
        part.file = label;
        for (name, v) in &self.columns {
            let mut cut = Vec::with_capacity(ranges.iter().map(|r| r.len()).sum());
            for r in ranges {
                cut.extend_from_slice(&v[r.start.min(v.len())..r.end.min(v.len())]);
            }
            part.columns.insert(name.clone(), cut);
        }
        part
    }

    /// The log without samples (metadata, notices, timing kept).
    fn clone_empty(&self) -> Log {
        Log {
            file: self.file.clone(),
            plant: self.plant,
            meta: self.meta.clone(),
            columns: BTreeMap::new(),
            order: self.order.clone(),
            dt_s: self.dt_s,
            jitter_pct: self.jitter_pct,
            notices: self.notices.clone(),
        }
    }

    /// A metadata value by key.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }
    /// A numeric metadata value; an error names the key when it is present but not a number.
    pub fn meta_f64(&self, key: &str) -> Result<Option<f64>, LogError> {
        match self.meta(key) {
            None => Ok(None),
            Some(v) => match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(LogError {
                    file: self.file.clone(),
                    line: None,
                    column: None,
                    message: format!("metadata `{key}` is `{v}`, not a finite number"),
                }),
            },
        }
    }
}

/// Reads and checks a log file. `plant` overrides the file's `# plant:` metadata.
/// An ASAM MDF 4 file (`.mf4`, or the MDF signature) is read by `crate::mf4` with its channels
/// under their DATA-FORMAT names; `read_log_mapped` takes a channel map for other names.
pub fn read_log(path: &Path, plant: Option<Plant>) -> Result<Log, LogError> {
    read_log_mapped(path, plant, None)
}

/// `read_log` with a channel map (`--channel-map`) that renames an MF4 file's channels and adds
/// metadata; a CSV log takes the map's metadata only when the file lacks the key.
pub fn read_log_mapped(path: &Path, plant: Option<Plant>, map: Option<&ChannelMap>) -> Result<Log, LogError> {
    if crate::mf4::is_mf4(path) {
        return crate::mf4::read_mf4(path, plant, map);
    }
    let map_plant = map
        .and_then(|m| m.meta.iter().find(|(k, _)| k == "plant"))
        .and_then(|(_, v)| Plant::from_name(v));
    let renames = map.map(|m| csv::Renames {
        map_file: &m.file,
        columns: &m.channels,
        units: &m.units,
    });
    let mut log = read_csv_log(path, plant.or(map_plant), renames)?;
    if let Some(map) = map {
        for (k, v) in &map.meta {
            if log.meta(k).is_none() {
                log.meta.push((k.clone(), v.clone()));
            }
        }
    }
    Ok(log)
}

fn read_csv_log(path: &Path, plant: Option<Plant>, renames: Option<csv::Renames<'_>>) -> Result<Log, LogError> {
    let file = path.display().to_string();
    let input = fs::File::open(path).map_err(|e| LogError {
        file: file.clone(),
        line: None,
        column: None,
        message: format!("cannot read: {e}"),
    })?;
    let size = input.metadata().ok().filter(|m| m.is_file()).map(|m| m.len());
    csv::read_csv_sized(&file, BufReader::with_capacity(1 << 16, input), plant, size, renames)
}

/// Parses log text; `file` names it in errors.
pub fn parse_log(file: &str, text: &str, plant_override: Option<Plant>) -> Result<Log, LogError> {
    read_csv(file, text.as_bytes(), plant_override)
}

/// Writes a log in the same format. `columns` are (name, samples), all the same length.
pub fn write_log(path: &Path, meta: &[(String, String)], columns: &[(&str, &[f64])]) -> std::io::Result<()> {
    fs::write(path, format_log(meta, columns))
}

/// The text of a log (what `write_log` writes).
pub fn format_log(meta: &[(String, String)], columns: &[(&str, &[f64])]) -> String {
    let mut s = String::new();
    for (k, v) in meta {
        s.push_str(&format!("# {k}: {v}\n"));
    }
    s.push_str(&columns.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(","));
    s.push('\n');
    let n = columns.iter().map(|(_, v)| v.len()).min().unwrap_or(0);
    for i in 0..n {
        let row: Vec<String> = columns.iter().map(|(_, v)| format_number(v[i])).collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
}

/// Shortest text that reads back to the same f64 (Rust's `{}` is round-trip exact).
fn format_number(x: f64) -> String {
    format!("{x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "# plant: positioner\n# source: test\n# sample_rate_hz: 1000\n# bench: A7\nt_s,force_N,pos_m,extra\n0.000,1.5,0.0,9\n0.001,2.5,0.001,9\n0.002,3.5,0.002,9\n";

    #[test]
    fn reads_a_good_log_and_notes_extras() {
        let log = parse_log("a.csv", GOOD, None).unwrap();
        assert_eq!(log.plant, Plant::Positioner);
        assert_eq!(log.len(), 3);
        assert_eq!(log.col("force_N").unwrap(), &[1.5, 2.5, 3.5]);
        assert!((log.dt_s - 0.001).abs() < 1e-12);
        assert_eq!(log.meta("bench"), Some("A7"));
        assert!(log.notices.iter().any(|n| n.contains("`extra`")));
        assert!(log.notices.iter().any(|n| n.contains("`bench`")));
        assert!(log.col("extra").is_none());
    }

    fn error_of(text: &str) -> LogError {
        parse_log("bad.csv", text, None).unwrap_err()
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let e = error_of(&GOOD.replace("2.5,0.001", "abc,0.001"));
        assert_eq!((e.line, e.column.as_deref()), (Some(7), Some("force_N")));
        assert!(e.to_string().starts_with("bad.csv:7, column force_N:"), "{e}");

        let e = error_of(&GOOD.replace("2.5,0.001", "NaN,0.001"));
        assert_eq!((e.line, e.column.as_deref()), (Some(7), Some("force_N")));

        let e = error_of(&GOOD.replace("0.002,3.5,0.002", "0.002,3.5,11.0"));
        assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("pos_m")));
        assert!(e.message.contains("range"));

        let e = error_of(&GOOD.replace("0.002,3.5", "0.001,3.5"));
        assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("t_s")));

        let e = error_of(
            &GOOD
                .replace("t_s,force_N,pos_m,extra", "t_s,pos_m,extra")
                .replace(",1.5,", ",")
                .replace(",2.5,", ",")
                .replace(",3.5,", ","),
        );
        assert_eq!((e.line, e.column.as_deref()), (Some(5), Some("force_N")));

        let e = error_of(&GOOD.replace("0.001,2.5,0.001,9", "0.001,2.5,0.001"));
        assert_eq!(e.line, Some(7));
    }

    #[test]
    fn rejects_nonuniform_sampling_and_accepts_small_jitter() {
        let e = error_of(&GOOD.replace("0.002,3.5", "0.0025,3.5"));
        assert_eq!(e.column.as_deref(), Some("t_s"));
        let ok = parse_log("j.csv", &GOOD.replace("0.002,3.5", "0.002005,3.5"), None).unwrap();
        // Steps 1 ms and 1.005 ms: the period is their mean, each 0.25 % off it.
        assert!(ok.jitter_pct > 0.24 && ok.jitter_pct < 0.26, "{}", ok.jitter_pct);
        assert!(ok.notices.iter().any(|n| n.contains("jitter")));
    }

    #[test]
    fn flags_must_be_zero_or_one_and_plant_must_be_known() {
        let text = "# plant: ehvva\nt_s,u_pilot,p_supply_MPa,p_back_MPa,temp_C,lift_high,snubber_on,lift_mm\n0,0,7,1,22,1,0,0\n1e-5,0.5,7,1,22,1,0,0\n";
        let e = error_of(text);
        assert_eq!((e.line, e.column.as_deref()), (Some(4), Some("u_pilot")));
        let e = error_of(&GOOD.replace("positioner", "turbine"));
        assert!(e.message.contains("unknown plant `turbine`"));
        let e = error_of(&GOOD.replace("# plant: positioner\n", ""));
        assert!(e.message.contains("--plant"));
    }

    #[test]
    fn split_tail_moves_the_samples() {
        let log = parse_log("a.csv", GOOD, None).unwrap();
        let whole = log.col("pos_m").unwrap().to_vec();
        let (head, tail) = log.split_tail(0.3);
        assert_eq!((head.len(), tail.len()), (2, 1));
        assert_eq!([head.col("pos_m").unwrap(), tail.col("pos_m").unwrap()].concat(), whole);
        assert_eq!(tail.file, "a.csv (last 30 %, held out)");
        assert_eq!(head.file, "a.csv (first 70 %)");
    }

    #[test]
    fn written_logs_read_back_bit_exact() {
        let t = [0.0, 0.01, 0.02];
        let x = [0.1 + 0.2, 1.0 / 3.0, -0.0];
        let f = [1e-300, 123456.789, -5.0];
        let text = format_log(
            &[("plant".into(), "positioner".into())],
            &[("t_s", &t), ("pos_m", &x), ("force_N", &f)],
        );
        let log = parse_log("w.csv", &text, None).unwrap();
        assert_eq!(log.col("pos_m").unwrap(), &x);
        assert_eq!(log.col("force_N").unwrap(), &f);
    }

    #[test]
    fn reads_the_emps_benchmark_when_shared_data_is_present() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/emps/emps-estimation.csv");
        if !path.exists() {
            eprintln!(
                "SKIP: {} not found (../shared is absent in a fresh clone)",
                path.display()
            );
            return;
        }
        let log = read_log(&path, None).unwrap();
        assert_eq!(log.plant, Plant::Positioner);
        assert_eq!(log.len(), 24841);
        assert!((log.dt_s - 0.001).abs() < 1e-9);
        assert_eq!(log.meta_f64("gtau").unwrap(), Some(35.1506518825));
    }
}
