//! Supervisor logic: ADC channels converted with range checks, faults debounced (and latched
//! where a healed reading is not to be trusted again in this drive cycle), and every fault
//! mapped to the safe state of each actuator:
//! - EHVVA: pilot off, so the engine valve is closed by its return spring (Li 2018, Sec. 2:
//!   the top port falls back to the low pressure Pl when the actuation valve is released);
//! - EVVT: cam phase parked: the open-loop park command towards the retard stop
//!   ([`crate::control::evvt_phase`]);
//! - vacuum: all valves at 0 % duty, so the actuators see ambient pressure and the wastegate
//!   and bypasses sit where their springs put them (Thomasson 2013, eqs. (2), (8)); the pump
//!   off where running it is pointless or harmful (leak, no tank sensor, battery out of range:
//!   the pump is the largest electrical load, Sec. 4).

use super::board::{elapsed_us, AnalogFault, AnalogScale};

/// The ADC channels, in the order the board samples them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    BatteryV = 0,
    SupplyPressureMpa,
    BackPressureMpa,
    OilTempC,
    TankPressureKpa,
    AmbientPressureKpa,
    LptPositionPct,
    HptPositionPct,
    HpcPositionPct,
    EcuTempC,
}

pub const N_CHANNELS: usize = 10;

impl Channel {
    pub const ALL: [Channel; N_CHANNELS] = [
        Channel::BatteryV,
        Channel::SupplyPressureMpa,
        Channel::BackPressureMpa,
        Channel::OilTempC,
        Channel::TankPressureKpa,
        Channel::AmbientPressureKpa,
        Channel::LptPositionPct,
        Channel::HptPositionPct,
        Channel::HpcPositionPct,
        Channel::EcuTempC,
    ];

    /// The fault a failed reading of this channel raises.
    pub fn sensor_fault(self) -> Fault {
        match self {
            Channel::BatteryV => Fault::BatteryLow,
            Channel::SupplyPressureMpa => Fault::SupplyPressureSensor,
            Channel::BackPressureMpa => Fault::BackPressureSensor,
            Channel::OilTempC => Fault::OilTempSensor,
            Channel::TankPressureKpa => Fault::TankPressureSensor,
            Channel::AmbientPressureKpa => Fault::AmbientPressureSensor,
            Channel::LptPositionPct | Channel::HptPositionPct | Channel::HpcPositionPct => Fault::VacuumPositionSensor,
            Channel::EcuTempC => Fault::EcuTempSensor,
        }
    }
}

/// Everything the supervisor can flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    BatteryLow = 0,
    BatteryHigh,
    SupplyPressureSensor,
    BackPressureSensor,
    OilTempSensor,
    TankPressureSensor,
    AmbientPressureSensor,
    VacuumPositionSensor,
    EcuTempSensor,
    OverTemperature,
    CrankLost,
    CamLost,
    VacuumActuatorStuck,
    /// Tank pressure rises faster than the tank model says: a leak or a failed pump.
    AbnormalLeak,
}

pub const N_FAULTS: usize = 14;

/// What each actuator does in the safe state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct SafeState {
    pub ehvva_closed: bool,
    pub evvt_parked: bool,
    pub vacuum_spring_open: bool,
    pub pump_off: bool,
}

impl SafeState {
    pub const ALL: Self = Self {
        ehvva_closed: true,
        evvt_parked: true,
        vacuum_spring_open: true,
        pump_off: true,
    };

    fn union(self, o: Self) -> Self {
        Self {
            ehvva_closed: self.ehvva_closed | o.ehvva_closed,
            evvt_parked: self.evvt_parked | o.evvt_parked,
            vacuum_spring_open: self.vacuum_spring_open | o.vacuum_spring_open,
            pump_off: self.pump_off | o.pump_off,
        }
    }
}

impl Fault {
    pub const ALL: [Fault; N_FAULTS] = [
        Fault::BatteryLow,
        Fault::BatteryHigh,
        Fault::SupplyPressureSensor,
        Fault::BackPressureSensor,
        Fault::OilTempSensor,
        Fault::TankPressureSensor,
        Fault::AmbientPressureSensor,
        Fault::VacuumPositionSensor,
        Fault::EcuTempSensor,
        Fault::OverTemperature,
        Fault::CrankLost,
        Fault::CamLost,
        Fault::VacuumActuatorStuck,
        Fault::AbnormalLeak,
    ];

    /// A short name for the log.
    pub fn name(self) -> &'static str {
        match self {
            Fault::BatteryLow => "battery low",
            Fault::BatteryHigh => "battery high",
            Fault::SupplyPressureSensor => "supply pressure sensor",
            Fault::BackPressureSensor => "back pressure sensor",
            Fault::OilTempSensor => "oil temperature sensor",
            Fault::TankPressureSensor => "tank pressure sensor",
            Fault::AmbientPressureSensor => "ambient pressure sensor",
            Fault::VacuumPositionSensor => "vacuum actuator position sensor",
            Fault::EcuTempSensor => "ECU temperature sensor",
            Fault::OverTemperature => "over-temperature",
            Fault::CrankLost => "crank signal lost",
            Fault::CamLost => "cam signal lost",
            Fault::VacuumActuatorStuck => "vacuum actuator stuck",
            Fault::AbnormalLeak => "abnormal vacuum leak or pump failure",
        }
    }

    /// The reaction (why, per fault):
    pub fn reaction(self) -> SafeState {
        let none = SafeState::default();
        match self {
            // Out-of-range supply: coil currents and the LPV schedules are no longer valid,
            // and the pump would load the battery further.
            Fault::BatteryLow | Fault::BatteryHigh => SafeState::ALL,
            // td(Ph, T) and the seating depend on these: no valve timing without them.
            Fault::SupplyPressureSensor | Fault::BackPressureSensor | Fault::OilTempSensor => SafeState {
                ehvva_closed: true,
                ..none
            },
            // No tank feedback: the pump cannot be switched on the need, valves cannot be fed.
            Fault::TankPressureSensor => SafeState {
                vacuum_spring_open: true,
                pump_off: true,
                ..none
            },
            // The inverse model and the stuck check need these.
            Fault::AmbientPressureSensor | Fault::VacuumPositionSensor | Fault::VacuumActuatorStuck => SafeState {
                vacuum_spring_open: true,
                ..none
            },
            // Drivers cannot be protected without a temperature.
            Fault::EcuTempSensor | Fault::OverTemperature => SafeState::ALL,
            // No engine position: no valve events, no phase control.
            Fault::CrankLost | Fault::CamLost => SafeState {
                ehvva_closed: true,
                evvt_parked: true,
                ..none
            },
            // Running the pump against a leak only wastes energy.
            Fault::AbnormalLeak => SafeState {
                vacuum_spring_open: true,
                pump_off: true,
                ..none
            },
        }
    }

    /// Latched faults stay until [`Supervisor::clear_latched`] (next ignition cycle): a
    /// sensor that failed once is not trusted again. Battery and temperature recover.
    pub fn latched(self) -> bool {
        !matches!(self, Fault::BatteryLow | Fault::BatteryHigh | Fault::OverTemperature)
    }

    /// How long the condition must persist before the fault is set, µs.
    fn debounce_us(self) -> u32 {
        match self {
            Fault::BatteryLow | Fault::BatteryHigh => 100_000,
            Fault::OverTemperature => 1_000_000,
            _ => 50_000,
        }
    }
}

/// A set of faults (one bit each).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct FaultSet(pub u32);

impl FaultSet {
    pub fn contains(self, f: Fault) -> bool {
        self.0 & (1 << f as u32) != 0
    }
    pub fn insert(&mut self, f: Fault) {
        self.0 |= 1 << f as u32;
    }
    pub fn remove(&mut self, f: Fault) {
        self.0 &= !(1 << f as u32);
    }
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    pub fn iter(self) -> impl Iterator<Item = Fault> {
        Fault::ALL.into_iter().filter(move |f| self.contains(*f))
    }
    /// The union of the reactions.
    pub fn safe_state(self) -> SafeState {
        self.iter().fold(SafeState::default(), |s, f| s.union(f.reaction()))
    }
}

/// Conversions of all channels plus the supply and temperature limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorConfig {
    pub scales: [AnalogScale; N_CHANNELS],
    pub battery_low_v: f32,
    pub battery_high_v: f32,
    /// Range must hold this long before a battery or temperature fault clears.
    pub recover_us: u32,
    pub ecu_temp_max_c: f32,
    pub oil_temp_max_c: f32,
    /// Hysteresis below the temperature limits for recovery.
    pub temp_hysteresis_c: f32,
}

/// A ratiometric 5 V sensor (0.5..4.5 V ↔ `lo..hi`) seen through a 5 V → 3.3 V divider by a
/// 12-bit ADC; readings outside 0.25..4.75 V are wiring faults.
pub const fn ratiometric_5v(lo: f32, hi: f32, plausible_min: f32, plausible_max: f32) -> AnalogScale {
    const COUNTS_PER_V: f32 = 4095.0 / 5.0;
    let c_lo = 0.5 * COUNTS_PER_V;
    let c_hi = 4.5 * COUNTS_PER_V;
    let gain = (hi - lo) / (c_hi - c_lo);
    AnalogScale {
        counts_min: (0.25 * COUNTS_PER_V) as u16,
        counts_max: (4.75 * COUNTS_PER_V) as u16,
        offset: lo - gain * c_lo,
        gain_per_count: gain,
        plausible_min,
        plausible_max,
    }
}

impl Default for SupervisorConfig {
    /// The ECU board: battery through an 8:1 divider (26.4 V full scale, so a load dump still
    /// reads), ratiometric sensors (Ph 0..25 MPa, Pl 0..10 MPa, oil −40..160 °C, tank and
    /// ambient 0..250 kPa abs, positions 0..100 %), the STM32 temperature sensor (0.76 V at
    /// 25 °C, 2.5 mV/K). Battery 7..16.5 V: below 7 V the pilot's 3 A peak takes over 2 ms
    /// ([`crate::peak_hold`]), above 16.5 V is a load dump or a 24 V jump start.
    fn default() -> Self {
        let v_per_count = 3.3 / 4095.0;
        Self {
            scales: [
                AnalogScale {
                    counts_min: 0,
                    counts_max: 4095,
                    offset: 0.0,
                    gain_per_count: 8.0 * v_per_count,
                    plausible_min: 0.0,
                    plausible_max: 30.0,
                },
                ratiometric_5v(0.0, 25.0, 0.0, 15.0),
                ratiometric_5v(0.0, 10.0, 0.0, 8.0),
                ratiometric_5v(-40.0, 160.0, -40.0, 160.0),
                ratiometric_5v(0.0, 250.0, 1.0, 115.0),
                ratiometric_5v(0.0, 250.0, 50.0, 115.0),
                ratiometric_5v(0.0, 100.0, -5.0, 105.0),
                ratiometric_5v(0.0, 100.0, -5.0, 105.0),
                ratiometric_5v(0.0, 100.0, -5.0, 105.0),
                AnalogScale {
                    counts_min: 0,
                    counts_max: 4095,
                    offset: 25.0 - 0.76 / 0.0025,
                    gain_per_count: v_per_count / 0.0025,
                    plausible_min: -40.0,
                    plausible_max: 150.0,
                },
            ],
            battery_low_v: 7.0,
            battery_high_v: 16.5,
            recover_us: 500_000,
            ecu_temp_max_c: 110.0,
            oil_temp_max_c: 140.0,
            temp_hysteresis_c: 10.0,
        }
    }
}

/// Engineering values; a failed channel keeps its last good value (or the default) so the
/// tasks always get a number, and its fault puts the users of it in their safe state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurements {
    pub u_batt_v: f32,
    pub p_supply_mpa: f32,
    pub p_back_mpa: f32,
    pub temp_oil_c: f32,
    pub p_tank_kpa: f32,
    pub p_amb_kpa: f32,
    /// LPT, HPT, HPC actuator positions.
    pub x_pct: [f32; 3],
    pub temp_ecu_c: f32,
}

impl Measurements {
    /// The values before the first scan (nominal: 13.5 V, Ph 6 MPa, Pl 2 MPa, oil 22 °C,
    /// 100 kPa tank and ambient, positions 0 %, ECU 25 °C); a const so that the firmware's
    /// shared cell can start with them.
    pub const BOOT: Self = Self {
        u_batt_v: 13.5,
        p_supply_mpa: 6.0,
        p_back_mpa: 2.0,
        temp_oil_c: 22.0,
        p_tank_kpa: 100.0,
        p_amb_kpa: 100.0,
        x_pct: [0.0; 3],
        temp_ecu_c: 25.0,
    };
}

impl Default for Measurements {
    /// [`Measurements::BOOT`].
    fn default() -> Self {
        Self::BOOT
    }
}

impl Measurements {
    fn set(&mut self, ch: Channel, v: f32) {
        match ch {
            Channel::BatteryV => self.u_batt_v = v,
            Channel::SupplyPressureMpa => self.p_supply_mpa = v,
            Channel::BackPressureMpa => self.p_back_mpa = v,
            Channel::OilTempC => self.temp_oil_c = v,
            Channel::TankPressureKpa => self.p_tank_kpa = v,
            Channel::AmbientPressureKpa => self.p_amb_kpa = v,
            Channel::LptPositionPct => self.x_pct[0] = v,
            Channel::HptPositionPct => self.x_pct[1] = v,
            Channel::HpcPositionPct => self.x_pct[2] = v,
            Channel::EcuTempC => self.temp_ecu_c = v,
        }
    }
}

/// Faults the tasks detect themselves (already debounced there).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct TaskReports {
    pub crank_lost: bool,
    pub cam_lost: bool,
    pub vacuum_stuck: bool,
    pub abnormal_leak: bool,
}

/// One step's result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorOutput {
    pub measurements: Measurements,
    /// Per-channel conversion result of this sample (for the log).
    pub channel_faults: [Option<AnalogFault>; N_CHANNELS],
    pub active: FaultSet,
    pub newly_set: FaultSet,
    pub newly_cleared: FaultSet,
    pub safe: SafeState,
}

/// The supervisor state machine.
#[derive(Clone, Debug)]
pub struct Supervisor {
    cfg: SupervisorConfig,
    meas: Measurements,
    active: FaultSet,
    /// When each fault's condition started (debounce) or, for an active fault, when it went
    /// away (recovery).
    since_us: [Option<u32>; N_FAULTS],
}

impl Supervisor {
    pub fn new(cfg: SupervisorConfig) -> Self {
        Self {
            cfg,
            meas: Measurements::default(),
            active: FaultSet::default(),
            since_us: [None; N_FAULTS],
        }
    }

    pub fn active(&self) -> FaultSet {
        self.active
    }

    /// Forgets latched faults (a new ignition cycle).
    pub fn clear_latched(&mut self) {
        self.active = FaultSet::default();
        self.since_us = [None; N_FAULTS];
    }

    /// Debounces one condition; returns the change of the fault's state.
    fn update(&mut self, f: Fault, present: bool, now_us: u32, set: &mut FaultSet, cleared: &mut FaultSet) {
        let i = f as usize;
        let Some(since) = self.since_us.get_mut(i) else { return };
        let active = self.active.contains(f);
        // For an inactive fault `since` times the condition, for an active one its absence.
        if present != active {
            let start = *since.get_or_insert(now_us);
            let wait = if active { self.cfg.recover_us } else { f.debounce_us() };
            if elapsed_us(now_us, start) >= wait && !(active && f.latched()) {
                *since = None;
                if active {
                    self.active.remove(f);
                    cleared.insert(f);
                } else {
                    self.active.insert(f);
                    set.insert(f);
                }
            }
        } else {
            *since = None;
        }
    }

    /// One supervision step: raw counts of all channels (in [`Channel`] order), the tasks'
    /// reports, the time.
    pub fn step(&mut self, counts: &[u16; N_CHANNELS], reports: &TaskReports, now_us: u32) -> SupervisorOutput {
        let mut set = FaultSet::default();
        let mut cleared = FaultSet::default();
        let mut channel_faults = [None; N_CHANNELS];
        let mut sensor_bad = FaultSet::default();
        for (k, ch) in Channel::ALL.into_iter().enumerate() {
            let (Some(scale), Some(&c)) = (self.cfg.scales.get(k), counts.get(k)) else {
                continue;
            };
            match scale.convert(c) {
                Ok(v) => self.meas.set(ch, v),
                Err(e) => {
                    if let Some(slot) = channel_faults.get_mut(k) {
                        *slot = Some(e);
                    }
                    sensor_bad.insert(ch.sensor_fault());
                }
            }
        }
        let m = self.meas;
        let battery_bad = sensor_bad.contains(Fault::BatteryLow);
        let hyst = if self.active.contains(Fault::OverTemperature) {
            self.cfg.temp_hysteresis_c
        } else {
            0.0
        };
        let hot = m.temp_ecu_c > self.cfg.ecu_temp_max_c - hyst || m.temp_oil_c > self.cfg.oil_temp_max_c - hyst;
        let conditions = [
            (
                Fault::BatteryLow,
                battery_bad || !(m.u_batt_v >= self.cfg.battery_low_v),
            ),
            (Fault::BatteryHigh, m.u_batt_v > self.cfg.battery_high_v),
            (
                Fault::SupplyPressureSensor,
                sensor_bad.contains(Fault::SupplyPressureSensor),
            ),
            (
                Fault::BackPressureSensor,
                sensor_bad.contains(Fault::BackPressureSensor),
            ),
            (Fault::OilTempSensor, sensor_bad.contains(Fault::OilTempSensor)),
            (
                Fault::TankPressureSensor,
                sensor_bad.contains(Fault::TankPressureSensor),
            ),
            (
                Fault::AmbientPressureSensor,
                sensor_bad.contains(Fault::AmbientPressureSensor),
            ),
            (
                Fault::VacuumPositionSensor,
                sensor_bad.contains(Fault::VacuumPositionSensor),
            ),
            (Fault::EcuTempSensor, sensor_bad.contains(Fault::EcuTempSensor)),
            (Fault::OverTemperature, hot),
        ];
        for (f, present) in conditions {
            self.update(f, present, now_us, &mut set, &mut cleared);
        }
        // Task reports are debounced by the tasks: latch at once.
        for (f, present) in [
            (Fault::CrankLost, reports.crank_lost),
            (Fault::CamLost, reports.cam_lost),
            (Fault::VacuumActuatorStuck, reports.vacuum_stuck),
            (Fault::AbnormalLeak, reports.abnormal_leak),
        ] {
            if present && !self.active.contains(f) {
                self.active.insert(f);
                set.insert(f);
            }
        }
        SupervisorOutput {
            measurements: m,
            channel_faults,
            active: self.active,
            newly_set: set,
            newly_cleared: cleared,
            safe: self.active.safe_state(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts for a healthy engine: 13.8 V, Ph 6 MPa, Pl 2 MPa, oil 80 °C, tank 40 kPa,
    /// ambient 100 kPa, positions 20/40/60 %, ECU 50 °C.
    fn healthy(cfg: &SupervisorConfig) -> [u16; N_CHANNELS] {
        let values = [13.8, 6.0, 2.0, 80.0, 40.0, 100.0, 20.0, 40.0, 60.0, 50.0];
        let mut c = [0u16; N_CHANNELS];
        for k in 0..N_CHANNELS {
            c[k] = cfg.scales[k].counts_for(values[k]);
        }
        c
    }

    /// Runs 10 ms steps from `t0` for `ms` with `counts`; returns the last output.
    fn run(s: &mut Supervisor, counts: &[u16; N_CHANNELS], rep: &TaskReports, t0_ms: u32, ms: u32) -> SupervisorOutput {
        let mut out = s.step(counts, rep, t0_ms * 1000);
        let mut t = t0_ms;
        while t < t0_ms + ms {
            t += 10;
            out = s.step(counts, rep, t * 1000);
        }
        out
    }

    #[test]
    fn healthy_inputs_convert_and_raise_nothing() {
        let cfg = SupervisorConfig::default();
        let mut s = Supervisor::new(cfg);
        let out = run(&mut s, &healthy(&cfg), &TaskReports::default(), 0, 2000);
        assert!(
            out.active.is_empty(),
            "{:?}",
            out.active.iter().map(Fault::name).collect::<heapless::Vec<_, 16>>()
        );
        let m = out.measurements;
        assert!((m.u_batt_v - 13.8).abs() < 0.01 && (m.p_supply_mpa - 6.0).abs() < 0.01);
        assert!((m.p_tank_kpa - 40.0).abs() < 0.1 && (m.x_pct[2] - 60.0).abs() < 0.05);
        assert!((m.temp_ecu_c - 50.0).abs() < 0.5);
        assert_eq!(out.safe, SafeState::default());
    }

    #[test]
    fn every_fault_has_a_safe_state_and_a_name() {
        for f in Fault::ALL {
            assert_ne!(f.reaction(), SafeState::default(), "{f:?}");
            assert!(!f.name().is_empty());
        }
        // The bit layout covers all faults once.
        let mut all = FaultSet::default();
        for f in Fault::ALL {
            assert!(!all.contains(f));
            all.insert(f);
        }
        assert_eq!(all.iter().count(), N_FAULTS);
        assert_eq!(all.safe_state(), SafeState::ALL);
    }

    #[test]
    fn battery_low_and_high_are_debounced_and_recover() {
        let cfg = SupervisorConfig::default();
        let mut s = Supervisor::new(cfg);
        let rep = TaskReports::default();
        let mut c = healthy(&cfg);
        run(&mut s, &c, &rep, 0, 100);
        // 6 V for 50 ms (a cranking dip) is not a fault; for 200 ms it is.
        c[0] = cfg.scales[0].counts_for(6.0);
        let out = run(&mut s, &c, &rep, 200, 50);
        assert!(out.active.is_empty());
        let out = run(&mut s, &c, &rep, 260, 200);
        assert!(out.active.contains(Fault::BatteryLow));
        assert_eq!(out.safe, SafeState::ALL);
        // Back to 13.8 V: clears after 500 ms, not before.
        let h = healthy(&cfg);
        let out = run(&mut s, &h, &rep, 500, 300);
        assert!(out.active.contains(Fault::BatteryLow));
        let out = run(&mut s, &h, &rep, 810, 300);
        assert!(!out.active.contains(Fault::BatteryLow));
        assert_eq!(out.safe, SafeState::default());
        // Load dump 24 V.
        c[0] = cfg.scales[0].counts_for(24.0);
        let out = run(&mut s, &c, &rep, 2000, 200);
        assert!(out.active.contains(Fault::BatteryHigh) && out.safe == SafeState::ALL);
    }

    #[test]
    fn pressure_sensor_open_or_short_latches_and_closes_the_valves() {
        let cfg = SupervisorConfig::default();
        for (bad_counts, kind) in [
            (0u16, AnalogFault::OpenOrShortToGround),
            (4095, AnalogFault::ShortToSupply),
        ] {
            let mut s = Supervisor::new(cfg);
            let rep = TaskReports::default();
            let mut c = healthy(&cfg);
            c[Channel::SupplyPressureMpa as usize] = bad_counts;
            // A single bad sample is filtered.
            let out = s.step(&c, &rep, 0);
            assert_eq!(out.channel_faults[1], Some(kind));
            assert!(out.active.is_empty());
            let out = run(&mut s, &c, &rep, 0, 100);
            assert!(out.active.contains(Fault::SupplyPressureSensor));
            // The last good value is kept for the users.
            assert!((out.measurements.p_supply_mpa - 6.0).abs() < 0.01);
            assert_eq!(
                out.safe,
                SafeState {
                    ehvva_closed: true,
                    ..Default::default()
                }
            );
            // Latched: a healed reading does not clear it.
            let out = run(&mut s, &healthy(&cfg), &rep, 200, 2000);
            assert!(out.active.contains(Fault::SupplyPressureSensor));
            s.clear_latched();
            let out = run(&mut s, &healthy(&cfg), &rep, 3000, 100);
            assert!(out.active.is_empty());
        }
    }

    #[test]
    fn tank_sensor_fault_opens_the_wastegate_and_stops_the_pump() {
        let cfg = SupervisorConfig::default();
        let mut s = Supervisor::new(cfg);
        let mut c = healthy(&cfg);
        // 150 kPa in a vacuum tank is implausible.
        c[Channel::TankPressureKpa as usize] = cfg.scales[4].counts_for(150.0);
        let out = run(&mut s, &c, &TaskReports::default(), 0, 100);
        assert_eq!(out.channel_faults[4], Some(AnalogFault::Implausible));
        assert_eq!(
            out.safe,
            SafeState {
                vacuum_spring_open: true,
                pump_off: true,
                ..Default::default()
            }
        );
    }

    #[test]
    fn over_temperature_with_hysteresis() {
        let cfg = SupervisorConfig::default();
        let mut s = Supervisor::new(cfg);
        let rep = TaskReports::default();
        let mut c = healthy(&cfg);
        c[Channel::EcuTempC as usize] = cfg.scales[9].counts_for(115.0);
        let out = run(&mut s, &c, &rep, 0, 500);
        assert!(out.active.is_empty(), "1 s debounce");
        let out = run(&mut s, &c, &rep, 510, 600);
        assert!(out.active.contains(Fault::OverTemperature) && out.safe == SafeState::ALL);
        // 105 °C is below the limit but inside the hysteresis: stays.
        c[9] = cfg.scales[9].counts_for(105.0);
        let out = run(&mut s, &c, &rep, 1200, 1000);
        assert!(out.active.contains(Fault::OverTemperature));
        c[9] = cfg.scales[9].counts_for(95.0);
        let out = run(&mut s, &c, &rep, 2300, 1000);
        assert!(!out.active.contains(Fault::OverTemperature));
    }

    #[test]
    fn task_reports_latch_with_their_reactions() {
        let cfg = SupervisorConfig::default();
        let h = healthy(&cfg);
        for (rep, safe) in [
            (
                TaskReports {
                    crank_lost: true,
                    ..Default::default()
                },
                SafeState {
                    ehvva_closed: true,
                    evvt_parked: true,
                    ..Default::default()
                },
            ),
            (
                TaskReports {
                    cam_lost: true,
                    ..Default::default()
                },
                SafeState {
                    ehvva_closed: true,
                    evvt_parked: true,
                    ..Default::default()
                },
            ),
            (
                TaskReports {
                    vacuum_stuck: true,
                    ..Default::default()
                },
                SafeState {
                    vacuum_spring_open: true,
                    ..Default::default()
                },
            ),
            (
                TaskReports {
                    abnormal_leak: true,
                    ..Default::default()
                },
                SafeState {
                    vacuum_spring_open: true,
                    pump_off: true,
                    ..Default::default()
                },
            ),
        ] {
            let mut s = Supervisor::new(cfg);
            let out = s.step(&h, &rep, 0);
            assert_eq!(out.safe, safe);
            assert_eq!(out.newly_set.iter().count(), 1);
            let out = run(&mut s, &h, &TaskReports::default(), 10, 1000);
            assert_eq!(out.safe, safe, "latched");
        }
    }
}
