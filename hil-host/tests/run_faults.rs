//! `hil-host run` with injected faults: each scenario file under `scenarios/fault-*.toml` runs
//! the ECU's code against the plants, and the designed safe reaction is asserted on the
//! actuator frames and the plants' states.
//!
//! Every run goes through two ECUs fed the same sensor frames, and every actuator frame of one
//! must equal the other's bit for bit: model-core's `EcuCore` (what `hil-host run` and the QEMU
//! image run), and the firmware's task layer on mock boards ([`FirmwareTasks`]): the
//! composition's parts split as `firmware/src/main.rs` splits them, each called through its
//! `run` method with boards shaped like the ECU's (a capture queue of 8 edges that drops when
//! full, an active-low driver fault pin, ADC channels read one by one, PWM outputs that clamp),
//! sharing their values through a copy-in/copy-out cell as `firmware/src/shared.rs` does. So
//! the fault reactions asserted here are those of the composition that ships.
use std::cell::Cell;

use hil_host::run::{run_with, EcuLink, NativeLink, RunOptions, RunOutput, Scenario};
use model_core::ecu::board::{AnalogIn, Capture, Edge, PwmOut, SolenoidCmd, SolenoidDriver, SwitchOut};
use model_core::ecu::frame::{ActuatorFrame, SensorFrame};
use model_core::ecu::lockstep::{setpoints_of, EcuCoreConfig};
use model_core::ecu::schedule::{
    AnalogBank, Ecu, EcuShared, EhvvaBoard, EhvvaPart, EvvtBoard, EvvtPart, Schedule, SharedAccess, SupervisorPart,
    VacuumBoard, VacuumPart, Watchdog,
};
use model_core::ecu::supervisor::{Fault, FaultSet, SupervisorConfig, N_CHANNELS};
use model_core::peak_hold::{plan, SolenoidParams};

/// A PWM output as the ECU's timers have it: the duty clamped to 0..1 (NaN to 0).
#[derive(Clone, Copy, Default)]
struct Pwm(f32);
impl PwmOut for Pwm {
    fn set_duty(&mut self, duty: f32) {
        self.0 = if duty.is_nan() { 0.0 } else { duty.clamp(0.0, 1.0) };
    }
    fn disable(&mut self) {
        self.0 = 0.0;
    }
}
#[derive(Clone, Copy, Default)]
struct Pin(bool);
impl SwitchOut for Pin {
    fn set(&mut self, on: bool) {
        self.0 = on;
    }
}
#[derive(Clone, Copy)]
struct Pilot(SolenoidCmd);
impl SolenoidDriver for Pilot {
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

/// TIM2's captures in a queue of 8 (the firmware's `Deque<Edge, 8>`), the pilot stage, the
/// lift and snubber valves.
struct EhvvaIo {
    pending: std::collections::VecDeque<Edge>,
    pilot: Pilot,
    lift: Pin,
    snubber: Pin,
}
impl Capture for EhvvaIo {
    fn next_edge(&mut self) -> Option<Edge> {
        self.pending.pop_front()
    }
}
impl EhvvaBoard for EhvvaIo {
    type Pilot = Pilot;
    type Switch = Pin;
    fn pilot(&mut self) -> &mut Pilot {
        &mut self.pilot
    }
    fn lift_valve(&mut self) -> &mut Pin {
        &mut self.lift
    }
    fn snubber_valve(&mut self) -> &mut Pin {
        &mut self.snubber
    }
}
/// PB7's speed command, PB15's level (low = fault).
struct EvvtIo {
    motor: Pwm,
    fault_pin_high: bool,
}
impl EvvtBoard for EvvtIo {
    type Motor = Pwm;
    fn motor(&mut self) -> &mut Pwm {
        &mut self.motor
    }
    fn driver_fault(&mut self) -> bool {
        !self.fault_pin_high
    }
}
struct VacuumIo {
    valves: [Pwm; 3],
    pump: Pin,
}
impl VacuumBoard for VacuumIo {
    type Valve = Pwm;
    type Pump = Pin;
    fn valves(&mut self) -> &mut [Pwm; 3] {
        &mut self.valves
    }
    fn pump(&mut self) -> &mut Pin {
        &mut self.pump
    }
}
/// ADC1: one conversion per channel read, counting the reads.
struct Adc {
    counts: [u16; N_CHANNELS],
    reads: usize,
}
struct Conversion(u16);
impl AnalogIn for Conversion {
    fn read_counts(&mut self) -> u16 {
        self.0
    }
}
impl AnalogBank for Adc {
    type In<'a> = Conversion;
    fn analog(&mut self, index: usize) -> Conversion {
        self.reads += 1;
        Conversion(self.counts[index])
    }
}
struct Iwdg {
    pets: u32,
}
impl Watchdog for Iwdg {
    fn pet(&mut self) {
        self.pets += 1;
    }
}

/// The shared values as the firmware keeps them: one cell, copied in and out per access.
struct CellShared(Cell<EcuShared>);
impl SharedAccess for &CellShared {
    fn with<R>(&mut self, f: impl FnOnce(&mut EcuShared) -> R) -> R {
        let mut v = self.0.get();
        let r = f(&mut v);
        self.0.set(v);
        r
    }
}

/// The firmware's task layer on mock boards, stepped on the lockstep grid.
struct FirmwareTasks {
    supervisor: SupervisorPart,
    ehvva: EhvvaPart,
    evvt: EvvtPart,
    vacuum: VacuumPart,
    shared: CellShared,
    schedule: Schedule,
    ehvva_io: EhvvaIo,
    evvt_io: EvvtIo,
    vacuum_io: VacuumIo,
    adc: Adc,
    iwdg: Iwdg,
}

impl FirmwareTasks {
    fn new() -> Self {
        let Ecu {
            supervisor,
            ehvva,
            evvt,
            vacuum,
            shared: _,
        } = Ecu::new(EcuCoreConfig::default()).unwrap();
        Self {
            supervisor,
            ehvva,
            evvt,
            vacuum,
            shared: CellShared(Cell::new(EcuShared::BOOT)),
            schedule: Schedule::default(),
            ehvva_io: EhvvaIo {
                pending: Default::default(),
                pilot: Pilot(SolenoidCmd::Off),
                lift: Pin(false),
                snubber: Pin(false),
            },
            evvt_io: EvvtIo {
                motor: Pwm(0.0),
                fault_pin_high: true,
            },
            vacuum_io: VacuumIo {
                valves: [Pwm(0.0); 3],
                pump: Pin(false),
            },
            adc: Adc {
                counts: [0; N_CHANNELS],
                reads: 0,
            },
            iwdg: Iwdg { pets: 0 },
        }
    }

    fn step(&mut self, s: &SensorFrame) -> ActuatorFrame {
        for e in s.edges() {
            if self.ehvva_io.pending.len() < 8 {
                self.ehvva_io.pending.push_back(*e);
            }
        }
        self.adc.counts = s.adc_counts;
        self.evvt_io.fault_pin_high = !s.motor_driver_fault;
        let set = setpoints_of(s);
        let now = s.t_us;
        let mut sh = &self.shared;
        if self.schedule.supervisor.due(now) {
            self.supervisor.run(&mut sh, &mut self.adc, &mut self.iwdg, now);
        }
        self.ehvva.run(&mut sh, &mut self.ehvva_io, &set.valve, now);
        if self.schedule.evvt.due(now) {
            self.evvt.run(&mut sh, &mut self.evvt_io, set.cam_phase_deg, now);
        }
        if self.schedule.vacuum.due(now) {
            self.vacuum.run(&mut sh, &mut self.vacuum_io, set.vacuum_x_pct, now);
        }
        ActuatorFrame {
            seq: s.seq,
            t_us: now,
            pilot: self.ehvva_io.pilot.0,
            lift_valve_on: self.ehvva_io.lift.0,
            snubber_on: self.ehvva_io.snubber.0,
            motor_duty: self.evvt_io.motor.0,
            vacuum_duty: self.vacuum_io.valves.map(|v| v.0),
            pump_on: self.vacuum_io.pump.0,
            faults: self.shared.0.get().faults.0,
            bad_frames: 0,
        }
    }
}

/// The bits of every field (f32 compared as bits, so -0.0 and NaN differences count).
fn bits(a: &ActuatorFrame) -> (u32, u32, bool, bool, u32, [u32; 3], bool, u32) {
    let pilot = match a.pilot {
        SolenoidCmd::Off => 0,
        SolenoidCmd::Full => 1,
        SolenoidCmd::Pwm(d) => 2 ^ d.to_bits(),
    };
    (
        a.seq,
        pilot,
        a.lift_valve_on,
        a.snubber_on,
        a.motor_duty.to_bits(),
        a.vacuum_duty.map(f32::to_bits),
        a.pump_on,
        a.faults,
    )
}

/// The native link, with the firmware's task layer run beside it and compared every step, and
/// the EVVT task's scheduled gain recorded per step (not in the frame).
struct Observed {
    link: NativeLink,
    firmware: FirmwareTasks,
    kp: Vec<f32>,
}

impl EcuLink for Observed {
    fn exchange(&mut self, s: &SensorFrame) -> Result<ActuatorFrame, String> {
        let a = self.link.exchange(s)?;
        let f = self.firmware.step(s);
        if bits(&a) != bits(&f) {
            return Err(format!(
                "step {} ({} µs): EcuCore {a:?}, firmware task layer {f:?}",
                s.seq, s.t_us
            ));
        }
        self.kp.push(self.link.core().evvt().map_or(0.0, |e| e.kp_rpm_per_deg));
        Ok(a)
    }
}

fn load(name: &str) -> Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../scenarios/{name}.toml"));
    Scenario::from_toml(&path, &std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn run(name: &str) -> (Scenario, RunOutput, Vec<f32>) {
    let sc = load(name);
    let mut link = Observed {
        link: NativeLink::new().unwrap(),
        firmware: FirmwareTasks::new(),
        kp: Vec::new(),
    };
    let o = run_with(
        &sc,
        &mut link,
        &RunOptions {
            until_s: None,
            keep_frames: true,
        },
    )
    .unwrap();
    // Both ECUs petted the watchdog every 50 ms (no task stalled) and read every ADC channel
    // at every 10 ms scan.
    let scans = o.frames.len().div_ceil(200);
    assert_eq!(link.firmware.adc.reads, scans * N_CHANNELS);
    assert_eq!(link.firmware.iwdg.pets as usize, scans / 5);
    assert_eq!(link.link.core().watchdog_pets(), link.firmware.iwdg.pets);
    (sc, o, link.kp)
}

const STEP_S: f64 = 50e-6;

fn t_of(k: usize) -> f64 {
    k as f64 * STEP_S
}

/// Frames with their step index between two times.
fn window(o: &RunOutput, t0: f64, t1: f64) -> impl Iterator<Item = (usize, &ActuatorFrame)> {
    o.frames
        .iter()
        .enumerate()
        .filter(move |(k, _)| t_of(*k) >= t0 && t_of(*k) < t1)
        .map(|(k, (_, a))| (k, a))
}

/// Pilot events in a window: (steps at full voltage, hold duties seen).
fn events(o: &RunOutput, t0: f64, t1: f64) -> Vec<(usize, Vec<f32>)> {
    let mut ev: Vec<(usize, Vec<f32>)> = Vec::new();
    let mut prev_off = true;
    for (_, a) in window(o, t0, t1) {
        match a.pilot {
            SolenoidCmd::Off => prev_off = true,
            SolenoidCmd::Full => {
                if prev_off {
                    ev.push((0, Vec::new()));
                }
                if let Some(e) = ev.last_mut() {
                    e.0 += 1;
                }
                prev_off = false;
            }
            SolenoidCmd::Pwm(d) => {
                if let Some(e) = ev.last_mut() {
                    e.1.push(d);
                }
                prev_off = false;
            }
        }
    }
    ev
}

fn only_faults(o: &RunOutput) -> FaultSet {
    FaultSet(o.frames.iter().fold(0, |acc, (_, a)| acc | a.faults))
}

/// The plant's lift stays at the seat in a window.
fn valve_closed(o: &RunOutput, t0: f64, t1: f64) -> bool {
    o.ehvva
        .iter()
        .filter(|r| r.t_s >= t0 && r.t_s < t1)
        .all(|r| r.lift_mm < 1e-3 && !r.u_pilot)
}

#[test]
fn battery_sag_to_8_v_is_compensated_without_a_fault() {
    let (sc, o, kp) = run("fault-battery-sag");
    // 8 V lies above the supervisor's battery-low limit: by design nothing is raised.
    let limit = SupervisorConfig::default().battery_low_v;
    assert!(limit < 8.0, "battery-low limit {limit} V");
    assert_eq!(only_faults(&o), FaultSet::default(), "{:?}", o.summary.fault_events);
    assert!((sc.u_batt_at(1.0) - 8.0).abs() < 1e-9);

    // Peak-and-hold re-planned per event from the measured voltage: peak time from the RL
    // step response, hold duty I_hold·R/U (2 Ω · 1 A / U).
    let coil = SolenoidParams::pilot_default();
    for (t0, t1, u) in [(0.2, 0.6, 14.0f32), (0.75, 1.25, 8.0)] {
        let ev = events(&o, t0, t1);
        // 1500 rpm: one event per 80 ms cycle.
        assert!(ev.len() >= 4, "{} events in {t0}..{t1} s", ev.len());
        let p = plan::<f32>(&coil, u);
        for (peak_steps, holds) in &ev[1..ev.len() - 1] {
            let peak_us = *peak_steps as f32 * 50.0;
            assert!(
                (peak_us - p.t_peak_us).abs() <= 60.0,
                "{u} V: peak {peak_us} µs, plan {} µs",
                p.t_peak_us
            );
            let hold = holds.iter().sum::<f32>() / holds.len() as f32;
            assert!(
                (hold - p.hold_duty).abs() < 0.02 * p.hold_duty,
                "{u} V: hold duty {hold} vs {}",
                p.hold_duty
            );
        }
        // The plant's coil holds about 1 A either way, so the pilot never drops out.
        let hold_rows: Vec<_> = o
            .ehvva
            .iter()
            .filter(|r| r.t_s >= t0 && r.t_s < t1 && r.pilot_duty > 0.0 && r.pilot_duty < 1.0)
            .collect();
        let i_end = hold_rows.iter().map(|r| r.coil_a).fold(f64::MAX, f64::min);
        assert!((0.9..1.1).contains(&i_end), "{u} V: lowest hold current {i_end} A");
        assert!(
            o.ehvva
                .iter()
                .filter(|r| r.t_s >= t0 && r.t_s < t1)
                .all(|r| r.u_pilot == (r.pilot_duty > 0.0)),
            "pilot dropped out at {u} V"
        );
    }
    // Without compensation the 14 V hold duty at 8 V gives 0.57 A: below the drop-out.
    assert!(f64::from(plan::<f32>(&coil, 14.0).hold_duty) * 8.0 / coil.r_ohm < 0.7);
    // The valve keeps its timing through the sag (events advanced by the same td).
    let open_err = |t0: f64, t1: f64| {
        let lifts: Vec<_> = o.ehvva.iter().filter(|r| r.t_s >= t0 && r.t_s < t1).collect();
        lifts
            .windows(2)
            .filter(|w| w[0].lift_mm < 0.075 && w[1].lift_mm >= 0.075)
            .map(|w| w[1].crank_deg - 360.0)
            .collect::<Vec<f64>>()
    };
    let (before, during) = (open_err(0.2, 0.6), open_err(0.75, 1.25));
    assert!(before.len() >= 4 && during.len() >= 5);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(
        (mean(&during) - mean(&before)).abs() < 1.0,
        "opening angle before {before:?}, during {during:?}"
    );

    // Vacuum: the compensated duty times the voltage stays the same (the valve sees duty·U),
    // and the wastegate holds its position.
    let at = |t: f64| o.vacuum.iter().find(|r| r.t_s >= t).unwrap();
    let (b, d, a) = (at(0.55), at(1.0), at(1.9));
    // After the recovery ramp the position loop (vacuum task: feedforward + PI) trims what the
    // ramp's 80 Hz lag moved through the rod's friction, so the duty does not simply return
    // to its value before (as it did feedforward only): the valves end within 0.5 % of their
    // set-points (wastegate 40 %, HPT bypass 30 %).
    let (ramped, set) = (at(1.45), [40.0, 30.0]);
    for i in 0..2 {
        let (vb, vd) = (b.duty_pct[i] * b.u_batt_v, d.duty_pct[i] * d.u_batt_v);
        assert!(
            vb > 0.0 && (vd - vb).abs() < 0.01 * vb,
            "actuator {i}: duty·U {vb} before, {vd} in the sag"
        );
        let (e_ramped, e_after) = ((ramped.x_pct[i] - set[i]).abs(), (a.x_pct[i] - set[i]).abs());
        // Measured (session 15, with the friction feedforward): wastegate 0.21 -> 0.04 %, HPT
        // bypass 0.16 -> 0.25 % (inside the integrator's 0.3 % deadband); before it the ramp
        // left about 1 % that the PI took back.
        assert!(
            e_after < 0.5,
            "actuator {i} after recovery: {e_ramped} % off at 1.45 s, {e_after} % at 1.9 s"
        );
    }
    // On the sag's plateau the wastegate stays where it was (uncompensated, the valve would
    // see 8/14 of the duty). Across the 0.1 s ramps the 80 Hz duty lags the voltage by up to
    // 0.75 V, and the rod's friction keeps what that transient moved (measured 1.2 %: the
    // friction feedforward takes the side of the ramp's transient error).
    let x_sag = o
        .vacuum
        .iter()
        .filter(|r| r.t_s > 0.75 && r.t_s < 1.3)
        .map(|r| (r.x_pct[0] - b.x_pct[0]).abs())
        .fold(0.0, f64::max);
    assert!(x_sag < 1.5, "wastegate moved {x_sag} % in the sag");

    // EVVT: the scheduled gain rises as the motor weakens, and falls back after.
    let kp_at = |t: f64| kp[(t / STEP_S) as usize];
    let (kp14, kp8, kp_after) = (kp_at(0.55), kp_at(1.0), kp_at(1.9));
    assert!(kp14 > 0.0 && kp8 > 1.15 * kp14, "kp 14 V {kp14}, 8 V {kp8}");
    assert!((kp_after - kp14).abs() < 1e-3 * kp14);
    let phase_err = o
        .evvt
        .iter()
        .filter(|r| r.t_s > 0.6)
        .map(|r| (r.phase_deg - r.phase_ref_deg).abs())
        .fold(0.0, f64::max);
    assert!(phase_err < 1.5, "phase error {phase_err} deg through the sag");
}

fn supply_pressure_sensor_fault(name: &str, counts: u16) {
    let (_, o, _) = run(name);
    // The channel really reads the faulty counts while the fault lasts.
    assert!(o
        .frames
        .iter()
        .filter(|(s, _)| (500_000..800_000).contains(&s.t_us))
        .all(|(s, _)| s.adc_counts[1] == counts));
    // Debounced 50 ms (scans every 10 ms), then latched past the sensor's recovery at 0.8 s.
    let t = o
        .summary
        .raised_at(Fault::SupplyPressureSensor)
        .expect("fault not raised");
    assert!((0.549..=0.57).contains(&t), "raised at {t}");
    assert!(
        o.frames
            .last()
            .is_some_and(|(_, a)| FaultSet(a.faults).contains(Fault::SupplyPressureSensor)),
        "not latched"
    );
    assert_eq!(only_faults(&o), {
        let mut f = FaultSet::default();
        f.insert(Fault::SupplyPressureSensor);
        f
    });
    // Pilot off, lift and snubber valves off from the fault on; the engine valve closed by its
    // spring once the event in progress has ended (td,VC + closing < 20 ms).
    for (k, a) in window(&o, t, 1.0) {
        assert_eq!(a.pilot, SolenoidCmd::Off, "pilot at {} s", t_of(k));
        assert!(!a.lift_valve_on && !a.snubber_on);
    }
    assert!(valve_closed(&o, t + 0.02, 1.0));
    // Before the fault the valve did open every cycle.
    assert!(o.ehvva.iter().any(|r| r.t_s > 0.4 && r.t_s < 0.5 && r.lift_mm > 7.0));
    // EVVT and vacuum are not concerned.
    let last = o.frames.last().unwrap().1;
    assert!(last.vacuum_duty[0] > 0.1 && last.motor_duty > 0.05);
    // (The phaser is still settling from the start-up: within 2.5 deg, then 1.5 deg.)
    assert!(o
        .evvt
        .iter()
        .filter(|r| r.t_s > 0.5)
        .all(|r| (r.phase_deg - r.phase_ref_deg).abs() < 2.5));
    assert!(o
        .evvt
        .last()
        .is_some_and(|r| (r.phase_deg - r.phase_ref_deg).abs() < 1.5));
}

#[test]
fn supply_pressure_sensor_open_closes_the_valve() {
    supply_pressure_sensor_fault("fault-supply-pressure-open", 0);
}

#[test]
fn supply_pressure_sensor_short_closes_the_valve() {
    supply_pressure_sensor_fault("fault-supply-pressure-short", 4095);
}

#[test]
fn lost_crank_signal_stops_events_and_parks_the_phaser() {
    let (_, o, _) = run("fault-crank-lost");
    // Declared lost after three gap intervals without a tooth (6 ms at 1500 rpm), raised at
    // the next supervisor scan.
    let t = o.summary.raised_at(Fault::CrankLost).expect("crank lost not raised");
    assert!((0.5..0.53).contains(&t), "raised at {t}");
    // No valve event after it, valve closed, slow valves off.
    assert!(events(&o, t, 1.5).is_empty());
    assert!(window(&o, t, 1.5).all(|(_, a)| a.pilot == SolenoidCmd::Off && !a.lift_valve_on && !a.snubber_on));
    assert!(valve_closed(&o, t + 0.02, 1.5));
    // Phaser parked: no engine speed known, so the speed command is at its bottom (the motor
    // stops, the ring gear turns the cam towards retard) and the cam reaches its retard stop.
    assert!(window(&o, t + 0.011, 1.5).all(|(_, a)| a.motor_duty == 0.0));
    let phase_at_fault = o.evvt.iter().find(|r| r.t_s >= 0.5).unwrap().phase_deg;
    assert!(phase_at_fault > 18.0, "phase {phase_at_fault} before the fault");
    let end = o.evvt.last().unwrap().phase_deg;
    assert!(end < 0.5, "phase {end} deg at the end");
    // The vacuum side goes on.
    assert!(o.frames.last().unwrap().1.vacuum_duty[0] > 0.1);
}

#[test]
fn stuck_wastegate_is_flagged_and_the_vacuum_side_goes_safe() {
    let (_, o, _) = run("fault-vacuum-stuck");
    let x_stuck = o.vacuum.iter().find(|r| r.t_s >= 0.5).unwrap().x_pct[0];
    assert!(
        o.vacuum.iter().filter(|r| r.t_s >= 0.5).all(|r| r.x_pct[0] == x_stuck),
        "rod moved"
    );
    // The observer leaves the measurement behind once the set-point steps at 0.6 s; the flag
    // needs 1 s beyond 15 %, the supervisor's debounce 50 ms.
    let t = o
        .summary
        .raised_at(Fault::VacuumActuatorStuck)
        .expect("stuck not raised");
    assert!((1.6..1.8).contains(&t), "raised at {t}");
    assert_eq!(only_faults(&o).0, 1 << Fault::VacuumActuatorStuck as u32);
    // Before: the HPT bypass driven to its set-point; after: every valve unpowered.
    let hpt_before = o.vacuum.iter().find(|r| r.t_s >= 0.55).unwrap();
    assert!(hpt_before.duty_pct[1] > 10.0 && hpt_before.x_pct[1] > 10.0);
    assert!(window(&o, t, 2.5).all(|(_, a)| a.vacuum_duty == [0.0; 3]));
    let end = o.vacuum.last().unwrap();
    assert!(end.x_pct[1] < 2.0, "HPT bypass at {} %", end.x_pct[1]);
    // Valve events and phase control go on.
    assert!(events(&o, t, 2.5).len() >= 8);
    assert!((end.t_s - 2.5).abs() < 0.01 && (o.evvt.last().unwrap().phase_deg - 20.0).abs() < 1.5);
}

#[test]
fn vacuum_pump_failure_raises_the_tank_pressure_and_the_leak_flag() {
    let (_, o, _) = run("fault-vacuum-pump");
    // The tank starts above what the set-points need: the pump is on when it fails.
    let at = |t: f64| o.vacuum.iter().find(|r| r.t_s >= t).unwrap();
    assert!(
        at(0.4).pump_on && at(0.4).p_tank_kpa < 60.0,
        "pump {} tank {}",
        at(0.4).pump_on,
        at(0.4).p_tank_kpa
    );
    // From the failure on the tank pressure only rises although the pump is switched on.
    let rising: Vec<_> = o.vacuum.iter().filter(|r| r.t_s > 0.55 && r.t_s < 3.9).collect();
    assert!(rising.iter().all(|r| r.pump_on));
    assert!(rising.windows(2).all(|w| w[1].p_tank_kpa >= w[0].p_tank_kpa));
    assert!(
        at(3.9).p_tank_kpa > at(0.55).p_tank_kpa + 0.5,
        "tank {} -> {}",
        at(0.55).p_tank_kpa,
        at(3.9).p_tank_kpa
    );
    // Two abnormal 2 s residual windows: flagged at 4 s.
    let t = o.summary.raised_at(Fault::AbnormalLeak).expect("leak not raised");
    assert!((3.95..4.1).contains(&t), "raised at {t}");
    // Safe: pump off, valves unpowered, the wastegate back at its spring position.
    assert!(window(&o, t, 5.0).all(|(_, a)| !a.pump_on && a.vacuum_duty == [0.0; 3]));
    assert!(o.vacuum.last().unwrap().x_pct[0] < 2.0);
    // Valves and phaser go on.
    assert!(events(&o, t, 5.0).len() >= 10);
}

#[test]
fn motor_driver_fault_pin_parks_the_phaser() {
    let (_, o, _) = run("fault-motor-driver");
    // Not a supervisor fault: the EVVT task reacts to the pin itself.
    assert_eq!(only_faults(&o), FaultSet::default());
    let phase_at_fault = o.evvt.iter().find(|r| r.t_s >= 1.0).unwrap().phase_deg;
    assert!((phase_at_fault - 20.0).abs() < 1.5);
    // From the next 10 ms tick: motor at ring speed + the park command (−100 rpm).
    for (k, a) in window(&o, 1.011, 2.0) {
        let motor_rpm = a.motor_duty * 6000.0;
        assert!(
            (motor_rpm - (750.0 - 100.0)).abs() < 5.0,
            "motor {motor_rpm} rpm at {} s",
            t_of(k)
        );
    }
    // The phase moves towards the retard stop.
    let end = o.evvt.last().unwrap().phase_deg;
    assert!(end < phase_at_fault - 5.0, "phase {phase_at_fault} -> {end}");
    // Valve events and vacuum go on.
    assert!(events(&o, 1.0, 2.0).len() >= 11);
    assert!(o.frames.last().unwrap().1.vacuum_duty[0] > 0.1);
}

/// The default scenario (speed ramps, phase and wastegate steps, battery sag) closed loop over
/// its 10 s: the firmware's task layer equals `EcuCore` in every actuator frame (checked in
/// `run`), valve events happen and no fault is raised.
#[test]
fn default_scenario_runs_the_same_composition_on_the_firmware_task_layer() {
    let (sc, o, _) = run("default");
    assert_eq!(o.frames.len() as f64, (sc.duration_s / STEP_S).round());
    assert_eq!(only_faults(&o), FaultSet::default(), "{:?}", o.summary.fault_events);
    assert!(events(&o, 0.0, sc.duration_s).len() > 50);
}
