//! Actuation piston, snubbers and accumulators shared by the three EHVVA models: eq. (1)
//! (piston with end stops), eqs. (5)-(6) (top and bottom snubbers as equivalent orifices) and
//! eqs. (7)-(8) (accumulators).
//!
//! Units: lift mm, time ms, velocity mm/ms (= m/s), pressure MPa, area mm², force N
//! (MPa·mm² = N), mass kg, so an acceleration in mm/ms² is F[N] / m[kg] / 1000.
//! An orifice of area A passing the piston flow A_p·v drops ρ/2·(A_p v / (Cd A))²; with ρ in
//! kg/m³ and the velocity ratio in m/s this is ρ/2·1e-6 MPa per (m/s)².

use super::params::{EhvvaError, EhvvaInputs, EhvvaParams};
use crate::real::Real;

/// Physical constants of the piston, snubbers and accumulators in the model's number type.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Piston<R: Real> {
    pub area_top: R,
    pub area_bottom: R,
    /// 1/(1000·me): N → mm/ms².
    pub accel_per_newton: R,
    pub spring: R,
    pub preload: R,
    pub friction: R,
    pub lift_high: R,
    pub lift_low: R,
    /// ρ/2·1e-6·At³ and ρ/2·1e-6·Ab³: the quadratic damping force is these times
    /// (1/A²)·v·|v| / Cd² (eqs. (5), (6) times the piston areas).
    half_rho_at3: R,
    half_rho_ab3: R,
    inv_a2_main: R,
    area_top_orifice: R,
    area_top_switch: R,
    area_top_notch: R,
    /// Ls1 scaled by the `snubber` effect gain (0 = no zone).
    snub_top_len: R,
    inv_a2_bottom_port: R,
    area_bottom_notch: R,
    area_bottom_min: R,
    snub_bottom_len: R,
    /// `snub_top_len`, `snub_bottom_len` as divisors.
    snub_top_len_div: R::Divisor,
    snub_bottom_len_div: R::Divisor,
    /// 1/A² of the top snubber with its notch uncovered ([switch off, on]) and of the bottom
    /// orifice with its notch uncovered: the values outside the snubbing zones, computed once
    /// by the same operations (no division per sub-step).
    inv_a2_top_snubber_open: [R; 2],
    inv_a2_bottom_open: R,
    inv_cap_high: R,
    inv_cap_low: R,
    pump: R,
    relief_high: R,
    /// Pump flow / relief gain, MPa: how far below the set-point the relief cracks. Divided
    /// once in f64 (a Q16.16 division of two small numbers loses most of the quotient's bits;
    /// in f64 it is the same number as dividing per step).
    pump_over_relief_high: R,
    relief_low: R,
}

impl<R: Real> Piston<R> {
    pub fn new(p: &EhvvaParams) -> Result<Self, EhvvaError> {
        p.validate()?;
        let half_rho = 0.5 * p.density_kg_m3 * 1e-6;
        if !R::IS_FLOAT {
            // The fixed-point force and damping sum exact products of these with any state
            // (`Real::sum_of_products`): each factor below 2^13.
            for (v, name) in [
                (p.area_top_mm2, "area_top_mm2"),
                (p.area_bottom_mm2, "area_bottom_mm2"),
                (p.spring_n_per_mm, "spring_n_per_mm"),
                // ρ/2·A³ of the orifice damping (95 for the paper's top area).
                (
                    half_rho * p.area_top_mm2 * p.area_top_mm2 * p.area_top_mm2,
                    "area_top_mm2",
                ),
                (
                    half_rho * p.area_bottom_mm2 * p.area_bottom_mm2 * p.area_bottom_mm2,
                    "area_bottom_mm2",
                ),
            ] {
                if v >= 8192.0 {
                    return Err(EhvvaError::InvalidParameter(name));
                }
            }
        }
        let r = R::from_f64;
        let mut piston = Self {
            area_top: r(p.area_top_mm2),
            area_bottom: r(p.area_bottom_mm2),
            accel_per_newton: r(1.0 / (1000.0 * p.mass_kg)),
            spring: r(p.spring_n_per_mm),
            preload: r(p.spring_preload_mm),
            friction: r(p.friction_n_per_m_s),
            lift_high: r(p.lift_high_mm),
            lift_low: r(p.lift_low_mm),
            half_rho_at3: r(half_rho * p.area_top_mm2 * p.area_top_mm2 * p.area_top_mm2),
            half_rho_ab3: r(half_rho * p.area_bottom_mm2 * p.area_bottom_mm2 * p.area_bottom_mm2),
            inv_a2_main: r(1.0 / (p.area_main_mm2 * p.area_main_mm2)),
            area_top_orifice: r(p.area_top_orifice_mm2),
            area_top_switch: r(p.area_top_switch_orifice_mm2),
            area_top_notch: r(p.area_top_notch_mm2),
            snub_top_len: r(p.snub_top_len_mm * p.effect_snubber),
            inv_a2_bottom_port: r(1.0 / (p.area_bottom_port_mm2 * p.area_bottom_port_mm2)),
            area_bottom_notch: r(p.area_bottom_notch_mm2),
            area_bottom_min: r(p.area_bottom_min_mm2),
            snub_bottom_len: r(p.snub_bottom_len_mm),
            snub_top_len_div: R::divisor(r(p.snub_top_len_mm * p.effect_snubber)),
            snub_bottom_len_div: R::divisor(r(p.snub_bottom_len_mm)),
            inv_a2_top_snubber_open: [R::ZERO; 2],
            inv_a2_bottom_open: R::ZERO,
            inv_cap_high: r(1.0 / p.cap_high_mm3_per_mpa),
            inv_cap_low: r(1.0 / p.cap_low_mm3_per_mpa),
            pump: r(p.pump_flow_mm3_per_ms),
            relief_high: r(p.relief_high_mm3_per_ms_mpa),
            pump_over_relief_high: r(p.pump_flow_mm3_per_ms / p.relief_high_mm3_per_ms_mpa),
            relief_low: r(p.relief_low_mm3_per_ms_mpa),
        };
        piston.inv_a2_top_snubber_open = [
            piston.inv_a2_top_snubber_at(R::ONE, false),
            piston.inv_a2_top_snubber_at(R::ONE, true),
        ];
        piston.inv_a2_bottom_open = piston.inv_a2_bottom_at(R::ONE);
        Ok(piston)
    }

    /// Full stroke S: S1 (high lift) or S2 (low lift).
    pub fn stroke(&self, lift_high: bool) -> R {
        if lift_high {
            self.lift_high
        } else {
            self.lift_low
        }
    }

    /// 1/Aorit² of the equivalent top orifice (eq. (5)): the main valve and top port in
    /// series with the top snubber. Opening (`closing == false`): the snubber's check valve
    /// opens and only the main valve restricts. Closing: the notch is covered linearly over the
    /// snubbing zone `L < Ls1`, leaving the fixed orifice plus the switch orifice when the
    /// switch valve is off.
    #[inline(always)]
    pub fn inv_a2_top(&self, lift: R, closing: bool, switch_on: bool) -> R {
        self.inv_a2_main + self.inv_a2_top_snubber(lift, closing, switch_on)
    }

    /// 1/A² of the top snubber alone (0 while opening: the check valve bypasses it).
    #[inline(always)]
    pub fn inv_a2_top_snubber(&self, lift: R, closing: bool, switch_on: bool) -> R {
        if !closing {
            return R::ZERO;
        }
        if lift >= self.snub_top_len {
            return self.inv_a2_top_snubber_open[usize::from(switch_on)];
        }
        // snub_top_len > lift >= 0 here, so the division is safe.
        let uncovered = lift.div_by(self.snub_top_len_div).clamp(R::ZERO, R::ONE);
        self.inv_a2_top_snubber_at(uncovered, switch_on)
    }

    /// 1/A² of the closing top snubber with the fraction `uncovered` of its notch open.
    fn inv_a2_top_snubber_at(&self, uncovered: R, switch_on: bool) -> R {
        let fixed = if switch_on {
            self.area_top_orifice
        } else {
            self.area_top_orifice + self.area_top_switch
        };
        let area = fixed + self.area_top_notch * uncovered;
        R::ONE / (area * area)
    }

    /// 1/Aorib² of the equivalent bottom orifice (eq. (6)): bottom port in series with the
    /// bottom notch, which closes linearly over the last Ls2 before full lift.
    #[inline(always)]
    pub fn inv_a2_bottom(&self, lift: R, stroke: R) -> R {
        let to_go = stroke - lift;
        if to_go >= self.snub_bottom_len {
            return self.inv_a2_bottom_open;
        }
        self.inv_a2_bottom_at(to_go.div_by(self.snub_bottom_len_div).clamp(R::ZERO, R::ONE))
    }

    /// 1/Aorib² with the fraction `uncovered` of the bottom notch open.
    fn inv_a2_bottom_at(&self, uncovered: R) -> R {
        let area = self.area_bottom_min + self.area_bottom_notch * uncovered;
        self.inv_a2_bottom_port + R::ONE / (area * area)
    }

    /// Quadratic damping gain k such that the orifice forces of eqs. (5)-(6) on the piston are
    /// −k·|v|·v (N, v in mm/ms). This is −me·K of eq. (15) without the friction part.
    pub fn quadratic_gain(&self, cd: R, lift: R, vel: R, stroke: R, switch_on: bool) -> R {
        let closing = vel < R::ZERO;
        self.quadratic_gain_with(cd, self.inv_a2_top(lift, closing, switch_on), lift, stroke)
    }

    /// [`Self::quadratic_gain`] with 1/Cd² given: Cd is constant over a step, so a model that
    /// sub-steps divides once per step instead of once per sub-step. Inlined: as a call of
    /// its own, about 15 instructions a sub-step on the target went to the call.
    #[inline(always)]
    pub(crate) fn quadratic_gain_inv_cd2(&self, inv_cd2: R, lift: R, vel: R, stroke: R, switch_on: bool) -> R {
        let closing = vel < R::ZERO;
        // The floats' ρ/2·At³/Aorit² + ρ/2·Ab³/Aorib²; fixed point rounds and saturates once
        // (both ρ/2·A³ below 2^13, `Piston::new`).
        R::sum_of_products([
            (self.half_rho_at3, self.inv_a2_top(lift, closing, switch_on)),
            (self.half_rho_ab3, self.inv_a2_bottom(lift, stroke)),
        ]) * inv_cd2
    }

    /// Fixed point's damping gains at one temperature, ρ/2·At³/Cd² and ρ/2·Ab³/Cd², for
    /// [`Self::quadratic_gain_at`]: Cd changes with the oil temperature only, so the product
    /// by 1/Cd² is made when it changes, not once a sub-step. Refused where a gain would
    /// reach 2^13 (`Real::sum_of_products`'s contract): `inv_cd2_max` is the largest 1/Cd²
    /// the tables give.
    pub(crate) fn damping_gains(&self, inv_cd2: R) -> DampingGains<R> {
        DampingGains {
            top: self.half_rho_at3 * inv_cd2,
            bottom: self.half_rho_ab3 * inv_cd2,
        }
    }

    /// Whether [`Self::damping_gains`] stay below 2^13 for every 1/Cd² up to `inv_cd2_max`.
    pub(crate) fn check_damping_gains(&self, inv_cd2_max: f64) -> Result<(), EhvvaError> {
        if self.half_rho_at3.to_f64() * inv_cd2_max < 8192.0 && self.half_rho_ab3.to_f64() * inv_cd2_max < 8192.0 {
            Ok(())
        } else {
            Err(EhvvaError::InvalidParameter("tables.cd"))
        }
    }

    /// Fixed point's [`Self::quadratic_gain_inv_cd2`] with the gains of [`Self::damping_gains`]:
    /// one sum of two exact products, rounded and saturated once.
    #[inline(always)]
    pub(crate) fn quadratic_gain_at(&self, gains: DampingGains<R>, lift: R, vel: R, stroke: R, switch_on: bool) -> R {
        let closing = vel < R::ZERO;
        R::sum_of_products([
            (gains.top, self.inv_a2_top(lift, closing, switch_on)),
            (gains.bottom, self.inv_a2_bottom(lift, stroke)),
        ])
    }

    /// As [`Self::quadratic_gain`] with the top orifice's 1/Aorit² given (the ninth-order model
    /// meters the main valve by its spool position).
    pub fn quadratic_gain_with(&self, cd: R, inv_a2_top: R, lift: R, stroke: R) -> R {
        R::sum_of_products([
            (self.half_rho_at3, inv_a2_top),
            (self.half_rho_ab3, self.inv_a2_bottom(lift, stroke)),
        ]) / (cd * cd)
    }

    /// Pressure, spring and seat-free force on the piston (eq. (1) right side without the
    /// velocity terms): At·P̃mo − Ab·Pl − ks(L + ds).
    pub fn static_force(&self, p_top: R, p_low: R, lift: R) -> R {
        // The floats' At·P̃mo − Ab·Pl − ks(L + ds); fixed point rounds and saturates once (the
        // areas and the spring rate below 2^13, `Piston::new`).
        R::sum_of_products([
            (self.area_top, p_top),
            (-self.area_bottom, p_low),
            (-self.spring, lift + self.preload),
        ])
    }

    /// One semi-implicit velocity step: the static force explicitly, friction and the quadratic
    /// orifice damping implicitly (linearised about the current |v|), so the stiff snubber
    /// damping cannot make the step unstable whatever the orifice area.
    ///
    /// The floats only; fixed point takes [`Self::motion_step_fixed`].
    pub fn velocity_step(&self, vel: R, force: R, quad_gain: R, h: R) -> R {
        let damping = self.friction + quad_gain * vel.abs();
        let accel = h.step_times(self.accel_per_newton, force);
        (vel + accel) / (R::ONE + h.step_times(self.accel_per_newton, damping))
    }

    /// Fixed point's [`Self::velocity_step`] and lift update, unclamped: the same scheme as
    /// the increment `(a − c·v)/(1 + c)` with a = h·F/m and c = h·damping/m, formed times 2^10
    /// and added with what lies below the LSB carried. Near its terminal velocity the piston's
    /// velocity relaxes by less than an LSB a sub-step (c ≈ 2e-4 at 1.5 m/s), and rounded each
    /// sub-step it stalled up to 0.5 LSB/c off (the velocity 0.4 % low at 5.5 MPa supply, 4 MPa
    /// back pressure); the lift's increment h·v, the same each sub-step at a steady velocity,
    /// rounded the same way each time. h and h/m held times 2^10 and 2^20 ([`SubStep`]).
    fn motion_step_fixed(&self, m: &mut Moving<R>, force: R, quad_gain: R, h: SubStep<R>) -> (R, R) {
        let damping = self.friction + quad_gain * m.vel.abs();
        // h·F/m and h·damping/m times 2^10, one product each (h/m held times 2^20): a few
        // tens at most for any force and velocity of the envelope.
        let a_x1024 = force.mul_shr_in_range(h.h_per_kn_x2p20, 10);
        let c_x1024 = damping.mul_shr_in_range(h.h_per_kn_x2p20, 10);
        let num_x1024 = a_x1024 - c_x1024 * m.vel;
        let c = c_x1024.mul_pow2(-10);
        // 1/(1 + c) as 1 − c + c² − … where c < 1/16 (most of a stroke: c ≈ 2e-4 at 1.5 m/s
        // off the snubbers) and the type is coarse: the terms up to the first below a quarter
        // of Q16.16's LSB (2^-18): 1 − c for c < 2^-9, to c² for c < 2^-6, to c⁴ for c < 2^-4;
        // products in range (c < 1, each factor in [0, 1]) for a long division. Otherwise,
        // and in Q32.32, the division.
        let dv_x1024 = if !crate::real::resolves::<R>(1e-6) && c_x1024 < R::ONE.mul_pow2(6) {
            let inv = if c_x1024 < R::ONE.mul_pow2(1) {
                R::ONE - c
            } else if c_x1024 < R::ONE.mul_pow2(4) {
                R::ONE - c.mul_in_range(R::ONE - c)
            } else {
                R::ONE - c.mul_in_range(R::ONE - c.mul_in_range(R::ONE - c.mul_in_range(R::ONE - c)))
            };
            num_x1024.mul_in_range(inv)
        } else {
            num_x1024 / (R::ONE + c)
        };
        let (mut vel, mut lift) = (m.vel, m.lift);
        add_carried(&mut vel, &mut m.carry_x1024.vel, dv_x1024);
        add_carried(&mut lift, &mut m.carry_x1024.lift, h.h_x1024 * vel);
        (lift, vel)
    }

    /// End stops of eq. (1): the seat at 0 and the lift sleeve at S stop the piston at once.
    /// Returns the clamped lift and velocity and, when the piston hit the seat in this step,
    /// its velocity just before (the seating velocity).
    pub fn stops(lift: R, vel: R, stroke: R) -> (R, R, Option<R>) {
        stops(lift, vel, stroke)
    }
}

/// The orifice damping's gains at one oil temperature ([`Piston::damping_gains`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct DampingGains<R> {
    top: R,
    bottom: R,
}

/// End stops at 0 and `max` for any sliding part (piston eq. (1), spools eq. (2)): clamps the
/// position, removes the velocity into the stop, and reports the velocity of a hit on 0.
pub(crate) fn stops<R: Real>(lift: R, vel: R, stroke: R) -> (R, R, Option<R>) {
    {
        if lift <= R::ZERO {
            let impact = if vel < R::ZERO { Some(vel) } else { None };
            (R::ZERO, vel.max(R::ZERO), impact)
        } else if lift >= stroke {
            (stroke, vel.min(R::ZERO), None)
        } else {
            (lift, vel, None)
        }
    }
}

impl<R: Real> Piston<R> {
    /// dPh/dt of eq. (8): the piston draws At·v from the supply while opening; the pump
    /// delivers a constant flow; the relief valve returns the excess above the crack pressure,
    /// set so the steady state with the valve at rest is exactly the set-point.
    #[inline(always)]
    pub fn p_high_rate(&self, p_high: R, p_set: R, vel: R) -> R {
        let crack = p_set - self.pump_over_relief_high;
        let relief = self.relief_high * (p_high - crack).max(R::ZERO);
        let net_flow = self.pump - relief - self.area_top * vel.max(R::ZERO);
        net_flow * self.inv_cap_high
    }

    /// dPl/dt of eq. (7): the bottom chamber pushes Ab·v into the back-pressure line while
    /// opening; the top chamber returns (At − Ab)·|v| net while closing (volume balance of the
    /// two chambers); relief above and check-valve make-up below the set-point.
    #[inline(always)]
    pub fn p_low_rate(&self, p_low: R, p_set: R, vel: R) -> R {
        let inflow = self.area_bottom * vel.max(R::ZERO) + (self.area_top - self.area_bottom) * (-vel).max(R::ZERO);
        let net_flow = inflow - self.relief_low * (p_low - p_set);
        net_flow * self.inv_cap_low
    }

    /// One sub-step `h` of the piston and both accumulators, the part the reduced (eq. (12))
    /// and ninth-order (eq. (9)) models share once each has its top pressure and damping:
    /// velocity (semi-implicit), position and end stops, then eqs. (7)-(8) with the new
    /// velocity. A seat impact is reported only for a landing, not for the seat holding a
    /// piston already at rest on it.
    pub fn advance(
        &self,
        m: &mut Moving<R>,
        force: R,
        quad_gain: R,
        h: SubStep<R>,
        stroke: R,
        p_supply_set: R,
        p_back_set: R,
    ) {
        let (free_lift, free_vel) = if R::IS_FLOAT {
            let vel = self.velocity_step(m.vel, force, quad_gain, h.h);
            (m.lift + h.h * vel, vel)
        } else {
            self.motion_step_fixed(m, force, quad_gain, h)
        };
        if free_lift > R::ZERO && free_lift < stroke {
            // Between the stops (most sub-steps of a motion): what `stops` would return, without
            // its tuple and option (on the target a dozen stores and loads a sub-step).
            m.lift = free_lift;
            m.vel = free_vel;
        } else {
            let (lift, vel, impact) = Piston::stops(free_lift, free_vel, stroke);
            if !R::IS_FLOAT && lift != free_lift {
                // On a stop: nothing below the LSB of a motion that ended.
                m.carry_x1024.vel = R::ZERO;
                m.carry_x1024.lift = R::ZERO;
            }
            if impact.is_some() && m.lift > R::ZERO {
                m.seat_velocity = impact;
            }
            m.lift = lift;
            m.vel = vel;
        }
        self.advance_accumulators(m, h, p_supply_set, p_back_set);
    }

    /// Whether a piston at rest (`vel == 0`) on a stop stays there this sub-step: on the seat
    /// with the net `force` not lifting it, or on the sleeve with the force not pulling it
    /// back. Then [`Self::advance`] would compute a velocity into the stop (its sign is the
    /// force's: the damping only scales it), which the stop takes away, leaving lift and
    /// velocity as they are; [`Self::advance_held`] gives the same numbers without the
    /// damping and the division.
    pub fn held_at_stop(&self, m: &Moving<R>, force: R, stroke: R) -> bool {
        m.vel == R::ZERO && ((m.lift == R::ZERO && force <= R::ZERO) || (m.lift == stroke && force >= R::ZERO))
    }

    /// One sub-step of a piston [`Self::held_at_stop`]: only the accumulators move, as in
    /// [`Self::advance`] with the velocity 0.
    pub fn advance_held(&self, m: &mut Moving<R>, h: SubStep<R>, p_supply_set: R, p_back_set: R) {
        m.vel = R::ZERO;
        self.advance_accumulators(m, h, p_supply_set, p_back_set);
    }

    /// Eqs. (7)-(8) over a sub-step with the piston's new velocity. Inlined into both
    /// callers: as a call of its own it cost ~10 instructions a sub-step on the target.
    ///
    /// Fixed point: an accumulator relaxing to its set-point moves by ~1e-5 MPa a 10 µs
    /// step, below Q16.16's LSB (1.5e-5), and rounded each step it stalled: the back pressure
    /// stayed 0.01 MPa above f64's through a hold, the lift's closing 0.4 % of the stroke off
    /// (until session 18). The increment is formed times 2^10 and what the pressure cannot
    /// take yet is carried to the next sub-step.
    #[inline(always)]
    fn advance_accumulators(&self, m: &mut Moving<R>, h: SubStep<R>, p_supply_set: R, p_back_set: R) {
        if R::IS_FLOAT {
            m.p_high += h.h * self.p_high_rate(m.p_high, p_supply_set, m.vel);
            m.p_low += h.h * self.p_low_rate(m.p_low, p_back_set, m.vel);
        } else {
            // The flows of `p_high_rate` and `p_low_rate`, each term times h/C·2^10
            // (`SubStep`): one product a term, and only the velocity's direction's.
            let crack = p_supply_set - self.pump_over_relief_high;
            // Each constant below 2^10 (`SubStep::new`): every product in range.
            let relief_high = (m.p_high - crack)
                .max(R::ZERO)
                .mul_shr_in_range(h.relief_high_x2p20, 10);
            let relief_low = (m.p_low - p_back_set).mul_shr_in_range(h.relief_low_x2p20, 10);
            let (drawn_high, pushed_low) = if m.vel > R::ZERO {
                (
                    m.vel.mul_shr_in_range(h.area_top_high_x2p20, 10),
                    m.vel.mul_shr_in_range(h.area_bottom_low_x2p20, 10),
                )
            } else {
                (R::ZERO, (-m.vel).mul_shr_in_range(h.area_net_low_x2p20, 10))
            };
            add_carried(
                &mut m.p_high,
                &mut m.carry_x1024.p_high,
                h.pump_high_x1024 - relief_high - drawn_high,
            );
            add_carried(&mut m.p_low, &mut m.carry_x1024.p_low, pushed_low - relief_low);
        }
    }
}

/// `p += increment_x1024 / 2^10` with what `p` cannot take yet below its LSB kept in `carry`
/// (times 2^10) for the next call.
#[inline(always)]
pub(crate) fn add_carried<R: Real>(p: &mut R, carry: &mut R, increment_x1024: R) {
    let (whole, rest) = (*carry + increment_x1024).split_pow2(10);
    *carry = rest;
    *p += whole;
}

/// A sub-step's length h (ms) as the models multiply by it. Fixed point also holds h times
/// 2^10: the target's 10 µs step cut in two is 327.5 LSB of Q16.16, and rounded to 328 the
/// piston and accumulators ran 0.15 % fast against the model's own delay lines (the lift up to
/// 0.2 % of the stroke off f64's at 5.5 MPa supply, 4 MPa back pressure; until session 19).
///
/// Fixed point also holds the sub-step's products with the piston's and accumulators'
/// constants, times 2^20, so that each increment is one product of a state-dependent force
/// or flow: h/(1000·m) (N → mm/ms a sub-step; 0.005 ms over 0.2 kg is 2.5e-5, under 2 LSB
/// of Q16.16) and h/C (mm³/ms → MPa a sub-step, 1.4e-6), each a few tens times 2^20.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SubStep<R> {
    /// h, ms.
    pub h: R,
    /// Fixed point: h times 2^10 (5.12 at the model's 5 µs, 102.4 at the longest sub-step a
    /// caller may ask for, 0.1 ms); the floats do not use it.
    pub h_x1024: R,
    /// Fixed point: h/(1000·me) times 2^20 (the floats do not use it).
    pub h_per_kn_x2p20: R,
    /// Fixed point: the accumulators' flow terms times h/C·2^20: the pump's (times 2^10 only:
    /// a constant increment), the relief valves' gains, the piston areas' (At and Ab opening,
    /// At − Ab closing).
    pub pump_high_x1024: R,
    pub relief_high_x2p20: R,
    pub area_top_high_x2p20: R,
    pub relief_low_x2p20: R,
    pub area_bottom_low_x2p20: R,
    pub area_net_low_x2p20: R,
}

impl<R: Real> SubStep<R> {
    /// `h_ms` ([`super::reduced::MAX_SUBSTEP_MS`] or shorter; at most
    /// [`super::reduced::MAX_STEP_MS`] for a coarse approach) in the model's number type, with
    /// its products with the mass and capacities of `p`.
    ///
    /// Fixed point takes the products held times 2^20 by a force or pressure with
    /// [`Real::mul_shr_in_range`], which needs each below 2^10 (h/m, h/C and the flow gains
    /// a fraction of an LSB a sub-step, as they are for any valve the model's sub-step can
    /// resolve: 29 for h/(1000 m) at 5 µs and 0.183 kg); a parameter that breaks it is refused
    /// by name.
    pub fn new(h_ms: f64, p: &EhvvaParams) -> Result<Self, EhvvaError> {
        let x2p20 = 1024.0 * 1024.0 * h_ms;
        let (high, low) = (p.cap_high_mm3_per_mpa, p.cap_low_mm3_per_mpa);
        if !R::IS_FLOAT {
            for (v, name) in [
                (x2p20 / (1000.0 * p.mass_kg), "mass_kg"),
                (
                    x2p20 * p.relief_high_mm3_per_ms_mpa / high,
                    "relief_high_mm3_per_ms_mpa",
                ),
                (x2p20 * p.area_top_mm2 / high, "cap_high_mm3_per_mpa"),
                (x2p20 * p.relief_low_mm3_per_ms_mpa / low, "relief_low_mm3_per_ms_mpa"),
                // Ab opening, At − Ab closing: both below the larger area.
                (
                    x2p20 * p.area_top_mm2.max(p.area_bottom_mm2) / low,
                    "cap_low_mm3_per_mpa",
                ),
            ] {
                if !(v < 1024.0) {
                    return Err(EhvvaError::InvalidParameter(name));
                }
            }
        }
        Ok(Self {
            h: R::from_f64(h_ms),
            h_x1024: R::from_f64(h_ms * 1024.0),
            h_per_kn_x2p20: R::from_f64(x2p20 / (1000.0 * p.mass_kg)),
            pump_high_x1024: R::from_f64(x2p20 / 1024.0 * p.pump_flow_mm3_per_ms / high),
            relief_high_x2p20: R::from_f64(x2p20 * p.relief_high_mm3_per_ms_mpa / high),
            area_top_high_x2p20: R::from_f64(x2p20 * p.area_top_mm2 / high),
            relief_low_x2p20: R::from_f64(x2p20 * p.relief_low_mm3_per_ms_mpa / low),
            area_bottom_low_x2p20: R::from_f64(x2p20 * p.area_bottom_mm2 / low),
            area_net_low_x2p20: R::from_f64(x2p20 * (p.area_top_mm2 - p.area_bottom_mm2) / low),
        })
    }
}

/// The moving state the models share: lift (mm), velocity (mm/ms = m/s), accumulator
/// pressures (MPa), and the velocity of the last seat landing (cleared on read).
#[derive(Clone, Copy, Debug)]
pub struct Moving<R> {
    pub lift: R,
    pub vel: R,
    pub p_high: R,
    pub p_low: R,
    pub seat_velocity: Option<R>,
    /// Fixed point: what the states gained below their LSB ([`Piston::advance`]); 0 for the
    /// floats.
    pub carry_x1024: SubLsb<R>,
}

impl<R: Real> Moving<R> {
    /// Valve seated and still, the accumulators at the operating point's pressures.
    pub fn at_rest(inputs: &EhvvaInputs<R>) -> Self {
        Self {
            lift: R::ZERO,
            vel: R::ZERO,
            p_high: inputs.p_supply_mpa,
            p_low: inputs.p_back_mpa,
            seat_velocity: None,
            carry_x1024: SubLsb::ZERO,
        }
    }
}

/// What each integrated state of [`Moving`] gained below its LSB, times 2^10 (fixed point's
/// increments too small for the state's type, added later: `add_carried`).
#[derive(Clone, Copy, Debug)]
pub struct SubLsb<R> {
    pub p_high: R,
    pub p_low: R,
    pub vel: R,
    pub lift: R,
}

impl<R: Real> SubLsb<R> {
    /// Nothing carried.
    pub const ZERO: Self = Self {
        p_high: R::ZERO,
        p_low: R::ZERO,
        vel: R::ZERO,
        lift: R::ZERO,
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Q16;
    use proptest::prelude::*;

    /// One sub-step both ways from a piston at rest on a stop; `None` where the fast path does
    /// not apply. Compares bits (a zero's sign aside: ±0 are the same velocity).
    fn both_ways<R: Real>(lift_on_seat: bool, force: f64, quad_gain: f64, h: f64, ph: f64, pl: f64) -> Option<bool> {
        let p = EhvvaParams::paper_default();
        let piston = Piston::<R>::new(&p).unwrap();
        let stroke = piston.stroke(true);
        let m0 = Moving {
            lift: if lift_on_seat { R::ZERO } else { stroke },
            vel: R::ZERO,
            p_high: R::from_f64(ph),
            p_low: R::from_f64(pl),
            seat_velocity: None,
            carry_x1024: SubLsb::ZERO,
        };
        let (force, set_high, set_low) = (R::from_f64(force), R::from_f64(6.0), R::from_f64(2.0));
        if !piston.held_at_stop(&m0, force, stroke) {
            return None;
        }
        let h = match SubStep::new(h, &p) {
            Ok(h) => h,
            // Fixed point refuses a sub-step too long for its in-range products.
            Err(_) if !R::IS_FLOAT => return None,
            Err(e) => panic!("{e:?}"),
        };
        let (mut full, mut held) = (m0, m0);
        piston.advance(&mut full, force, R::from_f64(quad_gain), h, stroke, set_high, set_low);
        piston.advance_held(&mut held, h, set_high, set_low);
        Some(
            full.lift == held.lift
                && full.vel == held.vel
                && full.p_high == held.p_high
                && full.p_low == held.p_low
                && full.seat_velocity.is_none()
                && held.seat_velocity.is_none(),
        )
    }

    #[test]
    fn fixed_point_refuses_constants_its_in_range_products_cannot_hold() {
        // The model's 5 µs sub-step holds the paper's valve; a 0.1 ms one (a coarse approach's,
        // for the floats) makes h/C times the supply accumulator's relief gain 6x too large
        // for Q16.16's in-range product, and is refused by the parameter's name.
        let p = EhvvaParams::paper_default();
        assert!(SubStep::<Q16>::new(super::super::reduced::MAX_SUBSTEP_MS, &p).is_ok());
        assert!(SubStep::<f64>::new(super::super::reduced::MAX_STEP_MS, &p).is_ok());
        assert_eq!(
            SubStep::<Q16>::new(super::super::reduced::MAX_STEP_MS, &p).err(),
            Some(EhvvaError::InvalidParameter("relief_high_mm3_per_ms_mpa"))
        );
        // A piston area whose exact products with pressures the force's sum cannot hold.
        let big = EhvvaParams {
            area_top_mm2: 9000.0,
            ..p
        };
        assert_eq!(
            Piston::<Q16>::new(&big).err(),
            Some(EhvvaError::InvalidParameter("area_top_mm2"))
        );
        assert!(Piston::<f32>::new(&big).is_ok());
    }

    proptest! {
        /// The held sub-step is the full sub-step's result for a piston on a stop that the
        /// force presses it against, whatever the damping, step and accumulator pressures, in
        /// f64, f32 and Q16.16; and a force away from the stop is never taken as held.
        #[test]
        fn a_held_piston_steps_as_the_full_sub_step_gives(
            on_seat: bool,
            force_n in -3000.0f64..3000.0,
            tiny in proptest::bool::weighted(0.2),
            quad_gain in 0.0f64..1e4,
            h_ms in 1e-4f64..0.01,
            ph in 3.0f64..9.0,
            pl in 0.5f64..5.0,
        ) {
            // Forces near 0 too, where the velocity into the stop rounds to nothing.
            let force = if tiny { force_n * 1e-12 } else { force_n };
            let into_stop = if on_seat { force <= 0.0 } else { force >= 0.0 };
            for same in [
                both_ways::<f64>(on_seat, force, quad_gain, h_ms, ph, pl),
                both_ways::<f32>(on_seat, force, quad_gain, h_ms, ph, pl),
            ] {
                prop_assert_eq!(same.is_some(), into_stop);
                prop_assert!(same.unwrap_or(true));
            }
            prop_assert!(both_ways::<Q16>(on_seat, force, quad_gain.min(30.0), h_ms, ph, pl).unwrap_or(true));
        }
    }
}
