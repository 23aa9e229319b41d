//! Electric cam phaser (EVVT): planetary gear set whose carrier is driven by an electric motor,
//! ring gear driven by the timing belt at half crank speed, sun gear on the camshaft
//! (Yang, Zhang, Song, Zhu, "LPV Model Identification of an EVVT System", ACC 2015).
//!
//! The identified LPV model, eq. (12): from the motor speed command (motor speed minus ring-gear
//! speed, rpm) to the cam phase (crank degrees),
//!
//! ```text
//!     G(N, V) = α(N, V) / (s (s + β(N, V)))
//! ```
//!
//! with engine speed N and battery voltage V as scheduling parameters, bounded as in
//! eqs. (13)-(14). The state is `x1` = cam phase (crank deg), `x2` = phase rate (crank deg/s):
//! `x1' = x2`, `x2' = -β x2 + α u`. It is stepped with the exact zero-order-hold
//! discretization [`zoh`], recomputed whenever α, β or the step changes.
//!
//! # The α, β table (a design, not the paper's numbers)
//!
//! The PDF-to-text extraction lost Table III: only fragments survive ("s(s+8.47)", "0.45",
//! "s(s+10.6)", "s(s+1.4)") and the upper bounds `α <= 0.595`, `β <= 6.975` of eqs. (13)-(14).
//! The extraction also drops every digit '2' throughout the text ("015" for 2015, "\[1\]" for
//! \[12\], "nd order" for 2nd order, "centered at 5" for 25 degrees), so those fragments are not
//! reliable either: β fragments 8.47 and 10.6 exceed the bound 6.975, which therefore probably
//! lost a '2' itself (e.g. 26.975). We keep the bounds as given (max α = 0.595 crank-deg/(s²·rpm),
//! max β = 6.975 1/s, both at 1400 rpm, 14 V) and designed the remaining eight points to honour
//! everything the text states (Section III, Fig. 3, Section IV-D, Fig. 10):
//!
//! - higher battery voltage → larger α and β at every engine speed (more motor torque);
//! - at 14 V, higher engine speed → larger α and β (torque-limited motor, more power at speed);
//! - at 9.5 V, higher engine speed → smaller α and β (motor power saturates);
//! - engine speed has less influence than voltage (at 14 V and 11.5 V speed moves α, β by about
//!   10 %, voltage moves them 2× to 8.5×);
//! - with one proportional gain kp = [`PAPER_DESIGN_KP_RPM_PER_DEG`] for all nine points, the
//!   closed-loop step settling time at 800 rpm about doubles from 14 V to 9.5 V, and at 9.5 V
//!   about halves from 1400 rpm to 800 rpm (Fig. 3 text). `tests/evvt_paper.rs` measures it.
//!
//! The DC velocity gain α/β (crank-deg/s per rpm) falls at low voltage (0.087 → 0.079 → 0.045 at
//! 14 V / 800 rpm, 9.5 V / 800 rpm, 9.5 V / 1400 rpm): the motor cannot reach the commanded
//! speed difference when its power saturates ("reduced DC gain", Section IV-D).
//!
//! Note on units: the kinematic gain of eq. (11) for a motor that drives the carrier directly
//! is 12·(n_s + n_r)/n_s crank-deg/s per rpm (tens of degrees per second per rpm), about 400
//! times the identified α/β. The paper's command signal therefore carries a scaling that the
//! text does not give; the plant model follows the identified α/β (the brief's units), and
//! [`PlanetaryGear`] gives the ideal kinematics for the feed-through.

use crate::lut::{Lut2, LutError};
use crate::real::{horner_in_range, Real};

/// Engine speed breakpoints of the identification grid (Section IV-B), rpm.
pub const ENGINE_SPEED_BREAKPOINTS_RPM: [f64; 3] = [800.0, 1100.0, 1400.0];
/// Battery voltage breakpoints of the identification grid (Section IV-B), V.
pub const BATTERY_VOLTAGE_BREAKPOINTS_V: [f64; 3] = [9.5, 11.5, 14.0];

/// α(N, V), crank-deg/(s²·rpm), rows: engine speed 800/1100/1400 rpm, columns: battery
/// voltage 9.5/11.5/14 V. Designed (see the module doc); maximum 0.595 as eq. (13).
pub const PAPER_DESIGN_ALPHA: [[f64; 3]; 3] = [[0.27, 0.36, 0.54], [0.16, 0.34, 0.57], [0.07, 0.32, 0.595]];
/// β(N, V), 1/s, same layout as [`PAPER_DESIGN_ALPHA`]; maximum 6.975 as eq. (14).
pub const PAPER_DESIGN_BETA: [[f64; 3]; 3] = [[3.4, 4.8, 6.2], [2.4, 4.7, 6.6], [1.55, 4.6, 6.975]];
/// The one proportional gain (motor rpm per crank degree of phase error) for which the table
/// reproduces the Fig. 3 settling-time ratios (Section IV-A: "a well-tuned proportional
/// controller").
pub const PAPER_DESIGN_KP_RPM_PER_DEG: f64 = 25.0;

/// The plant's default nominal step (the ECU's 10 ms EVVT task), s: see
/// [`EvvtPlant::set_nominal_step_s`].
pub const NOMINAL_STEP_S: f64 = 0.01;

/// Resolution of the cam phase calculation (Section IV-C: "1 crank degree").
pub const PHASE_RESOLUTION_DEG: f64 = 1.0;

/// The LPV scheduling table of eq. (12): α and β at the 3×3 grid of engine speed and battery
/// voltage, interpolated bilinearly and clamped outside the grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvvtLpvTable {
    pub engine_speed_rpm: [f64; 3],
    pub battery_voltage_v: [f64; 3],
    /// `alpha[i][j]` at `engine_speed_rpm[i]`, `battery_voltage_v[j]`, crank-deg/(s²·rpm).
    pub alpha_deg_per_s2_rpm: [[f64; 3]; 3],
    /// `beta[i][j]`, 1/s.
    pub beta_per_s: [[f64; 3]; 3],
}

impl EvvtLpvTable {
    /// The designed table (module doc).
    pub const PAPER_DESIGN: Self = Self {
        engine_speed_rpm: ENGINE_SPEED_BREAKPOINTS_RPM,
        battery_voltage_v: BATTERY_VOLTAGE_BREAKPOINTS_V,
        alpha_deg_per_s2_rpm: PAPER_DESIGN_ALPHA,
        beta_per_s: PAPER_DESIGN_BETA,
    };

    /// One α and one β at every grid point: the LTI model the diagnosis fits as its baseline
    /// (then the `supply-voltage` and `engine-speed` scales have nothing to act on).
    pub fn uniform(alpha_deg_per_s2_rpm: f64, beta_per_s: f64) -> Self {
        Self {
            alpha_deg_per_s2_rpm: [[alpha_deg_per_s2_rpm; 3]; 3],
            beta_per_s: [[beta_per_s; 3]; 3],
            ..Self::PAPER_DESIGN
        }
    }

    /// Builds the two lookup tables, checking that α > 0 and β >= 0 everywhere (a non-positive
    /// α would turn the phaser around; a negative β would make it unstable).
    pub fn build<R: Real>(&self) -> Result<(Lut2<R, 3, 3>, Lut2<R, 3, 3>), EvvtParamError> {
        for i in 0..3 {
            for j in 0..3 {
                let a = self.alpha_deg_per_s2_rpm[i][j];
                if !(a > 0.0 && a < 1.0e3) {
                    return Err(EvvtParamError::AlphaDegPerS2Rpm {
                        speed_index: i,
                        voltage_index: j,
                    });
                }
                let b = self.beta_per_s[i][j];
                if !(0.0..1.0e4).contains(&b) {
                    return Err(EvvtParamError::BetaPerS {
                        speed_index: i,
                        voltage_index: j,
                    });
                }
            }
        }
        let alpha = Lut2::new(self.engine_speed_rpm, self.battery_voltage_v, self.alpha_deg_per_s2_rpm)
            .map_err(EvvtParamError::Breakpoints)?;
        let beta = Lut2::new(self.engine_speed_rpm, self.battery_voltage_v, self.beta_per_s)
            .map_err(EvvtParamError::Breakpoints)?;
        Ok((alpha, beta))
    }
}

impl Default for EvvtLpvTable {
    fn default() -> Self {
        Self::PAPER_DESIGN
    }
}

/// Why an [`EvvtParams`] (or a controller config built on its table) was rejected; each
/// variant names the parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EvvtParamError {
    /// The breakpoints of `engine_speed_rpm` (axis 0) or `battery_voltage_v` (axis 1).
    Breakpoints(LutError),
    /// `alpha_deg_per_s2_rpm[speed_index][voltage_index]` is not in (0, 1e3).
    AlphaDegPerS2Rpm { speed_index: usize, voltage_index: usize },
    /// `beta_per_s[speed_index][voltage_index]` is not in [0, 1e4).
    BetaPerS { speed_index: usize, voltage_index: usize },
    /// `phase_min_deg` / `phase_max_deg` not finite or not increasing.
    PhaseRangeDeg,
    /// `initial_phase_deg` outside the phase range.
    InitialPhaseDeg,
    /// `voltage_effect_scale` not in [0, 2].
    VoltageEffectScale,
    /// `nominal_voltage_v` not finite or not positive.
    NominalVoltageV,
    /// `engine_speed_effect_scale` not in [0, 2].
    EngineSpeedEffectScale,
    /// `nominal_engine_rpm` not finite or not positive.
    NominalEngineRpm,
    /// `advance_alpha_factor` not in (0, 4].
    AdvanceAlphaFactor,
    /// `belt_vibration_amplitude_deg` not in [0, 20].
    BeltVibrationAmplitudeDeg,
    /// `belt_vibration_order` not in [0, 16].
    BeltVibrationOrder,
    /// `belt_vibration_phase_rad` not finite.
    BeltVibrationPhaseRad,
}

/// Parameters of the phaser model, plain f64 with units in the names. The four effects of the
/// diagnosis catalogue (DATA-FORMAT.md, plant `evvt`) are fields; each has an "off" value that
/// gives the baseline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvvtParams {
    pub lpv: EvvtLpvTable,
    /// Mechanical stops (Section IV-B: "adjustable cam phase range of 0 to 40 degree").
    pub phase_min_deg: f64,
    pub phase_max_deg: f64,
    pub initial_phase_deg: f64,
    /// Effect `supply-voltage`: α and β are looked up at
    /// `V_nom + scale·(V − V_nom)`. 1 = the table's voltage dependence, 0 = off (frozen at
    /// `nominal_voltage_v`).
    pub voltage_effect_scale: f64,
    pub nominal_voltage_v: f64,
    /// Effect `engine-speed`: α and β are looked up at `N_nom + scale·(N − N_nom)`.
    /// 1 = the table's speed dependence, 0 = off (frozen at `nominal_engine_rpm`).
    pub engine_speed_effect_scale: f64,
    pub nominal_engine_rpm: f64,
    /// Effect `direction`: α is multiplied by this factor while the command drives the phase
    /// towards advance (u > 0), Section IV-C: "advancing responses are slightly slower than the
    /// retarding responses" (extra motor torque to accelerate). 1 = off (symmetric), < 1 slower
    /// advance.
    pub advance_alpha_factor: f64,
    /// Effect `belt-vibration`: a phase disturbance `A·sin(2π·order·revolutions + φ0)` added to
    /// the cam phase, locked to crank angle, so its frequency follows engine speed (Section
    /// IV-B, the spike in Fig. 8 whose frequency "increases as the engine speed goes up").
    /// 0 = off.
    pub belt_vibration_amplitude_deg: f64,
    /// Disturbance cycles per engine revolution (0.5 = once per camshaft revolution, the
    /// default: the text puts Fig. 8's spike "near 4.5 rad/sec" at 800 rpm, which with the
    /// extraction's lost '2' reads 42.5 rad/s, close to the camshaft's 41.9 rad/s).
    pub belt_vibration_order: f64,
    pub belt_vibration_phase_rad: f64,
}

impl Default for EvvtParams {
    /// The designed table, the 0..40 degree range, all effects of the catalogue at the values
    /// the table implies: voltage and speed dependence on, direction symmetric, no belt
    /// vibration (its order preset to 0.5 so switching it on needs only an amplitude).
    fn default() -> Self {
        Self {
            lpv: EvvtLpvTable::PAPER_DESIGN,
            phase_min_deg: 0.0,
            phase_max_deg: 40.0,
            initial_phase_deg: 0.0,
            voltage_effect_scale: 1.0,
            nominal_voltage_v: 14.0,
            engine_speed_effect_scale: 1.0,
            nominal_engine_rpm: 1100.0,
            advance_alpha_factor: 1.0,
            belt_vibration_amplitude_deg: 0.0,
            belt_vibration_order: 0.5,
            belt_vibration_phase_rad: 0.0,
        }
    }
}

impl EvvtParams {
    /// The baseline for the diagnosis: every catalogue effect off (α, β frozen at the nominal
    /// voltage and engine speed, symmetric, no belt vibration). With both scales 0 only the
    /// table entry at the nominal point counts (1100 rpm, 14 V: `[1][2]`);
    /// [`EvvtLpvTable::uniform`] sets the same value everywhere.
    pub fn baseline() -> Self {
        Self {
            voltage_effect_scale: 0.0,
            engine_speed_effect_scale: 0.0,
            ..Self::default()
        }
    }

    pub fn validate(&self) -> Result<(), EvvtParamError> {
        let in_range = |x: f64, lo: f64, hi: f64| x >= lo && x <= hi;
        if !(self.phase_min_deg.is_finite()
            && self.phase_max_deg.is_finite()
            && self.phase_max_deg > self.phase_min_deg)
        {
            return Err(EvvtParamError::PhaseRangeDeg);
        }
        if !in_range(self.initial_phase_deg, self.phase_min_deg, self.phase_max_deg) {
            return Err(EvvtParamError::InitialPhaseDeg);
        }
        if !in_range(self.voltage_effect_scale, 0.0, 2.0) {
            return Err(EvvtParamError::VoltageEffectScale);
        }
        if !(self.nominal_voltage_v.is_finite() && self.nominal_voltage_v > 0.0) {
            return Err(EvvtParamError::NominalVoltageV);
        }
        if !in_range(self.engine_speed_effect_scale, 0.0, 2.0) {
            return Err(EvvtParamError::EngineSpeedEffectScale);
        }
        if !(self.nominal_engine_rpm.is_finite() && self.nominal_engine_rpm > 0.0) {
            return Err(EvvtParamError::NominalEngineRpm);
        }
        if !(self.advance_alpha_factor > 0.0 && self.advance_alpha_factor <= 4.0) {
            return Err(EvvtParamError::AdvanceAlphaFactor);
        }
        if !in_range(self.belt_vibration_amplitude_deg, 0.0, 20.0) {
            return Err(EvvtParamError::BeltVibrationAmplitudeDeg);
        }
        if !in_range(self.belt_vibration_order, 0.0, 16.0) {
            return Err(EvvtParamError::BeltVibrationOrder);
        }
        if !self.belt_vibration_phase_rad.is_finite() {
            return Err(EvvtParamError::BeltVibrationPhaseRad);
        }
        Ok(())
    }
}

/// Exact zero-order-hold discretization of `x1' = x2`, `x2' = -β x2 + α u` over one step T:
///
/// ```text
///     Ad = [[1, T φ1], [0, e^{-βT}]],   Bd = α [T² φ2, T φ1],
///     φ1 = (1 − e^{-x})/x,   φ2 = (x − 1 + e^{-x})/x²,   x = βT
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Zoh<R: Real> {
    /// `Ad[0][1]` = T φ1, s.
    pub ad12_s: R,
    /// `Ad[1][1]` = e^{-βT}.
    pub ad22: R,
    /// `Bd[0]` = α T² φ2, crank-deg per rpm.
    pub bd1_deg_per_rpm: R,
    /// `Ad[0][1]` · 2^6 (s): the plant's phase update multiplies by it and scales back by an
    /// exact power of two, so fixed point keeps its digits (T φ1 = 0.01 s is 655 LSB in Q16.16).
    pub ad12_x64_s: R,
    /// `Bd[0]` · 2^10, computed from factors of order 0.1 for the same reason (α T² φ2 is about
    /// 3e-5, two LSB in Q16.16).
    pub bd1_x1024_deg_per_rpm: R,
    /// `Bd[1]` · 2^6 (α T = 0.006 is 393 LSB in Q16.16: a 0.13 % gain error unscaled).
    pub bd2_x64_deg_per_s_rpm: R,
    /// `Bd[1]` = α T φ1, crank-deg/s per rpm.
    pub bd2_deg_per_s_rpm: R,
}

/// Computes [`Zoh`] for `alpha` (crank-deg/(s²·rpm)), `beta` (1/s) and `t_s` (s). For
/// βT < 2 φ1, φ2 come from their power series (Horner form, 25 terms, truncation < 1e-16):
/// no division by β, so β → 0 gives the double integrator (φ1 = 1, φ2 = 1/2) smoothly, and no
/// cancellation in `x − 1 + e^{-x}` (which in f32 would lose most digits at βT = 0.07).
/// Negative β or T are treated as 0 (the plant is never unstable).
pub fn zoh<R: Real>(alpha: R, beta: R, t_s: R) -> Zoh<R> {
    zoh_scaled(alpha, beta, t_s, t_s.mul_pow2(6))
}

/// [`zoh`] with the step also given as `t_x64_s` = 64·T, which the caller may know more
/// precisely than T itself (10 ms is 655.36 LSB in Q16.16: T alone is 0.06 % short, and every
/// coefficient with it).
fn zoh_scaled<R: Real>(alpha: R, beta: R, t_s: R, t_x64_s: R) -> Zoh<R> {
    let t = t_s.max(R::ZERO);
    let (step, phi1, phi2) = zoh_step_phis(alpha, beta, t_x64_s);
    Zoh {
        ad12_s: t * phi1,
        ad12_x64_s: step.ad12_x64_s,
        bd1_x1024_deg_per_rpm: step.bd1_x1024_deg_per_rpm,
        bd2_x64_deg_per_s_rpm: step.bd2_x64_deg_per_s_rpm,
        ad22: step.ad22,
        // α·T·(T·φ2) keeps each factor well scaled for Q32.32.
        bd1_deg_per_rpm: alpha * t * (t * phi2),
        bd2_deg_per_s_rpm: alpha * t * phi1,
    }
}

/// The scaled coefficients of [`Zoh`] the plant's step uses: computed every step where the
/// engine speed or the voltage moves, so without the unscaled ones it never reads.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ZohStep<R: Real> {
    ad12_x64_s: R,
    ad22: R,
    bd1_x1024_deg_per_rpm: R,
    bd2_x64_deg_per_s_rpm: R,
}

/// φ1, φ2 and e^{-x} of [`Zoh`] at x = βT >= 0.
#[inline(always)]
fn zoh_phis<R: Real>(x: R) -> (R, R, R) {
    // Above βT = 2 the closed form is accurate even with f32's approximate exp (e^{-x} < 0.14
    // enters φ2 only through 1 − φ1 > 0.57).
    if x < R::from_f64(2.0) {
        // g = 2 Σ (−x)^k/(k+2)! = 1 − x/3 (1 − x/4 (1 − … x/26)), coefficients as literals
        // (converted at compile time). Below βT = 1/4 (the usual step) 13 terms already leave
        // a truncation < 1e-20. In range: |x| < 2, coefficients <= 1, every partial sum within
        // [0, 1.4].
        let nx = -x;
        let g = if !crate::real::resolves::<R>(1e-6) {
            // A type that cannot hold 1e-6 (Q16.16, LSB 1.5e-5) needs fewer terms: the first
            // left out is below one LSB, 1.1e-5 for x < 1/4 (4 terms) and 4.3e-6 for x < 2
            // (10 terms), and enters φ2 halved.
            if x < R::from_f64(0.25) {
                horner_in_range!(R, nx; 1.0, 0.3333333333333333, 0.08333333333333333, 0.016666666666666666)
            } else {
                horner_in_range!(R, nx; 1.0, 0.3333333333333333, 0.08333333333333333, 0.016666666666666666, 0.002777777777777778, 0.0003968253968253968, 4.96031746031746e-05, 5.5114638447971785e-06, 5.511463844797178e-07, 5.010421677088344e-08)
            }
        } else if x < R::from_f64(0.25) {
            horner_in_range!(R, nx; 1.0, 0.3333333333333333, 0.08333333333333333, 0.016666666666666666, 0.002777777777777778, 0.0003968253968253968, 4.96031746031746e-05, 5.5114638447971785e-06, 5.511463844797178e-07, 5.010421677088344e-08, 4.17535139757362e-09, 3.2118087673643227e-10, 2.294149119545945e-11)
        } else {
            horner_in_range!(R, nx; 1.0, 0.3333333333333333, 0.08333333333333333, 0.016666666666666666, 0.002777777777777778, 0.0003968253968253968, 4.96031746031746e-05, 5.5114638447971785e-06, 5.511463844797178e-07, 5.010421677088344e-08, 4.17535139757362e-09, 3.2118087673643227e-10, 2.294149119545945e-11, 1.5294327463639633e-12, 9.55895466477477e-14, 5.622914508691041e-15, 3.123841393717245e-16, 1.644127049324866e-17, 8.22063524662433e-19, 3.9145882126782525e-20, 1.779358278490115e-21, 7.736340341261367e-23, 3.2234751421922368e-24, 1.2893900568768947e-25, 4.9591925264495945e-27)
        };
        // In range: x < 2, 0 < φ2 <= 1/2, 0 < φ1 <= 1.
        let phi2 = g.mul_pow2(-1);
        let phi1 = R::ONE - x.mul_floor_in_range(phi2);
        // e^{-x} = 1 − x φ1, consistent with φ1 to the last bit.
        (phi1, phi2, R::ONE - x.mul_floor_in_range(phi1))
    } else {
        let e = (-x).exp();
        let phi1 = (R::ONE - e) / x;
        let phi2 = (R::ONE - phi1) / x;
        (phi1, phi2, e)
    }
}

/// [`ZohStep`] in fixed point at a step with 64·T <= 2, from the prescaled table values α·64T
/// and β·64T ([`EvvtPlant`]'s `prescaled`): the products of [`zoh_step_phis`] with T fall
/// away. In range: α·64T <= 3·2 048 (lut.rs) times the advance factor <= 4 is at most 24 576,
/// T·32φ2 <= 1/2 and φ1 <= 1.
#[inline(always)]
fn zoh_step_prescaled<R: Real>(alpha_t64: R, beta_t64: R, t_x64_s: R) -> ZohStep<R> {
    let x = beta_t64.mul_pow2(-6).max(R::ZERO);
    let (phi1, phi2, e) = zoh_phis(x);
    let t32 = t_x64_s.mul_pow2(-1);
    ZohStep {
        ad12_x64_s: t_x64_s.mul_floor_in_range(phi1),
        // α·(32T)²φ2 = (α·64T)·(32T·φ2)/2.
        bd1_x1024_deg_per_rpm: alpha_t64.mul_floor_in_range(t32.mul_floor_in_range(phi2)).mul_pow2(-1),
        bd2_x64_deg_per_s_rpm: alpha_t64.mul_floor_in_range(phi1),
        ad22: e,
    }
}

/// [`ZohStep`] from α, β and 64·T, with φ1 and φ2.
#[inline(always)]
fn zoh_step_phis<R: Real>(alpha: R, beta: R, t_x64_s: R) -> (ZohStep<R>, R, R) {
    let t64 = t_x64_s.max(R::ZERO);
    let t32 = t64.mul_pow2(-1);
    // Fixed point, 64·T <= 2 (T <= 31 ms; the ECU's 10 ms step): the products with α and β
    // are in range. The tables hold α < 10^3 and β < 10^4 ([`EvvtLpvTable::build`]), at most
    // 2 048 in fixed point (lut.rs), and an interpolated value is within 3× an entry: β·64T
    // <= 12 288, α (times the advance factor <= 4) <= 12 000, α·64T <= 24 000, α·32T·32Tφ2
    // <= 6 000. Longer steps keep the saturating products.
    let in_range = !R::IS_FLOAT && t64 <= R::from_f64(2.0);
    let mul = |a: R, b: R| if in_range { a.mul_in_range(b) } else { a * b };
    let x = mul(beta, t64).mul_pow2(-6).max(R::ZERO);
    let (phi1, phi2, e) = zoh_phis(x);
    // φ1 and φ2 lie in [0, 1]: their products are no larger than the other factor.
    let step = ZohStep {
        ad12_x64_s: t64.mul_in_range(phi1),
        bd1_x1024_deg_per_rpm: mul(mul(alpha, t32), t32.mul_in_range(phi2)),
        bd2_x64_deg_per_s_rpm: mul(alpha, t64).mul_in_range(phi1),
        ad22: e,
    };
    (step, phi1, phi2)
}

/// The fixed-point tables α·64T and β·64T for the nominal step `dt_s` (see
/// [`EvvtPlant`]'s `prescaled`); `None` for the floats and where they do not apply.
fn prescaled_tables<R: Real>(lpv: &EvvtLpvTable, dt_s: f64) -> Option<(Lut2<R, 3, 3>, Lut2<R, 3, 3>)> {
    if R::IS_FLOAT || !(dt_s > 0.0 && 64.0 * dt_s <= 2.0) {
        return None;
    }
    let t64 = 64.0 * dt_s;
    let scaled = EvvtLpvTable {
        alpha_deg_per_s2_rpm: lpv.alpha_deg_per_s2_rpm.map(|row| row.map(|a| a * t64)),
        beta_per_s: lpv.beta_per_s.map(|row| row.map(|b| b * t64)),
        ..*lpv
    };
    let alpha = Lut2::new(
        scaled.engine_speed_rpm,
        scaled.battery_voltage_v,
        scaled.alpha_deg_per_s2_rpm,
    )
    .ok()?;
    let beta = Lut2::new(scaled.engine_speed_rpm, scaled.battery_voltage_v, scaled.beta_per_s).ok()?;
    Some((alpha, beta))
}

/// The table input an effect scale makes of `x`: `nominal + scale·(x − nominal)`. With the
/// effect off (scale exactly 1) fixed point takes `x` itself, the same value (no voltage or
/// speed makes the difference saturate) without two products; the floats keep the formula,
/// whose rounding their results carry.
#[inline(always)]
fn effect_scaled<R: Real>(x: R, nominal: R, scale: R) -> R {
    if !R::IS_FLOAT && scale == R::ONE {
        x
    } else {
        nominal + scale * (x - nominal)
    }
}

/// Rounds the phase to the resolution of the cam phase calculation (round half up), the
/// measurement the controller sees (Section IV-C: 1 crank degree). A non-positive resolution
/// returns the phase unchanged.
pub fn quantize_phase_deg<R: Real>(phase_deg: R, resolution_deg: R) -> R {
    if resolution_deg <= R::ZERO {
        return phase_deg;
    }
    // The phase is within a few hundred degrees, so the count fits f64 exactly.
    let counts = libm::floor((phase_deg / resolution_deg).to_f64() + 0.5);
    R::from_f64(counts) * resolution_deg
}

/// Planetary gear kinematics of eq. (11): `Φ = (n_s + n_r)/n_s ∫ (Ω_c − Ω_r) dt` (cam
/// degrees), the ring gear at half crank speed (Section III). Teeth counts are not given in the
/// paper; the default (sun 24, ring 60) is an assumption.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanetaryGear {
    pub sun_teeth: f64,
    pub ring_teeth: f64,
}

impl Default for PlanetaryGear {
    fn default() -> Self {
        Self {
            sun_teeth: 24.0,
            ring_teeth: 60.0,
        }
    }
}

impl PlanetaryGear {
    /// (n_s + n_r)/n_s; teeth counts below 1 are taken as 1 (avoids a division by zero).
    pub fn ratio(&self) -> f64 {
        let s = self.sun_teeth.max(1.0);
        (s + self.ring_teeth.max(1.0)) / s
    }

    /// Crank-degrees per second of cam phase per rpm of carrier-minus-ring speed:
    /// ratio · 6 deg/s per rpm · 2 crank degrees per cam degree.
    pub fn phase_rate_gain_deg_per_s_rpm(&self) -> f64 {
        12.0 * self.ratio()
    }

    /// The ring gear runs at half crank speed (Section III).
    pub fn ring_speed_rpm<R: Real>(engine_rpm: R) -> R {
        engine_rpm / R::from_f64(2.0)
    }

    /// dΦ/dt of eq. (11) in crank degrees per second.
    pub fn phase_rate_deg_per_s<R: Real>(&self, carrier_rpm: R, ring_rpm: R) -> R {
        R::from_f64(self.phase_rate_gain_deg_per_s_rpm()) * (carrier_rpm - ring_rpm)
    }

    /// Inverse of eq. (11) for the firmware: the motor (carrier) speed that moves the phase at
    /// `phase_rate_deg_per_s`: ring speed (holds the phase) plus the correction.
    pub fn motor_speed_for_phase_rate_rpm<R: Real>(&self, phase_rate_deg_per_s: R, engine_rpm: R) -> R {
        Self::ring_speed_rpm(engine_rpm) + phase_rate_deg_per_s / R::from_f64(self.phase_rate_gain_deg_per_s_rpm())
    }
}

/// The phaser plant: eq. (12) with the LPV table, exact ZOH stepping, mechanical stops and the
/// catalogue effects.
#[derive(Clone, Debug)]
pub struct EvvtPlant<R: Real> {
    alpha: Lut2<R, 3, 3>,
    beta: Lut2<R, 3, 3>,
    phase_min_deg: R,
    phase_max_deg: R,
    voltage_effect_scale: R,
    nominal_voltage_v: R,
    engine_speed_effect_scale: R,
    nominal_engine_rpm: R,
    advance_alpha_factor: R,
    belt_amplitude_deg: R,
    belt_order: R,
    belt_phase_rad: R,
    /// x1: cam phase without the belt disturbance, crank deg.
    phase_deg: R,
    /// x2: phase rate, crank deg/s.
    rate_deg_per_s: R,
    /// Belt disturbance cycle position in [0, 1).
    belt_cycle: R,
    /// ZOH coefficients and the (α, β, T) they were computed for.
    zoh: ZohStep<R>,
    zoh_key: (R, R, R),
    /// The nominal step in `R` and 64 times it converted from f64 (see [`zoh_scaled`]).
    nominal_dt_s: R,
    nominal_dt_x64_s: R,
    /// Fixed point with 64·T <= 2 at the nominal step: the tables α·64T and β·64T (the
    /// scaling is linear, so they interpolate to 64T times the interpolated α and β), which
    /// spare the zero-order hold three products ([`zoh_step_prescaled`]). `None` for the
    /// floats, for longer steps and for tables whose scaled values leave lut.rs's bound.
    prescaled: Option<(Lut2<R, 3, 3>, Lut2<R, 3, 3>)>,
    /// The table, kept to prescale it for a new nominal step.
    lpv: EvvtLpvTable,
}

impl<R: Real> EvvtPlant<R> {
    pub fn new(p: &EvvtParams) -> Result<Self, EvvtParamError> {
        p.validate()?;
        let (alpha, beta) = p.lpv.build::<R>()?;
        let f = R::from_f64;
        Ok(Self {
            alpha,
            beta,
            phase_min_deg: f(p.phase_min_deg),
            phase_max_deg: f(p.phase_max_deg),
            voltage_effect_scale: f(p.voltage_effect_scale),
            nominal_voltage_v: f(p.nominal_voltage_v),
            engine_speed_effect_scale: f(p.engine_speed_effect_scale),
            nominal_engine_rpm: f(p.nominal_engine_rpm),
            advance_alpha_factor: f(p.advance_alpha_factor),
            belt_amplitude_deg: f(p.belt_vibration_amplitude_deg),
            belt_order: f(p.belt_vibration_order),
            belt_phase_rad: f(p.belt_vibration_phase_rad),
            phase_deg: f(p.initial_phase_deg),
            rate_deg_per_s: R::ZERO,
            belt_cycle: R::ZERO,
            zoh: zoh_step_phis(R::ZERO, R::ZERO, R::ZERO).0,
            zoh_key: (R::ZERO, R::ZERO, R::ZERO),
            nominal_dt_s: f(NOMINAL_STEP_S),
            nominal_dt_x64_s: f(64.0 * NOMINAL_STEP_S),
            prescaled: prescaled_tables(&p.lpv, NOMINAL_STEP_S),
            lpv: p.lpv,
        })
    }

    /// Sets the step the plant is usually advanced by (default [`NOMINAL_STEP_S`]): a step of
    /// exactly `R::from_f64(dt_s)` then uses coefficients computed from `dt_s` itself, which in
    /// fixed point is more precise than the converted step (other steps work as well).
    pub fn set_nominal_step_s(&mut self, dt_s: f64) {
        self.nominal_dt_s = R::from_f64(dt_s);
        self.nominal_dt_x64_s = R::from_f64(64.0 * dt_s);
        self.prescaled = prescaled_tables(&self.lpv, dt_s);
        self.zoh_key = (R::ZERO, R::ZERO, R::ZERO);
        self.zoh = zoh_step_phis(R::ZERO, R::ZERO, R::ZERO).0;
    }

    /// α (crank-deg/(s²·rpm)) and β (1/s) of eq. (12) at engine speed `engine_rpm` and battery
    /// voltage `u_batt_v`, with the `supply-voltage` and `engine-speed` effect scales applied.
    pub fn alpha_beta(&self, engine_rpm: R, u_batt_v: R) -> (R, R) {
        Self::look_up(&self.alpha, &self.beta, self.table_input(engine_rpm, u_batt_v))
    }

    /// The (speed, voltage) the tables are read at: the effect scales applied.
    #[inline(always)]
    fn table_input(&self, engine_rpm: R, u_batt_v: R) -> (R, R) {
        (
            effect_scaled(engine_rpm, self.nominal_engine_rpm, self.engine_speed_effect_scale),
            effect_scaled(u_batt_v, self.nominal_voltage_v, self.voltage_effect_scale),
        )
    }

    /// Both tables at `(n, v)`: they are on the same grid, so one look-up.
    #[inline(always)]
    fn look_up(a: &Lut2<R, 3, 3>, b: &Lut2<R, 3, 3>, (n, v): (R, R)) -> (R, R) {
        let at = a.locate(n, v);
        (a.eval_at(at), b.eval_at(at))
    }

    /// Advances the plant by `dt_s` with the motor speed command `motor_cmd_rpm` (motor speed
    /// minus ring-gear speed) held constant, and returns the cam phase (crank deg, including
    /// the belt disturbance, not quantized).
    pub fn step(&mut self, motor_cmd_rpm: R, engine_rpm: R, u_batt_v: R, dt_s: R) -> R {
        let dt = dt_s.max(R::ZERO);
        let input = self.table_input(engine_rpm, u_batt_v);
        // Fixed point at the nominal step: α·64T and β·64T from the prescaled tables (the key
        // below tells them apart by the step).
        let prescaled = match &self.prescaled {
            Some(tables) if !R::IS_FLOAT && dt == self.nominal_dt_s => Some(tables),
            _ => None,
        };
        let (table_a, table_b) = match prescaled {
            Some((a, b)) => (a, b),
            None => (&self.alpha, &self.beta),
        };
        let (mut alpha, beta) = Self::look_up(table_a, table_b, input);
        // A factor of exactly 1 (the effect off) changes no bit: fixed point skips its product
        // (the floats' one instruction is cheaper than the test).
        if motor_cmd_rpm > R::ZERO && (R::IS_FLOAT || self.advance_alpha_factor != R::ONE) {
            alpha *= self.advance_alpha_factor;
        }
        let key = (alpha, beta, dt);
        if key != self.zoh_key {
            self.zoh = if prescaled.is_some() {
                zoh_step_prescaled(alpha, beta, self.nominal_dt_x64_s)
            } else {
                let dt_x64 = if dt == self.nominal_dt_s {
                    self.nominal_dt_x64_s
                } else {
                    dt.mul_pow2(6)
                };
                zoh_step_phis(alpha, beta, dt_x64).0
            };
            self.zoh_key = key;
        }
        let z = self.zoh;
        // Products of the scaled coefficients, scaled back by exact powers of two. Fixed point,
        // T <= 1/64 s (the ECU's 10 ms): 64Tφ1 <= 1, so its product is in range.
        let ad12_rate = if !R::IS_FLOAT && dt <= R::from_f64(1.0 / 64.0) {
            z.ad12_x64_s.mul_in_range(self.rate_deg_per_s)
        } else {
            z.ad12_x64_s * self.rate_deg_per_s
        };
        let x1 = self.phase_deg + ad12_rate.mul_pow2(-6) + (z.bd1_x1024_deg_per_rpm * motor_cmd_rpm).mul_pow2(-10);
        // e^{-βT} in [0, 1]: in range.
        let x2 = z.ad22.mul_in_range(self.rate_deg_per_s) + (z.bd2_x64_deg_per_s_rpm * motor_cmd_rpm).mul_pow2(-6);
        self.phase_deg = x1;
        self.rate_deg_per_s = x2;
        // Mechanical stops: the phase cannot pass them and the motion into the stop ends there.
        if self.phase_deg >= self.phase_max_deg {
            self.phase_deg = self.phase_max_deg;
            self.rate_deg_per_s = self.rate_deg_per_s.min(R::ZERO);
        } else if self.phase_deg <= self.phase_min_deg {
            self.phase_deg = self.phase_min_deg;
            self.rate_deg_per_s = self.rate_deg_per_s.max(R::ZERO);
        }
        // Without vibration the belt's cycle reaches no output: not advanced.
        if self.belt_amplitude_deg != R::ZERO {
            self.advance_belt(engine_rpm.max(R::ZERO), dt);
        }
        self.phase_deg_out()
    }

    fn advance_belt(&mut self, engine_rpm: R, dt: R) {
        // rpm/60 = revolutions per second (a multiplication: no division in the step).
        self.belt_cycle += self.belt_order * engine_rpm * R::from_f64(1.0 / 60.0) * dt;
        // Wrap to [0, 1): keeps the sine argument small (Q32 range, f32 precision). One step
        // advances at most order·N·dt/60 cycles (< 1 for any realistic dt); the bound keeps the
        // loop finite whatever the input, and an absurd step restarts the cycle.
        let mut wraps = 0;
        while self.belt_cycle >= R::ONE {
            self.belt_cycle -= R::ONE;
            wraps += 1;
            if wraps >= 16 {
                self.belt_cycle = R::ZERO;
            }
        }
    }

    /// The belt disturbance now, crank deg.
    pub fn belt_disturbance_deg(&self) -> R {
        if self.belt_amplitude_deg == R::ZERO {
            return R::ZERO;
        }
        let two_pi = R::from_f64(2.0 * core::f64::consts::PI);
        self.belt_amplitude_deg * (two_pi * self.belt_cycle + self.belt_phase_rad).sin()
    }

    fn phase_deg_out(&self) -> R {
        self.phase_deg + self.belt_disturbance_deg()
    }

    /// Cam phase including the belt disturbance, crank deg.
    pub fn phase_deg(&self) -> R {
        self.phase_deg_out()
    }

    /// The phase as the ECU measures it: quantized to [`PHASE_RESOLUTION_DEG`].
    pub fn measured_phase_deg(&self) -> R {
        quantize_phase_deg(self.phase_deg_out(), R::from_f64(PHASE_RESOLUTION_DEG))
    }

    /// Phase rate (state x2), crank deg/s.
    pub fn phase_rate_deg_per_s(&self) -> R {
        self.rate_deg_per_s
    }

    /// Sets the phase (clamped to the stops) and zeroes the rate and the belt cycle.
    pub fn reset(&mut self, phase_deg: R) {
        self.phase_deg = phase_deg.clamp(self.phase_min_deg, self.phase_max_deg);
        self.rate_deg_per_s = R::ZERO;
        self.belt_cycle = R::ZERO;
    }
}

#[cfg(test)]
mod tests;
