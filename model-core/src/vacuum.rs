//! Vacuum boost-pressure actuation: PWM solenoid valve, vacuum membrane actuator (turbine
//! wastegate, turbine or compressor bypass), vacuum tank and pump, after Thomasson, Leufvén,
//! Criscuolo and Eriksson, "Modeling and validation of a boost pressure actuation system, for a
//! series sequentially turbocharged SI engine", Control Eng. Practice 21 (2013) 1860-1870.
//!
//! Structure (paper Sections 3-4):
//! - control signal to pressure: voltage-corrected duty, eq. (1); static map, eq. (2) (LPT and
//!   HPT) or eq. (5) (HPC), saturated between tank and ambient pressure; first-order pressure
//!   dynamics eq. (4) with separate rise and fall time constants (Fig. 5);
//! - pressure to position: the force balance eq. (6) divided by the membrane area, so every
//!   force is a pressure (eq. (7)); spring from the inverse of the static position map, linear
//!   eq. (8) or arctan eq. (9); Dahl friction eq. (10) with alpha = 1; end stops at 0 and 100 %;
//!   optionally a linkage clearance (the HPC stick of Figs. 10 and 12);
//! - mass flows to the tank: compressible orifice flow eq. (3) through a duty-dependent leakage
//!   area (Fig. 13) and the evacuation flow eq. (12); tank eq. (13); pump eq. (14).
//!
//! Units: pressure kPa, position % of stroke, duty %, voltage V, time s, volume L, leakage
//! area mm², mass flow mg/s. In these units the normalized mass is ~1e-4 kPa·s²/%, flows are
//! 1..1000 mg/s, and every intermediate stays well inside the Q32.32 range.
//!
//! Effects the diagnosis switches (DATA-FORMAT.md, plant `vacuum`) are the fields of
//! [`VacuumEffects`]; [`VacuumParams::baseline`] turns all of them off.

use crate::real::{horner, horner_in_range, Real};

/// Specific gas constant of air, J/(kg·K).
pub const R_AIR_J_PER_KG_K: f64 = 287.0;
/// Critical pressure ratio for gamma = 1.4: (2/(γ+1))^(γ/(γ-1)), eq. (3).
const P_CRIT: f64 = 0.528_281_787_717_174_4;
/// Largest mechanical integration step; longer calls are split (stiffest mode ~ 250 rad/s).
const H_MAX_S: f64 = 0.0005;
/// Cap on substeps per call so a huge `dt` cannot stall the caller.
const MAX_SUBSTEPS: f64 = 2000.0;
/// The arctan spring needs tan((x - a1)/a2) over the stroke; the angle is kept below this.
const THETA_MAX_RAD: f64 = 1.5;

/// Why a parameter set was rejected; the name is the offending field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VacuumParamError {
    BadParameter(&'static str),
}

/// Duty-to-pressure static relation of the solenoid valve, before saturation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StaticPressureMap {
    /// Eq. (2): p* = min(k1·u + p01, k2·u + p02) (LPT and HPT valves).
    PiecewiseLinear {
        k1_kpa_per_pct: f64,
        p01_kpa: f64,
        k2_kpa_per_pct: f64,
        p02_kpa: f64,
    },
    /// Eq. (5): p* = min(k1·u + p01, p_amb + k2·max(0, u − u0)³) (HPC valve); `k2` is
    /// negative: the pressure leaves ambient at u0.
    Cubic {
        k1_kpa_per_pct: f64,
        p01_kpa: f64,
        k2_kpa_per_pct3: f64,
        u0_pct: f64,
    },
}

/// Static pressure-to-position relation, identified at `p_amb_ref_kpa` (Figs. 9, 10).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PositionMap {
    /// Eq. (8): x = k·p + x0.
    Linear { k_pct_per_kpa: f64, x0_pct: f64 },
    /// Eq. (9): x = a1 + a2·atan((a3 − p)/a4).
    Arctan {
        a1_pct: f64,
        a2_pct_per_rad: f64,
        a3_kpa: f64,
        a4_kpa: f64,
    },
}

/// The catalogue effects (DATA-FORMAT.md, plant `vacuum`). `false` gives the baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VacuumEffects {
    /// `supply-voltage`: the valve sees duty·U/U_ref (eq. (1)); off: it sees the duty.
    pub supply_voltage: bool,
    /// `pressure-direction`: `tau_fall_s` for falling pressure (Fig. 5); off: `tau_rise_s`
    /// both ways.
    pub pressure_direction: bool,
    /// `coulomb-friction`: Dahl friction of magnitude `fc_kpa` on the rod (eq. (10)).
    pub coulomb_friction: bool,
    /// `backlash`: a clearance of `backlash_pct` between membrane and valve.
    pub backlash: bool,
}

impl VacuumEffects {
    pub const NONE: Self = Self {
        supply_voltage: false,
        pressure_direction: false,
        coulomb_friction: false,
        backlash: false,
    };
}

/// One solenoid valve and its membrane actuator. Plain f64, unit in the name.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumParams {
    /// U_ref of eq. (1): the supply voltage at which the static map holds.
    pub u_ref_v: f64,
    pub static_map: StaticPressureMap,
    /// Time constant of eq. (4) for rising pressure (air from ambient into the actuator).
    pub tau_rise_s: f64,
    /// Time constant of eq. (4) for falling pressure (air from actuator to tank).
    pub tau_fall_s: f64,
    pub position_map: PositionMap,
    /// Ambient pressure at which `position_map` was identified; the membrane sees
    /// p_amb − p_act, so the map is applied to p_amb_ref − (p_amb − p_act).
    pub p_amb_ref_kpa: f64,
    /// m/A_act of eq. (6) normalized as in eq. (7).
    pub mass_kpa_s2_per_pct: f64,
    /// b/A_act for the extending (vacuum-pulled) stroke.
    pub damping_extend_kpa_s_per_pct: f64,
    /// b/A_act for the retracting (spring-driven) stroke; Sec. 3.2: differs by about 2.
    pub damping_retract_kpa_s_per_pct: f64,
    /// Coulomb level F_c/A_act of Dahl's model eq. (10).
    pub fc_kpa: f64,
    /// Dahl's rest stiffness σ/A_act, eq. (10).
    pub dahl_sigma_kpa_per_pct: f64,
    /// Total linkage clearance between membrane and valve.
    pub backlash_pct: f64,
    /// Leakage area through the oscillating plunger per % effective duty (Fig. 13, right).
    pub leak_area_mm2_per_pct: f64,
    /// The leakage area grows up to this duty and is held beyond it (Fig. 13: linear to 80 %).
    pub leak_duty_max_pct: f64,
    /// Actuator chamber volume at x = 0 (eqs. (11), (12)).
    pub volume_x0_l: f64,
    /// Volume swept by the membrane over the full stroke (chamber shrinks as x grows).
    pub volume_stroke_l: f64,
    /// Gas temperature (isothermal, T_act = T_amb).
    pub temp_amb_k: f64,
    pub effects: VacuumEffects,
}

// Shared by all three presets: the same solenoid valve type (Sec. 2.2) on one bench.
/// U_ref of eq. (1)/(15). The paper gives no number; its Fig. 4 measurements span
/// U_syst = 10.3..11.9 V and the corrected duty axis keeps the raw one's range, so U_ref is a
/// nominal system voltage: 12 V.
const U_REF_V: f64 = 12.0;
/// Sea-level bench.
const P_AMB_REF_KPA: f64 = 100.0;
const TEMP_AMB_K: f64 = 293.0;
/// Fig. 13 right: the effective leakage area grows linearly to ~0.08 mm² (8e-8 m² on its
/// 0..1e-7 m² axis) at 80 % duty; held constant beyond, where the paper's line stops fitting.
const LEAK_AREA_MM2_PER_PCT: f64 = 0.001;
const LEAK_DUTY_MAX_PCT: f64 = 80.0;
/// Chamber volumes (eq. (12)): not in the paper; a ~70 mm membrane with a ~15 mm stroke
/// sweeps about 0.06 L of a 0.15 L chamber.
const VOLUME_X0_L: f64 = 0.15;
const VOLUME_STROKE_L: f64 = 0.06;

impl VacuumParams {
    /// Low-pressure turbine wastegate: piecewise-linear valve map eq. (2), linear position
    /// map eq. (8), small friction (Figs. 4, 5, 9, 11, 13).
    pub fn lpt() -> Self {
        Self {
            u_ref_v: U_REF_V,
            // Kink at (122-107)/(1.0-0.4) = 25 % (Sec. 3.1); p(20 %) = 99 kPa, p(100 %) = 22 kPa:
            // Fig. 4 spans 20..100 kPa over 20..100 % duty, pressure falling with duty.
            static_map: StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct: -0.4,
                p01_kpa: 107.0,
                k2_kpa_per_pct: -1.0,
                p02_kpa: 122.0,
            },
            // Fig. 5: steps settle in 0.1-0.3 s (98 % at 3.9τ: 0.16 and 0.27 s); which way is
            // faster the paper does not state numerically: venting from ambient (large
            // pressure difference) is taken as the faster one.
            tau_rise_s: 0.04,
            tau_fall_s: 0.07,
            // x = 0 at 90 kPa (10 kPa spring preload), x = 100 % at 40 kPa (Fig. 9).
            position_map: PositionMap::Linear {
                k_pct_per_kpa: -2.0,
                x0_pct: 180.0,
            },
            p_amb_ref_kpa: P_AMB_REF_KPA,
            // Mass and damping are not given numerically; chosen so that the rod follows the
            // pressure within a few tens of ms as in Fig. 11: spring 0.5 kPa/%,
            // ω = sqrt(0.5/2e-4) = 50 rad/s, ζ = 0.7 extending; retracting damped twice as much
            // (Sec. 3.2: "different, roughly by a factor of two").
            mass_kpa_s2_per_pct: 2.0e-4,
            damping_extend_kpa_s_per_pct: 0.014,
            damping_retract_kpa_s_per_pct: 0.028,
            // Fig. 9: "a small difference between ramps up and down": 2·Fc = 3 kPa. Dahl's σ
            // builds up the friction over Fc/σ = 0.5 % of travel (near-Coulomb, as Fig. 9's
            // sharp corners suggest).
            fc_kpa: 1.5,
            dahl_sigma_kpa_per_pct: 3.0,
            backlash_pct: 0.0,
            leak_area_mm2_per_pct: LEAK_AREA_MM2_PER_PCT,
            leak_duty_max_pct: LEAK_DUTY_MAX_PCT,
            volume_x0_l: VOLUME_X0_L,
            volume_stroke_l: VOLUME_STROKE_L,
            temp_amb_k: TEMP_AMB_K,
            effects: VacuumEffects {
                supply_voltage: true,
                pressure_direction: true,
                coulomb_friction: true,
                backlash: false,
            },
        }
    }

    /// High-pressure turbine bypass: valve map eq. (2) (Fig. 6 left), arctan position map
    /// eq. (9) and larger friction (Fig. 10 left). Steep around 70 kPa: the actuator most
    /// sensitive to supply voltage (Sec. 5.1).
    pub fn hpt() -> Self {
        Self {
            // Kink at (123.5-102.5)/(0.95-0.25) = 30 %; 80 kPa (Fig. 16) at u_corr = 46 %.
            static_map: StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct: -0.25,
                p01_kpa: 102.5,
                k2_kpa_per_pct: -0.95,
                p02_kpa: 123.5,
            },
            tau_rise_s: 0.05,
            tau_fall_s: 0.08,
            // 8 %/kPa at 70 kPa, the steepest of the three maps (Sec. 5.1: "the most
            // sensitive to supply voltage disturbances, due to steepness of the pressure to
            // position curves"); x = 0 at 85 kPa, 100 % at 55 kPa, x(80 kPa) = 6 %.
            position_map: PositionMap::Arctan {
                a1_pct: 50.0,
                a2_pct_per_rad: 40.0,
                a3_kpa: 70.0,
                a4_kpa: 5.0,
            },
            // Spring 0.125 kPa/% mid-stroke: ω = 35 rad/s.
            mass_kpa_s2_per_pct: 1.0e-4,
            damping_extend_kpa_s_per_pct: 0.006,
            damping_retract_kpa_s_per_pct: 0.012,
            // Fig. 10: "a larger friction" than the LPT (position dependent there; one Fc here).
            fc_kpa: 4.0,
            dahl_sigma_kpa_per_pct: 8.0,
            ..Self::lpt()
        }
    }

    /// High-pressure compressor bypass: cubic valve map eq. (5) (Fig. 6 right), arctan position
    /// map, the largest friction and the linkage clearance that makes it stick on closing
    /// (Figs. 10, 12).
    pub fn hpc() -> Self {
        Self {
            // Ambient up to u0 = 40 %, cubic fall to 60 kPa at 90 %, then the steep line
            // (both branches meet at 90 %: 420 − 4·90 = 100 − 3.2e-4·50³ = 60 kPa).
            static_map: StaticPressureMap::Cubic {
                k1_kpa_per_pct: -4.0,
                p01_kpa: 420.0,
                k2_kpa_per_pct3: -3.2e-4,
                u0_pct: 40.0,
            },
            tau_rise_s: 0.05,
            tau_fall_s: 0.085,
            // x = 0 at ambient (100 kPa), 100 % at 49 kPa, 2.3 %/kPa mid-stroke. The spring
            // barely holds the valve near its seat (x(95 kPa) = 8 %): a closing step ends
            // where the spring no longer overcomes the rod's 5 kPa friction, and the valve
            // stops half the clearance above the membrane, at 10 % (Sec. 3.2: "causing the
            // HPC actuator to stick at 10 % for closing steps").
            position_map: PositionMap::Arctan {
                a1_pct: 50.0,
                a2_pct_per_rad: 80.0,
                a3_kpa: 74.5,
                a4_kpa: 35.3,
            },
            mass_kpa_s2_per_pct: 1.0e-4,
            damping_extend_kpa_s_per_pct: 0.007,
            damping_retract_kpa_s_per_pct: 0.014,
            fc_kpa: 5.0,
            dahl_sigma_kpa_per_pct: 10.0,
            // Sec. 3.2: "small linkage clearance ... causing the HPC actuator to stick at 10 %".
            backlash_pct: 4.0,
            effects: VacuumEffects {
                supply_voltage: true,
                pressure_direction: true,
                coulomb_friction: true,
                backlash: true,
            },
            ..Self::lpt()
        }
    }

    /// The Coulomb level the rod sees: `fc_kpa` with the `coulomb-friction` effect on, else 0.
    pub fn rod_friction_kpa(&self) -> f64 {
        if self.effects.coulomb_friction {
            self.fc_kpa
        } else {
            0.0
        }
    }

    /// How far the valve lags the membrane in the direction of motion: half of
    /// `backlash_pct` with the `backlash` effect on, else 0.
    pub fn half_clearance_pct(&self) -> f64 {
        if self.effects.backlash {
            0.5 * self.backlash_pct
        } else {
            0.0
        }
    }

    /// The same actuator with every catalogue effect off (the diagnosis baseline).
    pub fn baseline(&self) -> Self {
        Self {
            effects: VacuumEffects::NONE,
            ..*self
        }
    }

    /// The same actuator with the given effects.
    pub fn with_effects(&self, effects: VacuumEffects) -> Self {
        Self { effects, ..*self }
    }

    fn validate(&self) -> Result<(), VacuumParamError> {
        let bad = |name| Err(VacuumParamError::BadParameter(name));
        let fin = |x: f64| x.is_finite();
        if !(fin(self.u_ref_v) && self.u_ref_v > 0.0) {
            return bad("u_ref_v");
        }
        match self.static_map {
            StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct,
                p02_kpa,
            } => {
                if !(fin(k1_kpa_per_pct) && fin(p01_kpa) && fin(k2_kpa_per_pct) && fin(p02_kpa)) {
                    return bad("static_map");
                }
            }
            StaticPressureMap::Cubic {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct3,
                u0_pct,
            } => {
                // |k2|·100³ must stay far inside the Q32 range.
                if !(fin(k1_kpa_per_pct)
                    && fin(p01_kpa)
                    && fin(k2_kpa_per_pct3)
                    && k2_kpa_per_pct3.abs() < 1.0
                    && fin(u0_pct))
                {
                    return bad("static_map");
                }
            }
        }
        if !(fin(self.tau_rise_s) && self.tau_rise_s > 0.0) {
            return bad("tau_rise_s");
        }
        if !(fin(self.tau_fall_s) && self.tau_fall_s > 0.0) {
            return bad("tau_fall_s");
        }
        match self.position_map {
            PositionMap::Linear { k_pct_per_kpa, x0_pct } => {
                if !(fin(k_pct_per_kpa) && k_pct_per_kpa.abs() > 1e-3 && fin(x0_pct)) {
                    return bad("position_map");
                }
            }
            PositionMap::Arctan {
                a1_pct,
                a2_pct_per_rad,
                a3_kpa,
                a4_kpa,
            } => {
                let ok = fin(a1_pct)
                    && fin(a2_pct_per_rad)
                    && a2_pct_per_rad > 0.0
                    && fin(a3_kpa)
                    && fin(a4_kpa)
                    && a4_kpa > 0.0;
                // The stroke 0..100 % must lie inside the map's open range a1 ± a2·π/2.
                if !ok
                    || (a1_pct / a2_pct_per_rad).abs() > THETA_MAX_RAD
                    || ((100.0 - a1_pct) / a2_pct_per_rad).abs() > THETA_MAX_RAD
                {
                    return bad("position_map");
                }
            }
        }
        if !(fin(self.p_amb_ref_kpa) && self.p_amb_ref_kpa > 0.0 && self.p_amb_ref_kpa < 400.0) {
            return bad("p_amb_ref_kpa");
        }
        if !(fin(self.mass_kpa_s2_per_pct) && self.mass_kpa_s2_per_pct >= 1e-6) {
            return bad("mass_kpa_s2_per_pct");
        }
        if !(fin(self.damping_extend_kpa_s_per_pct) && self.damping_extend_kpa_s_per_pct >= 0.0) {
            return bad("damping_extend_kpa_s_per_pct");
        }
        if !(fin(self.damping_retract_kpa_s_per_pct) && self.damping_retract_kpa_s_per_pct >= 0.0) {
            return bad("damping_retract_kpa_s_per_pct");
        }
        if !(fin(self.fc_kpa) && self.fc_kpa >= 0.0) {
            return bad("fc_kpa");
        }
        if !(fin(self.dahl_sigma_kpa_per_pct) && self.dahl_sigma_kpa_per_pct > 0.0 && self.dahl_sigma_kpa_per_pct < 1e4)
        {
            return bad("dahl_sigma_kpa_per_pct");
        }
        if !(fin(self.backlash_pct) && (0.0..=50.0).contains(&self.backlash_pct)) {
            return bad("backlash_pct");
        }
        if !(fin(self.leak_area_mm2_per_pct) && self.leak_area_mm2_per_pct >= 0.0) {
            return bad("leak_area_mm2_per_pct");
        }
        if !(fin(self.leak_duty_max_pct) && (0.0..=100.0).contains(&self.leak_duty_max_pct)) {
            return bad("leak_duty_max_pct");
        }
        if !(fin(self.volume_x0_l) && self.volume_x0_l > 0.0) {
            return bad("volume_x0_l");
        }
        if !(fin(self.volume_stroke_l) && self.volume_stroke_l >= 0.0 && self.volume_stroke_l < self.volume_x0_l) {
            return bad("volume_stroke_l");
        }
        if !(fin(self.temp_amb_k) && self.temp_amb_k > 100.0) {
            return bad("temp_amb_k");
        }
        Ok(())
    }
}

/// Inputs of one valve + actuator (DATA-FORMAT.md columns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumInputs<R> {
    /// Commanded PWM duty, clamped to 0..100.
    pub duty_pct: R,
    /// Supply voltage at the solenoid.
    pub u_batt_v: R,
    pub p_amb_kpa: R,
    pub p_tank_kpa: R,
}

/// Outputs of one valve + actuator after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumOutputs<R> {
    /// Actuator chamber pressure (eq. (4) output).
    pub p_act_kpa: R,
    /// Valve position, where `x_pct` is measured (after the linkage clearance).
    pub x_pct: R,
    /// Membrane (rod) position.
    pub x_membrane_pct: R,
    /// Saturated static pressure eq. (2)/(5), the target of eq. (4).
    pub p_static_kpa: R,
    /// Mean mass flow into the tank over the step: plunger leakage (eq. (3), Fig. 13) plus
    /// evacuation (eq. (12)).
    pub flow_to_tank_mg_s: R,
}

/// Compressible orifice flow eq. (3), signed from `p_a` to `p_b`, in mg/s for an effective
/// area in mm². `c_orifice` = 1e3/sqrt(R·T) converts kPa·mm² to mg/s.
pub fn orifice_flow_mg_s<R: Real>(p_a_kpa: R, p_b_kpa: R, area_mm2: R, c_orifice: R) -> R {
    let (p_up, p_down, dir) = if p_a_kpa >= p_b_kpa {
        (p_a_kpa, p_b_kpa, R::ONE)
    } else {
        (p_b_kpa, p_a_kpa, -R::ONE)
    };
    if !positive(p_up) || !positive(area_mm2) {
        return R::ZERO;
    }
    let ratio = (p_down / p_up).clamp(R::from_f64(P_CRIT), R::ONE);
    dir * c_orifice * p_up * area_mm2 * psi(ratio)
}

/// Ψ(Π)² = 7(Π^(10/7) − Π^(12/7)) on [Π_crit, 1] as a polynomial of degree 5 in
/// w = (2Π − Π_crit − 1)/(1 − Π_crit), w in [−1, 1], lowest power first: the Chebyshev
/// interpolant at 64 nodes, written in powers of w (largest error 4.3e-7, a thirtieth of
/// Q16.16's LSB; `psi_squared_polynomial_is_within_its_stated_error` checks it). The
/// fixed-point form of [`psi`]: its ln and exp cost ~250 instructions a call on the
/// Cortex-M4 in Q16.16, the polynomial five products.
const PSI_SQ_POLY: [f64; 6] = [
    0.352_622_505_523_097_65,
    -0.233_770_308_159_076_85,
    -0.118_452_024_627_122_5,
    -0.000_602_266_990_282_783_5,
    0.000_257_715_776_684_236_4,
    -5.596_457_624_768_014e-5,
];

/// Ψ(Π) = sqrt(2γ/(γ−1)·(Π^(2/γ) − Π^((γ+1)/γ))) for γ = 1.4, i.e. sqrt(7·y¹⁰·(1 − y²))
/// with y = Π^(1/7); Π already limited to [Π_crit, 1] (choking, eq. (3)).
fn psi<R: Real>(ratio: R) -> R {
    if !R::IS_FLOAT {
        // Fixed point: Ψ² as the polynomial [`PSI_SQ_POLY`] in w, Horner's scheme written
        // out, every product in range (|w| <= 1, each partial sum below 1).
        let f = R::from_f64;
        let c = PSI_SQ_POLY;
        let w = ratio.mul_in_range(f(2.0 / (1.0 - P_CRIT))) - f((1.0 + P_CRIT) / (1.0 - P_CRIT));
        let mut s = f(c[4]) + w.mul_in_range(f(c[5]));
        s = f(c[3]) + w.mul_in_range(s);
        s = f(c[2]) + w.mul_in_range(s);
        s = f(c[1]) + w.mul_in_range(s);
        s = f(c[0]) + w.mul_in_range(s);
        return s.max(R::ZERO).sqrt();
    }
    let y = ratio.ln().div_by(R::divisor(R::from_f64(7.0))).exp();
    let y2 = y * y;
    let y4 = y2 * y2;
    let y10 = y4 * y4 * y2;
    (R::from_f64(7.0) * y10 * (R::ONE - y2)).sqrt()
}

/// (−1)^(k+1)/k!, k = 1..=16: the Taylor coefficients of 1 − e^(−x).
const ONE_MINUS_EXP_NEG_COEFFS: [f64; 16] = {
    let mut c = [0.0; 16];
    let mut term = 1.0;
    let mut k = 0;
    while k < 16 {
        term /= (k + 1) as f64;
        c[k] = if k % 2 == 0 { term } else { -term };
        k += 1;
    }
    c
};

/// 1 − e^(−x) for x >= 0, accurate for small x where `1 - exp(-x)` would cancel (f32's exp
/// loses ~1e-6 absolute): Taylor series to x¹⁶ below 1 (truncation < 3e-14) by Horner's rule
/// with the coefficients precomputed (multiplications only: a division chain cost the host
/// diagnosis, which runs this every rod substep, twice its time), the direct form above.
///
/// Unrolled by `horner!` so that each coefficient converts to `R` at compile time (a loop left
/// `R::from_f64` at run time: soft-float double arithmetic on the target, ~60 % of the Q16.16
/// actuator step). The same operations in the same order as the loop `s = c + x·s` from s = 0.
///
/// A type that cannot hold 1e-6 (Q16.16, LSB 1.5e-5) takes the series to x⁸ (the first term
/// left out below 2.8e-7) with products in range: 0 <= x < 1, coefficients and partial sums
/// within [−1, 1].
fn one_minus_exp_neg<R: Real>(x: R) -> R {
    if x < R::ONE {
        const C: [f64; 16] = ONE_MINUS_EXP_NEG_COEFFS;
        if !crate::real::resolves::<R>(1e-6) {
            let s = horner_in_range!(R, x; C[0], C[1], C[2], C[3], C[4], C[5], C[6], C[7], C[8]);
            return x.mul_in_range(s);
        }
        let s = horner!(R, x; C[0], C[1], C[2], C[3], C[4], C[5], C[6], C[7], C[8], C[9], C[10], C[11],
            C[12], C[13], C[14], C[15]);
        x * s
    } else {
        R::ONE - (-x).exp()
    }
}

/// Eq. (4)'s 1 − e^(−dt/τ) for a step `dt_s` and τ as a divisor, with the power of two it is
/// held times. The floats: the value, shift 0. Fixed point: a 1 ms step on τ = 40 ms is
/// 0.0248, and Q16.16's LSB is 6e-4 of it, a time-constant error that left the chamber
/// pressure 0.004 kPa off f64's and the rod, whose force balance is a few kPa, 0.3 % of its
/// stroke (until session 18). Below 1/2 it is computed and held times 2^k in [1/2, 1):
/// x·2^k = (dt·2^k)/τ, times (1 − e^(−x))/x from the series at x.
fn scaled_decay<R: Real>(dt_s: R, tau_div: R::Divisor) -> (R, i32) {
    let x = dt_s.div_by(tau_div);
    let half = R::from_f64(0.5);
    if R::IS_FLOAT || x >= half || x <= R::ZERO {
        return (one_minus_exp_neg(x), 0);
    }
    let (mut k, mut coarse) = (0, x);
    while k < 14 && coarse < half {
        coarse = coarse.mul_pow2(1);
        k += 1;
    }
    let x_scaled = dt_s.mul_pow2(k).div_by(tau_div);
    const C: [f64; 16] = ONE_MINUS_EXP_NEG_COEFFS;
    // x < 1/2: the series' terms to x⁸/9! (below 1e-8), each product in range.
    let over_x = horner_in_range!(R, x; C[0], C[1], C[2], C[3], C[4], C[5], C[6], C[7], C[8]);
    (x_scaled.mul_in_range(over_x), k)
}

/// `x > 0`, false for NaN too (so a NaN step or area does nothing).
fn positive<R: Real>(x: R) -> bool {
    x > R::ZERO
}

/// Number of substeps of at most `h_max_s` in `dt_s`. The ratio is shrunk by 1e-6 first so
/// that a step that is a whole multiple of `h_max_s` in decimal (0.001 s as f32 is
/// 0.0010000000475) gets the same count in every number type, and by half the type's
/// spacing over `h_max_s` for fixed point, whose step is the requested one rounded to that
/// spacing (1 ms in Q16.16 is 66·2^-16 s, 0.7 % long: 3 sub-steps of 0.5 ms where f32 takes 2,
/// until session 18). A sub-step may then exceed `h_max_s` by that rounding.
fn substeps<R: Real>(dt_s: R, h_max_s: f64) -> f64 {
    let ratio = dt_s.to_f64() / h_max_s * (1.0 - 1e-6);
    // (A term of 0 for the floats would still cost them a soft-float division on the target.)
    let rounding = if R::ABS_RESOLUTION > 0.0 {
        0.5 * R::ABS_RESOLUTION / h_max_s
    } else {
        0.0
    };
    libm::ceil(ratio - rounding).clamp(1.0, MAX_SUBSTEPS)
}

/// Saturation of eq. (2)/(5): between the tank (lowest reachable) and ambient pressure.
fn saturate<R: Real>(p: R, p_tank: R, p_amb: R) -> R {
    let lo = p_tank.min(p_amb);
    p.clamp(lo, p_amb)
}

/// One PWM solenoid valve and its vacuum membrane actuator.
#[derive(Clone, Copy, Debug)]
pub struct VacuumValveActuator<R: Real> {
    maps: Maps<R>,
    effects: VacuumEffects,
    u_ref_v: R::Divisor,
    /// τ of eq. (4) rising and falling, as divisors (a rate's first step divides the step by them).
    tau_rise_div: R::Divisor,
    tau_fall_div: R::Divisor,
    p_amb_ref_kpa: R,
    inv_mass: R,
    damping_extend: R,
    damping_retract: R,
    fc_kpa: R,
    sigma_over_fc: R,
    half_backlash_pct: R,
    leak_area_per_pct: R,
    leak_duty_max_pct: R,
    volume_x0_l: R,
    volume_per_pct_l: R,
    c_orifice: R,
    /// mg per kPa·L at T_amb: 1e6/(R·T).
    c_mass: R,
    // State.
    p_act_kpa: R,
    x_mem_pct: R,
    v_pct_s: R,
    friction_kpa: R,
    x_valve_pct: R,
    /// Largest rod integration step, s ([`Self::with_rod_step_s`]).
    rod_step_max_s: f64,
    /// Eq. (4)'s 1 − e^(−dt/τ) for rising and falling pressure at the step `decay_dt_s` (0: none
    /// yet): steps come at a fixed rate, so they are computed once per rate.
    decay_dt_s: R,
    decay_rise: R,
    decay_fall: R,
    /// Fixed point: `decay_rise`, `decay_fall` are held times 2^shift ([`scaled_decay`]),
    /// 0 for the floats.
    decay_shift: [i32; 2],
    /// `decay_dt_s` as a divisor (the evacuation flow divides by the step).
    decay_dt_div: R::Divisor,
    /// The rod substeps of a step of `rods_dt_s` (0: none yet): their number, as `R` and as a
    /// divisor, their length, and the implicit damping's denominators 1 + h·b/m (extending,
    /// retracting) as divisors, computed once per step length (the count goes through f64,
    /// soft-float on the target; a prepared divisor makes a fixed-point division a multiply).
    rods_dt_s: R,
    rods_n: u32,
    rods_n_div: R::Divisor,
    rods_h_s: R,
    rods_damping_div: [R::Divisor; 2],
    /// Fixed point only (the floats keep their operations and bits): 1/n and h/m, products
    /// where the floats divide by n and multiply by h, then 1/m, every sub-step.
    rods_inv_n: R,
    rods_h_over_mass: R,
    /// Fixed point: (h/m)/(1 + h·b/m) per direction, and b (extending, retracting) times 2^10.
    rods_gain: [R; 2],
    damping_x1024: [R; 2],
}

/// Longest rod step [`VacuumValveActuator::with_rod_step_s`] accepts: the semi-implicit
/// Euler step of the stiffest spring mode (~250 rad/s) is stable below 2/ω = 8 ms.
const ROD_STEP_MAX_S: f64 = 0.005;

impl<R: Real> VacuumValveActuator<R> {
    /// Builds the actuator at rest, vented to `p_amb_ref_kpa` (valve closed, x at the spring's
    /// rest position). Use [`Self::settle`] to start at a steady operating point.
    pub fn new(p: &VacuumParams) -> Result<Self, VacuumParamError> {
        p.validate()?;
        let f = R::from_f64;
        let fc = p.rod_friction_kpa();
        let sigma_over_fc = if fc > 0.0 { p.dahl_sigma_kpa_per_pct / fc } else { 0.0 };
        let half_backlash = p.half_clearance_pct();
        let rt = R_AIR_J_PER_KG_K * p.temp_amb_k;
        let maps = Maps::new(p);
        let p_amb_ref = f(p.p_amb_ref_kpa);
        let x0 = maps.position(p_amb_ref).clamp(R::ZERO, f(100.0));
        Ok(Self {
            maps,
            effects: p.effects,
            u_ref_v: R::divisor(f(p.u_ref_v)),
            tau_rise_div: R::divisor(f(p.tau_rise_s)),
            tau_fall_div: R::divisor(f(p.tau_fall_s)),
            p_amb_ref_kpa: p_amb_ref,
            inv_mass: f(1.0 / p.mass_kpa_s2_per_pct),
            damping_extend: f(p.damping_extend_kpa_s_per_pct),
            damping_retract: f(p.damping_retract_kpa_s_per_pct),
            fc_kpa: f(fc),
            sigma_over_fc: f(sigma_over_fc),
            half_backlash_pct: f(half_backlash),
            leak_area_per_pct: f(p.leak_area_mm2_per_pct),
            leak_duty_max_pct: f(p.leak_duty_max_pct),
            volume_x0_l: f(p.volume_x0_l),
            volume_per_pct_l: f(p.volume_stroke_l / 100.0),
            c_orifice: f(1e3 / libm::sqrt(rt)),
            c_mass: f(1e6 / rt),
            p_act_kpa: p_amb_ref,
            x_mem_pct: x0,
            v_pct_s: R::ZERO,
            friction_kpa: R::ZERO,
            x_valve_pct: x0,
            rod_step_max_s: H_MAX_S,
            decay_dt_s: R::ZERO,
            decay_rise: R::ZERO,
            decay_fall: R::ZERO,
            decay_shift: [0; 2],
            decay_dt_div: R::divisor(R::ONE),
            rods_dt_s: R::ZERO,
            rods_n: 0,
            rods_n_div: R::divisor(R::ONE),
            rods_h_s: R::ZERO,
            rods_inv_n: R::ONE,
            rods_h_over_mass: R::ZERO,
            rods_gain: [R::ZERO; 2],
            damping_x1024: [
                f(p.damping_extend_kpa_s_per_pct * 1024.0),
                f(p.damping_retract_kpa_s_per_pct * 1024.0),
            ],
            rods_damping_div: [R::divisor(R::ONE); 2],
        })
    }

    /// The same actuator with its rod (eqs. (6), (7), (10)) integrated in steps of at most
    /// `h_max_s` instead of the default 0.5 ms: a coarser step trades accuracy for speed where
    /// many simulations run (the host diagnosis fits at 1 ms). Between 1 µs and 5 ms.
    pub fn with_rod_step_s(mut self, h_max_s: f64) -> Result<Self, VacuumParamError> {
        if !(h_max_s.is_finite() && (1e-6..=ROD_STEP_MAX_S).contains(&h_max_s)) {
            return Err(VacuumParamError::BadParameter("rod_step_max_s"));
        }
        self.rod_step_max_s = h_max_s;
        self.rods_dt_s = R::ZERO;
        Ok(self)
    }

    /// Largest rod integration step, s.
    pub fn rod_step_s(&self) -> f64 {
        self.rod_step_max_s
    }

    /// The duty the valve acts on: eq. (1) with the `supply-voltage` effect, else the duty.
    pub fn effective_duty_pct(&self, duty_pct: R, u_batt_v: R) -> R {
        let u = duty_pct.clamp(R::ZERO, R::from_f64(100.0));
        if self.effects.supply_voltage {
            (u * u_batt_v.max(R::ZERO)).div_by(self.u_ref_v)
        } else {
            u
        }
    }

    /// Saturated static pressure, eqs. (1), (2)/(5).
    pub fn static_pressure_kpa(&self, inputs: &VacuumInputs<R>) -> R {
        let u = self.effective_duty_pct(inputs.duty_pct, inputs.u_batt_v);
        self.static_pressure_at_duty(u, inputs)
    }

    /// Eq. (2)/(5) saturated at the effective duty `u`.
    fn static_pressure_at_duty(&self, u: R, inputs: &VacuumInputs<R>) -> R {
        saturate(
            self.maps.unsaturated_pressure(u, inputs.p_amb_kpa),
            inputs.p_tank_kpa,
            inputs.p_amb_kpa,
        )
    }

    /// Frictionless static membrane position for a chamber pressure, eqs. (7)-(9), on the
    /// stroke 0..100 %.
    pub fn static_position_pct(&self, p_act_kpa: R, p_amb_kpa: R) -> R {
        let p_map = self.p_amb_ref_kpa - (p_amb_kpa - p_act_kpa);
        self.maps.position(p_map).clamp(R::ZERO, R::from_f64(100.0))
    }

    /// Puts the actuator at the steady state of constant `inputs`: static pressure, static
    /// position, no friction load, valve centred on the membrane.
    pub fn settle(&mut self, inputs: &VacuumInputs<R>) {
        self.p_act_kpa = self.static_pressure_kpa(inputs);
        self.x_mem_pct = self.static_position_pct(self.p_act_kpa, inputs.p_amb_kpa);
        self.v_pct_s = R::ZERO;
        self.friction_kpa = R::ZERO;
        self.x_valve_pct = self.x_mem_pct;
    }

    pub fn p_act_kpa(&self) -> R {
        self.p_act_kpa
    }
    pub fn x_pct(&self) -> R {
        self.x_valve_pct
    }
    pub fn x_membrane_pct(&self) -> R {
        self.x_mem_pct
    }
    /// Current friction load (Dahl state), kPa.
    pub fn friction_kpa(&self) -> R {
        self.friction_kpa
    }

    fn volume_l(&self, x: R) -> R {
        self.volume_x0_l - self.volume_per_pct_l * x
    }

    /// Advances by `dt_s`. Pressure eq. (4) is integrated exactly over the step; the rod
    /// (eqs. (6), (7), (10)) in substeps of at most 0.5 ms (or [`Self::with_rod_step_s`]) with
    /// the chamber pressure interpolated across the step.
    pub fn step(&mut self, inputs: &VacuumInputs<R>, dt_s: R) -> VacuumOutputs<R> {
        // The effective duty and the static pressure once for the whole step.
        let u = self.effective_duty_pct(inputs.duty_pct, inputs.u_batt_v);
        let p_stat = self.static_pressure_at_duty(u, inputs);
        if !positive(dt_s) {
            return self.outputs(p_stat, R::ZERO);
        }
        let p_old = self.p_act_kpa;
        let volume_old = self.volume_l(self.x_mem_pct);
        self.advance_to(inputs.p_amb_kpa, p_stat, dt_s);
        let p_new = self.p_act_kpa;

        // Mass flows into the tank. Leakage eq. (3) through the Fig. 13 area, from the chamber.
        let area = self.leak_area_per_pct * u.clamp(R::ZERO, self.leak_duty_max_pct);
        let leak = orifice_flow_mg_s(p_new, inputs.p_tank_kpa, area, self.c_orifice);
        // Eq. (12): the chamber's mass loss d(pV)/(RT), counted only when it leaves towards the
        // tank (a gain comes from ambient through the valve).
        let pv_change = p_new * self.volume_l(self.x_mem_pct) - p_old * volume_old;
        // (`advance_to` has prepared the step as a divisor.)
        let evacuation = ((-pv_change).max(R::ZERO) * self.c_mass).div_by(self.decay_dt_div);
        self.outputs(p_stat, leak + evacuation)
    }

    /// [`Self::step`] without the mass flows to the tank: the same pressure and positions, for
    /// simulations that only compare those (the host diagnosis runs millions of steps).
    pub fn advance(&mut self, inputs: &VacuumInputs<R>, dt_s: R) {
        if !positive(dt_s) {
            return;
        }
        let p_stat = self.static_pressure_kpa(inputs);
        self.advance_to(inputs.p_amb_kpa, p_stat, dt_s);
    }

    /// [`Self::advance`] towards the static pressure `p_stat`, for `dt_s > 0`.
    fn advance_to(&mut self, p_amb_kpa: R, p_stat: R, dt_s: R) {
        let p_old = self.p_act_kpa;
        let p_new = self.pressure_towards(p_stat, dt_s);
        if dt_s != self.rods_dt_s {
            let n = substeps(dt_s, self.rod_step_max_s) as u32;
            // A whole count (at most MAX_SUBSTEPS) converts exactly from an integer; from f64
            // it was soft-float arithmetic in fixed point. The floats' divisor is the count
            // itself, so their h is dt/n as before.
            let n_r = R::from_i32(n as i32);
            self.rods_n_div = R::divisor(n_r);
            let h = dt_s.div_by(self.rods_n_div);
            self.rods_dt_s = dt_s;
            self.rods_n = n;
            self.rods_h_s = h;
            self.rods_inv_n = R::ONE.div_by(self.rods_n_div);
            self.rods_h_over_mass = h * self.inv_mass;
            if R::IS_FLOAT {
                self.rods_damping_div = [
                    R::divisor(R::ONE + h * self.damping_extend * self.inv_mass),
                    R::divisor(R::ONE + h * self.damping_retract * self.inv_mass),
                ];
            } else {
                // h/m first: h·b is below Q16.16's LSB (0.5 ms · 0.006 kPa·s/% = 3e-6), and
                // the damping vanished (the rod ran up to twice as fast as in f64 until
                // session 18); h/m is of order 1-10. One division each, no divisor kept.
                let hm = self.rods_h_over_mass;
                self.rods_gain = [
                    hm / (R::ONE + self.damping_extend * hm),
                    hm / (R::ONE + self.damping_retract * hm),
                ];
            }
        }
        let dp_step = if R::IS_FLOAT {
            (p_new - p_old).div_by(self.rods_n_div)
        } else {
            // |p_new − p_old| is below the pressures' span and 1/n <= 1.
            (p_new - p_old).mul_in_range(self.rods_inv_n)
        };
        let hundred = R::from_f64(100.0);
        let mut p_sub = p_old;
        for _ in 0..self.rods_n {
            p_sub += dp_step;
            self.mechanics_substep(p_amb_kpa - p_sub, self.rods_h_s, hundred);
        }
    }

    /// Advances the chamber pressure alone (eq. (4)) by `dt_s` and returns it; the rod stays
    /// where it is. Eq. (4) does not depend on the rod, so a pressure model can be fitted to a
    /// logged chamber pressure at a fraction of the cost of the whole actuator.
    pub fn advance_pressure(&mut self, inputs: &VacuumInputs<R>, dt_s: R) -> R {
        if positive(dt_s) {
            let p_stat = self.static_pressure_kpa(inputs);
            self.pressure_towards(p_stat, dt_s);
        }
        self.p_act_kpa
    }

    /// Eq. (4) over `dt_s > 0` towards `p_stat`; the new chamber pressure.
    fn pressure_towards(&mut self, p_stat: R, dt_s: R) -> R {
        let p_old = self.p_act_kpa;
        // Eq. (4), exact for a constant target: p += (p_stat − p)(1 − e^(−dt/τ)).
        if dt_s != self.decay_dt_s {
            self.decay_dt_s = dt_s;
            let (rise, rise_shift) = scaled_decay(dt_s, self.tau_rise_div);
            let (fall, fall_shift) = scaled_decay(dt_s, self.tau_fall_div);
            (self.decay_rise, self.decay_fall, self.decay_shift) = (rise, fall, [rise_shift, fall_shift]);
            self.decay_dt_div = R::divisor(dt_s);
        }
        let (decay, shift) = if self.effects.pressure_direction && p_stat < p_old {
            (self.decay_fall, self.decay_shift[1])
        } else {
            (self.decay_rise, self.decay_shift[0])
        };
        self.p_act_kpa = if R::IS_FLOAT {
            p_old + (p_stat - p_old) * decay
        } else {
            // |p_stat − p_old| is below the pressures' span, the scaled decay below 1.
            p_old + (p_stat - p_old).mul_in_range(decay).mul_pow2(-shift)
        };
        self.p_act_kpa
    }

    /// One semi-implicit Euler step of the normalized force balance eq. (7) with mass and
    /// damping (eq. (6)), Dahl friction (eq. (10)), end stops and the linkage clearance.
    fn mechanics_substep(&mut self, dp_membrane_kpa: R, h: R, hundred: R) {
        let x = self.x_mem_pct;
        let spring = self.p_amb_ref_kpa - self.maps.pressure_at(x);
        let b = if self.v_pct_s >= R::ZERO { 0 } else { 1 };
        let drive = dp_membrane_kpa - spring - self.friction_kpa;
        // Damping implicit: stable for any b.
        let mut v = if R::IS_FLOAT {
            // (1 + h·b/m prepared once per step length.)
            (self.v_pct_s + h * drive * self.inv_mass).div_by(self.rods_damping_div[b])
        } else {
            // The same step as v + (h/m)(drive − b·v)/(1 + h·b/m), so that the velocity the
            // damping settles at, drive/b, carries b's precision, not that of h·b/m (0.03
            // for the HPT, whose error in Q16.16 left the moving rod 0.5 %/s fast):
            // b·v from b held times 2^10.
            let damping = (self.v_pct_s * self.damping_x1024[b]).mul_pow2(-10);
            self.v_pct_s + (drive - damping) * self.rods_gain[b]
        };
        let mut x_new = x + h * v;
        // The membrane's stops lie half the clearance beyond the valve's travel: x_pct is
        // measured on the valve, whose 0 and 100 % are its own seat and stop, so a unit with
        // clearance still reaches both (the membrane takes up the play beyond them).
        let x_min = -self.half_backlash_pct;
        let x_max = hundred + self.half_backlash_pct;
        if x_new <= x_min {
            x_new = x_min;
            v = v.max(R::ZERO);
        } else if x_new >= x_max {
            x_new = x_max;
            v = v.min(R::ZERO);
        }
        // Dahl eq. (10) with α = 1 is linear in x for a fixed sign of motion:
        // F → s·Fc + (F − s·Fc)·exp(−σ|Δx|/Fc), exact and unconditionally stable.
        let dx = x_new - x;
        if self.fc_kpa > R::ZERO && dx != R::ZERO {
            let target = dx.sign() * self.fc_kpa;
            self.friction_kpa += (target - self.friction_kpa) * one_minus_exp_neg(self.sigma_over_fc * dx.abs());
        }
        self.x_mem_pct = x_new;
        self.v_pct_s = v;
        // Play operator: the valve moves only when the membrane takes up the clearance.
        let lo = x_new - self.half_backlash_pct;
        let hi = x_new + self.half_backlash_pct;
        self.x_valve_pct = self.x_valve_pct.clamp(lo, hi).clamp(R::ZERO, hundred);
    }

    fn outputs(&self, p_stat: R, flow: R) -> VacuumOutputs<R> {
        VacuumOutputs {
            p_act_kpa: self.p_act_kpa,
            x_pct: self.x_valve_pct,
            x_membrane_pct: self.x_mem_pct,
            p_static_kpa: p_stat,
            flow_to_tank_mg_s: flow,
        }
    }
}

mod maps;
use maps::Maps;
pub use maps::VacuumStaticModel;

mod tank;
pub use tank::{VacuumSystem, VacuumSystemOutputs, VacuumTank, VacuumTankParams};

#[cfg(test)]
mod tests;
