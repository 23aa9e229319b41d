//! Tests of the EVVT plant (`evvt.rs`).

use super::*;
use crate::real::Q32;
use proptest::prelude::*;

/// Fine-step RK4 of the continuous model, the reference for the ZOH.
fn rk4(alpha: f64, beta: f64, t: f64, x0: (f64, f64), u: f64, n: usize) -> (f64, f64) {
    let f = |x: (f64, f64)| (x.1, -beta * x.1 + alpha * u);
    let h = t / n as f64;
    let mut x = x0;
    for _ in 0..n {
        let k1 = f(x);
        let k2 = f((x.0 + h / 2.0 * k1.0, x.1 + h / 2.0 * k1.1));
        let k3 = f((x.0 + h / 2.0 * k2.0, x.1 + h / 2.0 * k2.1));
        let k4 = f((x.0 + h * k3.0, x.1 + h * k3.1));
        x.0 += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        x.1 += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
    }
    x
}

/// Phase and rate of the plant in `R` and in f64 under the same piecewise-constant inputs
/// (command rpm, engine rpm, battery V per segment of 0.2 s in steps of `dt_s`); the
/// largest deviations (deg, deg/s), `None` when the f64 run came within 1 degree of a stop.
fn deviation_from_f64<R: Real>(segments: &[(f64, f64, f64)], dt_s: f64) -> Option<(f64, f64)> {
    let p = EvvtParams {
        initial_phase_deg: 20.0,
        ..EvvtParams::default()
    };
    let mut a = EvvtPlant::<R>::new(&p).unwrap();
    let mut b = EvvtPlant::<f64>::new(&p).unwrap();
    let (mut dev_phase, mut dev_rate) = (0.0f64, 0.0f64);
    let steps = libm::round(0.2 / dt_s) as usize;
    for &(u, n, v) in segments {
        for _ in 0..steps {
            let f = R::from_f64;
            let x = a.step(f(u), f(n), f(v), f(dt_s)).to_f64();
            let y = b.step(u, n, v, dt_s);
            if !(1.0..=39.0).contains(&y) {
                return None;
            }
            dev_phase = dev_phase.max((x - y).abs());
            dev_rate = dev_rate.max((a.phase_rate_deg_per_s().to_f64() - b.phase_rate_deg_per_s()).abs());
        }
    }
    Some((dev_phase, dev_rate))
}

proptest! {
    /// Q16.16 over the operating envelope (commands ±300 rpm, 800-7000 rpm engine speed,
    /// 9-16 V, 2 s from mid-range): within 0.1 % of the 40 degree phase range of f64.
    /// Runs that reach a stop are left out: the stop zeroes the rate, so a phase 1e-4
    /// degree short of it keeps a rate of tens of deg/s the other run lost (a difference
    /// not bounded by the state's). Steps of 10 ms (the nominal step: the prescaled
    /// tables), 5 ms (the general step, its products in range) and 40 ms (longer than
    /// 31 ms: the saturating products).
    #[test]
    fn q16_phase_tracks_f64_over_the_envelope(
        segments in proptest::collection::vec((-300.0f64..300.0, 800.0f64..7000.0, 9.0f64..16.0), 10),
        dt_s in proptest::sample::select(&[0.01, 0.005, 0.04][..]),
    ) {
        let dev = deviation_from_f64::<crate::real::Q16>(&segments, dt_s);
        prop_assume!(dev.is_some());
        let (dev_phase, dev_rate) = dev.unwrap_or_default();
        prop_assert!(dev_phase <= 0.04, "phase {dev_phase} deg, rate {dev_rate} deg/s");
    }
}

proptest! {
    /// The ZOH step equals the continuous solution under a held input, both branches
    /// (βT < 1 series, βT >= 1 closed form) and β = 0.
    #[test]
    fn zoh_matches_fine_integration(alpha in 0.01f64..2.0, beta in 0.0f64..200.0,
                                    t in 0.0005f64..0.05, x1 in -10.0f64..40.0,
                                    x2 in -50.0f64..50.0, u in -800.0f64..800.0) {
        let z = zoh(alpha, beta, t);
        let y1 = x1 + z.ad12_s * x2 + z.bd1_deg_per_rpm * u;
        let y2 = z.ad22 * x2 + z.bd2_deg_per_s_rpm * u;
        let (r1, r2) = rk4(alpha, beta, t, (x1, x2), u, 2000);
        prop_assert!((y1 - r1).abs() < 1e-9 * (1.0 + r1.abs()), "x1 {y1} vs {r1}");
        prop_assert!((y2 - r2).abs() < 1e-9 * (1.0 + r2.abs()), "x2 {y2} vs {r2}");
    }

    /// Series and closed form agree where they meet (βT = 2).
    #[test]
    fn zoh_continuous_across_branch(alpha in 0.05f64..1.0, t in 0.001f64..0.1) {
        let lo = zoh(alpha, (2.0 - 1e-9) / t, t);
        let hi = zoh(alpha, (2.0 + 1e-9) / t, t);
        prop_assert!((lo.bd1_deg_per_rpm - hi.bd1_deg_per_rpm).abs() <= 1e-8 * hi.bd1_deg_per_rpm);
        prop_assert!((lo.ad22 - hi.ad22).abs() < 1e-8);
    }

    /// f32 ZOH against f64 over both branches: relative error of Bd below 5e-5 (the
    /// closed-form branch inherits micromath's exp error, damped by the form of φ2).
    #[test]
    fn zoh_f32_close_to_f64(alpha in 0.05f64..1.0, beta in 0.0f64..100.0, t in 0.001f64..0.05) {
        let r = zoh(alpha, beta, t);
        let s = zoh(alpha as f32, beta as f32, t as f32);
        prop_assert!((s.bd1_deg_per_rpm as f64 - r.bd1_deg_per_rpm).abs() <= 5e-5 * r.bd1_deg_per_rpm);
        prop_assert!((s.bd2_deg_per_s_rpm as f64 - r.bd2_deg_per_s_rpm).abs() <= 5e-5 * r.bd2_deg_per_s_rpm);
        prop_assert!((s.ad22 as f64 - r.ad22).abs() <= 5e-5);
    }
}

#[test]
fn zoh_of_zero_beta_is_the_double_integrator() {
    let z = zoh(0.5f64, 0.0, 0.01);
    assert_eq!(z.ad22, 1.0);
    assert!((z.ad12_s - 0.01).abs() < 1e-15);
    assert!((z.bd1_deg_per_rpm - 0.5 * 0.01 * 0.01 / 2.0).abs() < 1e-15);
    assert!((z.bd2_deg_per_s_rpm - 0.5 * 0.01).abs() < 1e-15);
    // Negative inputs are clamped, not propagated.
    assert_eq!(zoh(0.5f64, -3.0, 0.01), z);
}

#[test]
fn zoh_in_fixed_point_matches_f64() {
    for &(a, b) in &[(0.595, 6.975), (0.07, 1.55), (0.27, 3.4)] {
        let r = zoh(a, b, 0.01);
        let q = zoh(Q32::from_f64(a), Q32::from_f64(b), Q32::from_f64(0.01));
        assert!((q.bd1_deg_per_rpm.to_f64() - r.bd1_deg_per_rpm).abs() < 1e-5 * r.bd1_deg_per_rpm);
        assert!((q.bd2_deg_per_s_rpm.to_f64() - r.bd2_deg_per_s_rpm).abs() < 1e-6 * r.bd2_deg_per_s_rpm);
        assert!((q.ad22.to_f64() - r.ad22).abs() < 1e-8);
    }
}

#[test]
fn table_honours_the_papers_text() {
    let a = PAPER_DESIGN_ALPHA;
    let b = PAPER_DESIGN_BETA;
    for i in 0..3 {
        for j in 0..2 {
            // Higher voltage → larger α and β at every speed.
            assert!(a[i][j + 1] > a[i][j] && b[i][j + 1] > b[i][j]);
        }
    }
    for i in 0..2 {
        // At 14 V faster with speed, at 9.5 V slower with speed.
        assert!(a[i + 1][2] > a[i][2] && b[i + 1][2] > b[i][2]);
        assert!(a[i + 1][0] < a[i][0] && b[i + 1][0] < b[i][0]);
    }
    let max_a = a.iter().flatten().fold(0.0f64, |m, &x| m.max(x));
    let max_b = b.iter().flatten().fold(0.0f64, |m, &x| m.max(x));
    assert_eq!((max_a, max_b), (0.595, 6.975)); // eqs. (13), (14)
                                                // Voltage has more influence than speed: the largest ratio over voltage at any speed
                                                // exceeds the largest ratio over speed at 14 V and 11.5 V.
    for j in 1..3 {
        let speed_ratio = a[2][j].max(a[0][j]) / a[2][j].min(a[0][j]);
        assert!(speed_ratio < 1.2, "speed ratio {speed_ratio} at voltage column {j}");
    }
    for row in a {
        assert!(row[2] / row[0] > 1.9);
    }
}

#[test]
fn rejects_bad_parameters_by_name() {
    let mut p = EvvtParams::default();
    p.lpv.beta_per_s[1][2] = -1.0;
    assert_eq!(
        EvvtPlant::<f32>::new(&p).unwrap_err(),
        EvvtParamError::BetaPerS {
            speed_index: 1,
            voltage_index: 2
        }
    );
    let mut p = EvvtParams::default();
    p.lpv.alpha_deg_per_s2_rpm[0][0] = f64::NAN;
    assert!(matches!(
        EvvtPlant::<f64>::new(&p),
        Err(EvvtParamError::AlphaDegPerS2Rpm { .. })
    ));
    let p = EvvtParams {
        advance_alpha_factor: 0.0,
        ..EvvtParams::default()
    };
    assert_eq!(
        EvvtPlant::<f64>::new(&p).unwrap_err(),
        EvvtParamError::AdvanceAlphaFactor
    );
    let p = EvvtParams {
        initial_phase_deg: 41.0,
        ..EvvtParams::default()
    };
    assert_eq!(EvvtPlant::<f64>::new(&p).unwrap_err(), EvvtParamError::InitialPhaseDeg);
    let mut p = EvvtParams::default();
    p.lpv.battery_voltage_v = [9.5, 9.5, 14.0];
    assert!(matches!(EvvtPlant::<f64>::new(&p), Err(EvvtParamError::Breakpoints(_))));
}

#[test]
fn zero_command_holds_the_phase_and_stops_clamp() {
    let p = EvvtParams {
        initial_phase_deg: 20.0,
        ..EvvtParams::default()
    };
    let mut plant = EvvtPlant::<f64>::new(&p).unwrap();
    for _ in 0..1000 {
        plant.step(0.0, 1100.0, 12.0, 0.01);
    }
    assert_eq!(plant.phase_deg(), 20.0);
    // Full advance command for 10 s: stops at 40 with zero rate, no overshoot past it.
    for _ in 0..1000 {
        let y = plant.step(1000.0, 1400.0, 14.0, 0.01);
        assert!(y <= 40.0);
    }
    assert_eq!(plant.phase_deg(), 40.0);
    assert_eq!(plant.phase_rate_deg_per_s(), 0.0);
    // Reversing leaves the stop at once.
    plant.step(-1000.0, 1400.0, 14.0, 0.01);
    assert!(plant.phase_deg() < 40.0 && plant.phase_rate_deg_per_s() < 0.0);
    for _ in 0..2000 {
        plant.step(-1000.0, 800.0, 9.5, 0.01);
    }
    assert_eq!((plant.phase_deg(), plant.phase_rate_deg_per_s()), (0.0, 0.0));
}

#[test]
fn steady_phase_rate_is_alpha_over_beta_times_command() {
    let mut plant = EvvtPlant::<f64>::new(&EvvtParams {
        initial_phase_deg: 0.0,
        ..Default::default()
    })
    .unwrap();
    for _ in 0..300 {
        plant.step(100.0, 800.0, 14.0, 0.01);
    }
    let expect = 100.0 * 0.54 / 6.2;
    assert!((plant.phase_rate_deg_per_s() - expect).abs() < 1e-3 * expect);
}

#[test]
fn effect_scales_switch_dependence_off() {
    let base = EvvtPlant::<f64>::new(&EvvtParams::baseline()).unwrap();
    let full = EvvtPlant::<f64>::new(&EvvtParams::default()).unwrap();
    // Baseline: the same α, β at every operating point, the table's value at 1100 rpm, 14 V.
    let near = |(a, b): (f64, f64), (ea, eb): (f64, f64)| (a - ea).abs() < 1e-12 && (b - eb).abs() < 1e-12;
    for &(n, v) in &[(800.0, 9.5), (1400.0, 14.0), (1100.0, 11.5), (600.0, 16.0)] {
        assert!(near(base.alpha_beta(n, v), (0.57, 6.6)));
    }
    assert!(near(full.alpha_beta(800.0, 9.5), (0.27, 3.4)));
    assert!(near(full.alpha_beta(1400.0, 14.0), (0.595, 6.975)));
    // Bilinear inside, clamped outside.
    let (a, _) = full.alpha_beta(950.0, 14.0);
    assert!((a - 0.555).abs() < 1e-12);
    assert!(near(full.alpha_beta(3000.0, 20.0), (0.595, 6.975)));
    assert!(near(full.alpha_beta(100.0, 5.0), (0.27, 3.4)));
}

#[test]
fn uniform_table_is_lti() {
    let p = EvvtParams {
        lpv: EvvtLpvTable::uniform(0.3, 4.0),
        ..EvvtParams::default()
    };
    let plant = EvvtPlant::<f64>::new(&p).unwrap();
    for &(n, v) in &[(800.0, 9.5), (1234.0, 12.3), (1400.0, 14.0)] {
        let (a, b) = plant.alpha_beta(n, v);
        assert!((a - 0.3).abs() < 1e-12 && (b - 4.0).abs() < 1e-12);
    }
}

#[test]
fn direction_effect_slows_advancing_only() {
    let p = EvvtParams {
        advance_alpha_factor: 0.7,
        initial_phase_deg: 20.0,
        ..EvvtParams::default()
    };
    let mut slow = EvvtPlant::<f64>::new(&p).unwrap();
    let mut sym = EvvtPlant::<f64>::new(&EvvtParams {
        initial_phase_deg: 20.0,
        ..EvvtParams::default()
    })
    .unwrap();
    for _ in 0..50 {
        slow.step(100.0, 1100.0, 14.0, 0.01);
        sym.step(100.0, 1100.0, 14.0, 0.01);
    }
    let ratio = (slow.phase_deg() - 20.0) / (sym.phase_deg() - 20.0);
    assert!((ratio - 0.7).abs() < 1e-9, "advance ratio {ratio}");
    slow.reset(20.0);
    sym.reset(20.0);
    for _ in 0..50 {
        slow.step(-100.0, 1100.0, 14.0, 0.01);
        sym.step(-100.0, 1100.0, 14.0, 0.01);
    }
    assert_eq!(slow.phase_deg(), sym.phase_deg());
}

/// Counts upward zero crossings of the belt disturbance over 2 s at two engine speeds: its
/// frequency is order × N / 60.
#[test]
fn belt_vibration_follows_engine_speed() {
    for &n in &[800.0, 1400.0] {
        let p = EvvtParams {
            belt_vibration_amplitude_deg: 0.8,
            belt_vibration_order: 0.5,
            initial_phase_deg: 20.0,
            ..EvvtParams::default()
        };
        let mut plant = EvvtPlant::<f32>::new(&p).unwrap();
        let (mut prev, mut crossings, mut peak) = (0.0f32, 0, 0.0f32);
        for _ in 0..2000 {
            let d = plant.step(0.0, n as f32, 14.0, 0.001) - 20.0;
            if prev < 0.0 && d >= 0.0 {
                crossings += 1;
            }
            peak = peak.max(d.abs());
            prev = d;
        }
        let expected = 0.5 * n / 60.0 * 2.0;
        assert!(
            (crossings as f64 - expected).abs() <= 1.0,
            "{crossings} crossings at {n} rpm"
        );
        assert!((peak - 0.8).abs() < 0.01);
    }
    // Off: no disturbance at all.
    let mut plant = EvvtPlant::<f64>::new(&EvvtParams {
        initial_phase_deg: 20.0,
        ..Default::default()
    })
    .unwrap();
    for _ in 0..100 {
        assert_eq!(plant.step(0.0, 1400.0, 14.0, 0.001), 20.0);
    }
}

#[test]
fn quantizer_rounds_to_one_degree() {
    assert_eq!(quantize_phase_deg(10.49f64, 1.0), 10.0);
    assert_eq!(quantize_phase_deg(10.5f64, 1.0), 11.0);
    assert_eq!(quantize_phase_deg(-0.6f32, 1.0), -1.0);
    assert_eq!(quantize_phase_deg(Q32::from_f64(29.7), Q32::ONE), Q32::from_f64(30.0));
    assert_eq!(quantize_phase_deg(3.3f64, 0.0), 3.3);
}

#[test]
fn planetary_relation_eq_11() {
    let g = PlanetaryGear::default();
    assert_eq!(g.ratio(), 3.5);
    // Ring at half crank speed; carrier at ring speed holds the phase.
    let ring = PlanetaryGear::ring_speed_rpm(1600.0f64);
    assert_eq!(ring, 800.0);
    assert_eq!(g.phase_rate_deg_per_s(ring, ring), 0.0);
    // 1 rpm carrier over ring: 6 deg/s at the carrier, × 3.5 at the sun, × 2 in crank deg.
    assert!((g.phase_rate_deg_per_s(801.0, 800.0) - 42.0).abs() < 1e-12);
    assert!(g.phase_rate_deg_per_s(799.0, 800.0) < 0.0);
    // Inverse: the motor speed for a requested rate reproduces the rate.
    let m = g.motor_speed_for_phase_rate_rpm(-21.0f64, 1600.0);
    assert!((m - 799.5).abs() < 1e-12);
    assert!((g.phase_rate_deg_per_s(m, ring) + 21.0).abs() < 1e-12);
    // Integrating eq. (11) for 0.5 s at +0.2 rpm difference gives 0.5 × 0.2 × 42 = 4.2 deg.
    let mut phase = 0.0;
    for _ in 0..500 {
        phase += g.phase_rate_deg_per_s(ring + 0.2, ring) * 0.001;
    }
    assert!((phase - 4.2).abs() < 1e-9);
}
