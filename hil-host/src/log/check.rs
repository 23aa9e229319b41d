//! The checks every log goes through, whatever file it came from (CSV, MF4, memory):
//! metadata typed and consistent, the header's columns, then every sample.
//!
//! All three steps are linear in the input. Errors name the source, the line (when the
//! source has lines: [`RowLines`] maps a sample to its file line) and the column.

use std::collections::{BTreeMap, HashMap};

use super::{column_range, Log, LogError, Plant, FLAGS};

/// At most this many columns in a header (a wider header is an error, not a slow read).
pub const MAX_COLUMNS: usize = 10_000;

/// Sample periods outside this range (s) are not a bench log's: 10 MHz .. one sample in ~3 h.
pub const PERIOD_RANGE_S: (f64, f64) = (1e-7, 1e4);

/// Times beyond ±this (s, ~317 years) are garbage, not a clock.
pub const MAX_ABS_TIME_S: f64 = 1e10;

/// How a metadata value must look.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// Free text; may repeat.
    Text,
    /// One of the plant names.
    Plant,
    /// A finite number.
    Number,
    /// A finite number within (lo, hi], lo excluded.
    Positive(f64),
    /// A whole number within 1..=max.
    Count(u64),
    /// An unsigned 64-bit integer.
    Seed,
}

/// Metadata keys the tools understand, with the type their value must have; others are kept
/// and shown.
const KNOWN_KEYS: [(&str, Kind); 16] = [
    ("plant", Kind::Plant),
    ("source", Kind::Text),
    ("sample_rate_hz", Kind::Positive(1.0 / PERIOD_RANGE_S.0)),
    ("controller", Kind::Text),
    ("kp", Kind::Number),
    ("kv", Kind::Number),
    ("gtau", Kind::Number),
    ("control_period_s", Kind::Positive(PERIOD_RANGE_S.1)),
    ("force_max_N", Kind::Positive(1e7)),
    ("motor_cmd_max_rpm", Kind::Positive(1e6)),
    ("cam_events_per_cycle", Kind::Count(1000)),
    ("u_ref_V", Kind::Positive(1000.0)),
    ("seed", Kind::Seed),
    ("effect", Kind::Text),
    ("experiment", Kind::Text),
    ("note", Kind::Text),
];

/// One `key: value` with the file line it came from (`None` for sources without lines).
#[derive(Clone, Debug, PartialEq)]
pub struct MetaEntry {
    pub key: String,
    pub value: String,
    pub line: Option<usize>,
}

/// Where the samples of a source sit in its file: sample `i` is on line `first + i` until a
/// break (a blank line skipped between rows, a units row) shifts the rest. Stores only the
/// breaks, so a million contiguous rows cost nothing.
#[derive(Clone, Debug, Default)]
pub struct RowLines {
    /// (first sample, its line), ascending; empty when the source has no lines.
    breaks: Vec<(usize, usize)>,
}

impl RowLines {
    /// No lines (an in-memory or MF4 source): errors then name the sample index.
    pub fn none() -> Self {
        RowLines { breaks: Vec::new() }
    }
    /// Records that sample `row` is on `line` (call in row order, for every row).
    pub fn push(&mut self, row: usize, line: usize) {
        match self.breaks.last() {
            Some(&(r, l)) if l + (row - r) == line => {}
            _ => self.breaks.push((row, line)),
        }
    }
    /// The file line of sample `row`, when the source has lines.
    pub fn line_of(&self, row: usize) -> Option<usize> {
        let k = self.breaks.partition_point(|&(r, _)| r <= row);
        let (r, l) = *self.breaks.get(k.checked_sub(1)?)?;
        Some(l + (row - r))
    }
}

fn error(source: &str, line: Option<usize>, column: Option<&str>, message: String) -> LogError {
    LogError {
        file: source.to_string(),
        line,
        column: column.map(str::to_string),
        message,
    }
}

/// Where a sample is, for an error's text: the line in the file, or the sample index.
fn at_row(rows: &RowLines, row: usize) -> (Option<usize>, String) {
    match rows.line_of(row) {
        Some(l) => (Some(l), String::new()),
        None => (None, format!("sample {} (0-based): ", row)),
    }
}

/// A number as a reader wants it: plain when moderate, in exponent form when huge or tiny.
fn show(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e9).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

fn parse_number(value: &str) -> Option<f64> {
    value.trim().parse::<f64>().ok().filter(|x| x.is_finite())
}

/// What [`check_meta`] settles: the plant, the metadata as (key, value) in source order, and
/// notices.
pub type MetaVerdict = (Plant, Vec<(String, String)>, Vec<String>);

/// Checks the metadata's types and consistency and settles the plant (`plant_override`, from
/// `--plant`, wins over `# plant:`). Returns the plant, the metadata as (key, value) in
/// source order, and notices.
pub fn check_meta(source: &str, meta: &[MetaEntry], plant_override: Option<Plant>) -> Result<MetaVerdict, LogError> {
    let mut notices = Vec::new();
    let mut seen: HashMap<&str, &MetaEntry> = HashMap::new();
    let mut unknown = Vec::new();
    for m in meta {
        let key = m.key.as_str();
        let kind = KNOWN_KEYS.iter().find(|(k, _)| *k == key).map(|(_, t)| *t);
        let bad = |what: String| error(source, m.line, None, format!("metadata `{key}`: {what}"));
        match kind {
            None => unknown.push(key),
            Some(Kind::Text) => {}
            Some(Kind::Plant) => {
                if Plant::from_name(&m.value).is_none() {
                    return Err(bad(format!(
                        "unknown plant `{}` (known: vacuum, ehvva, evvt, positioner)",
                        m.value
                    )));
                }
            }
            Some(Kind::Number) => {
                if parse_number(&m.value).is_none() {
                    return Err(bad(format!("`{}` is not a finite number", m.value)));
                }
            }
            Some(Kind::Positive(hi)) => match parse_number(&m.value) {
                Some(x) if x > 0.0 && x <= hi => {}
                _ => return Err(bad(format!("`{}` must be a number in (0, {hi:e}]", m.value))),
            },
            Some(Kind::Count(max)) => match m.value.trim().parse::<u64>() {
                Ok(n) if (1..=max).contains(&n) => {}
                _ => return Err(bad(format!("`{}` must be a whole number in 1..={max}", m.value))),
            },
            Some(Kind::Seed) => {
                if m.value.trim().parse::<u64>().is_err() {
                    return Err(bad(format!("`{}` is not an unsigned integer", m.value)));
                }
            }
        }
        if let Some(first) = seen.get(key) {
            let same = match kind {
                Some(Kind::Number | Kind::Positive(_)) => parse_number(&first.value) == parse_number(&m.value),
                Some(Kind::Plant) => Plant::from_name(&first.value) == Plant::from_name(&m.value),
                _ => first.value.trim() == m.value.trim(),
            };
            let where_first = first.line.map_or(String::new(), |l| format!(" (line {l})"));
            if !same && kind.is_some_and(|k| k != Kind::Text) {
                return Err(bad(format!(
                    "`{}` contradicts the earlier `{}`{where_first}",
                    m.value, first.value
                )));
            }
            notices.push(format!(
                "{}metadata `{key}` given again{}; the first{where_first} is used",
                m.line.map_or(String::new(), |l| format!("line {l}: ")),
                if same { " with the same value" } else { "" }
            ));
        } else {
            seen.insert(key, m);
        }
    }
    if !unknown.is_empty() {
        unknown.dedup();
        notices.push(format!(
            "metadata {} {} not used by the tools; kept",
            list_names(unknown.iter().copied(), "key", "keys"),
            if unknown.len() == 1 { "is" } else { "are" }
        ));
    }
    let from_meta = seen.get("plant").map(|m| (Plant::from_name(&m.value), m.line));
    let plant = match (plant_override, from_meta) {
        (Some(p), Some((Some(q), line))) if p != q => {
            notices.push(format!(
                "{}metadata says plant `{q}`; `{p}` as asked is used",
                line.map_or(String::new(), |l| format!("line {l}: "))
            ));
            p
        }
        (Some(p), _) => p,
        (None, Some((Some(q), _))) => q,
        (None, _) => {
            return Err(error(
                source,
                None,
                None,
                "no `# plant:` metadata and no plant given (--plant)".into(),
            ))
        }
    };
    let meta = meta.iter().map(|m| (m.key.clone(), m.value.clone())).collect();
    Ok((plant, meta, notices))
}

/// "keys `a`, `b` and 3 more", bounded however many there are.
fn list_names<'a>(names: impl Iterator<Item = &'a str>, one: &str, many: &str) -> String {
    let names: Vec<&str> = names.collect();
    let shown: Vec<String> = names.iter().take(8).map(|n| format!("`{n}`")).collect();
    let more = names.len().saturating_sub(shown.len());
    format!(
        "{} {}{}",
        if names.len() == 1 { one } else { many },
        shown.join(", "),
        if more > 0 {
            format!(" and {more} more")
        } else {
            String::new()
        }
    )
}

/// The header's verdict: which source columns are kept, in which slot.
#[derive(Clone, Debug)]
pub struct Selection {
    /// Per source column: `Some(slot)` when kept.
    pub keep: Vec<Option<usize>>,
    /// The kept columns' names by slot (file order); `t_s` is among them.
    pub order: Vec<String>,
    pub notices: Vec<String>,
}

/// Checks a header (names trimmed, non-empty, distinct, at most [`MAX_COLUMNS`], `t_s` and the
/// plant's required columns present) and picks the columns to keep. `line` is the header's
/// file line when it has one. Linear in the number of columns.
pub fn select_columns(
    source: &str,
    plant: Plant,
    names: &[String],
    line: Option<usize>,
) -> Result<Selection, LogError> {
    let err = |column: &str, message: String| error(source, line, Some(column), message);
    if names.len() > MAX_COLUMNS {
        return Err(error(
            source,
            line,
            None,
            format!("header has {} columns; at most {MAX_COLUMNS} are accepted", names.len()),
        ));
    }
    let known: Vec<&str> = plant.columns().iter().map(|(n, _)| *n).collect();
    let mut first_at: HashMap<&str, usize> = HashMap::with_capacity(names.len());
    let mut keep = Vec::with_capacity(names.len());
    let mut order = Vec::new();
    let mut ignored = Vec::new();
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() {
            return Err(err(&format!("#{}", i + 1), "empty column name in header".into()));
        }
        if let Some(j) = first_at.insert(name, i) {
            return Err(err(
                name,
                format!("column appears twice in header (columns #{} and #{})", j + 1, i + 1),
            ));
        }
        if name == "t_s" || known.contains(&name.as_str()) {
            keep.push(Some(order.len()));
            order.push(name.clone());
        } else {
            keep.push(None);
            ignored.push(name.as_str());
        }
    }
    if !first_at.contains_key("t_s") {
        return Err(err("t_s", "required column `t_s` is missing".into()));
    }
    for name in plant.required_columns() {
        if !first_at.contains_key(name) {
            return Err(err(name, format!("required `{plant}` column `{name}` is missing")));
        }
    }
    let mut notices = Vec::new();
    if !ignored.is_empty() {
        let one = ignored.len() == 1;
        let what = if one {
            format!("is not a `{plant}` column")
        } else {
            format!("are not `{plant}` columns")
        };
        notices.push(format!(
            "{} {what}; ignored",
            list_names(ignored.into_iter(), "column", "columns")
        ));
    }
    Ok(Selection { keep, order, notices })
}

/// What the samples' check finds out.
#[derive(Clone, Debug)]
pub struct Timing {
    pub dt_s: f64,
    pub jitter_pct: f64,
    pub notices: Vec<String>,
}

/// Checks every sample: equal lengths, at least 2 rows, finite, within its column's range,
/// flags 0 or 1, `t_s` within ±[`MAX_ABS_TIME_S`], strictly increasing and uniformly sampled
/// (every step within 1 % of the period: the mean step, or the median one when a gap spoils
/// the mean) with a plausible period ([`PERIOD_RANGE_S`]), and `# sample_rate_hz:` against it. The
/// first bad sample (lowest row, then leftmost column) is the error. Linear in the samples.
pub fn check_samples(
    source: &str,
    meta: &[(String, String)],
    columns: &[(String, Vec<f64>)],
    rows: &RowLines,
) -> Result<Timing, LogError> {
    let n = columns.first().map_or(0, |(_, v)| v.len());
    if let Some((name, v)) = columns.iter().find(|(_, v)| v.len() != n) {
        return Err(error(
            source,
            None,
            Some(name),
            format!("{} samples where `{}` has {n}", v.len(), columns[0].0),
        ));
    }
    let Some((_, t)) = columns.iter().find(|(name, _)| name == "t_s") else {
        return Err(error(
            source,
            None,
            Some("t_s"),
            "required column `t_s` is missing".into(),
        ));
    };
    // The first bad cell: (row, column index, message).
    let mut first: Option<(usize, usize, String)> = None;
    for (c, (name, v)) in columns.iter().enumerate() {
        let range = if name == "t_s" {
            Some((-MAX_ABS_TIME_S, MAX_ABS_TIME_S))
        } else {
            column_range(name)
        };
        let flag = FLAGS.contains(&name.as_str());
        let limit = first.as_ref().map_or(n, |f| f.0 + 1);
        for (i, &x) in v[..limit.min(n)].iter().enumerate() {
            let problem = if !x.is_finite() {
                Some(format!("{x} is not finite"))
            } else if let Some((lo, hi)) = range.filter(|(lo, hi)| x < *lo || x > *hi) {
                Some(format!(
                    "{} is outside the column's range {}..{}",
                    show(x),
                    show(lo),
                    show(hi)
                ))
            } else if flag && x != 0.0 && x != 1.0 {
                Some(format!("{x} is not a flag (0 or 1)"))
            } else {
                None
            };
            if let Some(p) = problem {
                if first.as_ref().is_none_or(|f| i < f.0) {
                    first = Some((i, c, p));
                }
                break;
            }
        }
    }
    if let Some((row, c, message)) = first {
        let (line, prefix) = at_row(rows, row);
        return Err(error(source, line, Some(&columns[c].0), format!("{prefix}{message}")));
    }
    if n < 2 {
        return Err(error(
            source,
            None,
            None,
            format!("{n} data rows; at least 2 are needed"),
        ));
    }
    let between = |i: usize| match (rows.line_of(i - 1), rows.line_of(i)) {
        (Some(a), Some(b)) => format!("lines {a} and {b}"),
        _ => format!("samples {} and {}", i - 1, i),
    };
    // Strictly increasing; every step finite (bounded times make it so) and positive.
    if let Some(i) = (1..n).find(|&i| t[i] <= t[i - 1]) {
        let (line, prefix) = at_row(rows, i);
        return Err(error(
            source,
            line,
            Some("t_s"),
            format!(
                "{prefix}time {} does not increase (previous {})",
                show(t[i]),
                show(t[i - 1])
            ),
        ));
    }
    // The period: the mean step when every step lies within 1 % of it (a uniform log: no
    // memory beyond the columns), else the median step (robust to the gap that the check
    // below then names), found in linear time.
    let mean_s = (t[n - 1] - t[0]) / (n - 1) as f64;
    let dt_s = if t.windows(2).all(|w| ((w[1] - w[0]) - mean_s).abs() <= 0.01 * mean_s) {
        mean_s
    } else {
        let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let mid = steps.len() / 2;
        *steps.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    if !(dt_s >= PERIOD_RANGE_S.0 && dt_s <= PERIOD_RANGE_S.1) {
        let i = (1..n)
            .min_by(|&a, &b| {
                ((t[a] - t[a - 1]) - dt_s)
                    .abs()
                    .total_cmp(&((t[b] - t[b - 1]) - dt_s).abs())
            })
            .unwrap_or(1);
        return Err(error(
            source,
            rows.line_of(i),
            Some("t_s"),
            format!(
                "the sample period (median step, e.g. between {}) is {dt_s:e} s; a log's lies in {:e}..{:e} s",
                between(i),
                PERIOD_RANGE_S.0,
                PERIOD_RANGE_S.1
            ),
        ));
    }
    let mut jitter_pct: f64 = 0.0;
    for i in 1..n {
        let s = t[i] - t[i - 1];
        let dev = (s - dt_s).abs() / dt_s * 100.0;
        if dev > 1.0 {
            let (line, _) = at_row(rows, i);
            return Err(error(
                source,
                line,
                Some("t_s"),
                format!(
                    "not uniformly sampled: step {} s between {} deviates {dev:.1} % from the period {} s (1 % accepted)",
                    show(s),
                    between(i),
                    show(dt_s)
                ),
            ));
        }
        jitter_pct = jitter_pct.max(dev);
    }
    let mut notices = Vec::new();
    if jitter_pct > 0.01 {
        notices.push(format!(
            "time jitter up to {jitter_pct:.2} % of the {dt_s} s period (accepted up to 1 %)"
        ));
    }
    // Typed by check_meta already: finite and positive.
    if let Some(hz) = meta
        .iter()
        .find(|(k, _)| k == "sample_rate_hz")
        .and_then(|(_, v)| parse_number(v))
    {
        if ((1.0 / hz) - dt_s).abs() / dt_s > 0.01 {
            notices.push(format!(
                "metadata sample_rate_hz {hz} disagrees with the time column's {:.6} Hz; the time column is used",
                1.0 / dt_s
            ));
        }
    }
    // A column that never moves carries no excitation: a fit on it has nothing to identify.
    let constant: Vec<&str> = columns
        .iter()
        .filter(|(name, v)| name != "t_s" && !FLAGS.contains(&name.as_str()) && v.iter().all(|&x| x == v[0]))
        .map(|(name, _)| name.as_str())
        .collect();
    if !constant.is_empty() {
        let verb = if constant.len() == 1 { "is" } else { "are" };
        notices.push(format!(
            "{} {verb} constant over all {n} samples (no excitation to identify from)",
            list_names(constant.into_iter(), "column", "columns")
        ));
    }
    Ok(Timing {
        dt_s,
        jitter_pct,
        notices,
    })
}

/// Builds a [`Log`] from an in-memory table after every check a CSV file goes through:
/// metadata typed and consistent, header, samples. `source` names the data in errors (a file
/// name, `file.mf4`, ...); errors name the column and the sample index (0-based). Columns not
/// of the plant are dropped with a notice. This is the one entry point for readers of other
/// formats (MF4); the CSV reader runs the same three checks with file lines.
pub fn log_from_columns(
    source: &str,
    meta: Vec<(String, String)>,
    columns: Vec<(String, Vec<f64>)>,
    plant: Option<Plant>,
) -> Result<Log, LogError> {
    let entries: Vec<MetaEntry> = meta
        .into_iter()
        .map(|(key, value)| MetaEntry { key, value, line: None })
        .collect();
    let (plant, meta, mut notices) = check_meta(source, &entries, plant)?;
    let names: Vec<String> = columns.iter().map(|(n, _)| n.trim().to_string()).collect();
    let sel = select_columns(source, plant, &names, None)?;
    notices.extend(sel.notices);
    let mut kept: Vec<(String, Vec<f64>)> = Vec::with_capacity(sel.order.len());
    for ((_, v), slot) in columns.into_iter().zip(&sel.keep) {
        if let Some(s) = slot {
            kept.push((sel.order[*s].clone(), v));
        }
    }
    finish(source, plant, meta, kept, &RowLines::none(), notices)
}

/// The last step of every reader: the samples' check, then the [`Log`].
pub(crate) fn finish(
    source: &str,
    plant: Plant,
    meta: Vec<(String, String)>,
    columns: Vec<(String, Vec<f64>)>,
    rows: &RowLines,
    mut notices: Vec<String>,
) -> Result<Log, LogError> {
    let timing = check_samples(source, &meta, &columns, rows)?;
    notices.extend(timing.notices);
    let order: Vec<String> = columns.iter().map(|(n, _)| n.clone()).collect();
    let columns: BTreeMap<String, Vec<f64>> = columns.into_iter().collect();
    Ok(Log {
        file: source.to_string(),
        plant,
        meta,
        columns,
        order,
        dt_s: timing.dt_s,
        jitter_pct: timing.jitter_pct,
        notices,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_lines_map_samples_to_file_lines_across_breaks() {
        let mut r = RowLines::default();
        for (row, line) in [(0, 6), (1, 7), (2, 9), (3, 10), (4, 11), (5, 20)] {
            r.push(row, line);
        }
        assert_eq!(r.breaks.len(), 3);
        let lines: Vec<_> = (0..6).map(|i| r.line_of(i)).collect();
        assert_eq!(lines, [6, 7, 9, 10, 11, 20].map(Some));
        assert_eq!(RowLines::none().line_of(3), None);
    }
}
