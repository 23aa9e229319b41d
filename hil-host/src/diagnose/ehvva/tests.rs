use super::fits::TAU_P;
use super::*;
use crate::generate::ehvva as gen;

fn logs(effect: &str, seed: u64) -> (Log, Log, Vec<(String, f64)>) {
    let case = gen::generate(effect, seed).unwrap();
    let (est, val) = case.logs().expect("generated logs read back");
    (est, val, case.truth)
}

/// RMS of the lift simulated with `p` on `set`'s events minus the measured lift, mm.
fn simulation_rmse(p: &EhvvaParams, set: &Events) -> f64 {
    let mut sim = vec![0.0; set.samples];
    simulate_all(p, set, &mut sim).unwrap();
    let e: Vec<f64> = sim.iter().zip(set.measured()).map(|(s, y)| s - y).collect();
    crate::residuals::rmse(&e)
}

/// The EHVVA diagnosis of a log pair with the default rules.
fn diagnosed(est: &Log, val: &Log) -> crate::diagnose::Diagnosis {
    crate::diagnose::diagnose(
        &EhvvaFamily::default(),
        est,
        val,
        false,
        &crate::diagnose::Rules::default(),
        &mut |_| {},
    )
    .unwrap()
}

fn get(v: &[(String, f64)], key: &str) -> f64 {
    v.iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| *v)
        .unwrap_or_else(|| panic!("no {key}"))
}

/// Simulating the events of a generated log with the generator's true parameters gives
/// the logged lift back to the sensor noise: the cut into events, the set-points read at
/// rest and the early stop after seating lose nothing.
#[test]
fn event_simulation_reproduces_the_bench_with_the_truth() {
    let (est, _, truth) = logs("direction-delay", 3);
    let set = Events::from_log(&est).unwrap();
    let p = gen::params_from_truth(&truth);
    let rms = simulation_rmse(&p, &set);
    assert!(rms < 0.008, "rms {rms} mm: more than the lift sensor's noise");
    // A 10 % longer delay does not.
    let mut wrong = p;
    scale_td(&mut wrong, get(&truth, "td_ms_at_7MPa_22C") * 1.1);
    assert!(simulation_rmse(&wrong, &set) > 5.0 * rms);
}

/// A perfect model is `explained` against the verdict's floor. A healthy unit near its
/// force balance (seed 246489, the most such of sixty sweep seeds; 143542 until the
/// estimation matrix's back-pressure sweep changed the logs' noise draws): its own true
/// model, simulated from the set-points the log gives (means of the rest samples), misses
/// the validation lift by over 2x the sensor floor, what the set-points' standard errors
/// move it; with that cost in the floor the truth is within the `explained` ratio. A model
/// 10 % off in td stays far outside it.
#[test]
fn the_set_points_own_error_is_in_the_floor_a_perfect_model_reaches() {
    let (_, val, truth) = logs("none", 246489);
    let p = gen::params_from_truth(&truth);
    let set = Events::from_log(&val).unwrap();
    let floor_of = |p: &EhvvaParams| {
        let mut sim = vec![0.0; set.samples];
        simulate_all(p, &set, &mut sim).unwrap();
        let measured = set.measured();
        let e: Vec<f64> = sim.iter().zip(&measured).map(|(s, y)| s - y).collect();
        let sensor = crate::diagnose::noise_floor_of(&e, crate::diagnose::resolution(&measured)).rmse;
        let (input, _) = setpoint_floor(p, &val, 2).unwrap();
        (crate::residuals::rmse(&e), sensor, sensor.hypot(input))
    };
    let ratio = crate::diagnose::Rules::default().explained_ratio;
    let (rmse, sensor, floor) = floor_of(&p);
    assert!(rmse > 2.0 * sensor, "truth {rmse} mm against the sensor floor {sensor}");
    assert!(rmse <= ratio * floor, "truth {rmse} mm against the floor {floor}");
    let mut wrong = p;
    scale_td(&mut wrong, get(&truth, "td_ms_at_7MPa_22C") * 1.1);
    let (rmse, _, floor) = floor_of(&wrong);
    assert!(
        rmse > 2.0 * ratio * floor,
        "td 10 % long: {rmse} mm against the floor {floor}"
    );
}

/// The events stepped side by side (lanes) and on two threads give the bits of each event
/// simulated alone, whatever the number of events per lane group (9 here: two groups of
/// four and a lone one).
#[test]
fn events_in_lanes_give_the_numbers_of_one_event_at_a_time() {
    let (est, _, truth) = logs("snubber", 5);
    let set = Events::from_log(&est).unwrap().for_fitting(9);
    assert_eq!(set.events.len(), 9);
    let p = gen::params_from_truth(&truth);
    let mut alone = vec![0.0; set.samples];
    for ev in &set.events {
        let len = ev.lift_mm.len();
        simulate_event(&p, ev, set.dt_ms, &mut alone[ev.start..ev.start + len]).unwrap();
    }
    let (mut lanes, mut threaded) = (vec![0.0; set.samples], vec![0.0; set.samples]);
    simulate_all(&p, &set, &mut lanes).unwrap();
    simulate_all_on(&p, &set, &mut threaded, 2).unwrap();
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&lanes), bits(&alone));
    assert_eq!(bits(&threaded), bits(&alone));
    assert!(alone.iter().any(|&y| y > 1.0), "the events open the valve");
}

/// A unit whose spring is too weak to hold the valve on its seat against a high back
/// pressure ((At − Ab)·Pl > ks·ds with the top chamber at Pl): the valve leaves its seat
/// before the command, in the rest window of the event. Its events are simulated from the
/// rest window, as the bench ran them, not from the command: started at the command the
/// truth missed this unit's estimation log by 8x the sensor noise (0.038 mm), the baseline
/// fit bent the main valve and bottom path to bound values to make up for it and a
/// healthy unit was called `unexplained` at 6.6x the noise floor.
#[test]
fn a_valve_that_floats_off_its_seat_at_rest_is_simulated_from_the_rest_window() {
    let (est, val, truth) = logs("none", 8919);
    let p = gen::params_from_truth(&truth);
    let set = Events::from_log(&est).unwrap();
    let floats = |e: &Event| {
        (p.area_top_mm2 - p.area_bottom_mm2) * e.inputs.p_back_mpa > p.spring_n_per_mm * p.spring_preload_mm
    };
    assert!(
        set.events.iter().any(floats),
        "the case must have an event whose valve floats at rest"
    );
    let rms = simulation_rmse(&p, &set);
    assert!(rms < 0.008, "rms {rms} mm: more than the lift sensor's noise");
    // The healthy unit is explained, with no cause.
    let d = diagnosed(&est, &val);
    assert!(d.causes.is_empty(), "{:?}", d.causes);
    assert_eq!(d.verdict, "explained", "{}", crate::diagnose::report::summary(&d));
    // Within the floor, the probe for outside physics is not fitted.
    assert!(
        d.evidence
            .iter()
            .any(|e| e.starts_with("probe `lift-temperature-scale` not fitted")),
        "{:?}",
        d.evidence
    );
}

/// A lift that grows with the fluid temperature (outside the catalogue: 0.1-0.2 %/°C of the
/// whole profile) hid a direction-dependent delay: fitted on the baseline, the scale took the
/// estimation cost to a twelfth but lost 20 % on validation (the model still lacked the
/// delay), and no cause was named. The probe is tried with the causes selected beside it: the
/// delay is named, the scale measured within 5 %, the verdict `unexplained`.
#[test]
fn a_lift_growing_with_temperature_is_measured_and_the_delay_it_hid_named() {
    let (est, val, truth) = logs("thermal-stroke+direction-delay", 11);
    let d = diagnosed(&est, &val);
    let summary = crate::diagnose::report::summary(&d);
    assert_eq!(d.causes, ["direction-delay"], "{summary}");
    assert_eq!(d.verdict, "unexplained", "{summary}");
    let fitted = crate::diagnose::tests::probe_value(
        &d,
        "a lift that scales with the fluid temperature",
        LIFT_SCALE_KNOB.name,
    );
    let growth = get(&truth, "stroke_growth_per_C");
    assert!((fitted / growth - 1.0).abs() < 0.05, "{fitted} /degC against {growth}");
}

/// A log cut out of a longer record in the middle of a valve event (the held-out tail of
/// `diagnose` with one file): the samples until the valve rests before the next command are
/// left out, as the model cannot start from an unknown motion, and the events after them
/// reproduce the bench with the truth to the sensor noise.
#[test]
fn a_log_beginning_mid_event_is_simulated_from_its_first_rest() {
    let (est, _, truth) = logs("snubber", 5);
    let full = Events::from_log(&est).unwrap();
    assert_eq!(full.skipped(), 0, "a generated log begins at rest");
    // Cut where the third event's valve is fully open.
    let ev = &full.events[2];
    let lift = est.col("lift_mm").unwrap();
    let cut = (ev.start..ev.start + ev.lift_mm.len())
        .max_by(|&a, &b| lift[a].total_cmp(&lift[b]))
        .unwrap();
    assert!(lift[cut] > 0.5, "lift {} mm at the cut", lift[cut]);
    let mut tail = est.clone();
    for c in tail.columns.values_mut() {
        c.drain(..cut);
    }
    let set = Events::from_log(&tail).unwrap();
    let seated = set.skipped();
    assert!(seated > 0 && seated < full.events[3].start - cut, "skipped {seated}");
    assert!(tail.col("lift_mm").unwrap()[seated..seated + 5]
        .iter()
        .all(|l| l.abs() < 0.05));
    let rms = simulation_rmse(&gen::params_from_truth(&truth), &set);
    assert!(rms < 0.008, "rms {rms} mm");
    // The family scores the skipped samples as measured, for every candidate alike.
    let fit = EhvvaFamily::default().fit(&["snubber"], None, &est, &tail).unwrap();
    assert_eq!(&fit.measured[..seated], &tail.col("lift_mm").unwrap()[..seated]);
    assert!(fit.rmse < 0.008, "validation rmse {} mm", fit.rmse);
}

/// Every fitted knob's bounds are a model that model-core accepts: a bound beyond what the
/// model validates cuts the range where the solver's trial steps fail, and a Jacobian column
/// stepped across it reads zero (the snubber gain's bound 6 had been cut at 2 that way).
#[test]
fn every_knob_bound_is_a_valid_model() {
    let knobs = BASELINE_KNOBS
        .iter()
        .chain(&UNIT_KNOBS)
        .copied()
        .chain(EFFECTS.iter().map(|e| effect_knob(e).unwrap()));
    for k in knobs {
        for v in [k.lo, k.hi] {
            let p = apply_knobs(&EhvvaParams::baseline(), &[k], &[v]);
            assert!(p.validate().is_ok(), "{} = {v}: {:?}", k.name, p.validate());
        }
    }
}

/// The baseline and an extension recover the generator's parameters from the estimation
/// log alone.
#[test]
fn fits_recover_the_hidden_parameters() {
    let f = EhvvaFamily::default();
    let (est, val, truth) = logs("none", 17);
    let fit = f.fit(&[], None, &est, &val).unwrap();
    // Mass, Cd and the other forces come out relative to the piston top area, held at the
    // paper's value (the scale the data cannot see).
    let scale = EhvvaParams::baseline().area_top_mm2 / get(&truth, "area_top_mm2");
    for (name, tol, s) in [
        ("td_ms_at_7MPa_22C", 0.01, 1.0),
        ("mass_kg", 0.05, scale),
        ("spring_N_per_mm", 0.05, scale),
    ] {
        let (got, want) = (get(&fit.params, name), get(&truth, name) * s);
        assert!((got / want - 1.0).abs() < tol, "{name}: {got} vs {want}");
    }
    // Cd is held at the paper's value (it trades exactly with the orifice areas' common
    // scale): the flow path the losses see, Cd times the main valve's area, is the unit's.
    let cd_paper = reference_values().1;
    let got = cd_paper * get(&fit.params, "area_main_mm2");
    let want = get(&truth, "cd_at_22C") * scale * get(&truth, "area_main_mm2");
    assert!((got / want - 1.0).abs() < 0.06, "Cd·A_main: {got} vs {want}");
    assert!(fit.not_identifiable.iter().any(|n| n.starts_with("area_top_mm2")));
    assert!(fit.not_identifiable.iter().any(|n| n.starts_with("cd_at_22C")));
    let (est, val, truth) = logs("viscosity", 18);
    let fit = f.fit(&["viscosity"], None, &est, &val).unwrap();
    let (got, want) = (get(&fit.params, "viscosity_gain"), get(&truth, "viscosity_gain"));
    assert!((got / want - 1.0).abs() < 0.05, "viscosity gain {got} vs {want}");
    // The orifices of a real unit vary too and are not all fitted: a little above the
    // sensor noise (σ 2-6 µm).
    assert!(fit.rmse < 0.02, "validation rmse {}", fit.rmse);
}

/// A unit whose baseline absorbed its direction-dependent delay into the pilot lag (seed
/// 88109: the baseline's τp ends at 4x the unit's): the extension starting there stopped in
/// the τp-td valley at 25x the sensor noise, so the effect was never named. With the τp
/// profile start it reaches the unit: τp and the delay gain within 5 % of the truth, the
/// validation lift at the sensor noise.
#[test]
fn an_extension_stopped_in_the_pilot_lag_valley_is_restarted_with_the_lag_held() {
    let f = EhvvaFamily::default();
    let (est, val, truth) = logs("direction-delay", 88109);
    let base = f.fit(&[], None, &est, &val).unwrap();
    let tau_truth = get(&truth, TAU_P);
    assert!(
        get(&base.params, TAU_P) > 1.5 * tau_truth,
        "the case needs a baseline whose τp absorbed the effect: {}",
        get(&base.params, TAU_P)
    );
    let fit = f.fit(&["direction-delay"], Some(&base), &est, &val).unwrap();
    for name in [TAU_P, "direction_delay_gain"] {
        let (got, want) = (get(&fit.params, name), get(&truth, name));
        assert!((got / want - 1.0).abs() < 0.05, "{name}: {got} vs {want}");
    }
    assert!(fit.rmse < 0.008, "validation rmse {} mm", fit.rmse);
}

/// A long record (the matrix run four times) is fitted on a subset that keeps every test
/// condition and spreads over the whole record; a short one is fitted whole.
#[test]
fn long_records_are_fitted_on_every_condition_spread_over_the_record() {
    for seed in 3..7 {
        long_record_subset(seed);
    }
}

fn long_record_subset(seed: u64) {
    let case = crate::generate::ehvva::generate_repeated(&[], seed, 4).unwrap();
    let (est, _) = case.logs().unwrap();
    let all = Events::from_log(&est).unwrap();
    assert_eq!(all.events.len(), 80);
    let sub = all.for_fitting(40);
    assert_eq!(sub.events.len(), 40);
    assert_eq!(sub.samples, sub.covered());
    let condition = |e: &Event| {
        (
            e.inputs.lift_high,
            e.inputs.snubber_on,
            (e.inputs.temp_c / 10.0).round() as i64,
        )
    };
    let wanted: std::collections::BTreeSet<_> = all.events.iter().map(condition).collect();
    let got: std::collections::BTreeSet<_> = sub.events.iter().map(condition).collect();
    assert_eq!(
        got, wanted,
        "seed {seed}: a condition is missing from the fitted subset"
    );
    // Taken from the whole record, not only its beginning: the subset's events are found
    // in every quarter of the original.
    let lifts: Vec<&[f64]> = sub.events.iter().map(|e| e.lift_mm.as_slice()).collect();
    for quarter in 0..4 {
        let part = &all.events[quarter * 20..(quarter + 1) * 20];
        assert!(
            part.iter().any(|e| lifts.contains(&e.lift_mm.as_slice())),
            "no event of quarter {quarter} is fitted"
        );
    }
    assert_eq!(all.for_fitting(80).events.len(), 80);
    // The part of the log that `diagnose` keeps cuts into the same events (samples and
    // set-points) as the fits' choice from the whole record.
    let family = EhvvaFamily::default();
    let part = family.estimation_part(est.clone()).unwrap();
    assert!(part.file.contains("of its 80 valve events"), "{}", part.file);
    let from_part = Events::from_log(&part).unwrap();
    let chosen = all.for_fitting(MAX_FIT_EVENTS);
    assert_eq!(from_part.events.len(), chosen.events.len());
    for (a, b) in from_part.events.iter().zip(&chosen.events) {
        assert_eq!((a.start, &a.lift_mm, &a.u_pilot), (b.start, &b.lift_mm, &b.u_pilot));
        assert_eq!((a.on_index, a.off_index), (b.on_index, b.off_index));
        assert_eq!(a.inputs.p_supply_mpa, b.inputs.p_supply_mpa);
        assert_eq!(a.inputs.temp_c, b.inputs.temp_c);
    }
}

#[test]
fn logs_without_events_or_too_slow_are_refused_by_name() {
    let (mut est, _, _) = logs("none", 1);
    est.columns.insert("u_pilot".into(), vec![0.0; est.len()]);
    assert!(Events::from_log(&est).unwrap_err().contains("no valve event"));
    let (mut est, _, _) = logs("none", 1);
    est.dt_s = 1e-3;
    assert!(Events::from_log(&est).unwrap_err().contains("0.1 ms or less"));
}

/// A fit's approach on the coarse model ([`Events::coarse`]) ends where the fit on the model
/// alone ends: the paper's four knobs on a unit's log, from the onset-matched start, reach the
/// same cost and values either way; the coarse simulation itself differs from the model's.
#[test]
fn the_approach_on_the_coarse_model_ends_at_the_models_own_optimum() {
    let f = EhvvaFamily::default();
    let (est, _, _) = logs("none", 5);
    let set = Events::from_log(&est).unwrap();
    let x0 = f.baseline_start(&set).unwrap();
    let p = EhvvaParams::baseline();
    let fine_only = calibrate_with(&p, &BASELINE_KNOBS, &x0, &set, &f.lsq, &|_| Ok(())).unwrap();
    let two_stage = calibrate(&p, &BASELINE_KNOBS, &x0, &set, &f.lsq).unwrap();
    assert!(
        (two_stage.cost / fine_only.cost - 1.0).abs() < 1e-3,
        "cost {} vs {}",
        two_stage.cost,
        fine_only.cost
    );
    for (k, (a, b)) in BASELINE_KNOBS.iter().zip(two_stage.x.iter().zip(&fine_only.x)) {
        assert!((a / b - 1.0).abs() < 0.01, "{}: {a} vs {b}", k.name);
    }
    let pp = apply_knobs(&p, &BASELINE_KNOBS, &fine_only.x);
    let (mut fine, mut coarse) = (vec![0.0; set.samples], vec![0.0; set.samples]);
    simulate_all(&pp, &set, &mut fine).unwrap();
    simulate_all(&pp, &set.coarse(), &mut coarse).unwrap();
    assert!(fine != coarse, "the coarse sub-step did not reach the model");
}

/// A bench log at 20 kHz written out: one 40 ms event per entry of `held_at` (low lift, 4 mm
/// stroke, 8 ms command). The lift rises at 1 mm/ms from 3 ms after the command and stands at
/// `held_at` (a fraction of the stroke: 1.0 its stop) until 3 ms after the command ends, then
/// falls at 1 mm/ms.
fn trapezoid_log(name: &str, held_at: &[f64]) -> Log {
    let (dt_ms, per_event) = (0.05, 800);
    let mut cols: [Vec<f64>; 8] = Default::default();
    for (i, &level) in held_at.iter().enumerate() {
        let top = 4.0 * level;
        for k in 0..per_event {
            let t = k as f64 * dt_ms - 2.0; // ms from the command's rising edge
            let lift = if t < 3.0 {
                0.0
            } else if t < 11.0 {
                (t - 3.0).min(top)
            } else {
                (top - (t - 11.0)).max(0.0)
            };
            let row = [
                ((i * per_event + k) as f64 * dt_ms * 1e-3),
                if (0.0..8.0).contains(&t) { 1.0 } else { 0.0 },
                6.0,
                1.0,
                22.0,
                0.0,
                0.0,
                lift,
            ];
            for (c, v) in cols.iter_mut().zip(row) {
                c.push(v);
            }
        }
    }
    // The rows above are in the layout's column order, after the time.
    let names = Plant::Ehvva.column_names();
    let columns: Vec<(&str, &[f64])> = names.zip(cols.iter().map(|c| &c[..])).collect();
    let text = crate::log::format_log(&[("plant".into(), "ehvva".into())], &columns);
    crate::log::parse_log(name, &text, None).unwrap()
}

/// An event held short of its stroke by the force balance is told from one at its stop, one
/// still opening when its command ends, and one that never opened.
#[test]
fn a_valve_held_short_of_its_stroke_is_told_from_one_at_its_stop_or_still_moving() {
    let events = |held_at: &[f64]| Events::from_log(&trapezoid_log("t.csv", held_at)).unwrap();
    let held = |e: &Events, i: usize| e.events[i].held_short_of_stroke(4.0, e.dt_ms);
    let e = events(&[1.0, 0.7, 0.2, 0.98]);
    assert!(!held(&e, 0), "a valve at its stop");
    assert!(held(&e, 1), "a valve standing at 2.8 of 4 mm");
    assert!(held(&e, 2), "a valve standing at 0.8 of 4 mm");
    assert!(!held(&e, 3), "3.92 mm: within the stop's tolerance");
    // A command of 8 ms ends with the valve 5 mm up a 7.5 mm stroke, still opening at 1 mm/ms.
    let moving = events(&[1.9]);
    assert!(!moving.events[0].held_short_of_stroke(7.5, moving.dt_ms));
    // One that never moved while commanded.
    assert!(!held(&events(&[0.0]), 0));
}

/// Validation events held short of the stroke are left out of the scores when the
/// estimation log holds none, with their count, times and set-points said; kept when the
/// estimation log holds one, or when they would be most of the validation log.
#[test]
fn validation_events_in_a_regime_the_estimation_never_holds_are_left_out_and_named() {
    let family = EhvvaFamily::default();
    let est = trapezoid_log("est.csv", &[1.0, 1.0, 1.0, 1.0]);
    let val = trapezoid_log("val.csv", &[1.0, 0.7, 1.0, 0.6, 1.0]);
    let scope = family
        .validation_scope(&est, &val)
        .unwrap()
        .expect("two events left out");
    assert_eq!((scope.left_out, scope.of), (2, 5));
    // The kept rows are the first, third and fifth events whole (800 rows each).
    assert_eq!(scope.kept_rows.iter().map(|r| r.len()).sum::<usize>(), 3 * 800);
    assert!(scope
        .kept_rows
        .iter()
        .all(|r| !r.contains(&(800 + 400)) && !r.contains(&(3 * 800 + 400))));
    assert!(scope.reason.contains("0.042, 0.122 s"), "{}", scope.reason);
    assert!(scope.reason.contains("supply 6.00..6.00 MPa"), "{}", scope.reason);
    let kept = val.select_rows(&scope.kept_rows, "part".into());
    let part = Events::from_log(&kept).unwrap();
    assert_eq!(part.events.len(), 3);
    assert!(part.events.iter().all(|e| !e.held_short_of_stroke(4.0, part.dt_ms)));

    let est_holding_one = trapezoid_log("est.csv", &[1.0, 0.5, 1.0, 1.0]);
    assert_eq!(family.validation_scope(&est_holding_one, &val).unwrap(), None);
    let mostly_held = trapezoid_log("val.csv", &[0.7, 0.6, 1.0]);
    assert_eq!(family.validation_scope(&est, &mostly_held).unwrap(), None);
}
