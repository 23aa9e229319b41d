//! Reduced-order (fifth-order) nonlinear EHVVA model, eq. (12) of Li et al. 2018: states
//! main-valve outlet pressure Pmo, lift L, velocity L̇, back pressure Pl, supply pressure Ph.
//!
//! - Pmo follows the main-valve inlet pressure u·(Ph − Pl) + Pl with the time constant
//!   τp(Ph, T) (eq. (10)) and reaches the piston delayed by td (eq. (11)), taken from a
//!   [`DelayLine`] of Pmo. The delay differs between the opening edge (VO) and the closing
//!   edge (VC): the piston sees min(Pmo(t − td,VO), Pmo(t − td,VC)) when td,VO ≥ td,VC (a
//!   rising Pmo is read with the longer delay, a falling one with the shorter) and the max
//!   otherwise; with equal delays both are the same sample.
//! - Piston, snubbers and accumulators: see `piston.rs` (eqs. (1), (5)-(8)).
//!
//! Integration: the delay line is pushed once per `step` (the step `dt_ms` is fixed at
//! construction so that samples are equally spaced); each step is cut into sub-steps of at
//! most [`MAX_SUBSTEP_MS`]. Per sub-step: Pmo by implicit Euler (stable for any τp), velocity
//! semi-implicitly (friction and the quadratic orifice damping implicit, linearised about the
//! current |v|), lift with the new velocity (symplectic Euler), then the end stops, then the
//! accumulator pressures by explicit Euler (their time constants are ≥ 10 ms). The delayed Pmo
//! is interpolated inside the step. This is stable in f32, f64 and Q32.32 (tests in
//! `tests/ehvva_paper.rs` measure the differences).

use super::event::EhvvaPlant;
use super::params::{EhvvaError, EhvvaInputs, EhvvaParams};
use super::piston::{DampingGains, Moving, Piston, SubStep};
use super::tables::{EhvvaTables, EhvvaTablesAt};
use crate::delay::DelayLine;
use crate::real::Real;

/// Longest sub-step of the piston integration. 5 µs resolves τp ≥ 0.07 ms with < 4 % error per
/// time constant and the 1 %/99 % crossings to well under 0.01 ms.
pub const MAX_SUBSTEP_MS: f64 = 0.005;
/// Longest allowed `step` (the delayed Pmo is interpolated linearly inside one step).
pub const MAX_STEP_MS: f64 = 0.1;
/// At most this many sub-steps per step.
const MAX_SUBSTEPS: usize = 64;

/// Default delay line length: 512 samples hold 10.2 ms at the 0.02 ms step the tests use.
pub const DEFAULT_DELAY_SAMPLES: usize = 512;

/// Checks the step and that a delay line of `n` samples holds the longest delay; the number
/// of sub-steps of at most [`MAX_SUBSTEP_MS`] a step.
pub(crate) fn check_step(params: &EhvvaParams, dt_ms: f64, n: usize) -> Result<usize, EhvvaError> {
    check_step_with(params, dt_ms, MAX_SUBSTEP_MS, n)
}

/// [`check_step`] with sub-steps of at most `max_substep_ms` (in (0, [`MAX_STEP_MS`]]).
fn check_step_with(params: &EhvvaParams, dt_ms: f64, max_substep_ms: f64, n: usize) -> Result<usize, EhvvaError> {
    if !(dt_ms.is_finite() && dt_ms > 0.0 && dt_ms <= MAX_STEP_MS) {
        return Err(EhvvaError::InvalidParameter("dt_ms"));
    }
    if !(max_substep_ms.is_finite() && max_substep_ms > 0.0 && max_substep_ms <= MAX_STEP_MS) {
        return Err(EhvvaError::InvalidParameter("max_substep_ms"));
    }
    let t = &params.tables;
    let mut max_half: f64 = 0.0;
    for i in 0..4 {
        for j in 0..5 {
            max_half = max_half.max(0.5 * (t.td_open_ms[i][j] - t.td_close_ms[i][j]).abs());
        }
    }
    let needed_ms = t.max_delay_ms() + (params.effect_direction_delay - 1.0).max(0.0) * max_half;
    let capacity_ms = (n.saturating_sub(1)) as f64 * dt_ms;
    // One extra step: the delayed value is interpolated up to one step ahead.
    if capacity_ms < needed_ms + dt_ms {
        return Err(EhvvaError::DelayLineTooShort { capacity_ms, needed_ms });
    }
    let sub = libm::ceil(dt_ms / max_substep_ms) as usize;
    Ok(sub.clamp(1, MAX_SUBSTEPS))
}

/// Picks the delayed value: the longer delay for a rising signal, the shorter for a falling
/// one (see the module docs).
pub(crate) fn directional<R: Real>(via_open: R, via_close: R, open_is_longer: bool) -> R {
    if open_is_longer {
        via_open.min(via_close)
    } else {
        via_open.max(via_close)
    }
}

/// The fifth-order nonlinear model of eq. (12). `N` is the length of the Pmo delay line.
#[derive(Clone, Debug)]
pub struct EhvvaReduced<R: Real, const N: usize = DEFAULT_DELAY_SAMPLES> {
    piston: Piston<R>,
    tables: EhvvaTables<R>,
    /// `tables` at the last step's oil temperature.
    at: EhvvaTablesAt<R>,
    /// Fixed point: the orifice damping's gains at that temperature (the floats multiply by
    /// 1/Cd² each sub-step, as they always have).
    damping: DampingGains<R>,
    dt: R,
    inv_dt: R,
    h: SubStep<R>,
    substeps: usize,
    /// 1/substeps, converted once (a run-time `from_f64` is soft-float on the target).
    inv_substeps: R,
    p_mo: R,
    /// Fixed point: the last step's Pmo lag h/(τp + h), which the next step refines by one
    /// Newton step instead of a long division (`pmo_lag_fixed`); 0 before the first step.
    pmo_lag: R,
    /// Fixed point: 1/h with h held times 2^10 (the Newton step's 1/(τp + h) ≈ lag/h).
    inv_h_x1024: R,
    /// Lift, velocity, accumulators and the last seat landing (shared with the other models).
    m: Moving<R>,
    pmo_history: DelayLine<R, N>,
}

impl<R: Real, const N: usize> EhvvaReduced<R, N> {
    /// A model at rest (valve seated, Pmo = Pl, accumulators at their set-points) for the
    /// operating point `inputs`, stepped every `dt_ms` (≤ 0.1 ms).
    pub fn new(params: &EhvvaParams, inputs: &EhvvaInputs<R>, dt_ms: f64) -> Result<Self, EhvvaError> {
        Self::with_max_substep(params, inputs, dt_ms, MAX_SUBSTEP_MS)
    }

    /// [`EhvvaReduced::new`] with sub-steps of at most `max_substep_ms` instead of
    /// [`MAX_SUBSTEP_MS`] (at most [`MAX_STEP_MS`]). A coarser sub-step is stable (the
    /// integration above) but less accurate: at 25 µs an event of Table 1's envelope lifts up
    /// to 0.24 % of the stroke RMS off the model's own, its opening and closing times within
    /// 0.05 ms (test), more than a lift sensor's noise. For a fit's first approach to its
    /// optimum, never for a result.
    pub fn with_max_substep(
        params: &EhvvaParams,
        inputs: &EhvvaInputs<R>,
        dt_ms: f64,
        max_substep_ms: f64,
    ) -> Result<Self, EhvvaError> {
        let substeps = check_step_with(params, dt_ms, max_substep_ms, N)?;
        if !R::IS_FLOAT && N >= 1 << 15 {
            // The delays in samples must be in fixed point's range (see `step`).
            return Err(EhvvaError::InvalidParameter("delay line length N"));
        }
        let piston = Piston::new(params)?;
        let tables = EhvvaTables::new(params)?;
        if !R::IS_FLOAT {
            // Cd(T) is piecewise linear with clamped ends: its least value is at a breakpoint.
            let inv_cd2_max = params
                .tables
                .cd_temp_c
                .iter()
                .map(|&t| tables.cd(R::from_f64(t)).to_f64())
                .map(|cd| 1.0 / (cd * cd))
                .fold(0.0, f64::max);
            piston.check_damping_gains(inv_cd2_max)?;
        }
        let at = tables.at_temperature(inputs.temp_c);
        let h_ms = dt_ms / substeps as f64;
        let mut model = Self {
            piston,
            at,
            damping: piston.damping_gains(at.inv_cd2()),
            tables,
            dt: R::from_f64(dt_ms),
            inv_dt: R::from_f64(1.0 / dt_ms),
            h: SubStep::new(h_ms, params)?,
            substeps,
            inv_substeps: R::from_f64(1.0 / substeps as f64),
            p_mo: inputs.p_back_mpa,
            pmo_lag: R::ZERO,
            inv_h_x1024: R::from_f64(1.0 / (1024.0 * h_ms)),
            m: Moving::at_rest(inputs),
            pmo_history: DelayLine::new(inputs.p_back_mpa),
        };
        model.rest_at(inputs);
        Ok(model)
    }

    /// Puts the model back at rest for the operating point `inputs`, as [`EhvvaReduced::new`]
    /// leaves it (the same numbers from here on): the unit's constants kept, the states,
    /// the temperature's table slice and the Pmo history set anew. For a simulation of many
    /// events of one unit, each from rest, without building the unit's tables for each.
    pub fn rest_at(&mut self, inputs: &EhvvaInputs<R>) {
        self.at = self.tables.at_temperature(inputs.temp_c);
        self.damping = self.piston.damping_gains(self.at.inv_cd2());
        self.p_mo = inputs.p_back_mpa;
        self.pmo_lag = R::ZERO;
        self.m = Moving::at_rest(inputs);
        self.pmo_history.fill(inputs.p_back_mpa);
    }

    /// Main-valve outlet pressure Pmo (undelayed), MPa.
    pub fn p_mo_mpa(&self) -> R {
        self.p_mo
    }
    /// Supply (high) accumulator pressure Ph, MPa.
    pub fn p_high_mpa(&self) -> R {
        self.m.p_high
    }
    /// Back (low) accumulator pressure Pl, MPa.
    pub fn p_low_mpa(&self) -> R {
        self.m.p_low
    }
    /// The calibrated tables this model uses.
    pub fn tables(&self) -> &EhvvaTables<R> {
        &self.tables
    }

    /// Fixed point's Pmo lag h/(τ + h) for this step's τ (ms), τ and h both times 2^10 (h's
    /// own precision; τ ≤ 32 ms holds). τ follows the supply pressure, which moves little
    /// from one step to the next: one Newton step from the last step's lag, lag + r·lag/h with
    /// the residual r = h − (τ + h)·lag, squares its relative error (a few 1e-5 a step, below
    /// the lag's LSB after it), in three products where the long division costs about 65
    /// instructions on the target. The division where the last lag is more than 2^-9 off
    /// (the first step, a temperature's or a pressure's jump): within that the Newton step
    /// lands within a quarter of an LSB even for a lag near 1 (2^-18 relative). Within an LSB
    /// of the division's quotient either way (test).
    fn pmo_lag_fixed(&mut self, tau: R) -> R {
        let h = self.h.h_x1024;
        let d = tau.mul_pow2(10) + h;
        // In range: lag is in [0, 1] and d below the range.
        let r = h - d.mul_in_range(self.pmo_lag);
        let lag = if r.abs() < h.mul_pow2(-9) {
            // |r·(1/h)| < 2^-9 and lag < 1: both products in range.
            self.pmo_lag + r.mul_in_range(self.inv_h_x1024).mul_in_range(self.pmo_lag)
        } else {
            R::ONE - (d - h) / d
        };
        self.pmo_lag = lag;
        lag
    }

    /// One sub-step with the delayed Pmo `p_top` and the step's constants. Inlined: until
    /// session 21 the compiler hoisted every parameter out of the (two-pass) sub-step loop and
    /// spilled them to the stack (some 60 instructions a step), so it was kept a call; with
    /// fixed point's products fused and in range fewer values live across the loop, and the
    /// call and its arguments cost more (Q16.16 883 -> 843 instructions a step, f32 552 -> 553).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn substep(
        &mut self,
        u_pilot: bool,
        inputs: &EhvvaInputs<R>,
        p_top: R,
        lag: R,
        inv_1_plus_lag: R,
        inv_cd2: R,
        stroke: R,
    ) {
        // Eq. (10): τp dPmo/dt = −Pmo + u(Ph − Pl) + Pl, implicit: (Pmo + lag·Pin)/(1 + lag);
        // in fixed point `lag` is already lag/(1 + lag).
        let p_in = if u_pilot { self.m.p_high } else { self.m.p_low };
        self.p_mo = if R::IS_FLOAT {
            (self.p_mo + lag * p_in) * inv_1_plus_lag
        } else {
            // Both weights in [0, 1] and adding up to 1: the sum is between the two pressures.
            R::sum_of_products_in_range([(self.p_mo, inv_1_plus_lag), (lag, p_in)])
        };
        // Eq. (12) first line, with eqs. (5)-(6) as damping.
        let force = self.piston.static_force(p_top, self.m.p_low, self.m.lift);
        // Seated or at full lift and held there (much of an event): the same numbers as the
        // full sub-step, without the damping and the division it only scales.
        if self.piston.held_at_stop(&self.m, force, stroke) {
            self.piston
                .advance_held(&mut self.m, self.h, inputs.p_supply_mpa, inputs.p_back_mpa);
            return;
        }
        let k = if R::IS_FLOAT {
            self.piston
                .quadratic_gain_inv_cd2(inv_cd2, self.m.lift, self.m.vel, stroke, inputs.snubber_on)
        } else {
            self.piston
                .quadratic_gain_at(self.damping, self.m.lift, self.m.vel, stroke, inputs.snubber_on)
        };
        // Piston, end stops and eqs. (7)-(8).
        self.piston.advance(
            &mut self.m,
            force,
            k,
            self.h,
            stroke,
            inputs.p_supply_mpa,
            inputs.p_back_mpa,
        );
    }
}

impl<R: Real, const N: usize> EhvvaPlant<R> for EhvvaReduced<R, N> {
    fn step(&mut self, u_pilot: bool, inputs: &EhvvaInputs<R>) -> R {
        let stroke = self.piston.stroke(inputs.lift_high);
        if inputs.temp_c != self.at.temp_c() {
            self.at = self.tables.at_temperature(inputs.temp_c);
            self.damping = self.piston.damping_gains(self.at.inv_cd2());
        }
        let tau = self.at.tau_p_ms(self.m.p_high);
        let (td_open, td_close) = self.at.t_delay_pair_ms(self.m.p_high);
        let open_is_longer = td_open >= td_close;
        // In range: both delays are at most the line's (N − 1)·dt (`check_step_with`, and N is
        // below 2^15 in fixed point), so the delays in samples are below N.
        let d_open = td_open.mul_in_range(self.inv_dt);
        let d_close = td_close.mul_in_range(self.inv_dt);
        // Per-step constants of the sub-step loop: its implicit Pmo update (lag = h/τ and
        // 1/(1 + lag); in fixed point h/(τ + h) by `pmo_lag_fixed` and 1 − that).
        let (lag, inv_1_plus_lag) = if R::IS_FLOAT {
            let lag = self.h.h / tau;
            (lag, R::ONE / (R::ONE + lag))
        } else {
            let lag = self.pmo_lag_fixed(tau);
            (lag, R::ONE - lag)
        };
        let inv_cd2 = self.at.inv_cd2();
        let inv_n = self.inv_substeps;
        self.pmo_history.push(self.p_mo);
        // Delayed Pmo at the start of each sub-step (eq. (11)), `back` steps before the line's
        // newest sample. With many sub-steps (a host's fit runs ten a step) the line's index
        // work is done once a step (`span`: 4 % of a diagnosis's instructions); with one or two
        // (the target's 10 µs step) that set-up costs more than it saves (f32 554 -> 701
        // instructions a step), and each read does its own. Floats only: in fixed point the
        // second loop cost the step's register allocation 94 instructions (792 -> 886).
        let spans = if R::IS_FLOAT && self.substeps > 2 {
            self.pmo_history.span(d_open).zip(self.pmo_history.span(d_close))
        } else {
            None
        };
        let mut back = R::ZERO;
        if let Some((open, close)) = spans {
            for _ in 0..self.substeps {
                let p_top = directional(open.at(back), close.at(back), open_is_longer);
                back += inv_n;
                self.substep(u_pilot, inputs, p_top, lag, inv_1_plus_lag, inv_cd2, stroke);
            }
        } else {
            for _ in 0..self.substeps {
                let p_top = directional(
                    self.pmo_history.get(d_open - back),
                    self.pmo_history.get(d_close - back),
                    open_is_longer,
                );
                back += inv_n;
                self.substep(u_pilot, inputs, p_top, lag, inv_1_plus_lag, inv_cd2, stroke);
            }
        }
        self.m.lift
    }

    fn dt_ms(&self) -> R {
        self.dt
    }
    fn lift_mm(&self) -> R {
        self.m.lift
    }
    fn velocity_m_s(&self) -> R {
        self.m.vel
    }
    fn take_seat_velocity(&mut self) -> Option<R> {
        self.m.seat_velocity.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ehvva::event::{run_event, ValveEvent};
    use crate::real::Q32;

    fn inputs(p_supply: f64, lift_high: bool) -> EhvvaInputs<f64> {
        EhvvaInputs {
            p_supply_mpa: p_supply,
            p_back_mpa: 1.0,
            temp_c: 22.0,
            lift_high,
            snubber_on: false,
        }
    }

    /// [`inputs`] in Q16.16 with a back pressure of its own (high lift, switch valve off).
    fn q16_inputs(p_supply: f64, p_back: f64) -> EhvvaInputs<crate::real::Q16> {
        use crate::real::Q16;
        EhvvaInputs {
            p_supply_mpa: Q16::from_f64(p_supply),
            p_back_mpa: Q16::from_f64(p_back),
            temp_c: Q16::from_f64(22.0),
            lift_high: true,
            snubber_on: false,
        }
    }

    #[test]
    fn the_fixed_point_pmo_lag_stays_within_an_lsb_of_the_division() {
        // Events at both ends of the supply range (τp follows the supply pressure, which the
        // piston draws down while it opens) and an oil temperature that jumps mid-event (τp
        // jumps: the Newton step's start is far off and the division takes over): every step's
        // lag within one LSB of h/(τ + h) by the long division, as the model took it before
        // session 21.
        use crate::real::Q16;
        let p = EhvvaParams::paper_default();
        for (p_supply, jump_to_c) in [(5.5, 90.0), (8.0, -20.0)] {
            let mut i = q16_inputs(p_supply, 2.0);
            let mut m = EhvvaReduced::<Q16>::new(&p, &i, 0.01).unwrap();
            let (mut max_lift, mut p_high_min) = (0.0f64, f64::MAX);
            for k in 0..2500 {
                if k == 1200 {
                    i.temp_c = Q16::from_f64(jump_to_c);
                }
                let at = m.tables.at_temperature(i.temp_c);
                let tau_x1024 = at.tau_p_ms(m.m.p_high).mul_pow2(10);
                let want = Q16::ONE - tau_x1024 / (tau_x1024 + m.h.h_x1024);
                max_lift = max_lift.max(m.step((100..1100).contains(&k), &i).to_f64());
                p_high_min = p_high_min.min(m.m.p_high.to_f64());
                let off = (m.pmo_lag.to_bits() - want.to_bits()).abs();
                assert!(off <= 1, "{p_supply} MPa, step {k}: lag {:?} vs {:?}", m.pmo_lag, want);
            }
            // The valve opened, and the supply pressure (with it τp) moved along the way.
            assert!(
                max_lift > 6.0 && p_high_min < p_supply - 0.01,
                "{max_lift} mm, {p_high_min} MPa"
            );
        }
    }

    /// Steps `a` and `b` side by side for `steps` steps with the pilot on from step 100 to
    /// 1100; the largest lift (in mm) and whether every step's lift, velocity and pressures
    /// were the same.
    fn side_by_side<R: Real>(
        a: &mut EhvvaReduced<R>,
        b: &mut EhvvaReduced<R>,
        i: &EhvvaInputs<R>,
        steps: usize,
    ) -> (f64, bool) {
        let state = |m: &EhvvaReduced<R>| [m.m.lift, m.m.vel, m.p_mo, m.m.p_high, m.m.p_low].map(R::to_f64);
        let (mut max_lift, mut same) = (0.0f64, true);
        for k in 0..steps {
            let on = (100..1100).contains(&k);
            a.step(on, i);
            b.step(on, i);
            same &= state(a).map(f64::to_bits) == state(b).map(f64::to_bits);
            max_lift = max_lift.max(a.m.lift.to_f64());
        }
        (max_lift, same)
    }

    /// An event stopped with the pilot on (the valve open, Pmo's history high), then the model
    /// put back at rest for `then`: from there bit for bit a new model's.
    fn runs_as_new_after_rest_at<R: Real>(first: EhvvaInputs<R>, then: EhvvaInputs<R>) {
        let p = EhvvaParams::paper_default();
        let mut used = EhvvaReduced::<R>::new(&p, &first, 0.01).unwrap();
        let mut twin = EhvvaReduced::<R>::new(&p, &first, 0.01).unwrap();
        assert!(side_by_side(&mut used, &mut twin, &first, 800).0 > 3.0);
        used.rest_at(&then);
        let mut fresh = EhvvaReduced::<R>::new(&p, &then, 0.01).unwrap();
        let (max_lift, same) = side_by_side(&mut used, &mut fresh, &then, 2500);
        assert!(max_lift > 1.0 && same, "{max_lift} mm, same {same}");
    }

    #[test]
    fn a_model_put_back_at_rest_runs_as_a_new_one() {
        // Another supply, back pressure and oil temperature (the table's slice), and in fixed
        // point the same supply and temperature (the Pmo lag's Newton step from the last
        // step's, which a new model does not have).
        let mut first = inputs(8.0, true);
        (first.temp_c, first.p_back_mpa) = (100.0, 3.0);
        runs_as_new_after_rest_at(first, inputs(5.5, false));
        use crate::real::Q16;
        let mut q_first = q16_inputs(8.0, 3.0);
        q_first.temp_c = Q16::from_f64(100.0);
        runs_as_new_after_rest_at(q_first, q16_inputs(5.5, 1.0));
        runs_as_new_after_rest_at(q16_inputs(7.0, 1.0), q16_inputs(7.0, 2.0));
    }

    #[test]
    fn fixed_point_refuses_a_cd_table_its_damping_gains_cannot_hold() {
        // Cd 0.05 (the tables' floor) makes ρ/2·At³/Cd² 38 000, beyond the 2^13 the fixed
        // point's sum of products is proven for: refused by the table's name, in Q16.16 only.
        use crate::real::Q16;
        let mut p = EhvvaParams::paper_default();
        p.tables.cd[0] = 0.05;
        let i = inputs(7.0, true);
        let qi = q16_inputs(7.0, 1.0);
        assert_eq!(
            EhvvaReduced::<Q16>::new(&p, &qi, 0.01).err(),
            Some(EhvvaError::InvalidParameter("tables.cd"))
        );
        assert!(EhvvaReduced::<f64>::new(&p, &i, 0.01).is_ok());
        // The paper's table (Cd 0.21 at -20 °C: 2 170) is taken.
        assert!(EhvvaReduced::<Q16>::new(&EhvvaParams::paper_default(), &qi, 0.01).is_ok());
    }

    #[test]
    fn rejects_bad_step_and_short_delay_line() {
        let p = EhvvaParams::paper_default();
        let i = inputs(7.0, true);
        assert_eq!(
            EhvvaReduced::<f64>::new(&p, &i, 0.0).err(),
            Some(EhvvaError::InvalidParameter("dt_ms"))
        );
        assert_eq!(
            EhvvaReduced::<f64>::new(&p, &i, f64::NAN).err(),
            Some(EhvvaError::InvalidParameter("dt_ms"))
        );
        // 64 samples of 0.02 ms hold 1.26 ms, far less than the 4.2 ms table maximum.
        assert!(matches!(
            EhvvaReduced::<f64, 64>::new(&p, &i, 0.02),
            Err(EhvvaError::DelayLineTooShort { .. })
        ));
        let mut bad = p;
        bad.mass_kg = -1.0;
        assert_eq!(
            EhvvaReduced::<f64>::new(&bad, &i, 0.02).err(),
            Some(EhvvaError::InvalidParameter("mass_kg"))
        );
    }

    /// The sub-step of a fit's first approach (25 µs, two a 20 kHz sample) over Table 1's
    /// supply pressures, both lifts and three oil temperatures: stable (finite, within the
    /// stroke, its highest lift within 1 % of the model's: a slow opening at 5 MPa, -20 °C
    /// need not reach the stop in the dwell), the lift near the model's own and its opening and
    /// closing times within 0.05 ms; a bound outside (0, MAX_STEP_MS] is refused.
    #[test]
    fn a_coarser_substep_stays_stable_and_near_the_models_own() {
        let p = EhvvaParams::paper_default();
        let mut worst_rms_pct: f64 = 0.0;
        for p_supply in [5.0, 6.5, 8.0] {
            for lift_high in [false, true] {
                for temp_c in [-20.0, 22.0, 100.0] {
                    let i = EhvvaInputs {
                        temp_c,
                        ..inputs(p_supply, lift_high)
                    };
                    let stroke = if lift_high { p.lift_high_mm } else { p.lift_low_mm };
                    let ev = ValveEvent::with_dwell(8.0);
                    let mut fine = EhvvaReduced::<f64>::new(&p, &i, 0.05).unwrap();
                    let mut coarse = EhvvaReduced::<f64>::with_max_substep(&p, &i, 0.05, 0.025).unwrap();
                    // 34 ms of 0.05 ms samples.
                    let (mut a, mut b) = ([0.0f64; 1024], [0.0f64; 1024]);
                    let (mut na, mut nb) = (0, 0);
                    let rf = run_event(&mut fine, &ev, &i, stroke, |_, y| {
                        a[na] = y;
                        na += 1;
                    });
                    let rc = run_event(&mut coarse, &ev, &i, stroke, |_, y| {
                        b[nb] = y;
                        nb += 1;
                    });
                    assert_eq!(na, nb);
                    let (a, b) = (&a[..na], &b[..nb]);
                    assert!(b.iter().all(|y| y.is_finite() && (0.0..=stroke).contains(y)));
                    let (top_fine, top_coarse) = (
                        a.iter().cloned().fold(0.0, f64::max),
                        b.iter().cloned().fold(0.0, f64::max),
                    );
                    assert!(
                        (top_fine - top_coarse).abs() < 0.01 * stroke,
                        "{p_supply} MPa {temp_c} C: {top_fine} {top_coarse}"
                    );
                    let rms = libm::sqrt(a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / na as f64);
                    worst_rms_pct = worst_rms_pct.max(100.0 * rms / stroke);
                    // Both times or neither (a valve slower than the dwell has no closing time).
                    let close = |x: Option<f64>, y: Option<f64>| match (x, y) {
                        (Some(x), Some(y)) => (x - y).abs(),
                        (None, None) => 0.0,
                        _ => f64::INFINITY,
                    };
                    let d_open = close(rf.opening_delay_ms(), rc.opening_delay_ms());
                    let d_close = close(rf.closing_time_ms(), rc.closing_time_ms());
                    assert!(
                        d_open < 0.05 && d_close < 0.05,
                        "{p_supply} MPa, high {lift_high}, {temp_c} C: opening {d_open} ms, closing {d_close} ms apart"
                    );
                }
            }
        }
        // Measured 0.24 % (5 MPa, -20 °C, low lift: the slow opening); and the bound is used.
        assert!(worst_rms_pct < 0.5 && worst_rms_pct > 0.01, "{worst_rms_pct} %");
        let i = inputs(7.0, true);
        for bad in [0.0, -0.01, f64::NAN, 0.2] {
            assert_eq!(
                EhvvaReduced::<f64>::with_max_substep(&p, &i, 0.05, bad).err(),
                Some(EhvvaError::InvalidParameter("max_substep_ms"))
            );
        }
    }

    #[test]
    fn stays_seated_without_command_and_within_stroke_with_it() {
        let p = EhvvaParams::paper_default();
        for lift_high in [false, true] {
            let i = inputs(8.0, lift_high);
            let mut m = EhvvaReduced::<f64>::new(&p, &i, 0.02).unwrap();
            for _ in 0..300 {
                assert_eq!(m.step(false, &i), 0.0);
            }
            let stroke = if lift_high { p.lift_high_mm } else { p.lift_low_mm };
            let mut max: f64 = 0.0;
            for _ in 0..600 {
                let y = m.step(true, &i);
                assert!((0.0..=stroke).contains(&y));
                max = max.max(y);
            }
            assert_eq!(max, stroke, "does not reach the lift stop");
            // The supply accumulator gave the swept volume At·S (eq. (8)) and the pump and
            // relief bring it back towards the set-point.
            assert!(m.p_high_mpa() < 8.0);
        }
    }

    #[test]
    fn nothing_moves_before_the_actuation_delay() {
        // Eq. (11): the piston sees Pmo only td after the command.
        let p = EhvvaParams::paper_default();
        let i = inputs(7.0, true);
        let td = EhvvaTables::<f64>::new(&p).unwrap().t_delay_ms(7.0, 22.0, true);
        let mut m = EhvvaReduced::<f64>::new(&p, &i, 0.02).unwrap();
        let ev = ValveEvent {
            t_open_ms: 1.0,
            dwell_ms: 8.0,
            t_end_ms: 30.0,
        };
        let r = run_event(&mut m, &ev, &i, 7.5, |t, y| {
            if t < 1.0 + td {
                assert_eq!(y, 0.0, "moved at {t} ms, before td = {td}");
            }
        });
        assert!(r.opening_delay_ms().unwrap() > td);
    }

    #[test]
    fn runs_in_q32() {
        // Fixed point gives the same event to within a few µm.
        let p = EhvvaParams::paper_default();
        let fi = inputs(6.0, false);
        let qi = EhvvaInputs::<Q32> {
            p_supply_mpa: Q32::from_f64(6.0),
            p_back_mpa: Q32::ONE,
            temp_c: Q32::from_f64(22.0),
            lift_high: false,
            snubber_on: false,
        };
        let mut mf = EhvvaReduced::<f64>::new(&p, &fi, 0.02).unwrap();
        let mut mq = EhvvaReduced::<Q32>::new(&p, &qi, 0.02).unwrap();
        for k in 0..1500 {
            let u = (50..450).contains(&k);
            let yf = mf.step(u, &fi);
            let yq = mq.step(u, &qi).to_f64();
            assert!((yf - yq).abs() < 1e-3, "step {k}: {yf} vs {yq}");
        }
    }

    #[test]
    fn runs_in_q16_close_to_f64_over_whole_events() {
        // The target's 10 µs step, a whole high-lift event with the snubber: in Q16.16 a step
        // times the reciprocal mass is 1.8 LSB, so `Real::step_times` forms the gain times the
        // force first (left to right the piston ran 11 % fast).
        use crate::real::Q16;
        let p = EhvvaParams::paper_default();
        // Tolerance in % of the stroke: 0.1 (issue #14's goal) at 6.5 and 8 MPa; 1 at 5 MPa, where
        // the pressure force on the top area (60.8 mm² x 5 MPa = 304 N) barely exceeds the
        // spring's preload (252 N), so a rounding of the pressure force is six times larger in
        // the net force that moves the piston (measured: 0.43 % there, 0.03-0.05 % above).
        for (p_supply, tol_pct) in [(8.0, 0.1), (6.5, 0.1), (5.0, 1.0)] {
            let fi = EhvvaInputs {
                snubber_on: true,
                ..inputs(p_supply, true)
            };
            let qi = EhvvaInputs::<Q16> {
                p_supply_mpa: Q16::from_f64(p_supply),
                p_back_mpa: Q16::ONE,
                temp_c: Q16::from_f64(22.0),
                lift_high: true,
                snubber_on: true,
            };
            let mut mf = EhvvaReduced::<f64>::new(&p, &fi, 0.01).unwrap();
            let mut mq = EhvvaReduced::<Q16>::new(&p, &qi, 0.01).unwrap();
            let mut max_lift: f64 = 0.0;
            for k in 0..3000 {
                let u = (100..1100).contains(&k);
                let yf = mf.step(u, &fi);
                let yq = mq.step(u, &qi).to_f64();
                max_lift = max_lift.max(yf);
                assert!(
                    (yf - yq).abs() <= tol_pct / 100.0 * p.lift_high_mm,
                    "{p_supply} MPa, step {k}: {yf} vs {yq}"
                );
            }
            assert!(max_lift > 6.0, "the event must open: {max_lift}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        /// Q16.16 against f64 over Table 1's envelope (supply 5.5-8 MPa, back pressure 1-4 MPa,
        /// -20..100 °C, both lifts and switch states, an 8-20 ms event and the closing after
        /// it, at the target's 10 µs step as Q16.16 holds it, so that the comparison is of the
        /// arithmetic): the lift within 0.1 % of the stroke (issue #14). Measured on a 3x3x3
        /// grid of the corners, both lifts and switch states, 8 and 20 ms events: 0.012 % at
        /// most. Session 18 0.21 %: the velocity stalled below its LSB near its terminal value
        /// (0.4 % low at 5.5 MPa, 4 MPa back pressure), partly offset by the sub-step held as
        /// 328 LSB for 327.5; before session 18 0.84 %: the accumulators stalled the same way
        /// and 1/m was held 1.4e-3 off.
        #[test]
        fn q16_lift_tracks_f64_over_the_envelope(c in crate::ehvva::envelope::cases()) {
            use crate::real::Q16;
            let dev = crate::ehvva::envelope::q16_lift_deviation(
                c,
                |p, i, dt| EhvvaReduced::<f64>::new(p, i, dt).unwrap(),
                |p, i, dt| EhvvaReduced::<Q16>::new(p, i, dt).unwrap(),
            );
            proptest::prop_assert!(dev <= 0.001, "{c:?}: lift {} % of the stroke off", 100.0 * dev);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        /// Whatever the operating point and command pattern: the lift stays within the stops,
        /// the velocity is zero on a stop it pushes against, and the accumulator pressures stay
        /// finite and between tank and the supply set-point plus the relief band.
        #[test]
        fn lift_stays_between_the_stops(
            p_supply in 4.0f64..9.0,
            p_back in 0.5f64..4.5,
            temp in -40.0f64..130.0,
            lift_high: bool,
            snubber_on: bool,
            pattern in proptest::collection::vec(proptest::bool::ANY, 8),
        ) {
            let p = EhvvaParams::paper_default();
            let stroke = if lift_high { p.lift_high_mm } else { p.lift_low_mm };
            // On the target number type.
            let fi = EhvvaInputs {
                p_supply_mpa: p_supply as f32,
                p_back_mpa: p_back as f32,
                temp_c: temp as f32,
                lift_high,
                snubber_on,
            };
            let mut m = EhvvaReduced::<f32>::new(&p, &fi, 0.02).unwrap();
            for (seg, &u) in pattern.iter().enumerate() {
                for _ in 0..(100 + 37 * seg) {
                    let y = m.step(u, &fi) as f64;
                    proptest::prop_assert!(y.is_finite() && (0.0..=stroke + 1e-6).contains(&y), "lift {}", y);
                    let ph = m.p_high_mpa() as f64;
                    let pl = m.p_low_mpa() as f64;
                    proptest::prop_assert!(ph > 0.0 && ph < p_supply + 0.2, "Ph {}", ph);
                    proptest::prop_assert!(pl > 0.0 && pl < p_back + 2.0, "Pl {}", pl);
                }
            }
        }
    }
}
