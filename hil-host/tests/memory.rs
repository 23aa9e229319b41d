//! Issue #16's memory goal: the diagnosis of a long log pair holds at most 100 B a row of the
//! pair at its peak (a 10 M-row log must not need gigabytes). Measured on the command as a user
//! runs it: `HIL_HOST_PEAK_RSS` makes `hil-host` print its peak resident set (Linux VmHWM)
//! before and after the command; the difference over the pair's rows is the diagnosis's cost
//! (the program's own few MB before it reads anything are not the log's). Each family on a
//! ~400 000-row pair of `generate --repeat`, the size the goal was stated for. Measured this
//! way in session 6: EHVVA 83, vacuum 87, positioner 58, EVVT 89 B a row; before session 5's
//! work the whole process peaked at EHVVA 108, vacuum 128, positioner 119 and EVVT 411 B a row
//! (the program's 4 MB included), which the EVVT, vacuum and positioner cases fail.
use std::path::{Path, PathBuf};

use assert_cmd::Command;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hil-memory-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Data rows of a CSV log (not comments, not the header).
fn rows(p: &Path) -> usize {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    text.lines().filter(|l| !l.starts_with('#')).count() - 1
}

fn kb_after(stderr: &str, what: &str) -> u64 {
    stderr
        .lines()
        .find_map(|l| l.strip_prefix(what))
        .and_then(|r| r.trim().strip_suffix("kB"))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no `{what}` line in:\n{stderr}"))
}

/// Generates `plant none` with `repeat` programmes, diagnoses it, returns (rows, B a row).
fn bytes_per_row(plant: &str, seed: u64, repeat: u32) -> (usize, f64) {
    if !cfg!(target_os = "linux") {
        eprintln!("skipped: the peak resident set is read from Linux's /proc");
        return (0, 0.0);
    }
    let dir = scratch(plant);
    Command::cargo_bin("hil-host")
        .unwrap()
        .args([
            "generate",
            plant,
            "none",
            "--seed",
            &seed.to_string(),
            "--repeat",
            &repeat.to_string(),
            "--out",
        ])
        .arg(&dir)
        .assert()
        .success();
    let (est, val) = (dir.join("estimation.csv"), dir.join("validation.csv"));
    let n = rows(&est) + rows(&val);
    let out = Command::cargo_bin("hil-host")
        .unwrap()
        .env("HIL_HOST_PEAK_RSS", "1")
        .arg("diagnose")
        .arg(&est)
        .arg("--validation")
        .arg(&val)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{plant}: diagnose failed:\n{stderr}");
    let before = kb_after(&stderr, "peak RSS before the command:");
    let peak = kb_after(&stderr, "peak RSS:");
    let per_row = (peak.saturating_sub(before) * 1024) as f64 / n as f64;
    eprintln!("{plant}: {n} rows, peak {peak} kB ({before} kB before the command): {per_row:.1} B a row");
    let _ = std::fs::remove_dir_all(&dir);
    (n, per_row)
}

fn assert_within_goal(plant: &str, seed: u64, repeat: u32) {
    let (n, per_row) = bytes_per_row(plant, seed, repeat);
    if n > 0 {
        assert!(n > 350_000, "{plant}: the pair has {n} rows, not a long log");
        assert!(
            per_row <= 100.0,
            "{plant}: the diagnosis peaks at {per_row:.1} B a row of {n} rows (goal <= 100)"
        );
    }
}

#[test]
fn ehvva_diagnosis_within_100_bytes_a_row() {
    assert_within_goal("ehvva", 11, 18);
}

#[test]
fn evvt_diagnosis_within_100_bytes_a_row() {
    assert_within_goal("evvt", 3, 13);
}

#[test]
fn vacuum_diagnosis_within_100_bytes_a_row() {
    assert_within_goal("vacuum", 3, 30);
}

#[test]
fn positioner_diagnosis_within_100_bytes_a_row() {
    assert_within_goal("positioner", 3, 10);
}
