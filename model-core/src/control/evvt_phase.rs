//! Closed-loop cam phase controller for the electric cam phaser (Yang et al. 2015), in the
//! rusEFI style: setpoint → observe the measured phase → open-loop part + closed-loop part →
//! motor speed command, with enable conditions and safe defaults.
//!
//! - Open-loop part: the ring-gear speed feed-through (eq. (11): with the motor at ring speed
//!   the phase holds), so the closed-loop part only has to supply the speed *difference*
//!   `motor_cmd_rpm`, the input of the plant model `G(N, V) = α/(s(s+β))` (eq. (12)).
//! - Closed-loop part, one of
//!   - [`EvvtGains::FixedP`]: `motor_cmd = kp·(setpoint − measured)`, the "well-tuned
//!     proportional controller" the paper's closed-loop identification used (Section IV-A),
//!     and the law the data format's closed-loop logs state;
//!   - [`EvvtGains::Scheduled`]: PI on the phase error with kp scheduled on engine speed and
//!     battery voltage from the LPV table so that the loop `L = kp α/(s(s+β))` crosses over at
//!     the same frequency ωc everywhere: `|L(jωc)| = 1` gives `kp = ωc √(ωc² + β²)/α(N, V)`.
//!     The phase margin is then `90° − atan(ωc/β)`; where β is small (9.5 V, high engine
//!     speed) holding ωc would leave too little, so ωc is lowered to `β·cot(PM_min)` there: the
//!     bandwidth stays the same wherever the plant allows it. The integral rate ki/kp must stay
//!     below β for stability (`s³ + βs² + kpα s + kiα`, Routh).
//! - Anti-windup: conditional integration (the integrator does not move further into an
//!   active magnitude or rate limit) and an integrator clamp at the magnitude limit.
//! - Integral zone: the integrator only runs while |error| <= `integral_zone_deg`. On an
//!   integrating plant a PI loop with no load ends with zero integral, so the integral of the
//!   error over a setpoint step must vanish: every degree-second of rise would come back as
//!   overshoot. Integrating only near the setpoint keeps the integral for what it is for
//!   (loads: cam torque, friction, a motor speed offset) without that overshoot.
//! - Output limits: magnitude `motor_cmd_max_rpm` and, optionally, rate
//!   `motor_cmd_rate_max_rpm_per_s`.
//! - Enable conditions: while cranking or below `min_engine_rpm` the command is zero (motor at
//!   ring speed: the phase holds, usually parked at the retard stop). A fault flagged by the
//!   caller (sensor out of range, driver fault) gives the park command: a fixed small speed
//!   difference towards the retard stop (0 degrees), open loop, since the phase signal may be
//!   the faulty one.
//!   The motor speed output is always ring speed (half the engine speed passed in, negative
//!   readings taken as 0) plus the difference; with an engine speed sensor fault the caller
//!   passes its best estimate (e.g. from the cam signal).

use crate::evvt::{EvvtLpvTable, EvvtParamError, PlanetaryGear};
use crate::lut::Lut2;
use crate::real::Real;

/// Input faults the caller detects (range checks on the sensors, driver diagnostics).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvvtFault {
    None,
    /// Cam phase signal missing or out of range.
    PhaseSensor,
    /// Crank speed signal missing or out of range.
    EngineSpeedSensor,
    /// Battery voltage out of range.
    BatteryVoltage,
    /// Motor driver reports a fault.
    MotorDriver,
}

/// What the controller did this step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvvtPhaseMode {
    /// Cranking: no control, motor at ring speed.
    HoldCranking,
    /// Engine speed below `min_engine_rpm`: no control, motor at ring speed.
    HoldLowSpeed,
    /// A fault: the park command.
    Park(EvvtFault),
    /// Closed-loop control.
    Control,
}

/// The closed-loop law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EvvtGains {
    /// `motor_cmd = kp·e`, the identification controller.
    FixedP { kp_rpm_per_deg: f64 },
    /// PI with scheduled kp (module doc).
    Scheduled {
        /// Target crossover frequency of the P loop, rad/s.
        crossover_rad_s: f64,
        /// Lower bound on the P loop's phase margin, degrees (lowers the crossover at small β).
        min_phase_margin_deg: f64,
        /// ki/kp, 1/s (0 = P only).
        integral_rate_per_s: f64,
        /// The integrator runs only while |error| is at most this, crank degrees.
        integral_zone_deg: f64,
    },
}

/// Controller configuration, plain f64 with units in the names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvvtPhaseConfig {
    pub gains: EvvtGains,
    /// The plant table the schedule is computed from (the same as the plant's by default).
    pub lpv: EvvtLpvTable,
    /// Bounds on the scheduled kp.
    pub kp_min_rpm_per_deg: f64,
    pub kp_max_rpm_per_deg: f64,
    /// Magnitude limit of the speed difference command.
    pub motor_cmd_max_rpm: f64,
    /// Rate limit of the command; `None` = no rate limit (the identification controller).
    pub motor_cmd_rate_max_rpm_per_s: Option<f64>,
    /// Below this engine speed there is no control.
    pub min_engine_rpm: f64,
    /// Speed difference commanded on a fault: towards the retard stop, so <= 0.
    pub park_cmd_rpm: f64,
    /// The setpoint is clamped into this range (the mechanical range, Section IV-B).
    pub setpoint_min_deg: f64,
    pub setpoint_max_deg: f64,
}

impl EvvtPhaseConfig {
    /// The paper's identification loop: fixed kp, magnitude limit only.
    pub fn paper_fixed_p(kp_rpm_per_deg: f64) -> Self {
        Self {
            gains: EvvtGains::FixedP { kp_rpm_per_deg },
            motor_cmd_rate_max_rpm_per_s: None,
            ..Self::default()
        }
    }
}

impl Default for EvvtPhaseConfig {
    /// Scheduled PI: crossover 2 rad/s (about what kp = 25 gives at 800 rpm, 14 V: 2.07),
    /// phase margin >= 55°, ki/kp = 0.5 /s (below the smallest β, 1.55 /s), integral zone
    /// ±3 deg, ±1000 rpm, 20000 rpm/s, control from 400 rpm, park at −100 rpm.
    fn default() -> Self {
        Self {
            gains: EvvtGains::Scheduled {
                crossover_rad_s: 2.0,
                min_phase_margin_deg: 55.0,
                integral_rate_per_s: 0.5,
                integral_zone_deg: 3.0,
            },
            lpv: EvvtLpvTable::PAPER_DESIGN,
            kp_min_rpm_per_deg: 2.0,
            kp_max_rpm_per_deg: 200.0,
            motor_cmd_max_rpm: 1000.0,
            motor_cmd_rate_max_rpm_per_s: Some(20_000.0),
            min_engine_rpm: 400.0,
            park_cmd_rpm: -100.0,
            setpoint_min_deg: 0.0,
            setpoint_max_deg: 40.0,
        }
    }
}

/// Why a configuration was rejected; each variant names the parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EvvtPhaseConfigError {
    Table(EvvtParamError),
    KpRpmPerDeg,
    CrossoverRadS,
    MinPhaseMarginDeg,
    IntegralRatePerS,
    IntegralZoneDeg,
    KpBounds,
    MotorCmdMaxRpm,
    MotorCmdRateMaxRpmPerS,
    MinEngineRpm,
    ParkCmdRpm,
    SetpointRange,
}

/// One step's inputs.
#[derive(Clone, Copy, Debug)]
pub struct EvvtPhaseInputs<R: Real> {
    pub setpoint_deg: R,
    /// The measured (quantized) cam phase.
    pub measured_phase_deg: R,
    pub engine_rpm: R,
    pub u_batt_v: R,
    pub cranking: bool,
    pub fault: EvvtFault,
}

/// One step's outputs.
#[derive(Clone, Copy, Debug)]
pub struct EvvtPhaseOutput<R: Real> {
    /// Motor speed to command: ring speed + `motor_cmd_rpm`.
    pub motor_speed_rpm: R,
    /// The speed difference (the plant input).
    pub motor_cmd_rpm: R,
    pub mode: EvvtPhaseMode,
    /// The proportional gain used this step (0 when not controlling).
    pub kp_rpm_per_deg: R,
    /// A magnitude or rate limit was active.
    pub limited: bool,
}

#[derive(Clone, Copy, Debug)]
enum Law<R: Real> {
    FixedP {
        kp: R,
    },
    Scheduled {
        crossover: R,
        max_crossover_per_beta: R,
        integral_rate: R,
        integral_zone: R,
    },
}

/// Crossover frequency (rad/s) and phase margin (degrees) of the proportional loop
/// `kp·α/(s(s+β))` (α in crank-deg/(s²·rpm), kp in rpm/deg, β in 1/s): ω·√(ω² + β²) = kp·α
/// solved for ω, and 90° − atan(ω/β) there. The controller schedules kp from a wanted
/// crossover; this is the way back, for a host that analyses a loop (`calibrate`'s notes).
pub fn p_loop_crossover_and_margin(kp_rpm_per_deg: f64, alpha_deg_per_s2_rpm: f64, beta_per_s: f64) -> (f64, f64) {
    let k = kp_rpm_per_deg * alpha_deg_per_s2_rpm;
    let b2 = beta_per_s * beta_per_s;
    let w = libm::sqrt(0.5 * (libm::sqrt(b2 * b2 + 4.0 * k * k) - b2));
    (w, 90.0 - libm::atan(w / beta_per_s).to_degrees())
}

/// The controller state machine.
#[derive(Clone, Debug)]
pub struct EvvtPhaseController<R: Real> {
    law: Law<R>,
    alpha: Lut2<R, 3, 3>,
    beta: Lut2<R, 3, 3>,
    kp_min: R,
    kp_max: R,
    cmd_max: R,
    rate_max: Option<R>,
    min_engine_rpm: R,
    park_cmd: R,
    setpoint_min: R,
    setpoint_max: R,
    /// Integral part, rpm.
    integral_rpm: R,
    /// Last output command, rpm (the rate limiter's reference).
    last_cmd_rpm: R,
}

impl<R: Real> EvvtPhaseController<R> {
    pub fn new(c: &EvvtPhaseConfig) -> Result<Self, EvvtPhaseConfigError> {
        use EvvtPhaseConfigError as E;
        let (alpha, beta) = c.lpv.build::<R>().map_err(E::Table)?;
        let f = R::from_f64;
        let law = match c.gains {
            EvvtGains::FixedP { kp_rpm_per_deg } => {
                if !(kp_rpm_per_deg > 0.0 && kp_rpm_per_deg <= 1.0e4) {
                    return Err(E::KpRpmPerDeg);
                }
                Law::FixedP { kp: f(kp_rpm_per_deg) }
            }
            EvvtGains::Scheduled {
                crossover_rad_s,
                min_phase_margin_deg,
                integral_rate_per_s,
                integral_zone_deg,
            } => {
                if !(crossover_rad_s > 0.0 && crossover_rad_s <= 100.0) {
                    return Err(E::CrossoverRadS);
                }
                if !(min_phase_margin_deg > 0.0 && min_phase_margin_deg < 89.0) {
                    return Err(E::MinPhaseMarginDeg);
                }
                if !(0.0..=100.0).contains(&integral_rate_per_s) {
                    return Err(E::IntegralRatePerS);
                }
                if !(0.0..=40.0).contains(&integral_zone_deg) {
                    return Err(E::IntegralZoneDeg);
                }
                Law::Scheduled {
                    crossover: f(crossover_rad_s),
                    // PM = 90° − atan(ωc/β) >= PM_min  ⇔  ωc <= β·cot(PM_min).
                    max_crossover_per_beta: f(1.0 / libm::tan(min_phase_margin_deg.to_radians())),
                    integral_rate: f(integral_rate_per_s),
                    integral_zone: f(integral_zone_deg),
                }
            }
        };
        if !(c.kp_min_rpm_per_deg > 0.0
            && c.kp_max_rpm_per_deg >= c.kp_min_rpm_per_deg
            && c.kp_max_rpm_per_deg <= 1.0e4)
        {
            return Err(E::KpBounds);
        }
        if !(c.motor_cmd_max_rpm > 0.0 && c.motor_cmd_max_rpm <= 20_000.0) {
            return Err(E::MotorCmdMaxRpm);
        }
        if let Some(r) = c.motor_cmd_rate_max_rpm_per_s {
            if !(r > 0.0 && r <= 1.0e7) {
                return Err(E::MotorCmdRateMaxRpmPerS);
            }
        }
        if !(0.0..=12_000.0).contains(&c.min_engine_rpm) {
            return Err(E::MinEngineRpm);
        }
        if !(c.park_cmd_rpm <= 0.0 && c.park_cmd_rpm >= -c.motor_cmd_max_rpm) {
            return Err(E::ParkCmdRpm);
        }
        if !(c.setpoint_min_deg.is_finite()
            && c.setpoint_max_deg.is_finite()
            && c.setpoint_max_deg > c.setpoint_min_deg)
        {
            return Err(E::SetpointRange);
        }
        Ok(Self {
            law,
            alpha,
            beta,
            kp_min: f(c.kp_min_rpm_per_deg),
            kp_max: f(c.kp_max_rpm_per_deg),
            cmd_max: f(c.motor_cmd_max_rpm),
            rate_max: c.motor_cmd_rate_max_rpm_per_s.map(f),
            min_engine_rpm: f(c.min_engine_rpm),
            park_cmd: f(c.park_cmd_rpm),
            setpoint_min: f(c.setpoint_min_deg),
            setpoint_max: f(c.setpoint_max_deg),
            integral_rpm: R::ZERO,
            last_cmd_rpm: R::ZERO,
        })
    }

    /// Proportional gain (rpm per crank degree) and integral rate (1/s) at engine speed
    /// `engine_rpm` and battery voltage `u_batt_v`.
    pub fn gains_at(&self, engine_rpm: R, u_batt_v: R) -> (R, R) {
        match self.law {
            Law::FixedP { kp } => (kp, R::ZERO),
            Law::Scheduled {
                crossover,
                max_crossover_per_beta,
                integral_rate,
                ..
            } => {
                // α and β share their grid: one look-up.
                let at = self.alpha.locate(engine_rpm, u_batt_v);
                let alpha = self.alpha.eval_at(at);
                let beta = self.beta.eval_at(at);
                let wc = crossover.min(max_crossover_per_beta * beta);
                let kp = wc * (wc * wc + beta * beta).sqrt() / alpha;
                (kp.clamp(self.kp_min, self.kp_max), integral_rate)
            }
        }
    }

    /// The integral part, rpm (for logging and tests).
    pub fn integral_rpm(&self) -> R {
        self.integral_rpm
    }

    /// Forgets the integral and the rate limiter's history.
    pub fn reset(&mut self) {
        self.integral_rpm = R::ZERO;
        self.last_cmd_rpm = R::ZERO;
    }

    fn output(&mut self, cmd: R, engine_rpm: R, mode: EvvtPhaseMode, kp: R, limited: bool) -> EvvtPhaseOutput<R> {
        self.last_cmd_rpm = cmd;
        EvvtPhaseOutput {
            motor_speed_rpm: PlanetaryGear::ring_speed_rpm(engine_rpm.max(R::ZERO)) + cmd,
            motor_cmd_rpm: cmd,
            mode,
            kp_rpm_per_deg: kp,
            limited,
        }
    }

    /// One control period of length `dt_s`.
    pub fn update(&mut self, inp: &EvvtPhaseInputs<R>, dt_s: R) -> EvvtPhaseOutput<R> {
        let dt = dt_s.max(R::ZERO);
        if inp.fault != EvvtFault::None {
            self.integral_rpm = R::ZERO;
            return self.output(
                self.park_cmd,
                inp.engine_rpm,
                EvvtPhaseMode::Park(inp.fault),
                R::ZERO,
                false,
            );
        }
        if inp.cranking || inp.engine_rpm < self.min_engine_rpm {
            self.integral_rpm = R::ZERO;
            let mode = if inp.cranking {
                EvvtPhaseMode::HoldCranking
            } else {
                EvvtPhaseMode::HoldLowSpeed
            };
            return self.output(R::ZERO, inp.engine_rpm, mode, R::ZERO, false);
        }

        let setpoint = inp.setpoint_deg.clamp(self.setpoint_min, self.setpoint_max);
        let error = setpoint - inp.measured_phase_deg;
        let (kp, integral_rate) = self.gains_at(inp.engine_rpm, inp.u_batt_v);
        let in_zone = match self.law {
            Law::Scheduled { integral_zone, .. } => error.abs() <= integral_zone,
            Law::FixedP { .. } => false,
        };
        let integral_step = if in_zone {
            kp * integral_rate * error * dt
        } else {
            R::ZERO
        };
        let candidate_integral = (self.integral_rpm + integral_step).clamp(-self.cmd_max, self.cmd_max);
        let unlimited = kp * error + candidate_integral;
        let mut cmd = unlimited.clamp(-self.cmd_max, self.cmd_max);
        if let Some(rate) = self.rate_max {
            let step = rate * dt;
            cmd = cmd.clamp(self.last_cmd_rpm - step, self.last_cmd_rpm + step);
        }
        let limited = cmd != unlimited;
        // Conditional integration: accept the new integral unless a limit is active and the
        // error pushes further into it.
        let pushes_into_limit = (unlimited - cmd) * error > R::ZERO;
        if !(limited && pushes_into_limit) {
            self.integral_rpm = candidate_integral;
        }
        self.output(cmd, inp.engine_rpm, EvvtPhaseMode::Control, kp, limited)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs(setpoint: f64, measured: f64) -> EvvtPhaseInputs<f64> {
        EvvtPhaseInputs {
            setpoint_deg: setpoint,
            measured_phase_deg: measured,
            engine_rpm: 1100.0,
            u_batt_v: 13.0,
            cranking: false,
            fault: EvvtFault::None,
        }
    }

    #[test]
    fn fixed_p_is_kp_times_error_with_ring_speed_feed_through() {
        let mut c = EvvtPhaseController::<f64>::new(&EvvtPhaseConfig::paper_fixed_p(25.0)).unwrap();
        let out = c.update(&inputs(25.0, 21.0), 0.01);
        assert_eq!(out.mode, EvvtPhaseMode::Control);
        assert_eq!(out.motor_cmd_rpm, 100.0);
        assert_eq!(out.motor_speed_rpm, 550.0 + 100.0);
        // Saturates at the magnitude limit; the setpoint is clamped to the mechanical range.
        let out = c.update(&inputs(90.0, -5.0), 0.01);
        assert_eq!((out.motor_cmd_rpm, out.limited), (1000.0, true));
        let out = c.update(&inputs(-10.0, 2.0), 0.01);
        assert_eq!(out.motor_cmd_rpm, -50.0);
    }

    #[test]
    fn enable_conditions_and_park() {
        let mut c = EvvtPhaseController::<f64>::new(&EvvtPhaseConfig::default()).unwrap();
        let mut i = inputs(30.0, 10.0);
        i.cranking = true;
        let out = c.update(&i, 0.01);
        assert_eq!(
            (out.mode, out.motor_cmd_rpm, out.motor_speed_rpm),
            (EvvtPhaseMode::HoldCranking, 0.0, 550.0)
        );
        let mut i = inputs(30.0, 10.0);
        i.engine_rpm = 350.0;
        let out = c.update(&i, 0.01);
        assert_eq!(
            (out.mode, out.motor_cmd_rpm, out.motor_speed_rpm),
            (EvvtPhaseMode::HoldLowSpeed, 0.0, 175.0)
        );
        for fault in [
            EvvtFault::PhaseSensor,
            EvvtFault::EngineSpeedSensor,
            EvvtFault::BatteryVoltage,
            EvvtFault::MotorDriver,
        ] {
            let mut i = inputs(30.0, 10.0);
            i.fault = fault;
            let out = c.update(&i, 0.01);
            assert_eq!((out.mode, out.motor_cmd_rpm), (EvvtPhaseMode::Park(fault), -100.0));
            assert_eq!(c.integral_rpm(), 0.0);
        }
        // A fault wins over cranking; a negative speed reading never gives a negative ring speed.
        let mut i = inputs(30.0, 10.0);
        i.cranking = true;
        i.fault = EvvtFault::PhaseSensor;
        i.engine_rpm = -5.0;
        let out = c.update(&i, 0.01);
        assert_eq!(
            (out.mode, out.motor_speed_rpm),
            (EvvtPhaseMode::Park(EvvtFault::PhaseSensor), -100.0)
        );
    }

    #[test]
    fn rate_limit_ramps_the_command() {
        let mut c = EvvtPhaseController::<f64>::new(&EvvtPhaseConfig::default()).unwrap();
        let mut prev = 0.0;
        for k in 0..10 {
            let out = c.update(&inputs(40.0, 0.0), 0.001);
            // 20000 rpm/s × 1 ms = 20 rpm per step at most.
            assert!((out.motor_cmd_rpm - prev - 20.0).abs() < 1e-9, "step {k}");
            assert!(out.limited);
            prev = out.motor_cmd_rpm;
        }
        // Integrator frozen while the limit holds the output back.
        assert_eq!(c.integral_rpm(), 0.0);
    }

    #[test]
    fn schedule_holds_the_crossover_and_the_phase_margin() {
        let c = EvvtPhaseController::<f64>::new(&EvvtPhaseConfig::default()).unwrap();
        let mut capped = 0;
        for n in [800.0, 1100.0, 1400.0, 950.0] {
            for v in [9.5, 11.5, 14.0, 10.0] {
                let (kp, ki_rate) = c.gains_at(n, v);
                let a = c.alpha.eval(n, v);
                let b = c.beta.eval(n, v);
                let (wc, pm) = p_loop_crossover_and_margin(kp, a, b);
                assert!(pm >= 55.0 - 1e-6, "{n} rpm {v} V: phase margin {pm}");
                if b * (35.0f64).to_radians().tan() >= 2.0 {
                    assert!((wc - 2.0).abs() < 1e-9, "{n} rpm {v} V: crossover {wc}");
                } else {
                    capped += 1;
                    assert!((pm - 55.0).abs() < 1e-6 && wc < 2.0);
                }
                // Routh: ki/kp below β.
                assert!(ki_rate < b);
            }
        }
        // The cap binds only at low voltage and higher speed: β < 2/tan 35° = 2.86 /s
        // (1100 rpm 9.5 V, 1400 rpm 9.5 V and 10 V).
        assert_eq!(capped, 3);
    }

    #[test]
    fn rejects_bad_configuration_by_name() {
        use EvvtPhaseConfigError as E;
        let bad = |c: EvvtPhaseConfig| EvvtPhaseController::<f32>::new(&c).unwrap_err();
        assert_eq!(bad(EvvtPhaseConfig::paper_fixed_p(0.0)), E::KpRpmPerDeg);
        assert_eq!(
            bad(EvvtPhaseConfig {
                park_cmd_rpm: 50.0,
                ..Default::default()
            }),
            E::ParkCmdRpm
        );
        assert_eq!(
            bad(EvvtPhaseConfig {
                motor_cmd_max_rpm: f64::NAN,
                ..Default::default()
            }),
            E::MotorCmdMaxRpm
        );
        assert_eq!(
            bad(EvvtPhaseConfig {
                motor_cmd_rate_max_rpm_per_s: Some(-1.0),
                ..Default::default()
            }),
            E::MotorCmdRateMaxRpmPerS
        );
        assert_eq!(
            bad(EvvtPhaseConfig {
                gains: EvvtGains::Scheduled {
                    crossover_rad_s: 2.0,
                    min_phase_margin_deg: 90.0,
                    integral_rate_per_s: 0.5,
                    integral_zone_deg: 3.0,
                },
                ..Default::default()
            }),
            E::MinPhaseMarginDeg
        );
        assert_eq!(
            bad(EvvtPhaseConfig {
                setpoint_min_deg: 40.0,
                ..Default::default()
            }),
            E::SetpointRange
        );
    }
}
