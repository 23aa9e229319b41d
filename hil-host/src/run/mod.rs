//! `hil-host run`: the ECU's control code against the plant models, natively on the host, in
//! lockstep through frames.
//!
//! Each 50 µs step ([`STEP_US`]) the plant side builds a [`SensorFrame`] (crank and cam edges,
//! ADC counts of every channel, the setpoints of the engine management), an [`EcuLink`]
//! answers the [`ActuatorFrame`], and the plant side applies it over the next step. The native
//! link ([`NativeLink`]) calls model-core's [`EcuCore`] (supervisor + EHVVA + EVVT + vacuum
//! tasks, the firmware's own code and schedule); the emulated-board route implements
//! [`EcuLink`] over the UART and calls the same [`run_with`], so two runs of one scenario can
//! be compared step by step.
//!
//! The plant side (everything from model-core, nothing re-implemented here):
//! - engine: crank angle integrated from the speed profile → 60-2 crank tooth edges (first
//!   tooth after the gap at cycle angle 0, [`TriggerWheel::sixty_minus_two`]) and the cam sync
//!   edge at cycle angle `cam_edge_parked_deg − phase` (the EVVT plant's phase, as
//!   [`model_core::ecu::evvt_task::EvvtTask::phase_from_edge_deg`] reads it back);
//! - EHVVA: the pilot coil ([`RlCoil`]) under the commanded peak-and-hold voltage, the pilot
//!   valve held while its current stays above the drop-out current, the reduced nonlinear
//!   model of eq. (12) at 10 µs with the commanded lift valve and snubber switch states;
//! - EVVT: the motor speed command output (duty × full scale) minus the ring-gear speed is
//!   the plant's command (eq. (11)); the LPV plant steps at 0.5 ms;
//! - vacuum: the three actuators, the tank and the pump ([`VacuumSystem`]) at 0.5 ms.
//!
//! Faults (`[[fault]]` in the scenario) act on the plant side only: the ECU sees what a real
//! one would see (a sensor reading 0 or 4095 counts, no crank teeth, a position that stops
//! following, a tank that does not get pumped, the driver's fault pin).

use std::path::Path;

use model_core::ecu::board::SolenoidCmd;
use model_core::ecu::calibration::CALIBRATION_FAULT_BIT;
use model_core::ecu::crank_sim::CrankSignal;
use model_core::ecu::ehvva_task::{TriggerWheel, ValveRequest, CYCLE_DEG};
use model_core::ecu::evvt_task::EvvtTaskConfig;
use model_core::ecu::frame::{ActuatorFrame, SensorFrame, MAX_EDGES};
use model_core::ecu::lockstep::{EcuCore, EcuCoreConfig, STEP_US};
use model_core::ecu::supervisor::{Channel, Fault, FaultSet, SupervisorConfig, N_CHANNELS};
use model_core::ehvva::{EhvvaInputs, EhvvaParams, EhvvaPlant, EhvvaReduced};
use model_core::evvt::{EvvtParams, EvvtPlant, PlanetaryGear};
use model_core::peak_hold::{RlCoil, SolenoidParams};
use model_core::vacuum::{VacuumParams, VacuumSystem, VacuumTankParams};

use crate::log::format_log;

mod output;
mod scenario;
mod summary;
pub use output::write_outputs;
pub use scenario::*;
pub use summary::*;

/// The ECU side of the lockstep: one sensor frame in, one actuator frame out.
pub trait EcuLink {
    fn exchange(&mut self, sensors: &SensorFrame) -> Result<ActuatorFrame, String>;
}

/// The ECU's control code called directly on the host.
pub struct NativeLink {
    core: EcuCore,
}

impl NativeLink {
    /// The firmware's calibration.
    pub fn new() -> Result<Self, String> {
        Self::with_config(EcuCoreConfig::default())
    }
    pub fn with_config(cfg: EcuCoreConfig) -> Result<Self, String> {
        Ok(Self {
            core: EcuCore::new(cfg).map_err(|e| format!("ECU calibration: {e}"))?,
        })
    }
    /// The ECU's internals after the last step (measurements, engine snapshot, task outputs).
    pub fn core(&self) -> &EcuCore {
        &self.core
    }
}

impl EcuLink for NativeLink {
    fn exchange(&mut self, sensors: &SensorFrame) -> Result<ActuatorFrame, String> {
        Ok(self.core.step(sensors))
    }
}

/// The unit the plant side simulates: the paper's plants by default, or a unit `hil-host
/// generate` described (`--unit truth.json`, [`crate::calibrate::unit_from_truth`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unit {
    pub ehvva: EhvvaParams,
    /// The cam phaser.
    pub evvt: EvvtParams,
    /// LPT, HPT, HPC.
    pub vacuum: [VacuumParams; 3],
}

impl Default for Unit {
    fn default() -> Self {
        Self {
            ehvva: EhvvaParams::paper_default(),
            evvt: EvvtParams::default(),
            vacuum: [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()],
        }
    }
}

/// What [`run_with`] runs and keeps.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunOptions {
    /// Stop after this much simulated time (capped at the scenario's duration).
    pub until_s: Option<f64>,
    /// Keep every step's sensor and actuator frames in [`RunOutput::frames`] (50 µs steps:
    /// about 3 MB per simulated second).
    pub keep_frames: bool,
}

/// Everything a run produced.
#[derive(Clone, Debug, Default)]
pub struct RunOutput {
    pub summary: Summary,
    pub evvt: Vec<EvvtRow>,
    pub vacuum: Vec<VacuumRow>,
    pub ehvva: Vec<EhvvaRow>,
    /// Every step's frames, when [`RunOptions::keep_frames`].
    pub frames: Vec<(SensorFrame, ActuatorFrame)>,
}

const STEP_S: f64 = STEP_US as f64 * 1e-6;
/// Longest scenario: its logs (about 2 MB per simulated second) stay in memory.
pub const MAX_DURATION_S: f64 = 120.0;
/// The EHVVA model's step: 5 per lockstep step.
const EHVVA_DT_MS: f64 = 0.01;
const EHVVA_SUBSTEPS: usize = 5;
/// The EVVT and vacuum plants step every 10 lockstep steps (0.5 ms); both ECU periods
/// (10 ms, 12.5 ms) are whole multiples.
const SLOW_EVERY: u64 = 10;
const EVVT_LOG_EVERY: u64 = 200;
const VACUUM_LOG_EVERY: u64 = 50;
/// The battery sag's ramps.
const SAG_RAMP_S: f64 = 0.1;
/// The pilot valve drops out below this coil current: 70 % of the 1 A hold current, the
/// usual margin of a hold current over the drop-out current. An uncompensated hold duty at
/// 8 V (the 14 V duty gives 0.57 A) would drop the valve; the pull-in itself is inside the
/// measured actuation delay td of the valve model.
const PILOT_DROPOUT_A: f64 = 0.7;
/// Valve timing is measured where the lift passes 1 % of the stroke (opening) and 99 %
/// (closing), the paper's thresholds, once per pilot command: the opening after its rising
/// edge, the closing after its falling edge. A valve below 99 % at the falling edge (it never
/// reached its stop, or fell back from it while the pilot was on: a unit near force balance,
/// the supply dipping) has no closing time at that threshold; such cycles are counted apart
/// (`stop_not_held_events`), not scored as a timing error against another cycle's edge.
const LIFT_FRACTION: f64 = 0.01;

/// Runs `scenario` against `link` and returns the logs and the summary (nothing is written).
pub fn run_with(scenario: &Scenario, link: &mut dyn EcuLink, opts: &RunOptions) -> Result<RunOutput, String> {
    run_with_unit(scenario, link, opts, &Unit::default())
}

/// [`run_with`] against `unit`'s plants instead of the paper's.
pub fn run_with_unit(
    scenario: &Scenario,
    link: &mut dyn EcuLink,
    opts: &RunOptions,
    unit: &Unit,
) -> Result<RunOutput, String> {
    let sc = scenario;
    let started = std::time::Instant::now();
    let err = |what: &str, e: &dyn std::fmt::Debug| format!("{what}: {e:?}");
    let until_s = opts.until_s.map_or(sc.duration_s, |u| u.min(sc.duration_s));
    if until_s <= 0.0 || until_s.is_nan() {
        return Err(format!("run length {until_s} s: nothing to run"));
    }
    let n_steps = (until_s / STEP_S).round() as u64;

    let board = SupervisorConfig::default();
    let evvt_cfg = EvvtTaskConfig::default();
    let ehvva_params = unit.ehvva;
    let solenoid = SolenoidParams::pilot_default();

    // Plants.
    let ehvva_inputs = |t: f64, lift_high: bool, snubber_on: bool| EhvvaInputs::<f32> {
        p_supply_mpa: sc.p_supply_mpa.at(t) as f32,
        p_back_mpa: sc.p_back_mpa.at(t) as f32,
        temp_c: sc.temp_c.at(t) as f32,
        lift_high,
        snubber_on,
    };
    let mut valve = EhvvaReduced::<f32>::new(
        &ehvva_params,
        &ehvva_inputs(0.0, sc.lift_high.at(0.0), sc.snubber_on.at(0.0)),
        EHVVA_DT_MS,
    )
    .map_err(|e| err("EHVVA plant", &e))?;
    let mut coil = RlCoil::<f64>::new(&solenoid);
    let (mut pilot_armed, mut pilot_dropped) = (false, false);
    let mut evvt = EvvtPlant::<f32>::new(&unit.evvt).map_err(|e| err("EVVT plant", &e))?;
    evvt.reset(sc.cam_phase_setpoint_deg.at(0.0) as f32);
    let [lpt, hpt, hpc] = &unit.vacuum;
    let mut vacuum = VacuumSystem::<f32>::new(lpt, hpt, hpc, &VacuumTankParams::paper(), sc.p_tank_initial_kpa)
        .map_err(|e| err("vacuum plant", &e))?;
    let mut stuck_x: [Option<f32>; 3] = [None; 3];
    let mut engine = CrankSignal::new(TriggerWheel::sixty_minus_two(), 5.0);

    let mut out = RunOutput {
        summary: Summary {
            faults_injected: sc.faults.iter().map(describe_fault).collect(),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut faults_before = FaultSet::default();
    let (mut open_err, mut close_err) = (Vec::new(), Vec::new());
    let (mut opened, mut prev_lift, mut worst_seat) = (false, 0.0f64, None::<f64>);
    // The pilot command of the step before, and whether this cycle's closing is being timed.
    let (mut prev_pilot, mut closing, mut stop_not_held) = (false, false, 0usize);
    let (mut evvt_se, mut evvt_n, mut wg_n, mut pump_steps) = (0.0, 0usize, 0usize, 0u64);
    let mut x_se = [0.0f64; 3];

    for k in 0..n_steps {
        // Time from whole microseconds: fault and profile breakpoints at round times fall on
        // exact steps.
        let t = (k * u64::from(STEP_US)) as f64 / 1e6;
        let t_us = (k as u32).wrapping_mul(STEP_US);
        let rpm = sc.engine_rpm.at(t).max(0.0);
        let u_batt = sc.u_batt_at(t);
        let p_amb = sc.p_amb_kpa.at(t);

        // Sensor side: the edges of the step just ended, the ADC counts now.
        let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
        let mut n_edges = 0;
        if k > 0 {
            let t_prev = ((k - 1) * u64::from(STEP_US)) as f64 / 1e6;
            let cam_deg = f64::from(evvt_cfg.cam_edge_parked_deg) - f64::from(evvt.phase_deg());
            let crank_ok = !sc.fault_active(FaultKind::CrankLost, t_prev);
            n_edges = engine.advance(
                sc.engine_rpm.at(t_prev).max(0.0),
                STEP_US,
                cam_deg,
                crank_ok,
                true,
                t_us.wrapping_sub(STEP_US),
                &mut edges,
            );
        }
        if n_edges > MAX_EDGES {
            return Err(format!("t = {t:.5} s: {n_edges} edges in one {STEP_US} µs step (engine speed {rpm:.0} rpm too high for the frame)"));
        }
        let x_meas = [0, 1, 2].map(|i| stuck_x[i].unwrap_or_else(|| actuator(&vacuum, i).x_pct()));
        let mut values = [0.0f32; N_CHANNELS];
        for ch in Channel::ALL {
            values[ch as usize] = match ch {
                Channel::BatteryV => u_batt as f32,
                Channel::SupplyPressureMpa => valve.p_high_mpa(),
                Channel::BackPressureMpa => valve.p_low_mpa(),
                Channel::OilTempC => sc.temp_c.at(t) as f32,
                Channel::TankPressureKpa => vacuum.tank.p_tank_kpa(),
                Channel::AmbientPressureKpa => p_amb as f32,
                Channel::LptPositionPct => x_meas[0],
                Channel::HptPositionPct => x_meas[1],
                Channel::HpcPositionPct => x_meas[2],
                Channel::EcuTempC => sc.temp_ecu_c.at(t) as f32,
            };
        }
        let mut adc_counts: [u16; N_CHANNELS] = core::array::from_fn(|i| board.scales[i].counts_for(values[i]));
        if sc.fault_active(FaultKind::SupplyPressureOpen, t) {
            adc_counts[Channel::SupplyPressureMpa as usize] = 0;
        }
        if sc.fault_active(FaultKind::SupplyPressureShort, t) {
            adc_counts[Channel::SupplyPressureMpa as usize] = 4095;
        }
        let x_set = [
            sc.wastegate_setpoint_pct.at(t),
            sc.hpt_bypass_setpoint_pct.at(t),
            sc.hpc_bypass_setpoint_pct.at(t),
        ];
        let frame = SensorFrame {
            seq: k as u32,
            t_us,
            n_edges: n_edges as u8,
            edges,
            adc_counts,
            valve: ValveRequest {
                open_deg: sc.valve_open_deg.at(t) as f32,
                close_deg: sc.valve_close_deg.at(t) as f32,
                high_lift: sc.lift_high.at(t),
                soft_seat: sc.snubber_on.at(t),
                enabled: true,
            },
            cam_phase_set_deg: sc.cam_phase_setpoint_deg.at(t) as f32,
            vacuum_x_set_pct: x_set.map(|x| x as f32),
            motor_driver_fault: sc.fault_active(FaultKind::MotorDriverFault, t),
        };

        // The ECU.
        let act = link
            .exchange(&frame)
            .map_err(|e| format!("step {k} (t = {t:.5} s): {e}"))?;
        if act.seq != frame.seq {
            return Err(format!(
                "step {k} (t = {t:.5} s): the actuator frame answers seq {} instead of {}",
                act.seq, frame.seq
            ));
        }
        let faults = FaultSet(act.faults);
        for f in Fault::ALL {
            if faults.contains(f) != faults_before.contains(f) {
                out.summary.fault_events.push(FaultEvent {
                    t_s: t,
                    fault: f,
                    raised: faults.contains(f),
                });
            }
        }
        faults_before = faults;
        out.summary.calibration_fault |= act.faults & CALIBRATION_FAULT_BIT != 0;
        if opts.keep_frames {
            out.frames.push((frame, act));
        }

        // Stuck rods: frozen from the fault's start.
        for (i, sx) in stuck_x.iter_mut().enumerate() {
            let stuck = sc.faults.iter().any(|f| {
                f.kind == FaultKind::VacuumStuck
                    && f.actuator.unwrap_or(VacuumActuator::Lpt).index() == i
                    && f.active(t)
            });
            *sx = match (stuck, *sx) {
                (true, Some(x)) => Some(x),
                (true, None) => Some(actuator(&vacuum, i).x_pct()),
                (false, _) => None,
            };
        }

        // Logs: the state now and the outputs that apply from now.
        let motor_speed_rpm = f64::from(act.motor_duty) * f64::from(evvt_cfg.motor_full_scale_rpm);
        let motor_cmd_rpm = motor_speed_rpm - PlanetaryGear::ring_speed_rpm(rpm);
        let phase_ref = sc.cam_phase_setpoint_deg.at(t);
        if k % EVVT_LOG_EVERY == 0 {
            let phase = f64::from(evvt.phase_deg());
            out.evvt.push(EvvtRow {
                t_s: t,
                motor_duty: f64::from(act.motor_duty),
                motor_cmd_rpm,
                engine_rpm: rpm,
                u_batt_v: u_batt,
                phase_ref_deg: phase_ref,
                phase_deg: phase,
            });
            evvt_se += (phase_ref - phase).powi(2);
            evvt_n += 1;
        }
        if k % VACUUM_LOG_EVERY == 0 {
            let x_pct = x_meas.map(f64::from);
            out.vacuum.push(VacuumRow {
                t_s: t,
                duty_pct: act.vacuum_duty.map(|d| f64::from(d) * 100.0),
                pump_on: act.pump_on,
                u_batt_v: u_batt,
                p_amb_kpa: p_amb,
                p_tank_kpa: f64::from(vacuum.tank.p_tank_kpa()),
                x_set_pct: x_set,
                x_pct,
                p_act_kpa: [0, 1, 2].map(|i| f64::from(actuator(&vacuum, i).p_act_kpa())),
            });
            for i in 0..3 {
                x_se[i] += (x_set[i] - x_pct[i]).powi(2);
            }
            wg_n += 1;
        }

        // Apply the outputs over the next step. Pilot coil: mean voltage of the PWM.
        let pilot_duty = match act.pilot {
            SolenoidCmd::Off => 0.0,
            SolenoidCmd::Full => 1.0,
            SolenoidCmd::Pwm(d) => f64::from(d).clamp(0.0, 1.0),
        };
        if pilot_duty == 0.0 {
            (pilot_armed, pilot_dropped) = (false, false);
        } else if coil.current_a >= PILOT_DROPOUT_A {
            pilot_armed = true;
        } else if pilot_armed {
            pilot_dropped = true;
        }
        let u_pilot = pilot_duty > 0.0 && !pilot_dropped;
        let stroke = ehvva_params.stroke_mm(act.lift_valve_on);
        if u_pilot && !prev_pilot {
            (opened, closing) = (false, false);
        } else if !u_pilot && prev_pilot && opened {
            if prev_lift > (1.0 - LIFT_FRACTION) * stroke {
                closing = true;
            } else {
                stop_not_held += 1;
            }
        }
        prev_pilot = u_pilot;
        out.ehvva.push(EhvvaRow {
            t_s: t,
            u_pilot,
            pilot_duty,
            coil_a: coil.current_a,
            p_supply_mpa: sc.p_supply_mpa.at(t),
            p_back_mpa: sc.p_back_mpa.at(t),
            temp_c: sc.temp_c.at(t),
            lift_high: act.lift_valve_on,
            snubber_on: act.snubber_on,
            lift_mm: f64::from(valve.lift_mm()),
            crank_deg: engine.cycle_deg(),
        });
        coil.step(pilot_duty * u_batt, f64::from(STEP_US));
        let inp = ehvva_inputs(t, act.lift_valve_on, act.snubber_on);
        let deg_per_substep = rpm * 6.0 * EHVVA_DT_MS * 1e-3;
        for j in 0..EHVVA_SUBSTEPS {
            let lift = f64::from(valve.step(u_pilot, &inp));
            let angle = (engine.cycle_deg() + (j + 1) as f64 * deg_per_substep).rem_euclid(f64::from(CYCLE_DEG));
            if !opened && prev_lift < LIFT_FRACTION * stroke && lift >= LIFT_FRACTION * stroke {
                opened = true;
                open_err.push(wrap_deg(angle - sc.valve_open_deg.at(t)));
            }
            if closing && prev_lift > (1.0 - LIFT_FRACTION) * stroke && lift <= (1.0 - LIFT_FRACTION) * stroke {
                closing = false;
                close_err.push(wrap_deg(angle - sc.valve_close_deg.at(t)));
            }
            if let Some(v) = valve.take_seat_velocity() {
                let v = f64::from(v).abs();
                worst_seat = Some(worst_seat.map_or(v, |w| w.max(v)));
            }
            prev_lift = lift;
        }
        if k % SLOW_EVERY == 0 {
            let dt = (SLOW_EVERY as f64 * STEP_S) as f32;
            evvt.step(motor_cmd_rpm as f32, rpm as f32, u_batt as f32, dt);
            let pump_works = !sc.fault_active(FaultKind::VacuumPumpFailure, t);
            vacuum.step(
                act.vacuum_duty.map(|d| d * 100.0),
                u_batt as f32,
                p_amb as f32,
                act.pump_on && pump_works,
                dt,
            );
            pump_steps += u64::from(act.pump_on);
        }
    }

    let stats = |v: &[f64]| -> (f64, f64) {
        if v.is_empty() {
            return (f64::NAN, f64::NAN);
        }
        (
            v.iter().sum::<f64>() / v.len() as f64,
            v.iter().fold(0.0f64, |a, x| a.max(x.abs())),
        )
    };
    let s = &mut out.summary;
    s.evvt_rms_error_deg = (evvt_se / evvt_n.max(1) as f64).sqrt();
    s.evvt_settling_s = settling_times(
        &out.evvt
            .iter()
            .map(|r| (r.t_s, r.phase_ref_deg, r.phase_deg))
            .collect::<Vec<_>>(),
        1.0,
    );
    s.vacuum_rms_error_pct_each = x_se.map(|se| (se / wg_n.max(1) as f64).sqrt());
    s.vacuum_rms_error_pct = s.vacuum_rms_error_pct_each[0];
    s.vacuum_position_error_pct_rms = (x_se.iter().sum::<f64>() / (3 * wg_n.max(1)) as f64).sqrt();
    let all: Vec<f64> = open_err.iter().chain(&close_err).copied().collect();
    s.ehvva_timing_error_deg_rms = if all.is_empty() {
        f64::NAN
    } else {
        (all.iter().map(|e| e * e).sum::<f64>() / all.len() as f64).sqrt()
    };
    s.vacuum_settling_s = settling_times(
        &out.vacuum
            .iter()
            .map(|r| (r.t_s, r.x_set_pct[0], r.x_pct[0]))
            .collect::<Vec<_>>(),
        2.0,
    );
    s.vacuum_pump_on_fraction = pump_steps as f64 / (n_steps / SLOW_EVERY).max(1) as f64;
    s.ehvva_events = open_err.len();
    s.ehvva_stop_not_held_events = stop_not_held;
    s.ehvva_closings = close_err.len();
    s.ehvva_open_error_deg = stats(&open_err);
    s.ehvva_close_error_deg = stats(&close_err);
    s.ehvva_seating_velocity_m_s = worst_seat;
    s.simulated_s = n_steps as f64 * STEP_S;
    s.wall_s = started.elapsed().as_secs_f64();
    Ok(out)
}

fn actuator(v: &VacuumSystem<f32>, i: usize) -> &model_core::vacuum::VacuumValveActuator<f32> {
    match i {
        0 => &v.lpt,
        1 => &v.hpt,
        _ => &v.hpc,
    }
}

fn describe_fault(f: &FaultSpec) -> String {
    let mut s = format!("{} from {:.3} s", f.kind.name(), f.start_s);
    if let Some(e) = f.end_s {
        s += &format!(" to {e:.3} s");
    }
    if let Some(u) = f.u_batt_v {
        s += &format!(" at {u} V");
    }
    if f.kind == FaultKind::VacuumStuck {
        s += &format!(" ({:?})", f.actuator.unwrap_or(VacuumActuator::Lpt));
    }
    s
}

/// Runs the scenario natively ([`NativeLink`]); writes logs and plots into `out` when given.
pub fn run(sc: &Scenario, out: Option<&Path>) -> Result<Summary, String> {
    run_unit(sc, out, EcuCoreConfig::default(), Unit::default())
}

/// [`run`] with the ECU's configuration (`--calibration`) and the simulated unit (`--unit`).
pub fn run_unit(sc: &Scenario, out: Option<&Path>, ecu: EcuCoreConfig, unit: Unit) -> Result<Summary, String> {
    let mut link = NativeLink::with_config(ecu)?;
    let o = run_with_unit(sc, &mut link, &RunOptions::default(), &unit)?;
    if let Some(dir) = out {
        write_outputs(sc, &o, dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    Ok(o.summary)
}

fn wrap_deg(d: f64) -> f64 {
    (d + 360.0).rem_euclid(720.0) - 360.0
}

/// For each set-point step in `(t, setpoint, measured)` samples, the time until the measured
/// value stays within `band` of the set-point (until the next step).
pub fn settling_times(log: &[(f64, f64, f64)], band: f64) -> Vec<(f64, Option<f64>)> {
    let mut out = Vec::new();
    for i in 1..log.len() {
        if (log[i].1 - log[i - 1].1).abs() > 2.0 * band {
            let t0 = log[i].0;
            let sp = log[i].1;
            let end = (i + 1..log.len())
                .find(|&j| (log[j].1 - sp).abs() > 1e-9)
                .unwrap_or(log.len());
            // Last sample outside the band before the next step.
            let last_out = (i..end).rev().find(|&j| (log[j].2 - sp).abs() > band);
            let settled = match last_out {
                None => Some(0.0),
                Some(j) if j + 1 < end => Some(log[j + 1].0 - t0),
                Some(_) => None,
            };
            out.push((t0, settled));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_entries_are_parsed_strictly() {
        let parse = |faults: &str| {
            Scenario::from_toml(
                Path::new("f.toml"),
                &format!("name = \"x\"\nduration_s = 1.0\n{faults}"),
            )
        };
        let ok = parse("[[fault]]\nkind = \"battery_sag\"\nstart_s = 0.2\nend_s = 0.6\nu_batt_v = 8.0\n[[fault]]\nkind = \"vacuum_stuck\"\nstart_s = 0.1\nactuator = \"hpt\"\n").unwrap();
        assert_eq!(ok.faults.len(), 2);
        assert_eq!(ok.faults[1].actuator, Some(VacuumActuator::Hpt));
        // The sag: 14 V before, ramps, 8 V inside, back to 14 V after the ramp out.
        assert_eq!(ok.u_batt_at(0.1), 14.0);
        assert!((ok.u_batt_at(0.25) - 11.0).abs() < 1e-9);
        assert_eq!(ok.u_batt_at(0.5), 8.0);
        assert_eq!(ok.u_batt_at(0.8), 14.0);
        for (text, needle) in [
            ("[[fault]]\nkind = \"gremlin\"\nstart_s = 0.0\n", "gremlin"),
            (
                "[[fault]]\nkind = \"crank_lost\"\nstart_s = 0.0\ncolour = 1\n",
                "colour",
            ),
            ("[[fault]]\nkind = \"crank_lost\"\n", "start_s"),
            ("[[fault]]\nkind = \"battery_sag\"\nstart_s = 0.0\n", "u_batt_v"),
            (
                "[[fault]]\nkind = \"crank_lost\"\nstart_s = 0.5\nend_s = 0.2\n",
                "end_s",
            ),
            (
                "[[fault]]\nkind = \"crank_lost\"\nstart_s = 0.0\nu_batt_v = 8.0\n",
                "belongs to `battery_sag` only",
            ),
            (
                "[[fault]]\nkind = \"crank_lost\"\nstart_s = 0.0\nactuator = \"lpt\"\n",
                "belongs to `vacuum_stuck` only",
            ),
            (
                "[[fault]]\nkind = \"vacuum_stuck\"\nstart_s = 0.0\nactuator = \"egr\"\n",
                "egr",
            ),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.starts_with("f.toml:") && e.contains(needle), "{text}: {e}");
        }
    }

    #[test]
    fn switches_are_booleans_or_0_1_profiles() {
        let parse =
            |text: &str| Scenario::from_toml(Path::new("w.toml"), &format!("name = \"x\"\nduration_s = 1.0\n{text}"));
        let s = parse("lift_high = [[0.0, 1.0], [0.5, 0.0]]\nsnubber_on = true\n").unwrap();
        assert!(s.lift_high.at(0.2) && !s.lift_high.at(0.7) && s.snubber_on.at(0.7));
        let e = parse("lift_high = [[0.0, 0.3]]\n").unwrap_err();
        assert!(e.contains("lift_high") && e.contains("neither"), "{e}");
        let e = parse("snubber_on = \"yes\"\n").unwrap_err();
        assert!(e.starts_with("w.toml:") && e.contains("snubber_on"), "{e}");
    }
}
