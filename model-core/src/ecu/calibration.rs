//! The ECU calibration image: every table and constant a unit's bench logs can change, as
//! little-endian f32 values at fixed offsets behind a versioned header and ahead of a CRC-32,
//! so that the ECU can read it from its calibration flash sector and a calibration tool can
//! show and edit it (through the A2L file `hil-host calibrate` writes from [`CHARACTERISTICS`]).
//!
//! Layout (version [`FORMAT_VERSION`], [`IMAGE_BYTES`] bytes):
//!
//! | offset | bytes | what |
//! |---|---|---|
//! | 0 | 4 | magic `ECAL` |
//! | 4 | 2 | format version, u16 LE |
//! | 6 | 2 | number of f32 values, u16 LE ([`N_VALUES`]) |
//! | 8 | 4 | bytes of values, u32 LE |
//! | 12 | 4 | reserved, 0 |
//! | 16 | 4·[`N_VALUES`] | the values of [`CHARACTERISTICS`] in order, f32 LE |
//! | end − 4 | 4 | CRC-32 (ISO-HDLC, the zip/Ethernet CRC) of everything before it, u32 LE |
//!
//! Maps are stored with the second index fastest (`[x][y]`, A2L `COLUMN_DIR`), axes are
//! stored as their own characteristics (A2L `AXIS_PTS`) that the maps name.
//!
//! [`CalibrationImage::parse`] checks the image whole before anything is used: length, magic,
//! version, value count, CRC, every value finite and inside its limits, every axis strictly
//! increasing, the EVVT gains consistent with the α/β tables they follow from, and the tasks
//! built from it. An image that fails any check is refused with the check's name; nothing of it
//! is applied ([`EcuCalibration`] is a value: the caller applies all of it or none). No heap.

use core::fmt;

use crate::control::evvt_phase::{EvvtGains, EvvtPhaseConfig, EvvtPhaseController};
use crate::ecu::lockstep::EcuCoreConfig;
use crate::ecu::vacuum_task::{VacuumTask, VacuumTaskConfig};
use crate::ehvva::{EhvvaParams, EhvvaTableData, EhvvaTables, ValveMotionData};
use crate::evvt::EvvtLpvTable;
use crate::vacuum::{PositionMap, StaticPressureMap, VacuumEffects, VacuumParams};

/// The image's first four bytes.
pub const MAGIC: [u8; 4] = *b"ECAL";
/// The layout this code reads and writes.
pub const FORMAT_VERSION: u16 = 1;
/// Header bytes before the first value.
pub const HEADER_BYTES: usize = 16;
/// Trailing CRC-32 bytes.
pub const CRC_BYTES: usize = 4;
/// The bit [`crate::ecu::lockstep::EcuCore`] sets in the actuator frames' fault word when the
/// ECU runs on the paper defaults because its calibration image was refused (bad CRC, version,
/// limits). It lies above every supervisor fault bit.
pub const CALIBRATION_FAULT_BIT: u32 = 1 << 31;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

mod layout;
pub use layout::{Characteristic, Shape, CHARACTERISTICS, IMAGE_BYTES, N_CHARACTERISTICS, N_VALUES};

/// Why an image was refused. Each variant names what is wrong; [`fmt::Display`] starts with
/// "calibration".
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CalibrationError {
    /// Fewer bytes than a whole image (an incomplete write).
    TooShort { len: usize, needed: usize },
    /// The caller's buffer cannot hold an image.
    BufferTooSmall { len: usize, needed: usize },
    /// No `ECAL` magic: no image at all (an erased sector reads all 0xFF).
    NoImage,
    /// A layout this code does not read.
    Version { found: u16, supported: u16 },
    /// The header's value count or byte count is not this version's.
    Layout { values: u16, bytes: u32 },
    /// The CRC does not match the bytes: a corrupted image.
    Crc { stored: u32, computed: u32 },
    /// A value is NaN or infinite.
    NotFinite { name: &'static str, index: usize },
    /// A value is outside its A2L limits.
    OutOfLimits {
        name: &'static str,
        index: usize,
        value: f32,
        min: f32,
        max: f32,
    },
    /// Axis breakpoints not strictly increasing at `index`.
    AxisNotIncreasing { name: &'static str, index: usize },
    /// A value that does not agree with the values it follows from, or with which a task
    /// refuses to start; `what` says which.
    Inconsistent { name: &'static str, what: &'static str },
}

impl CalibrationError {
    /// The check that failed and the value it failed on, without number formatting (for the
    /// firmware's log, where float formatting would cost flash).
    pub fn names(&self) -> (&'static str, &'static str) {
        match *self {
            Self::TooShort { .. } => ("incomplete", "image"),
            Self::BufferTooSmall { .. } => ("buffer too small", "image"),
            Self::NoImage => ("missing", "image"),
            Self::Version { .. } => ("version", "image"),
            Self::Layout { .. } => ("layout", "image"),
            Self::Crc { .. } => ("CRC", "image"),
            Self::NotFinite { name, .. } => ("not finite", name),
            Self::OutOfLimits { name, .. } => ("outside limits", name),
            Self::AxisNotIncreasing { name, .. } => ("axis not increasing", name),
            Self::Inconsistent { name, .. } => ("inconsistent", name),
        }
    }
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooShort { len, needed } => write!(
                f,
                "calibration image incomplete: {len} bytes, format v{FORMAT_VERSION} needs {needed}"
            ),
            Self::BufferTooSmall { len, needed } => {
                write!(f, "calibration image buffer too small: {len} bytes, needs {needed}")
            }
            Self::NoImage => write!(f, "calibration image missing: no `ECAL` magic at offset 0"),
            Self::Version { found, supported } => write!(
                f,
                "calibration image version {found} at offset 4: this ECU reads version {supported}"
            ),
            Self::Layout { values, bytes } => write!(
                f,
                "calibration image header: {values} values / {bytes} bytes, version {FORMAT_VERSION} has {N_VALUES} / {}",
                4 * N_VALUES
            ),
            Self::Crc { stored, computed } => write!(
                f,
                "calibration image corrupted: CRC-32 stored 0x{stored:08x}, computed 0x{computed:08x}"
            ),
            Self::NotFinite { name, index } => write!(f, "calibration value {name}[{index}] is not a finite number"),
            Self::OutOfLimits {
                name,
                index,
                value,
                min,
                max,
            } => write!(
                f,
                "calibration value {name}[{index}] = {value} outside its limits {min}..{max}"
            ),
            Self::AxisNotIncreasing { name, index } => write!(
                f,
                "calibration axis {name}: breakpoint {index} not above breakpoint {}",
                index.saturating_sub(1)
            ),
            Self::Inconsistent { name, what } => write!(f, "calibration value {name}: {what}"),
        }
    }
}

/// One vacuum actuator's calibratable values (its static map's and position map's kind are
/// fixed by the hardware: LPT and HPT eq. (2), HPC eq. (5); LPT eq. (8), HPT and HPC eq. (9)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumActuatorCalibration {
    pub u_ref_v: f64,
    /// `[k1, p01, k2, p02]` (eq. (2)) or `[k1, p01, k2, u0]` (eq. (5)).
    pub static_map: [f64; 4],
    /// `[k, x0, -, -]` (eq. (8), two values used) or `[a1, a2, a3, a4]` (eq. (9)).
    pub position_map: [f64; 4],
    pub tau_rise_s: f64,
    pub tau_fall_s: f64,
    pub fc_kpa: f64,
    pub backlash_pct: f64,
    pub p_amb_ref_kpa: f64,
    /// The effects the ECU's model of the actuator has: `[supply-voltage, pressure-direction,
    /// coulomb-friction, backlash]`, 0 or 1.
    pub effects: [f64; 4],
}

impl VacuumActuatorCalibration {
    /// The calibratable values of `p`.
    pub fn from_params(p: &VacuumParams) -> Self {
        let static_map = match p.static_map {
            StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct,
                p02_kpa,
            } => [k1_kpa_per_pct, p01_kpa, k2_kpa_per_pct, p02_kpa],
            StaticPressureMap::Cubic {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct3,
                u0_pct,
            } => [k1_kpa_per_pct, p01_kpa, k2_kpa_per_pct3, u0_pct],
        };
        let position_map = match p.position_map {
            PositionMap::Linear { k_pct_per_kpa, x0_pct } => [k_pct_per_kpa, x0_pct, 0.0, 0.0],
            PositionMap::Arctan {
                a1_pct,
                a2_pct_per_rad,
                a3_kpa,
                a4_kpa,
            } => [a1_pct, a2_pct_per_rad, a3_kpa, a4_kpa],
        };
        Self {
            u_ref_v: p.u_ref_v,
            static_map,
            position_map,
            tau_rise_s: p.tau_rise_s,
            tau_fall_s: p.tau_fall_s,
            fc_kpa: p.fc_kpa,
            backlash_pct: p.backlash_pct,
            p_amb_ref_kpa: p.p_amb_ref_kpa,
            effects: [
                p.effects.supply_voltage,
                p.effects.pressure_direction,
                p.effects.coulomb_friction,
                p.effects.backlash,
            ]
            .map(|on| if on { 1.0 } else { 0.0 }),
        }
    }

    /// `base` (the paper's actuator of the same kind) with these values.
    pub fn apply(&self, base: &VacuumParams) -> VacuumParams {
        let m = self.static_map;
        let x = self.position_map;
        let static_map = match base.static_map {
            StaticPressureMap::PiecewiseLinear { .. } => StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct: m[0],
                p01_kpa: m[1],
                k2_kpa_per_pct: m[2],
                p02_kpa: m[3],
            },
            StaticPressureMap::Cubic { .. } => StaticPressureMap::Cubic {
                k1_kpa_per_pct: m[0],
                p01_kpa: m[1],
                k2_kpa_per_pct3: m[2],
                u0_pct: m[3],
            },
        };
        let position_map = match base.position_map {
            PositionMap::Linear { .. } => PositionMap::Linear {
                k_pct_per_kpa: x[0],
                x0_pct: x[1],
            },
            PositionMap::Arctan { .. } => PositionMap::Arctan {
                a1_pct: x[0],
                a2_pct_per_rad: x[1],
                a3_kpa: x[2],
                a4_kpa: x[3],
            },
        };
        VacuumParams {
            u_ref_v: self.u_ref_v,
            static_map,
            position_map,
            tau_rise_s: self.tau_rise_s,
            tau_fall_s: self.tau_fall_s,
            fc_kpa: self.fc_kpa,
            backlash_pct: self.backlash_pct,
            p_amb_ref_kpa: self.p_amb_ref_kpa,
            effects: VacuumEffects {
                supply_voltage: self.effects[0] == 1.0,
                pressure_direction: self.effects[1] == 1.0,
                coulomb_friction: self.effects[2] == 1.0,
                backlash: self.effects[3] == 1.0,
            },
            ..*base
        }
    }
}

/// Every value of the calibration image, as the ECU's tasks take them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EcuCalibration {
    pub ehvva_tables: EhvvaTableData,
    pub ehvva_pressure_delay_gain: f64,
    pub ehvva_direction_delay_gain: f64,
    pub ehvva_viscosity_gain: f64,
    pub ehvva_delay_nominal_p_supply_mpa: f64,
    pub valve_motion: ValveMotionData,
    pub evvt_lpv: EvvtLpvTable,
    pub evvt_crossover_rad_s: f64,
    pub evvt_min_phase_margin_deg: f64,
    pub evvt_integral_rate_per_s: f64,
    pub evvt_integral_zone_deg: f64,
    pub evvt_kp_min_rpm_per_deg: f64,
    pub evvt_kp_max_rpm_per_deg: f64,
    /// `kp[i][j]` at `evvt_lpv`'s grid: what the α/β tables imply ([`Self::implied_kp`]).
    pub evvt_kp_rpm_per_deg: [[f64; 3]; 3],
    pub vacuum_comp_u_min_v: f64,
    /// LPT, HPT, HPC.
    pub vacuum: [VacuumActuatorCalibration; 3],
}

impl EcuCalibration {
    /// The firmware's built-in calibration: the papers' tables ([`EcuCoreConfig::default`]).
    pub fn paper_defaults() -> Self {
        Self::from_config(&EcuCoreConfig::default())
    }

    /// The calibratable values of a configuration (the scheduled EVVT law's gains; a fixed-P
    /// configuration keeps the default schedule's).
    pub fn from_config(cfg: &EcuCoreConfig) -> Self {
        let m = &cfg.ehvva_model;
        let ctl = &cfg.evvt.controller;
        let scheduled = |g: EvvtGains| match g {
            EvvtGains::Scheduled {
                crossover_rad_s,
                min_phase_margin_deg,
                integral_rate_per_s,
                integral_zone_deg,
            } => Some((
                crossover_rad_s,
                min_phase_margin_deg,
                integral_rate_per_s,
                integral_zone_deg,
            )),
            EvvtGains::FixedP { .. } => None,
        };
        let (crossover, pm, rate, zone) = scheduled(ctl.gains)
            .or_else(|| scheduled(EvvtPhaseConfig::default().gains))
            .unwrap_or((2.0, 55.0, 0.5, 3.0));
        let mut cal = Self {
            ehvva_tables: m.tables,
            ehvva_pressure_delay_gain: m.effect_pressure_delay,
            ehvva_direction_delay_gain: m.effect_direction_delay,
            ehvva_viscosity_gain: m.effect_viscosity,
            ehvva_delay_nominal_p_supply_mpa: m.delay_nominal_p_supply_mpa,
            valve_motion: cfg.ehvva_motion,
            evvt_lpv: ctl.lpv,
            evvt_crossover_rad_s: crossover,
            evvt_min_phase_margin_deg: pm,
            evvt_integral_rate_per_s: rate,
            evvt_integral_zone_deg: zone,
            evvt_kp_min_rpm_per_deg: ctl.kp_min_rpm_per_deg,
            evvt_kp_max_rpm_per_deg: ctl.kp_max_rpm_per_deg,
            evvt_kp_rpm_per_deg: [[0.0; 3]; 3],
            vacuum_comp_u_min_v: cfg.vacuum.comp_u_min_v,
            vacuum: cfg.vacuum.actuators.map(|a| VacuumActuatorCalibration::from_params(&a)),
        };
        cal.evvt_kp_rpm_per_deg = cal.implied_kp().unwrap_or([[0.0; 3]; 3]);
        cal
    }

    /// The EVVT controller configuration of this calibration (the default one's limits).
    pub fn evvt_controller(&self) -> EvvtPhaseConfig {
        EvvtPhaseConfig {
            gains: EvvtGains::Scheduled {
                crossover_rad_s: self.evvt_crossover_rad_s,
                min_phase_margin_deg: self.evvt_min_phase_margin_deg,
                integral_rate_per_s: self.evvt_integral_rate_per_s,
                integral_zone_deg: self.evvt_integral_zone_deg,
            },
            lpv: self.evvt_lpv,
            kp_min_rpm_per_deg: self.evvt_kp_min_rpm_per_deg,
            kp_max_rpm_per_deg: self.evvt_kp_max_rpm_per_deg,
            ..EvvtPhaseConfig::default()
        }
    }

    /// The scheduled kp at each grid point of the α/β tables (the controller's own
    /// computation, [`EvvtPhaseController::gains_at`]), or why the controller refuses them.
    pub fn implied_kp(&self) -> Result<[[f64; 3]; 3], CalibrationError> {
        // f32: the controller the ECU runs (and no f64 soft-float code on the target).
        let ctl =
            EvvtPhaseController::<f32>::new(&self.evvt_controller()).map_err(|_| CalibrationError::Inconsistent {
                name: "evvt.alpha_deg_per_s2_rpm",
                what: "the EVVT controller refuses these tables and gains",
            })?;
        let t = &self.evvt_lpv;
        Ok(core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                f64::from(
                    ctl.gains_at(t.engine_speed_rpm[i] as f32, t.battery_voltage_v[j] as f32)
                        .0,
                )
            })
        }))
    }

    /// The EHVVA valve model the ECU's delay tables come from: the paper's valve with these
    /// tables and gains.
    pub fn ehvva_model(&self) -> EhvvaParams {
        EhvvaParams {
            tables: self.ehvva_tables,
            effect_pressure_delay: self.ehvva_pressure_delay_gain,
            effect_direction_delay: self.ehvva_direction_delay_gain,
            effect_viscosity: self.ehvva_viscosity_gain,
            delay_nominal_p_supply_mpa: self.ehvva_delay_nominal_p_supply_mpa,
            ..EhvvaParams::paper_default()
        }
    }

    /// Writes every value into `cfg` (the rest of `cfg`, limits and thresholds, stays).
    pub fn apply(&self, cfg: &mut EcuCoreConfig) {
        cfg.ehvva_model = self.ehvva_model();
        cfg.ehvva_motion = self.valve_motion;
        cfg.evvt.controller = EvvtPhaseConfig {
            motor_cmd_max_rpm: cfg.evvt.controller.motor_cmd_max_rpm,
            motor_cmd_rate_max_rpm_per_s: cfg.evvt.controller.motor_cmd_rate_max_rpm_per_s,
            min_engine_rpm: cfg.evvt.controller.min_engine_rpm,
            park_cmd_rpm: cfg.evvt.controller.park_cmd_rpm,
            setpoint_min_deg: cfg.evvt.controller.setpoint_min_deg,
            setpoint_max_deg: cfg.evvt.controller.setpoint_max_deg,
            ..self.evvt_controller()
        };
        cfg.vacuum.comp_u_min_v = self.vacuum_comp_u_min_v;
        let base = VacuumTaskConfig::default().actuators;
        for k in 0..3 {
            cfg.vacuum.actuators[k] = self.vacuum[k].apply(&base[k]);
        }
    }

    /// The configuration of the ECU with this calibration.
    pub fn config(&self) -> EcuCoreConfig {
        let mut cfg = EcuCoreConfig::default();
        self.apply(&mut cfg);
        cfg
    }

    /// The storage of each characteristic, in [`CHARACTERISTICS`] order.
    fn slots(&mut self) -> [&mut [f64]; N_CHARACTERISTICS] {
        let t = &mut self.ehvva_tables;
        let m = &mut self.valve_motion;
        let [open_high, open_low] = &mut m.open_ms;
        let [close_high, close_low] = &mut m.close_ms;
        let e = &mut self.evvt_lpv;
        let [lpt, hpt, hpc] = &mut self.vacuum;
        let one = core::slice::from_mut;
        [
            &mut t.td_p_supply_mpa,
            &mut t.td_temp_c,
            t.td_open_ms.as_flattened_mut(),
            t.td_close_ms.as_flattened_mut(),
            &mut t.tau_p_supply_mpa,
            &mut t.tau_temp_c,
            t.tau_ms.as_flattened_mut(),
            &mut t.cd_temp_c,
            &mut t.cd,
            one(&mut self.ehvva_pressure_delay_gain),
            one(&mut self.ehvva_direction_delay_gain),
            one(&mut self.ehvva_viscosity_gain),
            one(&mut self.ehvva_delay_nominal_p_supply_mpa),
            &mut m.p_supply_mpa,
            &mut m.temp_c,
            one(&mut m.p_back_mpa),
            open_high.as_flattened_mut(),
            open_low.as_flattened_mut(),
            close_high.as_flattened_mut(),
            close_low.as_flattened_mut(),
            &mut e.engine_speed_rpm,
            &mut e.battery_voltage_v,
            e.alpha_deg_per_s2_rpm.as_flattened_mut(),
            e.beta_per_s.as_flattened_mut(),
            one(&mut self.evvt_crossover_rad_s),
            one(&mut self.evvt_min_phase_margin_deg),
            one(&mut self.evvt_integral_rate_per_s),
            one(&mut self.evvt_integral_zone_deg),
            one(&mut self.evvt_kp_min_rpm_per_deg),
            one(&mut self.evvt_kp_max_rpm_per_deg),
            self.evvt_kp_rpm_per_deg.as_flattened_mut(),
            one(&mut self.vacuum_comp_u_min_v),
            one(&mut lpt.u_ref_v),
            &mut lpt.static_map,
            &mut lpt.position_map[..2],
            one(&mut lpt.tau_rise_s),
            one(&mut lpt.tau_fall_s),
            one(&mut lpt.fc_kpa),
            one(&mut lpt.backlash_pct),
            one(&mut hpt.u_ref_v),
            &mut hpt.static_map,
            &mut hpt.position_map,
            one(&mut hpt.tau_rise_s),
            one(&mut hpt.tau_fall_s),
            one(&mut hpt.fc_kpa),
            one(&mut hpt.backlash_pct),
            one(&mut hpc.u_ref_v),
            &mut hpc.static_map,
            &mut hpc.position_map,
            one(&mut hpc.tau_rise_s),
            one(&mut hpc.tau_fall_s),
            one(&mut hpc.fc_kpa),
            one(&mut hpc.backlash_pct),
            one(&mut lpt.p_amb_ref_kpa),
            one(&mut hpt.p_amb_ref_kpa),
            one(&mut hpc.p_amb_ref_kpa),
            &mut lpt.effects,
            &mut hpt.effects,
            &mut hpc.effects,
        ]
    }

    /// Calls `f(characteristic, values)` for every characteristic in image order (the values
    /// as the image holds them: rounded to f32).
    pub fn for_each(&self, mut f: impl FnMut(&Characteristic, &[f64])) {
        let mut copy = *self;
        for (c, s) in CHARACTERISTICS.iter().zip(copy.slots()) {
            f(c, s);
        }
    }

    /// Sets the values of the characteristic `name` (host tools: a value learned from a log);
    /// `false` when there is no such characteristic or `values` has the wrong length.
    pub fn set(&mut self, name: &str, values: &[f64]) -> bool {
        for (c, s) in CHARACTERISTICS.iter().zip(self.slots()) {
            if c.name == name && s.len() == values.len() {
                s.copy_from_slice(values);
                return true;
            }
        }
        false
    }

    /// Checks every value the way [`CalibrationImage::parse`] does (limits, axes, the derived
    /// kp, the tasks accept it) after rounding to f32, the image's precision.
    pub fn check(&self) -> Result<(), CalibrationError> {
        let mut buf = [0u8; IMAGE_BYTES];
        CalibrationImage::serialize(self, &mut buf)?;
        CalibrationImage::parse(&buf).map(|_| ())
    }
}

/// What the ECU found in its calibration sector at boot ([`boot_config`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BootCalibration {
    /// A valid image: its values run.
    Image,
    /// No image (an erased sector): the paper defaults run, no fault.
    Absent,
    /// An image that was refused: the paper defaults run and every actuator frame carries
    /// [`CALIBRATION_FAULT_BIT`].
    Refused(CalibrationError),
}

/// The ECU's configuration from the bytes of its calibration sector: the image's values when it
/// passes every check of [`CalibrationImage::parse`], else the paper defaults (with the fault
/// flag when an image was there but refused). Never a mix of the two.
pub fn boot_config(sector: &[u8]) -> (EcuCoreConfig, BootCalibration) {
    match CalibrationImage::parse(sector) {
        Ok(cal) => (cal.config(), BootCalibration::Image),
        Err(CalibrationError::NoImage) => (EcuCoreConfig::default(), BootCalibration::Absent),
        Err(e) => (
            EcuCoreConfig {
                calibration_fault: true,
                ..EcuCoreConfig::default()
            },
            BootCalibration::Refused(e),
        ),
    }
}

/// The image format: parse and check, serialize into a caller's buffer.
pub struct CalibrationImage;

impl CalibrationImage {
    /// Reads and checks an image (module doc: every check, in order) and returns its values,
    /// or why it was refused. Bytes after the image's CRC are ignored (a flash sector is
    /// larger than the image).
    pub fn parse(bytes: &[u8]) -> Result<EcuCalibration, CalibrationError> {
        if bytes.len() >= 4 && bytes[..4] != MAGIC {
            return Err(CalibrationError::NoImage);
        }
        if bytes.len() < HEADER_BYTES {
            return Err(CalibrationError::TooShort {
                len: bytes.len(),
                needed: IMAGE_BYTES,
            });
        }
        let version = u16::from_le_bytes([bytes[4], bytes[5]]);
        if version != FORMAT_VERSION {
            return Err(CalibrationError::Version {
                found: version,
                supported: FORMAT_VERSION,
            });
        }
        let values = u16::from_le_bytes([bytes[6], bytes[7]]);
        let n_bytes = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if usize::from(values) != N_VALUES || n_bytes as usize != 4 * N_VALUES {
            return Err(CalibrationError::Layout { values, bytes: n_bytes });
        }
        if bytes.len() < IMAGE_BYTES {
            return Err(CalibrationError::TooShort {
                len: bytes.len(),
                needed: IMAGE_BYTES,
            });
        }
        let body = &bytes[..IMAGE_BYTES - CRC_BYTES];
        let tail = &bytes[IMAGE_BYTES - CRC_BYTES..IMAGE_BYTES];
        let stored = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
        let computed = CRC32.checksum(body);
        if stored != computed {
            return Err(CalibrationError::Crc { stored, computed });
        }
        let mut cal = EcuCalibration::paper_defaults();
        let mut off = HEADER_BYTES;
        for (c, slot) in CHARACTERISTICS.iter().zip(cal.slots()) {
            let mut last = f32::NEG_INFINITY;
            for (index, v) in slot.iter_mut().enumerate() {
                let x = f32::from_le_bytes([bytes[off], bytes[off + 1], bytes[off + 2], bytes[off + 3]]);
                off += 4;
                if !x.is_finite() {
                    return Err(CalibrationError::NotFinite { name: c.name, index });
                }
                if !(x >= c.min && x <= c.max) {
                    return Err(CalibrationError::OutOfLimits {
                        name: c.name,
                        index,
                        value: x,
                        min: c.min,
                        max: c.max,
                    });
                }
                if matches!(c.shape, Shape::Axis(_)) && !(x > last) {
                    return Err(CalibrationError::AxisNotIncreasing { name: c.name, index });
                }
                last = x;
                *v = f64::from(x);
            }
        }
        check_derived(&cal)?;
        Ok(cal)
    }

    /// Writes the image of `cal` into `buf` (at least [`IMAGE_BYTES`]) and returns its length.
    /// Values are rounded to f32; nothing is checked here ([`EcuCalibration::check`] does).
    pub fn serialize(cal: &EcuCalibration, buf: &mut [u8]) -> Result<usize, CalibrationError> {
        if buf.len() < IMAGE_BYTES {
            return Err(CalibrationError::BufferTooSmall {
                len: buf.len(),
                needed: IMAGE_BYTES,
            });
        }
        buf[..4].copy_from_slice(&MAGIC);
        buf[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
        buf[6..8].copy_from_slice(&(N_VALUES as u16).to_le_bytes());
        buf[8..12].copy_from_slice(&((4 * N_VALUES) as u32).to_le_bytes());
        buf[12..16].copy_from_slice(&[0; 4]);
        let mut off = HEADER_BYTES;
        cal.for_each(|_, values| {
            for v in values {
                buf[off..off + 4].copy_from_slice(&(*v as f32).to_le_bytes());
                off += 4;
            }
        });
        let crc = CRC32.checksum(&buf[..off]);
        buf[off..off + 4].copy_from_slice(&crc.to_le_bytes());
        Ok(off + CRC_BYTES)
    }
}

/// The checks that need several values at once: the derived kp, and the tasks accept it.
fn check_derived(cal: &EcuCalibration) -> Result<(), CalibrationError> {
    const NAMES: [&str; 3] = ["vacuum.lpt.effects", "vacuum.hpt.effects", "vacuum.hpc.effects"];
    for (a, name) in cal.vacuum.iter().zip(NAMES) {
        if a.effects.iter().any(|e| *e != 0.0 && *e != 1.0) {
            return Err(CalibrationError::Inconsistent {
                name,
                what: "each effect is 0 (off) or 1 (on)",
            });
        }
    }
    let kp = cal.implied_kp()?;
    for i in 0..3 {
        for j in 0..3 {
            let stored = cal.evvt_kp_rpm_per_deg[i][j];
            if (stored - kp[i][j]).abs() > 1e-3 * kp[i][j].abs().max(1.0) {
                return Err(CalibrationError::Inconsistent {
                    name: "evvt.kp_rpm_per_deg",
                    what: "does not follow from evvt.alpha_deg_per_s2_rpm, evvt.beta_per_s and the PI gains",
                });
            }
        }
    }
    if cal.evvt_kp_max_rpm_per_deg < cal.evvt_kp_min_rpm_per_deg {
        return Err(CalibrationError::Inconsistent {
            name: "evvt.kp_max_rpm_per_deg",
            what: "below evvt.kp_min_rpm_per_deg",
        });
    }
    EhvvaTables::<f32>::with_valve_motion(&cal.ehvva_model(), &cal.valve_motion).map_err(|_| {
        CalibrationError::Inconsistent {
            name: "ehvva.td_open_ms",
            what: "the EHVVA delay tables refuse these values",
        }
    })?;
    let cfg = cal.config();
    VacuumTask::new(cfg.vacuum).map_err(|_| CalibrationError::Inconsistent {
        name: "vacuum.lpt.static_map",
        what: "the vacuum task refuses these maps",
    })?;
    Ok(())
}

#[cfg(test)]
mod tests;
