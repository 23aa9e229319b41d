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
//! - [`calibration`]: the calibration image (tables and constants learned from a unit's
//!   bench logs) the ECU reads at boot, with its checks.
//! - [`crank_sim`]: the crank and cam edges a turning engine produces (for benches).
//! - [`schedule`]: the one composition of these tasks (what they share, periods, order,
//!   input assembly from the board, watchdog decision) that the firmware, the QEMU image and
//!   the host runs all execute.
//! - [`lockstep`] and [`frame`]: the whole ECU as one function of sensor frames (the
//!   composition with the frames as its board), and the CRC-checked frames that carry them
//!   over a UART (hardware/processor in the loop).
//!
//! Everything runs in f32 (the target's FPU type).

pub mod board;
pub mod calibration;
pub mod crank_sim;
pub mod ehvva_task;
pub mod evvt_task;
pub mod frame;
pub mod lockstep;
pub mod schedule;
pub mod supervisor;
pub mod vacuum_task;

/// Every fault reaction end to end on the test doubles: the whole ECU ([`lockstep::EcuCore`],
/// the composition [`schedule::Ecu`] the firmware runs) fed by a turning engine and the
/// doubles' readings, its outputs written to the doubles, a fault injected through them, and
/// the outputs checked against the fault's safe state.
#[cfg(test)]
mod fault_reactions {
    use super::board::doubles::{FakePwm, FakeSolenoid, FakeSwitch};
    use super::board::{PwmOut, SolenoidCmd, SolenoidDriver, SwitchOut};
    use super::crank_sim::CrankSignal;
    use super::ehvva_task::{TriggerWheel, ValveRequest};
    use super::frame::{SensorFrame, MAX_EDGES};
    use super::lockstep::{EcuCore, EcuCoreConfig, STEP_US};
    use super::supervisor::{Channel, Fault, SupervisorConfig, N_CHANNELS};
    use super::vacuum_task::VacuumTaskConfig;
    use crate::vacuum::{VacuumEffects, VacuumParams, VacuumSystem, VacuumTankParams};

    const RPM: f64 = 1500.0;
    /// The cam edge's cycle angle: phase 450 − 438 = 12 deg, so the phase loop is working.
    const CAM_CYCLE_DEG: f64 = 438.0;

    struct Bench {
        counts: [u16; N_CHANNELS],
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
        ecu: EcuCore,
        engine: CrankSignal,
        t_us: u32,
        crank_signal: bool,
        fault_set_at_us: Option<u32>,
    }

    impl Bench {
        fn new() -> Self {
            let cfg = SupervisorConfig::default();
            let values = [13.8, 6.0, 2.0, 80.0, 40.0, 100.0, 20.0, 40.0, 60.0, 50.0];
            let e = VacuumEffects {
                supply_voltage: true,
                ..VacuumEffects::NONE
            };
            let actuators = [
                VacuumParams::lpt().with_effects(e),
                VacuumParams::hpt().with_effects(e),
                VacuumParams::hpc().with_effects(e),
            ];
            let tank = VacuumTankParams::paper();
            let ecu_cfg = EcuCoreConfig {
                vacuum: VacuumTaskConfig {
                    actuators,
                    ..Default::default()
                },
                ..Default::default()
            };
            Self {
                counts: core::array::from_fn(|k| cfg.scales[k].counts_for(values[k])),
                forced: [false; N_CHANNELS],
                plant: VacuumSystem::new(&actuators[0], &actuators[1], &actuators[2], &tank, 40.0).unwrap(),
                pilot: FakeSolenoid::default(),
                lift: FakeSwitch::default(),
                snubber: FakeSwitch::default(),
                motor: FakePwm::default(),
                valves: [FakePwm::default(); 3],
                pump: FakeSwitch::default(),
                ecu: EcuCore::new(ecu_cfg).unwrap(),
                engine: CrankSignal::new(TriggerWheel::sixty_minus_two(), 0.0),
                t_us: 0,
                crank_signal: true,
                fault_set_at_us: None,
            }
        }

        fn set_channel(&mut self, ch: Channel, counts: u16) {
            self.counts[ch as usize] = counts;
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
                    self.counts[k] = SupervisorConfig::default().scales[k].counts_for(v);
                }
            }
        }

        /// One 50 µs lockstep step: the edges and readings into the ECU, its outputs onto the
        /// doubles; the vacuum plant follows the valve doubles at the vacuum task's 80 Hz.
        fn tick(&mut self) {
            let t0 = self.t_us;
            self.t_us += STEP_US;
            let now = self.t_us;
            let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
            let crank_ok = self.crank_signal;
            let n = self
                .engine
                .advance(RPM, STEP_US, CAM_CYCLE_DEG, crank_ok, crank_ok, t0, &mut edges);
            let frame = SensorFrame {
                seq: now / STEP_US,
                t_us: now,
                n_edges: n.min(MAX_EDGES) as u8,
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
            };
            let out = self.ecu.step(&frame);
            if out.faults != 0 && self.fault_set_at_us.is_none() {
                self.fault_set_at_us = Some(now);
            }
            self.pilot.now_us = now;
            self.pilot.apply(out.pilot);
            self.lift.set(out.lift_valve_on);
            self.snubber.set(out.snubber_on);
            self.motor.set_duty(out.motor_duty);
            for (p, d) in self.valves.iter_mut().zip(out.vacuum_duty) {
                p.set_duty(d);
            }
            self.pump.set(out.pump_on);
            if now.is_multiple_of(12_500) {
                let duties = [0, 1, 2].map(|k| self.valves[k].duty * 100.0);
                self.plant
                    .step(duties, self.ecu.measurements().u_batt_v, 100.0, self.pump.on, 0.0125);
                self.plant_readings();
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
        assert!(
            b.ecu.faults().is_empty(),
            "{name}: healthy phase raised {:?}",
            b.ecu.faults()
        );
        assert!(
            b.pilot.log.iter().any(|(_, c)| *c == SolenoidCmd::Full),
            "{name}: no valve event before the fault"
        );
        assert!(
            b.valves.iter().all(|v| v.duty > 0.0),
            "{name}: vacuum valves idle before the fault"
        );
        inject(&mut b);
        b.run_ms(1200);
        let active = b.ecu.faults();
        assert!(active.contains(expected_fault), "{name}: {expected_fault:?} not set");
        assert_eq!(active.iter().count(), 1, "{name}: more faults than expected");
        let safe = active.safe_state();
        assert_eq!(safe, expected_fault.reaction());
        let t_set = b.fault_set_at_us.unwrap();
        if safe.ehvva_closed {
            // No pilot drive after the fault was set (one EHVVA step later at most).
            let late = b
                .pilot
                .log
                .iter()
                .filter(|(t, c)| *t > t_set + STEP_US && *c != SolenoidCmd::Off)
                .count();
            assert_eq!(late, 0, "{name}: pilot driven after the fault");
            assert_eq!(b.pilot.current(), SolenoidCmd::Off);
            assert!(!b.lift.on && !b.snubber.on, "{name}: slow valves on");
        } else {
            assert!(
                b.pilot.log.iter().any(|(t, c)| *t > t_set && *c == SolenoidCmd::Full),
                "{name}: EHVVA stopped needlessly"
            );
        }
        // Park: ring speed (half the engine speed, 0 once the crank signal is gone) − 100 rpm.
        let rpm = b.ecu.engine().map_or(0.0, |e| e.rpm);
        let park_duty = ((rpm / 2.0 - 100.0) / 6000.0).max(0.0);
        if safe.evvt_parked {
            assert!(
                (b.motor.duty - park_duty).abs() < 1e-4,
                "{name}: motor duty {} (park {park_duty})",
                b.motor.duty
            );
        } else {
            assert!((b.motor.duty - park_duty).abs() > 1e-3, "{name}: parked needlessly");
        }
        if safe.vacuum_spring_open {
            assert!(b.valves.iter().all(|v| v.duty == 0.0), "{name}: vacuum valves driven");
        } else {
            assert!(
                b.valves.iter().all(|v| v.duty > 0.0),
                "{name}: vacuum valves released needlessly"
            );
        }
        if safe.pump_off {
            assert!(!b.pump.on, "{name}: pump on");
        }
    }

    #[test]
    fn each_fault_drives_its_safe_state_on_the_doubles() {
        let cfg = SupervisorConfig::default();
        let counts = |ch: Channel, v: f32| cfg.scales[ch as usize].counts_for(v);
        check(
            "battery low",
            |b| b.set_channel(Channel::BatteryV, counts(Channel::BatteryV, 6.0)),
            Fault::BatteryLow,
        );
        check(
            "battery high",
            |b| b.set_channel(Channel::BatteryV, counts(Channel::BatteryV, 24.0)),
            Fault::BatteryHigh,
        );
        check(
            "supply pressure open",
            |b| b.set_channel(Channel::SupplyPressureMpa, 0),
            Fault::SupplyPressureSensor,
        );
        check(
            "back pressure short",
            |b| b.set_channel(Channel::BackPressureMpa, 4095),
            Fault::BackPressureSensor,
        );
        check(
            "oil temperature open",
            |b| b.set_channel(Channel::OilTempC, 0),
            Fault::OilTempSensor,
        );
        check(
            "tank pressure short",
            |b| b.set_channel(Channel::TankPressureKpa, 4095),
            Fault::TankPressureSensor,
        );
        check(
            "ambient pressure open",
            |b| b.set_channel(Channel::AmbientPressureKpa, 0),
            Fault::AmbientPressureSensor,
        );
        check(
            "position sensor open",
            |b| b.set_channel(Channel::HptPositionPct, 0),
            Fault::VacuumPositionSensor,
        );
        check(
            "ECU over-temperature",
            |b| b.set_channel(Channel::EcuTempC, counts(Channel::EcuTempC, 125.0)),
            Fault::OverTemperature,
        );
        check("crank signal lost", |b| b.crank_signal = false, Fault::CrankLost);
    }
}
