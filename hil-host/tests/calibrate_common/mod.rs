//! What the calibration tests share: a scratch directory, a generated case written as
//! `hil-host generate` writes it, the calibration-sweep scenario.
use std::path::{Path, PathBuf};

use hil_host::generate::Case;
use hil_host::run::Scenario;

/// A fresh scratch directory for one test (this process's own).
pub fn workdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hil-calibrate-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes a generated case as `hil-host generate` does: the two logs and truth.json.
pub fn write_case(case: &Case, dir: &Path) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let est = dir.join("estimation.csv");
    std::fs::write(&est, &case.estimation_csv).unwrap();
    std::fs::write(dir.join("validation.csv"), &case.validation_csv).unwrap();
    let params: serde_json::Map<String, serde_json::Value> = case
        .truth
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::json!(v)))
        .collect();
    let truth =
        serde_json::json!({"plant": case.plant.name(), "effect": case.effect, "seed": case.seed, "params": params});
    let truth_path = dir.join("truth.json");
    std::fs::write(&truth_path, serde_json::to_string_pretty(&truth).unwrap()).unwrap();
    (est, truth_path)
}

/// `scenarios/calibration-sweep.toml`, the gain scenario of docs/calibration.md.
pub fn sweep() -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/calibration-sweep.toml");
    Scenario::from_toml(&path, &std::fs::read_to_string(&path).unwrap()).unwrap()
}
