//! Tests of the vacuum family: the moving average, parameter round trips, map shapes, extended fits and residual grouping on generated units.
use super::*;
use crate::diagnose::tests::probe_value;
use model_core::vacuum::VacuumEffects;
use model_core::vacuum::{VacuumInputs, VacuumValveActuator};

#[test]
fn moving_average_is_the_prefix_sum_average_bit_for_bit() {
    let y: Vec<f64> = (0..5000)
        .map(|k| 100.0 + (k as f64 * 0.37).sin() * 3.1 + (k % 7) as f64 * 0.01)
        .collect();
    for (seconds, dt) in [(1.0f64, 0.01f64), (0.3, 0.001), (0.05, 0.01), (100.0, 0.01)] {
        let half = (0.5 * seconds / dt).round() as usize;
        let mut prefix = vec![0.0];
        for v in &y {
            prefix.push(prefix.last().unwrap() + v);
        }
        let got = moving_average(&y, seconds, dt);
        for (k, g) in got.iter().enumerate() {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(y.len()));
            let want = (prefix[b] - prefix[a]) / (b - a) as f64;
            assert_eq!(g.to_bits(), want.to_bits(), "{seconds} s, sample {k}");
        }
    }
}

/// Bench-like inputs: steps and ramps at changing voltage.
fn inputs(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let duty: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * 0.01;
            if (t as usize / 2).is_multiple_of(2) {
                20.0 + 30.0 * (t * 0.7).sin().abs()
            } else {
                90.0 - (t * 13.0) % 60.0
            }
        })
        .map(|d: f64| (d * 10.0).round() / 10.0)
        .collect();
    let u: Vec<f64> = (0..n).map(|k| 12.0 + 1.5 * ((k / 300) % 3) as f64 - 1.5).collect();
    (
        duty,
        u,
        vec![99.0; n],
        (0..n).map(|k| 25.0 + 5.0 * (k as f64 * 0.001).sin()).collect(),
    )
}

fn reference(p: &VacuumParams, io: &Inputs, dt: f64) -> (Vec<f64>, Vec<f64>) {
    let mut a = VacuumValveActuator::<f64>::new(p).unwrap();
    let inp = |k: usize| VacuumInputs {
        duty_pct: io.duty[k],
        u_batt_v: io.u_batt[k],
        p_amb_kpa: io.p_amb[k],
        p_tank_kpa: io.p_tank[k],
    };
    a.settle(&inp(0));
    let (mut xs, mut ps) = (Vec::new(), Vec::new());
    for k in 0..io.len() {
        xs.push(a.x_pct());
        ps.push(a.p_act_kpa());
        a.step(&inp(k), dt);
    }
    (xs, ps)
}

fn all_effects() -> VacuumEffects {
    VacuumEffects {
        supply_voltage: true,
        pressure_direction: true,
        coulomb_friction: true,
        backlash: true,
    }
}

/// The family's parameter vector carries a model-core parameter set through unchanged: the
/// family simulates the generator's plant (same rod step) to rounding, including Dahl's σ
/// as Fc/dahl_x and eq. (1) as κ = 1; κ = 0 is the voltage-blind baseline.
#[test]
fn parameters_round_trip_to_the_generators_plant() {
    let n = 3000;
    let (d, u, pa, pt) = inputs(n);
    let io = Inputs {
        duty: &d,
        u_batt: u.clone(),
        p_amb: pa.clone(),
        p_tank: pt.clone(),
        dt_s: 0.01,
    };
    for p in [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()] {
        for effects in [VacuumEffects::NONE, all_effects()] {
            let p = p.with_effects(effects);
            let (xr, pr) = reference(&p, &io, 0.01);
            let m = VacuumModel::from_params(&p);
            let (mut xs, mut ps) = (vec![0.0; n], vec![0.0; n]);
            m.simulate(&io, 0..n, 0.0005, true, &mut xs, &mut ps).unwrap();
            let dx = xs.iter().zip(&xr).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            let dp = ps.iter().zip(&pr).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(dx < 1e-9 && dp < 1e-9, "{effects:?}: max |dx| {dx}, |dp| {dp}");
            let span = xr.iter().cloned().fold(f64::MAX, f64::max) - xr.iter().cloned().fold(f64::MAX, f64::min);
            // The motion is real (the HPC valve hardly vents below 40 % duty).
            assert!(span > 10.0, "{effects:?}: span {span}");
            // The pressure-only run gives the same pressure.
            let (mut x2, mut p2) = (vec![0.0; n], vec![0.0; n]);
            m.simulate(&io, 0..n, 0.0005, false, &mut x2, &mut p2).unwrap();
            assert_eq!(p2, ps);
        }
        // κ = 0 with the supply-voltage effect on is the baseline, whatever the voltage.
        let blind = VacuumModel {
            voltage_gain: 0.0,
            ..VacuumModel::from_params(&p.with_effects(VacuumEffects {
                supply_voltage: true,
                ..VacuumEffects::NONE
            }))
        };
        let base = VacuumModel::from_params(&p.baseline());
        let (mut xa, mut pa_) = (vec![0.0; n], vec![0.0; n]);
        let (mut xb, mut pb) = (vec![0.0; n], vec![0.0; n]);
        blind.simulate(&io, 0..n, 0.001, true, &mut xa, &mut pa_).unwrap();
        base.simulate(&io, 0..n, 0.001, true, &mut xb, &mut pb).unwrap();
        // (duty·U_ref/U_ref rounds differently from the duty: equal to rounding.)
        let dev = xa
            .iter()
            .zip(&xb)
            .chain(pa_.iter().zip(&pb))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(dev < 1e-9, "κ = 0 differs from the baseline by {dev}");
    }
    // A parameter set model-core rejects is an error naming it, not a panic.
    let mut bad = VacuumModel::from_params(&VacuumParams::hpt());
    bad.a2_pct_per_rad = 10.0;
    let (mut xs, mut ps) = (vec![0.0; 10], vec![0.0; 10]);
    let e = bad.simulate(&io, 0..10, 0.001, true, &mut xs, &mut ps).unwrap_err();
    assert!(e.contains("position_map"), "{e}");
}

#[test]
fn coarse_rod_step_stays_far_below_sensor_noise() {
    let n = 6000;
    let (d, u, pa, pt) = inputs(n);
    let io = Inputs {
        duty: &d,
        u_batt: u.clone(),
        p_amb: pa.clone(),
        p_tank: pt.clone(),
        dt_s: 0.01,
    };
    let fam = VacuumFamily::default();
    for p in [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()] {
        for effects in [VacuumEffects::NONE, all_effects()] {
            let m = VacuumModel::from_params(&p.with_effects(effects));
            let (mut x1, mut p1) = (vec![0.0; n], vec![0.0; n]);
            let (mut x2, mut p2) = (vec![0.0; n], vec![0.0; n]);
            m.simulate(&io, 0..n, 0.0005, true, &mut x1, &mut p1).unwrap();
            m.simulate(&io, 0..n, fam.h_max_s, true, &mut x2, &mut p2).unwrap();
            let rms = (x1.iter().zip(&x2).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / n as f64).sqrt();
            eprintln!("{effects:?}: rms x deviation at {} ms: {rms:.4} %", fam.h_max_s * 1e3);
            assert!(rms < 0.08, "{rms}");
        }
    }
}

#[test]
fn parameter_names_round_trip_and_have_bounds() {
    for valve in [ValveMap::PiecewiseLinear, ValveMap::Cubic] {
        for rod in [RodMap::Linear, RodMap::Arctan] {
            let m = VacuumModel::baseline_guess(valve, rod);
            for e in [
                &[][..],
                &["supply-voltage"],
                &["pressure-direction"],
                &["coulomb-friction"],
                &["backlash"],
                &["supply-voltage", "backlash"],
            ] {
                let mut names = m.parameter_names(e).unwrap();
                names.retain(|n| !n.is_empty());
                for (i, n) in names.iter().enumerate() {
                    let mut m2 = m;
                    m2.set(n, 1234.5 + i as f64).unwrap();
                    assert_eq!(m2.get(n), 1234.5 + i as f64, "{n}");
                    assert_eq!(m2.u_ref_v, 12.0, "{n} is not a field");
                    let (lo, hi) = bounds(n);
                    assert!(lo.is_finite() && hi.is_finite() && lo < hi, "{n}");
                }
            }
        }
    }
    assert!(m_err().contains("`friction`"));
    // An unknown name is an error, never a scratch field.
    let mut m = VacuumModel::baseline_guess(ValveMap::Cubic, RodMap::Linear);
    assert!(m.set("friction_kPa", 1.0).unwrap_err().contains("`friction_kPa`"));
    assert!(m.get("friction_kPa").is_nan());
}

fn m_err() -> String {
    VacuumModel::baseline_guess(ValveMap::Cubic, RodMap::Linear)
        .with_effect("friction")
        .unwrap_err()
}

fn case_logs(effect: &str, seed: u64) -> (crate::generate::Case, Log, Log) {
    let case = crate::generate::vacuum::generate(effect, seed).unwrap();
    let (est, val) = case.logs().expect("generated logs read back");
    (case, est, val)
}

/// The diagnosis of two logs with the default rules.
fn diagnose_logs(est: &Log, val: &Log) -> crate::diagnose::Diagnosis {
    use crate::diagnose::{diagnose, Rules};
    diagnose(
        &VacuumFamily::default(),
        est,
        val,
        false,
        &Rules::default(),
        &mut |_| {},
    )
    .unwrap()
}

/// A generated case and its diagnosis.
fn diagnosed(effect: &str, seed: u64) -> (crate::generate::Case, crate::diagnose::Diagnosis) {
    let (case, est, val) = case_logs(effect, seed);
    let d = diagnose_logs(&est, &val);
    (case, d)
}

fn truth(case: &crate::generate::Case, name: &str) -> f64 {
    case.truth.iter().find(|(n, _)| n == name).map(|(_, v)| *v).unwrap()
}

#[test]
fn map_shapes_are_picked_from_the_data() {
    // Seeds 3, 11 and 8 draw an LPT, HPT and HPC actuator (the preset is the first draw).
    for (seed, preset, valve, rod) in [
        (3, "preset_LPT", ValveMap::PiecewiseLinear, RodMap::Linear),
        (11, "preset_HPT", ValveMap::PiecewiseLinear, RodMap::Arctan),
        (8, "preset_HPC", ValveMap::Cubic, RodMap::Arctan),
    ] {
        for effect in ["none", "coulomb-friction"] {
            let (case, est, _) = case_logs(effect, seed);
            assert_eq!(case.truth[0].0, preset);
            let fam = VacuumFamily::default();
            let data = fam.est_data(&est).unwrap();
            let m = fam.prepared(&est, &data).unwrap().model;
            assert_eq!(m.valve_map, valve, "{preset} {effect}");
            // With friction the band of a linear map comes out bent (measured: a line misses
            // its centre by 1.5 %, an arctan by 0.7 %) and the arctan, which can mimic the
            // line, is taken; the arctan actuators must always get their arctan.
            if effect == "none" || rod == RodMap::Arctan {
                assert_eq!(m.rod_map, rod, "{preset} {effect}");
            }
        }
    }
}

#[test]
fn extended_fits_recover_the_hidden_magnitudes() {
    let fam = VacuumFamily::default();
    let got = |effect: &str, seed: u64, name: &str| {
        let (case, est, _) = case_logs(effect, seed);
        let (m, _, ci, _, _) = fam.calibrate(&est, &[effect], None).unwrap();
        let names = m.parameter_names(&[effect]).unwrap();
        let i = names.iter().position(|n| *n == name).unwrap();
        eprintln!(
            "{effect} seed {seed}: {name} {:.4} ± {:?}, truth {:.4}",
            m.get(name),
            ci[i],
            truth(&case, name)
        );
        (m, case)
    };
    let (m, case) = got("coulomb-friction", 77_001, "fc_kPa");
    assert!((m.fc_kpa / truth(&case, "fc_kPa") - 1.0).abs() < 0.05);
    let (m, case) = got("backlash", 11, "backlash_pct");
    assert!((m.backlash_pct / truth(&case, "backlash_pct") - 1.0).abs() < 0.05);
    let (m, case) = got("pressure-direction", 11, "tau_fall_s");
    let ratio = (m.tau_fall_s / m.tau_rise_s) / (truth(&case, "tau_fall_s") / truth(&case, "tau_rise_s"));
    assert!((ratio - 1.0).abs() < 0.05, "{ratio}");
    // Eq. (1) is κ = 1.
    let (m, _) = got("supply-voltage", 2024, "voltage_gain");
    assert!((m.voltage_gain - 1.0).abs() < 0.05, "{}", m.voltage_gain);
}

#[test]
fn position_only_logs_are_diagnosed_too() {
    let (_, mut est, mut val) = case_logs("coulomb-friction", 77_001);
    est.columns.remove("p_act_kPa");
    val.columns.remove("p_act_kPa");
    let d = diagnose_logs(&est, &val);
    assert_eq!(d.cause, "coulomb-friction");
    assert!(d.gain_pct > 50.0, "{}", d.gain_pct);
}

/// Issue 3, step 3: a supply-voltage effect shows as a bias of the baseline residual that
/// changes with the supply voltage (grouped by operating condition), and every logged input
/// is a regressor; the extended model's residual no longer depends on the voltage.
#[test]
fn supply_voltage_shows_in_the_residual_grouped_by_voltage() {
    use crate::residuals::group_check;
    let (_, est, val) = case_logs("supply-voltage", 2024);
    let d = diagnose_logs(&est, &val);
    assert_eq!(d.cause, "supply-voltage");
    let names: Vec<&str> = d.cross.iter().map(|c| c.name.as_str()).collect();
    for input in [
        "supply voltage",
        "duty",
        "tank pressure (vacuum supply)",
        "ambient pressure",
    ] {
        assert!(names.contains(&input), "{input} missing from {names:?}");
    }
    let by_voltage = d.grouped.iter().find(|g| g.name == "supply voltage").unwrap();
    assert!(!by_voltage.pass && by_voltage.groups.len() == 3, "{by_voltage:?}");
    // Eq. (1): a low voltage weakens the valve (less vacuum, x lower than the baseline says).
    let (low, high) = (&by_voltage.groups[0], &by_voltage.groups[2]);
    assert!(low.mean < high.mean, "{by_voltage:?}");
    assert!(
        d.evidence
            .iter()
            .any(|e| e.contains("residual: mean differs by supply voltage")),
        "{:?}",
        d.evidence
    );
    // The extended model's residual no longer depends on the voltage: the test passes and
    // each group's mean is under a quarter of the position sensor's noise (0.2 %), where the
    // baseline's were 2-18 %.
    let volts = val.col("u_batt_V").unwrap();
    let after = group_check("supply voltage", &d.extended.residual(), volts);
    assert!(
        after.pass && after.groups.iter().all(|g| g.mean.abs() < 0.05),
        "extended {after:?} vs baseline {by_voltage:?}"
    );
}

#[test]
fn moving_average_keeps_levels_and_cuts_noise() {
    let y: Vec<f64> = (0..1000).map(|k| 100.0 + if k % 2 == 0 { 0.3 } else { -0.3 }).collect();
    let s = moving_average(&y, 1.0, 0.01);
    assert!(s.iter().all(|v| (v - 100.0).abs() < 0.01), "{:?}", &s[..3]);
    assert_eq!(moving_average(&[5.0; 10], 0.3, 0.01), vec![5.0; 10]);
}

/// A friction fit of a unit with friction and clearance sharpens Dahl's presliding distance to
/// its bound to mimic the clearance; the pair then stopped within a few solver steps at 1.5x
/// the friction fit's validation error and the clearance was never named (seed 1000: 82 % of
/// the error left at 10x the noise floor). After a coarse global stage over the distance and
/// the dead band's share between the two it reaches the unit.
#[test]
fn friction_and_clearance_together_are_fitted_from_the_friction_fit() {
    let (case, est, val) = case_logs("coulomb-friction+backlash", 1000);
    let fam = VacuumFamily::default();
    let (cf, bl) = ("coulomb-friction", "backlash");
    let parent = fam.fit(&[cf], None, &est, &val).unwrap();
    let pair = fam.fit(&[cf, bl], Some(&parent), &est, &val).unwrap();
    let got = |name: &str| pair.internal_value(name).unwrap();
    for name in ["fc_kPa", "backlash_pct"] {
        let rel = got(name) / truth(&case, name) - 1.0;
        assert!(rel.abs() < 0.05, "{name} {} against {}", got(name), truth(&case, name));
    }
    assert!(pair.rmse < 0.25 * parent.rmse, "{} against {}", pair.rmse, parent.rmse);
}

/// Friction under another effect: the friction fit alone, which takes a slow pressure fall for
/// its rod, ends at a presliding distance of 0.058 % on this HPT unit (truth 0.48 %); from
/// there, with the pressure model put right, the rod stage stopped at once (estimation cost
/// 9 525 against the parent's 8 918). Every fit with friction now starts also from the best two
/// of a coarse grid of distances.
#[test]
fn friction_under_pressure_direction_leaves_the_parents_presliding_distance() {
    let (case, est, val) = case_logs("pressure-direction+coulomb-friction", 119_785);
    let fam = VacuumFamily::default();
    let (cf, pd) = ("coulomb-friction", "pressure-direction");
    let baseline = fam.fit(&[], None, &est, &val).unwrap();
    let parent = fam.fit(&[cf], Some(&baseline), &est, &val).unwrap();
    let pair = fam.fit(&[cf, pd], Some(&parent), &est, &val).unwrap();
    let got = |name: &str| pair.internal_value(name).unwrap();
    for (name, tol) in [("fc_kPa", 0.05), ("dahl_x_pct", 0.15)] {
        let rel = got(name) / truth(&case, name) - 1.0;
        assert!(rel.abs() < tol, "{name} {} against {}", got(name), truth(&case, name));
    }
    let ratio = (got("tau_fall_s") / got("tau_rise_s")) / (truth(&case, "tau_fall_s") / truth(&case, "tau_rise_s"));
    assert!((ratio - 1.0).abs() < 0.05, "tau_fall/tau_rise {ratio} of the truth's");
    assert!(
        pair.est_cost < parent.est_cost,
        "{} against {}",
        pair.est_cost,
        parent.est_cost
    );
    assert!(pair.rmse < 0.25 * parent.rmse, "{} against {}", pair.rmse, parent.rmse);
}

/// Friction and a clearance that stand in for each other (an LPT unit): friction predicts the
/// validation log better alone (0.353 against 0.362 %) and is named first, the clearance fits
/// the estimation log better (cost 382 against 417). Friction + clearance from friction's
/// optimum stopped at 322 (19 % on validation at z 3.3: not added); the pair is also fitted
/// from the clearance's optimum, which reaches the floor, and both are named.
#[test]
fn friction_and_clearance_are_both_named_from_the_clearances_optimum() {
    let (case, est, val) = case_logs("coulomb-friction+backlash", 103_947);
    let d = diagnose_logs(&est, &val);
    assert_eq!(d.causes, ["coulomb-friction", "backlash"], "{:#?}", d.evidence);
    assert_eq!(d.verdict, "explained", "{:#?}", d.evidence);
    assert!(
        d.evidence
            .iter()
            .any(|e| e.contains("fitted also from the `backlash` model's optimum")),
        "{:#?}",
        d.evidence
    );
    let clearance = d.candidates.iter().find(|c| c.fit.effect == "backlash").unwrap();
    let pair = &d.rounds[0]
        .candidates
        .iter()
        .find(|c| c.fit.effects.len() == 2 && c.fit.effects[1] == "backlash")
        .unwrap()
        .fit;
    assert!(
        pair.est_cost < 0.6 * clearance.fit.est_cost,
        "{} against {}",
        pair.est_cost,
        clearance.fit.est_cost
    );
    let fc = pair.internal_value("fc_kPa").unwrap();
    assert!(
        (fc / truth(&case, "fc_kPa") - 1.0).abs() < 0.15,
        "fc {fc} kPa against {}",
        truth(&case, "fc_kPa")
    );
}

#[test]
fn the_running_median_keeps_steps_and_plateaus_and_drops_noise() {
    let dt = 0.01;
    // A 12.8 V plateau with alternating 20 mV noise, a sag to 11.0 V for 0.3 s, and back.
    let truth: Vec<f64> = (0..200)
        .map(|k| if (80..110).contains(&k) { 11.0 } else { 12.8 })
        .collect();
    let logged: Vec<f64> = truth
        .iter()
        .enumerate()
        .map(|(k, u)| u + if k % 3 == 0 { 0.02 } else { 0.0 })
        .collect();
    let m = moving_median(&logged, U_BATT_MEDIAN_S, dt);
    let half = (0.5 * U_BATT_MEDIAN_S / dt).round() as usize;
    for (k, (got, want)) in m.iter().zip(&truth).enumerate() {
        // Within one noise step everywhere (a 9-sample mean would put 11.8 V at the sag's
        // first sample), exact where the window lies on one plateau.
        assert!((got - want).abs() <= 0.02 + 1e-12, "sample {k}: {got} against {want}");
        let one_plateau = [80, 110].iter().all(|&edge| k + half < edge || k >= edge + half);
        if one_plateau {
            assert_eq!(got, want, "sample {k}");
        }
    }
}

/// The logged supply voltage's noise, replayed sample by sample, dithered the simulated duty;
/// a rod with friction then crept where the unit's stood, the friction fit sharpened Dahl's
/// presliding distance to its bound against the dither (seed 8919: 0.022 % for the unit's
/// 0.234 %) and a clearance was named on top of it. With the voltage's running median the two
/// effects are named, the unit's friction is found and nothing is left above the floor.
#[test]
fn supply_voltage_noise_does_not_dither_a_rod_with_friction() {
    let (case, d) = diagnosed("supply-voltage+coulomb-friction", 8919);
    let mut causes = d.causes.clone();
    causes.sort();
    assert_eq!(causes, ["coulomb-friction", "supply-voltage"]);
    assert_eq!(d.verdict, "explained", "{:?}", d.remainder.evidence);
    let fc = d.extended.params.iter().find(|(n, _)| n == "fc_kPa").unwrap().1;
    assert!((fc / truth(&case, "fc_kPa") - 1.0).abs() < 0.05, "fc {fc}");
}

/// Outside the catalogue: a transport delay of the duty. Friction takes part of its lag into a
/// dead band and gained enough to be named (seed 111866: `coulomb-friction`, 80 ms delay); the
/// duty-delay probe finds the delay, and with it fitted on the baseline too friction gains
/// nothing, so no catalogue effect is named and the verdict says what is missing.
#[test]
fn a_duty_delay_is_found_by_its_probe_and_not_named_as_friction() {
    let (case, d) = diagnosed("duty-delay", 111_866);
    assert!(d.causes.is_empty(), "{:?}", d.causes);
    assert_eq!(d.verdict, "unexplained");
    let delay = truth(&case, "duty_delay_s");
    // The evidence says what is missing, with the fitted delay.
    let fitted = probe_value(&d, "a transport delay of the duty", "duty_delay_s");
    assert!((fitted / delay - 1.0).abs() < 0.1, "{fitted} s against {delay} s");
}

/// Outside the catalogue: the rod's travel ends at a stop inside the stroke (seed 2024: at
/// 77.4 %). The position stays flat while the chamber pressure goes on, which a clearance's
/// dead band half mimics: `backlash` was named (27 % gain, z 11.6, the remainder still 31x the
/// floor). The travel-stop probe finds the stop; beside it the clearance gains nothing, so no
/// catalogue effect is named, and the verdict says what is missing and where the stop is.
#[test]
fn a_travel_stop_is_found_by_its_probe_and_not_named_as_a_clearance() {
    let (case, d) = diagnosed("travel-stop", 2024);
    assert!(d.causes.is_empty(), "{:?}", d.causes);
    assert_eq!(d.verdict, "unexplained");
    let stop = truth(&case, "x_stop_high_pct");
    let fitted = probe_value(&d, "a travel that ends inside the stroke", "x_stop_high_pct");
    assert!((fitted - stop).abs() < 0.5, "{fitted} % against {stop} %");
}

/// A cause added first whose effect the final model fitted back to neutral is not named
/// (seed 127704, pressure-direction + coulomb-friction: the clearance came first as friction's
/// dead band, then friction and the pressure's direction, and the clearance ended at 0).
#[test]
fn a_cause_the_final_model_switched_off_is_not_named() {
    let (_, d) = diagnosed("pressure-direction+coulomb-friction", 127_704);
    let mut causes = d.causes.clone();
    causes.sort();
    assert_eq!(causes, ["coulomb-friction", "pressure-direction"]);
    assert_eq!(d.extended.effects.len(), 2);
}

/// A clearance next to a duty delay is named alone, the delay found by its probe:
/// - seed 2024: the probe gains 50 % at z = 3.0 (under `min_z`; the estimation cost more than
///   halved confirms it), and without it the clearance's lag was taken for friction;
/// - seed 77001: beside the probe the clearance reaches 1.1x the floor; friction then gained
///   10 % by ending switched off (a better optimum of the same model), as the pressure
///   direction had before: neither is a cause.
#[test]
fn a_clearance_beside_a_duty_delay_is_named_alone() {
    for seed in [2024, 77_001] {
        let (case, d) = diagnosed("backlash+duty-delay", seed);
        assert_eq!(d.causes, ["backlash"], "seed {seed}");
        assert_eq!(d.verdict, "unexplained", "seed {seed}");
        let fitted = probe_value(&d, "a transport delay of the duty", "duty_delay_s");
        let delay = truth(&case, "duty_delay_s");
        assert!(
            (fitted / delay - 1.0).abs() < 0.1,
            "seed {seed}: {fitted} s against {delay} s"
        );
    }
}
