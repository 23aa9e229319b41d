//! Vacuum task logic (Thomasson 2013), run at 80 Hz for the three 300 Hz PWM valves (LPT
//! wastegate, HPT bypass, HPC bypass):
//! - position control per valve, one [`VacuumPositionController`] each (the project's one
//!   vacuum position law): open-loop part from the inverse actuator model (Sec. 5.2/5.4:
//!   setpoint → chamber pressure, inverse of eq. (8)/(9) → corrected duty, inverse of eq.
//!   (2)/(5) → supply-voltage compensation, eq. (15)) plus a PI on the measured position as a
//!   pressure correction, with a deadband inside the rod's Coulomb/Dahl friction band, a
//!   conditional integration zone and limit (anti-windup);
//! - enable conditions per valve: setpoint at rest, the supervisor's spring-open safe state,
//!   a stuck actuator or an abnormal leak → 0 % (the spring's safe position) and the
//!   integrator cleared; an implausible position reading (non-finite or outside
//!   `x_meas_min_pct..x_meas_max_pct`) → feedforward only for that valve, integrator cleared
//!   (the supervisor's debounced position-sensor fault then asks for the spring position); a
//!   supply below `comp_u_min_v` → feedforward with the integrator frozen;
//! - vacuum pump switched on the pressure the actuators need (Sec. 5.3): the tank must be a
//!   margin below the lowest chamber pressure the setpoints ask for (the valve cannot pull
//!   a chamber below the tank, eq. (2) saturation), and never above a reserve level; instead
//!   of the conservative "always below 35 kPa";
//! - tank-pressure residual against the tank model (eqs. (3), (12)-(14)), driven by the same
//!   commands: the measured tank pressure rising faster than the model says is an abnormal
//!   leak (broken hose, leaking valve) or a pump that does not pump (Sec. 5.3);
//! - a stuck actuator: measured position far from the model's position for too long.

use super::board::elapsed_us;
use super::supervisor::SafeState;
use crate::control::vacuum_position::{
    VacuumPositionConfig, VacuumPositionConfigError, VacuumPositionController, VacuumPositionFault,
    VacuumPositionInputs, VacuumPositionMode,
};
use crate::vacuum::{VacuumInputs, VacuumParamError, VacuumParams, VacuumTank, VacuumTankParams, VacuumValveActuator};

/// Calibration of the vacuum task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumTaskConfig {
    /// LPT, HPT, HPC.
    pub actuators: [VacuumParams; 3],
    pub tank: VacuumTankParams,
    /// Below this supply voltage the compensation holds (eq. (15) limit).
    pub comp_u_min_v: f64,
    /// Setpoints at or below this position get 0 % duty (spring position, no air used).
    pub x_rest_pct: f32,
    /// The tank is kept this far below the lowest needed chamber pressure.
    pub tank_margin_kpa: f32,
    /// The tank is never left above this (a reserve for a sudden demand).
    pub tank_reserve_kpa: f32,
    /// Never ask for less: the pump's floor is about p_amb/7 ≈ 15 kPa (eq. (14)).
    pub tank_target_min_kpa: f32,
    pub pump_hysteresis_kpa: f32,
    /// Length of one residual window.
    pub leak_window_s: f32,
    /// Residual rate above which a window counts as abnormal.
    pub leak_rate_kpa_per_s: f32,
    /// Consecutive abnormal windows before the flag.
    pub leak_windows: u8,
    pub stuck_error_pct: f32,
    pub stuck_time_s: f32,
    /// Position PI (see [`VacuumPositionConfig`]): proportional loop gain (the pressure
    /// correction follows each map's slope) and integral gain in kPa/(%·s); 0 and 0 leave
    /// the feedforward alone.
    pub kp_loop_gain: f64,
    pub ki_kpa_per_pct_s: f64,
    /// Share of each actuator's rod friction and clearance fed forward (see
    /// [`VacuumPositionConfig::friction_compensation`]).
    pub friction_compensation: f64,
    /// The integrator holds inside this band (inside the friction band: no hunting).
    pub integral_deadband_pct: f64,
    /// ... and beyond this error (large moves: no windup).
    pub integral_zone_pct: f64,
    /// A position reading outside this range is implausible: that valve runs open loop.
    pub x_meas_min_pct: f32,
    pub x_meas_max_pct: f32,
}

impl VacuumTaskConfig {
    /// The position controller for `actuator` (its own maps, U_ref and friction limit).
    pub fn position_config(&self, actuator: VacuumParams) -> VacuumPositionConfig {
        VacuumPositionConfig {
            kp_loop_gain: self.kp_loop_gain,
            ki_kpa_per_pct_s: self.ki_kpa_per_pct_s,
            friction_compensation: self.friction_compensation,
            integral_deadband_pct: self.integral_deadband_pct,
            integral_zone_pct: self.integral_zone_pct,
            u_min_v: self.comp_u_min_v,
            pump_margin_kpa: f64::from(self.tank_margin_kpa),
            ..VacuumPositionConfig::for_actuator(actuator)
        }
    }
}

impl Default for VacuumTaskConfig {
    /// The paper's actuators and tank; reserve 70 kPa (the Sec. 5.3 example: "70 kPa would be
    /// enough"), margin 10 kPa, hysteresis 5 kPa, leak above 0.5 kPa/s (the base leak is
    /// ~0.1 kPa/s, a broken hose several kPa/s) in two 2 s windows, stuck above 15 % for 1 s;
    /// the position controller's PI defaults; a reading beyond −5..105 % is implausible (the
    /// ADC scale's ends; a sound sensor reads 0..100 %).
    fn default() -> Self {
        // The position controller's gains (the same for the three valves; its integral limit
        // follows each actuator's friction).
        let gains = VacuumPositionConfig::for_actuator(VacuumParams::lpt());
        Self {
            actuators: [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()],
            tank: VacuumTankParams::paper(),
            comp_u_min_v: 6.0,
            x_rest_pct: 0.5,
            tank_margin_kpa: 10.0,
            tank_reserve_kpa: 70.0,
            tank_target_min_kpa: 20.0,
            pump_hysteresis_kpa: 5.0,
            leak_window_s: 2.0,
            leak_rate_kpa_per_s: 0.5,
            leak_windows: 2,
            stuck_error_pct: 15.0,
            stuck_time_s: 1.0,
            kp_loop_gain: gains.kp_loop_gain,
            ki_kpa_per_pct_s: gains.ki_kpa_per_pct_s,
            friction_compensation: gains.friction_compensation,
            integral_deadband_pct: gains.integral_deadband_pct,
            integral_zone_pct: gains.integral_zone_pct,
            x_meas_min_pct: -5.0,
            x_meas_max_pct: 105.0,
        }
    }
}

/// Why the task could not be built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VacuumTaskError {
    Model(VacuumParamError),
    Controller(VacuumPositionConfigError),
    Parameter(&'static str),
}

/// Inputs of one 80 Hz step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumTaskInputs {
    /// Position setpoints, LPT, HPT, HPC.
    pub x_set_pct: [f32; 3],
    /// Measured positions.
    pub x_meas_pct: [f32; 3],
    pub p_tank_kpa: f32,
    pub p_amb_kpa: f32,
    pub u_batt_v: f32,
    /// The supervisor's safe state (vacuum and pump parts are used).
    pub safe: SafeState,
}

/// Outputs of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumTaskOutputs {
    /// PWM duties 0..1.
    pub duty: [f32; 3],
    pub pump_on: bool,
    /// The tank pressure the setpoints need now.
    pub p_tank_target_kpa: f32,
    /// Last completed window's residual rate, measured minus model, kPa/s.
    pub residual_kpa_per_s: f32,
    pub abnormal_leak: bool,
    pub stuck: [bool; 3],
    /// The supply was below the compensator's range.
    pub supply_low: bool,
    /// What each valve's position controller did (`Off`: 0 %, spring position).
    pub mode: [VacuumPositionMode; 3],
}

/// The vacuum task state machine.
#[derive(Clone, Debug)]
pub struct VacuumTask {
    cfg: VacuumTaskConfig,
    control: [VacuumPositionController<f32>; 3],
    /// Observer: the actuators driven by the commanded duties, seeing the measured tank.
    observer: [VacuumValveActuator<f32>; 3],
    tank_model: VacuumTank<f32>,
    pump_on: bool,
    last_duty_pct: [f32; 3],
    last_step_us: Option<u32>,
    window_start_us: Option<u32>,
    window_p_meas_start: f32,
    residual_kpa_per_s: f32,
    abnormal_windows: u8,
    abnormal_leak: bool,
    stuck_since_us: [Option<u32>; 3],
    stuck: [bool; 3],
}

impl VacuumTask {
    pub fn new(cfg: VacuumTaskConfig) -> Result<Self, VacuumTaskError> {
        let m = VacuumTaskError::Model;
        let [a, b, c] = &cfg.actuators;
        let ctrl = |p: &VacuumParams| {
            VacuumPositionController::new(&cfg.position_config(*p)).map_err(VacuumTaskError::Controller)
        };
        let control = [ctrl(a)?, ctrl(b)?, ctrl(c)?];
        let observer = [
            VacuumValveActuator::new(a).map_err(m)?,
            VacuumValveActuator::new(b).map_err(m)?,
            VacuumValveActuator::new(c).map_err(m)?,
        ];
        if !(cfg.x_meas_min_pct < cfg.x_meas_max_pct && cfg.x_meas_min_pct <= 0.0 && cfg.x_meas_max_pct >= 100.0) {
            return Err(VacuumTaskError::Parameter("x_meas_min_pct/x_meas_max_pct"));
        }
        let tank_model = VacuumTank::new(&cfg.tank, 100.0).map_err(m)?;
        if !(cfg.leak_window_s > 0.05 && cfg.leak_window_s < 60.0) {
            return Err(VacuumTaskError::Parameter("leak_window_s"));
        }
        if !(cfg.pump_hysteresis_kpa >= 0.0
            && cfg.tank_target_min_kpa >= 1.0
            && cfg.tank_reserve_kpa > cfg.tank_target_min_kpa)
        {
            return Err(VacuumTaskError::Parameter("tank pressure targets"));
        }
        Ok(Self {
            cfg,
            control,
            observer,
            tank_model,
            pump_on: false,
            last_duty_pct: [0.0; 3],
            last_step_us: None,
            window_start_us: None,
            window_p_meas_start: 0.0,
            residual_kpa_per_s: 0.0,
            abnormal_windows: 0,
            abnormal_leak: false,
            stuck_since_us: [None; 3],
            stuck: [false; 3],
        })
    }

    /// The open-loop part of valve `i`'s command: chamber pressure that holds `x_set_pct`
    /// (no friction), and the compensated duty (%) that gives it at `u_batt_v`; 0 % at the
    /// rest position.
    pub fn feedforward(&self, i: usize, x_set_pct: f32, p_amb_kpa: f32, u_batt_v: f32) -> (Option<f32>, f32, bool) {
        let Some(ctrl) = self.control.get(i) else {
            return (None, 0.0, false);
        };
        if !(x_set_pct > self.cfg.x_rest_pct) {
            return (None, 0.0, false);
        }
        let (p_need, c) = ctrl.feedforward(x_set_pct, p_amb_kpa, u_batt_v);
        (Some(p_need), c.duty_pct, c.supply_low)
    }

    /// Valve `i`'s integral pressure correction, kPa (0 for a bad index).
    pub fn integral_kpa(&self, i: usize) -> f32 {
        self.control.get(i).map_or(0.0, |c| c.integral_kpa())
    }

    /// One step at `now_us` (nominally every 12.5 ms).
    pub fn step(&mut self, inp: &VacuumTaskInputs, now_us: u32) -> VacuumTaskOutputs {
        let dt_s = self
            .last_step_us
            .map_or(0.0, |t| elapsed_us(now_us, t) as f32 * 1e-6)
            .min(1.0);
        self.last_step_us = Some(now_us);
        let p_amb = inp.p_amb_kpa;
        let p_tank = inp.p_tank_kpa;

        // Observer over the last period with the duties and pump state then applied.
        let mut inflow_mg_s = 0.0;
        for (k, obs) in self.observer.iter_mut().enumerate() {
            let duty_pct = self.last_duty_pct.get(k).copied().unwrap_or(0.0);
            let o = obs.step(
                &VacuumInputs {
                    duty_pct,
                    u_batt_v: inp.u_batt_v,
                    p_amb_kpa: p_amb,
                    p_tank_kpa: p_tank,
                },
                dt_s,
            );
            inflow_mg_s += o.flow_to_tank_mg_s;
        }
        self.tank_model.step(self.pump_on, inflow_mg_s, p_amb, dt_s);
        self.update_residual(p_tank, now_us);
        self.update_stuck(inp, now_us);

        // Position control per valve and the tank pressure the setpoints need. Disabled (0 %,
        // integrator cleared): the safe states, and a setpoint at the spring position.
        let vacuum_safe = inp.safe.vacuum_spring_open || self.abnormal_leak || self.stuck.iter().any(|s| *s);
        let mut duty_pct = [0.0f32; 3];
        let mut mode = [VacuumPositionMode::Off; 3];
        let mut p_need_min = f32::INFINITY;
        let mut supply_low = false;
        // The controllers see it too (their compensator has the same u_min); reported here
        // also while they are disabled.
        let supply_below_range = inp.u_batt_v.is_nan() || f64::from(inp.u_batt_v) < self.cfg.comp_u_min_v;
        for (k, ctrl) in self.control.iter_mut().enumerate() {
            let x_set = inp.x_set_pct.get(k).copied().unwrap_or(0.0);
            let x_meas = inp.x_meas_pct.get(k).copied().unwrap_or(f32::NAN);
            let at_rest = x_set.is_nan() || x_set <= self.cfg.x_rest_pct;
            let plausible =
                x_meas.is_finite() && x_meas >= self.cfg.x_meas_min_pct && x_meas <= self.cfg.x_meas_max_pct;
            let o = ctrl.step(
                &VacuumPositionInputs {
                    setpoint_pct: x_set,
                    measured_x_pct: if plausible { x_meas } else { 0.0 },
                    p_amb_kpa: p_amb,
                    p_tank_kpa: p_tank,
                    u_batt_v: inp.u_batt_v,
                    enabled: !(at_rest || vacuum_safe),
                    fault: if plausible {
                        VacuumPositionFault::None
                    } else {
                        VacuumPositionFault::PositionSensor
                    },
                },
                dt_s,
            );
            if let (Some(d), Some(m)) = (duty_pct.get_mut(k), mode.get_mut(k)) {
                *d = o.duty_pct;
                *m = o.mode;
            }
            // What the setpoints need, also while disabled (the pump still serves a
            // supervisor that only cut the pump); not for valves at rest.
            if !at_rest {
                supply_low |= supply_below_range;
                p_need_min = p_need_min.min(o.p_feedforward_kpa);
            }
        }
        let target = (p_need_min - self.cfg.tank_margin_kpa)
            .min(self.cfg.tank_reserve_kpa)
            .max(self.cfg.tank_target_min_kpa);
        // Hysteresis: on above the target, off once the hysteresis below it is reached.
        if p_tank > target {
            self.pump_on = true;
        } else if p_tank < target - self.cfg.pump_hysteresis_kpa {
            self.pump_on = false;
        }

        if inp.safe.pump_off || self.abnormal_leak {
            self.pump_on = false;
        }
        self.last_duty_pct = duty_pct;
        VacuumTaskOutputs {
            duty: duty_pct.map(|d| d / 100.0),
            pump_on: self.pump_on,
            p_tank_target_kpa: target,
            residual_kpa_per_s: self.residual_kpa_per_s,
            abnormal_leak: self.abnormal_leak,
            stuck: self.stuck,
            supply_low,
            mode,
        }
    }

    /// Residual per window: measured minus modelled tank pressure change, then the model
    /// restarts from the measurement (an open-loop integrator drifts, Sec. 4.1).
    fn update_residual(&mut self, p_tank_meas: f32, now_us: u32) {
        let Some(start) = self.window_start_us else {
            self.restart_window(p_tank_meas, now_us);
            return;
        };
        let window_s = elapsed_us(now_us, start) as f32 * 1e-6;
        if window_s < self.cfg.leak_window_s {
            return;
        }
        let measured = p_tank_meas - self.window_p_meas_start;
        let modelled = self.tank_model.p_tank_kpa() - self.window_p_meas_start;
        self.residual_kpa_per_s = (measured - modelled) / window_s;
        if self.residual_kpa_per_s > self.cfg.leak_rate_kpa_per_s {
            self.abnormal_windows = self.abnormal_windows.saturating_add(1);
        } else {
            self.abnormal_windows = 0;
        }
        if self.abnormal_windows >= self.cfg.leak_windows {
            self.abnormal_leak = true;
        }
        self.restart_window(p_tank_meas, now_us);
    }

    fn restart_window(&mut self, p_tank_meas: f32, now_us: u32) {
        // The model accepts 1..400 kPa; a sensor value outside is the supervisor's business.
        let p0 = p_tank_meas.clamp(1.0, 400.0) as f64;
        if let Ok(t) = VacuumTank::new(&self.cfg.tank, p0) {
            self.tank_model = t;
        }
        self.window_start_us = Some(now_us);
        self.window_p_meas_start = p_tank_meas;
    }

    fn update_stuck(&mut self, inp: &VacuumTaskInputs, now_us: u32) {
        // Judged only while the valves are commanded: in the supervisor's safe state the
        // position reading may be the failed sensor's last good value.
        if inp.safe.vacuum_spring_open {
            self.stuck_since_us = [None; 3];
            return;
        }
        for k in 0..3 {
            let (Some(obs), Some(&x_meas), Some(since), Some(stuck)) = (
                self.observer.get(k),
                inp.x_meas_pct.get(k),
                self.stuck_since_us.get_mut(k),
                self.stuck.get_mut(k),
            ) else {
                continue;
            };
            let off = !((x_meas - obs.x_pct()).abs() <= self.cfg.stuck_error_pct);
            if off {
                let t0 = *since.get_or_insert(now_us);
                if elapsed_us(now_us, t0) as f32 * 1e-6 >= self.cfg.stuck_time_s {
                    *stuck = true;
                }
            } else {
                *since = None;
            }
        }
    }
}

#[cfg(test)]
mod tests;
