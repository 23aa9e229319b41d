//! The outside check: the twelve logs of other units in `../shared/data/units/` (an independent
//! generator, README there), each diagnosed and set against its `truth.json`. Not a CI test and
//! never a tuning target (acceptance is judged on other units drawn the same way): it prints the
//! table that docs/diagnosis.md records.
//! `cargo test -p hil-host --test units_check -- --ignored --nocapture` (`SHARED_DIR=/path/to/shared`
//! when ../shared is not beside the repository).
use std::path::Path;

use hil_host::diagnose::{self, Rules};
use hil_host::log::read_log;

#[test]
#[ignore]
fn other_units_table() {
    // ../shared beside the repository, or $SHARED_DIR (a worktree elsewhere).
    let shared = std::env::var_os("SHARED_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let root = shared.join("data/units");
    let Ok(dirs) = std::fs::read_dir(&root) else {
        eprintln!("no {} here: nothing to check", root.display());
        return;
    };
    let mut dirs: Vec<_> = dirs
        .filter_map(|d| d.ok().map(|d| d.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    println!("| unit | truth | causes | verdict | baseline RMSE | extended RMSE | floor | gain % |");
    println!("|---|---|---|---|---|---|---|---|");
    for dir in dirs {
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap_or_default())
                .unwrap_or_default();
        let truth_effect = truth["effect"].as_str().unwrap_or("?").to_string();
        let est = read_log(&dir.join("estimation.csv"), None);
        let val = read_log(&dir.join("validation.csv"), None);
        let name = dir
            .file_name()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        let (est, val) = match (est, val) {
            (Ok(e), Ok(v)) => (e, v),
            (Err(e), _) | (_, Err(e)) => {
                println!("| {name} | {truth_effect} | error: {e} | | | | | |");
                continue;
            }
        };
        let plant = est.plant;
        let family = diagnose::family_for(plant).expect("family");
        match diagnose::diagnose(family.as_ref(), &est, &val, false, &Rules::default(), &mut |_| {}) {
            Ok(d) => {
                let j = diagnose::report::to_json(&d);
                let causes = j["causes"]
                    .as_array()
                    .map(|a| a.iter().filter_map(|c| c.as_str()).collect::<Vec<_>>().join("+"))
                    .unwrap_or_else(|| d.cause.clone());
                println!(
                    "| {name} | {truth_effect} | {} | {} | {:.4} | {:.4} | {} | {:.1} |",
                    if causes.is_empty() { "none" } else { &causes },
                    j["verdict"].as_str().unwrap_or("-"),
                    d.baseline.rmse,
                    d.extended.rmse,
                    j["noise_floor"]["rmse"]
                        .as_f64()
                        .map_or("-".into(), |f| format!("{f:.4}")),
                    d.gain_pct
                );
                eprintln!("{}", diagnose::report::summary(&d));
            }
            Err(e) => println!("| {name} | {truth_effect} | error: {e} | | | | | |"),
        }
    }
}
