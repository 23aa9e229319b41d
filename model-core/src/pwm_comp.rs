//! Supply-voltage compensator for PWM-driven solenoid valves (Thomasson 2013, eq. (15)).
//!
//! A solenoid valve's plunger force follows the mean coil voltage, duty × U_syst, so the valve
//! effectively sees u·U_syst/U_ref (eq. (1)). Scaling the commanded duty by U_ref/U_syst cancels
//! that: u_corr = U_ref/U_syst · u. The result is clamped to the duty range the driver accepts;
//! below `u_min_v` the supply is treated as implausible and the compensation holds at its
//! `u_min_v` value instead of asking for ever larger duty (a sagging battery during cranking
//! must not drive the valves to 100 %).

use crate::real::Real;

/// Why compensator settings were rejected.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PwmCompError {
    /// A parameter is not finite or out of its range; the name says which.
    BadParameter(&'static str),
}

#[derive(Clone, Copy, Debug)]
pub struct PwmCompensator<R: Real> {
    u_ref_v: R,
    u_min_v: R,
    duty_min_pct: R,
    duty_max_pct: R,
}

/// The compensated duty and whether a limit was active (for the caller's diagnostics).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compensated<R> {
    pub duty_pct: R,
    /// The duty was clamped to the driver's range.
    pub duty_limited: bool,
    /// The supply voltage was below `u_min_v`; the compensation used `u_min_v`.
    pub supply_low: bool,
}

impl<R: Real> PwmCompensator<R> {
    /// `u_ref_v`: the voltage at which the valve was calibrated; `u_min_v`: the lowest supply
    /// voltage that is compensated; duties in percent.
    pub fn new(u_ref_v: f64, u_min_v: f64, duty_min_pct: f64, duty_max_pct: f64) -> Result<Self, PwmCompError> {
        let ok = |x: f64| x.is_finite();
        if !(ok(u_ref_v) && u_ref_v > 0.0) {
            return Err(PwmCompError::BadParameter("u_ref_v"));
        }
        if !(ok(u_min_v) && u_min_v > 0.0) {
            return Err(PwmCompError::BadParameter("u_min_v"));
        }
        if !(ok(duty_min_pct) && (0.0..=100.0).contains(&duty_min_pct)) {
            return Err(PwmCompError::BadParameter("duty_min_pct"));
        }
        if !(ok(duty_max_pct) && duty_max_pct >= duty_min_pct && duty_max_pct <= 100.0) {
            return Err(PwmCompError::BadParameter("duty_max_pct"));
        }
        Ok(Self {
            u_ref_v: R::from_f64(u_ref_v),
            u_min_v: R::from_f64(u_min_v),
            duty_min_pct: R::from_f64(duty_min_pct),
            duty_max_pct: R::from_f64(duty_max_pct),
        })
    }

    /// u_corr = U_ref/U_syst · u, clamped (eq. (15)).
    pub fn apply(&self, duty_pct: R, u_batt_v: R) -> Compensated<R> {
        // `!(u >= min)` also catches NaN from a float caller.
        let supply_low = !(u_batt_v >= self.u_min_v);
        let u = if supply_low { self.u_min_v } else { u_batt_v };
        let raw = duty_pct * self.u_ref_v / u;
        let clamped = raw.clamp(self.duty_min_pct, self.duty_max_pct);
        Compensated {
            duty_pct: clamped,
            duty_limited: clamped != raw,
            supply_low,
        }
    }

    pub fn u_ref_v(&self) -> R {
        self.u_ref_v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Q32;
    use proptest::prelude::*;

    fn comp<R: Real>() -> PwmCompensator<R> {
        PwmCompensator::new(13.5, 6.0, 0.0, 100.0).unwrap()
    }

    #[test]
    fn rejects_bad_parameters_by_name() {
        assert_eq!(
            PwmCompensator::<f32>::new(0.0, 6.0, 0.0, 100.0).unwrap_err(),
            PwmCompError::BadParameter("u_ref_v")
        );
        assert_eq!(
            PwmCompensator::<f32>::new(13.5, f64::NAN, 0.0, 100.0).unwrap_err(),
            PwmCompError::BadParameter("u_min_v")
        );
        assert_eq!(
            PwmCompensator::<f32>::new(13.5, 6.0, 50.0, 40.0).unwrap_err(),
            PwmCompError::BadParameter("duty_max_pct")
        );
    }

    #[test]
    fn at_reference_voltage_duty_passes_unchanged() {
        let c = comp::<f64>().apply(42.0, 13.5);
        assert_eq!(c.duty_pct, 42.0);
        assert!(!c.duty_limited && !c.supply_low);
    }

    #[test]
    fn low_supply_and_saturation_are_flagged() {
        let c = comp::<f32>().apply(50.0, 3.0);
        assert!(c.supply_low);
        assert!((c.duty_pct - 50.0 * 13.5 / 6.0).abs() < 1e-3 || c.duty_limited);
        let c = comp::<f32>().apply(90.0, 9.0);
        assert!(c.duty_limited);
        assert_eq!(c.duty_pct, 100.0);
        let c = comp::<f32>().apply(50.0, f32::NAN);
        assert!(c.supply_low && c.duty_pct.is_finite());
    }

    proptest! {
        /// The valve sees duty × U/U_ref; after compensation that product equals the request
        /// wherever no limit is active, in f32 and in fixed point.
        #[test]
        fn compensation_restores_the_effective_duty(duty in 0.0f64..100.0, u in 6.0f64..18.0) {
            let f = comp::<f32>().apply(duty as f32, u as f32);
            if !f.duty_limited {
                let seen = f.duty_pct as f64 * u / 13.5;
                prop_assert!((seen - duty).abs() < 1e-3 * duty.max(1.0));
            }
            let q = comp::<Q32>().apply(Q32::from_f64(duty), Q32::from_f64(u));
            prop_assert!((q.duty_pct.to_f64() - f.duty_pct as f64).abs() < 1e-3);
            prop_assert!(q.duty_pct.to_f64() >= 0.0 && q.duty_pct.to_f64() <= 100.0);
        }
    }
}
