//! The image's contents: every characteristic (A2L object) in image order, with its shape,
//! unit, limits and description, and the sizes that follow from them. The offsets, the A2L
//! file and `calibration.json` are all derived from [`CHARACTERISTICS`].

use super::{CRC_BYTES, HEADER_BYTES};

/// What a characteristic is, in A2L terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// One value (A2L `VALUE`).
    Value,
    /// Breakpoints of an axis shared by curves and maps (A2L `AXIS_PTS`), strictly increasing.
    Axis(usize),
    /// A vector of coefficients (A2L `VAL_BLK`).
    Array(usize),
    /// A curve over the named axis (A2L `CURVE` with `COM_AXIS`).
    Curve { x_axis: &'static str, n: usize },
    /// A map `[x][y]` over two named axes (A2L `MAP`, `COM_AXIS` twice, `COLUMN_DIR`).
    Map {
        x_axis: &'static str,
        nx: usize,
        y_axis: &'static str,
        ny: usize,
    },
}

impl Shape {
    /// Number of f32 values.
    pub const fn len(&self) -> usize {
        match *self {
            Shape::Value => 1,
            Shape::Axis(n) | Shape::Array(n) | Shape::Curve { n, .. } => n,
            Shape::Map { nx, ny, .. } => nx * ny,
        }
    }
    /// `true` for none (never: every shape holds at least one value).
    pub const fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One calibratable value, table or axis of the image: the A2L `CHARACTERISTIC` (or
/// `AXIS_PTS`) that describes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Characteristic {
    /// A2L name (also the key in `calibration.json`).
    pub name: &'static str,
    pub shape: Shape,
    /// Physical unit, as the A2L `COMPU_METHOD` shows it.
    pub unit: &'static str,
    /// A2L `LOWER_LIMIT` / `UPPER_LIMIT`: the image is refused outside them.
    pub min: f32,
    pub max: f32,
    /// Derived from other values (shown read-only in a calibration tool and checked on parse).
    pub read_only: bool,
    pub description: &'static str,
}

impl Characteristic {
    /// Byte offset of the first value in the image.
    pub fn offset(&self) -> usize {
        let mut off = HEADER_BYTES;
        for c in CHARACTERISTICS.iter() {
            if c.name == self.name {
                return off;
            }
            off += 4 * c.shape.len();
        }
        off
    }
}

const fn c(
    name: &'static str,
    shape: Shape,
    unit: &'static str,
    min: f32,
    max: f32,
    description: &'static str,
) -> Characteristic {
    Characteristic {
        name,
        shape,
        unit,
        min,
        max,
        read_only: false,
        description,
    }
}

const fn map(x_axis: &'static str, nx: usize, y_axis: &'static str, ny: usize) -> Shape {
    Shape::Map { x_axis, nx, y_axis, ny }
}

const TD_P: &str = "ehvva.td_p_supply_mpa";
const TD_T: &str = "ehvva.td_temp_c";
const TAU_P: &str = "ehvva.tau_p_supply_mpa";
const TAU_T: &str = "ehvva.tau_temp_c";
const CD_T: &str = "ehvva.cd_temp_c";
const MO_P: &str = "ehvva.motion_p_supply_mpa";
const MO_T: &str = "ehvva.motion_temp_c";
const EV_N: &str = "evvt.engine_speed_rpm";
const EV_U: &str = "evvt.battery_voltage_v";

/// Number of characteristics (A2L objects) in the image.
pub const N_CHARACTERISTICS: usize = 59;

/// Every value of the image, in image order.
pub const CHARACTERISTICS: [Characteristic; N_CHARACTERISTICS] = [
    // EHVVA (Li 2018): actuation delay, main-valve time constant, discharge coefficient.
    c(
        TD_P,
        Shape::Axis(4),
        "MPa",
        0.0,
        30.0,
        "EHVVA td tables: supply pressure breakpoints",
    ),
    c(
        TD_T,
        Shape::Axis(5),
        "degC",
        -60.0,
        200.0,
        "EHVVA td tables: oil temperature breakpoints",
    ),
    c(
        "ehvva.td_open_ms",
        map(TD_P, 4, TD_T, 5),
        "ms",
        0.0,
        20.0,
        "EHVVA actuation delay td at valve opening (VO), Fig. 4",
    ),
    c(
        "ehvva.td_close_ms",
        map(TD_P, 4, TD_T, 5),
        "ms",
        0.0,
        20.0,
        "EHVVA actuation delay td at valve closing (VC), Fig. 4",
    ),
    c(
        TAU_P,
        Shape::Axis(2),
        "MPa",
        0.0,
        30.0,
        "EHVVA tau_p table: supply pressure breakpoints",
    ),
    c(
        TAU_T,
        Shape::Axis(3),
        "degC",
        -60.0,
        200.0,
        "EHVVA tau_p table: oil temperature breakpoints",
    ),
    c(
        "ehvva.tau_p_ms",
        map(TAU_P, 2, TAU_T, 3),
        "ms",
        0.01,
        5.0,
        "EHVVA main-valve outlet pressure time constant tau_p, Fig. 5",
    ),
    c(
        CD_T,
        Shape::Axis(4),
        "degC",
        -60.0,
        200.0,
        "EHVVA Cd curve: oil temperature breakpoints",
    ),
    c(
        "ehvva.cd",
        Shape::Curve { x_axis: CD_T, n: 4 },
        "-",
        0.05,
        1.0,
        "EHVVA mean effective discharge coefficient Cd(T), Table 4",
    ),
    c(
        "ehvva.pressure_delay_gain",
        Shape::Value,
        "-",
        0.0,
        2.0,
        "EHVVA: share of the td tables' fall with supply pressure applied (1 = the tables as they are)",
    ),
    c(
        "ehvva.direction_delay_gain",
        Shape::Value,
        "-",
        0.0,
        2.0,
        "EHVVA: share of the VO/VC td difference applied (1 = the tables as they are)",
    ),
    c(
        "ehvva.viscosity_gain",
        Shape::Value,
        "-",
        0.0,
        2.0,
        "EHVVA: share of Cd's temperature dependence applied (1 = the curve as it is)",
    ),
    c(
        "ehvva.delay_nominal_p_supply_mpa",
        Shape::Value,
        "MPa",
        1.0,
        30.0,
        "EHVVA: supply pressure td is read at when pressure_delay_gain is 0",
    ),
    // EHVVA valve motion after td to the 1 % / 99 % lift thresholds.
    c(
        MO_P,
        Shape::Axis(4),
        "MPa",
        0.0,
        30.0,
        "EHVVA valve motion tables: supply pressure breakpoints",
    ),
    c(
        MO_T,
        Shape::Axis(5),
        "degC",
        -60.0,
        200.0,
        "EHVVA valve motion tables: oil temperature breakpoints",
    ),
    c(
        "ehvva.motion_p_back_mpa",
        Shape::Value,
        "MPa",
        0.0,
        10.0,
        "EHVVA valve motion: back pressure the tables were computed at",
    ),
    c(
        "ehvva.motion_open_high_ms",
        map(MO_P, 4, MO_T, 5),
        "ms",
        0.0,
        50.0,
        "EHVVA high lift: from td,VO to 1 % lift",
    ),
    c(
        "ehvva.motion_open_low_ms",
        map(MO_P, 4, MO_T, 5),
        "ms",
        0.0,
        50.0,
        "EHVVA low lift: from td,VO to 1 % lift",
    ),
    c(
        "ehvva.motion_close_high_ms",
        map(MO_P, 4, MO_T, 5),
        "ms",
        0.0,
        50.0,
        "EHVVA high lift: from td,VC to 99 % lift on closing",
    ),
    c(
        "ehvva.motion_close_low_ms",
        map(MO_P, 4, MO_T, 5),
        "ms",
        0.0,
        50.0,
        "EHVVA low lift: from td,VC to 99 % lift on closing",
    ),
    // EVVT (Yang 2015): LPV plant alpha/(s(s+beta)) and the scheduled PI it implies.
    c(
        EV_N,
        Shape::Axis(3),
        "rpm",
        0.0,
        12000.0,
        "EVVT LPV tables: engine speed breakpoints",
    ),
    c(
        EV_U,
        Shape::Axis(3),
        "V",
        0.0,
        40.0,
        "EVVT LPV tables: battery voltage breakpoints",
    ),
    c(
        "evvt.alpha_deg_per_s2_rpm",
        map(EV_N, 3, EV_U, 3),
        "deg/(s^2*rpm)",
        1.0e-3,
        1.0e3,
        "EVVT plant gain alpha(N, V), eq. (12)",
    ),
    c(
        "evvt.beta_per_s",
        map(EV_N, 3, EV_U, 3),
        "1/s",
        0.0,
        1.0e3,
        "EVVT plant pole beta(N, V), eq. (12)",
    ),
    c(
        "evvt.crossover_rad_s",
        Shape::Value,
        "rad/s",
        0.01,
        100.0,
        "EVVT scheduled PI: target crossover frequency",
    ),
    c(
        "evvt.min_phase_margin_deg",
        Shape::Value,
        "deg",
        1.0,
        88.0,
        "EVVT scheduled PI: least phase margin (lowers the crossover at small beta)",
    ),
    c(
        "evvt.integral_rate_per_s",
        Shape::Value,
        "1/s",
        0.0,
        100.0,
        "EVVT scheduled PI: ki/kp",
    ),
    c(
        "evvt.integral_zone_deg",
        Shape::Value,
        "deg",
        0.0,
        40.0,
        "EVVT scheduled PI: the integrator runs within this error",
    ),
    c(
        "evvt.kp_min_rpm_per_deg",
        Shape::Value,
        "rpm/deg",
        0.001,
        1.0e4,
        "EVVT scheduled PI: least kp",
    ),
    c(
        "evvt.kp_max_rpm_per_deg",
        Shape::Value,
        "rpm/deg",
        0.001,
        1.0e4,
        "EVVT scheduled PI: largest kp",
    ),
    Characteristic {
        read_only: true,
        ..c(
            "evvt.kp_rpm_per_deg",
            map(EV_N, 3, EV_U, 3),
            "rpm/deg",
            0.0,
            1.0e4,
            "EVVT: the kp the alpha/beta tables imply at each grid point (derived, checked on load)",
        )
    },
    // Vacuum actuators (Thomasson 2013): static maps, supply-voltage compensation, friction
    // and backlash compensation.
    c(
        "vacuum.comp_u_min_v",
        Shape::Value,
        "V",
        1.0,
        30.0,
        "vacuum: below this supply voltage the compensation holds, eq. (15)",
    ),
    c(
        "vacuum.lpt.u_ref_v",
        Shape::Value,
        "V",
        1.0,
        30.0,
        "LPT wastegate: U_ref of the voltage compensation, eq. (1)",
    ),
    c(
        "vacuum.lpt.static_map",
        Shape::Array(4),
        "-",
        -1.0e3,
        1.0e3,
        "LPT valve map eq. (2): k1 (kPa/%), p01 (kPa), k2 (kPa/%), p02 (kPa)",
    ),
    c(
        "vacuum.lpt.position_map",
        Shape::Array(2),
        "-",
        -1.0e3,
        1.0e3,
        "LPT position map eq. (8): k (%/kPa), x0 (%)",
    ),
    c(
        "vacuum.lpt.tau_rise_s",
        Shape::Value,
        "s",
        1.0e-3,
        5.0,
        "LPT chamber time constant, rising pressure",
    ),
    c(
        "vacuum.lpt.tau_fall_s",
        Shape::Value,
        "s",
        1.0e-3,
        5.0,
        "LPT chamber time constant, falling pressure",
    ),
    c(
        "vacuum.lpt.fc_kpa",
        Shape::Value,
        "kPa",
        0.0,
        50.0,
        "LPT Coulomb friction (friction compensation)",
    ),
    c(
        "vacuum.lpt.backlash_pct",
        Shape::Value,
        "%",
        0.0,
        30.0,
        "LPT linkage clearance (backlash compensation)",
    ),
    c(
        "vacuum.hpt.u_ref_v",
        Shape::Value,
        "V",
        1.0,
        30.0,
        "HPT bypass: U_ref of the voltage compensation, eq. (1)",
    ),
    c(
        "vacuum.hpt.static_map",
        Shape::Array(4),
        "-",
        -1.0e3,
        1.0e3,
        "HPT valve map eq. (2): k1 (kPa/%), p01 (kPa), k2 (kPa/%), p02 (kPa)",
    ),
    c(
        "vacuum.hpt.position_map",
        Shape::Array(4),
        "-",
        -1.0e3,
        1.0e3,
        "HPT position map eq. (9): a1 (%), a2 (%/rad), a3 (kPa), a4 (kPa)",
    ),
    c(
        "vacuum.hpt.tau_rise_s",
        Shape::Value,
        "s",
        1.0e-3,
        5.0,
        "HPT chamber time constant, rising pressure",
    ),
    c(
        "vacuum.hpt.tau_fall_s",
        Shape::Value,
        "s",
        1.0e-3,
        5.0,
        "HPT chamber time constant, falling pressure",
    ),
    c(
        "vacuum.hpt.fc_kpa",
        Shape::Value,
        "kPa",
        0.0,
        50.0,
        "HPT Coulomb friction (friction compensation)",
    ),
    c(
        "vacuum.hpt.backlash_pct",
        Shape::Value,
        "%",
        0.0,
        30.0,
        "HPT linkage clearance (backlash compensation)",
    ),
    c(
        "vacuum.hpc.u_ref_v",
        Shape::Value,
        "V",
        1.0,
        30.0,
        "HPC bypass: U_ref of the voltage compensation, eq. (1)",
    ),
    c(
        "vacuum.hpc.static_map",
        Shape::Array(4),
        "-",
        -1.0e3,
        1.0e3,
        "HPC valve map eq. (5): k1 (kPa/%), p01 (kPa), k2 (kPa/%^3), u0 (%)",
    ),
    c(
        "vacuum.hpc.position_map",
        Shape::Array(4),
        "-",
        -1.0e3,
        1.0e3,
        "HPC position map eq. (9): a1 (%), a2 (%/rad), a3 (kPa), a4 (kPa)",
    ),
    c(
        "vacuum.hpc.tau_rise_s",
        Shape::Value,
        "s",
        1.0e-3,
        5.0,
        "HPC chamber time constant, rising pressure",
    ),
    c(
        "vacuum.hpc.tau_fall_s",
        Shape::Value,
        "s",
        1.0e-3,
        5.0,
        "HPC chamber time constant, falling pressure",
    ),
    c(
        "vacuum.hpc.fc_kpa",
        Shape::Value,
        "kPa",
        0.0,
        50.0,
        "HPC Coulomb friction (friction compensation)",
    ),
    c(
        "vacuum.hpc.backlash_pct",
        Shape::Value,
        "%",
        0.0,
        30.0,
        "HPC linkage clearance (backlash compensation)",
    ),
    c(
        "vacuum.lpt.p_amb_ref_kpa",
        Shape::Value,
        "kPa",
        50.0,
        120.0,
        "LPT: ambient pressure the position map was identified at",
    ),
    c(
        "vacuum.hpt.p_amb_ref_kpa",
        Shape::Value,
        "kPa",
        50.0,
        120.0,
        "HPT: ambient pressure the position map was identified at",
    ),
    c(
        "vacuum.hpc.p_amb_ref_kpa",
        Shape::Value,
        "kPa",
        50.0,
        120.0,
        "HPC: ambient pressure the position map was identified at",
    ),
    c("vacuum.lpt.effects", Shape::Array(4), "-", 0.0, 1.0, EFFECTS_DOC),
    c("vacuum.hpt.effects", Shape::Array(4), "-", 0.0, 1.0, EFFECTS_DOC),
    c("vacuum.hpc.effects", Shape::Array(4), "-", 0.0, 1.0, EFFECTS_DOC),
];

const EFFECTS_DOC: &str = "the ECU's actuator model (observer, stuck check): supply-voltage, pressure-direction, coulomb-friction, backlash, each 0 (off) or 1 (on)";

/// Number of f32 values in the image.
pub const N_VALUES: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < N_CHARACTERISTICS {
        n += CHARACTERISTICS[i].shape.len();
        i += 1;
    }
    n
};

/// Bytes of a whole image.
pub const IMAGE_BYTES: usize = HEADER_BYTES + 4 * N_VALUES + CRC_BYTES;
