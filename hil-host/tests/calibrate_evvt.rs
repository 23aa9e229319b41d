//! `hil-host calibrate` and `run --unit` on EVVT units: a unit's phaser from its truth, its
//! table from a one-file bench recording, and the image's loop next to the paper defaults'.
use hil_host::calibrate;
use hil_host::generate;
use hil_host::log::Plant;
use hil_host::run::run_unit;
use model_core::ecu::lockstep::EcuCoreConfig;

mod calibrate_common;
use calibrate_common::{sweep, workdir, write_case};

/// `run --unit` on a generated EVVT unit: its plant is the one the generator drew (α, β at the
/// nominal point as in the truth), and a unit whose advance is slower (the `direction` effect)
/// tracks the sweep's advance step worse than the same unit made symmetric. A unit with a
/// command delay (outside the catalogue; `run`'s plant has none) is refused by name.
#[test]
fn an_evvt_unit_runs_from_its_truth_and_its_slow_advance_shows() {
    use model_core::evvt::EvvtPlant;
    let dir = workdir("evvt-unit");
    let case = generate::generate(Plant::Evvt, "direction", 4).unwrap();
    let (_, truth) = write_case(&case, &dir.join("unit"));
    let get = |k: &str| case.truth.iter().find(|(n, _)| n == k).unwrap().1;
    let unit = calibrate::unit_from_truth(&truth).unwrap();
    assert_eq!(unit.evvt.advance_alpha_factor, get("advance_alpha_factor"));
    let (a, b) = EvvtPlant::<f64>::new(&unit.evvt)
        .unwrap()
        .alpha_beta(get("nominal_engine_rpm"), get("nominal_voltage_V"));
    assert!(
        (a / get("alpha_at_nominal_deg_per_s2_rpm") - 1.0).abs() < 1e-12,
        "alpha {a}"
    );
    assert!((b / get("beta_at_nominal_per_s") - 1.0).abs() < 1e-12, "beta {b}");

    let slow = run_unit(&sweep(), None, EcuCoreConfig::default(), unit).unwrap();
    let mut symmetric = unit;
    symmetric.evvt.advance_alpha_factor = 1.0;
    let sym = run_unit(&sweep(), None, EcuCoreConfig::default(), symmetric).unwrap();
    assert!(
        slow.evvt_rms_error_deg.is_finite() && slow.evvt_rms_error_deg > 1.02 * sym.evvt_rms_error_deg,
        "slow advance {} vs symmetric {}",
        slow.evvt_rms_error_deg,
        sym.evvt_rms_error_deg
    );

    let delayed = generate::generate(Plant::Evvt, "command-delay", 4).unwrap();
    let (_, truth) = write_case(&delayed, &dir.join("delayed"));
    let e = calibrate::unit_from_truth(&truth).unwrap_err();
    assert!(e.contains("command_delay_s") && e.contains("truth.json"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `calibrate` on an EVVT bench recording over nine jittered operating points (one log, the
/// test points 806-856 rpm apart by more than the 50 rpm grouping): the segments are
/// identified and grouped into the 3×3 table, whose α and β are the unit's (an LTI unit: every
/// cell the truth's α and β at the nominal point).
#[test]
fn an_evvt_recording_calibrates_the_units_table() {
    let dir = workdir("evvt-recording");
    let case = generate::generate(Plant::Evvt, "none", 9).unwrap();
    let (est, _) = write_case(&case, &dir.join("unit"));
    let get = |k: &str| case.truth.iter().find(|(n, _)| n == k).unwrap().1;
    let outcome = calibrate::calibrate(std::slice::from_ref(&est), &mut |_| {}).unwrap();
    let t = outcome.calibration.evvt_lpv;
    // The notes say which speeds and voltages the tables cover (the ECU holds the edges).
    let range = format!(
        "cover {:.0}-{:.0} rpm and {:.1}-{:.1} V",
        t.engine_speed_rpm[0], t.engine_speed_rpm[2], t.battery_voltage_v[0], t.battery_voltage_v[2]
    );
    assert!(
        outcome
            .notes
            .iter()
            .any(|n| n.contains(&range) && n.contains("no extrapolation")),
        "{:?}",
        outcome.notes
    );
    for i in 0..3 {
        for j in 0..3 {
            let (a, b) = (t.alpha_deg_per_s2_rpm[i][j], t.beta_per_s[i][j]);
            assert!(
                (a / get("alpha_at_nominal_deg_per_s2_rpm") - 1.0).abs() < 0.05,
                "alpha {a} in {t:?}"
            );
            assert!(
                (b / get("beta_at_nominal_per_s") - 1.0).abs() < 0.10,
                "beta {b} in {t:?}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The EVVT image's loop on a unit faster and on one slower than the paper's, next to the
/// paper defaults. On a unit whose α is 1.27x the paper's (none seed 2) the paper's kp runs
/// the loop above the designed 2 rad/s: the image keeps that speed (its crossover the largest
/// the paper's kp gives over the identified table) and tracks the sweep's phase steps at
/// least as well as the defaults. On one at 0.79x (seed 3) the paper's kp runs it slower: the
/// image restores the designed 2 rad/s and tracks better. On a unit whose β falls with engine
/// speed (engine-speed seed 2) the phase-margin floor would hold the image's loop below the
/// defaults' at high speed: the floor is lowered to the least margin the defaults run it at.
/// The notes say which, checked against the crossover of the paper's kp on the unit's true
/// α/β at its nominal point, |kp·α / (jω(jω + β))| = 1.
#[test]
fn the_evvt_image_never_runs_the_units_loop_slower_than_the_paper_defaults() {
    use model_core::control::evvt_phase::EvvtPhaseController;
    use model_core::ecu::calibration::EcuCalibration;
    let paper = EvvtPhaseController::<f64>::new(&EcuCalibration::paper_defaults().evvt_controller()).unwrap();
    for (effect, seed) in [("none", 2), ("none", 3), ("engine-speed", 2)] {
        let dir = workdir(&format!("evvt-loop-{effect}-{seed}"));
        let case = generate::generate(Plant::Evvt, effect, seed).unwrap();
        let (est, truth) = write_case(&case, &dir.join("unit"));
        let get = |k: &str| case.truth.iter().find(|(n, _)| n == k).unwrap().1;
        let (a, b) = (get("alpha_at_nominal_deg_per_s2_rpm"), get("beta_at_nominal_per_s"));
        let kp = paper.gains_at(get("nominal_engine_rpm"), get("nominal_voltage_V")).0;
        let k = kp * a;
        let wc = (0.5 * ((b.powi(4) + 4.0 * k * k).sqrt() - b * b)).sqrt();
        // The premise, from the truth alone: α well above or well below the design's.
        let scale = get("alpha_scale_of_design");
        assert!(!(0.9..=1.1).contains(&scale), "{effect} seed {seed}: α × {scale}");
        let faster = scale > 1.0;
        let outcome = calibrate::calibrate(std::slice::from_ref(&est), &mut |_| {}).unwrap();
        let note = outcome
            .notes
            .iter()
            .find(|n| n.contains("the paper defaults would run it at"))
            .unwrap_or_else(|| panic!("{:?}", outcome.notes));
        // The true nominal point's crossover lies within the reported range (±5 %).
        let range = note.split("would run it at ").nth(1).unwrap();
        let (lo, hi) = range.split(" rad/s").next().unwrap().split_once('-').unwrap();
        let (lo, hi): (f64, f64) = (lo.parse().unwrap(), hi.parse().unwrap());
        assert!(wc > 0.95 * lo && wc < 1.05 * hi, "seed {seed}: {wc} against {lo}-{hi}");
        let crossover = outcome.calibration.evvt_crossover_rad_s;
        if faster {
            assert!((crossover - hi).abs() < 0.006, "seed {seed}: {crossover} rad/s, {note}");
            assert!(
                note.contains("faster than the designed 2.0 rad/s") && note.contains("keeps that speed"),
                "{note}"
            );
        } else {
            assert_eq!(crossover, 2.0, "seed {seed}: {note}");
            assert!(note.contains("at a crossover of 2.00-2.00 rad/s"), "{note}");
            assert!(note.contains("slower than designed"), "seed {seed}: {note}");
        }
        // The margin floor: the design's 55 deg unless the defaults run the unit below it.
        let margins = note
            .split("(phase margin ")
            .nth(1)
            .unwrap()
            .split(" deg")
            .next()
            .unwrap();
        let least: f64 = margins.split_once('-').unwrap().0.parse().unwrap();
        let floor = outcome.calibration.evvt_min_phase_margin_deg;
        if effect == "engine-speed" {
            assert!(
                least < 50.0,
                "the premise: the defaults run this unit below the floor, {note}"
            );
            assert!(
                (floor - least).abs() <= 0.5 && floor >= 45.0,
                "floor {floor} deg, {note}"
            );
            assert!(note.contains("phase-margin floor lowered from 55"), "{note}");
        } else {
            assert_eq!(floor, 55.0, "{note}");
        }
        // The tracking on the calibration sweep, the unit simulated as drawn.
        let unit = calibrate::unit_from_truth(&truth).unwrap();
        let before = run_unit(&sweep(), None, EcuCoreConfig::default(), unit).unwrap();
        let after = run_unit(&sweep(), None, outcome.calibration.config(), unit).unwrap();
        assert!(
            before.fault_events.is_empty() && after.fault_events.is_empty(),
            "{:?} {:?}",
            before.fault_events,
            after.fault_events
        );
        let (b_deg, a_deg) = (before.evvt_rms_error_deg, after.evvt_rms_error_deg);
        assert!(
            a_deg.is_finite() && a_deg <= b_deg,
            "{effect} seed {seed}: {a_deg} deg with the image, {b_deg} deg with the defaults"
        );
        if !faster {
            assert!(a_deg < 0.95 * b_deg, "seed {seed}: {a_deg} deg against {b_deg} deg");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// The EVVT gain over many units (ignored; `CAL_SWEEP_SEEDS=n`, default 12): for each EVVT
/// class, units of seeds 1..=n calibrated from their one-file recording alone, each run on
/// `calibration-sweep.toml` with the paper defaults and with its own image. Prints one row
/// per class for docs/calibration.md: how many units track better with their own image, the
/// median change of the RMS phase error and the worst unit's change, with its seed and the
/// margins the defaults run it at (the note's). Fails on a run that raises a fault.
#[test]
#[ignore = "a sweep of 60 units (about 1 min); run with --ignored --nocapture for the docs' table"]
fn evvt_calibration_gain_sweep() {
    let n: u64 = std::env::var("CAL_SWEEP_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(12);
    println!("| class | units better | median change | worst unit |");
    println!("|---|---|---|---|");
    for effect in ["none", "supply-voltage", "direction", "engine-speed", "belt-vibration"] {
        let mut changes: Vec<(f64, u64, String)> = Vec::new();
        for seed in 1..=n {
            let dir = workdir(&format!("evvt-gain-{effect}-{seed}"));
            let case = generate::generate(Plant::Evvt, effect, seed).unwrap();
            let (est, truth) = write_case(&case, &dir.join("unit"));
            let outcome = calibrate::calibrate(std::slice::from_ref(&est), &mut |_| {}).unwrap();
            let unit = calibrate::unit_from_truth(&truth).unwrap();
            let before = run_unit(&sweep(), None, EcuCoreConfig::default(), unit).unwrap();
            let after = run_unit(&sweep(), None, outcome.calibration.config(), unit).unwrap();
            assert!(
                before.fault_events.is_empty() && after.fault_events.is_empty(),
                "{effect} seed {seed}: {:?} {:?}",
                before.fault_events,
                after.fault_events
            );
            let change = 100.0 * (after.evvt_rms_error_deg / before.evvt_rms_error_deg - 1.0);
            let margins = outcome
                .notes
                .iter()
                .find_map(|n| n.split("(phase margin ").nth(1))
                .and_then(|r| r.split(')').next())
                .unwrap_or("?")
                .to_string();
            changes.push((change, seed, margins));
            let _ = std::fs::remove_dir_all(&dir);
        }
        let better = changes.iter().filter(|c| c.0 < 0.0).count();
        let mut sorted: Vec<f64> = changes.iter().map(|c| c.0).collect();
        sorted.sort_by(f64::total_cmp);
        let worst = changes.iter().max_by(|a, b| a.0.total_cmp(&b.0)).unwrap();
        println!(
            "| {effect} | {better}/{n} | {:+.0} % | {:+.1} % (seed {}; the defaults' phase margin {}) |",
            sorted[sorted.len() / 2],
            worst.0,
            worst.1,
            worst.2
        );
    }
}
