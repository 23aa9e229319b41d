//! `diagnose` on real measured data: the EMPS benchmark (closed loop, estimation and validation
//! experiments) in ../shared/data/emps (or `$SHARED_DIR/data/emps`, for a worktree that sits
//! elsewhere). Skips with a message where neither is present.
use std::path::PathBuf;
use std::process::Command;

fn emps(file: &str) -> Option<PathBuf> {
    let shared = std::env::var_os("SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let p = shared.join("data/emps").join(file);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIP: {} not found (../shared is absent in a fresh clone)", p.display());
        None
    }
}

#[test]
fn names_coulomb_friction_with_the_published_parameters() {
    let (Some(est), Some(val)) = (emps("emps-estimation.csv"), emps("emps-validation.csv")) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("emps-diag-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("report.json");
    let out = Command::new(env!("CARGO_BIN_EXE_hil-host"))
        .args([
            "diagnose",
            est.to_str().unwrap(),
            "--validation",
            val.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
            "--plots",
        ])
        .arg(dir.join("plots"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}\n{}",
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(r["plant"], "positioner");
    assert_eq!(r["cause"], "coulomb-friction", "{stdout}");
    assert!(r["formulation"].as_str().unwrap().contains("equation-error"));
    assert_eq!(r["validation"]["samples"], 24841);
    // Published IDIM-LS reference: M 95.1 kg, Fv 203.5 N s/m, Fc 20.4 N, offset -3.2 N.
    let p = &r["extended"]["params"];
    let near = |k: &str, want: f64, tol: f64| {
        let got = p[k].as_f64().unwrap();
        assert!((got - want).abs() <= tol, "{k} = {got}, published {want} ± {tol}");
    };
    near("M_kg", 95.1, 2.0);
    near("Fv_Ns_per_m", 203.5, 6.0);
    near("Fc_N", 20.4, 1.0);
    near("offset_N", -3.2, 0.5);
    // The gain on the validation experiment is reported and large: friction is the missing physics.
    let gain = r["gain_pct"].as_f64().unwrap();
    let (rb, re) = (
        r["baseline"]["rmse"].as_f64().unwrap(),
        r["extended"]["rmse"].as_f64().unwrap(),
    );
    // The JSON carries 6 significant digits.
    assert!(
        (gain - 100.0 * (rb - re) / rb).abs() < 1e-3,
        "gain {gain}, RMSE {rb} -> {re}"
    );
    assert!(gain > 50.0, "gain {gain}");
    assert_eq!(r["residual_tests"]["whiteness_pass"], false);
    // Grouped by the direction of motion, the baseline residual force has a different mean
    // each way: the Coulomb friction it lacks (the missing +Fc·sign(v) shows as a positive
    // residual force moving forwards, a negative one backwards).
    let by_sign = r["residual_tests"]["grouped_by_condition"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["condition"] == "velocity sign")
        .unwrap();
    assert_eq!(by_sign["pass"], false, "{by_sign}");
    // (The sign is decimated with the other regressors, so it is grouped in thirds.)
    let mean = |third: &str| {
        by_sign["groups"]
            .as_array()
            .unwrap()
            .iter()
            .find(|g| g["group"].as_str().unwrap().starts_with(third))
            .unwrap()["mean"]
            .as_f64()
            .unwrap()
    };
    assert!(mean("high") > 2.0 && mean("low") < -2.0, "{by_sign}");
    assert_eq!(r["residual_tests"]["grouped_by_condition_pass"], false);
    for f in [
        "fit.svg",
        "residuals.svg",
        "autocorrelation.svg",
        "cross_correlation.svg",
    ] {
        assert!(dir.join("plots").join(f).exists(), "{f} missing");
    }
    // The cross-correlation plot shows the 99 % band (a shaded band) and the velocity sign.
    let svg = std::fs::read_to_string(dir.join("plots/cross_correlation.svg")).unwrap();
    assert_eq!(svg.matches("class=\"band\"").count(), 1);
    assert!(
        svg.contains("velocity sign"),
        "the most correlated regressors should include the velocity sign"
    );
    // Not a terminal: one plain progress line per fit, no carriage returns.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(
            "fitting baseline (1/3) ...\nfitting coulomb-friction (2/3) ...\nfitting asymmetric-friction (3/3) ...\n"
        ),
        "{stderr}"
    );
    assert!(!stderr.contains('\r'));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn without_validation_the_tail_is_held_out() {
    let Some(est) = emps("emps-estimation.csv") else { return };
    let out = Command::new(env!("CARGO_BIN_EXE_hil-host"))
        .args(["diagnose", est.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(stdout.contains("last 30 %, held out"), "{stdout}");
    assert!(stdout.contains("cause: coulomb-friction"), "{stdout}");
}

#[test]
fn a_bad_log_is_an_error_naming_file_line_and_column() {
    let dir = std::env::temp_dir().join(format!("emps-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "# plant: positioner\nt_s,force_N,pos_m\n0,1,0\n0.001,x,0\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hil-host"))
        .args(["diagnose", bad.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr.contains("bad.csv:4, column force_N: `x` is not a number"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
