//! The whole ECU as one synchronous function of frames, for lockstep HIL: the host's native
//! run and the emulated MCU under QEMU both call [`EcuCore::step`] once per [`STEP_US`] with a
//! [`SensorFrame`] and apply the [`ActuatorFrame`] it returns, so the two runs of a scenario
//! can be compared step by step.
//!
//! The schedule is the firmware's: the EHVVA task every step (it runs on crank edges and its
//! own deadlines on the ECU; 50 µs is 0.45 crank degrees at 1500 rpm), the supervisor and
//! the EVVT task every 10 ms, the vacuum task every 12.5 ms (80 Hz). The supervisor runs
//! first in its tick so the tasks see the measurements and faults of that scan, as on the
//! ECU where the scan completes before the slower tasks' ticks.

use super::board::{elapsed_us, SolenoidCmd};
use super::calibration::CALIBRATION_FAULT_BIT;
use super::ehvva_task::{EhvvaStepInputs, EhvvaTask, EhvvaTaskConfig, EngineSnapshot};
use super::evvt_task::{EvvtTask, EvvtTaskConfig, EvvtTaskInputs, EvvtTaskOutputs};
use super::frame::{ActuatorFrame, SensorFrame};
use super::supervisor::{FaultSet, Measurements, SafeState, Supervisor, SupervisorConfig, TaskReports};
use super::vacuum_task::{VacuumTask, VacuumTaskConfig, VacuumTaskInputs, VacuumTaskOutputs};
use crate::ehvva::{EhvvaParams, EhvvaTables, ValveMotionData};

/// The lockstep period.
pub const STEP_US: u32 = 50;
pub const SUPERVISOR_PERIOD_US: u32 = 10_000;
pub const EVVT_PERIOD_US: u32 = 10_000;
pub const VACUUM_PERIOD_US: u32 = 12_500;

/// The calibration of every task (the firmware's defaults).
#[derive(Clone, Debug)]
pub struct EcuCoreConfig {
    pub supervisor: SupervisorConfig,
    pub ehvva: EhvvaTaskConfig,
    /// The valve model whose delay tables td(Ph, T) advance the pilot command.
    pub ehvva_model: EhvvaParams,
    /// The valve's own motion after td (added to the pilot edges' advance).
    pub ehvva_motion: ValveMotionData,
    pub evvt: EvvtTaskConfig,
    pub vacuum: VacuumTaskConfig,
    /// The calibration image was refused and this is the paper defaults' fall-back: every
    /// actuator frame carries [`CALIBRATION_FAULT_BIT`] (see [`super::calibration`]).
    pub calibration_fault: bool,
}

impl Default for EcuCoreConfig {
    fn default() -> Self {
        Self {
            supervisor: SupervisorConfig::default(),
            ehvva: EhvvaTaskConfig::default(),
            ehvva_model: EhvvaParams::paper_default(),
            ehvva_motion: ValveMotionData::paper_default(),
            evvt: EvvtTaskConfig::default(),
            vacuum: VacuumTaskConfig::default(),
            calibration_fault: false,
        }
    }
}

/// A periodic task's next due time on the wrapping µs clock.
#[derive(Clone, Copy, Debug)]
struct Period {
    period_us: u32,
    next_us: Option<u32>,
}

impl Period {
    const fn new(period_us: u32) -> Self {
        Self {
            period_us,
            next_us: None,
        }
    }
    /// Due at the first call, then every period; a late call (a gap in the frames) does
    /// not make it run several times in a row, it restarts the grid.
    fn due(&mut self, now_us: u32) -> bool {
        match self.next_us {
            Some(next) if elapsed_us(now_us, next) > u32::MAX / 2 => false,
            Some(next) => {
                let late = elapsed_us(now_us, next);
                self.next_us = Some(if late >= self.period_us {
                    now_us.wrapping_add(self.period_us)
                } else {
                    next.wrapping_add(self.period_us)
                });
                true
            }
            None => {
                self.next_us = Some(now_us.wrapping_add(self.period_us));
                true
            }
        }
    }
}

/// The tasks of one step, as [`EcuCore::step_probed`] reports them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepPart {
    Supervisor,
    /// The crank/cam edges of the frame and the EHVVA task's step.
    Ehvva,
    Evvt,
    Vacuum,
}

/// Supervisor + EHVVA + EVVT + vacuum tasks with their schedule and the values they share.
#[derive(Clone, Debug)]
pub struct EcuCore {
    sup: Supervisor,
    ehvva: EhvvaTask<EhvvaTables<f32>>,
    evvt: EvvtTask,
    vacuum: VacuumTask,
    sup_period: Period,
    evvt_period: Period,
    vacuum_period: Period,
    meas: Measurements,
    faults: FaultSet,
    safe: SafeState,
    engine: Option<EngineSnapshot>,
    last_evvt: Option<EvvtTaskOutputs>,
    last_vacuum: Option<VacuumTaskOutputs>,
    motor_duty: f32,
    /// Fault bits outside the supervisor's ([`CALIBRATION_FAULT_BIT`]).
    extra_faults: u32,
}

impl EcuCore {
    pub fn new(cfg: EcuCoreConfig) -> Result<Self, &'static str> {
        let tables = EhvvaTables::<f32>::with_valve_motion(&cfg.ehvva_model, &cfg.ehvva_motion)
            .map_err(|_| "EHVVA delay tables")?;
        Ok(Self {
            sup: Supervisor::new(cfg.supervisor),
            ehvva: EhvvaTask::new(cfg.ehvva, tables)?,
            evvt: EvvtTask::new(cfg.evvt).map_err(|_| "EVVT controller calibration")?,
            vacuum: VacuumTask::new(cfg.vacuum).map_err(|_| "vacuum task calibration")?,
            sup_period: Period::new(SUPERVISOR_PERIOD_US),
            evvt_period: Period::new(EVVT_PERIOD_US),
            vacuum_period: Period::new(VACUUM_PERIOD_US),
            meas: Measurements::default(),
            faults: FaultSet::default(),
            safe: SafeState::default(),
            engine: None,
            last_evvt: None,
            last_vacuum: None,
            motor_duty: 0.0,
            extra_faults: if cfg.calibration_fault {
                CALIBRATION_FAULT_BIT
            } else {
                0
            },
        })
    }

    /// Every output off: pilot unpowered (valve closed by its spring), slow valves off, motor
    /// command 0, vacuum valves unpowered (wastegate open by its spring), pump off. The ECU
    /// applies it when the link falls silent.
    pub fn safe_outputs(seq: u32, t_us: u32) -> ActuatorFrame {
        ActuatorFrame {
            seq,
            t_us,
            pilot: SolenoidCmd::Off,
            lift_valve_on: false,
            snubber_on: false,
            motor_duty: 0.0,
            vacuum_duty: [0.0; 3],
            pump_on: false,
            faults: 0,
            bad_frames: 0,
        }
    }

    /// One lockstep step: the edges and ADC counts of `s`, the tasks that are due, the outputs.
    pub fn step(&mut self, s: &SensorFrame) -> ActuatorFrame {
        self.step_probed(s, |_, _| {})
    }

    /// [`Self::step`] with `probe(part, true)` before and `probe(part, false)` after each
    /// task that runs (the emulated target counts instructions per task with it).
    pub fn step_probed(&mut self, s: &SensorFrame, mut probe: impl FnMut(StepPart, bool)) -> ActuatorFrame {
        let now = s.t_us;
        if self.sup_period.due(now) {
            let vac = self.last_vacuum;
            let reports = TaskReports {
                crank_lost: self.engine.is_some_and(|e| e.crank_lost),
                cam_lost: self.engine.is_some_and(|e| e.cam_lost),
                vacuum_stuck: vac.is_some_and(|v| v.stuck.iter().any(|x| *x)),
                abnormal_leak: vac.is_some_and(|v| v.abnormal_leak),
            };
            probe(StepPart::Supervisor, true);
            let out = self.sup.step(&s.adc_counts, &reports, now);
            probe(StepPart::Supervisor, false);
            self.meas = out.measurements;
            self.faults = out.active;
            self.safe = out.safe;
        }
        let m = self.meas;
        probe(StepPart::Ehvva, true);
        for &edge in s.edges() {
            self.ehvva.on_edge(edge);
        }
        let e = self.ehvva.step(
            &EhvvaStepInputs {
                request: s.valve,
                p_supply_mpa: m.p_supply_mpa,
                temp_oil_c: m.temp_oil_c,
                u_batt_v: m.u_batt_v,
                force_safe: self.safe.ehvva_closed,
            },
            now,
        );
        probe(StepPart::Ehvva, false);
        self.engine = Some(e.engine);
        if self.evvt_period.due(now) {
            probe(StepPart::Evvt, true);
            let o = self.evvt.step(
                &EvvtTaskInputs {
                    engine: e.engine,
                    setpoint_deg: s.cam_phase_set_deg,
                    u_batt_v: m.u_batt_v,
                    faults: self.faults,
                    motor_driver_fault: s.motor_driver_fault,
                },
                now,
            );
            probe(StepPart::Evvt, false);
            self.motor_duty = o.motor_duty;
            self.last_evvt = Some(o);
        }
        if self.vacuum_period.due(now) {
            probe(StepPart::Vacuum, true);
            let o = self.vacuum.step(
                &VacuumTaskInputs {
                    x_set_pct: s.vacuum_x_set_pct,
                    x_meas_pct: m.x_pct,
                    p_tank_kpa: m.p_tank_kpa,
                    p_amb_kpa: m.p_amb_kpa,
                    u_batt_v: m.u_batt_v,
                    safe: self.safe,
                },
                now,
            );
            probe(StepPart::Vacuum, false);
            self.last_vacuum = Some(o);
        }
        let vac = self.last_vacuum;
        ActuatorFrame {
            seq: s.seq,
            t_us: now,
            pilot: e.pilot,
            lift_valve_on: e.lift_valve_on,
            snubber_on: e.snubber_switch_on,
            motor_duty: self.motor_duty,
            vacuum_duty: vac.map_or([0.0; 3], |v| v.duty),
            pump_on: vac.is_some_and(|v| v.pump_on),
            faults: self.faults.0 | self.extra_faults,
            bad_frames: 0,
        }
    }

    /// The supervisor's converted measurements of its last scan.
    pub fn measurements(&self) -> Measurements {
        self.meas
    }
    pub fn faults(&self) -> FaultSet {
        self.faults
    }
    /// The crank decoder's view of the engine after the last step.
    pub fn engine(&self) -> Option<EngineSnapshot> {
        self.engine
    }
    /// The EVVT task's last outputs (measured phase, mode, scheduled gain).
    pub fn evvt(&self) -> Option<EvvtTaskOutputs> {
        self.last_evvt
    }
    /// The vacuum task's last outputs (pump target, leak residual, stuck flags).
    pub fn vacuum(&self) -> Option<VacuumTaskOutputs> {
        self.last_vacuum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ecu::crank_sim::CrankSignal;
    use crate::ecu::ehvva_task::{TriggerWheel, ValveRequest};
    use crate::ecu::frame::MAX_EDGES;
    use crate::ecu::supervisor::{Channel, Fault, N_CHANNELS};

    const RPM: f64 = 1500.0;

    /// A 60-2 wheel at constant speed, the cam edge at cycle angle 438 deg, healthy sensors.
    struct Feed {
        engine: CrankSignal,
        counts: [u16; N_CHANNELS],
        crank: bool,
    }

    impl Feed {
        fn new() -> Self {
            let cfg = SupervisorConfig::default();
            let values = [13.8, 6.0, 2.0, 80.0, 40.0, 100.0, 20.0, 40.0, 60.0, 50.0];
            let engine = CrankSignal::new(TriggerWheel::sixty_minus_two(), 0.0);
            Self {
                engine,
                counts: core::array::from_fn(|k| cfg.scales[k].counts_for(values[k])),
                crank: true,
            }
        }
        /// The frame of step `seq` (called for seq = 1, 2, 3, ...).
        fn frame(&mut self, seq: u32) -> SensorFrame {
            let t_us = seq * STEP_US;
            let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
            let n = self
                .engine
                .advance(RPM, STEP_US, 438.0, self.crank, self.crank, t_us - STEP_US, &mut edges)
                .min(MAX_EDGES);
            SensorFrame {
                seq,
                t_us,
                n_edges: n as u8,
                edges,
                adc_counts: self.counts,
                valve: ValveRequest {
                    open_deg: 100.0,
                    close_deg: 400.0,
                    high_lift: true,
                    soft_seat: true,
                    enabled: true,
                },
                cam_phase_set_deg: 20.0,
                vacuum_x_set_pct: [20.0, 40.0, 60.0],
                motor_driver_fault: false,
            }
        }
    }

    #[test]
    fn schedule_runs_each_task_at_its_rate() {
        let mut p = Period::new(10_000);
        let ticks = (0..2000u32).filter(|k| p.due(k * 50)).count();
        assert_eq!(ticks, 10, "100 ms of 50 µs steps: 10 supervisor ticks");
        let mut v = Period::new(12_500);
        let ticks = (0..2000u32).filter(|k| v.due(k * 50)).count();
        assert_eq!(ticks, 8, "100 ms at 80 Hz");
        // Across the clock's wrap and after a gap: no burst of catch-up runs.
        let mut w = Period::new(10_000);
        let t0 = u32::MAX - 25_000;
        let wrapped = (0..2000u32).filter(|k| w.due(t0.wrapping_add(k * 50))).count();
        assert_eq!(wrapped, 10);
        assert!(w.due(t0.wrapping_add(1_000_000)));
        assert!(!w.due(t0.wrapping_add(1_000_050)));
    }

    #[test]
    fn runs_valve_events_and_control_then_reacts_to_a_sensor_fault() {
        let mut ecu = EcuCore::new(EcuCoreConfig::default()).unwrap();
        let mut feed = Feed::new();
        let mut pilot_full = 0;
        let mut seq = 0;
        for _ in 0..12_000 {
            seq += 1;
            let s = feed.frame(seq);
            let a = ecu.step(&s);
            assert_eq!(a.seq, seq);
            pilot_full += (a.pilot == SolenoidCmd::Full) as u32;
        }
        // 0.6 s at 1500 rpm = 7.5 cycles; events need sync first (a few cycles).
        assert!(pilot_full > 0, "no pilot peak in 0.6 s");
        assert_eq!(ecu.faults().0, 0);
        let e = ecu.evvt().unwrap();
        assert!(
            e.phase_deg.is_some() && e.kp_rpm_per_deg > 0.0,
            "EVVT not controlling: {e:?}"
        );
        let v = ecu.vacuum().unwrap();
        assert!(v.duty.iter().all(|d| *d > 0.0), "vacuum valves idle: {v:?}");
        // Supply pressure sensor open: debounced fault, then the valves stay closed.
        feed.counts[Channel::SupplyPressureMpa as usize] = 0;
        let mut last = EcuCore::safe_outputs(0, 0);
        for _ in 0..24_000 {
            seq += 1;
            last = ecu.step(&feed.frame(seq));
        }
        assert!(ecu.faults().contains(Fault::SupplyPressureSensor));
        assert_eq!(last.faults, ecu.faults().0);
        assert_eq!(last.pilot, SolenoidCmd::Off);
        assert!(!last.lift_valve_on && !last.snubber_on);
    }

    #[test]
    fn identical_frames_give_identical_outputs() {
        // Determinism: two cores fed the same frames agree bit for bit (the PIL comparison
        // relies on it).
        let mut a = EcuCore::new(EcuCoreConfig::default()).unwrap();
        let mut b = EcuCore::new(EcuCoreConfig::default()).unwrap();
        let mut feed = Feed::new();
        for seq in 1..4000 {
            let s = feed.frame(seq);
            let (x, y) = (a.step(&s), b.step(&s));
            assert_eq!(x, y);
            assert_eq!(x.motor_duty.to_bits(), y.motor_duty.to_bits());
        }
    }
}
