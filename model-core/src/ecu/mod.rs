//! The ECU firmware's hardware-free logic: one synchronous state machine per task
//! (`fn step(&mut self, inputs, now) -> outputs`), written against the small traits of
//! [`board`], so that the embassy tasks on the ECU board and on an emulated board are a few
//! lines of glue and everything here is tested on the host.
//!
//! - [`ehvva_task`]: crank/cam decoding, valve events in the crank-angle domain advanced by
//!   the LPV model's delay td(Ph, T), pilot peak-and-hold, lift and snubber switch valves.
//! - [`evvt_task`]: cam phase from the edges, scheduled cam phase control, motor speed command.
//! - [`vacuum_task`]: 80 Hz duty from the inverse actuator model with supply-voltage
//!   compensation, pump on the needed pressure, tank leak residual, stuck actuators.
//! - [`supervisor`]: ADC range checks, fault debouncing, the safe state of each actuator.
//! - [`lockstep`] and [`frame`]: the whole ECU as one function of sensor frames, and the
//!   CRC-checked frames that carry them over a UART (hardware/processor in the loop).
//!
//! Everything runs in f32 (the target's FPU type).

pub mod board;
pub mod ehvva_task;
pub mod evvt_task;
pub mod frame;
pub mod lockstep;
pub mod supervisor;
pub mod vacuum_task;

/// Every fault reaction end to end on the test doubles: the four state machines wired like
/// the firmware's tasks (read the doubles, step, write the doubles), a fault injected through
/// the doubles, and the outputs checked against the fault's safe state.
#[cfg(test)]
mod fault_reactions {
    use super::board::doubles::{FakeAnalog, FakePwm, FakeSolenoid, FakeSwitch};
    use super::board::{AnalogIn, Edge, EdgeSource, PwmOut, SolenoidCmd, SolenoidDriver, SwitchOut};
    use super::ehvva_task::{EhvvaStepInputs, EhvvaTask, EhvvaTaskConfig, ValveRequest};
    use super::evvt_task::{EvvtTask, EvvtTaskConfig, EvvtTaskInputs};
    use super::supervisor::{Channel, Fault, Measurements, Supervisor, SupervisorConfig, TaskReports, N_CHANNELS};
    use super::vacuum_task::{VacuumTask, VacuumTaskConfig, VacuumTaskInputs};
    use crate::vacuum::{VacuumEffects, VacuumParams, VacuumSystem, VacuumTankParams};

    const RPM: f64 = 1500.0;
    const STEP_US: u32 = 50;

    struct Bench {
        adc: [FakeAnalog; N_CHANNELS],
        /// Channels a test has taken over (a wiring fault); the rest follow the plant.
        forced: [bool; N_CHANNELS],
        /// The vacuum system the valve doubles drive; it sets the tank and position readings.
        plant: VacuumSystem<f32>,
        pilot: FakeSolenoid,
        lift: FakeSwitch,
        snubber: FakeSwitch,
        motor: FakePwm,
        valves: [FakePwm; 3],
        pump: FakeSwitch,
        sup: Supervisor,
        ehvva: EhvvaTask<(f32, f32)>,
        evvt: EvvtTask,
        vacuum: VacuumTask,
        meas: Measurements,
        /// (stuck, abnormal leak) from the last vacuum step, for the supervisor.
        last_vacuum: (bool, bool),
        t_us: u32,
        next_tooth: u32,
        crank_signal: bool,
        fault_set_at_us: Option<u32>,
    }

    impl Bench {
        fn new() -> Self {
            let cfg = SupervisorConfig::default();
            let values = [13.8, 6.0, 2.0, 80.0, 40.0, 100.0, 20.0, 40.0, 60.0, 50.0];
            let adc = core::array::from_fn(|k| FakeAnalog { counts: cfg.scales[k].counts_for(values[k]) });
            let e = VacuumEffects { supply_voltage: true, ..VacuumEffects::NONE };
            let actuators = [VacuumParams::lpt().with_effects(e), VacuumParams::hpt().with_effects(e), VacuumParams::hpc().with_effects(e)];
            let tank = VacuumTankParams::paper();
            Self {
                adc,
                forced: [false; N_CHANNELS],
                plant: VacuumSystem::new(&actuators[0], &actuators[1], &actuators[2], &tank, 40.0).unwrap(),
                pilot: FakeSolenoid::default(),
                lift: FakeSwitch::default(),
                snubber: FakeSwitch::default(),
                motor: FakePwm::default(),
                valves: [FakePwm::default(); 3],
                pump: FakeSwitch::default(),
                sup: Supervisor::new(cfg),
                ehvva: EhvvaTask::new(EhvvaTaskConfig::default(), (3.5, 3.0)).unwrap(),
                evvt: EvvtTask::new(EvvtTaskConfig::default()).unwrap(),
                vacuum: VacuumTask::new(VacuumTaskConfig { actuators, ..Default::default() }).unwrap(),
                meas: Measurements::default(),
                last_vacuum: (false, false),
                t_us: 0,
                next_tooth: 1,
                crank_signal: true,
                fault_set_at_us: None,
            }
        }

        fn set_channel(&mut self, ch: Channel, counts: u16) {
            self.adc[ch as usize].counts = counts;
            self.forced[ch as usize] = true;
        }

        /// Sensor readings from the plant, except where a test forced a channel.
        fn plant_readings(&mut self) {
            let x = [self.plant.lpt.x_pct(), self.plant.hpt.x_pct(), self.plant.hpc.x_pct()];
            let readings = [
                (Channel::TankPressureKpa, self.plant.tank.p_tank_kpa()),
                (Channel::LptPositionPct, x[0]),
                (Channel::HptPositionPct, x[1]),
                (Channel::HpcPositionPct, x[2]),
            ];
            for (ch, v) in readings {
                let k = ch as usize;
                if !self.forced[k] {
                    self.adc[k].counts = SupervisorConfig::default().scales[k].counts_for(v);
                }
            }
        }

        /// Crank edges of a 60-2 wheel at constant speed; the cam edge 1 µs after the tooth at
        /// cycle angle 438 deg (phase 450 − 438 = 12 deg, so the phase loop is working).
        fn feed_edges(&mut self) {
            let us_per_deg = 1e6 / (RPM * 6.0);
            loop {
                let angle = self.next_tooth as f64 * 6.0;
                let t = (angle * us_per_deg) as u32;
                if t > self.t_us {
                    break;
                }
                let in_rev = self.next_tooth % 60;
                if self.crank_signal && in_rev < 58 {
                    self.ehvva.on_edge(Edge { source: EdgeSource::CrankTooth, t_us: t });
                }
                if self.crank_signal && self.next_tooth % 120 == 73 {
                    self.ehvva.on_edge(Edge { source: EdgeSource::CamSync, t_us: t + 1 });
                }
                self.next_tooth += 1;
            }
        }

        /// One 50 µs tick: EHVVA every tick, the others at their rates, like the firmware.
        fn tick(&mut self) {
            self.t_us += STEP_US;
            let now = self.t_us;
            self.feed_edges();
            let m;
            {
                let mut counts = [0u16; N_CHANNELS];
                for (c, a) in counts.iter_mut().zip(self.adc.iter_mut()) {
                    *c = a.read_counts();
                }
                if now % 10_000 == 0 {
                    let e = self.ehvva.decoder().snapshot();
                    let v = self.last_vacuum;
                    let rep = TaskReports { crank_lost: e.crank_lost, cam_lost: e.cam_lost, vacuum_stuck: v.0, abnormal_leak: v.1 };
                    let out = self.sup.step(&counts, &rep, now);
                    if !out.newly_set.is_empty() && self.fault_set_at_us.is_none() {
                        self.fault_set_at_us = Some(now);
                    }
                    self.meas = out.measurements;
                }
                m = self.meas;
            }
            let safe = self.sup.active().safe_state();
            let req = ValveRequest { open_deg: 100.0, close_deg: 400.0, high_lift: true, soft_seat: true, enabled: true };
            let inp = EhvvaStepInputs { request: req, p_supply_mpa: m.p_supply_mpa, temp_oil_c: m.temp_oil_c, u_batt_v: m.u_batt_v, force_safe: safe.ehvva_closed };
            let o = self.ehvva.step(&inp, now);
            self.pilot.now_us = now;
            self.pilot.apply(o.pilot);
            self.lift.set(o.lift_valve_on);
            self.snubber.set(o.snubber_switch_on);
            if now % 10_000 == 0 {
                let i = EvvtTaskInputs {
                    engine: o.engine,
                    setpoint_deg: 20.0,
                    u_batt_v: m.u_batt_v,
                    faults: self.sup.active(),
                    motor_driver_fault: false,
                };
                let e = self.evvt.step(&i, now);
                self.motor.set_duty(e.motor_duty);
            }
            if now % 12_500 == 0 {
                let i = VacuumTaskInputs {
                    x_set_pct: [20.0, 40.0, 60.0],
                    x_meas_pct: m.x_pct,
                    p_tank_kpa: m.p_tank_kpa,
                    p_amb_kpa: m.p_amb_kpa,
                    u_batt_v: m.u_batt_v,
                    safe,
                };
                let v = self.vacuum.step(&i, now);
                for (p, d) in self.valves.iter_mut().zip(v.duty) {
                    p.set_duty(d);
                }
                self.pump.set(v.pump_on);
                let duties = [0, 1, 2].map(|k| self.valves[k].duty * 100.0);
                self.plant.step(duties, m.u_batt_v, 100.0, self.pump.on, 0.0125);
                self.plant_readings();
                self.last_vacuum = (v.stuck.iter().any(|s| *s), v.abnormal_leak);
            }
        }

        fn run_ms(&mut self, ms: u32) {
            for _ in 0..(ms * 1000 / STEP_US) {
                self.tick();
            }
        }
    }

    /// Runs healthy for 0.6 s (events, control and valves active), injects a fault through
    /// the doubles, runs 1.2 s more (the longest debounce is 1 s) and checks every output
    /// against the fault's safe state: what must be safe is, and what need not be still works.
    fn check(name: &str, inject: impl FnOnce(&mut Bench), expected_fault: Fault) {
        let mut b = Bench::new();
        b.run_ms(600);
        assert!(b.sup.active().is_empty(), "{name}: healthy phase raised {:?}", b.sup.active());
        assert!(b.pilot.log.iter().any(|(_, c)| *c == SolenoidCmd::Full), "{name}: no valve event before the fault");
        assert!(b.valves.iter().all(|v| v.duty > 0.0), "{name}: vacuum valves idle before the fault");
        inject(&mut b);
        b.run_ms(1200);
        let active = b.sup.active();
        assert!(active.contains(expected_fault), "{name}: {expected_fault:?} not set");
        assert_eq!(active.iter().count(), 1, "{name}: more faults than expected");
        let safe = active.safe_state();
        assert_eq!(safe, expected_fault.reaction());
        let t_set = b.fault_set_at_us.unwrap();
        if safe.ehvva_closed {
            // No pilot drive after the fault was set (one EHVVA step later at most).
            let late = b.pilot.log.iter().filter(|(t, c)| *t > t_set + STEP_US && *c != SolenoidCmd::Off).count();
            assert_eq!(late, 0, "{name}: pilot driven after the fault");
            assert_eq!(b.pilot.current(), SolenoidCmd::Off);
            assert!(!b.lift.on && !b.snubber.on, "{name}: slow valves on");
        } else {
            assert!(b.pilot.log.iter().any(|(t, c)| *t > t_set && *c == SolenoidCmd::Full), "{name}: EHVVA stopped needlessly");
        }
        // Park: ring speed (half the engine speed, 0 once the crank signal is gone) − 100 rpm.
        let rpm = b.ehvva.decoder().snapshot().rpm;
        let park_duty = ((rpm / 2.0 - 100.0) / 6000.0).max(0.0);
        if safe.evvt_parked {
            assert!((b.motor.duty - park_duty).abs() < 1e-4, "{name}: motor duty {} (park {park_duty})", b.motor.duty);
        } else {
            assert!((b.motor.duty - park_duty).abs() > 1e-3, "{name}: parked needlessly");
        }
        if safe.vacuum_spring_open {
            assert!(b.valves.iter().all(|v| v.duty == 0.0), "{name}: vacuum valves driven");
        } else {
            assert!(b.valves.iter().all(|v| v.duty > 0.0), "{name}: vacuum valves released needlessly");
        }
        if safe.pump_off {
            assert!(!b.pump.on, "{name}: pump on");
        }
    }

    #[test]
    fn each_fault_drives_its_safe_state_on_the_doubles() {
        let cfg = SupervisorConfig::default();
        let counts = |ch: Channel, v: f32| cfg.scales[ch as usize].counts_for(v);
        check("battery low", |b| b.set_channel(Channel::BatteryV, counts(Channel::BatteryV, 6.0)), Fault::BatteryLow);
        check("battery high", |b| b.set_channel(Channel::BatteryV, counts(Channel::BatteryV, 24.0)), Fault::BatteryHigh);
        check("supply pressure open", |b| b.set_channel(Channel::SupplyPressureMpa, 0), Fault::SupplyPressureSensor);
        check("back pressure short", |b| b.set_channel(Channel::BackPressureMpa, 4095), Fault::BackPressureSensor);
        check("oil temperature open", |b| b.set_channel(Channel::OilTempC, 0), Fault::OilTempSensor);
        check("tank pressure short", |b| b.set_channel(Channel::TankPressureKpa, 4095), Fault::TankPressureSensor);
        check("ambient pressure open", |b| b.set_channel(Channel::AmbientPressureKpa, 0), Fault::AmbientPressureSensor);
        check("position sensor open", |b| b.set_channel(Channel::HptPositionPct, 0), Fault::VacuumPositionSensor);
        check("ECU over-temperature", |b| b.set_channel(Channel::EcuTempC, counts(Channel::EcuTempC, 125.0)), Fault::OverTemperature);
        check("crank signal lost", |b| b.crank_signal = false, Fault::CrankLost);
    }
}
