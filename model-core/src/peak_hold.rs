//! Peak-and-hold drive of the EHVVA pilot solenoid (Li 2018, Sec. 5.1: "a peak and hold drive
//! circuit, similar to the direct fuel injector drive circuit"; the coil is the RL circuit of
//! eq. (3), U − I R − Li dI/dt = 0).
//!
//! Each valve event: full battery voltage until the current reaches `i_peak_a` (fast pull-in),
//! then PWM at the duty that holds `i_hold_a` (low dissipation). Both are recomputed at every
//! event from the battery voltage measured then:
//! - peak time from the RL step response: t_peak = −(L/R) · ln(1 − I_peak·R/U);
//! - hold duty from the mean coil voltage: d = I_hold·R/U.
//!
//! When the battery is too low for the peak current, the peak phase is cut at `t_peak_max_us`
//! and a fault is reported: the valve may open late, but the coil is never left on full voltage.

use crate::real::Real;

/// Coil and drive calibration. Units in the names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolenoidParams {
    /// Coil resistance R (eq. (3)).
    pub r_ohm: f64,
    /// Coil inductance Li (eq. (3)), in millihenry.
    pub l_mh: f64,
    /// Pull-in (peak) current.
    pub i_peak_a: f64,
    /// Hold current, well below the peak.
    pub i_hold_a: f64,
    /// Longest allowed full-voltage phase, whatever the battery does.
    pub t_peak_max_us: f64,
}

impl SolenoidParams {
    /// A pilot coil like a port-injector's: 2 Ω, 2 mH (τ = 1 ms), 3 A peak, 1 A hold; the peak
    /// is reached in 0.56 ms at 14 V and 1.39 ms at 8 V, and not at all below 6 V.
    pub const fn pilot_default() -> Self {
        Self {
            r_ohm: 2.0,
            l_mh: 2.0,
            i_peak_a: 3.0,
            i_hold_a: 1.0,
            t_peak_max_us: 2500.0,
        }
    }

    /// Checks the calibration; the error names the offending parameter.
    pub fn validate(&self) -> Result<(), &'static str> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !pos(self.r_ohm) {
            return Err("r_ohm");
        }
        if !pos(self.l_mh) {
            return Err("l_mh");
        }
        if !pos(self.i_peak_a) {
            return Err("i_peak_a");
        }
        if !(pos(self.i_hold_a) && self.i_hold_a < self.i_peak_a) {
            return Err("i_hold_a");
        }
        if !pos(self.t_peak_max_us) {
            return Err("t_peak_max_us");
        }
        Ok(())
    }
}

/// Why an event's plan is degraded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeakHoldFault {
    /// U/R is below (or too close to) the peak current: peak phase cut at `t_peak_max_us`.
    PeakUnreachable,
    /// Even 100 % duty cannot hold `i_hold_a`: hold at 100 %.
    HoldUnreachable,
}

/// Timing for one valve event.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeakHoldPlan<R> {
    pub t_peak_us: R,
    /// Hold PWM duty, 0..1.
    pub hold_duty: R,
    pub fault: Option<PeakHoldFault>,
}

/// The plan for an event at battery voltage `u_batt_v`.
pub fn plan<R: Real>(p: &SolenoidParams, u_batt_v: R) -> PeakHoldPlan<R> {
    let r = R::from_f64(p.r_ohm);
    let tau_us = R::from_f64(p.l_mh / p.r_ohm * 1000.0);
    let t_max = R::from_f64(p.t_peak_max_us);
    let u = u_batt_v.max(R::ZERO);
    let mut fault = None;
    // Fraction of the final current U/R that the peak needs.
    let need = R::from_f64(p.i_peak_a) * r / u;
    let t_peak_us = if !(need < R::ONE) {
        fault = Some(PeakHoldFault::PeakUnreachable);
        t_max
    } else {
        let t = -tau_us * (R::ONE - need).ln();
        if t > t_max {
            fault = Some(PeakHoldFault::PeakUnreachable);
            t_max
        } else {
            t
        }
    };
    let duty = R::from_f64(p.i_hold_a) * r / u;
    let hold_duty = if !(duty <= R::ONE) {
        fault = fault.or(Some(PeakHoldFault::HoldUnreachable));
        R::ONE
    } else {
        duty
    };
    PeakHoldPlan {
        t_peak_us,
        hold_duty,
        fault,
    }
}

/// Where the driver is in the event.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PilotPhase {
    Off,
    /// Full voltage; `elapsed_us` since the event began.
    Peak {
        elapsed_us: f32,
    },
    Hold,
}

/// The peak-and-hold sequence as a state machine: the firmware calls `set` on command edges
/// and `tick` at its timer rate, and applies the returned duty (1 = full voltage, 0 = off).
#[derive(Clone, Debug)]
pub struct PeakHoldDriver<R: Real> {
    params: SolenoidParams,
    phase: PilotPhase,
    plan: PeakHoldPlan<R>,
}

impl<R: Real> PeakHoldDriver<R> {
    pub fn new(params: SolenoidParams) -> Result<Self, &'static str> {
        params.validate()?;
        Ok(Self {
            params,
            phase: PilotPhase::Off,
            plan: PeakHoldPlan {
                t_peak_us: R::ZERO,
                hold_duty: R::ZERO,
                fault: None,
            },
        })
    }

    /// Command edge: on starts a new event planned at the present battery voltage; off ends it.
    /// Returns the plan of a new event (`None` when nothing started).
    pub fn set(&mut self, on: bool, u_batt_v: R) -> Option<PeakHoldPlan<R>> {
        match (on, self.phase) {
            (true, PilotPhase::Off) => {
                self.plan = plan(&self.params, u_batt_v);
                self.phase = PilotPhase::Peak { elapsed_us: 0.0 };
                Some(self.plan)
            }
            (false, _) => {
                self.phase = PilotPhase::Off;
                None
            }
            _ => None,
        }
    }

    /// Advances by `dt_us`; `i_meas_a` ends the peak early when a current measurement shows the
    /// peak was reached (drivers with a shunt). Returns the duty to apply now.
    pub fn tick(&mut self, dt_us: R, i_meas_a: Option<R>) -> R {
        if let PilotPhase::Peak { elapsed_us } = self.phase {
            let elapsed = R::from_f64(elapsed_us as f64) + dt_us;
            let reached = i_meas_a.is_some_and(|i| i >= R::from_f64(self.params.i_peak_a));
            self.phase = if reached || elapsed >= self.plan.t_peak_us {
                PilotPhase::Hold
            } else {
                PilotPhase::Peak {
                    elapsed_us: elapsed.to_f32(),
                }
            };
        }
        self.duty()
    }

    /// The duty for the present phase.
    pub fn duty(&self) -> R {
        match self.phase {
            PilotPhase::Off => R::ZERO,
            PilotPhase::Peak { .. } => R::ONE,
            PilotPhase::Hold => self.plan.hold_duty,
        }
    }

    pub fn phase(&self) -> PilotPhase {
        self.phase
    }

    pub fn last_plan(&self) -> PeakHoldPlan<R> {
        self.plan
    }
}

/// The coil itself, integrated exactly over a step with constant applied voltage:
/// i(t+dt) = U/R + (i − U/R) e^(−dt R/L). Used by simulations and tests.
#[derive(Clone, Copy, Debug)]
pub struct RlCoil<R: Real> {
    r_ohm: R,
    tau_us: R,
    pub current_a: R,
}

impl<R: Real> RlCoil<R> {
    pub fn new(p: &SolenoidParams) -> Self {
        Self {
            r_ohm: R::from_f64(p.r_ohm),
            tau_us: R::from_f64(p.l_mh / p.r_ohm * 1000.0),
            current_a: R::ZERO,
        }
    }
    /// Applies `u_v` for `dt_us` (a freewheel diode keeps the current from going negative).
    pub fn step(&mut self, u_v: R, dt_us: R) -> R {
        let i_inf = u_v / self.r_ohm;
        let decay = (-(dt_us / self.tau_us)).exp();
        self.current_a = (i_inf + (self.current_a - i_inf) * decay).max(R::ZERO);
        self.current_a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Q32;

    /// Runs one event on the RL coil with a 20 kHz hold PWM; returns (current at the end of the
    /// peak, mean current over the last 2 ms of hold, plan).
    fn run_event(u_batt: f64) -> (f64, f64, PeakHoldPlan<f64>) {
        let p = SolenoidParams::pilot_default();
        let mut drv = PeakHoldDriver::<f64>::new(p).unwrap();
        let mut coil = RlCoil::<f64>::new(&p);
        let plan = drv.set(true, u_batt).unwrap();
        let dt_us = 0.1;
        let pwm_period_us = 50.0;
        let (mut t, mut i_peak_end, mut hold_sum, mut hold_n) = (0.0, 0.0, 0.0, 0);
        let mut was_peak = true;
        while t < 8000.0 {
            let duty = drv.tick(dt_us, None);
            let in_peak = matches!(drv.phase(), PilotPhase::Peak { .. });
            if was_peak && !in_peak {
                i_peak_end = coil.current_a;
            }
            was_peak = in_peak;
            let on = in_peak || (t % pwm_period_us) < duty * pwm_period_us;
            coil.step(if on { u_batt } else { 0.0 }, dt_us);
            if t > 6000.0 {
                hold_sum += coil.current_a;
                hold_n += 1;
            }
            t += dt_us;
        }
        (i_peak_end, hold_sum / hold_n as f64, plan)
    }

    #[test]
    fn peak_current_and_hold_current_are_met_across_battery_voltages() {
        for u in [8.0, 10.0, 12.0, 14.0, 16.0] {
            let (i_peak, i_hold, plan) = run_event(u);
            assert!(plan.fault.is_none(), "{u} V: {:?}", plan.fault);
            assert!((i_peak - 3.0).abs() < 0.03, "{u} V: peak ended at {i_peak} A");
            assert!((i_hold - 1.0).abs() < 0.03, "{u} V: hold current {i_hold} A");
        }
    }

    #[test]
    fn lower_battery_means_longer_peak_and_higher_hold_duty() {
        let p = SolenoidParams::pilot_default();
        let at = |u: f64| plan::<f64>(&p, u);
        // τ = 1 ms: −ln(1 − 6/14) = 0.560 ms at 14 V, −ln(1 − 6/8) = 1.386 ms at 8 V.
        assert!((at(14.0).t_peak_us - 559.6).abs() < 1.0);
        assert!((at(8.0).t_peak_us - 1386.3).abs() < 1.0);
        assert!((at(14.0).hold_duty - 2.0 / 14.0).abs() < 1e-12);
        assert!(at(8.0).hold_duty > at(14.0).hold_duty);
    }

    #[test]
    fn unreachable_peak_is_cut_at_the_limit_and_flagged() {
        let p = SolenoidParams::pilot_default();
        for u in [0.0, 4.0, 6.0, 6.1] {
            let pl = plan::<f64>(&p, u);
            assert_eq!(pl.fault, Some(PeakHoldFault::PeakUnreachable), "{u} V");
            assert!(pl.t_peak_us <= p.t_peak_max_us);
        }
        // Below 2 V not even the hold current: full duty, still flagged as the peak fault.
        assert_eq!(plan::<f64>(&p, 1.5).hold_duty, 1.0);
    }

    #[test]
    fn current_sense_ends_the_peak_early_and_off_stops_everything() {
        let mut drv = PeakHoldDriver::<f32>::new(SolenoidParams::pilot_default()).unwrap();
        drv.set(true, 14.0);
        assert_eq!(drv.tick(10.0, Some(1.0)), 1.0);
        assert!((drv.tick(10.0, Some(3.1)) - 2.0 / 14.0).abs() < 1e-6);
        assert_eq!(drv.phase(), PilotPhase::Hold);
        // A second "on" while on does not restart the peak.
        assert!(drv.set(true, 8.0).is_none());
        drv.set(false, 14.0);
        assert_eq!(drv.tick(10.0, None), 0.0);
    }

    #[test]
    fn invalid_calibration_is_named() {
        let mut p = SolenoidParams::pilot_default();
        p.i_hold_a = 4.0;
        assert_eq!(PeakHoldDriver::<f32>::new(p).unwrap_err(), "i_hold_a");
        p = SolenoidParams::pilot_default();
        p.l_mh = f64::NAN;
        assert_eq!(p.validate(), Err("l_mh"));
    }

    #[test]
    fn fixed_point_and_f32_plans_match_f64() {
        let p = SolenoidParams::pilot_default();
        let mut worst_f32: f64 = 0.0;
        let mut worst_q: f64 = 0.0;
        for k in 0..=100 {
            let u = 6.5 + k as f64 * 0.1;
            let r = plan::<f64>(&p, u);
            let f = plan::<f32>(&p, u as f32);
            let q = plan::<Q32>(&p, Q32::from_f64(u));
            worst_f32 = worst_f32.max((f.t_peak_us as f64 - r.t_peak_us).abs());
            worst_q = worst_q.max((q.t_peak_us.to_f64() - r.t_peak_us).abs());
        }
        // Measured: f32 within 0.001 µs, Q32.32 within 1e-5 µs of f64 over 6.5..16.5 V.
        assert!(worst_f32 < 0.01, "f32 peak time deviates by {worst_f32} µs");
        assert!(worst_q < 1e-3, "Q32 peak time deviates by {worst_q} µs");
    }
}
