//! Fuzzing the log reader on stable Rust: proptest draws arbitrary bytes and structured
//! mutations of valid logs in every dialect (flipped bytes, cut and repeated lines, huge
//! numbers, NaN, duplicate columns, stray BOMs, quotes and separators) and asserts that the
//! reader never panics, answers each input within [`fuzz_common::HANG_LIMIT`], and that whatever it accepts
//! is a valid log (the invariants of DATA-FORMAT.md, checked independently here).
//!
//! CI runs a short round; the long run (>= 10^6 inputs per target) is ignored:
//! `FUZZ_CASES=1000000 cargo test -p hil-host --test fuzz_reader -- --ignored --nocapture`.
//! Its figures are in docs/reliability.md. Every input that once failed is kept in
//! `tests/regressions/` (checked by [`regression_files_give_their_errors`]).

mod fuzz_common;

use fuzz_common::{cases, fuzz};

use std::path::Path;

use hil_host::log::check::PERIOD_RANGE_S;
use hil_host::log::{column_range, format_log, log_from_columns, parse_log, read_csv, read_log, Log, Plant, Role};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

/// What DATA-FORMAT.md promises of an accepted log, checked without the reader's code.
fn assert_valid(log: &Log) -> Result<(), TestCaseError> {
    let n = log.len();
    prop_assert!(n >= 2, "{} samples", n);
    prop_assert_eq!(log.order.len(), log.columns.len());
    for (name, role) in log.plant.columns() {
        if matches!(role, Role::Input | Role::PrimaryOutput) {
            prop_assert!(log.col(name).is_some(), "required {} missing", name);
        }
    }
    for name in &log.order {
        let v = log
            .col(name)
            .ok_or_else(|| TestCaseError::fail(format!("{name} in order, not in columns")))?;
        prop_assert_eq!(v.len(), n, "{}", name);
        prop_assert!(v.iter().all(|x| x.is_finite()), "{} not finite", name);
        if let Some((lo, hi)) = column_range(name) {
            prop_assert!(v.iter().all(|x| (lo..=hi).contains(x)), "{} out of range", name);
        }
    }
    let t = log.col("t_s").ok_or_else(|| TestCaseError::fail("no t_s"))?;
    prop_assert!(
        log.dt_s >= PERIOD_RANGE_S.0 && log.dt_s <= PERIOD_RANGE_S.1,
        "dt {}",
        log.dt_s
    );
    for w in t.windows(2) {
        let s = w[1] - w[0];
        prop_assert!(
            s > 0.0 && (s - log.dt_s).abs() <= 0.0100001 * log.dt_s,
            "step {} vs {}",
            s,
            log.dt_s
        );
    }
    Ok(())
}

fn read_bytes(bytes: &[u8]) -> Result<bool, TestCaseError> {
    let mut ok = false;
    if let Ok(log) = read_csv("fuzz.csv", bytes, None) {
        assert_valid(&log)?;
        ok = true;
    }
    // The plant given, as `--plant` does: other code paths (plant metadata ignored).
    if let Ok(log) = read_csv("fuzz.csv", bytes, Some(Plant::Vacuum)) {
        prop_assert_eq!(log.plant, Plant::Vacuum);
        assert_valid(&log)?;
    }
    Ok(ok)
}

/// Valid logs of every plant and dialect: what the mutations start from.
fn seeds() -> Vec<Vec<u8>> {
    let t: Vec<f64> = (0..6).map(|i| f64::from(i) * 1e-3).collect();
    let ramp = |a: f64, b: f64| -> Vec<f64> { (0..6).map(|i| a + b * f64::from(i)).collect() };
    let flags = [0.0, 1.0, 1.0, 0.0, 0.0, 1.0];
    let meta = |plant: &str| {
        vec![
            ("plant".to_string(), plant.to_string()),
            ("sample_rate_hz".into(), "1000".into()),
        ]
    };
    let vacuum = format_log(
        &meta("vacuum"),
        &[
            ("t_s", &t),
            ("duty_pct", &ramp(10.0, 7.5)),
            ("u_batt_V", &ramp(13.5, 0.1)),
            ("p_amb_kPa", &ramp(101.3, 0.0)),
            ("p_tank_kPa", &ramp(40.0, 0.25)),
            ("x_pct", &ramp(-0.5, 11.0)),
            ("p_act_kPa", &ramp(90.0, -3.0)),
        ],
    );
    let ehvva = format_log(
        &meta("ehvva"),
        &[
            ("t_s", &t),
            ("u_pilot", &flags),
            ("p_supply_MPa", &ramp(7.0, 0.0)),
            ("p_back_MPa", &ramp(1.0, 0.0)),
            ("temp_C", &ramp(22.0, 0.5)),
            ("lift_high", &flags),
            ("snubber_on", &flags),
            ("lift_mm", &ramp(0.0, 1.25)),
        ],
    );
    let mut evvt_meta = meta("evvt");
    evvt_meta.extend([
        ("kp".to_string(), "40".to_string()),
        ("control_period_s".into(), "0.01".into()),
    ]);
    let evvt = format_log(
        &evvt_meta,
        &[
            ("t_s", &t),
            ("motor_cmd_rpm", &ramp(-500.0, 300.0)),
            ("engine_rpm", &ramp(800.0, 100.0)),
            ("u_batt_V", &ramp(14.0, 0.0)),
            ("phase_ref_deg", &ramp(10.0, 0.0)),
            ("phase_deg", &ramp(0.0, 2.0)),
        ],
    );
    let positioner = format_log(
        &meta("positioner"),
        &[
            ("t_s", &t),
            ("force_N", &ramp(-20.0, 9.0)),
            ("pos_m", &ramp(0.0, 1e-3)),
            ("extra", &ramp(1.0, 1.0)),
        ],
    );
    let excel = {
        let mut s = String::from("\u{feff}");
        for (k, line) in vacuum.lines().enumerate() {
            if line.starts_with('#') {
                s.push_str(line);
            } else {
                let cells: Vec<String> = line
                    .split(',')
                    .map(|c| format!("\"{}\"", c.replace('.', ",")))
                    .collect();
                s.push_str(&cells.join(";"));
                if k == 2 {
                    s.push_str("\r\n[s];[%];[V];[kPa];[kPa];[%];[kPa]");
                }
            }
            s.push_str("\r\n");
        }
        s
    };
    let tabs = ehvva.replace(',', "\t");
    for s in [&vacuum, &ehvva, &evvt, &positioner, &excel, &tabs] {
        assert!(parse_log("seed.csv", s, None).is_ok(), "seed does not read: {s}");
    }
    [vacuum, ehvva, evvt, positioner, excel, tabs]
        .into_iter()
        .map(String::into_bytes)
        .collect()
}

/// Pieces that break logs in interesting ways.
const TOKENS: [&str; 32] = [
    ",",
    ";",
    "\t",
    "\"",
    "\r",
    "\n",
    "\r\n",
    "\u{feff}",
    "#",
    "# plant: ehvva\n",
    "# plant: vacuum\n",
    "# sample_rate_hz: 0\n",
    "# kp: nan\n",
    "NaN",
    "inf",
    "-inf",
    "1e400",
    "5e-324",
    "-0",
    "1e308",
    "999999999999999999999999999999999999999999",
    "t_s",
    "t_s,",
    "x_pct,",
    "lift_mm,",
    ",,,,",
    "\0",
    "é",
    "[s]",
    "%",
    "0,5",
    "\u{fffd}",
];

#[derive(Clone, Debug)]
enum Mutation {
    /// XOR one byte.
    Flip(usize, u8),
    /// Remove `len` bytes.
    Delete(usize, usize),
    /// Insert a token.
    Token(usize, usize),
    /// Insert raw bytes.
    Bytes(usize, Vec<u8>),
    /// Repeat the line at a position (a duplicate header is a duplicate column set).
    DupLine(usize),
    /// Cut the file at a position (a log cut off mid-line).
    Cut(usize),
    /// Repeat one cell of the header line (a duplicate column name).
    DupColumn(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(p, x)| Mutation::Flip(p, x)),
        (any::<usize>(), 1usize..40).prop_map(|(p, n)| Mutation::Delete(p, n)),
        (any::<usize>(), 0..TOKENS.len()).prop_map(|(p, k)| Mutation::Token(p, k)),
        (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8)).prop_map(|(p, b)| Mutation::Bytes(p, b)),
        any::<usize>().prop_map(Mutation::DupLine),
        any::<usize>().prop_map(Mutation::Cut),
        any::<usize>().prop_map(Mutation::DupColumn),
    ]
}

fn apply(mut b: Vec<u8>, m: &Mutation) -> Vec<u8> {
    let at = |p: usize, len: usize| if len == 0 { 0 } else { p % (len + 1) };
    match m {
        Mutation::Flip(p, x) if !b.is_empty() => {
            let i = p % b.len();
            b[i] ^= x;
        }
        Mutation::Flip(..) => {}
        Mutation::Delete(p, n) => {
            let i = at(*p, b.len());
            let j = (i + n).min(b.len());
            b.drain(i..j);
        }
        Mutation::Token(p, k) => {
            let i = at(*p, b.len());
            b.splice(i..i, TOKENS[*k].bytes());
        }
        Mutation::Bytes(p, bytes) => {
            let i = at(*p, b.len());
            b.splice(i..i, bytes.iter().copied());
        }
        Mutation::DupLine(p) => {
            let i = at(*p, b.len());
            let start = b[..i].iter().rposition(|&c| c == b'\n').map_or(0, |k| k + 1);
            let end = b[i..].iter().position(|&c| c == b'\n').map_or(b.len(), |k| i + k + 1);
            let line = b[start..end].to_vec();
            b.splice(end..end, line);
        }
        Mutation::Cut(p) => {
            let i = at(*p, b.len());
            b.truncate(i);
        }
        Mutation::DupColumn(p) => {
            // The header: the first line not starting with `#`.
            let mut start = 0;
            while start < b.len() && b[start] == b'#' {
                start = b[start..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .map_or(b.len(), |k| start + k + 1);
            }
            let end = b[start..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |k| start + k);
            let header = String::from_utf8_lossy(&b[start..end]).to_string();
            let cells: Vec<&str> = header.split([',', ';', '\t']).collect();
            let cell = cells[p % cells.len()].trim_end_matches('\r');
            let sep = if header.contains(';') {
                ';'
            } else if header.contains('\t') {
                '\t'
            } else {
                ','
            };
            let insert = format!("{sep}{cell}");
            let at_end = end - usize::from(header.ends_with('\r'));
            b.splice(at_end..at_end, insert.bytes());
        }
    }
    b
}

fn mutated() -> impl Strategy<Value = Vec<u8>> {
    let seeds = seeds();
    (0..seeds.len(), proptest::collection::vec(mutation(), 1..4))
        .prop_map(move |(k, ms)| ms.iter().fold(seeds[k].clone(), apply))
}

/// Tables through the shared entry point (the MF4 reader's): a positioner table whose cells
/// are mostly plausible and sometimes any f64 (NaN, infinities, subnormals, huge), a time base
/// that is uniform or not, columns of other lengths, extra and duplicate names, metadata from
/// a small set of good and bad values.
/// Metadata, columns and `--plant` for `log_from_columns`.
type Table = (Vec<(String, String)>, Vec<(String, Vec<f64>)>, Option<Plant>);

fn tables() -> impl Strategy<Value = Table> {
    const N: usize = 8;
    let cell = |lo: f64, hi: f64| prop_oneof![60 => lo..hi, 1 => any::<f64>(), 1 => Just(0.0)];
    let column = move |lo: f64, hi: f64| {
        prop_oneof![
            8 => proptest::collection::vec(cell(lo, hi), N..=N),
            1 => proptest::collection::vec(cell(lo, hi), 0..N + 2),
        ]
    };
    let time = prop_oneof![
        6 => (-1.0..1.0f64, -8.0..5.0f64).prop_map(|(t0, e)| (0..N).map(|i| t0 + 10f64.powf(e) * i as f64).collect::<Vec<_>>()),
        1 => proptest::collection::vec(any::<f64>(), 0..N + 2),
        1 => proptest::collection::vec(0.0..1.0f64, N..=N),
    ];
    let extra = proptest::collection::vec(
        (
            prop_oneof![Just("pos_m".to_string()), Just("x_pct".to_string()), "[a-z_]{0,6}"],
            column(-1.0, 1.0),
        ),
        0..3,
    );
    let meta = proptest::collection::vec(
        (
            prop_oneof![
                Just("plant"),
                Just("sample_rate_hz"),
                Just("kp"),
                Just("seed"),
                Just("note")
            ],
            prop_oneof![
                Just("positioner"),
                Just("vacuum"),
                Just("1000"),
                Just("nan"),
                Just("-1"),
                Just("")
            ],
        )
            .prop_map(|(k, v)| (k.to_string(), v.to_string())),
        0..2,
    );
    let plant = proptest::option::weighted(0.8, Just(Plant::Positioner));
    (meta, time, column(-1e6, 1e6), column(-10.0, 10.0), extra, plant).prop_map(|(mut meta, t, f, x, extra, plant)| {
        if plant.is_none() {
            meta.insert(0, ("plant".into(), "positioner".into()));
        }
        let mut cols = vec![
            ("t_s".to_string(), t),
            ("force_N".to_string(), f),
            ("pos_m".to_string(), x),
        ];
        cols.extend(extra);
        (meta, cols, plant)
    })
}

fn all_targets(n: u32) {
    fuzz(
        "reader/bytes",
        proptest::collection::vec(any::<u8>(), 0..2048),
        n,
        |b| read_bytes(b),
    );
    fuzz("reader/mutations", mutated(), n, |b| read_bytes(b));
    fuzz(
        "reader/tables",
        tables(),
        n,
        |(meta, cols, plant)| match log_from_columns("fuzz.mf4", meta.clone(), cols.clone(), *plant) {
            Ok(log) => assert_valid(&log).map(|()| true),
            Err(_) => Ok(false),
        },
    );
}

#[test]
fn reader_fuzz_short() {
    all_targets(cases(3000));
}

#[test]
#[ignore = "long run (>= 10^6 inputs per target), figures in docs/reliability.md"]
fn reader_fuzz_long() {
    all_targets(cases(1_000_000));
}

/// Every file in tests/regressions/ once failed (or is a defect's input from issue #16): each
/// starts with `# expect: <text>` and must give an error containing that text.
#[test]
fn regression_files_give_their_errors() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/regressions");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "csv") {
            continue;
        }
        let bytes = std::fs::read(&path).unwrap();
        let first = bytes.split(|&b| b == b'\n').next().unwrap();
        let expect = String::from_utf8_lossy(first)
            .trim_start_matches("# expect:")
            .trim()
            .to_string();
        let e = match read_log(&path, None) {
            Ok(_) => panic!("{} was accepted", path.display()),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(&expect), "{}: {e}\n  expected: {expect}", path.display());
        n += 1;
    }
    assert!(n >= 5, "{n} regression files");
}
