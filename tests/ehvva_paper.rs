//! The EHVVA models held to Li, Huang, Zhu, Lou 2018 (ehvva-lpv-model-li-2018.txt): Table 3
//! opening times, Table 4 temperature trends, the snubber's seating (Sec. 2, Fig. 2/8), the
//! back-pressure closing tail (Fig. 10), LPV vs reduced vs ninth-order agreement over the 15
//! tests of Table 1, and the number-type deviations (f64 vs f32 vs Q32.32).
//!
//! Definitions used throughout:
//! - opening / closing time: 1 % to 99 % of the stroke (Sec. 2, as for Fig. 2's 3.7/2.8 ms);
//!   Table 3 and Table 4's "VO time" are read this way (the delay is listed separately).
//! - full closing time: command off to the valve seated (lift 0).
//! - MRE: mean |lift error| over the valve event (command on to command off + 12 ms) divided
//!   by the stroke, in %.

use model_core::ehvva::*;
use model_core::{Real, Q32};

const DT_MS: f64 = 0.02;

fn stroke(t: &PaperTest) -> f64 {
    if t.lift_high {
        7.5
    } else {
        4.0
    }
}

fn test_no(n: u8) -> PaperTest {
    *PAPER_TESTS.iter().find(|t| t.number == n).unwrap()
}

fn metrics(p: &EhvvaParams, t: &PaperTest) -> EventMetrics {
    let inputs = EhvvaInputs::<f64>::from_test(t);
    let mut m = EhvvaReduced::<f64>::new(p, &inputs, DT_MS).unwrap();
    run_event(
        &mut m,
        &ValveEvent::with_dwell(t.dwell_ms),
        &inputs,
        stroke(t),
        |_, _| {},
    )
}

/// Lift trace of the reduced model in number type `R`, plus the accumulator pressures before
/// every step (the "measured" Ph, Pl the LPV model is scheduled on).
struct Run {
    lift: Vec<f64>,
    p_high: Vec<f64>,
    p_low: Vec<f64>,
}

fn command(k: usize, ev: &ValveEvent) -> bool {
    let t = k as f64 * DT_MS + 1e-9;
    t >= ev.t_open_ms && t < ev.t_open_ms + ev.dwell_ms
}

fn run_reduced<R: Real>(p: &EhvvaParams, t: &PaperTest) -> Run {
    let inputs = EhvvaInputs::<R>::from_test(t);
    let mut m = EhvvaReduced::<R>::new(p, &inputs, DT_MS).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    let n = (ev.t_end_ms / DT_MS) as usize;
    let mut run = Run {
        lift: vec![],
        p_high: vec![],
        p_low: vec![],
    };
    for k in 0..n {
        run.p_high.push(m.p_high_mpa().to_f64());
        run.p_low.push(m.p_low_mpa().to_f64());
        run.lift.push(m.step(command(k, &ev), &inputs).to_f64());
    }
    run
}

fn run_lpv(p: &EhvvaParams, t: &PaperTest, measured: &Run) -> Vec<f64> {
    let base = EhvvaInputs::<f64>::from_test(t);
    let mut m = EhvvaLpv::<f64>::new(p, &base, DT_MS).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    (0..measured.lift.len())
        .map(|k| {
            let inputs = EhvvaInputs {
                p_supply_mpa: measured.p_high[k],
                p_back_mpa: measured.p_low[k],
                ..base
            };
            m.step(command(k, &ev), &inputs)
        })
        .collect()
}

fn times(n: usize) -> Vec<f64> {
    (0..n).map(|k| (k + 1) as f64 * DT_MS).collect()
}

fn mre(t: &PaperTest, a: &[f64], b: &[f64]) -> f64 {
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    let ts = times(a.len());
    mean_relative_error_pct(&ts, a, b, ev.t_open_ms, ev.t_open_ms + ev.dwell_ms + 12.0, stroke(t))
}

#[test]
fn table3_opening_times_within_15_percent() {
    let p = EhvvaParams::paper_default();
    // (test number, Table 3 opening time): low lift tests 1-3, high lift tests 4-6.
    let table3 = [(1u8, 4.0), (2, 3.1), (3, 2.7), (4, 5.2), (5, 3.8), (6, 3.6)];
    for (n, paper_ms) in table3 {
        let m = metrics(&p, &test_no(n));
        let model_ms = m.opening_time_ms().expect("valve did not open fully");
        let err = (model_ms - paper_ms) / paper_ms;
        println!(
            "test {n}: opening {model_ms:.2} ms, paper {paper_ms} ms ({:+.1} %)",
            100.0 * err
        );
        assert!(err.abs() <= 0.15, "test {n}: {model_ms:.2} ms vs {paper_ms} ms");
    }
    // Supply pressure is the key factor (Sec. 5.3): strictly faster with Ph in both lifts.
    for ns in [[1u8, 2, 3], [4, 5, 6]] {
        let t: Vec<f64> = ns
            .iter()
            .map(|&n| metrics(&p, &test_no(n)).opening_time_ms().unwrap())
            .collect();
        assert!(t[0] > t[1] && t[1] > t[2], "{t:?}");
    }
}

#[test]
fn table4_temperature_trends_at_5_mpa() {
    let p = EhvvaParams::paper_default();
    let tables = EhvvaTables::<f64>::new(&p).unwrap();
    // Tests 8-11: -20, 22, 60, 100 °C.
    let ms: Vec<EventMetrics> = [8u8, 9, 10, 11].iter().map(|&n| metrics(&p, &test_no(n))).collect();
    let temps = [-20.0, 22.0, 60.0, 100.0];
    for i in 0..3 {
        // VO delay (table, and as measured from command to 1 % lift) and VO time grow as T falls.
        assert!(tables.t_delay_ms(5.0, temps[i], true) > tables.t_delay_ms(5.0, temps[i + 1], true));
        let d = |m: &EventMetrics| m.opening_delay_ms().unwrap();
        let o = |m: &EventMetrics| m.opening_time_ms().unwrap();
        assert!(
            d(&ms[i]) > d(&ms[i + 1]),
            "VO delay at {} vs {} °C",
            temps[i],
            temps[i + 1]
        );
        assert!(
            o(&ms[i]) > o(&ms[i + 1]),
            "VO time at {} vs {} °C",
            temps[i],
            temps[i + 1]
        );
    }
    let vc: Vec<f64> = ms.iter().map(|m| m.closing_time_ms().unwrap()).collect();
    let vo: Vec<f64> = ms.iter().map(|m| m.opening_time_ms().unwrap()).collect();
    println!("VO time {vo:.2?} (paper 8.2 6.2 4.8 4.4), VC time {vc:.2?} (paper 4.0 3.5 3.0 2.8)");
    // VC time nearly flat above 22 °C (paper: 3.5 -> 2.8 ms, -20 %) while opening moves more at
    // the cold end; cold (-20 °C) closing is clearly slower.
    assert!((vc[1] - vc[3]).abs() / vc[1] < 0.25, "VC 22 -> 100 °C: {vc:?}");
    assert!(vc[0] > 1.2 * vc[1], "VC at -20 °C not slower: {vc:?}");
    // The cold end slows the opening clearly (paper: +32 % from 22 to -20 °C). Weaker than the
    // paper: above 22 °C the model's opening moves by only ~5 % (paper 29 %), see the report.
    assert!(vo[0] > 1.15 * vo[1], "VO at -20 °C: {vo:?}");
}

#[test]
fn snubber_switch_lowers_seating_velocity_and_adds_a_tail() {
    let p = EhvvaParams::paper_default();
    // Test 6 (switch on) and test 7 (switch off): 8 MPa, high lift (Fig. 8).
    let on = metrics(&p, &test_no(6));
    let off = metrics(&p, &test_no(7));
    let v_on = on.seating_velocity_m_s.unwrap();
    let v_off = off.seating_velocity_m_s.unwrap();
    let tail = on.full_closing_ms().unwrap() - off.full_closing_ms().unwrap();
    println!("seating {v_on:.3} m/s (on) vs {v_off:.3} m/s (off), tail {tail:.2} ms");
    // Paper (Sec. 2): 0.25 vs 0.69 m/s (0.22 m/s in test 6, Sec. 5.3), about 1 ms tail.
    assert!((0.18..=0.32).contains(&v_on), "switch on {v_on}");
    assert!((0.55..=0.85).contains(&v_off), "switch off {v_off}");
    assert!((0.6..=1.5).contains(&tail), "tail {tail}");
    // Without the snubbing zone the valve seats hard whatever the switch.
    let mut bare = p;
    bare.effect_snubber = 0.0;
    let v_bare = metrics(&bare, &test_no(6)).seating_velocity_m_s.unwrap();
    println!("no snubbing zone, switch on: seating {v_bare:.3} m/s");
    assert!(v_bare > 3.0 * v_on && v_bare > 1.4 * v_off, "no snubber: {v_bare}");
}

#[test]
fn back_pressure_delays_full_closing() {
    let p = EhvvaParams::paper_default();
    // Tests 12-15: 8 MPa, 20 ms dwell, high lift, switch on, Pl = 1..4 MPa.
    let full: Vec<f64> = [12u8, 13, 14, 15]
        .iter()
        .map(|&n| metrics(&p, &test_no(n)).full_closing_ms().unwrap())
        .collect();
    println!("full closing {full:.2?} ms at Pl = 1..4 MPa");
    for i in 0..3 {
        assert!(full[i + 1] > full[i], "{full:?}");
    }
    let delay = full[3] - full[0];
    // Fig. 10: about 7 ms later at 4 MPa.
    assert!((5.0..=9.0).contains(&delay), "closing delayed by {delay:.2} ms");
}

#[test]
fn lpv_tracks_reduced_model_within_2_percent() {
    let p = EhvvaParams::paper_default();
    let mut worst: f64 = 0.0;
    for t in PAPER_TESTS.iter() {
        let red = run_reduced::<f64>(&p, t);
        let lpv = run_lpv(&p, t, &red);
        let e = mre(t, &red.lift, &lpv);
        println!("test {}: LPV vs reduced MRE {e:.3} %", t.number);
        assert!(e < 2.0, "test {}: {e} %", t.number);
        worst = worst.max(e);
    }
    println!("worst LPV MRE {worst:.3} %");
}

fn run_lpv_in<R: Real>(p: &EhvvaParams, t: &PaperTest, measured: &Run) -> Vec<f64> {
    let base = EhvvaInputs::<R>::from_test(t);
    let mut m = EhvvaLpv::<R>::new(p, &base, DT_MS).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    (0..measured.lift.len())
        .map(|k| {
            let inputs = EhvvaInputs {
                p_supply_mpa: R::from_f64(measured.p_high[k]),
                p_back_mpa: R::from_f64(measured.p_low[k]),
                ..base
            };
            m.step(command(k, &ev), &inputs).to_f64()
        })
        .collect()
}

fn run_full_in<R: Real>(p: &EhvvaParams, t: &PaperTest) -> Vec<f64> {
    let inputs = EhvvaInputs::<R>::from_test(t);
    let mut m = EhvvaFull::<R>::new(p, &inputs, DT_MS).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    let n = (ev.t_end_ms / DT_MS) as usize;
    (0..n).map(|k| m.step(command(k, &ev), &inputs).to_f64()).collect()
}

fn max_dev(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn number_types_agree() {
    // Largest lift deviation from the f64 run over the 15 tests of Table 1, per model.
    // Measured (f32, Q32): reduced 4.5e-5 / 3.2e-5 mm, LPV 1.1e-4 / 1.2e-6 mm, ninth-order
    // 4.1e-5 / 3.2e-5 mm; the asserted 1e-3 mm leaves a margin of about 10.
    let p = EhvvaParams::paper_default();
    let mut dev = [[0.0f64; 2]; 3];
    for t in PAPER_TESTS.iter() {
        let r64 = run_reduced::<f64>(&p, t);
        dev[0][0] = dev[0][0].max(max_dev(&run_reduced::<f32>(&p, t).lift, &r64.lift));
        dev[0][1] = dev[0][1].max(max_dev(&run_reduced::<Q32>(&p, t).lift, &r64.lift));
        let l64 = run_lpv_in::<f64>(&p, t, &r64);
        dev[1][0] = dev[1][0].max(max_dev(&run_lpv_in::<f32>(&p, t, &r64), &l64));
        dev[1][1] = dev[1][1].max(max_dev(&run_lpv_in::<Q32>(&p, t, &r64), &l64));
        let f64_run = run_full_in::<f64>(&p, t);
        dev[2][0] = dev[2][0].max(max_dev(&run_full_in::<f32>(&p, t), &f64_run));
        dev[2][1] = dev[2][1].max(max_dev(&run_full_in::<Q32>(&p, t), &f64_run));
    }
    for (name, d) in ["reduced", "LPV", "ninth-order"].iter().zip(dev) {
        println!(
            "{name}: largest lift deviation from f64: f32 {:.3e} mm, Q32.32 {:.3e} mm",
            d[0], d[1]
        );
    }
    for d in dev {
        assert!(d[0] < 1e-3 && d[1] < 1e-3, "{dev:?}");
    }
}

fn run_full(p: &EhvvaParams, t: &PaperTest) -> Vec<f64> {
    let inputs = EhvvaInputs::<f64>::from_test(t);
    let mut m = EhvvaFull::<f64>::new(p, &inputs, DT_MS).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    let n = (ev.t_end_ms / DT_MS) as usize;
    (0..n).map(|k| m.step(command(k, &ev), &inputs)).collect()
}

#[test]
fn reduced_model_tracks_ninth_order_within_5_percent() {
    let p = EhvvaParams::paper_default();
    let mut worst: f64 = 0.0;
    for t in PAPER_TESTS.iter() {
        let red = run_reduced::<f64>(&p, t);
        let full = run_full(&p, t);
        let e = mre(t, &red.lift, &full);
        println!("test {}: reduced vs ninth-order MRE {e:.3} %", t.number);
        assert!(e < 5.0, "test {}: {e} %", t.number);
        worst = worst.max(e);
    }
    println!("worst reduced-vs-ninth-order MRE {worst:.3} %");
}

#[test]
fn ninth_order_actuation_chain_behaves() {
    // Solenoid, pilot and main spool (eqs. (2)-(4)): the coil current rises towards U/R, the
    // pilot spool and then the main spool reach their strokes, and all fall back after the
    // command ends; the piston opens only after the main valve has switched.
    let p = EhvvaParams::paper_default();
    let t = test_no(6);
    let inputs = EhvvaInputs::<f64>::from_test(&t);
    let mut m = EhvvaFull::<f64>::new(&p, &inputs, DT_MS).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    let mut first_lift_k = None;
    let mut main_open_k = None;
    let mut max_current: f64 = 0.0;
    for k in 0..((ev.t_end_ms / DT_MS) as usize) {
        let y = m.step(command(k, &ev), &inputs);
        max_current = max_current.max(m.current_a());
        if main_open_k.is_none() && m.main_opening() >= 1.0 {
            main_open_k = Some(k);
        }
        if first_lift_k.is_none() && y > 0.0 {
            first_lift_k = Some(k);
        }
        assert!(m.pilot_mm() >= 0.0 && m.pilot_mm() <= p.valve.pilot_stroke_mm + 1e-12);
        assert!(m.main_mm() >= 0.0 && m.main_mm() <= p.valve.main_stroke_mm + 1e-12);
    }
    let i_max = p.valve.coil_voltage_v / p.valve.coil_resistance_ohm;
    assert!(
        max_current > 0.9 * i_max && max_current <= i_max + 1e-9,
        "{max_current}"
    );
    assert!(main_open_k.unwrap() < first_lift_k.unwrap());
    assert!(m.current_a() < 0.01 && m.pilot_mm() == 0.0 && m.main_mm() == 0.0 && m.lift_mm() == 0.0);
}

#[test]
fn effect_knobs_switch_their_effect_off() {
    // DATA-FORMAT.md, plant `ehvva`: each catalogue effect is a parameter that turns it off.
    let on = EhvvaParams::paper_default();
    let cold = test_no(8);
    let hot = test_no(11);
    let open_time = |p: &EhvvaParams, t: &PaperTest| metrics(p, t).opening_time_ms().unwrap();
    // viscosity: with Cd frozen at 22 °C, the 1-99 % opening no longer depends on temperature
    // (τp moves by under 4 %), with it on the cold valve is clearly slower.
    let mut off = on;
    off.effect_viscosity = 0.0;
    let spread_on = open_time(&on, &cold) - open_time(&on, &hot);
    let spread_off = (open_time(&off, &cold) - open_time(&off, &hot)).abs();
    println!("viscosity: cold-hot opening spread {spread_on:.2} ms on, {spread_off:.2} ms off");
    assert!(spread_on > 1.0 && spread_off < 0.1 * spread_on);
    // pressure-delay: the command-to-motion delay shrinks with Ph only while it is on.
    let delay = |p: &EhvvaParams, n: u8| metrics(p, &test_no(n)).opening_delay_ms().unwrap();
    let mut off = on;
    off.effect_pressure_delay = 0.0;
    let d_on = delay(&on, 1) - delay(&on, 3);
    let d_off = delay(&off, 1) - delay(&off, 3);
    println!("pressure-delay: 6 vs 8 MPa delay difference {d_on:.2} ms on, {d_off:.2} ms off");
    assert!(d_on > d_off + 0.4);
    // direction-delay: off, the closing edge waits as long as the opening edge.
    let mut off = on;
    off.effect_direction_delay = 0.0;
    let tb = EhvvaTables::<f64>::new(&off).unwrap();
    assert_eq!(tb.t_delay_ms(7.0, 22.0, true), tb.t_delay_ms(7.0, 22.0, false));
    let gap = |p: &EhvvaParams| {
        let m = metrics(p, &test_no(2));
        m.opening_delay_ms().unwrap() - m.closing_delay_ms().unwrap()
    };
    println!(
        "direction-delay: open-close delay gap {:.2} ms on, {:.2} ms off",
        gap(&on),
        gap(&off)
    );
    assert!(gap(&on) > gap(&off) + 0.3);
    // snubber: off, the switch valve hardly changes the seating velocity any more (its orifice
    // is then only a small part of the fully uncovered top area); on, it divides it by ~3.
    let mut off = on;
    off.effect_snubber = 0.0;
    let ratio = |p: &EhvvaParams| {
        metrics(p, &test_no(7)).seating_velocity_m_s.unwrap() / metrics(p, &test_no(6)).seating_velocity_m_s.unwrap()
    };
    println!(
        "snubber: seating velocity switch off/on {:.2} with the zone, {:.2} without",
        ratio(&on),
        ratio(&off)
    );
    assert!(ratio(&on) > 2.0 && ratio(&off) < 1.3);
}

#[test]
fn lpv_affine_data_matches_the_simulated_model() {
    // The controller designer's A(θ), B(θ) are the ones the simulation integrates: rebuild the
    // derivative from the exposed matrices at the model's own θ and compare it with a finite
    // difference of the state over one small step in free flight.
    let p = EhvvaParams::paper_default();
    let t = test_no(5);
    let inputs = EhvvaInputs::<f64>::from_test(&t);
    let dt = 0.001;
    let mut m = EhvvaLpv::<f64, 8192>::new(&p, &inputs, dt).unwrap();
    let ev = ValveEvent::with_dwell(t.dwell_ms);
    // Run to mid-stroke of the opening.
    let mut k = 0usize;
    loop {
        let u = (k as f64 * dt + 1e-9) >= ev.t_open_ms;
        let y = m.step(u, &inputs);
        k += 1;
        if y > 3.0 {
            break;
        }
        assert!(k < 20_000, "never opened");
    }
    let x0 = m.state();
    m.step(true, &inputs);
    let x1 = m.state();
    let th = m.theta();
    let aff = LpvAffine::<f64>::from_params(&p).unwrap();
    let a = aff.a_matrix(&th);
    let b = aff.b_matrix(&th);
    let u = [1.0, 0.0];
    for row in 0..3 {
        let rate: f64 = (0..3).map(|c| a[row][c] * x1[c]).sum::<f64>() + b[row][0] * u[0] + b[row][1] * u[1];
        let fd = (x1[row] - x0[row]) / dt;
        assert!(
            (rate - fd).abs() <= 0.02 * fd.abs().max(1.0),
            "row {row}: A x + B u = {rate}, Δx/Δt = {fd}"
        );
    }
    // θ1 = 1/τp, θ3 = P̃h/τp, θ5 = Pl (eq. (15)).
    assert!((th[2] / th[0] - t.p_supply_mpa).abs() < 1e-9 && (th[4] - t.p_back_mpa).abs() < 1e-12);
}
