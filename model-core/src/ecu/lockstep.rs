//! The whole ECU as one synchronous function of frames, for lockstep HIL: the host's native
//! run and the emulated MCU under QEMU both call [`EcuCore::step`] once per [`STEP_US`] with a
//! [`SensorFrame`] and apply the [`ActuatorFrame`] it returns, so the two runs of a scenario
//! can be compared step by step.
//!
//! `EcuCore` is a thin driver of the one composition, [`super::schedule::Ecu`]: the sensor
//! frame and the actuator frame are its board ([`FrameBoard`]: the frame's edges are the
//! capture timer, its counts the ADC, its set-points the engine management, the actuator
//! frame the output pins, which hold their value between the parts' runs as the ECU's do),
//! and [`Ecu::step_on`] runs the parts' `run` methods, the ones the firmware's tasks call, on
//! the lockstep grid: the supervisor and the EVVT part every 10 ms, the vacuum part every
//! 12.5 ms, the EHVVA part every step (on the ECU it runs on crank edges and its own
//! deadlines; 50 µs is 0.45 crank degrees at 1500 rpm).

use super::board::{AnalogIn, Capture, Edge, PwmOut, SolenoidCmd, SolenoidDriver, SwitchOut};
use super::calibration::CALIBRATION_FAULT_BIT;
use super::ehvva_task::{EhvvaTaskConfig, EngineSnapshot};
use super::evvt_task::{EvvtTaskConfig, EvvtTaskOutputs};
use super::frame::{ActuatorFrame, SensorFrame, MAX_EDGES};
use super::schedule::{AnalogBank, Boards, Ecu, EhvvaBoard, EvvtBoard, Schedule, Setpoints, VacuumBoard, Watchdog};
use super::supervisor::{FaultSet, Measurements, SupervisorConfig, N_CHANNELS};
use super::vacuum_task::{VacuumTaskConfig, VacuumTaskOutputs};
use crate::ehvva::{EhvvaParams, ValveMotionData};

pub use super::schedule::{StepPart, EVVT_PERIOD_US, SUPERVISOR_PERIOD_US, VACUUM_PERIOD_US};

/// The lockstep period.
pub const STEP_US: u32 = 50;

/// The calibration of every task (the firmware's defaults).
#[derive(Clone, Debug)]
pub struct EcuCoreConfig {
    /// ADC scales, battery and temperature limits.
    pub supervisor: SupervisorConfig,
    /// Trigger wheel, pilot coil, speed range, slow-valve timing.
    pub ehvva: EhvvaTaskConfig,
    /// The valve model whose delay tables td(Ph, T) advance the pilot command.
    pub ehvva_model: EhvvaParams,
    /// The valve's own motion after td (added to the pilot edges' advance).
    pub ehvva_motion: ValveMotionData,
    /// Cam phase controller and phase measurement.
    pub evvt: EvvtTaskConfig,
    /// Vacuum actuator models, position control, pump and diagnosis.
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

/// One output pin that remembers what it was told (a PWM duty, a switch).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Latch<T>(pub T);

impl PwmOut for Latch<f32> {
    fn set_duty(&mut self, duty: f32) {
        // The duty as the task computed it (the frame carries it; the board clamps).
        self.0 = duty;
    }
    fn disable(&mut self) {
        self.0 = 0.0;
    }
}

impl SwitchOut for Latch<bool> {
    fn set(&mut self, on: bool) {
        self.0 = on;
    }
}

impl SolenoidDriver for Latch<SolenoidCmd> {
    fn off(&mut self) {
        self.0 = SolenoidCmd::Off;
    }
    fn full_on(&mut self) {
        self.0 = SolenoidCmd::Full;
    }
    fn pwm(&mut self, duty: f32) {
        self.0 = SolenoidCmd::Pwm(duty);
    }
}

impl AnalogIn for Latch<u16> {
    fn read_counts(&mut self) -> u16 {
        self.0
    }
}

/// The EHVVA part's side of [`FrameBoard`].
#[derive(Clone, Copy, Debug)]
pub struct FrameEhvva {
    edges: [Edge; MAX_EDGES],
    n_edges: usize,
    next_edge: usize,
    /// The pilot stage's last command.
    pub pilot: Latch<SolenoidCmd>,
    /// The lift valve.
    pub lift: Latch<bool>,
    /// The snubber switch valve.
    pub snubber: Latch<bool>,
}

impl Capture for FrameEhvva {
    fn next_edge(&mut self) -> Option<Edge> {
        if self.next_edge >= self.n_edges {
            return None;
        }
        let e = self.edges.get(self.next_edge).copied();
        self.next_edge += 1;
        e
    }
}

impl EhvvaBoard for FrameEhvva {
    type Pilot = Latch<SolenoidCmd>;
    type Switch = Latch<bool>;
    fn pilot(&mut self) -> &mut Self::Pilot {
        &mut self.pilot
    }
    fn lift_valve(&mut self) -> &mut Self::Switch {
        &mut self.lift
    }
    fn snubber_valve(&mut self) -> &mut Self::Switch {
        &mut self.snubber
    }
}

/// The EVVT part's side of [`FrameBoard`].
#[derive(Clone, Copy, Debug)]
pub struct FrameEvvt {
    driver_fault: bool,
    /// The speed command's duty.
    pub motor: Latch<f32>,
}

impl EvvtBoard for FrameEvvt {
    type Motor = Latch<f32>;
    fn motor(&mut self) -> &mut Self::Motor {
        &mut self.motor
    }
    fn driver_fault(&mut self) -> bool {
        self.driver_fault
    }
}

/// The vacuum part's side of [`FrameBoard`].
#[derive(Clone, Copy, Debug)]
pub struct FrameVacuum {
    /// LPT, HPT, HPC valve duties.
    pub valves: [Latch<f32>; 3],
    /// The pump relay.
    pub pump: Latch<bool>,
}

impl VacuumBoard for FrameVacuum {
    type Valve = Latch<f32>;
    type Pump = Latch<bool>;
    fn valves(&mut self) -> &mut [Self::Valve; 3] {
        &mut self.valves
    }
    fn pump(&mut self) -> &mut Self::Pump {
        &mut self.pump
    }
}

/// The ADC of [`FrameBoard`]: the frame's counts.
#[derive(Clone, Copy, Debug)]
pub struct FrameAdc(pub [u16; N_CHANNELS]);

impl AnalogBank for FrameAdc {
    type In<'a> = Latch<u16>;
    fn analog(&mut self, index: usize) -> Latch<u16> {
        Latch(self.0.get(index).copied().unwrap_or(0))
    }
}

/// Counts the pets (lockstep has no reset: the count is for tests and logs).
#[derive(Clone, Copy, Debug, Default)]
pub struct PetCounter(pub u32);

impl Watchdog for PetCounter {
    fn pet(&mut self) {
        self.0 = self.0.wrapping_add(1);
    }
}

/// The sensor frame and the actuator frame as the ECU's board: inputs replaced by each frame,
/// outputs held between the parts' runs (all off at start, as on the ECU at boot).
#[derive(Clone, Copy, Debug)]
pub struct FrameBoard {
    /// Edges in, pilot, lift and snubber out.
    pub ehvva: FrameEhvva,
    /// Driver fault pin in, speed command out.
    pub evvt: FrameEvvt,
    /// Valves and pump out.
    pub vacuum: FrameVacuum,
    /// The frame's ADC counts.
    pub adc: FrameAdc,
    /// The watchdog's pets.
    pub watchdog: PetCounter,
}

impl Default for FrameBoard {
    fn default() -> Self {
        Self {
            ehvva: FrameEhvva {
                edges: [SensorFrame::NO_EDGE; MAX_EDGES],
                n_edges: 0,
                next_edge: 0,
                pilot: Latch(SolenoidCmd::Off),
                lift: Latch(false),
                snubber: Latch(false),
            },
            evvt: FrameEvvt {
                driver_fault: false,
                motor: Latch(0.0),
            },
            vacuum: FrameVacuum {
                valves: [Latch(0.0); 3],
                pump: Latch(false),
            },
            adc: FrameAdc([0; N_CHANNELS]),
            watchdog: PetCounter(0),
        }
    }
}

impl FrameBoard {
    /// The inputs of `s` (edges, counts, driver fault pin).
    pub fn load(&mut self, s: &SensorFrame) {
        self.ehvva.edges = s.edges;
        self.ehvva.n_edges = (s.n_edges as usize).min(MAX_EDGES);
        self.ehvva.next_edge = 0;
        self.adc = FrameAdc(s.adc_counts);
        self.evvt.driver_fault = s.motor_driver_fault;
    }

    /// The outputs as an actuator frame answering `seq` at `t_us`.
    pub fn outputs(&self, seq: u32, t_us: u32, faults: FaultSet) -> ActuatorFrame {
        ActuatorFrame {
            seq,
            t_us,
            pilot: self.ehvva.pilot.0,
            lift_valve_on: self.ehvva.lift.0,
            snubber_on: self.ehvva.snubber.0,
            motor_duty: self.evvt.motor.0,
            vacuum_duty: self.vacuum.valves.map(|v| v.0),
            pump_on: self.vacuum.pump.0,
            faults: faults.0,
            bad_frames: 0,
        }
    }
}

impl FrameBoard {
    /// Every part's board.
    pub fn boards(&mut self) -> Boards<'_, FrameEhvva, FrameEvvt, FrameVacuum, FrameAdc, PetCounter> {
        Boards {
            ehvva: &mut self.ehvva,
            evvt: &mut self.evvt,
            vacuum: &mut self.vacuum,
            adc: &mut self.adc,
            watchdog: &mut self.watchdog,
        }
    }
}

/// The set-points a sensor frame carries.
pub fn setpoints_of(s: &SensorFrame) -> Setpoints {
    Setpoints {
        valve: s.valve,
        cam_phase_deg: s.cam_phase_set_deg,
        vacuum_x_pct: s.vacuum_x_set_pct,
    }
}

/// The composition ([`Ecu`]) on the lockstep grid with the frames as its board.
#[derive(Clone, Debug)]
pub struct EcuCore {
    ecu: Ecu,
    schedule: Schedule,
    board: FrameBoard,
    started: bool,
    last_evvt: Option<EvvtTaskOutputs>,
    last_vacuum: Option<VacuumTaskOutputs>,
    /// Fault bits outside the supervisor's ([`CALIBRATION_FAULT_BIT`]).
    extra_faults: u32,
}

impl EcuCore {
    /// The composition from `cfg`; an error names the part of the calibration refused.
    pub fn new(cfg: EcuCoreConfig) -> Result<Self, &'static str> {
        let extra_faults = if cfg.calibration_fault {
            CALIBRATION_FAULT_BIT
        } else {
            0
        };
        Ok(Self {
            extra_faults,
            ecu: Ecu::new(cfg)?,
            schedule: Schedule::default(),
            board: FrameBoard::default(),
            started: false,
            last_evvt: None,
            last_vacuum: None,
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
    pub fn step_probed(&mut self, s: &SensorFrame, probe: impl FnMut(StepPart, bool)) -> ActuatorFrame {
        self.board.load(s);
        let r = self
            .ecu
            .step_on(&mut self.schedule, self.board.boards(), &setpoints_of(s), s.t_us, probe);
        self.started = true;
        if r.evvt.is_some() {
            self.last_evvt = r.evvt;
        }
        if r.vacuum.is_some() {
            self.last_vacuum = r.vacuum;
        }
        let mut out = self.board.outputs(s.seq, s.t_us, self.ecu.shared.faults);
        out.faults |= self.extra_faults;
        out
    }

    /// The supervisor's converted measurements of its last scan.
    pub fn measurements(&self) -> Measurements {
        self.ecu.shared.measurements
    }
    /// The supervisor's active faults.
    pub fn faults(&self) -> FaultSet {
        self.ecu.shared.faults
    }
    /// The crank decoder's view of the engine after the last step (`None` before the first).
    pub fn engine(&self) -> Option<EngineSnapshot> {
        self.started.then_some(self.ecu.shared.engine)
    }
    /// The EVVT task's last outputs (measured phase, mode, scheduled gain).
    pub fn evvt(&self) -> Option<EvvtTaskOutputs> {
        self.last_evvt
    }
    /// The vacuum task's last outputs (pump target, leak residual, stuck flags).
    pub fn vacuum(&self) -> Option<VacuumTaskOutputs> {
        self.last_vacuum
    }
    /// How often the supervisor petted the watchdog (every 50 ms while every task runs).
    pub fn watchdog_pets(&self) -> u32 {
        self.board.watchdog.0
    }
    /// The composition (parts and shared values).
    pub fn ecu(&self) -> &Ecu {
        &self.ecu
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

    use crate::ecu::schedule::Period;

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
