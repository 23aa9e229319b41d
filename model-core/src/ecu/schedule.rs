//! The ECU's one composition: the four task state machines, what they share, their periods,
//! their order, how each reads its inputs from the board and writes its outputs, and the
//! watchdog decision. Every runner of the ECU goes through the `run` methods here:
//!
//! - the ECU firmware (`firmware/src/tasks.rs`): one embassy task per part, a `Ticker` at the
//!   part's period (the EHVVA part on every crank edge and at its own deadline), each loop
//!   `read clock → part.run(shared, board, setpoint, now)`; the parts share one [`EcuShared`]
//!   behind a critical-section mutex (the firmware's [`SharedAccess`]);
//! - the lockstep core [`super::lockstep::EcuCore`] (`hil-host run`, the QEMU image, every
//!   host test): the same `run` methods in [`Ecu::step_on`]'s order on the lockstep grid, the
//!   sensor frame and the actuator frame being its board ([`super::lockstep`]).
//!
//! So the firmware keeps only peripheral glue behind the board traits of this module and of
//! [`super::board`]; input assembly (which measurement, which safe state, which set-point each
//! task gets), the supervisor's reports, the heartbeats and the watchdog decision are here.
//!
//! The parts are separate values (not one `&mut Ecu`) because on the ECU the EHVVA part runs
//! on a higher-priority executor than the others: a vacuum step (≈ 0.25 ms) must never hold
//! up a pilot edge, so each part owns its state machine and only the small [`EcuShared`] is
//! copied in and out under a lock, twice per run.

use super::board::{AnalogIn, Capture, Edge, PwmOut, SolenoidDriver, SwitchOut};
use super::ehvva_task::{EhvvaStepInputs, EhvvaStepOutputs, EhvvaTask, EngineSnapshot, SyncState, ValveRequest};
use super::evvt_task::{EvvtTask, EvvtTaskInputs, EvvtTaskOutputs};
use super::lockstep::EcuCoreConfig;
use super::supervisor::{FaultSet, Measurements, SafeState, Supervisor, SupervisorOutput, TaskReports, N_CHANNELS};
use super::vacuum_task::{VacuumTask, VacuumTaskInputs, VacuumTaskOutputs};
use crate::ehvva::EhvvaTables;

/// The supervisor's scan period (ADC channels, faults, watchdog decision), µs.
pub const SUPERVISOR_PERIOD_US: u32 = 10_000;
/// The EVVT control period (100 Hz), µs.
pub const EVVT_PERIOD_US: u32 = 10_000;
/// The vacuum task's period (80 Hz duty updates of the 300 Hz valve PWM), µs.
pub const VACUUM_PERIOD_US: u32 = 12_500;
/// The supervisor checks the heartbeats every this many scans (50 ms): the watchdog is petted
/// only when every task ran since the previous check.
pub const WATCHDOG_CHECK_SCANS: u32 = 5;
/// The independent watchdog's timeout (the ECU's IWDG), µs: four missed checks in a row reset
/// the ECU.
pub const WATCHDOG_TIMEOUT_US: u32 = 200_000;

/// The tasks that report a heartbeat (the supervisor is the one that checks them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskId {
    /// The EHVVA part (every crank edge and deadline, at least every 10 ms).
    Ehvva = 0,
    /// The EVVT part (100 Hz).
    Evvt = 1,
    /// The vacuum part (80 Hz).
    Vacuum = 2,
}

/// What the engine management asks for (over CAN on a car; in the sensor frame in lockstep).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoints {
    /// The valve event for the coming cycles.
    pub valve: ValveRequest,
    /// Cam phase set-point, deg (advance from the retard stop).
    pub cam_phase_deg: f32,
    /// LPT, HPT, HPC position set-points, %.
    pub vacuum_x_pct: [f32; 3],
}

/// The values the parts exchange: the supervisor's measurements, faults and safe state, the
/// crank decoder's engine view, the vacuum task's reports, the heartbeats.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EcuShared {
    /// The supervisor's converted measurements of its last scan ([`Measurements::BOOT`] before).
    pub measurements: Measurements,
    /// The supervisor's active faults.
    pub faults: FaultSet,
    /// The safe state of every actuator: [`SafeState::ALL`] until the first scan (no task
    /// drives an actuator on values nobody has measured), then the faults' reactions.
    pub safe: SafeState,
    /// The EHVVA part's crank decoder after its last run.
    pub engine: EngineSnapshot,
    /// The vacuum part's last report: an actuator stuck.
    pub vacuum_stuck: bool,
    /// The vacuum part's last report: abnormal leak or pump failure.
    pub abnormal_leak: bool,
    /// Runs of each task ([`TaskId`] order), wrapping.
    pub heartbeats: [u32; 3],
}

impl EcuShared {
    /// The state at boot (a const, so a firmware can put it in a static).
    pub const BOOT: Self = Self {
        measurements: Measurements::BOOT,
        faults: FaultSet(0),
        safe: SafeState::ALL,
        engine: EngineSnapshot {
            sync: SyncState::None,
            rpm: 0.0,
            cranking: false,
            cam_edge_deg: None,
            cam_edge_seq: 0,
            crank_lost: false,
            cam_lost: false,
        },
        vacuum_stuck: false,
        abnormal_leak: false,
        heartbeats: [0; 3],
    };

    fn beat(&mut self, task: TaskId) {
        if let Some(h) = self.heartbeats.get_mut(task as usize) {
            *h = h.wrapping_add(1);
        }
    }

    /// The faults the tasks detect themselves, for the supervisor.
    pub fn reports(&self) -> TaskReports {
        TaskReports {
            crank_lost: self.engine.crank_lost,
            cam_lost: self.engine.cam_lost,
            vacuum_stuck: self.vacuum_stuck,
            abnormal_leak: self.abnormal_leak,
        }
    }
}

/// How a part reaches the shared values: directly in a single-threaded runner (lockstep), under
/// a critical section on the ECU. `f` must not call `with` again.
pub trait SharedAccess {
    /// Runs `f` on the shared values, exclusively.
    fn with<R>(&mut self, f: impl FnOnce(&mut EcuShared) -> R) -> R;
}

impl SharedAccess for EcuShared {
    fn with<R>(&mut self, f: impl FnOnce(&mut EcuShared) -> R) -> R {
        f(self)
    }
}

/// The EHVVA part's board: the capture timer's edges, the pilot's peak-and-hold driver, the
/// lift and snubber switch valves.
pub trait EhvvaBoard: Capture {
    /// The pilot stage.
    type Pilot: SolenoidDriver;
    /// A slow solenoid valve.
    type Switch: SwitchOut;
    /// The pilot stage.
    fn pilot(&mut self) -> &mut Self::Pilot;
    /// The lift valve (S1 high lift when on).
    fn lift_valve(&mut self) -> &mut Self::Switch;
    /// The snubber switch valve (soft seating when on).
    fn snubber_valve(&mut self) -> &mut Self::Switch;
}

/// The EVVT part's board: the motor speed command and the driver's fault pin.
pub trait EvvtBoard {
    /// The speed command output (duty = speed / full scale).
    type Motor: PwmOut;
    /// The speed command output.
    fn motor(&mut self) -> &mut Self::Motor;
    /// The motor driver reports a fault (its fault pin is active).
    fn driver_fault(&mut self) -> bool;
}

/// The vacuum part's board: three valve PWMs (LPT, HPT, HPC) and the pump relay.
pub trait VacuumBoard {
    /// A valve's PWM output.
    type Valve: PwmOut;
    /// The pump relay.
    type Pump: SwitchOut;
    /// The LPT, HPT, HPC valves.
    fn valves(&mut self) -> &mut [Self::Valve; 3];
    /// The pump relay.
    fn pump(&mut self) -> &mut Self::Pump;
}

/// The supervisor's analog inputs, one [`AnalogIn`] per [`super::supervisor::Channel`] index.
pub trait AnalogBank {
    /// One channel's input.
    type In<'a>: AnalogIn
    where
        Self: 'a;
    /// The input of channel `index`.
    fn analog(&mut self, index: usize) -> Self::In<'_>;
}

/// The independent watchdog: restarts the ECU unless petted within [`WATCHDOG_TIMEOUT_US`].
pub trait Watchdog {
    /// Reloads the watchdog's counter.
    fn pet(&mut self);
}

/// Every output off, as at boot and after a watchdog reset: pilot unpowered (engine valve
/// closed by its spring), lift and snubber valves off, motor command 0, vacuum valves unpowered
/// (wastegate and bypasses where their springs put them), pump off.
pub fn outputs_off(ehvva: &mut impl EhvvaBoard, evvt: &mut impl EvvtBoard, vacuum: &mut impl VacuumBoard) {
    ehvva.pilot().off();
    ehvva.lift_valve().set(false);
    ehvva.snubber_valve().set(false);
    evvt.motor().set_duty(0.0);
    for v in vacuum.valves().iter_mut() {
        v.set_duty(0.0);
    }
    vacuum.pump().set(false);
}

/// The EHVVA task in the composition.
#[derive(Clone, Debug)]
pub struct EhvvaPart {
    task: EhvvaTask<EhvvaTables<f32>>,
}

impl EhvvaPart {
    /// Feeds one captured crank or cam edge (time order).
    pub fn on_edge(&mut self, edge: Edge) {
        self.task.on_edge(edge);
    }

    /// One step at `now_us` after the edges: the supervisor's supply pressure, oil temperature,
    /// battery voltage and EHVVA safe state in; the engine view and a heartbeat out.
    pub fn deadline(
        &mut self,
        shared: &mut impl SharedAccess,
        request: &ValveRequest,
        now_us: u32,
    ) -> EhvvaStepOutputs {
        let (m, safe) = shared.with(|s| (s.measurements, s.safe));
        let out = self.task.step(
            &EhvvaStepInputs {
                request: *request,
                p_supply_mpa: m.p_supply_mpa,
                temp_oil_c: m.temp_oil_c,
                u_batt_v: m.u_batt_v,
                force_safe: safe.ehvva_closed,
            },
            now_us,
        );
        shared.with(|s| {
            s.engine = out.engine;
            s.beat(TaskId::Ehvva);
        });
        out
    }

    /// What the ECU runs at every crank edge and deadline: the pending edges from the board,
    /// [`Self::deadline`], the pilot, lift and snubber outputs onto the board. Call it again at
    /// `wake_at_us` of the result at the latest.
    pub fn run(
        &mut self,
        shared: &mut impl SharedAccess,
        board: &mut impl EhvvaBoard,
        request: &ValveRequest,
        now_us: u32,
    ) -> EhvvaStepOutputs {
        while let Some(edge) = board.next_edge() {
            self.task.on_edge(edge);
        }
        let out = self.deadline(shared, request, now_us);
        board.pilot().apply(out.pilot);
        board.lift_valve().set(out.lift_valve_on);
        board.snubber_valve().set(out.snubber_switch_on);
        out
    }

    /// The EHVVA state machine (decoder, pilot driver).
    pub fn task(&self) -> &EhvvaTask<EhvvaTables<f32>> {
        &self.task
    }
}

/// The EVVT task in the composition.
#[derive(Clone, Debug)]
pub struct EvvtPart {
    task: EvvtTask,
}

impl EvvtPart {
    /// One control period: the engine view, battery voltage and faults in; a heartbeat out.
    pub fn tick(
        &mut self,
        shared: &mut impl SharedAccess,
        setpoint_deg: f32,
        motor_driver_fault: bool,
        now_us: u32,
    ) -> EvvtTaskOutputs {
        let (engine, u_batt_v, faults) = shared.with(|s| (s.engine, s.measurements.u_batt_v, s.faults));
        let out = self.task.step(
            &EvvtTaskInputs {
                engine,
                setpoint_deg,
                u_batt_v,
                faults,
                motor_driver_fault,
            },
            now_us,
        );
        shared.with(|s| s.beat(TaskId::Evvt));
        out
    }

    /// What the ECU runs every [`EVVT_PERIOD_US`]: the driver's fault pin from the board,
    /// [`Self::tick`], the speed command onto the board.
    pub fn run(
        &mut self,
        shared: &mut impl SharedAccess,
        board: &mut impl EvvtBoard,
        setpoint_deg: f32,
        now_us: u32,
    ) -> EvvtTaskOutputs {
        let driver_fault = board.driver_fault();
        let out = self.tick(shared, setpoint_deg, driver_fault, now_us);
        board.motor().set_duty(out.motor_duty);
        out
    }
}

/// The vacuum task in the composition.
#[derive(Clone, Debug)]
pub struct VacuumPart {
    task: VacuumTask,
}

impl VacuumPart {
    /// One period: positions, tank and ambient pressure, battery voltage and the safe state
    /// in; the stuck and leak reports and a heartbeat out.
    pub fn tick(&mut self, shared: &mut impl SharedAccess, x_set_pct: [f32; 3], now_us: u32) -> VacuumTaskOutputs {
        let (m, safe) = shared.with(|s| (s.measurements, s.safe));
        let out = self.task.step(
            &VacuumTaskInputs {
                x_set_pct,
                x_meas_pct: m.x_pct,
                p_tank_kpa: m.p_tank_kpa,
                p_amb_kpa: m.p_amb_kpa,
                u_batt_v: m.u_batt_v,
                safe,
            },
            now_us,
        );
        shared.with(|s| {
            s.vacuum_stuck = out.stuck.iter().any(|x| *x);
            s.abnormal_leak = out.abnormal_leak;
            s.beat(TaskId::Vacuum);
        });
        out
    }

    /// What the ECU runs every [`VACUUM_PERIOD_US`]: [`Self::tick`], the valve duties and the
    /// pump onto the board.
    pub fn run(
        &mut self,
        shared: &mut impl SharedAccess,
        board: &mut impl VacuumBoard,
        x_set_pct: [f32; 3],
        now_us: u32,
    ) -> VacuumTaskOutputs {
        let out = self.tick(shared, x_set_pct, now_us);
        for (valve, duty) in board.valves().iter_mut().zip(out.duty) {
            valve.set_duty(duty);
        }
        board.pump().set(out.pump_on);
        out
    }
}

/// One supervisor scan's result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorTick {
    /// Measurements, faults (active, newly set, cleared), safe state.
    pub out: SupervisorOutput,
    /// Every task ran since the previous check: the watchdog may be petted now.
    pub pet_watchdog: bool,
}

/// The supervisor in the composition, with the watchdog's heartbeat check.
#[derive(Clone, Debug)]
pub struct SupervisorPart {
    sup: Supervisor,
    scans: u32,
    beats_at_check: [u32; 3],
}

impl SupervisorPart {
    /// One scan on the raw counts (in [`super::supervisor::Channel`] order): the tasks'
    /// reports in; measurements, faults and safe state out; every
    /// [`WATCHDOG_CHECK_SCANS`]-th scan the watchdog decision.
    pub fn tick(&mut self, shared: &mut impl SharedAccess, counts: &[u16; N_CHANNELS], now_us: u32) -> SupervisorTick {
        let reports = shared.with(|s| s.reports());
        let out = self.sup.step(counts, &reports, now_us);
        let beats = shared.with(|s| {
            s.measurements = out.measurements;
            s.faults = out.active;
            s.safe = out.safe;
            s.heartbeats
        });
        self.scans = self.scans.wrapping_add(1);
        let mut pet_watchdog = false;
        if self.scans.is_multiple_of(WATCHDOG_CHECK_SCANS) {
            pet_watchdog = beats
                .iter()
                .zip(self.beats_at_check.iter())
                .all(|(now, then)| now != then);
            self.beats_at_check = beats;
        }
        SupervisorTick { out, pet_watchdog }
    }

    /// What the ECU runs every [`SUPERVISOR_PERIOD_US`]: every channel from the board's ADC,
    /// [`Self::tick`], the watchdog petted when it may be.
    pub fn run(
        &mut self,
        shared: &mut impl SharedAccess,
        adc: &mut impl AnalogBank,
        watchdog: &mut impl Watchdog,
        now_us: u32,
    ) -> SupervisorTick {
        let counts: [u16; N_CHANNELS] = core::array::from_fn(|k| adc.analog(k).read_counts());
        let tick = self.tick(shared, &counts, now_us);
        if tick.pet_watchdog {
            watchdog.pet();
        }
        tick
    }

    /// The supervisor's active faults.
    pub fn active(&self) -> FaultSet {
        self.sup.active()
    }
}

/// The whole ECU: the four parts and their shared values, built from one calibration.
#[derive(Clone, Debug)]
pub struct Ecu {
    /// The supervisor and the watchdog decision.
    pub supervisor: SupervisorPart,
    /// Crank/cam decoding, valve events, pilot peak-and-hold.
    pub ehvva: EhvvaPart,
    /// Cam phase control.
    pub evvt: EvvtPart,
    /// Vacuum valves and pump.
    pub vacuum: VacuumPart,
    /// What the parts exchange ([`EcuShared::BOOT`] at start).
    pub shared: EcuShared,
}

/// The boards of every part, for a single-threaded runner ([`Ecu::step_on`]).
pub struct Boards<'a, E, V, W, A, D> {
    /// The EHVVA part's board.
    pub ehvva: &'a mut E,
    /// The EVVT part's board.
    pub evvt: &'a mut V,
    /// The vacuum part's board.
    pub vacuum: &'a mut W,
    /// The ADC.
    pub adc: &'a mut A,
    /// The watchdog.
    pub watchdog: &'a mut D,
}

/// Which parts ran in one [`Ecu::step_on`] (and what they returned).
#[derive(Clone, Copy, Debug)]
pub struct StepReport {
    /// The supervisor's scan, if due.
    pub supervisor: Option<SupervisorTick>,
    /// The EHVVA step (every step).
    pub ehvva: EhvvaStepOutputs,
    /// The EVVT period, if due.
    pub evvt: Option<EvvtTaskOutputs>,
    /// The vacuum period, if due.
    pub vacuum: Option<VacuumTaskOutputs>,
}

/// The parts of one step, for [`Ecu::step_on`]'s probe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepPart {
    /// The supervisor's scan.
    Supervisor,
    /// The crank/cam edges and the EHVVA task's step.
    Ehvva,
    /// The EVVT period.
    Evvt,
    /// The vacuum period.
    Vacuum,
}

impl Ecu {
    /// Validates the calibration and builds every part (the EHVVA delay and motion tables from
    /// the valve model). An error names what was refused.
    pub fn new(cfg: EcuCoreConfig) -> Result<Self, &'static str> {
        let tables = EhvvaTables::<f32>::with_valve_motion(&cfg.ehvva_model, &cfg.ehvva_motion)
            .map_err(|_| "EHVVA delay tables")?;
        Ok(Self {
            supervisor: SupervisorPart {
                sup: Supervisor::new(cfg.supervisor),
                scans: 0,
                beats_at_check: [0; 3],
            },
            ehvva: EhvvaPart {
                task: EhvvaTask::new(cfg.ehvva, tables)?,
            },
            evvt: EvvtPart {
                task: EvvtTask::new(cfg.evvt).map_err(|_| "EVVT controller calibration")?,
            },
            vacuum: VacuumPart {
                task: VacuumTask::new(cfg.vacuum).map_err(|_| "vacuum task calibration")?,
            },
            shared: EcuShared::BOOT,
        })
    }

    /// One step of a single-threaded runner at `now_us`, the parts in the ECU's order: the
    /// supervisor's scan first when due (the tasks see the measurements and faults of that
    /// scan, as on the ECU where the scan completes before the slower tasks' ticks), the EHVVA
    /// part (every step: its edges and deadlines fall on the runner's grid), then the EVVT and
    /// vacuum parts when due. `probe(part, true)` before and `probe(part, false)` after each
    /// part that runs.
    pub fn step_on(
        &mut self,
        schedule: &mut Schedule,
        board: Boards<'_, impl EhvvaBoard, impl EvvtBoard, impl VacuumBoard, impl AnalogBank, impl Watchdog>,
        setpoints: &Setpoints,
        now_us: u32,
        mut probe: impl FnMut(StepPart, bool),
    ) -> StepReport {
        let Boards {
            ehvva: ehvva_io,
            evvt: evvt_io,
            vacuum: vacuum_io,
            adc,
            watchdog,
        } = board;
        let sh = &mut self.shared;
        let supervisor = schedule.supervisor.due(now_us).then(|| {
            probe(StepPart::Supervisor, true);
            let t = self.supervisor.run(sh, adc, watchdog, now_us);
            probe(StepPart::Supervisor, false);
            t
        });
        probe(StepPart::Ehvva, true);
        let ehvva = self.ehvva.run(sh, ehvva_io, &setpoints.valve, now_us);
        probe(StepPart::Ehvva, false);
        let evvt = schedule.evvt.due(now_us).then(|| {
            probe(StepPart::Evvt, true);
            let o = self.evvt.run(sh, evvt_io, setpoints.cam_phase_deg, now_us);
            probe(StepPart::Evvt, false);
            o
        });
        let vacuum = schedule.vacuum.due(now_us).then(|| {
            probe(StepPart::Vacuum, true);
            let o = self.vacuum.run(sh, vacuum_io, setpoints.vacuum_x_pct, now_us);
            probe(StepPart::Vacuum, false);
            o
        });
        StepReport {
            supervisor,
            ehvva,
            evvt,
            vacuum,
        }
    }
}

/// A periodic part's next due time on the wrapping µs clock (what an embassy `Ticker` does on
/// the ECU, on a runner's grid).
#[derive(Clone, Copy, Debug)]
pub struct Period {
    period_us: u32,
    next_us: Option<u32>,
}

impl Period {
    /// Due at the first call, then every `period_us`.
    pub const fn new(period_us: u32) -> Self {
        Self {
            period_us,
            next_us: None,
        }
    }

    /// Due at the first call, then every period; a late call (a gap in the frames) does not
    /// make it run several times in a row, it restarts the grid.
    pub fn due(&mut self, now_us: u32) -> bool {
        match self.next_us {
            Some(next) if now_us.wrapping_sub(next) > u32::MAX / 2 => false,
            Some(next) => {
                let late = now_us.wrapping_sub(next);
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

/// The periodic parts' grids for a single-threaded runner.
#[derive(Clone, Copy, Debug)]
pub struct Schedule {
    /// Every [`SUPERVISOR_PERIOD_US`].
    pub supervisor: Period,
    /// Every [`EVVT_PERIOD_US`].
    pub evvt: Period,
    /// Every [`VACUUM_PERIOD_US`].
    pub vacuum: Period,
}

impl Default for Schedule {
    fn default() -> Self {
        Self {
            supervisor: Period::new(SUPERVISOR_PERIOD_US),
            evvt: Period::new(EVVT_PERIOD_US),
            vacuum: Period::new(VACUUM_PERIOD_US),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::board::doubles::{FakeAnalog, FakeCapture, FakePwm, FakeSolenoid, FakeSwitch};
    use super::super::board::SolenoidCmd;
    use super::super::crank_sim::CrankSignal;
    use super::super::ehvva_task::{CrankDecoder, EhvvaTaskConfig, TriggerWheel};
    use super::super::supervisor::{SupervisorConfig, N_CHANNELS};
    use super::*;

    const STEP_US: u32 = 50;
    const RPM: f64 = 1500.0;

    /// The EHVVA part's board: queued edges in, recording doubles out.
    #[derive(Default)]
    struct EhvvaIo {
        capture: FakeCapture,
        pilot: FakeSolenoid,
        lift: FakeSwitch,
        snubber: FakeSwitch,
    }
    impl Capture for EhvvaIo {
        fn next_edge(&mut self) -> Option<Edge> {
            self.capture.next_edge()
        }
    }
    impl EhvvaBoard for EhvvaIo {
        type Pilot = FakeSolenoid;
        type Switch = FakeSwitch;
        fn pilot(&mut self) -> &mut FakeSolenoid {
            &mut self.pilot
        }
        fn lift_valve(&mut self) -> &mut FakeSwitch {
            &mut self.lift
        }
        fn snubber_valve(&mut self) -> &mut FakeSwitch {
            &mut self.snubber
        }
    }

    #[derive(Default)]
    struct EvvtIo {
        motor: FakePwm,
        fault_pin: bool,
    }
    impl EvvtBoard for EvvtIo {
        type Motor = FakePwm;
        fn motor(&mut self) -> &mut FakePwm {
            &mut self.motor
        }
        fn driver_fault(&mut self) -> bool {
            self.fault_pin
        }
    }

    #[derive(Default)]
    struct VacuumIo {
        valves: [FakePwm; 3],
        pump: FakeSwitch,
    }
    impl VacuumBoard for VacuumIo {
        type Valve = FakePwm;
        type Pump = FakeSwitch;
        fn valves(&mut self) -> &mut [FakePwm; 3] {
            &mut self.valves
        }
        fn pump(&mut self) -> &mut FakeSwitch {
            &mut self.pump
        }
    }

    struct Adc([u16; N_CHANNELS]);
    impl AnalogBank for Adc {
        type In<'a> = FakeAnalog;
        fn analog(&mut self, index: usize) -> FakeAnalog {
            FakeAnalog { counts: self.0[index] }
        }
    }

    /// The IWDG: expired once `WATCHDOG_TIMEOUT_US` passed without a pet.
    #[derive(Default)]
    struct Iwdg {
        now_us: u32,
        last_pet_us: u32,
        pets: heapless::Vec<u32, 64>,
    }
    impl Watchdog for Iwdg {
        fn pet(&mut self) {
            self.last_pet_us = self.now_us;
            self.pets.push(self.now_us).unwrap();
        }
    }
    impl Iwdg {
        fn expired(&self) -> bool {
            self.now_us - self.last_pet_us >= WATCHDOG_TIMEOUT_US
        }
    }

    /// Which part a test keeps from running (a task that hangs).
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Stall {
        Supervisor,
        Task(TaskId),
    }

    /// A board around the composition, driven on a 50 µs grid like the lockstep core, with a
    /// turning engine and healthy sensors (13.8 V, 6 MPa, oil 80 °C, tank 40 kPa, ...).
    struct Rig {
        ecu: Ecu,
        schedule: Schedule,
        ehvva: EhvvaIo,
        evvt: EvvtIo,
        vacuum: VacuumIo,
        adc: Adc,
        iwdg: Iwdg,
        engine: CrankSignal,
        setpoints: Setpoints,
        now_us: u32,
    }

    impl Rig {
        fn new() -> Self {
            let cfg = SupervisorConfig::default();
            let values = [13.8, 6.0, 2.0, 80.0, 40.0, 100.0, 20.0, 40.0, 60.0, 50.0];
            Self {
                ecu: Ecu::new(EcuCoreConfig::default()).unwrap(),
                schedule: Schedule::default(),
                ehvva: EhvvaIo::default(),
                evvt: EvvtIo::default(),
                vacuum: VacuumIo::default(),
                adc: Adc(core::array::from_fn(|k| cfg.scales[k].counts_for(values[k]))),
                iwdg: Iwdg::default(),
                engine: CrankSignal::new(TriggerWheel::sixty_minus_two(), 0.0),
                setpoints: Setpoints {
                    valve: ValveRequest {
                        open_deg: 100.0,
                        close_deg: 400.0,
                        high_lift: true,
                        soft_seat: true,
                        enabled: true,
                    },
                    cam_phase_deg: 20.0,
                    vacuum_x_pct: [20.0, 40.0, 60.0],
                },
                now_us: 0,
            }
        }

        /// One 50 µs step with the parts in the composition's order, except `stall`.
        fn tick(&mut self, stall: Option<Stall>) {
            let t0 = self.now_us;
            self.now_us += STEP_US;
            let now = self.now_us;
            self.iwdg.now_us = now;
            self.ehvva.pilot.now_us = now;
            let mut edges = [Edge {
                source: super::super::board::EdgeSource::CrankTooth,
                t_us: 0,
            }; 8];
            let n = self.engine.advance(RPM, STEP_US, 438.0, true, true, t0, &mut edges);
            for e in &edges[..n.min(edges.len())] {
                // A full queue drops the edge, as the ECU's capture queue does (a hung EHVVA
                // part does not drain it).
                let _ = self.ehvva.capture.pending.push_back(*e);
            }
            let sh = &mut self.ecu.shared;
            let runs = |p: Stall| stall != Some(p);
            if self.schedule.supervisor.due(now) && runs(Stall::Supervisor) {
                self.ecu.supervisor.run(sh, &mut self.adc, &mut self.iwdg, now);
            }
            if runs(Stall::Task(TaskId::Ehvva)) {
                self.ecu.ehvva.run(sh, &mut self.ehvva, &self.setpoints.valve, now);
            }
            if self.schedule.evvt.due(now) && runs(Stall::Task(TaskId::Evvt)) {
                self.ecu.evvt.run(sh, &mut self.evvt, self.setpoints.cam_phase_deg, now);
            }
            if self.schedule.vacuum.due(now) && runs(Stall::Task(TaskId::Vacuum)) {
                self.ecu
                    .vacuum
                    .run(sh, &mut self.vacuum, self.setpoints.vacuum_x_pct, now);
            }
        }

        fn all_outputs_off(&self) -> bool {
            self.ehvva.pilot.current() == SolenoidCmd::Off
                && !self.ehvva.lift.on
                && !self.ehvva.snubber.on
                && self.evvt.motor.duty == 0.0
                && self.vacuum.valves.iter().all(|v| v.duty == 0.0)
                && !self.vacuum.pump.on
        }
    }

    #[test]
    fn boot_engine_view_is_the_decoders() {
        let c = EhvvaTaskConfig::default();
        let d = CrankDecoder::new(c.wheel, c.stall_timeout_us, c.run_rpm);
        assert_eq!(EcuShared::BOOT.engine, d.snapshot());
        assert_eq!(EcuShared::BOOT.measurements, Measurements::default());
    }

    #[test]
    fn the_watchdog_is_petted_every_check_while_every_task_runs() {
        let mut r = Rig::new();
        for _ in 0..(1_000_000 / STEP_US) {
            r.tick(None);
        }
        // 1 s: a pet at every fifth scan, 50 ms apart, none missed.
        assert_eq!(r.iwdg.pets.len(), 20, "{:?}", r.iwdg.pets);
        assert!(r.iwdg.pets.windows(2).all(|w| w[1] - w[0] == 50_000));
        assert!(!r.iwdg.expired());
        // And the ECU was working: valve events, phase control, valves and slow valves on.
        assert!(r.ehvva.pilot.log.iter().any(|(_, c)| *c == SolenoidCmd::Full));
        assert!(r.ehvva.lift.on && r.evvt.motor.duty > 0.0);
        assert!(r.vacuum.valves.iter().all(|v| v.duty > 0.0));
    }

    /// A hung task stops the pets; the IWDG resets the ECU within 50 ms + its timeout; the
    /// reset ECU starts with every output off and keeps the actuators safe until its first scan.
    #[test]
    fn a_stalled_task_is_not_petted_over_and_the_reset_ecu_starts_with_every_output_off() {
        for stall in [
            Stall::Supervisor,
            Stall::Task(TaskId::Ehvva),
            Stall::Task(TaskId::Evvt),
            Stall::Task(TaskId::Vacuum),
        ] {
            let mut r = Rig::new();
            for _ in 0..(600_000 / STEP_US) {
                r.tick(None);
            }
            assert!(!r.all_outputs_off(), "{stall:?}: outputs idle before the stall");
            let t_stall = r.now_us;
            let pets_before = r.iwdg.pets.len();
            while !r.iwdg.expired() {
                r.tick(Some(stall));
                assert!(
                    r.now_us - t_stall < 400_000,
                    "{stall:?}: no reset 400 ms after the stall"
                );
            }
            let t_reset = r.now_us;
            // The check at the next 50 ms may still see the beats from before the stall.
            assert!(
                r.iwdg.pets.len() - pets_before <= 1,
                "{stall:?}: petted {} times while stalled",
                r.iwdg.pets.len() - pets_before
            );
            assert!(
                t_reset - t_stall <= WATCHDOG_CHECK_SCANS * SUPERVISOR_PERIOD_US + WATCHDOG_TIMEOUT_US,
                "{stall:?}: reset {} µs after the stall",
                t_reset - t_stall
            );
            // Reset: a new composition from the calibration, the board's outputs off first.
            r.ecu = Ecu::new(EcuCoreConfig::default()).unwrap();
            r.schedule = Schedule::default();
            outputs_off(&mut r.ehvva, &mut r.evvt, &mut r.vacuum);
            assert!(r.all_outputs_off(), "{stall:?}: an output on after the reset");
            // Before its first scan every part holds its safe state (the engine still turns).
            let sh = &mut r.ecu.shared;
            let now = r.now_us + STEP_US;
            let e = r.ecu.ehvva.run(sh, &mut r.ehvva, &r.setpoints.valve, now);
            let v = r.ecu.vacuum.run(sh, &mut r.vacuum, r.setpoints.vacuum_x_pct, now);
            r.ecu.evvt.run(sh, &mut r.evvt, r.setpoints.cam_phase_deg, now);
            assert_eq!(e.pilot, SolenoidCmd::Off);
            assert!(!e.lift_valve_on && !e.snubber_switch_on);
            assert!(v.duty == [0.0; 3] && !v.pump_on, "{v:?}");
            assert!(r.all_outputs_off(), "{stall:?}: an output on before the first scan");
            // After it, the ECU runs again and pets the watchdog.
            let pets = r.iwdg.pets.len();
            for _ in 0..(300_000 / STEP_US) {
                r.tick(None);
            }
            assert!(r.iwdg.pets.len() >= pets + 5, "{stall:?}: not petted after the reset");
            assert!(r.vacuum.valves.iter().all(|v| v.duty > 0.0));
        }
    }
}
