//! The valve's and the actuator's static relations, eqs. (2)/(5) and (8)/(9), converted once
//! to the number type, and their inverses for feedforward control ([`VacuumStaticModel`]).

use super::{saturate, PositionMap, StaticPressureMap, VacuumParamError, VacuumParams, THETA_MAX_RAD};
use crate::real::Real;

/// The actuator's static relations and their inverses, for feedforward control (Sec. 5.2,
/// 5.4: "given a desired value of wastegate position, a corresponding control signal can be
/// calculated using the inverse of the actuator model"). Duties here are corrected duties
/// u_corr (at U_ref); eq. (15) turns them into commands.
#[derive(Clone, Copy, Debug)]
pub struct VacuumStaticModel<R: Real> {
    maps: Maps<R>,
    p_amb_ref_kpa: R,
}

impl<R: Real> VacuumStaticModel<R> {
    /// Needs a valve map that falls with duty (k1, k2 < 0), so that it can be inverted.
    pub fn new(p: &VacuumParams) -> Result<Self, VacuumParamError> {
        p.validate()?;
        let falling = match p.static_map {
            StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct,
                k2_kpa_per_pct,
                ..
            } => k1_kpa_per_pct < 0.0 && k2_kpa_per_pct < 0.0,
            StaticPressureMap::Cubic {
                k1_kpa_per_pct,
                k2_kpa_per_pct3,
                ..
            } => k1_kpa_per_pct < 0.0 && k2_kpa_per_pct3 < 0.0,
        };
        if !falling {
            return Err(VacuumParamError::BadParameter("static_map"));
        }
        Ok(Self {
            maps: Maps::new(p),
            p_amb_ref_kpa: R::from_f64(p.p_amb_ref_kpa),
        })
    }

    /// Eq. (2)/(5) saturated: the static pressure at corrected duty `u_corr_pct`.
    pub fn pressure_for_duty_kpa(&self, u_corr_pct: R, p_amb_kpa: R, p_tank_kpa: R) -> R {
        saturate(
            self.maps.unsaturated_pressure(u_corr_pct, p_amb_kpa),
            p_tank_kpa,
            p_amb_kpa,
        )
    }

    /// Inverse of eq. (2)/(5): the corrected duty whose static pressure is `p_kpa`, not limited
    /// to 0..100 %. For a falling map, min(l1, l2) = p at u = min(u1, u2), u_i solving
    /// l_i(u) = p. At or above ambient this is the largest duty that still vents (u0 for the
    /// cubic map).
    pub fn duty_for_pressure_pct(&self, p_kpa: R, p_amb_kpa: R) -> R {
        match self.maps.static_map {
            StaticMapR::PiecewiseLinear { k1, p01, k2, p02 } => ((p_kpa - p01) / k1).min((p_kpa - p02) / k2),
            StaticMapR::Cubic { k1, p01, k2, u0, .. } => {
                let drop = ((p_kpa - p_amb_kpa) / k2).max(R::ZERO);
                let cube_root = if drop > R::ZERO {
                    (drop.ln() / R::from_f64(3.0)).exp()
                } else {
                    R::ZERO
                };
                ((p_kpa - p01) / k1).min(u0 + cube_root)
            }
        }
    }

    /// Frictionless static position for a chamber pressure, eqs. (7)-(9), on the stroke.
    pub fn position_for_pressure_pct(&self, p_act_kpa: R, p_amb_kpa: R) -> R {
        let p_map = self.p_amb_ref_kpa - (p_amb_kpa - p_act_kpa);
        self.maps.position(p_map).clamp(R::ZERO, R::from_f64(100.0))
    }

    /// Inverse of eq. (8)/(9): the chamber pressure that holds position `x_pct` with no
    /// friction, at ambient `p_amb_kpa`.
    pub fn pressure_for_position_kpa(&self, x_pct: R, p_amb_kpa: R) -> R {
        let x = x_pct.clamp(R::ZERO, R::from_f64(100.0));
        self.maps.pressure_at(x) + (p_amb_kpa - self.p_amb_ref_kpa)
    }

    /// |dp/dx| of eq. (8)/(9) at position `x_pct` (kPa of chamber pressure per % of
    /// position): how much pressure one percent of stroke takes there. A position controller
    /// that acts in pressure scales its gains with it, so its loop gain does not depend on how
    /// steep the actuator's map is at the set-point.
    pub fn pressure_per_position_kpa_per_pct(&self, x_pct: R) -> R {
        let x = x_pct.clamp(R::ZERO, R::from_f64(100.0));
        self.maps.pressure_slope_at(x)
    }
}

/// The static relations of one valve + actuator, converted once to `R`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Maps<R: Real> {
    static_map: StaticMapR<R>,
    position_map: PositionMapR<R>,
}

#[derive(Clone, Copy, Debug)]
enum StaticMapR<R: Real> {
    PiecewiseLinear {
        k1: R,
        p01: R,
        k2: R,
        p02: R,
    },
    /// `k2_x1024`: k2 times 2^10 for fixed point, where k2 itself (−3.2e-4 kPa/%³ for the
    /// HPC) holds 21 LSB of Q16.16, 0.14 % off, 0.06 kPa of a 40 kPa cubic drop.
    Cubic {
        k1: R,
        p01: R,
        k2: R,
        u0: R,
        k2_x1024: R,
    },
}

#[derive(Clone, Copy, Debug)]
enum PositionMapR<R: Real> {
    /// `k_div` is `k` as a divisor (the inverse map divides by it).
    Linear { k: R, x0: R, k_div: R::Divisor },
    /// `a2_div`, `a4_div`: `a2`, `a4` as divisors.
    Arctan {
        a1: R,
        a2: R,
        a3: R,
        a4: R,
        a2_div: R::Divisor,
        a4_div: R::Divisor,
    },
}

impl<R: Real> Maps<R> {
    pub(super) fn new(p: &VacuumParams) -> Self {
        let f = R::from_f64;
        let static_map = match p.static_map {
            StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct,
                p02_kpa,
            } => StaticMapR::PiecewiseLinear {
                k1: f(k1_kpa_per_pct),
                p01: f(p01_kpa),
                k2: f(k2_kpa_per_pct),
                p02: f(p02_kpa),
            },
            StaticPressureMap::Cubic {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct3,
                u0_pct,
            } => StaticMapR::Cubic {
                k1: f(k1_kpa_per_pct),
                p01: f(p01_kpa),
                k2: f(k2_kpa_per_pct3),
                u0: f(u0_pct),
                k2_x1024: f(k2_kpa_per_pct3 * 1024.0),
            },
        };
        let position_map = match p.position_map {
            PositionMap::Linear { k_pct_per_kpa, x0_pct } => PositionMapR::Linear {
                k: f(k_pct_per_kpa),
                x0: f(x0_pct),
                k_div: R::divisor(f(k_pct_per_kpa)),
            },
            PositionMap::Arctan {
                a1_pct,
                a2_pct_per_rad,
                a3_kpa,
                a4_kpa,
            } => PositionMapR::Arctan {
                a1: f(a1_pct),
                a2: f(a2_pct_per_rad),
                a3: f(a3_kpa),
                a4: f(a4_kpa),
                a2_div: R::divisor(f(a2_pct_per_rad)),
                a4_div: R::divisor(f(a4_kpa)),
            },
        };
        Self {
            static_map,
            position_map,
        }
    }

    /// Eq. (2)/(5) before saturation, at effective duty `u`.
    pub(super) fn unsaturated_pressure(&self, u: R, p_amb: R) -> R {
        match self.static_map {
            StaticMapR::PiecewiseLinear { k1, p01, k2, p02 } => (k1 * u + p01).min(k2 * u + p02),
            StaticMapR::Cubic {
                k1,
                p01,
                k2,
                u0,
                k2_x1024,
            } => {
                // Effective duty above 100 % only extrapolates; capped so the cube stays small.
                let d = (u - u0).clamp(R::ZERO, R::from_f64(200.0));
                let cubic = if R::IS_FLOAT {
                    k2 * d * d * d
                } else {
                    // k2·2^10·d² stays below 2^15 for |k2| < 8e-4, d <= 200; then 2^-10, · d.
                    (k2_x1024 * d * d).mul_pow2(-10) * d
                };
                (k1 * u + p01).min(p_amb + cubic)
            }
        }
    }

    /// Static position for the map pressure `p` (eq. (8)/(9)), not yet limited to the stroke.
    pub(super) fn position(&self, p: R) -> R {
        match self.position_map {
            PositionMapR::Linear { k, x0, .. } => k * p + x0,
            PositionMapR::Arctan { a1, a2, a3, a4_div, .. } => a1 + a2 * (a3 - p).div_by(a4_div).atan(),
        }
    }

    /// |d pressure_at / dx|: 1/|k| for eq. (8); (a4/a2)(1 + tan²θ) for eq. (9).
    pub(super) fn pressure_slope_at(&self, x: R) -> R {
        match self.position_map {
            PositionMapR::Linear { k_div, .. } => R::ONE.div_by(k_div).abs(),
            PositionMapR::Arctan { a1, a2_div, a4, .. } => {
                let lim = R::from_f64(THETA_MAX_RAD);
                let t = (x - a1).div_by(a2_div).clamp(-lim, lim).tan();
                (a4 + a4 * t * t).div_by(a2_div)
            }
        }
    }

    /// Inverse of `position`: the map pressure that holds the membrane at `x` with no friction.
    pub(super) fn pressure_at(&self, x: R) -> R {
        match self.position_map {
            PositionMapR::Linear { x0, k_div, .. } => (x - x0).div_by(k_div),
            PositionMapR::Arctan { a1, a3, a4, a2_div, .. } => {
                let lim = R::from_f64(THETA_MAX_RAD);
                let theta = (x - a1).div_by(a2_div).clamp(-lim, lim);
                a3 - a4 * theta.tan()
            }
        }
    }
}
