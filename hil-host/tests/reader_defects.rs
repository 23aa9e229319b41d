//! One test per reader defect of issue #16: each failed (or hung) before the reader was
//! rewritten and passes now. The inputs that once failed a fuzz run are in
//! `tests/regressions/` and `fuzz_reader.rs`.

use std::io::BufReader;

use hil_host::log::check::MAX_COLUMNS;
use hil_host::log::{log_from_columns, parse_log, read_csv, read_log, LogError, Plant};

const HEAD: &str = "# plant: positioner\nt_s,force_N,pos_m\n";

fn error(text: &str) -> LogError {
    match parse_log("bad.csv", text, None) {
        Ok(l) => panic!("accepted: {} samples at {} s", l.len(), l.dt_s),
        Err(e) => e,
    }
}

/// Was: a 100 000-column header took 41 s (a quadratic duplicate check) before failing on
/// something else. Now: refused by its width at once; a header at the limit reads in
/// linear time, and a duplicate far out is still found.
#[test]
fn a_header_of_100000_columns_is_refused_by_its_width() {
    let names: Vec<String> = (0..100_000).map(|i| format!("c{i}")).collect();
    let text = format!(
        "# plant: positioner\nt_s,force_N,pos_m,{}\n0,0,0{}\n",
        names.join(","),
        ",0".repeat(100_000)
    );
    let e = error(&text);
    assert_eq!(e.line, Some(2), "{e}");
    assert!(e.message.contains(&format!("at most {MAX_COLUMNS}")), "{e}");

    let wide = &names[..MAX_COLUMNS - 3];
    let row = |t: f64| format!("{t},1,0{}\n", ",7".repeat(wide.len()));
    let text = format!(
        "# plant: positioner\nt_s,force_N,pos_m,{}\n{}{}",
        wide.join(","),
        row(0.0),
        row(0.001)
    );
    let log = parse_log("wide.csv", &text, None).unwrap();
    assert_eq!(log.order, ["t_s", "force_N", "pos_m"]);
    assert!(
        log.notices
            .iter()
            .any(|n| n.contains(&format!("and {} more", wide.len() - 8))),
        "{:?}",
        log.notices
    );

    let mut dup = wide.to_vec();
    dup[MAX_COLUMNS - 4] = "c17".into();
    let text = format!(
        "# plant: positioner\nt_s,force_N,pos_m,{}\n{}{}",
        dup.join(","),
        row(0.0),
        row(0.001)
    );
    let e = error(&text);
    assert_eq!((e.line, e.column.as_deref()), (Some(2), Some("c17")), "{e}");
    assert!(e.message.contains(&format!("#21 and #{}", MAX_COLUMNS)), "{e}");
}

/// Was: "2 samples at inf s".
#[test]
fn a_time_column_spanning_the_doubles_is_refused() {
    let e = error(&format!("{HEAD}-1.7e308,0,0\n1.7e308,0,0\n"));
    assert_eq!((e.line, e.column.as_deref()), (Some(3), Some("t_s")), "{e}");
    assert!(e.message.contains("range"), "{e}");
}

/// Was: accepted; diagnose then failed with "cut-off inf Hz ..." or "DelayLineTooShort", naming
/// no file.
#[test]
fn a_subnormal_or_implausible_sample_period_is_refused_naming_the_file() {
    let e = error(&format!("{HEAD}0,0,0\n5e-324,0,0\n1e-323,0,0\n"));
    assert_eq!((e.file.as_str(), e.column.as_deref()), ("bad.csv", Some("t_s")), "{e}");
    assert!(e.message.contains("sample period"), "{e}");
    assert!(e.to_string().starts_with("bad.csv:4, column t_s:"), "{e}");
    // One sample a day: not a bench log either.
    let e = error(&format!("{HEAD}0,0,0\n86400,0,0\n172800,0,0\n"));
    assert!(e.message.contains("sample period"), "{e}");
    // The limits themselves are fine.
    assert!(parse_log("ok.csv", &format!("{HEAD}0,0,0\n1e-7,0,0\n2e-7,0,0\n"), None).is_ok());
}

/// Was: `# sample_rate_hz:` 0, -100 or nan accepted silently.
#[test]
fn sample_rate_metadata_must_be_a_positive_number() {
    for bad in ["0", "-100", "nan", "inf", "1e300", "fast", ""] {
        let e = error(&format!(
            "# plant: positioner\n# sample_rate_hz: {bad}\nt_s,force_N,pos_m\n0,0,0\n0.001,0,0\n"
        ));
        assert_eq!(e.line, Some(2), "{bad}: {e}");
        assert!(e.message.contains("sample_rate_hz"), "{e}");
    }
    let log = parse_log(
        "ok.csv",
        &format!("# sample_rate_hz: 500\n{HEAD}0,0,0\n0.001,0,0\n"),
        None,
    )
    .unwrap();
    assert!(log.notices.iter().any(|n| n.contains("disagrees")), "{:?}", log.notices);
}

/// Was: two different `# plant:` lines accepted, the first winning. Any typed key that
/// contradicts itself is an error naming both lines; a repeat with the same value is a notice.
#[test]
fn conflicting_metadata_is_an_error() {
    let e = error(&format!("# plant: ehvva\n{HEAD}0,0,0\n0.001,0,0\n"));
    assert_eq!(e.line, Some(2), "{e}");
    assert!(
        e.message.contains("contradicts") && e.message.contains("(line 1)"),
        "{e}"
    );
    let e = error(&format!("# kp: 3\n# kp: 3.5\n{HEAD}0,0,0\n0.001,0,0\n"));
    assert_eq!(e.line, Some(2), "{e}");
    let ok = parse_log("ok.csv", &format!("# kp: 3\n# kp: 3.0\n{HEAD}0,0,0\n0.001,0,0\n"), None).unwrap();
    assert!(
        ok.notices.iter().any(|n| n.contains("`kp` given again")),
        "{:?}",
        ok.notices
    );
    // Typed values are checked whether or not a tool will use them.
    for (key, bad) in [
        ("gtau", "x"),
        ("control_period_s", "-1"),
        ("cam_events_per_cycle", "2.5"),
        ("seed", "-3"),
    ] {
        let e = error(&format!("# {key}: {bad}\n{HEAD}0,0,0\n0.001,0,0\n"));
        assert_eq!(e.line, Some(1), "{key}: {e}");
        assert!(e.message.contains(key), "{e}");
    }
}

/// Was: "stream did not contain valid UTF-8" with no line. A byte UTF-8 does not allow makes
/// the file Windows-1252 (a bench export's code page), where 0xFF is `ÿ`: not a number, named
/// by line and column; a control byte is binary data in either encoding, named by line.
#[test]
fn invalid_utf8_names_the_line_and_column() {
    let mut bytes = format!("{HEAD}0,0,0\n0.001,0,0\n").into_bytes();
    let at = bytes.len() - 2;
    bytes[at] = 0xFF;
    let e = read_csv("bin.csv", &bytes[..], None).unwrap_err();
    assert_eq!((e.line, e.column.as_deref()), (Some(4), Some("pos_m")), "{e}");
    assert!(e.message.contains("`ÿ` is not a number"), "{e}");
    bytes[at - 1] = 0x01;
    let e = read_csv("bin.csv", &bytes[..], None).unwrap_err();
    assert_eq!(e.line, Some(4), "{e}");
    assert!(e.message.contains("not text: byte 0x01 at byte 8"), "{e}");
    let e = read_csv("u16.csv", &[0xFF, 0xFE, b't', 0][..], None).unwrap_err();
    assert!(e.message.contains("UTF-16"), "{e}");
}

/// Was: a time gap reported as "between rows 3 and 4" (data rows); the file's lines are what
/// an editor shows.
#[test]
fn time_gaps_name_the_files_lines() {
    let text = "# plant: positioner\n# source: x\n\nt_s,force_N,pos_m\n0,0,0\n\n0.001,0,0\n0.002,0,0\n0.0045,0,0\n0.0055,0,0\n".to_string();
    let e = error(&text);
    assert_eq!((e.line, e.column.as_deref()), (Some(9), Some("t_s")), "{e}");
    assert!(e.message.contains("between lines 8 and 9"), "{e}");
    let e = error(&text.replace("0.0045", "0.0015"));
    assert_eq!(e.line, Some(9), "{e}");
    assert!(e.message.contains("does not increase"), "{e}");
}

/// Was: `check /dev/zero` read until memory ran out. The reader now stops at the first line
/// longer than its bound, and at a header that never comes.
#[test]
fn endless_input_ends_in_an_error() {
    let e = read_csv("/dev/zero", BufReader::new(std::io::repeat(0)), None).unwrap_err();
    assert_eq!(e.line, Some(1), "{e}");
    assert!(e.message.contains("longer than"), "{e}");
    let e = read_csv("blank", BufReader::new(std::io::repeat(b'\n')), None).unwrap_err();
    assert_eq!(e.line, Some(10_001), "{e}");
    let e = read_csv("hashes", BufReader::new(std::io::repeat(b'#')), None).unwrap_err();
    assert!(e.message.contains("longer than"), "{e}");
    let comments = "# c\n".repeat(20_000);
    let e = read_csv("comments", comments.as_bytes(), None).unwrap_err();
    assert_eq!(e.line, Some(10_001), "{e}");
    if std::path::Path::new("/dev/zero").exists() {
        let e = read_log(std::path::Path::new("/dev/zero"), Some(Plant::Vacuum)).unwrap_err();
        assert!(e.to_string().starts_with("/dev/zero:1: line longer than"), "{e}");
    }
}

/// Was: `diagnose` failed with "the regressors are linearly dependent", naming no file and no
/// column. The reader now says which columns never move.
#[test]
fn constant_columns_are_named_in_a_notice() {
    let log = parse_log("still.csv", &format!("{HEAD}0,5,0.1\n0.001,5,0.2\n0.002,5,0.3\n"), None).unwrap();
    assert!(
        log.notices
            .iter()
            .any(|n| n.contains("`force_N`") && n.contains("constant")),
        "{:?}",
        log.notices
    );
}

/// The one entry point other readers (MF4) share: the same checks, errors naming the source,
/// the column and the sample.
#[test]
fn in_memory_tables_get_the_same_checks() {
    let cols = |t: Vec<f64>, pos: Vec<f64>| {
        vec![
            ("t_s".to_string(), t),
            ("force_N".to_string(), vec![1.0; 3]),
            ("pos_m".to_string(), pos),
        ]
    };
    let meta = vec![("plant".to_string(), "positioner".to_string())];
    let log = log_from_columns(
        "a.mf4",
        meta.clone(),
        cols(vec![0.0, 0.01, 0.02], vec![0.0, 0.1, 0.2]),
        None,
    )
    .unwrap();
    assert_eq!((log.len(), log.plant), (3, Plant::Positioner));
    let e = log_from_columns(
        "a.mf4",
        meta.clone(),
        cols(vec![0.0, 0.01, 0.02], vec![0.0, f64::NAN, 0.2]),
        None,
    )
    .unwrap_err();
    assert_eq!(
        (e.file.as_str(), e.line, e.column.as_deref()),
        ("a.mf4", None, Some("pos_m"))
    );
    assert!(e.message.starts_with("sample 1 (0-based)"), "{e}");
    let e = log_from_columns("a.mf4", meta.clone(), cols(vec![0.0, 0.01, 0.02], vec![0.0, 0.1]), None).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("pos_m"), "{e}");
    let mut dup = cols(vec![0.0, 0.01, 0.02], vec![0.0, 0.1, 0.2]);
    dup.push(("pos_m".into(), vec![0.0; 3]));
    let e = log_from_columns("a.mf4", meta.clone(), dup, None).unwrap_err();
    assert!(e.message.contains("twice"), "{e}");
    let mut conflict = meta;
    conflict.push(("plant".into(), "vacuum".into()));
    let e = log_from_columns("a.mf4", conflict, cols(vec![0.0, 0.01, 0.02], vec![0.0; 3]), None).unwrap_err();
    assert!(e.message.contains("contradicts"), "{e}");
}

/// Was: "the regressors are linearly dependent", naming no file. A fit that cannot be computed
/// now names the log and the inputs that never moved.
#[test]
fn a_fit_that_cannot_be_computed_names_the_file_and_the_still_inputs() {
    use hil_host::diagnose::{diagnose, family_for, Rules};
    let rows: String = (0..400).map(|k| format!("{},0,0\n", k as f64 * 0.001)).collect();
    let log = parse_log("still-bench.csv", &format!("{HEAD}{rows}"), None).unwrap();
    let (est, val) = log.split_tail(0.3);
    let family = family_for(Plant::Positioner).unwrap();
    let e = diagnose(family.as_ref(), &est, &val, true, &Rules::default(), &mut |_| {}).unwrap_err();
    assert!(e.starts_with("still-bench.csv (first 70 %)"), "{e}");
    assert!(e.contains("force_N"), "{e}");
}
