//! Vacuum task logic (Thomasson 2013), run at 80 Hz for the three 300 Hz PWM valves (LPT
//! wastegate, HPT bypass, HPC bypass):
//! - duty from the inverse actuator model (Sec. 5.2/5.4): position setpoint → chamber
//!   pressure (inverse of eq. (8)/(9)) → corrected duty (inverse of eq. (2)/(5)) → supply
//!   voltage compensation (eq. (15), [`crate::pwm_comp`]) with the measured battery voltage;
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
use crate::pwm_comp::{PwmCompError, PwmCompensator};
use crate::vacuum::{
    VacuumInputs, VacuumParamError, VacuumParams, VacuumStaticModel, VacuumTank, VacuumTankParams, VacuumValveActuator,
};

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
}

impl Default for VacuumTaskConfig {
    /// The paper's actuators and tank; reserve 70 kPa (the Sec. 5.3 example: "70 kPa would be
    /// enough"), margin 10 kPa, hysteresis 5 kPa, leak above 0.5 kPa/s (the base leak is
    /// ~0.1 kPa/s, a broken hose several kPa/s) in two 2 s windows, stuck above 15 % for 1 s.
    fn default() -> Self {
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
        }
    }
}

/// Why the task could not be built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VacuumTaskError {
    Model(VacuumParamError),
    Compensator(PwmCompError),
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
}

/// The vacuum task state machine.
#[derive(Clone, Debug)]
pub struct VacuumTask {
    cfg: VacuumTaskConfig,
    statics: [VacuumStaticModel<f32>; 3],
    comp: PwmCompensator<f32>,
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
        let statics = [VacuumStaticModel::new(a).map_err(m)?, VacuumStaticModel::new(b).map_err(m)?, VacuumStaticModel::new(c).map_err(m)?];
        let observer = [VacuumValveActuator::new(a).map_err(m)?, VacuumValveActuator::new(b).map_err(m)?, VacuumValveActuator::new(c).map_err(m)?];
        // One compensator: the three valves are the same type with one U_ref (Sec. 2.2).
        if cfg.actuators.iter().any(|p| p.u_ref_v != a.u_ref_v) {
            return Err(VacuumTaskError::Parameter("actuators.u_ref_v"));
        }
        let comp = PwmCompensator::new(a.u_ref_v, cfg.comp_u_min_v, 0.0, 100.0).map_err(VacuumTaskError::Compensator)?;
        let tank_model = VacuumTank::new(&cfg.tank, 100.0).map_err(m)?;
        if !(cfg.leak_window_s > 0.05 && cfg.leak_window_s < 60.0) {
            return Err(VacuumTaskError::Parameter("leak_window_s"));
        }
        if !(cfg.pump_hysteresis_kpa >= 0.0 && cfg.tank_target_min_kpa >= 1.0 && cfg.tank_reserve_kpa > cfg.tank_target_min_kpa) {
            return Err(VacuumTaskError::Parameter("tank pressure targets"));
        }
        Ok(Self {
            cfg,
            statics,
            comp,
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

    /// Chamber pressure that holds `x_set_pct` (no friction), and the compensated duty (%)
    /// that gives it at `u_batt_v`; 0 % at the rest position.
    pub fn feedforward(&self, i: usize, x_set_pct: f32, p_amb_kpa: f32, u_batt_v: f32) -> (Option<f32>, f32, bool) {
        let Some(model) = self.statics.get(i) else { return (None, 0.0, false) };
        if !(x_set_pct > self.cfg.x_rest_pct) {
            return (None, 0.0, false);
        }
        let p_need = model.pressure_for_position_kpa(x_set_pct, p_amb_kpa);
        let u_corr = model.duty_for_pressure_pct(p_need, p_amb_kpa).clamp(0.0, 100.0);
        let c = self.comp.apply(u_corr, u_batt_v);
        (Some(p_need), c.duty_pct, c.supply_low)
    }

    /// One step at `now_us` (nominally every 12.5 ms).
    pub fn step(&mut self, inp: &VacuumTaskInputs, now_us: u32) -> VacuumTaskOutputs {
        let dt_s = self.last_step_us.map_or(0.0, |t| elapsed_us(now_us, t) as f32 * 1e-6).min(1.0);
        self.last_step_us = Some(now_us);
        let p_amb = inp.p_amb_kpa;
        let p_tank = inp.p_tank_kpa;

        // Observer over the last period with the duties and pump state then applied.
        let mut inflow_mg_s = 0.0;
        for (k, obs) in self.observer.iter_mut().enumerate() {
            let duty_pct = self.last_duty_pct.get(k).copied().unwrap_or(0.0);
            let o = obs.step(&VacuumInputs { duty_pct, u_batt_v: inp.u_batt_v, p_amb_kpa: p_amb, p_tank_kpa: p_tank }, dt_s);
            inflow_mg_s += o.flow_to_tank_mg_s;
        }
        self.tank_model.step(self.pump_on, inflow_mg_s, p_amb, dt_s);
        self.update_residual(p_tank, now_us);
        self.update_stuck(inp, now_us);

        // Feedforward duties and the tank pressure they need.
        let mut duty_pct = [0.0f32; 3];
        let mut p_need_min = f32::INFINITY;
        let mut supply_low = false;
        for (k, d) in duty_pct.iter_mut().enumerate() {
            let x = inp.x_set_pct.get(k).copied().unwrap_or(0.0);
            let (p_need, duty, low) = self.feedforward(k, x, p_amb, inp.u_batt_v);
            *d = duty;
            supply_low |= low;
            if let Some(p) = p_need {
                p_need_min = p_need_min.min(p);
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

        let vacuum_safe = inp.safe.vacuum_spring_open || self.abnormal_leak || self.stuck.iter().any(|s| *s);
        if vacuum_safe {
            duty_pct = [0.0; 3];
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
            let (Some(obs), Some(&x_meas), Some(since), Some(stuck)) =
                (self.observer.get(k), inp.x_meas_pct.get(k), self.stuck_since_us.get_mut(k), self.stuck.get_mut(k))
            else {
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
        let e = VacuumEffects { supply_voltage: true, ..VacuumEffects::NONE };
        [VacuumParams::lpt().with_effects(e), VacuumParams::hpt().with_effects(e), VacuumParams::hpc().with_effects(e)]
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
            let cfg = VacuumTaskConfig { actuators: params, ..Default::default() };
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
                let r = self.plant.step(duties, u_batt, 100.0, o.pump_on && !self.pump_broken, DT_US as f32 * 1e-6);
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
                assert!((x[k] - x_set[k]).abs() < 1.0, "{u} V actuator {k}: {} vs {}", x[k], x_set[k]);
            }
        }
        // Without compensation (duty fixed at its 12 V value) the HPT at 14.5 V misses by far.
        let task = VacuumTask::new(VacuumTaskConfig { actuators: frictionless(), ..Default::default() }).unwrap();
        let (_, duty_12v, _) = task.feedforward(1, 30.0, 100.0, 12.0);
        let (_, duty_14v, _) = task.feedforward(1, 30.0, 100.0, 14.5);
        assert!((duty_14v / duty_12v - 12.0 / 14.5).abs() < 1e-4);
        let mut plant = VacuumSystem::<f32>::new(&frictionless()[0], &frictionless()[1], &frictionless()[2], &VacuumTankParams::paper(), 25.0).unwrap();
        for _ in 0..240 {
            plant.step([0.0, duty_12v, 0.0], 14.5, 100.0, true, 0.0125);
        }
        assert!((plant.hpt.x_pct() - 30.0).abs() > 10.0, "uncompensated HPT at {}", plant.hpt.x_pct());
    }

    #[test]
    fn pump_runs_on_the_needed_pressure_and_less_than_a_fixed_35_kpa_rule() {
        // Setpoints that need about 74 kPa in the chambers: target 64 kPa.
        let x_set = [30.0, 30.0, 0.0];
        let mut sim = Sim::new(frictionless(), 100.0);
        let out = sim.run(x_set, 13.5, 60.0);
        assert!((out.p_tank_target_kpa - 64.4).abs() < 0.5, "target {}", out.p_tank_target_kpa);
        let p = sim.plant.tank.p_tank_kpa();
        assert!(p < 65.0 && p > 55.0, "tank {p}");
        assert!((sim.plant.lpt.x_pct() - 30.0).abs() < 1.0 && (sim.plant.hpt.x_pct() - 30.0).abs() < 1.0);
        let on_needed = sim.pump_on_steps;
        // The fixed rule (always below 35 kPa, 5 kPa hysteresis) on the same plant and setpoints.
        let mut plant = VacuumSystem::<f32>::new(&frictionless()[0], &frictionless()[1], &frictionless()[2], &sim.tank_params, 100.0).unwrap();
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
        for x_set in [[20.0, 40.0, 60.0], [80.0, 10.0, 30.0], [0.0, 60.0, 90.0], [50.0, 50.0, 50.0]] {
            let out = sim.run(x_set, 13.5, 10.0);
            assert!(!out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
            assert!(out.residual_kpa_per_s.abs() < 0.2, "residual {}", out.residual_kpa_per_s);
            assert_eq!(out.stuck, [false; 3]);
        }
    }

    #[test]
    fn broken_hose_is_flagged_and_the_wastegate_goes_to_its_spring() {
        let mut sim = Sim::new(frictionless(), 60.0);
        let x_set = [40.0, 30.0, 20.0];
        assert!(!sim.run(x_set, 13.5, 10.0).abnormal_leak);
        // A hose cracks: 0.5 mm² from ambient into the tank (25 times the base leak).
        let cracked = VacuumTankParams { base_leak_area_mm2: 0.5, ..sim.tank_params };
        let p_now = sim.plant.tank.p_tank_kpa() as f64;
        sim.plant.tank = VacuumTank::new(&cracked, p_now).unwrap();
        let out = sim.run(x_set, 13.5, 6.5);
        assert!(out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
        assert!(out.residual_kpa_per_s > 0.5);
        assert_eq!(out.duty, [0.0; 3]);
        assert!(!out.pump_on);
        // Spring position: all actuators back at 0 %.
        sim.run(x_set, 13.5, 2.0);
        assert!(sim.plant.lpt.x_pct() < 0.5 && sim.plant.hpt.x_pct() < 0.5, "{} {}", sim.plant.lpt.x_pct(), sim.plant.hpt.x_pct());
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
        sim.safe = SafeState { vacuum_spring_open: true, pump_off: true, ..Default::default() };
        let out = sim.run([40.0, 30.0, 20.0], 13.5, 1.0);
        assert_eq!(out.duty, [0.0; 3]);
        assert!(!out.pump_on);
        // Pump off only (battery low): duties still follow the setpoints.
        sim.safe = SafeState { pump_off: true, ..Default::default() };
        let out = sim.run([40.0, 30.0, 20.0], 13.5, 0.1);
        assert!(out.duty[0] > 0.0 && !out.pump_on);
    }
}
