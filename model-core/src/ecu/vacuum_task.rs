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
mod tests {
    use super::*;
    use crate::vacuum::{VacuumEffects, VacuumSystem};

    const DT_US: u32 = 12_500;

    /// The actuators without friction/backlash but with the supply-voltage effect (the
    /// feedforward has no friction compensation; the position controller is another module).
    fn frictionless() -> [VacuumParams; 3] {
        let e = VacuumEffects {
            supply_voltage: true,
            ..VacuumEffects::NONE
        };
        [
            VacuumParams::lpt().with_effects(e),
            VacuumParams::hpt().with_effects(e),
            VacuumParams::hpc().with_effects(e),
        ]
    }

    struct Sim {
        task: VacuumTask,
        plant: VacuumSystem<f32>,
        tank_params: VacuumTankParams,
        t_us: u32,
        pump_on_steps: u32,
        pump_broken: bool,
        x_override: [Option<f32>; 3],
        safe: SafeState,
    }

    impl Sim {
        fn new(params: [VacuumParams; 3], p_tank0: f64) -> Self {
            Self::with_config(
                VacuumTaskConfig {
                    actuators: params,
                    ..Default::default()
                },
                p_tank0,
            )
        }

        fn with_config(cfg: VacuumTaskConfig, p_tank0: f64) -> Self {
            let params = cfg.actuators;
            let tank = VacuumTankParams::paper();
            Self {
                task: VacuumTask::new(cfg).unwrap(),
                plant: VacuumSystem::new(&params[0], &params[1], &params[2], &tank, p_tank0).unwrap(),
                tank_params: tank,
                t_us: 0,
                pump_on_steps: 0,
                pump_broken: false,
                x_override: [None; 3],
                safe: SafeState::default(),
            }
        }

        /// Runs for `s` seconds; returns the last outputs.
        fn run(&mut self, x_set: [f32; 3], u_batt: f32, s: f32) -> VacuumTaskOutputs {
            let steps = (s * 1e6 / DT_US as f32) as u32;
            let mut out = None;
            let mut x_meas = [self.plant.lpt.x_pct(), self.plant.hpt.x_pct(), self.plant.hpc.x_pct()];
            for _ in 0..steps {
                for k in 0..3 {
                    if let Some(x) = self.x_override[k] {
                        x_meas[k] = x;
                    }
                }
                let inp = VacuumTaskInputs {
                    x_set_pct: x_set,
                    x_meas_pct: x_meas,
                    p_tank_kpa: self.plant.tank.p_tank_kpa(),
                    p_amb_kpa: 100.0,
                    u_batt_v: u_batt,
                    safe: self.safe,
                };
                let o = self.task.step(&inp, self.t_us);
                self.pump_on_steps += u32::from(o.pump_on);
                let duties = o.duty.map(|d| d * 100.0);
                let r = self.plant.step(
                    duties,
                    u_batt,
                    100.0,
                    o.pump_on && !self.pump_broken,
                    DT_US as f32 * 1e-6,
                );
                x_meas = r.actuators.map(|a| a.x_pct);
                self.t_us += DT_US;
                out = Some(o);
            }
            out.unwrap()
        }
    }

    #[test]
    fn inverse_model_with_compensation_puts_the_actuators_at_the_setpoints() {
        // At 11 V and 14.5 V (U_ref = 12 V) the compensated duty holds the positions. (The
        // HPC valve needs 87 % corrected duty for 30 %: at 11 V that is 95 % of the PWM; below
        // about 10.5 V it saturates at 100 % and falls short, a physical limit.)
        for u in [11.0f32, 14.5] {
            let mut sim = Sim::new(frictionless(), 25.0);
            let x_set = [40.0, 30.0, 30.0];
            sim.run(x_set, u, 3.0);
            let x = [sim.plant.lpt.x_pct(), sim.plant.hpt.x_pct(), sim.plant.hpc.x_pct()];
            for k in 0..3 {
                assert!(
                    (x[k] - x_set[k]).abs() < 1.0,
                    "{u} V actuator {k}: {} vs {}",
                    x[k],
                    x_set[k]
                );
            }
        }
        // Without compensation (duty fixed at its 12 V value) the HPT at 14.5 V misses by far.
        let task = VacuumTask::new(VacuumTaskConfig {
            actuators: frictionless(),
            ..Default::default()
        })
        .unwrap();
        let (_, duty_12v, _) = task.feedforward(1, 30.0, 100.0, 12.0);
        let (_, duty_14v, _) = task.feedforward(1, 30.0, 100.0, 14.5);
        assert!((duty_14v / duty_12v - 12.0 / 14.5).abs() < 1e-4);
        let mut plant = VacuumSystem::<f32>::new(
            &frictionless()[0],
            &frictionless()[1],
            &frictionless()[2],
            &VacuumTankParams::paper(),
            25.0,
        )
        .unwrap();
        for _ in 0..240 {
            plant.step([0.0, duty_12v, 0.0], 14.5, 100.0, true, 0.0125);
        }
        assert!(
            (plant.hpt.x_pct() - 30.0).abs() > 10.0,
            "uncompensated HPT at {}",
            plant.hpt.x_pct()
        );
    }

    #[test]
    fn pump_runs_on_the_needed_pressure_and_less_than_a_fixed_35_kpa_rule() {
        // Setpoints that need about 73-74 kPa in the chambers (the HPC at rest needs none):
        // the target is the lower of the two less the 10 kPa margin.
        let x_set = [30.0, 30.0, 0.0];
        let mut sim = Sim::new(frictionless(), 100.0);
        let need = [0, 1].map(|k| sim.task.feedforward(k, x_set[k], 100.0, 13.5).0.unwrap());
        assert!(need.iter().all(|p| (70.0..76.0).contains(p)), "{need:?}");
        let expected = need[0].min(need[1]) - sim.task.cfg.tank_margin_kpa;
        let out = sim.run(x_set, 13.5, 60.0);
        assert!(
            (out.p_tank_target_kpa - expected).abs() < 0.5,
            "target {} (expected {expected})",
            out.p_tank_target_kpa
        );
        // The pump holds the tank within its hysteresis below the target.
        let p = sim.plant.tank.p_tank_kpa();
        assert!(p < expected + 1.0 && p > expected - 10.0, "tank {p}");
        assert!((sim.plant.lpt.x_pct() - 30.0).abs() < 1.0 && (sim.plant.hpt.x_pct() - 30.0).abs() < 1.0);
        let on_needed = sim.pump_on_steps;
        // The fixed rule (always below 35 kPa, 5 kPa hysteresis) on the same plant and setpoints.
        let mut plant = VacuumSystem::<f32>::new(
            &frictionless()[0],
            &frictionless()[1],
            &frictionless()[2],
            &sim.tank_params,
            100.0,
        )
        .unwrap();
        let duties = [0, 1, 2].map(|k| sim.task.feedforward(k, x_set[k], 100.0, 13.5).1);
        let (mut pump, mut on_fixed) = (false, 0u32);
        for _ in 0..(60_000_000 / DT_US) {
            let p = plant.tank.p_tank_kpa();
            pump = p > 35.0 || (pump && p > 30.0);
            on_fixed += u32::from(pump);
            plant.step(duties, 13.5, 100.0, pump, DT_US as f32 * 1e-6);
        }
        assert!(
            (on_needed as f32) < 0.6 * on_fixed as f32,
            "pump on {} steps on the need vs {} on the fixed rule",
            on_needed,
            on_fixed
        );
        // A setpoint that needs deep vacuum lowers the target.
        let out = sim.run([90.0, 30.0, 0.0], 13.5, 0.1);
        assert!(out.p_tank_target_kpa < 40.0, "{}", out.p_tank_target_kpa);
    }

    #[test]
    fn healthy_system_raises_no_leak_and_no_stuck_flag() {
        let mut sim = Sim::new(VacuumTaskConfig::default().actuators, 60.0);
        for x_set in [
            [20.0, 40.0, 60.0],
            [80.0, 10.0, 30.0],
            [0.0, 60.0, 90.0],
            [50.0, 50.0, 50.0],
        ] {
            let out = sim.run(x_set, 13.5, 10.0);
            assert!(!out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
            assert!(
                out.residual_kpa_per_s.abs() < 0.2,
                "residual {}",
                out.residual_kpa_per_s
            );
            assert_eq!(out.stuck, [false; 3]);
        }
    }

    #[test]
    fn broken_hose_is_flagged_and_the_wastegate_goes_to_its_spring() {
        let mut sim = Sim::new(frictionless(), 60.0);
        let x_set = [40.0, 30.0, 20.0];
        assert!(!sim.run(x_set, 13.5, 10.0).abnormal_leak);
        // A hose cracks: 0.5 mm² from ambient into the tank (25 times the base leak).
        let cracked = VacuumTankParams {
            base_leak_area_mm2: 0.5,
            ..sim.tank_params
        };
        let p_now = sim.plant.tank.p_tank_kpa() as f64;
        sim.plant.tank = VacuumTank::new(&cracked, p_now).unwrap();
        let out = sim.run(x_set, 13.5, 6.5);
        assert!(out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
        assert!(out.residual_kpa_per_s > 0.5);
        assert_eq!(out.duty, [0.0; 3]);
        assert!(!out.pump_on);
        // Spring position: all actuators back at 0 %.
        sim.run(x_set, 13.5, 2.0);
        assert!(
            sim.plant.lpt.x_pct() < 0.5 && sim.plant.hpt.x_pct() < 0.5,
            "{} {}",
            sim.plant.lpt.x_pct(),
            sim.plant.hpt.x_pct()
        );
    }

    #[test]
    fn failed_pump_is_flagged_as_a_leak() {
        let mut sim = Sim::new(frictionless(), 100.0);
        sim.pump_broken = true;
        let out = sim.run([40.0, 30.0, 20.0], 13.5, 6.5);
        assert!(out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
        assert!(!out.pump_on && out.duty == [0.0; 3]);
    }

    #[test]
    fn stuck_actuator_is_flagged_after_the_time_limit() {
        let mut sim = Sim::new(frictionless(), 40.0);
        sim.run([40.0, 30.0, 20.0], 13.5, 2.0);
        sim.x_override[1] = Some(30.0);
        // Setpoint moves; the HPT reading stays at 30 %.
        let out = sim.run([40.0, 80.0, 20.0], 13.5, 0.8);
        assert_eq!(out.stuck, [false; 3], "not before 1 s");
        let out = sim.run([40.0, 80.0, 20.0], 13.5, 1.0);
        assert_eq!(out.stuck, [false, true, false]);
        assert_eq!(out.duty, [0.0; 3]);
    }

    #[test]
    fn supervisor_safe_state_is_applied() {
        let mut sim = Sim::new(frictionless(), 90.0);
        sim.safe = SafeState {
            vacuum_spring_open: true,
            pump_off: true,
            ..Default::default()
        };
        let out = sim.run([40.0, 30.0, 20.0], 13.5, 1.0);
        assert_eq!(out.duty, [0.0; 3]);
        assert!(!out.pump_on);
        // Pump off only (battery low): duties still follow the setpoints.
        sim.safe = SafeState {
            pump_off: true,
            ..Default::default()
        };
        let out = sim.run([40.0, 30.0, 20.0], 13.5, 0.1);
        assert!(out.duty[0] > 0.0 && !out.pump_on);
    }

    fn x_now(sim: &Sim) -> [f32; 3] {
        [sim.plant.lpt.x_pct(), sim.plant.hpt.x_pct(), sim.plant.hpc.x_pct()]
    }

    /// Holds `x_set` for `s` seconds one 80 Hz period at a time; per valve the time after the
    /// hold's start from which |x − setpoint| stays within `band_pct` (None: not settled by
    /// the end), and the largest overshoot beyond the setpoint in the step's direction.
    fn hold(sim: &mut Sim, x_set: [f32; 3], band_pct: f32, s: f32) -> ([Option<f32>; 3], [f32; 3]) {
        let x0 = x_now(sim);
        let steps = (s * 1e6 / DT_US as f32) as u32;
        let mut last_out = [Some(0.0f32); 3];
        let mut overshoot = [0.0f32; 3];
        for n in 1..=steps {
            sim.run(x_set, 13.5, DT_US as f32 * 1e-6);
            let x = x_now(sim);
            for k in 0..3 {
                if (x[k] - x_set[k]).abs() > band_pct {
                    last_out[k] = Some(n as f32 * DT_US as f32 * 1e-6);
                }
                let dir = if x_set[k] >= x0[k] { 1.0 } else { -1.0 };
                overshoot[k] = overshoot[k].max(dir * (x[k] - x_set[k]));
            }
        }
        let end = x_now(sim);
        let settled = [0, 1, 2].map(|k| {
            if (end[k] - x_set[k]).abs() <= band_pct {
                last_out[k]
            } else {
                None
            }
        });
        (settled, overshoot)
    }

    /// The run's wastegate profile 20 → 60 → 40 % (with moves of the bypasses), 4 s holds.
    const PROFILE: [[f32; 3]; 3] = [[20.0, 20.0, 30.0], [60.0, 45.0, 50.0], [40.0, 30.0, 40.0]];

    #[test]
    fn with_rod_friction_the_closed_loop_settles_within_1_pct_where_feedforward_alone_does_not() {
        // The paper's actuators with their Dahl/Coulomb friction (Figs. 9-10; Fc 1.5/4/5 kPa).
        let mut closed = Sim::new(VacuumTaskConfig::default().actuators, 40.0);
        let ff_cfg = VacuumTaskConfig {
            kp_loop_gain: 0.0,
            ki_kpa_per_pct_s: 0.0,
            friction_compensation: 0.0,
            ..Default::default()
        };
        let mut open = Sim::with_config(ff_cfg, 40.0);
        let mut ff_misses = 0;
        for x_set in PROFILE {
            let (settled, overshoot) = hold(&mut closed, x_set, 1.0, 4.0);
            let (ff_settled, _) = hold(&mut open, x_set, 1.0, 4.0);
            extern crate std;
            std::println!("{x_set:?}: closed loop into ±1 % after {settled:?} s (overshoot {overshoot:?} %), x {:?}; feedforward only {ff_settled:?}, x {:?}", x_now(&closed), x_now(&open));
            for k in 0..3 {
                // Bound: into ±1 % within 1 s of the step and held to the end of the 4 s hold;
                // overshoot below 2 % on the wastegate, 3 % on the bypasses (their friction,
                // 4-5 kPa, is 10-30 % of stroke on the HPT's steep part; the feedforward of
                // friction and clearance and the slope-scaled gain keep it small: measured
                // 0.6 / 0.66 / 0.19 s, 1.7 / 1.6 / 0.6 %; with a fixed 0.3 kPa/% gain the HPT's
                // steeper map overshot 9 %).
                assert!(
                    settled[k].is_some_and(|t| t <= 1.0),
                    "{x_set:?} valve {k}: {settled:?}, x {:?}",
                    x_now(&closed)
                );
                assert!(
                    overshoot[k] < [2.0, 3.0, 3.0][k],
                    "{x_set:?} valve {k}: overshoot {} %",
                    overshoot[k]
                );
            }
            // Feedforward alone leaves the friction offset: (Fc on the rod)·slope, 1.5 kPa ≈ 3 %
            // on the wastegate.
            ff_misses += settled_count_missing(&ff_settled);
        }
        assert!(
            ff_misses >= 3,
            "feedforward alone settled into ±1 % in all but {ff_misses} holds"
        );
        let integrals = [0, 1, 2].map(|k| closed.task.integral_kpa(k));
        assert!(
            integrals.iter().any(|i| i.abs() > 0.5),
            "no friction offset learnt: {integrals:?}"
        );
        assert_eq!(open.task.integral_kpa(0), 0.0);
    }

    fn settled_count_missing(s: &[Option<f32>; 3]) -> u32 {
        s.iter().map(|t| u32::from(t.is_none())).sum()
    }

    #[test]
    fn no_windup_after_a_safe_state_or_a_stuck_reading() {
        let actuators = VacuumTaskConfig::default().actuators;
        let limit = [0, 1, 2].map(|k| 2.0 * actuators[k].fc_kpa as f32 + 5.0);
        let mut sim = Sim::new(actuators, 40.0);
        hold(&mut sim, [40.0, 30.0, 40.0], 1.0, 4.0);
        // Spring-open safe state for 2 s (e.g. a battery-low phase) while the setpoints ask
        // for more: the valves vent, the rods fall to the spring and the integrators stay
        // cleared, so nothing is stored for the recovery.
        sim.safe = SafeState {
            vacuum_spring_open: true,
            ..Default::default()
        };
        let x_set = [60.0, 45.0, 50.0];
        let out = sim.run(x_set, 13.5, 2.0);
        assert_eq!(out.duty, [0.0; 3]);
        assert_eq!(out.mode, [VacuumPositionMode::Off; 3]);
        assert_eq!([0, 1, 2].map(|k| sim.task.integral_kpa(k)), [0.0; 3]);
        assert!(x_now(&sim)[0] < 1.0, "wastegate {} % in the safe state", x_now(&sim)[0]);
        sim.safe = SafeState::default();
        let (settled, overshoot) = hold(&mut sim, x_set, 1.0, 4.0);
        extern crate std;
        std::println!("after the safe state: into ±1 % after {settled:?} s, overshoot {overshoot:?} %");
        for k in 0..3 {
            assert!(
                settled[k].is_some_and(|t| t <= 2.5) && overshoot[k] < 3.0,
                "valve {k}: {settled:?} {overshoot:?}"
            );
        }

        // The wastegate's reading freezes for 0.8 s (a binding rod or sensor, not yet the 1 s
        // stuck flag) while its setpoint steps up: the integrator sees a constant error but is
        // held by its limit (2·Fc + 5 kPa) and its zone; once the reading moves again the loop
        // is back within ±1 % without a long excursion.
        let x_frozen = x_now(&sim)[0];
        sim.x_override[0] = Some(x_frozen);
        let mut worst_integral = 0.0f32;
        for _ in 0..64 {
            let out = sim.run([70.0, 45.0, 50.0], 13.5, DT_US as f32 * 1e-6);
            assert_eq!(out.stuck, [false; 3]);
            worst_integral = worst_integral.max(sim.task.integral_kpa(0).abs());
        }
        assert!(
            worst_integral <= limit[0] + 1e-4,
            "integral {worst_integral} kPa beyond the limit {}",
            limit[0]
        );
        sim.x_override[0] = None;
        let (settled, overshoot) = hold(&mut sim, [70.0, 45.0, 50.0], 1.0, 4.0);
        std::println!("after the frozen reading: integral at most {worst_integral:.2} kPa, into ±1 % after {settled:?} s, overshoot {overshoot:?} %");
        assert!(settled[0].is_some_and(|t| t <= 3.0), "{settled:?}, x {:?}", x_now(&sim));

        // Flagged stuck: every valve disabled, integrators cleared.
        sim.x_override[0] = Some(x_now(&sim)[0]);
        let out = sim.run([20.0, 45.0, 50.0], 13.5, 1.2);
        assert!(out.stuck[0]);
        assert_eq!((out.duty, out.mode), ([0.0; 3], [VacuumPositionMode::Off; 3]));
        assert_eq!([0, 1, 2].map(|k| sim.task.integral_kpa(k)), [0.0; 3]);
    }

    #[test]
    fn implausible_position_reading_falls_back_to_feedforward_then_the_spring() {
        for bad_reading in [f32::NAN, 150.0, -20.0] {
            let mut sim = Sim::new(VacuumTaskConfig::default().actuators, 40.0);
            let x_set = [50.0, 30.0, 40.0];
            hold(&mut sim, x_set, 1.0, 4.0);
            // The wastegate's reading goes bad: that valve alone runs on its feedforward
            // (inverse model + eq. (15)), integrator cleared; the others stay in control.
            sim.x_override[0] = Some(bad_reading);
            let out = sim.run(x_set, 12.5, 0.5);
            let (_, ff_duty, _) = sim.task.feedforward(0, 50.0, 100.0, 12.5);
            assert_eq!(
                out.mode[0],
                VacuumPositionMode::OpenLoop(VacuumPositionFault::PositionSensor),
                "{bad_reading}"
            );
            assert_eq!(out.mode[1..], [VacuumPositionMode::Control; 2]);
            assert!(
                (out.duty[0] * 100.0 - ff_duty).abs() < 1e-5,
                "{bad_reading}: duty {} vs feedforward {ff_duty}",
                out.duty[0] * 100.0
            );
            assert_eq!(sim.task.integral_kpa(0), 0.0);
            // Open loop the wastegate stays within its friction band of the setpoint.
            let x = x_now(&sim)[0];
            assert!((x - 50.0).abs() < 5.0, "{bad_reading}: wastegate at {x} % open loop");
            // The supervisor's debounced position-sensor fault asks for the spring position.
            sim.safe = crate::ecu::supervisor::Fault::VacuumPositionSensor.reaction();
            let out = sim.run(x_set, 12.5, 1.0);
            assert_eq!((out.duty, out.mode), ([0.0; 3], [VacuumPositionMode::Off; 3]));
            assert!(x_now(&sim)[0] < 1.0);
        }
    }

    #[test]
    fn supply_below_the_compensator_range_freezes_the_integrators() {
        let mut sim = Sim::new(VacuumTaskConfig::default().actuators, 40.0);
        let x_set = [50.0, 30.0, 40.0];
        hold(&mut sim, x_set, 1.0, 4.0);
        let before = [0, 1, 2].map(|k| sim.task.integral_kpa(k));
        // 5 V: below comp_u_min_v = 6 V; the valves cannot hold the rods, the errors are large.
        let out = sim.run(x_set, 5.0, 1.0);
        assert!(out.supply_low);
        assert_eq!(
            out.mode,
            [VacuumPositionMode::OpenLoop(VacuumPositionFault::SupplyLow); 3]
        );
        assert_eq!(
            [0, 1, 2].map(|k| sim.task.integral_kpa(k)),
            before,
            "integrators moved below the range"
        );
        let x = x_now(&sim);
        assert!(
            (0..3).any(|k| (x[k] - x_set[k]).abs() > 1.0),
            "the sag did not move anything: {x:?}"
        );
        // Back in range the learnt offsets are still there and the loop settles again.
        let (settled, _) = hold(&mut sim, x_set, 1.0, 4.0);
        assert!(settled.iter().all(|t| t.is_some_and(|t| t <= 3.0)), "{settled:?}");
    }
}
