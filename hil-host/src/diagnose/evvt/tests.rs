//! Tests of the EVVT family: the closed-loop simulation against the generator, the fits, the
//! selection on pairs it used to miss, the command-delay and gear-backlash probes, open-loop
//! windows.
use super::*;
use crate::diagnose::tests::probe_value;
use crate::generate::evvt as gen;
use model_core::evvt::quantize_phase_deg;

fn logs(effect: &str, seed: u64) -> (Log, Log, Vec<(String, f64)>) {
    let case = gen::generate(effect, seed).unwrap();
    let (est, val) = case.logs().expect("generated logs read back");
    (est, val, case.truth)
}

fn truth(t: &[(String, f64)], key: &str) -> f64 {
    t.iter().find(|(k, _)| k == key).map(|(_, v)| *v).unwrap()
}

#[test]
fn resolution_is_detected() {
    assert_eq!(detect_resolution(&[1.0, 3.0, 2.0, 5.0]), 1.0);
    assert_eq!(detect_resolution(&[0.5, 1.0, 2.5]), 0.5);
    assert_eq!(detect_resolution(&[0.5, 1.0, 2.7]), 0.0);
}

/// The closed-loop simulation with the generator's true LTI parameters (and a true
/// direction factor) reproduces the bench log sample for sample: same quantizer, same
/// controller, same ZOH, same stops.
#[test]
fn closed_loop_simulation_reproduces_the_generator_with_the_truth() {
    for effect in ["none", "direction"] {
        let (est, _, t) = logs(effect, 21);
        let d = Data::from_log(&est, 2.0, 0.0).unwrap();
        assert!(matches!(d.drive, Drive::ClosedLoop { hold: 1, .. }) && d.lsb == 1.0);
        let mut m = Model::lti(
            truth(&t, "alpha_at_nominal_deg_per_s2_rpm"),
            truth(&t, "beta_at_nominal_per_s"),
        );
        if effect == "direction" {
            m.advance_factor = truth(&t, "advance_alpha_factor");
        }
        let mut out = vec![0.0; d.y.len()];
        simulate(&m, &d, &mut out).unwrap();
        let same = out
            .iter()
            .zip(d.y)
            .filter(|(p, y)| quantize_phase_deg(**p, 1.0) == **y)
            .count();
        assert_eq!(same, d.y.len(), "{effect}: quantized simulation differs from the log");
        // A 10 % wrong α does not.
        let wrong = Model {
            alpha: m.alpha * 1.1,
            ..m
        };
        simulate(&wrong, &d, &mut out).unwrap();
        let same = out
            .iter()
            .zip(d.y)
            .filter(|(p, y)| quantize_phase_deg(**p, 1.0) == **y)
            .count();
        assert!(same < d.y.len() * 99 / 100);
    }
}

/// The order spectrum finds a crank-locked sinusoid under noise at stitched engine speeds.
#[test]
fn baseline_recovers_lti_parameters() {
    let (est, val, t) = logs("none", 33);
    let f = EvvtFamily::default();
    let fit = f.fit(&[], None, &est, &val).unwrap();
    let (a, b) = (
        truth(&t, "alpha_at_nominal_deg_per_s2_rpm"),
        truth(&t, "beta_at_nominal_per_s"),
    );
    assert!(
        (fit.params[0].1 / a - 1.0).abs() < 0.03,
        "alpha {} vs {a}",
        fit.params[0].1
    );
    assert!(
        (fit.params[1].1 / b - 1.0).abs() < 0.05,
        "beta {} vs {b}",
        fit.params[1].1
    );
    // Validation error is about the 1-degree quantization (uniform: 0.29 rms).
    assert!(fit.rmse < 0.4, "rmse {}", fit.rmse);
}

/// The extensions find their own parameters: the advance factor and the belt's order,
/// amplitude and phase (all from the estimation log alone).
#[test]
fn extensions_recover_the_hidden_parameters() {
    let f = EvvtFamily::default();
    let (est, val, t) = logs("direction", 44);
    let fit = f.fit(&["direction"], None, &est, &val).unwrap();
    let factor = fit.params.iter().find(|(k, _)| k == "advance_alpha_factor").unwrap().1;
    let truth_factor = truth(&t, "advance_alpha_factor");
    assert!(
        (factor / truth_factor - 1.0).abs() < 0.03,
        "advance factor {factor} vs {truth_factor}"
    );
    let (est, val, t) = logs("belt-vibration", 45);
    let fit = f.fit(&["belt-vibration"], None, &est, &val).unwrap();
    let p = |k: &str| fit.params.iter().find(|(n, _)| n == k).unwrap().1;
    let order = truth(&t, "belt_order");
    assert!(
        (p("belt_order") - order).abs() < 1e-3,
        "order {} vs {order}",
        p("belt_order")
    );
    assert!((p("belt_amplitude_deg") / truth(&t, "belt_amplitude_deg") - 1.0).abs() < 0.05);
    let dphi = (p("belt_phase_rad_at_log_start") - truth(&t, "belt_phase_rad") + PI).rem_euclid(2.0 * PI) - PI;
    assert!(dphi.abs() < 0.1, "phase off by {dphi}");
    // Validation error back to the quantization level.
    assert!(fit.rmse < 0.4, "rmse {}", fit.rmse);
}

/// A command delay outside the catalogue: the baseline absorbs it into α and β near the
/// floor, the probe finds it (its value within 15 %) and turns the verdict; a unit without
/// one keeps `explained` and the probe fits next to no delay.
#[test]
fn the_command_delay_probe_finds_a_delay_and_only_a_delay() {
    let f = EvvtFamily::default();
    let rules = crate::diagnose::Rules::default();
    // 50 ms (14 % gain) and 40 ms (3.6 % gain at z 5.6: large by its value, four samples);
    // 30 ms (1.5 % at z 3.5, under `min_z`: pinned down by the estimation data, 33.8 ± 1.1 ms
    // and 14 % of their cost).
    for seed in [1000, 32676, 56433] {
        let (est, val, t) = logs("command-delay", seed);
        let d = crate::diagnose::diagnose(&f, &est, &val, false, &rules, &mut |_| {}).unwrap();
        assert!(d.causes.is_empty(), "{:?}", d.causes);
        assert_eq!(d.verdict, "unexplained", "seed {seed}");
        let delay_truth = truth(&t, "command_delay_s");
        let delay = probe_value(&d, "a transport delay of the motor command", "command_delay_s");
        assert!(
            (delay / delay_truth - 1.0).abs() < 0.15,
            "seed {seed}: {delay} vs {delay_truth}"
        );
    }
    let (est, val, _) = logs("none", 1000);
    let d = crate::diagnose::diagnose(&f, &est, &val, false, &rules, &mut |_| {}).unwrap();
    assert_eq!(d.verdict, "explained", "{:?}", d.evidence);
    let base = d.extended.clone();
    let p = f.fit_probe("command-delay", &[], &base, &est, &val).unwrap();
    let fitted = p.params.last().unwrap();
    assert_eq!(fitted.0, "command_delay_s");
    assert!(fitted.1 < 0.01, "{fitted:?}");
    assert!(f.fit_probe("thermal-stroke", &[], &base, &est, &val).is_err());
}

/// A clearance between the drive and the cam outside the catalogue: under the 1-degree phase
/// resolution the remainder without it stayed within twice the floor on 5 of 25 units
/// (`explained`); the probe measures it (within 15 %: the generator's 1.5-3 deg) and turns the
/// verdict; no catalogue effect is named for it; on a healthy unit it fits next to nothing.
#[test]
fn the_gear_backlash_probe_measures_a_clearance_and_only_a_clearance() {
    let f = EvvtFamily::default();
    let rules = crate::diagnose::Rules::default();
    // 32676 and 159380 were called `explained` without the probe (1.67x and 1.48x the floor).
    for seed in [32676, 159380] {
        let (est, val, t) = logs("gear-backlash", seed);
        let d = crate::diagnose::diagnose(&f, &est, &val, false, &rules, &mut |_| {}).unwrap();
        assert!(d.causes.is_empty(), "{:?}", d.causes);
        assert_eq!(d.verdict, "unexplained", "seed {seed}");
        let clearance = probe_value(
            &d,
            "a clearance between the phaser's drive and the camshaft",
            "backlash_deg",
        );
        let want = truth(&t, "backlash_deg");
        assert!((clearance / want - 1.0).abs() < 0.15, "{clearance} vs {want}");
    }
    let (est, val, _) = logs("none", 1000);
    let d = crate::diagnose::diagnose(&f, &est, &val, false, &rules, &mut |_| {}).unwrap();
    assert_eq!(d.verdict, "explained", "{:?}", d.evidence);
    let p = f.fit_probe("gear-backlash", &[], &d.extended, &est, &val).unwrap();
    let fitted = p.params.last().unwrap();
    assert_eq!(fitted.0, "backlash_deg");
    assert!(fitted.1 < 0.2, "{fitted:?}");
}

/// Two effects the forward selection used to miss one of: belt vibration next to a first
/// cause (the floor, lifted by the unmodelled vibration, stopped the selection after the
/// first), supply voltage with engine speed where supply voltage alone fits the
/// estimation data far better but loses on validation (no single effect eligible), and
/// the same pair where engine speed on top gains 29 % at z = 3.3 (its gain concentrated
/// away from the nominal speed) and leaves noise where supply voltage alone left structure,
/// or where it left a remainder near the floor that the pair takes (session 14).
#[test]
fn pairs_the_selection_used_to_miss_are_named() {
    let f = EvvtFamily::default();
    let rules = crate::diagnose::Rules::default();
    for (pair, seed) in [
        ("direction+belt-vibration", 8919),
        ("supply-voltage+engine-speed", 8919),
        ("supply-voltage+engine-speed", 1000),
        // Supply voltage alone left 1.37x the floor (the floor stop) and engine speed alone
        // gained 10.5 % at z = 3.5; on top, 27 % to 1.00x at z = 3.9: added as it takes the
        // variance above the floor.
        ("supply-voltage+engine-speed", 56433),
    ] {
        let (est, val, _) = logs(pair, seed);
        let d = crate::diagnose::diagnose(&f, &est, &val, false, &rules, &mut |_| {}).unwrap();
        let mut named = d.causes.clone();
        named.sort();
        let mut want: Vec<String> = pair.split('+').map(String::from).collect();
        want.sort();
        assert_eq!(named, want, "{pair} seed {seed}: {:?}", d.evidence);
        assert_eq!(d.verdict, "explained", "{pair} seed {seed}");
    }
}

#[test]
fn open_loop_windows_when_the_loop_is_not_logged() {
    let (mut est, mut val, t) = logs("none", 33);
    for l in [&mut est, &mut val] {
        l.columns.remove("phase_ref_deg");
    }
    let d = Data::from_log(&est, 2.0, 0.5).unwrap();
    assert!(matches!(d.drive, Drive::OpenLoop { window: 200 }));
    // A reference with a controller law the command does not obey is not simulated either.
    let (mut wrong, _, _) = logs("none", 33);
    for (k, v) in wrong.meta.iter_mut() {
        if k == "kp" {
            *v = "30".into();
        }
    }
    assert!(matches!(
        Data::from_log(&wrong, 2.0, 0.5).unwrap().drive,
        Drive::OpenLoop { .. }
    ));
    let fit = EvvtFamily::default().fit(&[], None, &est, &val).unwrap();
    let a = truth(&t, "alpha_at_nominal_deg_per_s2_rpm");
    assert!(
        (fit.params[0].1 / a - 1.0).abs() < 0.2,
        "alpha {} vs {a}",
        fit.params[0].1
    );
    assert!(fit.rmse < 1.0, "rmse {}", fit.rmse);
}

/// With both scheduling effects the model also fits the table's interaction: on the paper's
/// table the voltage dependence grows with engine speed (Section IV-D: α/β halves from 14 to
/// 9.5 V at high speed, at 1100 rpm α and β move together), so the fitted slope of α per
/// V·1000 rpm is positive and clear of 0, and the pair comes within 1.09x of the quantization
/// floor (0.306 deg; the sum of a voltage and a speed slope alone left 0.323 deg, 1.12x, and
/// on other units engine speed's gain on top of supply voltage stayed under z = 4, 15 of 25
/// pairs named against 19 now). The interaction belongs to the pair:
/// either effect alone has only its own slopes; it follows the second of the two to enter.
#[test]
fn the_scheduling_pair_fits_the_tables_interaction() {
    let f = EvvtFamily::default();
    let (est, val, _) = logs("supply-voltage+engine-speed", 1000);
    let names = |fit: &Fit| fit.params.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    let both = f.fit(&["supply-voltage", "engine-speed"], None, &est, &val).unwrap();
    let n = names(&both);
    assert_eq!(n.len(), 8, "{n:?}");
    assert_eq!(&n[6..], SCHEDULE_INTERACTION.map(String::from).as_slice());
    let (slope, ci) = (both.params[6].1, both.ci95[6].unwrap());
    assert!(
        slope > 0.05 && slope > 3.0 * ci,
        "alpha slope per V*1000 rpm {slope} +- {ci}"
    );
    assert!(
        both.rmse < 0.315,
        "rmse {} against the 0.289 deg quantization floor",
        both.rmse
    );
    let alone = f.fit(&["supply-voltage"], None, &est, &val).unwrap();
    assert!(names(&alone)
        .iter()
        .all(|n| !SCHEDULE_INTERACTION.contains(&n.as_str())));
    let reversed = f.fit(&["engine-speed", "supply-voltage"], None, &est, &val).unwrap();
    assert_eq!(
        &names(&reversed)[6..],
        SCHEDULE_INTERACTION.map(String::from).as_slice()
    );
    assert!(
        (reversed.rmse / both.rmse - 1.0).abs() < 0.05,
        "{} vs {}",
        reversed.rmse,
        both.rmse
    );
}
