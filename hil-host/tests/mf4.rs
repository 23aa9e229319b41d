//! MF4 logs (issue #15.1): files written by asammdf (the Python library most logger tools export
//! with, `tools/py/write_mf4.py`) read into the same log as the CSV they were made from, and
//! diagnose the same: compressed (deflate, transposed deflate), with logger channel names and a
//! channel map, metadata from the header comment or the map, and channels in a second channel
//! group at another rate.
//!
//! The files are written by the Python venv `target/py-venv` (tools/test.sh sets it up from
//! tools/py/requirements.txt). Without it the tests skip with a message, unless HIL_REQUIRE_PY
//! is set (test.sh sets it), when they fail.
use std::path::{Path, PathBuf};
use std::process::Command;

use hil_host::diagnose::{self, report, Rules};
use hil_host::generate;
use hil_host::log::{read_log, read_log_mapped, Log, Plant};
use hil_host::mf4::ChannelMap;
use serde_json::Value;

mod py_venv;
use py_venv::{python, root};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hil-mf4-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A generated case's estimation log as CSV and as MF4 (`args`: write_mf4.py's options) in
/// the scratch directory `name`: (directory, CSV, MF4).
fn estimation_as_mf4(
    py: &Path,
    (plant, effect, seed): (Plant, &str, u64),
    name: &str,
    args: &[&str],
) -> (PathBuf, PathBuf, PathBuf) {
    let case = generate::generate(plant, effect, seed).unwrap();
    let dir = scratch(name);
    let csv = dir.join("estimation.csv");
    std::fs::write(&csv, &case.estimation_csv).unwrap();
    let mf4 = dir.join("estimation.mf4");
    write_mf4(py, &csv, &mf4, args);
    (dir, csv, mf4)
}

/// A generated case's estimation and validation logs, each as CSV and as MF4 (written with
/// the same write_mf4.py options `args`), in the scratch directory `name`.
struct Pair {
    dir: PathBuf,
    est_csv: PathBuf,
    val_csv: PathBuf,
    est_mf4: PathBuf,
    val_mf4: PathBuf,
}

fn pair_as_mf4(py: &Path, (plant, effect, seed): (Plant, &str, u64), name: &str, args: &[&str]) -> Pair {
    let case = generate::generate(plant, effect, seed).unwrap();
    let dir = scratch(name);
    let pair = Pair {
        est_csv: dir.join("estimation.csv"),
        val_csv: dir.join("validation.csv"),
        est_mf4: dir.join("estimation.mf4"),
        val_mf4: dir.join("validation.mf4"),
        dir,
    };
    std::fs::write(&pair.est_csv, &case.estimation_csv).unwrap();
    std::fs::write(&pair.val_csv, &case.validation_csv).unwrap();
    write_mf4(py, &pair.est_csv, &pair.est_mf4, args);
    write_mf4(py, &pair.val_csv, &pair.val_mf4, args);
    pair
}

/// Writes `csv` as an MF4 file with asammdf; `args` are write_mf4.py's options.
fn write_mf4(py: &Path, csv: &Path, out: &Path, args: &[&str]) {
    let o = Command::new(py)
        .arg(root().join("tools/py/write_mf4.py"))
        .arg(csv)
        .arg(out)
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        o.status.success(),
        "write_mf4.py {args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn diagnose_json(est: &Log, val: &Log) -> Value {
    let family = diagnose::family_for(est.plant).unwrap();
    let d = diagnose::diagnose(family.as_ref(), est, val, false, &Rules::default(), &mut |_| {}).unwrap();
    report::to_json(&d)
}

/// Every number of two reports within `rel` (relative), every other value equal; file names
/// may differ.
fn assert_same_report(a: &Value, b: &Value, path: &str, rel: f64) {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!(
                (x - y).abs() <= rel * x.abs().max(y.abs()) + 1e-300,
                "{path}: CSV {x} vs MF4 {y}"
            );
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(x.keys().collect::<Vec<_>>(), y.keys().collect::<Vec<_>>(), "{path}");
            for (k, v) in x {
                if k != "file" {
                    assert_same_report(v, &y[k], &format!("{path}.{k}"), rel);
                }
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}");
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                assert_same_report(u, v, &format!("{path}[{i}]"), rel);
            }
        }
        _ => assert_eq!(a, b, "{path}"),
    }
}

fn assert_same_columns(csv: &Log, mf4: &Log) {
    assert_eq!(csv.plant, mf4.plant);
    for (name, v) in &csv.columns {
        let w = mf4.col(name).unwrap_or_else(|| panic!("MF4 log lacks `{name}`"));
        assert_eq!(v.len(), w.len(), "{name}");
        if let Some(k) = (0..v.len()).find(|&k| v[k].to_bits() != w[k].to_bits()) {
            panic!("`{name}` differs at sample {k}: CSV {} vs MF4 {}", v[k], w[k]);
        }
    }
    assert_eq!(csv.dt_s, mf4.dt_s);
}

/// A generated positioner case (hidden Coulomb friction) as a logger would record it:
/// transposed-deflate compressed, the position under the logger's name `Axis1.Pos_m` (renamed
/// by a channel map), the metadata as header-comment properties with `gtau` left out (the map
/// supplies it), and the reference `ref_m` in a second channel group at twice the rate. It must
/// read to the CSV's columns bit for bit and diagnose the same, to 1e-9.
#[test]
fn compressed_mapped_two_rate_mf4_diagnoses_like_its_csv() {
    let Some(py) = python() else { return };
    let logger = [
        "--compression",
        "2",
        "--rename",
        "pos_m=Axis1.Pos_m",
        "--meta-as",
        "properties",
        "--drop-meta",
        "gtau",
        "--group2",
        "ref_m",
        "--group2-factor",
        "2",
    ];
    let Pair {
        dir,
        est_csv,
        val_csv,
        est_mf4,
        val_mf4,
    } = pair_as_mf4(
        &py,
        (Plant::Positioner, "coulomb-friction", 2024),
        "positioner",
        &logger,
    );
    let csv_est = read_log(&est_csv, None).unwrap();
    let gtau = csv_est.meta("gtau").expect("the generator writes gtau").to_string();
    let map_path = dir.join("map.toml");
    std::fs::write(
        &map_path,
        format!("[channels]\n\"Axis1.Pos_m\" = \"pos_m\"\n\n[meta]\ngtau = {gtau}\n"),
    )
    .unwrap();
    let map = ChannelMap::read(&map_path).unwrap();
    // Compressed: the samples are in DZ (zipped data) blocks.
    let bytes = std::fs::read(&est_mf4).unwrap();
    assert!(bytes.windows(4).any(|w| w == b"##DZ"), "no DZ block in the file");

    // Without the map, the logger's name is not found, and the error says which and where.
    let e = read_log(&est_mf4, None).unwrap_err();
    assert_eq!(e.file, est_mf4.display().to_string());
    assert_eq!(e.column.as_deref(), Some("pos_m"));
    assert!(
        e.message.contains("Axis1.Pos_m") && e.message.contains("--channel-map"),
        "{e}"
    );

    let mf4_est = read_log_mapped(&est_mf4, None, Some(&map)).unwrap();
    let mf4_val = read_log_mapped(&val_mf4, None, Some(&map)).unwrap();
    let csv_val = read_log(&val_csv, None).unwrap();
    assert_same_columns(&csv_est, &mf4_est);
    assert_same_columns(&csv_val, &mf4_val);
    assert_eq!(mf4_est.meta("gtau"), Some(gtau.as_str()));
    assert_eq!(mf4_est.meta("kp"), csv_est.meta("kp"));
    let note = mf4_est
        .notices
        .iter()
        .find(|n| n.contains("`ref_m`"))
        .expect("a notice on the resampled reference");
    assert!(
        note.contains("linear interpolation") && note.contains("2000 Hz"),
        "{note}"
    );

    let a = diagnose_json(&csv_est, &csv_val);
    let b = diagnose_json(&mf4_est, &mf4_val);
    assert_eq!(a["cause"], "coulomb-friction");
    assert_same_report(&a, &b, "report", 1e-9);
}

/// An EVVT closed-loop case in a plain-deflate MF4 file with the metadata (`plant`, `kp`, ...)
/// as `key: value` lines of the header comment, the channels under their DATA-FORMAT names:
/// `diagnose` reads it with no map and names the same cause with the same numbers.
#[test]
fn deflate_mf4_with_header_comment_metadata_diagnoses_like_its_csv() {
    let Some(py) = python() else { return };
    let Pair {
        est_csv,
        val_csv,
        est_mf4,
        val_mf4,
        ..
    } = pair_as_mf4(
        &py,
        (Plant::Evvt, "supply-voltage", 11),
        "evvt",
        &["--compression", "1"],
    );
    let (csv_est, csv_val) = (read_log(&est_csv, None).unwrap(), read_log(&val_csv, None).unwrap());
    let (mf4_est, mf4_val) = (read_log(&est_mf4, None).unwrap(), read_log(&val_mf4, None).unwrap());
    assert_same_columns(&csv_est, &mf4_est);
    assert_eq!(mf4_est.meta, csv_est.meta, "header comment metadata");
    let a = diagnose_json(&csv_est, &csv_val);
    let b = diagnose_json(&mf4_est, &mf4_val);
    assert_eq!(a["cause"], "supply-voltage");
    assert_same_report(&a, &b, "report", 1e-9);
}

/// A slower channel group (every 4th sample) holding two flags and the supply pressure of an
/// EHVVA log: the flags are held (zero-order hold) and the pressure interpolated linearly onto
/// the lift's 20 kHz time base, the fast group's channels are untouched, and a notice says how.
#[test]
fn slower_channel_group_is_held_for_flags_and_interpolated_for_signals() {
    let Some(py) = python() else { return };
    let (dir, csv, mf4) = estimation_as_mf4(
        &py,
        (Plant::Ehvva, "none", 77_001),
        "ehvva",
        &[
            "--compression",
            "2",
            "--flags",
            "u_pilot,lift_high,snubber_on",
            "--group2",
            "lift_high,snubber_on,p_supply_MPa",
            "--group2-factor",
            "-4",
        ],
    );
    let c = read_log(&csv, None).unwrap();
    let m = read_log(&mf4, None).unwrap();
    let n = c.len();
    assert_eq!(m.len(), n);
    for name in ["t_s", "u_pilot", "p_back_MPa", "temp_C", "lift_mm"] {
        assert_eq!(c.col(name), m.col(name), "{name} is in the primary group: read as is");
    }
    let last = 4 * ((n - 1) / 4); // the slow group's last instant
    for name in ["lift_high", "snubber_on"] {
        let (cv, mv) = (c.col(name).unwrap(), m.col(name).unwrap());
        for k in 0..n {
            assert_eq!(mv[k], cv[4 * (k / 4)], "{name} held at sample {k}");
        }
    }
    let (t, cv, mv) = (
        c.col("t_s").unwrap(),
        c.col("p_supply_MPa").unwrap(),
        m.col("p_supply_MPa").unwrap(),
    );
    let mut moved = 0;
    for k in 0..n {
        let expect = if k >= last {
            cv[last]
        } else {
            let (a, b) = (4 * (k / 4), 4 * (k / 4) + 4);
            cv[a] + (t[k] - t[a]) / (t[b] - t[a]) * (cv[b] - cv[a])
        };
        assert!(
            (mv[k] - expect).abs() <= 1e-12 * expect.abs().max(1.0),
            "p_supply_MPa at {k}"
        );
        moved += usize::from(mv[k] != cv[k]);
    }
    assert!(
        moved > 0,
        "the supply pressure changes between conditions, so resampling shows"
    );
    let note = |col: &str| {
        m.notices
            .iter()
            .find(|s| s.contains(&format!("`{col}`")))
            .cloned()
            .unwrap_or_default()
    };
    assert!(note("lift_high").contains("zero-order hold") && note("lift_high").contains("5000 Hz"));
    assert!(note("p_supply_MPa").contains("linear interpolation"));
    assert!(note("p_supply_MPa").contains("outside its recorded span") == (last < n - 1));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Errors name the file and the channel: a value out of its column's range (with the sample
/// and its time), a file that is not MF4, and a bad channel map (file, line).
#[test]
fn errors_name_the_file_and_the_channel() {
    let Some(py) = python() else { return };
    let dir = scratch("errors");
    let csv = dir.join("bad.csv");
    let mut text = String::from("# plant: positioner\nt_s,force_N,pos_m\n");
    for k in 0..50 {
        let pos = if k == 37 { 12.5 } else { 0.001 * k as f64 };
        text.push_str(&format!("{},{},{}\n", k as f64 * 0.001, k as f64, pos));
    }
    std::fs::write(&csv, text).unwrap();
    let mf4 = dir.join("bad.mf4");
    write_mf4(&py, &csv, &mf4, &["--rename", "pos_m=Axis1.Pos_m"]);
    let map = ChannelMap::parse("map.toml", "[channels]\n\"Axis1.Pos_m\" = \"pos_m\"\n").unwrap();
    let e = read_log_mapped(&mf4, None, Some(&map)).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("pos_m"));
    assert!(e.message.contains("channel `Axis1.Pos_m`"), "{e}");
    assert!(
        e.message.contains("sample 37 (0-based, t = 0.037 s)") && e.message.contains("range"),
        "{e}"
    );
    assert!(e.to_string().starts_with(&mf4.display().to_string()), "{e}");

    let not_mf4 = dir.join("notes.mf4");
    std::fs::write(&not_mf4, b"\x00\xffthis is no measurement file").unwrap();
    let e = read_log(&not_mf4, Some(Plant::Positioner)).unwrap_err();
    assert!(e.message.contains("not a readable MF4 file"), "{e}");

    // A logger's file without the .mf4 name is still recognised by its signature.
    let renamed = dir.join("bench.dat");
    std::fs::copy(&mf4, &renamed).unwrap();
    let e = read_log_mapped(&renamed, None, Some(&map)).unwrap_err();
    assert!(e.message.contains("sample 37"), "{e}");
}

/// ETK/XCP measurement tools (INCA, CANape) name each signal after the device that measured it,
/// `Name\Device`: such channels are read by the name before the backslash, with a notice, and
/// give the CSV's columns bit for bit.
#[test]
fn device_suffixed_channel_names_are_read_by_their_signal_name() {
    let Some(py) = python() else { return };
    let (dir, csv, mf4) = estimation_as_mf4(
        &py,
        (Plant::Positioner, "none", 7),
        "device-suffix",
        &["--rename", "pos_m=pos_m\\ETKC:1", "--rename", "force_N=force_N\\XCP:2"],
    );
    let log = read_log(&mf4, None).unwrap();
    assert_same_columns(&read_log(&csv, None).unwrap(), &log);
    let notice = log
        .notices
        .iter()
        .find(|n| n.contains("device"))
        .unwrap_or_else(|| panic!("{:?}", log.notices));
    assert!(
        notice.contains("`pos_m\\ETKC:1` as `pos_m`") && notice.contains("`force_N\\XCP:2` as `force_N`"),
        "{notice}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A logger marks samples invalid (its invalidation bits: a sensor's dropout, a bus timeout);
/// they hold no measurement and are filled from the channel's valid samples at their times
/// (linear; flags held), with a notice; a channel with no valid sample is refused by name.
/// The file is written with falcon_mdf's own writer, which sets the bits (asammdf 8 does not
/// write them from a `Signal`); it has no header comment, so the plant is given.
#[test]
fn samples_a_logger_marked_invalid_are_filled_from_the_valid_ones() {
    use falcon_mdf::Mf4Writer;
    let case = generate::generate(Plant::Ehvva, "none", 3).unwrap();
    let dir = scratch("invalid");
    let csv_path = dir.join("estimation.csv");
    std::fs::write(&csv_path, &case.estimation_csv).unwrap();
    let csv = read_log(&csv_path, None).unwrap();
    let write = |path: &Path, invalid_in: &str, gap: std::ops::Range<usize>| {
        let mut w = Mf4Writer::with_start_time_ns(0);
        let g = w.add_group(csv.col("t_s").unwrap()).unwrap();
        for (name, values) in csv.columns.iter().filter(|(n, _)| n.as_str() != "t_s") {
            let mut values = values.clone();
            let valid: Vec<bool> = (0..values.len())
                .map(|i| !(name == invalid_in && gap.contains(&i)))
                .collect();
            for (v, ok) in values.iter_mut().zip(&valid) {
                if !ok {
                    *v = 0.0; // what a logger stores for a sample it has no value for
                }
            }
            g.add_channel_with_validity(name, "", &values, Some(&valid)).unwrap();
        }
        w.write_to_file(path).unwrap();
    };
    let (supply, lift_high) = (csv.col("p_supply_MPa").unwrap(), csv.col("lift_high").unwrap());
    let path = dir.join("supply-dropout.mf4");
    write(&path, "p_supply_MPa", 100..140);
    let log = read_log(&path, Some(Plant::Ehvva)).unwrap();
    for (name, values) in &csv.columns {
        let read = log.col(name).unwrap();
        if name == "p_supply_MPa" {
            // Between the valid neighbours, within the set-point's sensor noise.
            let (lo, hi) = (supply[99].min(supply[140]), supply[99].max(supply[140]));
            for i in 100..140 {
                assert!(read[i] >= lo && read[i] <= hi, "sample {i}: {}", read[i]);
                assert!(
                    (read[i] - supply[i]).abs() < 0.05,
                    "sample {i}: {} vs {}",
                    read[i],
                    supply[i]
                );
            }
            assert_eq!(&read[..100], &values[..100]);
            assert_eq!(&read[140..], &values[140..]);
        } else {
            assert_eq!(read, &values[..], "{name}");
        }
    }
    assert!(
        log.notices
            .iter()
            .any(|n| n.contains("`p_supply_MPa` (channel `p_supply_MPa`): 40 of") && n.contains("interpolated")),
        "{:?}",
        log.notices
    );
    // A flag's invalid samples (stored as 0) are held from the last valid one, a 1.
    let from = 1 + lift_high.iter().position(|v| *v == 1.0).expect("a high-lift event");
    let path = dir.join("flag-dropout.mf4");
    write(&path, "lift_high", from..from + 45);
    let log = read_log(&path, Some(Plant::Ehvva)).unwrap();
    assert!(log.col("lift_high").unwrap()[from..from + 45].iter().all(|v| *v == 1.0));
    // No valid sample at all.
    let path = dir.join("dead.mf4");
    write(&path, "temp_C", 0..csv.len());
    let e = read_log(&path, Some(Plant::Ehvva)).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("temp_C"), "{e}");
    assert!(e.message.contains("every sample is marked invalid"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A logger records a digital state with a value-to-text conversion (`OFF`/`ON`): a flag's
/// texts that are flag words read as 1/0, other texts by the raw values they name; both give
/// the CSV's columns, each said in a notice. A text channel under a signal's column is refused
/// by name.
#[test]
fn flags_recorded_as_text_read_as_their_0_1_states() {
    let Some(py) = python() else { return };
    let (dir, csv, mf4) = estimation_as_mf4(
        &py,
        (Plant::Ehvva, "none", 3),
        "text-flags",
        &["--text", "u_pilot=OFF,ON", "--text", "snubber_on=closed,open"],
    );
    let log = read_log(&mf4, None).unwrap();
    assert_same_columns(&read_log(&csv, None).unwrap(), &log);
    assert!(log.col("u_pilot").unwrap().contains(&1.0), "the pilot never on");
    let said = |what: &str| log.notices.iter().any(|n| n.contains(what));
    assert!(
        said("`u_pilot` (channel `u_pilot`) recorded as words"),
        "{:?}",
        log.notices
    );
    assert!(
        said("`snubber_on` (channel `snubber_on`) recorded as text (`")
            && said("is no flag's word): its raw values read"),
        "{:?}",
        log.notices
    );
    let bad = dir.join("bad.mf4");
    write_mf4(&py, &csv, &bad, &["--text", "p_back_MPa=low,high"]);
    let e = read_log(&bad, None).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("p_back_MPa"), "{e}");
    assert!(e.message.contains("holds text"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A logger records each channel in its own unit (the CN block's unit): a channel the map
/// renames is converted from it to the column's unit, with a notice; a channel under the
/// column's own name whose unit says otherwise, or a unit of another quantity, is refused by
/// name.
#[test]
fn a_loggers_units_are_converted_to_the_columns_units() {
    let Some(py) = python() else { return };
    let renames = [
        "--rename",
        "p_supply_MPa=P_Rail",
        "--rename",
        "lift_mm=Hub",
        "--rename",
        "temp_C=T_Oel",
    ];
    let units = [
        "--unit",
        // In brackets, as some loggers write a unit.
        "p_supply_MPa=[bar],10",
        "--unit",
        "lift_mm=m,0.001",
        "--unit",
        "temp_C=K,1,273.15",
    ];
    let args: Vec<&str> = renames.iter().chain(&units).copied().collect();
    let (dir, csv, mf4) = estimation_as_mf4(&py, (Plant::Ehvva, "none", 3), "units", &args);
    let map = ChannelMap::parse(
        "logger.toml",
        "[channels]\n\"P_Rail\" = \"p_supply_MPa\"\n\"Hub\" = \"lift_mm\"\n\"T_Oel\" = \"temp_C\"\n",
    )
    .unwrap();
    let want = read_log(&csv, None).unwrap();
    let log = read_log_mapped(&mf4, None, Some(&map)).unwrap();
    assert_eq!(want.order, log.order);
    for name in &want.order {
        let (a, b) = (want.col(name).unwrap(), log.col(name).unwrap());
        assert_eq!(a.len(), b.len(), "{name}");
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            // Stored times a factor in f64 and converted back: within rounding.
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{name}[{k}]: {x} vs {y}");
        }
    }
    let notice = log
        .notices
        .iter()
        .find(|n| n.starts_with("units converted"))
        .unwrap_or_else(|| panic!("{:?}", log.notices));
    assert!(
        notice.contains("`p_supply_MPa` from bar (÷ 10)")
            && notice.contains("`lift_mm` from m (× 1000)")
            && notice.contains("`temp_C` from K (− 273.15)"),
        "{notice}"
    );

    // The same lift in m under the column's own name: the name says mm, the channel m.
    let own = dir.join("own-name.mf4");
    write_mf4(&py, &csv, &own, &["--unit", "lift_mm=m,0.001"]);
    let e = read_log(&own, None).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("lift_mm"), "{e}");
    assert!(
        e.message.contains("channel `lift_mm`") && e.message.contains("unit `m`") && e.message.contains("`mm`"),
        "{e}"
    );
    // The channel map states what the logger got wrong: its `[units]` win over the file's.
    let stated = ChannelMap::parse("stated.toml", "[units]\nlift_mm = \"m\"\n").unwrap();
    let log = read_log_mapped(&own, None, Some(&stated)).unwrap();
    for (x, y) in want.col("lift_mm").unwrap().iter().zip(log.col("lift_mm").unwrap()) {
        assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}");
    }
    // A unit of another quantity on a renamed channel.
    let volts = dir.join("volts.mf4");
    write_mf4(&py, &csv, &volts, &["--rename", "lift_mm=Hub", "--unit", "lift_mm=V,1"]);
    let e = read_log_mapped(&volts, None, Some(&map)).unwrap_err();
    assert_eq!(e.column.as_deref(), Some("lift_mm"), "{e}");
    assert!(
        e.message.contains("channel `Hub` (mapped to `lift_mm`)")
            && e.message.contains("`V` is not a unit of `lift_mm`"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A logger's event-driven raster: the time stamps of a positioner's closed-loop log jitter
/// by up to ±15 % of the 1 ms period, each channel read at its jittered instant. The reader
/// puts every column onto a uniform grid (the logger's mean rate, from its first time stamp),
/// says so, and the diagnosis names the cause the CSV names, with the same verdict.
#[test]
fn a_jittered_loggers_time_base_is_resampled_onto_a_uniform_grid() {
    let Some(py) = python() else { return };
    let Pair {
        dir,
        est_csv,
        val_csv,
        est_mf4,
        val_mf4,
    } = pair_as_mf4(
        &py,
        (Plant::Positioner, "coulomb-friction", 4),
        "jitter",
        &["--jitter", "0.3"],
    );
    let (csv_est, csv_val) = (read_log(&est_csv, None).unwrap(), read_log(&val_csv, None).unwrap());
    let (mf4_est, mf4_val) = (read_log(&est_mf4, None).unwrap(), read_log(&val_mf4, None).unwrap());
    let notice = mf4_est
        .notices
        .iter()
        .find(|n| n.contains("not uniformly sampled"))
        .unwrap_or_else(|| panic!("{:?}", mf4_est.notices));
    assert!(notice.contains("uniform 1000 Hz grid"), "{notice}");
    // The grid is the CSV's time base, and the position (smooth) comes back within a small
    // fraction of its range: the jitter moved each sample by up to 0.15 ms.
    assert_eq!(mf4_est.len(), csv_est.len());
    assert!((mf4_est.dt_s - csv_est.dt_s).abs() < 1e-12 * csv_est.dt_s);
    let (a, b) = (csv_est.col("pos_m").unwrap(), mf4_est.col("pos_m").unwrap());
    let range = a.iter().cloned().fold(f64::MIN, f64::max) - a.iter().cloned().fold(f64::MAX, f64::min);
    let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-3 * range, "worst {worst} of a range {range}");
    let from_csv = diagnose_json(&csv_est, &csv_val);
    let from_mf4 = diagnose_json(&mf4_est, &mf4_val);
    assert_eq!(from_csv["cause"], "coulomb-friction");
    assert_eq!(from_mf4["cause"], from_csv["cause"]);
    assert_eq!(from_mf4["verdict"], from_csv["verdict"]);
    let _ = std::fs::remove_dir_all(&dir);
}
