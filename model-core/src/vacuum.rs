//! Vacuum boost-pressure actuation: PWM solenoid valve, vacuum membrane actuator (turbine
//! wastegate, turbine or compressor bypass), vacuum tank and pump, after Thomasson, Leufvén,
//! Criscuolo and Eriksson, "Modeling and validation of a boost pressure actuation system, for a
//! series sequentially turbocharged SI engine", Control Eng. Practice 21 (2013) 1860-1870.
//!
//! Structure (paper Sections 3-4):
//! - control signal to pressure: voltage-corrected duty, eq. (1); static map, eq. (2) (LPT and
//!   HPT) or eq. (5) (HPC), saturated between tank and ambient pressure; first-order pressure
//!   dynamics eq. (4) with separate rise and fall time constants (Fig. 5);
//! - pressure to position: the force balance eq. (6) divided by the membrane area, so every
//!   force is a pressure (eq. (7)); spring from the inverse of the static position map, linear
//!   eq. (8) or arctan eq. (9); Dahl friction eq. (10) with alpha = 1; end stops at 0 and 100 %;
//!   optionally a linkage clearance (the HPC stick of Figs. 10 and 12);
//! - mass flows to the tank: compressible orifice flow eq. (3) through a duty-dependent leakage
//!   area (Fig. 13) and the evacuation flow eq. (12); tank eq. (13); pump eq. (14).
//!
//! Units: pressure kPa, position % of stroke, duty %, voltage V, time s, volume L, leakage
//! area mm², mass flow mg/s. In these units the normalized mass is ~1e-4 kPa·s²/%, flows are
//! 1..1000 mg/s, and every intermediate stays well inside the Q32.32 range.
//!
//! Effects the diagnosis switches (DATA-FORMAT.md, plant `vacuum`) are the fields of
//! [`VacuumEffects`]; [`VacuumParams::baseline`] turns all of them off.

use crate::real::{horner, horner_in_range, Real};

/// Specific gas constant of air, J/(kg·K).
pub const R_AIR_J_PER_KG_K: f64 = 287.0;
/// Critical pressure ratio for gamma = 1.4: (2/(γ+1))^(γ/(γ-1)), eq. (3).
const P_CRIT: f64 = 0.528_281_787_717_174_4;
/// Largest mechanical integration step; longer calls are split (stiffest mode ~ 250 rad/s).
const H_MAX_S: f64 = 0.0005;
/// Cap on substeps per call so a huge `dt` cannot stall the caller.
const MAX_SUBSTEPS: f64 = 2000.0;
/// The arctan spring needs tan((x - a1)/a2) over the stroke; the angle is kept below this.
const THETA_MAX_RAD: f64 = 1.5;

mod params;
pub use params::*;

/// Inputs of one valve + actuator (DATA-FORMAT.md columns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumInputs<R> {
    /// Commanded PWM duty, clamped to 0..100.
    pub duty_pct: R,
    /// Supply voltage at the solenoid.
    pub u_batt_v: R,
    pub p_amb_kpa: R,
    pub p_tank_kpa: R,
}

/// Outputs of one valve + actuator after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumOutputs<R> {
    /// Actuator chamber pressure (eq. (4) output).
    pub p_act_kpa: R,
    /// Valve position, where `x_pct` is measured (after the linkage clearance).
    pub x_pct: R,
    /// Membrane (rod) position.
    pub x_membrane_pct: R,
    /// Saturated static pressure eq. (2)/(5), the target of eq. (4).
    pub p_static_kpa: R,
    /// Mean mass flow into the tank over the step: plunger leakage (eq. (3), Fig. 13) plus
    /// evacuation (eq. (12)).
    pub flow_to_tank_mg_s: R,
}

/// Compressible orifice flow eq. (3), signed from `p_a` to `p_b`, in mg/s for an effective
/// area in mm². `c_orifice` = 1e3/sqrt(R·T) converts kPa·mm² to mg/s.
pub fn orifice_flow_mg_s<R: Real>(p_a_kpa: R, p_b_kpa: R, area_mm2: R, c_orifice: R) -> R {
    let (p_up, p_down, dir) = if p_a_kpa >= p_b_kpa {
        (p_a_kpa, p_b_kpa, R::ONE)
    } else {
        (p_b_kpa, p_a_kpa, -R::ONE)
    };
    if !positive(p_up) || !positive(area_mm2) {
        return R::ZERO;
    }
    let ratio = (p_down / p_up).clamp(R::from_f64(P_CRIT), R::ONE);
    dir * c_orifice * p_up * area_mm2 * psi(ratio)
}

/// Ψ(Π)² = 7(Π^(10/7) − Π^(12/7)) on [Π_crit, 1] as a polynomial of degree 5 in
/// w = (2Π − Π_crit − 1)/(1 − Π_crit), w in [−1, 1], lowest power first: the Chebyshev
/// interpolant at 64 nodes, written in powers of w (largest error 4.3e-7, a thirtieth of
/// Q16.16's LSB; `psi_squared_polynomial_is_within_its_stated_error` checks it). The
/// fixed-point form of [`psi`]: its ln and exp cost ~250 instructions a call on the
/// Cortex-M4 in Q16.16, the polynomial five products.
const PSI_SQ_POLY: [f64; 6] = [
    0.352_622_505_523_097_65,
    -0.233_770_308_159_076_85,
    -0.118_452_024_627_122_5,
    -0.000_602_266_990_282_783_5,
    0.000_257_715_776_684_236_4,
    -5.596_457_624_768_014e-5,
];

/// Ψ(Π) = sqrt(2γ/(γ−1)·(Π^(2/γ) − Π^((γ+1)/γ))) for γ = 1.4, i.e. sqrt(7·y¹⁰·(1 − y²))
/// with y = Π^(1/7); Π already limited to [Π_crit, 1] (choking, eq. (3)).
fn psi<R: Real>(ratio: R) -> R {
    if !R::IS_FLOAT {
        // Fixed point: Ψ² as the polynomial [`PSI_SQ_POLY`] in w, Horner's scheme written
        // out, every product in range (|w| <= 1, each partial sum below 1).
        let f = R::from_f64;
        let c = PSI_SQ_POLY;
        let w = ratio.mul_in_range(f(2.0 / (1.0 - P_CRIT))) - f((1.0 + P_CRIT) / (1.0 - P_CRIT));
        let mut s = f(c[4]) + w.mul_in_range(f(c[5]));
        s = f(c[3]) + w.mul_in_range(s);
        s = f(c[2]) + w.mul_in_range(s);
        s = f(c[1]) + w.mul_in_range(s);
        s = f(c[0]) + w.mul_in_range(s);
        return s.max(R::ZERO).sqrt();
    }
    let y = ratio.ln().div_by(R::divisor(R::from_f64(7.0))).exp();
    let y2 = y * y;
    let y4 = y2 * y2;
    let y10 = y4 * y4 * y2;
    (R::from_f64(7.0) * y10 * (R::ONE - y2)).sqrt()
}

/// (−1)^(k+1)/k!, k = 1..=16: the Taylor coefficients of 1 − e^(−x).
const ONE_MINUS_EXP_NEG_COEFFS: [f64; 16] = {
    let mut c = [0.0; 16];
    let mut term = 1.0;
    let mut k = 0;
    while k < 16 {
        term /= (k + 1) as f64;
        c[k] = if k % 2 == 0 { term } else { -term };
        k += 1;
    }
    c
};

/// 1 − e^(−x) for x >= 0, accurate for small x where `1 - exp(-x)` would cancel (f32's exp
/// loses ~1e-6 absolute): Taylor series to x¹⁶ below 1 (truncation < 3e-14) by Horner's rule
/// with the coefficients precomputed (multiplications only: a division chain cost the host
/// diagnosis, which runs this every rod substep, twice its time), the direct form above.
///
/// Unrolled by `horner!` so that each coefficient converts to `R` at compile time (a loop left
/// `R::from_f64` at run time: soft-float double arithmetic on the target, ~60 % of the Q16.16
/// actuator step). The same operations in the same order as the loop `s = c + x·s` from s = 0.
///
/// A type that cannot hold 1e-6 (Q16.16, LSB 1.5e-5) takes the series to x⁸ (the first term
/// left out below 2.8e-7) with products in range: 0 <= x < 1, coefficients and partial sums
/// within [−1, 1].
fn one_minus_exp_neg<R: Real>(x: R) -> R {
    if x < R::ONE {
        const C: [f64; 16] = ONE_MINUS_EXP_NEG_COEFFS;
        if !crate::real::resolves::<R>(1e-6) {
            return x.mul_in_range(one_minus_exp_neg_over_x_coarse(x));
        }
        let s = horner!(R, x; C[0], C[1], C[2], C[3], C[4], C[5], C[6], C[7], C[8], C[9], C[10], C[11],
            C[12], C[13], C[14], C[15]);
        x * s
    } else {
        R::ONE - (-x).exp()
    }
}

/// (1 − e^(−x))/x for 0 <= x < 1 in a type that does not resolve 1e-6 (fixed point): the
/// series' terms to x⁸/9! (below 1e-8 for x < 1/2, 3e-6 below 1), each product in range.
fn one_minus_exp_neg_over_x_coarse<R: Real>(x: R) -> R {
    const C: [f64; 16] = ONE_MINUS_EXP_NEG_COEFFS;
    horner_in_range!(R, x; C[0], C[1], C[2], C[3], C[4], C[5], C[6], C[7], C[8])
}

/// Eq. (4)'s 1 − e^(−dt/τ) for a step `dt_s` and τ as a divisor, with the power of two it is
/// held times. The floats: the value, shift 0. Fixed point: a 1 ms step on τ = 40 ms is
/// 0.0248, and Q16.16's LSB is 6e-4 of it, a time-constant error (the HPT's chamber pressure
/// 5.8e-3 kPa off f64's at most, 2.1e-3 since session 18). Below 1/2 it is computed and held
/// times 2^k in [1/2, 1): x·2^k = (dt·2^k)/τ, times (1 − e^(−x))/x from the series at x.
fn scaled_decay<R: Real>(dt_s: R, tau_div: R::Divisor) -> (R, i32) {
    let x = dt_s.div_by(tau_div);
    let half = R::from_f64(0.5);
    if R::IS_FLOAT || x >= half || x <= R::ZERO {
        return (one_minus_exp_neg(x), 0);
    }
    let (mut k, mut coarse) = (0, x);
    while k < 14 && coarse < half {
        coarse = coarse.mul_pow2(1);
        k += 1;
    }
    let x_scaled = dt_s.mul_pow2(k).div_by(tau_div);
    (x_scaled.mul_in_range(one_minus_exp_neg_over_x_coarse(x)), k)
}

/// `x > 0`, false for NaN too (so a NaN step or area does nothing).
fn positive<R: Real>(x: R) -> bool {
    x > R::ZERO
}

/// Number of substeps of at most `h_max_s` in `dt_s`. The ratio is shrunk by 1e-6 first so
/// that a step that is a whole multiple of `h_max_s` in decimal (0.001 s as f32 is
/// 0.0010000000475) gets the same count in every number type, and by half the type's
/// spacing over `h_max_s` for fixed point, whose step is the requested one rounded to that
/// spacing (1 ms in Q16.16 is 66·2^-16 s, 0.7 % long: 3 sub-steps of 0.5 ms where f32 takes 2,
/// until session 18). A sub-step may then exceed `h_max_s` by that rounding.
fn substeps<R: Real>(dt_s: R, h_max_s: f64) -> f64 {
    let ratio = dt_s.to_f64() / h_max_s * (1.0 - 1e-6);
    // (A term of 0 for the floats would still cost them a soft-float division on the target.)
    let rounding = if R::ABS_RESOLUTION > 0.0 {
        0.5 * R::ABS_RESOLUTION / h_max_s
    } else {
        0.0
    };
    libm::ceil(ratio - rounding).clamp(1.0, MAX_SUBSTEPS)
}

/// Saturation of eq. (2)/(5): between the tank (lowest reachable) and ambient pressure.
fn saturate<R: Real>(p: R, p_tank: R, p_amb: R) -> R {
    let lo = p_tank.min(p_amb);
    p.clamp(lo, p_amb)
}

/// One PWM solenoid valve and its vacuum membrane actuator.
#[derive(Clone, Copy, Debug)]
pub struct VacuumValveActuator<R: Real> {
    maps: Maps<R>,
    effects: VacuumEffects,
    u_ref_v: R::Divisor,
    /// τ of eq. (4) rising and falling, as divisors (a rate's first step divides the step by them).
    tau_rise_div: R::Divisor,
    tau_fall_div: R::Divisor,
    p_amb_ref_kpa: R,
    inv_mass: R,
    damping_extend: R,
    damping_retract: R,
    fc_kpa: R,
    sigma_over_fc: R,
    half_backlash_pct: R,
    leak_area_per_pct: R,
    leak_duty_max_pct: R,
    volume_x0_l: R,
    volume_per_pct_l: R,
    c_orifice: R,
    /// mg per kPa·L at T_amb: 1e6/(R·T).
    c_mass: R,
    // State.
    p_act_kpa: R,
    x_mem_pct: R,
    v_pct_s: R,
    friction_kpa: R,
    x_valve_pct: R,
    /// Largest rod integration step, s ([`Self::with_rod_step_s`]).
    rod_step_max_s: f64,
    /// Eq. (4)'s 1 − e^(−dt/τ) for rising and falling pressure at the step `decay_dt_s` (0: none
    /// yet): steps come at a fixed rate, so they are computed once per rate.
    decay_dt_s: R,
    decay_rise: R,
    decay_fall: R,
    /// Fixed point: `decay_rise`, `decay_fall` are held times 2^shift ([`scaled_decay`]),
    /// 0 for the floats.
    decay_shift: [i32; 2],
    /// `decay_dt_s` as a divisor (the evacuation flow divides by the step).
    decay_dt_div: R::Divisor,
    /// The rod substeps of a step of `rods_dt_s` (0: none yet): their number, as `R` and as a
    /// divisor, their length, and the implicit damping's denominators 1 + h·b/m (extending,
    /// retracting) as divisors, computed once per step length (the count goes through f64,
    /// soft-float on the target; a prepared divisor makes a fixed-point division a multiply).
    rods_dt_s: R,
    rods_n: u32,
    rods_n_div: R::Divisor,
    rods_h_s: R,
    rods_damping_div: [R::Divisor; 2],
    /// Fixed point only (the floats keep their operations and bits): 1/n and h/m, products
    /// where the floats divide by n and multiply by h, then 1/m, every sub-step.
    rods_inv_n: R,
    rods_h_over_mass: R,
    /// Fixed point: (h/m)/(1 + h·b/m) per direction, and b (extending, retracting) times 2^10.
    rods_gain: [R; 2],
    damping_x1024: [R; 2],
}

/// Longest rod step [`VacuumValveActuator::with_rod_step_s`] accepts: the semi-implicit
/// Euler step of the stiffest spring mode (~250 rad/s) is stable below 2/ω = 8 ms.
const ROD_STEP_MAX_S: f64 = 0.005;

impl<R: Real> VacuumValveActuator<R> {
    /// Builds the actuator at rest, vented to `p_amb_ref_kpa` (valve closed, x at the spring's
    /// rest position). Use [`Self::settle`] to start at a steady operating point.
    pub fn new(p: &VacuumParams) -> Result<Self, VacuumParamError> {
        p.validate()?;
        let f = R::from_f64;
        let fc = p.rod_friction_kpa();
        let sigma_over_fc = if fc > 0.0 { p.dahl_sigma_kpa_per_pct / fc } else { 0.0 };
        let half_backlash = p.half_clearance_pct();
        let rt = R_AIR_J_PER_KG_K * p.temp_amb_k;
        let maps = Maps::new(p);
        let p_amb_ref = f(p.p_amb_ref_kpa);
        let x0 = maps.position(p_amb_ref).clamp(R::ZERO, f(100.0));
        Ok(Self {
            maps,
            effects: p.effects,
            u_ref_v: R::divisor(f(p.u_ref_v)),
            tau_rise_div: R::divisor(f(p.tau_rise_s)),
            tau_fall_div: R::divisor(f(p.tau_fall_s)),
            p_amb_ref_kpa: p_amb_ref,
            inv_mass: f(1.0 / p.mass_kpa_s2_per_pct),
            damping_extend: f(p.damping_extend_kpa_s_per_pct),
            damping_retract: f(p.damping_retract_kpa_s_per_pct),
            fc_kpa: f(fc),
            sigma_over_fc: f(sigma_over_fc),
            half_backlash_pct: f(half_backlash),
            leak_area_per_pct: f(p.leak_area_mm2_per_pct),
            leak_duty_max_pct: f(p.leak_duty_max_pct),
            volume_x0_l: f(p.volume_x0_l),
            volume_per_pct_l: f(p.volume_stroke_l / 100.0),
            c_orifice: f(1e3 / libm::sqrt(rt)),
            c_mass: f(1e6 / rt),
            p_act_kpa: p_amb_ref,
            x_mem_pct: x0,
            v_pct_s: R::ZERO,
            friction_kpa: R::ZERO,
            x_valve_pct: x0,
            rod_step_max_s: H_MAX_S,
            decay_dt_s: R::ZERO,
            decay_rise: R::ZERO,
            decay_fall: R::ZERO,
            decay_shift: [0; 2],
            decay_dt_div: R::divisor(R::ONE),
            rods_dt_s: R::ZERO,
            rods_n: 0,
            rods_n_div: R::divisor(R::ONE),
            rods_h_s: R::ZERO,
            rods_inv_n: R::ONE,
            rods_h_over_mass: R::ZERO,
            rods_gain: [R::ZERO; 2],
            damping_x1024: [
                f(p.damping_extend_kpa_s_per_pct * 1024.0),
                f(p.damping_retract_kpa_s_per_pct * 1024.0),
            ],
            rods_damping_div: [R::divisor(R::ONE); 2],
        })
    }

    /// The same actuator with its rod (eqs. (6), (7), (10)) integrated in steps of at most
    /// `h_max_s` instead of the default 0.5 ms: a coarser step trades accuracy for speed where
    /// many simulations run (the host diagnosis fits at 1 ms). Between 1 µs and 5 ms.
    pub fn with_rod_step_s(mut self, h_max_s: f64) -> Result<Self, VacuumParamError> {
        if !(h_max_s.is_finite() && (1e-6..=ROD_STEP_MAX_S).contains(&h_max_s)) {
            return Err(VacuumParamError::BadParameter("rod_step_max_s"));
        }
        self.rod_step_max_s = h_max_s;
        self.rods_dt_s = R::ZERO;
        Ok(self)
    }

    /// Largest rod integration step, s.
    pub fn rod_step_s(&self) -> f64 {
        self.rod_step_max_s
    }

    /// The duty the valve acts on: eq. (1) with the `supply-voltage` effect, else the duty.
    pub fn effective_duty_pct(&self, duty_pct: R, u_batt_v: R) -> R {
        let u = duty_pct.clamp(R::ZERO, R::from_f64(100.0));
        if self.effects.supply_voltage {
            (u * u_batt_v.max(R::ZERO)).div_by(self.u_ref_v)
        } else {
            u
        }
    }

    /// Saturated static pressure, eqs. (1), (2)/(5).
    pub fn static_pressure_kpa(&self, inputs: &VacuumInputs<R>) -> R {
        let u = self.effective_duty_pct(inputs.duty_pct, inputs.u_batt_v);
        self.static_pressure_at_duty(u, inputs)
    }

    /// Eq. (2)/(5) saturated at the effective duty `u`.
    fn static_pressure_at_duty(&self, u: R, inputs: &VacuumInputs<R>) -> R {
        saturate(
            self.maps.unsaturated_pressure(u, inputs.p_amb_kpa),
            inputs.p_tank_kpa,
            inputs.p_amb_kpa,
        )
    }

    /// Frictionless static membrane position for a chamber pressure, eqs. (7)-(9), on the
    /// stroke 0..100 %.
    pub fn static_position_pct(&self, p_act_kpa: R, p_amb_kpa: R) -> R {
        let p_map = self.p_amb_ref_kpa - (p_amb_kpa - p_act_kpa);
        self.maps.position(p_map).clamp(R::ZERO, R::from_f64(100.0))
    }

    /// Puts the actuator at the steady state of constant `inputs`: static pressure, static
    /// position, no friction load, valve centred on the membrane.
    pub fn settle(&mut self, inputs: &VacuumInputs<R>) {
        self.p_act_kpa = self.static_pressure_kpa(inputs);
        self.x_mem_pct = self.static_position_pct(self.p_act_kpa, inputs.p_amb_kpa);
        self.v_pct_s = R::ZERO;
        self.friction_kpa = R::ZERO;
        self.x_valve_pct = self.x_mem_pct;
    }

    pub fn p_act_kpa(&self) -> R {
        self.p_act_kpa
    }
    pub fn x_pct(&self) -> R {
        self.x_valve_pct
    }
    pub fn x_membrane_pct(&self) -> R {
        self.x_mem_pct
    }
    /// Current friction load (Dahl state), kPa.
    pub fn friction_kpa(&self) -> R {
        self.friction_kpa
    }

    fn volume_l(&self, x: R) -> R {
        self.volume_x0_l - self.volume_per_pct_l * x
    }

    /// Advances by `dt_s`. Pressure eq. (4) is integrated exactly over the step; the rod
    /// (eqs. (6), (7), (10)) in substeps of at most 0.5 ms (or [`Self::with_rod_step_s`]) with
    /// the chamber pressure interpolated across the step.
    pub fn step(&mut self, inputs: &VacuumInputs<R>, dt_s: R) -> VacuumOutputs<R> {
        // The effective duty and the static pressure once for the whole step.
        let u = self.effective_duty_pct(inputs.duty_pct, inputs.u_batt_v);
        let p_stat = self.static_pressure_at_duty(u, inputs);
        if !positive(dt_s) {
            return self.outputs(p_stat, R::ZERO);
        }
        let p_old = self.p_act_kpa;
        let volume_old = self.volume_l(self.x_mem_pct);
        self.advance_to(inputs.p_amb_kpa, p_stat, dt_s);
        let p_new = self.p_act_kpa;

        // Mass flows into the tank. Leakage eq. (3) through the Fig. 13 area, from the chamber.
        let area = self.leak_area_per_pct * u.clamp(R::ZERO, self.leak_duty_max_pct);
        let leak = orifice_flow_mg_s(p_new, inputs.p_tank_kpa, area, self.c_orifice);
        // Eq. (12): the chamber's mass loss d(pV)/(RT), counted only when it leaves towards the
        // tank (a gain comes from ambient through the valve).
        let pv_change = p_new * self.volume_l(self.x_mem_pct) - p_old * volume_old;
        // (`advance_to` has prepared the step as a divisor.)
        let evacuation = ((-pv_change).max(R::ZERO) * self.c_mass).div_by(self.decay_dt_div);
        self.outputs(p_stat, leak + evacuation)
    }

    /// [`Self::step`] without the mass flows to the tank: the same pressure and positions, for
    /// simulations that only compare those (the host diagnosis runs millions of steps).
    pub fn advance(&mut self, inputs: &VacuumInputs<R>, dt_s: R) {
        if !positive(dt_s) {
            return;
        }
        let p_stat = self.static_pressure_kpa(inputs);
        self.advance_to(inputs.p_amb_kpa, p_stat, dt_s);
    }

    /// [`Self::advance`] towards the static pressure `p_stat`, for `dt_s > 0`.
    fn advance_to(&mut self, p_amb_kpa: R, p_stat: R, dt_s: R) {
        let p_old = self.p_act_kpa;
        let p_new = self.pressure_towards(p_stat, dt_s);
        if dt_s != self.rods_dt_s {
            let n = substeps(dt_s, self.rod_step_max_s) as u32;
            // A whole count (at most MAX_SUBSTEPS) converts exactly from an integer; from f64
            // it was soft-float arithmetic in fixed point. The floats' divisor is the count
            // itself, so their h is dt/n as before.
            let n_r = R::from_i32(n as i32);
            self.rods_n_div = R::divisor(n_r);
            let h = dt_s.div_by(self.rods_n_div);
            self.rods_dt_s = dt_s;
            self.rods_n = n;
            self.rods_h_s = h;
            self.rods_inv_n = R::ONE.div_by(self.rods_n_div);
            self.rods_h_over_mass = h * self.inv_mass;
            if R::IS_FLOAT {
                self.rods_damping_div = [
                    R::divisor(R::ONE + h * self.damping_extend * self.inv_mass),
                    R::divisor(R::ONE + h * self.damping_retract * self.inv_mass),
                ];
            } else {
                // h/m first: h·b is below Q16.16's LSB (0.5 ms · 0.006 kPa·s/% = 3e-6), and
                // the damping vanished (the rod ran up to twice as fast as in f64 until
                // session 18); h/m is of order 1-10. One division each, no divisor kept.
                let hm = self.rods_h_over_mass;
                self.rods_gain = [
                    hm / (R::ONE + self.damping_extend * hm),
                    hm / (R::ONE + self.damping_retract * hm),
                ];
            }
        }
        let dp_step = if R::IS_FLOAT {
            (p_new - p_old).div_by(self.rods_n_div)
        } else {
            // |p_new − p_old| is below the pressures' span and 1/n <= 1.
            (p_new - p_old).mul_in_range(self.rods_inv_n)
        };
        let hundred = R::from_f64(100.0);
        let mut p_sub = p_old;
        for _ in 0..self.rods_n {
            p_sub += dp_step;
            self.mechanics_substep(p_amb_kpa - p_sub, self.rods_h_s, hundred);
        }
    }

    /// Advances the chamber pressure alone (eq. (4)) by `dt_s` and returns it; the rod stays
    /// where it is. Eq. (4) does not depend on the rod, so a pressure model can be fitted to a
    /// logged chamber pressure at a fraction of the cost of the whole actuator.
    pub fn advance_pressure(&mut self, inputs: &VacuumInputs<R>, dt_s: R) -> R {
        if positive(dt_s) {
            let p_stat = self.static_pressure_kpa(inputs);
            self.pressure_towards(p_stat, dt_s);
        }
        self.p_act_kpa
    }

    /// Eq. (4) over `dt_s > 0` towards `p_stat`; the new chamber pressure.
    fn pressure_towards(&mut self, p_stat: R, dt_s: R) -> R {
        let p_old = self.p_act_kpa;
        // Eq. (4), exact for a constant target: p += (p_stat − p)(1 − e^(−dt/τ)).
        if dt_s != self.decay_dt_s {
            self.decay_dt_s = dt_s;
            let (rise, rise_shift) = scaled_decay(dt_s, self.tau_rise_div);
            let (fall, fall_shift) = scaled_decay(dt_s, self.tau_fall_div);
            (self.decay_rise, self.decay_fall, self.decay_shift) = (rise, fall, [rise_shift, fall_shift]);
            self.decay_dt_div = R::divisor(dt_s);
        }
        let (decay, shift) = if self.effects.pressure_direction && p_stat < p_old {
            (self.decay_fall, self.decay_shift[1])
        } else {
            (self.decay_rise, self.decay_shift[0])
        };
        self.p_act_kpa = if R::IS_FLOAT {
            p_old + (p_stat - p_old) * decay
        } else {
            // |p_stat − p_old| is below the pressures' span, the scaled decay below 1.
            p_old + (p_stat - p_old).mul_in_range(decay).mul_pow2(-shift)
        };
        self.p_act_kpa
    }

    /// One semi-implicit Euler step of the normalized force balance eq. (7) with mass and
    /// damping (eq. (6)), Dahl friction (eq. (10)), end stops and the linkage clearance.
    fn mechanics_substep(&mut self, dp_membrane_kpa: R, h: R, hundred: R) {
        let x = self.x_mem_pct;
        let spring = self.p_amb_ref_kpa - self.maps.pressure_at(x);
        let b = if self.v_pct_s >= R::ZERO { 0 } else { 1 };
        let drive = dp_membrane_kpa - spring - self.friction_kpa;
        // Damping implicit: stable for any b.
        let mut v = if R::IS_FLOAT {
            // (1 + h·b/m prepared once per step length.)
            (self.v_pct_s + h * drive * self.inv_mass).div_by(self.rods_damping_div[b])
        } else {
            // The same step as v + (h/m)(drive − b·v)/(1 + h·b/m), so that the velocity the
            // damping settles at, drive/b, carries b's precision (b·v from b held times
            // 2^10), not that of h·b/m (0.03 for the HPT, 1.5e-5 absolute in Q16.16).
            let damping = (self.v_pct_s * self.damping_x1024[b]).mul_pow2(-10);
            self.v_pct_s + (drive - damping) * self.rods_gain[b]
        };
        let mut x_new = x + h * v;
        // The membrane's stops lie half the clearance beyond the valve's travel: x_pct is
        // measured on the valve, whose 0 and 100 % are its own seat and stop, so a unit with
        // clearance still reaches both (the membrane takes up the play beyond them).
        let x_min = -self.half_backlash_pct;
        let x_max = hundred + self.half_backlash_pct;
        if x_new <= x_min {
            x_new = x_min;
            v = v.max(R::ZERO);
        } else if x_new >= x_max {
            x_new = x_max;
            v = v.min(R::ZERO);
        }
        // Dahl eq. (10) with α = 1 is linear in x for a fixed sign of motion:
        // F → s·Fc + (F − s·Fc)·exp(−σ|Δx|/Fc), exact and unconditionally stable.
        let dx = x_new - x;
        if self.fc_kpa > R::ZERO && dx != R::ZERO {
            let target = dx.sign() * self.fc_kpa;
            self.friction_kpa += (target - self.friction_kpa) * one_minus_exp_neg(self.sigma_over_fc * dx.abs());
        }
        self.x_mem_pct = x_new;
        self.v_pct_s = v;
        // Play operator: the valve moves only when the membrane takes up the clearance.
        let lo = x_new - self.half_backlash_pct;
        let hi = x_new + self.half_backlash_pct;
        self.x_valve_pct = self.x_valve_pct.clamp(lo, hi).clamp(R::ZERO, hundred);
    }

    fn outputs(&self, p_stat: R, flow: R) -> VacuumOutputs<R> {
        VacuumOutputs {
            p_act_kpa: self.p_act_kpa,
            x_pct: self.x_valve_pct,
            x_membrane_pct: self.x_mem_pct,
            p_static_kpa: p_stat,
            flow_to_tank_mg_s: flow,
        }
    }
}

mod maps;
use maps::Maps;
pub use maps::VacuumStaticModel;

mod tank;
pub use tank::{VacuumSystem, VacuumSystemOutputs, VacuumTank, VacuumTankParams};

#[cfg(test)]
mod tests;
