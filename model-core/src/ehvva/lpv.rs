//! Third-order LPV time-delay model, eqs. (13)-(15) of Li et al. 2018.
//!
//! State x = [x1, x2, x3] = [P̃mo, L + ds, L̇] (the delayed main-valve outlet pressure, the
//! spring deflection, the velocity), input u = [ũ, 1 − ũ] with ũ(t) = u(t − td) (eq. (14)),
//! output y = x2 − ds = L. The supply and back pressures are measured inputs (Sec. 4.2.1).
//!
//! ẋ = A(θ) x + B(θ) u with the affine parameter dependence
//! A(θ) = A0 + A1 θ1 + A2 θ2, B(θ) = B3 θ3 + B4 θ4 + B5 θ5 and the scheduling vector
//! θ = [1/τp(P̃h, T), K, P̃h/τp(P̃h, T), P̃l/τp(P̃h, T), Pl] (eq. (15)); K is the lumped damping
//! −Cf/me − ρ |x3| / (2 me Cd(T)²) · (At³/Aorit(x2)² + Ab³/Aorib(x2)²).
//!
//! In this crate's units (MPa, mm, ms, kg) every force term carries 1/(1000 me) (N/kg = m/s² =
//! 1e-3 mm/ms²): `A0[2][0] = At/(1000 me)`, `A0[2][1] = −ks/(1000 me)`, `B5[2] = −Ab/(1000 me)`,
//! and K is in 1/ms. The sign of B5 is the physical one (the back pressure on the piston
//! bottom pushes the valve closed, eq. (1)); the printed matrix lost the minus sign.
//!
//! The simulation [`EhvvaLpv`] evaluates A(θ) and B(θ) from [`LpvAffine`] every sub-step and
//! integrates with a semi-implicit Gauss-Seidel sweep (rows in the order velocity, position,
//! pressure, each row's diagonal term implicit), which for these matrices is the same scheme as
//! the reduced model's (see `reduced.rs`). The valve's end stops 0 ≤ L ≤ S (eq. (1)), which the
//! linear form leaves implicit, are applied after each sub-step. The delayed input and
//! parameters come from three delay lines: ũ and P̃h with td,VO, P̃l with td,VC, and ũ as the
//! min (td,VO ≥ td,VC) or max of the two delayed commands, so that a rising command is delayed
//! by td,VO and a falling one by td,VC.

use super::event::EhvvaPlant;
use super::params::{EhvvaError, EhvvaInputs, EhvvaParams};
use super::piston::{add_carried, Piston, SubStep};
use super::reduced::{check_step, directional, DEFAULT_DELAY_SAMPLES};
use super::tables::{EhvvaTables, EhvvaTablesAt};
use crate::delay::DelayLine;
use crate::real::Real;

/// Number of scheduling parameters θ1..θ5.
pub const N_THETA: usize = 5;

/// The affine LPV data of eq. (15), for controller design: A(θ) = A0 + Σ Ai θi,
/// B(θ) = Σ Bi θi, y = C x. Index i = 0..5 is θ(i+1); matrices not in the paper's sum are 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LpvAffine<R: Real> {
    pub a0: [[R; 3]; 3],
    pub a: [[[R; 3]; 3]; N_THETA],
    pub b: [[[R; 2]; 3]; N_THETA],
    pub c: [R; 3],
}

impl<R: Real> LpvAffine<R> {
    pub fn from_params(params: &EhvvaParams) -> Result<Self, EhvvaError> {
        params.validate()?;
        let z = R::ZERO;
        let o = R::ONE;
        let per_newton = 1.0 / (1000.0 * params.mass_kg);
        let a31 = R::from_f64(params.area_top_mm2 * per_newton);
        let a32 = R::from_f64(-params.spring_n_per_mm * per_newton);
        let b5 = R::from_f64(-params.area_bottom_mm2 * per_newton);
        let zero3 = [[z; 3]; 3];
        let zero32 = [[z; 2]; 3];
        Ok(Self {
            a0: [[z, z, z], [z, z, o], [a31, a32, z]],
            a: [
                [[-o, z, z], [z, z, z], [z, z, z]],
                [[z, z, z], [z, z, z], [z, z, o]],
                zero3,
                zero3,
                zero3,
            ],
            b: [
                zero32,
                zero32,
                [[o, z], [z, z], [z, z]],
                [[z, o], [z, z], [z, z]],
                [[z, z], [z, z], [b5, b5]],
            ],
            c: [z, o, z],
        })
    }

    /// A(θ) = A0 + Σ Ai θi. In fixed point the zero entries of the Ai (all but two of 45)
    /// are skipped, which there changes nothing; the floats add every product (`0·θ` can be
    /// −0 or NaN there).
    pub fn a_matrix(&self, theta: &[R; N_THETA]) -> [[R; 3]; 3] {
        let mut m = self.a0;
        for (ai, &t) in self.a.iter().zip(theta) {
            for (row, ai_row) in m.iter_mut().zip(ai) {
                for (e, &aij) in row.iter_mut().zip(ai_row) {
                    if R::IS_FLOAT || aij != R::ZERO {
                        *e += aij * t;
                    }
                }
            }
        }
        m
    }

    /// B(θ) = Σ Bi θi (zero entries skipped in fixed point, as in [`Self::a_matrix`]).
    pub fn b_matrix(&self, theta: &[R; N_THETA]) -> [[R; 2]; 3] {
        let mut m = [[R::ZERO; 2]; 3];
        for (bi, &t) in self.b.iter().zip(theta) {
            for (row, bi_row) in m.iter_mut().zip(bi) {
                for (e, &bij) in row.iter_mut().zip(bi_row) {
                    if R::IS_FLOAT || bij != R::ZERO {
                        *e += bij * t;
                    }
                }
            }
        }
        m
    }
}

/// The entries of the Ai that [`LpvAffine::from_params`] can make nonzero, as (θ index, row,
/// column), in the order [`LpvAffine::a_matrix`] adds them: A1 = −e11 and A2 = e33 of eq. (15).
const A_TERMS: [(usize, usize, usize); 2] = [(0, 0, 0), (1, 2, 2)];
/// The same for the Bi: B3 and B4 in the first row, B5 in the third.
const B_TERMS: [(usize, usize, usize); 4] = [(2, 0, 0), (3, 0, 1), (4, 2, 0), (4, 2, 1)];

/// A(θ) of an affine form from [`LpvAffine::from_params`], in fixed point: A0 plus the entries
/// of [`A_TERMS`] times their θ, in θ order. The same sums as [`LpvAffine::a_matrix`] there (it
/// skips the other entries, all zero), so the same bits, without testing all 45 entries every
/// sub-step.
#[inline(always)]
fn fixed_a_matrix<R: Real>(affine: &LpvAffine<R>, theta: &[R; N_THETA]) -> [[R; 3]; 3] {
    let mut a = affine.a0;
    for (t, r, c) in A_TERMS {
        a[r][c] += affine.a[t][r][c] * theta[t];
    }
    a
}

/// B(θ) likewise from [`B_TERMS`] (the sums of [`LpvAffine::b_matrix`] in fixed point).
#[inline(always)]
fn fixed_b_matrix<R: Real>(affine: &LpvAffine<R>, theta: &[R; N_THETA]) -> [[R; 2]; 3] {
    let mut b = [[R::ZERO; 2]; 3];
    for (t, r, c) in B_TERMS {
        b[r][c] += affine.b[t][r][c] * theta[t];
    }
    b
}

/// The LPV time-delay model of eq. (15) as a simulation. `N` is the delay-line length.
#[derive(Clone, Debug)]
pub struct EhvvaLpv<R: Real, const N: usize = DEFAULT_DELAY_SAMPLES> {
    affine: LpvAffine<R>,
    piston: Piston<R>,
    tables: EhvvaTables<R>,
    /// `tables` at the last step's oil temperature.
    at: EhvvaTablesAt<R>,
    preload: R,
    dt: R,
    inv_dt: R,
    h: SubStep<R>,
    substeps: usize,
    /// 1/substeps, converted once (a run-time `from_f64` is soft-float on the target).
    inv_substeps: R,
    x: [R; 3],
    theta: [R; N_THETA],
    u_history: DelayLine<R, N>,
    p_high_history: DelayLine<R, N>,
    p_low_history: DelayLine<R, N>,
    seat_velocity: Option<R>,
    /// Fixed point: what each state of `x` gained below its LSB, times 2^10; 0 for the floats.
    carry_x1024: [R; 3],
}

impl<R: Real, const N: usize> EhvvaLpv<R, N> {
    /// A model at rest (valve seated, x1 = Pl) for the operating point `inputs` (measured Ph,
    /// Pl), stepped every `dt_ms` (≤ 0.1 ms).
    pub fn new(params: &EhvvaParams, inputs: &EhvvaInputs<R>, dt_ms: f64) -> Result<Self, EhvvaError> {
        let substeps = check_step(params, dt_ms, N)?;
        let preload = R::from_f64(params.spring_preload_mm);
        let tables = EhvvaTables::new(params)?;
        Ok(Self {
            affine: LpvAffine::from_params(params)?,
            piston: Piston::new(params)?,
            at: tables.at_temperature(inputs.temp_c),
            tables,
            preload,
            dt: R::from_f64(dt_ms),
            inv_dt: R::from_f64(1.0 / dt_ms),
            h: SubStep::new(dt_ms / substeps as f64, params)?,
            substeps,
            inv_substeps: R::ONE / R::from_f64(substeps as f64),
            x: [inputs.p_back_mpa, preload, R::ZERO],
            theta: [R::ZERO; N_THETA],
            u_history: DelayLine::new(R::ZERO),
            p_high_history: DelayLine::new(inputs.p_supply_mpa),
            p_low_history: DelayLine::new(inputs.p_back_mpa),
            seat_velocity: None,
            carry_x1024: [R::ZERO; 3],
        })
    }

    /// The affine matrices this model integrates.
    pub fn affine(&self) -> &LpvAffine<R> {
        &self.affine
    }
    /// The state [P̃mo, L + ds, L̇].
    pub fn state(&self) -> [R; 3] {
        self.x
    }
    /// The scheduling vector θ of the last sub-step.
    pub fn theta(&self) -> [R; N_THETA] {
        self.theta
    }

    /// θ of eq. (15) from the delayed command-side pressures, the current back pressure and
    /// the state (θ2 = K needs x2, x3 and Cd(T)).
    #[allow(clippy::too_many_arguments)]
    pub fn scheduling(
        &self,
        p_high_delayed: R,
        p_low_delayed: R,
        p_low: R,
        temp_c: R,
        stroke: R,
        snubber_on: bool,
    ) -> [R; N_THETA] {
        // The tables at temp_c: the step's (kept in `at`) or computed afresh.
        let fresh;
        let at = if temp_c == self.at.temp_c() {
            &self.at
        } else {
            fresh = self.tables.at_temperature(temp_c);
            &fresh
        };
        let tau = at.tau_p_ms(p_high_delayed);
        let inv_tau = R::ONE / tau;
        let cd = at.cd();
        let lift = self.x[1] - self.preload;
        let vel = self.x[2];
        // Fixed point multiplies by the tables' 1/Cd² instead of dividing by Cd² (a long
        // division); the floats keep their division.
        let quad = if R::IS_FLOAT {
            self.piston.quadratic_gain(cd, lift, vel, stroke, snubber_on)
        } else {
            self.piston
                .quadratic_gain_inv_cd2(at.inv_cd2(), lift, vel, stroke, snubber_on)
        };
        let k = -(self.piston.friction + quad * vel.abs()) * self.piston.accel_per_newton;
        [inv_tau, k, p_high_delayed * inv_tau, p_low_delayed * inv_tau, p_low]
    }
}

impl<R: Real, const N: usize> EhvvaPlant<R> for EhvvaLpv<R, N> {
    fn step(&mut self, u_pilot: bool, inputs: &EhvvaInputs<R>) -> R {
        let stroke = self.piston.stroke(inputs.lift_high);
        if inputs.temp_c != self.at.temp_c() {
            self.at = self.tables.at_temperature(inputs.temp_c);
        }
        let (td_open, td_close) = self.at.t_delay_pair_ms(inputs.p_supply_mpa);
        let open_is_longer = td_open >= td_close;
        let d_open = td_open * self.inv_dt;
        let d_close = td_close * self.inv_dt;
        self.u_history.push(if u_pilot { R::ONE } else { R::ZERO });
        self.p_high_history.push(inputs.p_supply_mpa);
        self.p_low_history.push(inputs.p_back_mpa);
        let inv_n = self.inv_substeps;
        let mut back = R::ZERO;
        for _ in 0..self.substeps {
            let u_delayed = directional(
                self.u_history.get(d_open - back),
                self.u_history.get(d_close - back),
                open_is_longer,
            );
            let p_high_delayed = self.p_high_history.get(d_open - back);
            let p_low_delayed = self.p_low_history.get(d_close - back);
            back += inv_n;
            self.theta = self.scheduling(
                p_high_delayed,
                p_low_delayed,
                inputs.p_back_mpa,
                inputs.temp_c,
                stroke,
                inputs.snubber_on,
            );
            // Fixed point sums only the nonzero entries (the same sums: x + 0·θ is x there).
            let a = if R::IS_FLOAT {
                self.affine.a_matrix(&self.theta)
            } else {
                fixed_a_matrix(&self.affine, &self.theta)
            };
            let b = if R::IS_FLOAT {
                self.affine.b_matrix(&self.theta)
            } else {
                fixed_b_matrix(&self.affine, &self.theta)
            };
            let u = [u_delayed, R::ONE - u_delayed];
            // The lift before this sub-step, read from the state as stored (after the last
            // clamp, exactly 0 on the seat): reconstructing it from the new state as
            // `lift − h·v` leaves a rounding residue of (ds + h·v) − ds − h·v that made every
            // sub-step on the seat look like a fresh landing at h·a ≈ 0.005 m/s, overwriting the
            // real seating velocity (issue #14).
            let lift_before = self.x[1] - self.preload;
            // Semi-implicit Gauss-Seidel sweep: velocity, position, pressure.
            // Fixed point skips the products with a zero entry (6 of the 12 off the diagonal,
            // and the position row's diagonal): `x + 0·y` is `x` there.
            let times = |c: R, x: R| if !R::IS_FLOAT && c == R::ZERO { R::ZERO } else { c * x };
            for row in [2usize, 1, 0] {
                let mut rate = times(b[row][0], u[0]) + times(b[row][1], u[1]);
                for (col, (&a_rc, &x_c)) in a[row].iter().zip(self.x.iter()).enumerate() {
                    if col != row {
                        rate += times(a_rc, x_c);
                    }
                }
                if R::IS_FLOAT {
                    let num = self.x[row] + self.h.h * rate;
                    self.x[row] = num / (R::ONE - self.h.h * a[row][row]);
                } else {
                    // The same update as the increment h(rate + a_rr x)/(1 − h a_rr), formed
                    // times 2^10 with what lies below the LSB carried: near its steady value
                    // a row relaxes by less than an LSB a sub-step and, rounded each time,
                    // stalled (the velocity short of its terminal value: with the sub-step
                    // held exactly, the lift 0.37 % of the stroke off f64's at 5.5 MPa). The
                    // position row has no diagonal: no division.
                    let inc_x1024 = if a[row][row] == R::ZERO {
                        self.h.h_x1024 * rate
                    } else {
                        let ha_x1024 = self.h.h_x1024 * a[row][row];
                        (self.h.h_x1024 * rate + ha_x1024 * self.x[row]) / (R::ONE - ha_x1024.mul_pow2(-10))
                    };
                    add_carried(&mut self.x[row], &mut self.carry_x1024[row], inc_x1024);
                }
            }
            let lift = self.x[1] - self.preload;
            let (lift, vel, impact) = Piston::stops(lift, self.x[2], stroke);
            if !R::IS_FLOAT && lift != self.x[1] - self.preload {
                // On a stop: nothing below the LSB of a motion that ended.
                self.carry_x1024[1] = R::ZERO;
                self.carry_x1024[2] = R::ZERO;
            }
            if impact.is_some() && lift_before > R::ZERO {
                self.seat_velocity = impact;
            }
            self.x[1] = lift + self.preload;
            self.x[2] = vel;
        }
        self.x[1] - self.preload
    }

    fn dt_ms(&self) -> R {
        self.dt
    }
    fn lift_mm(&self) -> R {
        self.x[1] - self.preload
    }
    fn velocity_m_s(&self) -> R {
        self.x[2]
    }
    fn take_seat_velocity(&mut self) -> Option<R> {
        self.seat_velocity.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn affine_form_reproduces_eq15_entries() {
        let p = EhvvaParams::paper_default();
        let lpv = LpvAffine::<f64>::from_params(&p).unwrap();
        let theta = [8.0, -3.0, 60.0, 9.0, 1.5];
        let a = lpv.a_matrix(&theta);
        let b = lpv.b_matrix(&theta);
        let per_n = 1.0 / (1000.0 * p.mass_kg);
        let expect_a = [
            [-8.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [p.area_top_mm2 * per_n, -p.spring_n_per_mm * per_n, -3.0],
        ];
        let expect_b = [[60.0, 9.0], [0.0, 0.0], [-p.area_bottom_mm2 * per_n * 1.5; 2]];
        for i in 0..3 {
            for j in 0..3 {
                assert!((a[i][j] - expect_a[i][j]).abs() < 1e-12, "A[{i}][{j}]");
            }
            for j in 0..2 {
                assert!((b[i][j] - expect_b[i][j]).abs() < 1e-12, "B[{i}][{j}]");
            }
        }
        assert_eq!(lpv.c, [0.0, 1.0, 0.0]);
    }

    #[test]
    fn fixed_matrices_give_the_dense_sums() {
        use crate::Q16;
        let p = EhvvaParams::paper_default();
        let lpv = LpvAffine::<Q16>::from_params(&p).unwrap();
        // Every nonzero entry of the Ai and Bi is listed.
        for t in 0..N_THETA {
            for r in 0..3 {
                for c in 0..3 {
                    assert!(lpv.a[t][r][c] == Q16::ZERO || A_TERMS.contains(&(t, r, c)));
                }
                for c in 0..2 {
                    assert!(lpv.b[t][r][c] == Q16::ZERO || B_TERMS.contains(&(t, r, c)));
                }
            }
        }
        for theta in [[8.0, -3.0, 60.0, 9.0, 1.5], [0.1, -700.0, 30_000.0, -2.0, 0.0]] {
            let theta = theta.map(Q16::from_f64);
            assert_eq!(fixed_a_matrix(&lpv, &theta), lpv.a_matrix(&theta));
            assert_eq!(fixed_b_matrix(&lpv, &theta), lpv.b_matrix(&theta));
        }
    }

    #[test]
    fn valve_at_rest_stays_at_rest() {
        // With the pilot off the spring preload holds the valve on its seat.
        let p = EhvvaParams::paper_default();
        let inputs = EhvvaInputs {
            p_supply_mpa: 8.0,
            p_back_mpa: 1.0,
            temp_c: 22.0,
            lift_high: true,
            snubber_on: true,
        };
        let mut m = EhvvaLpv::<f64>::new(&p, &inputs, 0.02).unwrap();
        for _ in 0..500 {
            assert_eq!(m.step(false, &inputs), 0.0);
        }
        let th = m.theta();
        assert!(th[0] > 5.0 && th[0] < 20.0, "1/τp = {}", th[0]);
        assert!((th[4] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn seating_velocity_is_the_landing_not_the_seat_holding_the_valve() {
        // Over the 15 tests of Table 1 the LPV model lands as fast as the reduced model it is
        // transformed from (they share eqs. (1), (5)-(6)); before the fix 3 of them (all now
        // landing at 0.05-1.6 m/s) reported about 0.005 m/s: the seat holding the valve.
        use crate::ehvva::event::{run_event, ValveEvent};
        use crate::ehvva::params::PAPER_TESTS;
        use crate::ehvva::reduced::EhvvaReduced;
        let p = EhvvaParams::paper_default();
        for t in PAPER_TESTS.iter() {
            let inputs = EhvvaInputs::<f64>::from_test(t);
            let stroke = if t.lift_high { p.lift_high_mm } else { p.lift_low_mm };
            let ev = ValveEvent::with_dwell(t.dwell_ms);
            let mut red = EhvvaReduced::<f64>::new(&p, &inputs, 0.02).unwrap();
            let mut lpv = EhvvaLpv::<f64>::new(&p, &inputs, 0.02).unwrap();
            let v_red = run_event(&mut red, &ev, &inputs, stroke, |_, _| {})
                .seating_velocity_m_s
                .unwrap();
            let v_lpv = run_event(&mut lpv, &ev, &inputs, stroke, |_, _| {})
                .seating_velocity_m_s
                .unwrap();
            assert!(v_red > 0.04, "test {}: reduced {v_red}", t.number);
            // Here the LPV model sees the set-point pressures, the reduced model its
            // accumulators; at 2-4 MPa back pressure the returned oil raises Pl during the slow
            // seating, so only the 1 MPa tests are held to 10 %.
            let tol = if t.p_back_mpa <= 1.0 { 0.1 } else { 0.5 };
            assert!(
                (v_lpv - v_red).abs() <= tol * v_red,
                "test {}: LPV {v_lpv} m/s, reduced {v_red} m/s",
                t.number
            );
        }
    }
}

#[cfg(test)]
mod envelope_tests {
    use super::*;
    use crate::real::Q16;

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        /// Q16.16 against f64 over Table 1's envelope, as the reduced model's test
        /// (`q16_lift_tracks_f64_over_the_envelope` in reduced.rs): the lift within 0.1 % of
        /// the stroke. Measured on the same grid: 0.030 % at most; 0.25 % in session 18, before
        /// each state's increment below its LSB was carried.
        #[test]
        fn q16_lpv_lift_tracks_f64_over_the_envelope(c in crate::ehvva::envelope::cases()) {
            let dev = crate::ehvva::envelope::q16_lift_deviation(
                c,
                |p, i, dt| EhvvaLpv::<f64>::new(p, i, dt).unwrap(),
                |p, i, dt| EhvvaLpv::<Q16>::new(p, i, dt).unwrap(),
            );
            proptest::prop_assert!(dev <= 0.001, "{c:?}: lift {} % of the stroke off", 100.0 * dev);
        }
    }
}
