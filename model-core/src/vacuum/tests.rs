//! Tests of the vacuum valve, actuator, tank and pump (`vacuum.rs`).

use super::*;
use crate::real::{Q16, Q32};
use proptest::prelude::*;

fn inp<R: Real>(duty: f64, u: f64, p_tank: f64) -> VacuumInputs<R> {
    VacuumInputs {
        duty_pct: R::from_f64(duty),
        u_batt_v: R::from_f64(u),
        p_amb_kpa: R::from_f64(100.0),
        p_tank_kpa: R::from_f64(p_tank),
    }
}

fn psi_reference(ratio: f64) -> f64 {
    let r = ratio.max(P_CRIT);
    libm::sqrt(7.0 * (libm::pow(r, 10.0 / 7.0) - libm::pow(r, 12.0 / 7.0)))
}

/// Ψ² as the fixed-point form evaluates it, in f64, within the polynomial's stated error of
/// the exact Ψ² over [Π_crit, 1].
#[test]
fn psi_squared_polynomial_is_within_its_stated_error() {
    let mut worst = 0.0f64;
    for i in 0..=2000 {
        let ratio = P_CRIT + (1.0 - P_CRIT) * i as f64 / 2000.0;
        let w = (2.0 * ratio - P_CRIT - 1.0) / (1.0 - P_CRIT);
        let poly = PSI_SQ_POLY.iter().rev().fold(0.0, |s, c| c + w * s);
        worst = worst.max((poly - psi_reference(ratio).powi(2)).abs());
    }
    assert!(worst < 4.5e-7, "largest error {worst}");
}

fn check_psi<R: Real>(tol: f64) {
    for i in 0..=40 {
        let ratio = i as f64 / 40.0;
        let got = psi(R::from_f64(ratio.max(P_CRIT))).to_f64();
        let want = psi_reference(ratio);
        assert!(
            (got - want).abs() < tol,
            "{}: psi({ratio}) = {got}, want {want}",
            R::NAME
        );
    }
}

#[test]
fn orifice_flow_follows_eq3_and_chokes() {
    // Ψ at the critical ratio for γ = 1.4 is 0.6847.
    assert!((psi_reference(P_CRIT) - 0.6847).abs() < 1e-4);
    check_psi::<f64>(1e-12);
    check_psi::<f32>(2e-5);
    check_psi::<Q32>(1e-6);
    // Q16.16: near Π = 1, where Ψ² is a few LSB, Ψ is their root (measured 3.5e-4 with the
    // polynomial, 1.5e-3 with ln and exp in Q16.16).
    check_psi::<Q16>(5e-4);
    let c = 1e3 / libm::sqrt(R_AIR_J_PER_KG_K * 293.0);
    // Choked: independent of the downstream pressure below 52.8 kPa for 100 kPa upstream.
    let choked = orifice_flow_mg_s(100.0, 30.0, 0.02, c);
    assert_eq!(choked, orifice_flow_mg_s(100.0, 10.0, 0.02, c));
    assert!((choked - c * 100.0 * 0.02 * 0.6847).abs() < 1e-3 * choked);
    // Unchoked flow falls to zero at equal pressures and reverses with them.
    assert!(orifice_flow_mg_s(100.0, 80.0, 0.02, c) < choked);
    assert_eq!(orifice_flow_mg_s(60.0, 60.0, 0.02, c), 0.0);
    assert_eq!(
        orifice_flow_mg_s(40.0, 70.0, 0.02, c),
        -orifice_flow_mg_s(70.0, 40.0, 0.02, c)
    );
}

#[test]
fn series_helpers_match_libm() {
    // Error of tan relative to max(1, |tan|): the floats' double-angle steps amplify rounding
    // near 1.5 rad (tan = 14), where the arctan spring is steepest.
    let mut tan_err = [0.0f64; 4];
    for i in -300..=300 {
        let th = 1.5 * i as f64 / 300.0;
        // Against tan of the angle as the type holds it (Q16.16's 2^-16 rad alone moves
        // tan(1.5) by 1e-4 relative).
        let rel = |th_held: f64, got: f64| {
            let want = libm::tan(th_held);
            (got - want).abs() / want.abs().max(1.0)
        };
        let (t32, q32, q16) = (th as f32, Q32::from_f64(th), Q16::from_f64(th));
        tan_err[0] = tan_err[0].max(rel(th, Real::tan(th)));
        tan_err[1] = tan_err[1].max(rel(t32 as f64, Real::tan(t32) as f64));
        tan_err[2] = tan_err[2].max(rel(q32.to_f64(), q32.tan().to_f64()));
        tan_err[3] = tan_err[3].max(rel(q16.to_f64(), q16.tan().to_f64()));
    }
    let mut exp_err = [0.0f64; 4];
    for x in [0.0, 1e-4, 0.025, 0.3, 0.49, 0.5, 2.0, 10.0] {
        let want = -libm::expm1(-x);
        exp_err[0] = exp_err[0].max((one_minus_exp_neg(x) - want).abs());
        exp_err[1] = exp_err[1].max((one_minus_exp_neg(x as f32) as f64 - want).abs());
        exp_err[2] = exp_err[2].max((one_minus_exp_neg(Q32::from_f64(x)).to_f64() - want).abs());
        exp_err[3] = exp_err[3].max((one_minus_exp_neg(Q16::from_f64(x)).to_f64() - want).abs());
    }
    extern crate std;
    std::println!("tan error f64/f32/Q32/Q16 {tan_err:?}, 1 - exp(-x) error {exp_err:?}");
    // Measured: tan 1.8e-9 / 1.1e-6 / 2.6e-8 / 7.6e-6 (Q16.16's Hermite table, half an
    // LSB; the generic series in Q16.16 had 8.2e-4), 1 − e^(−x) 1e-20 / 1.9e-8 / 3.2e-10 /
    // 9.1e-6.
    assert!(
        tan_err[0] < 5e-9 && tan_err[1] < 3e-6 && tan_err[2] < 5e-8 && tan_err[3] < 2e-5,
        "{tan_err:?}"
    );
    assert!(
        exp_err[0] < 1e-13 && exp_err[1] < 1e-7 && exp_err[2] < 1e-9 && exp_err[3] < 2e-5,
        "{exp_err:?}"
    );
}

#[test]
fn supply_voltage_knob_scales_the_duty_or_not() {
    let p = VacuumParams::lpt();
    let on = VacuumValveActuator::<f64>::new(&p).unwrap();
    let off = VacuumValveActuator::<f64>::new(&p.baseline()).unwrap();
    for duty in [30.0, 50.0, 70.0] {
        for u in [10.0, 11.0, 13.5] {
            // Eq. (1): the valve at U sees duty·U/U_ref.
            let seen = on.static_pressure_kpa(&inp(duty, u, 20.0));
            let at_ref = on.static_pressure_kpa(&inp(duty * u / p.u_ref_v, p.u_ref_v, 20.0));
            assert!((seen - at_ref).abs() < 1e-9);
            assert_eq!(
                off.static_pressure_kpa(&inp(duty, u, 20.0)),
                off.static_pressure_kpa(&inp(duty, 12.0, 20.0))
            );
        }
        // Lower voltage, less effective duty, higher pressure (Fig. 16).
        assert!(on.static_pressure_kpa(&inp(duty, 10.0, 20.0)) > on.static_pressure_kpa(&inp(duty, 12.0, 20.0)));
    }
}

#[test]
fn settled_state_is_a_fixed_point() {
    for p in [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()] {
        let mut a = VacuumValveActuator::<f64>::new(&p).unwrap();
        let i = inp(60.0, 12.0, 25.0);
        a.settle(&i);
        let (p0, x0) = (a.p_act_kpa(), a.x_pct());
        for _ in 0..2000 {
            a.step(&i, 0.001);
        }
        assert!(
            (a.p_act_kpa() - p0).abs() < 1e-9 && (a.x_pct() - x0).abs() < 1e-6,
            "{} {} vs {p0} {x0}",
            a.p_act_kpa(),
            a.x_pct()
        );
    }
}

#[test]
fn evacuation_flow_carries_the_chambers_mass_change() {
    // Eq. (12): with the plunger leakage off, the mass sent to the tank during a step from
    // ambient to low pressure equals (p0·V0 − p1·V1)/(R·T).
    let mut p = VacuumParams::lpt();
    p.leak_area_mm2_per_pct = 0.0;
    let mut a = VacuumValveActuator::<f64>::new(&p).unwrap();
    a.settle(&inp(0.0, 12.0, 20.0));
    let volume = |x: f64| p.volume_x0_l - p.volume_stroke_l * x / 100.0;
    let pv0 = a.p_act_kpa() * volume(a.x_membrane_pct());
    let mut mass_mg = 0.0;
    for _ in 0..1000 {
        mass_mg += a.step(&inp(100.0, 12.0, 20.0), 0.001).flow_to_tank_mg_s * 0.001;
    }
    let pv1 = a.p_act_kpa() * volume(a.x_membrane_pct());
    let expected = (pv0 - pv1) * 1e6 / (R_AIR_J_PER_KG_K * p.temp_amb_k);
    assert!(a.x_membrane_pct() > 99.0, "the membrane should be at its stop");
    assert!(
        (mass_mg - expected).abs() < 1e-9 * expected,
        "{mass_mg} vs {expected} mg"
    );
    // Venting back does not push anything into the tank.
    let back: f64 = (0..1000)
        .map(|_| a.step(&inp(0.0, 12.0, 20.0), 0.001).flow_to_tank_mg_s)
        .sum();
    assert_eq!(back, 0.0);
}

/// x_pct is the valve's own travel: with a linkage clearance the valve still reaches its
/// seat (0 %) and its stop (100 %), the membrane taking up the play beyond them; before,
/// the membrane stopped at the valve's stops and the valve half the clearance short.
#[test]
fn a_valve_with_clearance_reaches_both_stops() {
    let mut p = VacuumParams::lpt();
    p.backlash_pct = 8.0;
    p.effects.backlash = true;
    let mut a = VacuumValveActuator::<f64>::new(&p).unwrap();
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for duty in [0.0, 100.0, 0.0] {
        for _ in 0..3000 {
            let o = a.step(&inp(duty, 13.5, 20.0), 0.001);
            lo = lo.min(o.x_pct);
            hi = hi.max(o.x_pct);
        }
    }
    assert_eq!((lo, hi), (0.0, 100.0), "the valve's travel with 8 % clearance");
}

proptest! {
    /// Whatever the duty sequence: the Dahl friction never exceeds Fc, the valve stays on its
    /// stroke and the membrane within half the clearance beyond it, the valve stays within
    /// half the clearance of the membrane, and the pressure stays between tank and ambient.
    #[test]
    fn states_stay_physical(duties in proptest::collection::vec(0.0f64..100.0, 1..40), u in 8.0f64..16.0) {
        let p = VacuumParams::hpc();
        let mut a = VacuumValveActuator::<f64>::new(&p).unwrap();
        for d in duties {
            for _ in 0..50 {
                let o = a.step(&inp(d, u, 30.0), 0.002);
                prop_assert!(a.friction_kpa().abs() <= p.fc_kpa + 1e-9);
                let half = 0.5 * p.backlash_pct;
                prop_assert!((-half..=100.0 + half).contains(&o.x_membrane_pct) && (0.0..=100.0).contains(&o.x_pct));
                prop_assert!((o.x_pct - o.x_membrane_pct).abs() <= 0.5 * p.backlash_pct + 1e-9);
                prop_assert!((30.0 - 1e-9..=100.0 + 1e-9).contains(&o.p_act_kpa));
                prop_assert!(o.flow_to_tank_mg_s >= 0.0);
            }
        }
    }
}

/// `advance` is `step` without the flows, `advance_pressure` its pressure alone; the rod
/// step is a setting: the default reproduced exactly, a coarser one close, bad ones named.
#[test]
fn advance_and_rod_step_settings_keep_the_model() {
    // Ramps up over 1.5 s and steps down: 25..100 % reaches every preset's travel.
    let duty = |k: usize| {
        if (k / 150).is_multiple_of(2) {
            25.0 + (k % 150) as f64 * 0.5
        } else {
            100.0 - (k % 90) as f64
        }
    };
    for p in [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()] {
        let base = VacuumValveActuator::<f64>::new(&p).unwrap();
        assert_eq!(base.rod_step_s(), 0.0005);
        let (mut stepped, mut advanced, mut pressure_only) = (base, base, base);
        let mut same_step = base.with_rod_step_s(0.0005).unwrap();
        let mut coarse = base.with_rod_step_s(0.002).unwrap();
        let mut dev_coarse = 0.0f64;
        let mut span = (f64::MAX, f64::MIN);
        for k in 0..1500 {
            let i = inp(duty(k), 11.0 + (k % 7) as f64 * 0.3, 25.0);
            let o = stepped.step(&i, 0.01);
            advanced.advance(&i, 0.01);
            same_step.step(&i, 0.01);
            coarse.advance(&i, 0.01);
            let x_before = pressure_only.x_pct();
            assert_eq!(pressure_only.advance_pressure(&i, 0.01), o.p_act_kpa);
            assert_eq!(pressure_only.x_pct(), x_before, "the rod must stay");
            assert_eq!(
                (advanced.p_act_kpa(), advanced.x_pct(), advanced.x_membrane_pct()),
                (o.p_act_kpa, o.x_pct, o.x_membrane_pct)
            );
            assert_eq!((same_step.p_act_kpa(), same_step.x_pct()), (o.p_act_kpa, o.x_pct));
            assert_eq!(coarse.p_act_kpa(), o.p_act_kpa);
            dev_coarse = dev_coarse.max((coarse.x_pct() - o.x_pct).abs());
            span = (span.0.min(o.x_pct), span.1.max(o.x_pct));
        }
        // The rod really moves, and a 4x coarser rod step stays within 2.5 % of stroke of it
        // while not being the same computation.
        assert!(span.1 - span.0 > 30.0, "{span:?}");
        // Measured: LPT 1.3 %, HPT 2.1 % (its map is 8 %/kPa mid-stroke: a force error of a
        // coarse step moves the rod four times as far as on the LPT's 2 %/kPa).
        assert!(
            dev_coarse > 1e-9 && dev_coarse < 2.5,
            "coarse rod step deviates {dev_coarse} %"
        );
        for bad in [0.0, -0.001, 0.006, f64::NAN] {
            assert_eq!(
                base.with_rod_step_s(bad).unwrap_err(),
                VacuumParamError::BadParameter("rod_step_max_s"),
                "{bad}"
            );
        }
    }
}

#[test]
fn step_size_does_not_change_the_result_much() {
    // Logs come at 100 Hz..1 kHz: a 10 ms step (20 substeps) against 1 ms.
    let run = |dt: f64| {
        let mut a = VacuumValveActuator::<f64>::new(&VacuumParams::hpt()).unwrap();
        a.settle(&inp(30.0, 12.0, 25.0));
        let n = (2.0 / dt) as usize;
        for _ in 0..n {
            a.step(&inp(70.0, 12.0, 25.0), dt);
        }
        (a.p_act_kpa(), a.x_pct())
    };
    let (p1, x1) = run(0.001);
    let (p10, x10) = run(0.01);
    assert!(
        (p1 - p10).abs() < 1e-6 && (x1 - x10).abs() < 0.05,
        "{p1} {x1} vs {p10} {x10}"
    );
}

#[test]
fn static_model_inverts_the_maps() {
    for p in [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()] {
        let m = VacuumStaticModel::<f64>::new(&p).unwrap();
        for p_amb in [95.0, 100.0] {
            // Duty -> pressure -> duty on the unsaturated part of the map.
            for i in 0..=60 {
                let u = 20.0 + i as f64;
                let pr = m.pressure_for_duty_kpa(u, p_amb, 5.0);
                if pr < p_amb {
                    let back = m.duty_for_pressure_pct(pr, p_amb);
                    assert!((back - u).abs() < 1e-9, "duty {u} -> {pr} kPa -> {back}");
                }
            }
            for i in 1..100 {
                let x = i as f64;
                let pr = m.pressure_for_position_kpa(x, p_amb);
                assert!((m.position_for_pressure_pct(pr, p_amb) - x).abs() < 1e-9);
            }
        }
        // The controller's model agrees with the plant's.
        let a = VacuumValveActuator::<f64>::new(&p).unwrap();
        assert_eq!(
            a.static_pressure_kpa(&inp(55.0, 12.0, 20.0)),
            m.pressure_for_duty_kpa(55.0, 100.0, 20.0)
        );
    }
    let mut rising = VacuumParams::lpt();
    rising.static_map = StaticPressureMap::PiecewiseLinear {
        k1_kpa_per_pct: 0.4,
        p01_kpa: 20.0,
        k2_kpa_per_pct: -1.0,
        p02_kpa: 122.0,
    };
    assert_eq!(
        VacuumStaticModel::<f64>::new(&rising).err(),
        Some(VacuumParamError::BadParameter("static_map"))
    );
}

#[test]
fn bad_parameters_are_named() {
    let mut p = VacuumParams::lpt();
    p.tau_fall_s = 0.0;
    assert_eq!(
        VacuumValveActuator::<f32>::new(&p).err(),
        Some(VacuumParamError::BadParameter("tau_fall_s"))
    );
    let mut p = VacuumParams::hpt();
    p.position_map = PositionMap::Arctan {
        a1_pct: 50.0,
        a2_pct_per_rad: 20.0,
        a3_kpa: 70.0,
        a4_kpa: 8.0,
    };
    assert_eq!(
        VacuumValveActuator::<f32>::new(&p).err(),
        Some(VacuumParamError::BadParameter("position_map"))
    );
    let mut p = VacuumParams::hpc();
    p.volume_stroke_l = 1.0;
    assert_eq!(
        VacuumValveActuator::<Q32>::new(&p).err(),
        Some(VacuumParamError::BadParameter("volume_stroke_l"))
    );
    let mut t = VacuumTankParams::paper();
    t.volume_l = f64::NAN;
    assert_eq!(
        VacuumTank::<f64>::new(&t, 50.0).err(),
        Some(VacuumParamError::BadParameter("volume_l"))
    );
    assert_eq!(
        VacuumTank::<f64>::new(&VacuumTankParams::paper(), 0.0).err(),
        Some(VacuumParamError::BadParameter("p_tank_initial_kpa"))
    );
}

/// Every number type splits a step into the same rod sub-steps: Q16.16's 1 ms (66·2^-16 s,
/// 0.7 % long) takes 2 sub-steps of at most 0.5 ms as the floats do, not 3.
#[test]
fn every_number_type_takes_the_same_sub_steps() {
    for (dt_s, n) in [(0.0005, 1.0), (0.001, 2.0), (0.0012, 3.0), (0.002, 4.0), (0.0125, 25.0)] {
        assert_eq!(substeps(dt_s, H_MAX_S), n, "f64, {dt_s} s");
        assert_eq!(substeps(dt_s as f32, H_MAX_S), n, "f32, {dt_s} s");
        assert_eq!(substeps(Q32::from_f64(dt_s), H_MAX_S), n, "Q32.32, {dt_s} s");
        assert_eq!(substeps(Q16::from_f64(dt_s), H_MAX_S), n, "Q16.16, {dt_s} s");
    }
}

/// Largest deviation of Q16.16 from f64 on the same steps (2^-10 s, which both hold exactly,
/// so that the comparison is of the arithmetic, not of the step's rounding): chamber pressure
/// (kPa) and valve position (%), over segments of 0.3 s of (duty %, supply V, tank kPa).
fn q16_deviation_from_f64(p: &VacuumParams, segments: &[(f64, f64, f64)]) -> (f64, f64) {
    let mut fixed = VacuumValveActuator::<Q16>::new(p).unwrap();
    let mut float = VacuumValveActuator::<f64>::new(p).unwrap();
    let dt = Q16::from_f64(1.0 / 1024.0);
    let (mut dev_p, mut dev_x) = (0.0f64, 0.0f64);
    for &(duty, u, tank) in segments {
        for _ in 0..300 {
            let a = fixed.step(&inp::<Q16>(duty, u, tank), dt);
            let b = float.step(&inp::<f64>(duty, u, tank), dt.to_f64());
            dev_p = dev_p.max((a.p_act_kpa.to_f64() - b.p_act_kpa).abs());
            dev_x = dev_x.max((a.x_pct.to_f64() - b.x_pct).abs());
        }
    }
    (dev_p, dev_x)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    /// Q16.16 over the operating envelope (duty 0-100 %, 9-16 V, tank 20-50 kPa, the three
    /// presets with their effects, 1.8 s): within 0.1 % of f64's range in chamber pressure
    /// (0.1 kPa) and valve position (0.1 %). Measured on 20 sequences a preset: 5.3e-3 kPa
    /// and 1.1e-2 % at most. Before session 18 the position was up to 63 % off (the rod's
    /// damping h·b was below Q16.16's LSB) and the HPC's pressure 0.06 kPa (its cubic map's
    /// k2 held in 21 LSB).
    #[test]
    fn q16_tracks_f64_over_the_envelope(
        segments in proptest::collection::vec((0.0f64..100.0, 9.0f64..16.0, 20.0f64..50.0), 6),
        preset in 0usize..3,
    ) {
        let p = [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()][preset];
        let (dev_p, dev_x) = q16_deviation_from_f64(&p, &segments);
        prop_assert!(dev_p <= 0.1 && dev_x <= 0.1, "pressure {dev_p} kPa, position {dev_x} %");
    }
}
