//! Fuzzing the scenario reader (`Scenario::from_toml`) on stable Rust: arbitrary text and
//! structured mutations of the shipped scenarios (lines dropped or repeated, values replaced
//! by huge, negative, NaN or mistyped ones, names that are paths, extra `[[fault]]` tables).
//! It must never panic, answer each input within [`fuzz_common::HANG_LIMIT`], name the file in every
//! error, and whatever it accepts must be runnable: a name that is no path, a duration and
//! profiles within their ranges.
//!
//! Long run: `FUZZ_CASES=1000000 cargo test -p hil-host --test fuzz_scenario -- --ignored --nocapture`.

mod fuzz_common;

use fuzz_common::{cases, fuzz};

use std::path::Path;

use hil_host::run::{check_name, Scenario, MAX_DURATION_S, MIN_DURATION_S};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

fn read(text: &str) -> Result<bool, TestCaseError> {
    match Scenario::from_toml(Path::new("fz.toml"), text) {
        Err(e) => {
            prop_assert!(e.starts_with("fz.toml:"), "error without the file: {}", e);
            Ok(false)
        }
        Ok(s) => {
            prop_assert!(check_name(&s.name).is_ok(), "accepted name {:?}", s.name);
            prop_assert!(!s.name.contains(['/', '\\']) && !s.name.starts_with('.'));
            prop_assert!((MIN_DURATION_S..=MAX_DURATION_S).contains(&s.duration_s));
            for k in 0..=20 {
                let t = s.duration_s * f64::from(k) / 20.0;
                let u = s.u_batt_at(t);
                prop_assert!(u.is_finite() && (0.0..=32.0).contains(&u), "u_batt {} at {}", u, t);
                let n = s.engine_rpm.at(t);
                prop_assert!((0.0..=12_000.0).contains(&n), "engine {} at {}", n, t);
                prop_assert!(s.p_supply_mpa.at(t) > s.p_back_mpa.at(t));
            }
            Ok(true)
        }
    }
}

fn seeds() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut seeds: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "toml").then(|| std::fs::read_to_string(p).ok())?
        })
        .collect();
    seeds.sort();
    assert!(seeds.len() >= 8);
    seeds
}

/// Values and lines that break scenarios in interesting ways.
const VALUES: [&str; 20] = [
    "nan",
    "inf",
    "-inf",
    "-1e6",
    "1e6",
    "1e308",
    "0",
    "-0.0",
    "1e-9",
    "5e-324",
    "\"x\"",
    "[]",
    "[[]]",
    "[[0.0, 1.0], [0.0, 2.0]]",
    "[[1e308, 1.0]]",
    "[[-1.0, 5.0]]",
    "true",
    "{}",
    "\"../../../x\"",
    "[[nan, 1.0]]",
];
const LINES: [&str; 12] = [
    "name = \"../../../x\"",
    "name = \"\"",
    "name = \"a/b\"",
    "duration_s = 1e-9",
    "duration_s = 1e6",
    "[[fault]]",
    "kind = \"battery_sag\"",
    "u_batt_v = 1e6",
    "engine_rpm = [[0.0, -5.0]]",
    "u_batt_v = [[0.0, 1e6]]",
    "start_s = 1e9",
    "p_back_mpa = [[0.0, 30.0]]",
];

#[derive(Clone, Debug)]
enum Mutation {
    DropLine(usize),
    DupLine(usize),
    /// Replace the value after `=` on a line.
    Value(usize, usize),
    InsertLine(usize, usize),
    Flip(usize, u8),
    Cut(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::DropLine),
        any::<usize>().prop_map(Mutation::DupLine),
        (any::<usize>(), 0..VALUES.len()).prop_map(|(l, v)| Mutation::Value(l, v)),
        (any::<usize>(), 0..LINES.len()).prop_map(|(l, k)| Mutation::InsertLine(l, k)),
        (any::<usize>(), 1u8..=255).prop_map(|(p, x)| Mutation::Flip(p, x)),
        any::<usize>().prop_map(Mutation::Cut),
    ]
}

fn apply(text: String, m: &Mutation) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let n = lines.len().max(1);
    match m {
        Mutation::DropLine(l) if !lines.is_empty() => {
            lines.remove(l % n);
        }
        Mutation::DupLine(l) if !lines.is_empty() => {
            let line = lines[l % n].clone();
            lines.insert(l % n, line);
        }
        Mutation::Value(l, v) if !lines.is_empty() => {
            let line = &mut lines[l % n];
            if let Some((key, _)) = line.split_once('=') {
                *line = format!("{key}= {}", VALUES[*v]);
            }
        }
        Mutation::InsertLine(l, k) => lines.insert(l % (lines.len() + 1), LINES[*k].to_string()),
        Mutation::Flip(p, x) => {
            let mut b = text.into_bytes();
            if !b.is_empty() {
                let i = p % b.len();
                b[i] ^= x;
            }
            return String::from_utf8_lossy(&b).into_owned();
        }
        Mutation::Cut(p) => {
            let mut i = p % (text.len() + 1);
            while !text.is_char_boundary(i) {
                i -= 1;
            }
            return text[..i].to_string();
        }
        _ => {}
    }
    lines.join("\n") + "\n"
}

fn mutated() -> impl Strategy<Value = String> {
    let seeds = seeds();
    (0..seeds.len(), proptest::collection::vec(mutation(), 1..4))
        .prop_map(move |(k, ms)| ms.iter().fold(seeds[k].clone(), apply))
}

fn all_targets(n: u32) {
    fuzz("scenario/text", ".{0,400}", n, |s: &String| read(s));
    fuzz(
        "scenario/bytes",
        proptest::collection::vec(any::<u8>(), 0..400).prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        n,
        |s| read(s),
    );
    fuzz("scenario/mutations", mutated(), n, |s| read(s));
}

#[test]
fn scenario_fuzz_short() {
    all_targets(cases(2000));
}

#[test]
#[ignore = "long run (>= 10^6 inputs per target), figures in docs/reliability.md"]
fn scenario_fuzz_long() {
    all_targets(cases(1_000_000));
}

/// The scenario inputs of issue #16, kept as regressions.
#[test]
fn scenario_regressions() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/regressions");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let expect = text.lines().next().unwrap().trim_start_matches("# expect:").trim();
        let e = Scenario::from_toml(&path, &text).unwrap_err();
        assert!(e.contains(expect), "{}: {e}\n  expected: {expect}", path.display());
        n += 1;
    }
    assert!(n >= 3, "{n} regression files");
}
