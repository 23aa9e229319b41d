//! The `vacuum` family (Thomasson et al. 2013: PWM solenoid valve + vacuum membrane actuator) by
//! simulation error. Vacuum logs are open loop in duty, so each model is simulated from the
//! logged inputs (`duty_pct`, `u_batt_V`, `p_amb_kPa`, `p_tank_kPa`) and compared with the
//! measured `x_pct` (and `p_act_kPa` when logged); the parameters are found by the bounded
//! trust-region solver of [`crate::lsq`]. The slow inputs are replayed denoised: ambient and
//! tank pressure as moving averages, the supply voltage as a running median
//! ([`U_BATT_MEDIAN_S`]), which keeps its steps.
//!
//! The simulation is `model_core::vacuum::VacuumValveActuator<f64>` itself (the exact eq. (4)
//! pressure step, the normalized force balance eqs. (6)-(7) with the spring from the inverse
//! position map eq. (8)/(9), Dahl friction eq. (10), end stops and the play operator of the
//! linkage), built from a [`VacuumModel`]: the flat, named parameter vector the solver moves.
//! The pressure stage runs its `advance_pressure` only. The rod is integrated at
//! [`VacuumFamily::h_max_s`] = 1 ms (`with_rod_step_s`) instead of the plant's 0.5 ms: RMS within
//! 0.08 % of stroke of the 0.5 ms run on step-rich inputs (unit test; measured 0.02..0.075 %),
//! below the position sensor's noise, and half the cost (the rod's first-order step error grows
//! to 0.24 % at 2.5 ms). Parameter sets model-core rejects (e.g. an arctan map whose open range
//! does not cover the stroke) are points the solver cannot use (infinitely costly).
//!
//! Baseline: the paper's model with the catalogue effects off: the valve sees the duty, one
//! pressure time constant, no friction, no clearance. Its map shapes are picked from the data:
//! the valve map (piecewise-linear eq. (2) or cubic eq. (5)) by fitting the pressure model from
//! the three presets' maps (LPT, HPT lines, HPC cubic) to the logged pressure and keeping the
//! lowest error; the position map (linear eq. (8) or arctan eq. (9)) by fitting both to the
//! centre of the quasi-static (pressure, position) band and keeping the arctan only if it lowers
//! the error by 20 % and the line misses by more than 1 % (hysteresis of friction or clearance
//! lies on both sides of the map; the arctan can mimic a line anyway). Mass and the two damping
//! coefficients (Sec. 3.2: extend and retract differ) are baseline parameters; U_ref = 12 V and
//! p_amb_ref = 100 kPa are fixed (collinear with the maps' slopes and offsets).
//!
//! Effects, each calibrated with all baseline parameters:
//! - `supply-voltage`: the valve sees duty·(1 + κ(U/U_ref − 1)); κ = 1 is eq. (1), κ = 0 the
//!   baseline, so the magnitude is fitted rather than assumed;
//! - `pressure-direction`: separate `tau_rise_s` and `tau_fall_s` (Fig. 5);
//! - `coulomb-friction`: Dahl friction eq. (10) with level `fc_kPa` and presliding distance
//!   `dahl_x_pct` = Fc/σ;
//! - `backlash`: a clearance `backlash_pct` between membrane and valve (play operator).
//!
//! No pair nests: friction acts between pressure and membrane (the membrane stalls until the
//! pressure has changed by 2·Fc, so the hysteresis width in x follows the map's slope), the
//! clearance between membrane and valve (constant width in x; the membrane travels half the
//! clearance beyond the valve's stops, so the valve still reaches 0 and 100 %, and its own
//! dynamics continue through the reversal).
//! Neither can reproduce the other exactly, and the simulation error decides between them.
//!
//! Calibration and weighting: with `p_act_kPa` logged, the model is a cascade (the pressure of
//! eq. (4) does not depend on the rod), so it is fitted in two stages, each on its own output:
//! the pressure parameters (valve map, time constants, κ) on the pressure error in kPa, then the
//! rod parameters (position map, mass, damping, friction, clearance) on the position error in %
//! with the pressure model held. This block weighting keeps a rod that the baseline cannot
//! describe (friction, clearance) from bending the valve map, and a pressure model error from
//! being absorbed by the rod. The mechanical effects leave the pressure stage unchanged (it is the
//! baseline's); the pressure effects refit it and start their rod stage from the baseline's rod;
//! the mechanical effects start theirs from the band-centre map (the baseline's rod is bent by
//! the hysteresis it could not describe). Without `p_act_kPa`, every parameter is fitted at once
//! on the position error, from each preset's parameters, the best kept.
//! Ambient and tank pressure are smoothed before use (see [`Inputs`]).
//! Long logs: at most [`VacuumFamily::max_fit_samples`] estimation samples enter the solver, as
//! four evenly spread windows each started at its settled inputs with the first 2 s not scored.

use std::borrow::Cow;

use std::ops::Range;
use std::sync::Mutex;

use model_core::vacuum::{VacuumParams, VacuumStaticModel};

use super::catalogue::{Effect, VacuumEffect};
use super::{Family, Fit, Probe};
use crate::log::{Log, Plant};
use crate::lsq::{solve, LsqOptions};

mod model;
mod start;
use model::bounds;
pub use model::{RodMap, VacuumModel, ValveMap};
use start::Prepared;

/// The logged inputs of a vacuum log. Ambient and tank pressure are slow inputs: they are
/// smoothed by centred moving averages (1 s and 0.3 s) so that their sensor noise does not drive
/// the simulated membrane (0.1 kPa of ambient noise is 0.5 % of position on a 5 %/kPa map).
pub struct Inputs<'a> {
    pub duty: &'a [f64],
    pub u_batt: Vec<f64>,
    pub p_amb: Vec<f64>,
    pub p_tank: Vec<f64>,
    pub dt_s: f64,
}

/// Centred moving average over `seconds` (shorter at the ends).
pub fn moving_average(y: &[f64], seconds: f64, dt_s: f64) -> Vec<f64> {
    let half = (0.5 * seconds / dt_s).round() as usize;
    // The window's ends only move forward: the prefix sums at both ends are accumulated as
    // they go (the same additions, in the same order, as a prefix array, which would be a
    // second series of the log's length).
    let (mut at_a, mut at_b) = ((0usize, 0.0f64), (0usize, 0.0f64));
    let prefix_to = |(i, sum): &mut (usize, f64), j: usize| {
        while *i < j {
            *sum += y[*i];
            *i += 1;
        }
        *sum
    };
    (0..y.len())
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(y.len()));
            let (pa, pb) = (prefix_to(&mut at_a, a), prefix_to(&mut at_b, b));
            (pb - pa) / (b - a) as f64
        })
        .collect()
}

/// Window of the running median of the logged supply voltage, s. The valve acts on the supply
/// itself; its logged value adds sensor noise and quantization (0.02 V, 10 mV on the project's
/// benches). Replayed sample by sample, that noise dithers the simulated duty, and a rod with
/// friction creeps where the real one stood: a friction fit then sharpened Dahl's presliding
/// distance to its bound against the dither and a clearance was named on top (3 of 25
/// supply-voltage+coulomb-friction units, 13 of 25 left `unexplained`). A median keeps the
/// level of a plateau exactly and its steps where they are (a sag longer than half the
/// window passes unchanged, Fig. 16's last seconds); a mean would round a step's corners.
pub const U_BATT_MEDIAN_S: f64 = 0.09;

/// Centred running median over `seconds` (shorter at the ends).
pub fn moving_median(y: &[f64], seconds: f64, dt_s: f64) -> Vec<f64> {
    let half = (0.5 * seconds / dt_s).round() as usize;
    let mut window = Vec::with_capacity(2 * half + 1);
    (0..y.len())
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(y.len()));
            window.clear();
            window.extend_from_slice(&y[a..b]);
            window.sort_by(|p, q| p.total_cmp(q));
            let n = window.len();
            if n % 2 == 1 {
                window[n / 2]
            } else {
                0.5 * (window[n / 2 - 1] + window[n / 2])
            }
        })
        .collect()
}

impl<'a> Inputs<'a> {
    pub fn from_log(log: &'a Log) -> Result<Self, String> {
        let c = |n: &str| log.col(n).ok_or_else(|| format!("{}: no `{n}` column", log.file));
        Ok(Self {
            duty: c("duty_pct")?,
            u_batt: moving_median(c("u_batt_V")?, U_BATT_MEDIAN_S, log.dt_s),
            p_amb: moving_average(c("p_amb_kPa")?, 1.0, log.dt_s),
            p_tank: moving_average(c("p_tank_kPa")?, 0.3, log.dt_s),
            dt_s: log.dt_s,
        })
    }
    pub fn len(&self) -> usize {
        self.duty.len()
    }
    pub fn is_empty(&self) -> bool {
        self.duty.is_empty()
    }
}

/// A stretch of the estimation log simulated from its settled start; residuals count from
/// `score_from`.
#[derive(Clone, Debug)]
struct Window {
    range: Range<usize>,
    score_from: usize,
}

/// Estimation data as the solver sees it.
struct EstData<'a> {
    io: Inputs<'a>,
    x: &'a [f64],
    p: Option<&'a [f64]>,
    windows: Vec<Window>,
}

/// Which residuals a fit stage uses.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Residuals {
    Pressure,
    Position,
}

/// A calibrated model, its fitted parameter names, their 95 % half-widths, the iterations and
/// the last (position) stage's solver run.
type Calibrated = (
    VacuumModel,
    Vec<&'static str>,
    Vec<Option<f64>>,
    usize,
    crate::lsq::LsqResult,
);

/// Family settings.
#[derive(Debug)]
pub struct VacuumFamily {
    /// Largest rod integration step of the simulation.
    pub h_max_s: f64,
    /// Estimation samples used by the solver at most (long logs are windowed).
    pub max_fit_samples: usize,
    /// Solver settings for every stage.
    pub lsq: LsqOptions,
    /// The last prepared start, keyed by its estimation data: every fit starts from it.
    cache: Mutex<Option<(u64, Prepared)>>,
    /// The last baseline, same key: the pressure effects start their rod stage from it.
    baseline_cache: Mutex<Option<(u64, VacuumModel)>>,
}

impl Default for VacuumFamily {
    fn default() -> Self {
        Self {
            h_max_s: 0.001,
            max_fit_samples: 16_000,
            lsq: LsqOptions {
                max_iterations: 20,
                cost_tolerance: 1e-5,
                step_tolerance: 1e-7,
                ..LsqOptions::default()
            },
            cache: Mutex::new(None),
            baseline_cache: Mutex::new(None),
        }
    }
}

/// A fingerprint of the estimation data (file, length and every sample of the columns used).
fn fingerprint(log: &Log) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    log.file.hash(&mut h);
    log.len().hash(&mut h);
    for name in ["duty_pct", "u_batt_V", "p_amb_kPa", "p_tank_kPa", "x_pct", "p_act_kPa"] {
        if let Some(c) = log.col(name) {
            for v in c {
                v.to_bits().hash(&mut h);
            }
        }
    }
    h.finish()
}

impl VacuumFamily {
    /// The travel-stop probe: the model `effects` from `parent`'s values with the position
    /// limited below and above (a stop inside the stroke), refitted in both stages (an effect
    /// new beside the probe, such as the supply voltage's, has its parameters in the pressure
    /// stage), the stops with the rod's parameters on the position error. The stops start
    /// where the estimation log's position ends, or at `parent`'s where it has them (a
    /// selection beside the probe).
    fn fit_travel_stop(&self, effects: &[&str], parent: &Fit, est: &Log, val: &Log) -> Result<Fit, String> {
        let data = self.est_data(est)?;
        let prepared = self.prepared(est, &data)?.model;
        let mut start = model_of(&prepared, effects, parent)?;
        let (low, high) = data.x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
        let clamp_to = |v: f64, name: &str| v.max(bounds(name).0).min(bounds(name).1);
        let beside = start.x_stop_low_pct.is_finite() || start.x_stop_high_pct.is_finite();
        if !start.x_stop_low_pct.is_finite() {
            start.x_stop_low_pct = clamp_to(low, "x_stop_low_pct");
        }
        if !start.x_stop_high_pct.is_finite() {
            start.x_stop_high_pct = clamp_to(high, "x_stop_high_pct");
        }
        let mut names = start.parameter_names(effects)?;
        names.extend(["x_stop_low_pct", "x_stop_high_pct"]);
        let mut c = self.calibrate_from(&data, start, &names, true)?;
        if beside && !effects.is_empty() {
            // A selection beside the probe: also the effects fitted from every start of the
            // family's own fit, the stops held at the parent's, then all refitted together;
            // the lower estimation cost is kept. Friction's multimodal cost needs that grid:
            // from the one start a stop unit's friction stopped at twice the floor and a
            // clearance took its place (coulomb-friction + travel-stop, seeds 32676, 56433).
            let from_grid = self.calibrate(est, effects, Some(parent))?.0;
            let other = self.calibrate_from(&data, from_grid, &names, true)?;
            if other.4.cost < c.4.cost {
                c = other;
            }
        }
        self.record(&format!("probe: {}", PROBES[1].name), c, Some(parent), val)
    }

    fn est_data<'a>(&self, log: &'a Log) -> Result<EstData<'a>, String> {
        let io = Inputs::from_log(log)?;
        let x = log
            .col("x_pct")
            .ok_or_else(|| format!("{}: no `x_pct` column", log.file))?;
        let n = io.len();
        let burn = |seconds: f64| ((seconds / log.dt_s).round() as usize).min(n / 4);
        let windows = if n <= self.max_fit_samples {
            vec![Window {
                range: 0..n,
                score_from: burn(0.5),
            }]
        } else {
            // Four evenly spread windows; each starts from its settled inputs, unscored for 2 s.
            let count = 4;
            let len = self.max_fit_samples / count;
            let stride = (n - len) / (count - 1);
            (0..count)
                .map(|i| Window {
                    range: i * stride..i * stride + len,
                    score_from: i * stride + burn(2.0),
                })
                .collect()
        };
        if n < 50 {
            return Err(format!("{}: {n} samples are too few to fit a dynamic model", log.file));
        }
        Ok(EstData {
            io,
            x,
            p: log.col("p_act_kPa"),
            windows,
        })
    }

    /// Fits `names` of `start` on `data` with the given residuals.
    fn fit_stage(
        &self,
        start: &VacuumModel,
        names: &[&'static str],
        data: &EstData,
        which: Residuals,
        opts: &LsqOptions,
    ) -> Result<(VacuumModel, crate::lsq::LsqResult), String> {
        let use_p = data.p.is_some() && which == Residuals::Pressure;
        let use_x = which == Residuals::Position;
        let per_window: usize = data.windows.iter().map(|w| w.range.len()).sum();
        let n_res = per_window * (use_x as usize + use_p as usize);
        let x0: Vec<f64> = names.iter().map(|n| start.get(n)).collect();
        let lo: Vec<f64> = names.iter().map(|n| bounds(n).0).collect();
        let hi: Vec<f64> = names.iter().map(|n| bounds(n).1).collect();
        let max_len = data.windows.iter().map(|w| w.range.len()).max().unwrap_or(0);
        let residual = |theta: &[f64], out: &mut [f64]| -> Result<(), String> {
            let mut m = *start;
            for (n, v) in names.iter().zip(theta) {
                m.set(n, *v)?;
            }
            let mut xs = vec![0.0; max_len];
            let mut ps = vec![0.0; max_len];
            let mut o = 0;
            for w in &data.windows {
                let len = w.range.len();
                m.simulate(&data.io, w.range.clone(), self.h_max_s, use_x, &mut xs, &mut ps)?;
                for (i, k) in w.range.clone().enumerate() {
                    let scored = k >= w.score_from;
                    if use_x {
                        out[o] = if scored { xs[i] - data.x[k] } else { 0.0 };
                        o += 1;
                    }
                    if let (true, Some(p)) = (use_p, data.p) {
                        out[o] = if scored { ps[i] - p[k] } else { 0.0 };
                        o += 1;
                    }
                }
                debug_assert!(len > 0);
            }
            if out.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err("the simulation diverged".into())
            }
        };
        let r = solve(residual, &x0, &lo, &hi, n_res, opts).map_err(|e| e.to_string())?;
        let mut m = *start;
        for (n, v) in names.iter().zip(&r.x) {
            m.set(n, *v)?;
        }
        Ok((m, r))
    }

    /// Calibrates the baseline plus `effects` (empty: the baseline). With a logged pressure, in
    /// two stages on the two outputs: the pressure parameters (valve map, time constants, κ) on
    /// the pressure error, which does not depend on the rod; then the rod parameters (position
    /// map, mass, damping, friction, clearance) on the position error with the pressure model
    /// held. Without a logged pressure, all parameters at once on the position error.
    ///
    /// Starts: an extension starts from `parent` (the model it extends, at its optimum) with the
    /// new effect at its starting magnitude, and, for a mechanical effect, also from the
    /// band-centre map of the prepared start (the baseline's rod is bent by the hysteresis it
    /// could not describe); the clearance, whose cost is multimodal, also from a large
    /// clearance (10 %); any model with friction also from the best two of a coarse grid of
    /// Dahl distances (with the clearance too, of the parent's dead band split between the
    /// two). If every start ends above the parent's position cost, the parent with the effect
    /// at its neutral value is refitted too: an extension never ends worse on the estimation
    /// data than the model it extends.
    /// Returns the model, the fitted parameter names, their 95 % half-widths, the iterations
    /// and the final position-stage solver run.
    fn calibrate(&self, est: &Log, effects: &[&str], parent: Option<&Fit>) -> Result<Calibrated, String> {
        let data = self.est_data(est)?;
        let Prepared {
            model: prepared,
            mut iterations,
            other_rod,
            sv_valve,
        } = self.prepared(est, &data)?;
        let is_pressure_effect = |e: &str| {
            matches!(
                VacuumEffect::from_name(e),
                Ok(VacuumEffect::SupplyVoltage | VacuumEffect::PressureDirection)
            )
        };
        // The parent model: the prepared shapes with the parent's effects on and its values
        // (and the parent's position-map shape, which may be the other one).
        let parent_model = |new_neutral: bool| -> Result<VacuumModel, String> {
            let mut m = prepared;
            let Some((last, before)) = effects.split_last() else {
                return Ok(m);
            };
            if let Some(f) = parent {
                m = model_of(&prepared, before, f)?;
            } else {
                for e in before {
                    m = m.with_effect(e)?;
                }
            }
            if new_neutral {
                m.with_effect_neutral(last)
            } else {
                m.with_effect(last)
            }
        };
        let mut starts: Vec<VacuumModel> = Vec::new();
        if effects.is_empty() {
            starts.push(prepared);
        } else {
            starts.push(parent_model(false)?);
            let last = effects[effects.len() - 1];
            // From the band-centre map: the rod parameters of the prepared start. For a
            // mechanical effect (the parent's rod is bent by the hysteresis it could not
            // describe) and for a pressure effect too (a friction model takes a slow pressure
            // fall for a bent retract damping, and from its optimum the pressure effect gains
            // nothing).
            let rod_from = |rod: &VacuumModel| -> Result<VacuumModel, String> {
                let mut m = parent_model(false)?;
                m.rod_map = rod.rod_map;
                for n in rod.parameter_names(&[])? {
                    if !is_pressure_param(n) {
                        m.set(n, rod.get(n))?;
                    }
                }
                Ok(m)
            };
            starts.push(rod_from(&prepared)?);
            if let Some(other) = &other_rod {
                starts.push(rod_from(other)?);
            }
            // With the supply-voltage effect also from the valve map fitted with it: the
            // parent's map is bent by the voltage it lacked, and from it the pressure stage
            // stopped in another minimum (an HPC's cubic at u0 56 % for the unit's 43 %).
            if let (true, Some(v)) = (effects.contains(&VacuumEffect::SupplyVoltage.name()), &sv_valve) {
                let mut m = parent_model(false)?;
                if m.valve_map == v.valve_map {
                    for n in v.parameter_names(&[VacuumEffect::SupplyVoltage.name()])? {
                        if is_pressure_param(n) || n == "voltage_gain" {
                            m.set(n, v.get(n))?;
                        }
                    }
                    starts.push(m);
                }
            }
            if last == VacuumEffect::Backlash.name() {
                let mut m = parent_model(false)?;
                m.backlash_pct = 10.0;
                starts.push(m);
            }
            // Friction: the cost is multimodal in Dahl's presliding distance, and with the
            // clearance also in how the dead band is shared. A fit sharpens the distance to
            // mimic what it lacks (a clearance's dead band; a slow pressure fall: an HPT unit's
            // friction fit ended at 0.058 % for the unit's 0.48 %), and from there (a nearly
            // discontinuous friction, a rough cost) the solver stops within a few steps, even
            // once the extension has put the pressure right. So a coarse global stage first:
            // the parent's model, and with the clearance its dead band split half and half
            // between friction (2·Fc/slope wide in position, at the map's slope mid-band) and
            // clearance, and kept with the new effect at its starting magnitude and the
            // parent's smaller by as much; each with the parent's distance and 0.03-1 %. The
            // two with the lowest position cost (the pressure stage as it starts) are fitted.
            let (cf, bl) = (VacuumEffect::CoulombFriction.name(), VacuumEffect::Backlash.name());
            if effects.contains(&cf) {
                let m = parent_model(false)?;
                let mut bases = vec![m];
                if effects.contains(&bl) {
                    let x_mid = data.x.iter().sum::<f64>() / data.x.len().max(1) as f64;
                    let parent_only = parent_model(true)?;
                    let slope = VacuumStaticModel::<f64>::new(&parent_only.to_params())
                        .map(|s| s.pressure_per_position_kpa_per_pct(x_mid))
                        .unwrap_or(0.0);
                    let band_pct = 2.0 * parent_only.fc_kpa / slope + parent_only.backlash_pct;
                    if slope > 0.0 && band_pct.is_finite() && band_pct > 0.0 {
                        let (b_lo, b_hi) = bounds("backlash_pct");
                        let (f_lo, f_hi) = bounds("fc_kPa");
                        let mut split = m;
                        split.backlash_pct = (0.5 * band_pct).clamp(b_lo, b_hi);
                        split.fc_kpa = (0.25 * band_pct * slope).clamp(f_lo, f_hi);
                        bases.push(split);
                        // The band kept, the new effect at its starting magnitude and the
                        // parent's effect smaller by what the new one takes (a friction band of
                        // ±26 % on a clearance of 3.7 % is far from half and half).
                        let mut kept = m;
                        if last == bl {
                            kept.fc_kpa = (parent_only.fc_kpa - 0.5 * slope * m.backlash_pct).clamp(f_lo, f_hi);
                        } else {
                            kept.backlash_pct = (parent_only.backlash_pct - 2.0 * m.fc_kpa / slope).clamp(b_lo, b_hi);
                        }
                        bases.push(kept);
                    }
                }
                let rod_names: Vec<&'static str> = m
                    .parameter_names(effects)?
                    .into_iter()
                    .filter(|n| !in_pressure_stage(n))
                    .collect();
                let cost_only = LsqOptions {
                    max_iterations: 0,
                    intervals: false,
                    ..self.lsq.clone()
                };
                let mut grid: Vec<(f64, VacuumModel)> = Vec::new();
                for base in &bases {
                    for dahl_x_pct in [base.dahl_x_pct, 0.03, 0.1, 0.3, 1.0] {
                        let mut g = *base;
                        g.dahl_x_pct = dahl_x_pct;
                        if g == m {
                            continue; // the parent's start, fitted anyway
                        }
                        if let Ok((_, r)) = self.fit_stage(&g, &rod_names, &data, Residuals::Position, &cost_only) {
                            grid.push((r.cost, g));
                        }
                    }
                }
                grid.sort_by(|a, b| a.0.total_cmp(&b.0));
                starts.extend(grid.into_iter().take(2).map(|(_, g)| g));
            }
        }
        let parent_cost = parent.map_or(f64::INFINITY, |f| f.est_cost);
        let mut best: Option<Calibrated> = None;
        let mut tried_neutral = false;
        loop {
            for start in std::mem::take(&mut starts) {
                let names = start.parameter_names(effects)?;
                let c = self.calibrate_from(&data, start, &names, effects.iter().any(|e| is_pressure_effect(e)))?;
                iterations += c.3;
                if best.as_ref().is_none_or(|b| c.4.cost < b.4.cost) {
                    best = Some(c);
                }
            }
            let worse = best.as_ref().is_none_or(|b| b.4.cost > parent_cost);
            if !worse || tried_neutral || effects.is_empty() {
                break;
            }
            tried_neutral = true;
            starts.push(parent_model(true)?);
        }
        let mut best = best.ok_or("no start could be fitted")?;
        best.3 = iterations;
        Ok(best)
    }

    /// One calibration from `start` (see [`Self::calibrate`]); `pressure_stage` refits the
    /// pressure parameters first.
    fn calibrate_from(
        &self,
        data: &EstData,
        start: VacuumModel,
        names: &[&'static str],
        pressure_stage: bool,
    ) -> Result<Calibrated, String> {
        let mut model = start;
        let mut iterations = 0;
        if data.p.is_none() {
            let (m, r) = self.fit_stage(&model, names, data, Residuals::Position, &self.lsq)?;
            return Ok((m, names.to_vec(), r.ci95.clone(), r.iterations, r));
        }
        let pn: Vec<&'static str> = names.iter().copied().filter(|n| in_pressure_stage(n)).collect();
        let rn: Vec<&'static str> = names.iter().copied().filter(|n| !in_pressure_stage(n)).collect();
        let ci_p = if pressure_stage {
            let (m, r) = self.fit_stage(&model, &pn, data, Residuals::Pressure, &self.lsq)?;
            iterations += r.iterations;
            model = m;
            r.ci95
        } else {
            // Confidence of the shared pressure stage at its solution (no iterations, cheap).
            let opts = LsqOptions {
                max_iterations: 0,
                ..self.lsq.clone()
            };
            self.fit_stage(&model, &pn, data, Residuals::Pressure, &opts)?.1.ci95
        };
        let (m, r) = self.fit_stage(&model, &rn, data, Residuals::Position, &self.lsq)?;
        iterations += r.iterations;
        model = m;
        let ci = names
            .iter()
            .map(|n| {
                let from = |list: &[&'static str], ci: &[Option<f64>]| {
                    list.iter()
                        .position(|m| m == n)
                        .and_then(|i| ci.get(i).copied().flatten())
                };
                from(&pn, &ci_p).or_else(|| from(&rn, &r.ci95))
            })
            .collect();
        Ok((model, names.to_vec(), ci, iterations, r))
    }

    /// The report's record of a calibrated model: its validation prediction and error, the
    /// solver's outcome, the parameters on a bound or not identifiable.
    fn record(&self, label: &str, c: Calibrated, parent: Option<&Fit>, val: &Log) -> Result<Fit, String> {
        let (model, names, ci95, iterations, last) = c;
        let (x, _) = self.predict(&model, val)?;
        let measured = val
            .col("x_pct")
            .ok_or_else(|| format!("{}: no `x_pct` column", val.file))?;
        let measured = Fit::shared_measured(parent, measured);
        let mut fit = Fit::with_shared(label, model.named(&names), ci95, measured, x, iterations);
        fit.est_cost = last.cost;
        fit.convergence = format!(
            "position stage {} ({} iterations over all stages and starts)",
            crate::lsq::convergence_text(&last),
            iterations
        );
        for (i, n) in names.iter().enumerate() {
            let (lo, hi) = bounds(n);
            let v = model.get(n);
            let tol = 1e-6 * (hi - lo);
            let neutral_zero = matches!(*n, "fc_kPa" | "backlash_pct") && v <= lo + tol;
            if (v <= lo + tol || v >= hi - tol) && !neutral_zero {
                fit.at_bound.push(n.to_string());
            }
            if fit.ci95.get(i).copied().flatten().is_none() && !fit.at_bound.iter().any(|b| b == n) && !neutral_zero {
                fit.not_identifiable.push(n.to_string());
            }
        }
        Ok(fit)
    }

    /// Simulates a log with a model; (x, p).
    pub fn predict(&self, m: &VacuumModel, log: &Log) -> Result<(Vec<f64>, Vec<f64>), String> {
        let io = Inputs::from_log(log)?;
        let n = io.len();
        let (mut x, mut p) = (vec![0.0; n], vec![0.0; n]);
        m.simulate(&io, 0..n, self.h_max_s, true, &mut x, &mut p)?;
        Ok((x, p))
    }
}

/// The parameters the pressure stage fits (they move the chamber pressure, which does not
/// depend on the rod).
fn in_pressure_stage(name: &str) -> bool {
    is_pressure_param(name) || matches!(name, "voltage_gain" | "tau_fall_s" | "duty_delay_s")
}

/// The model `parent` was fitted as (the baseline plus `effects`, at the parent's optimum),
/// from the prepared shapes: the position map's shape is the parent's (inferred from its
/// parameter names: it may be the other one).
fn model_of(prepared: &VacuumModel, effects: &[&str], parent: &Fit) -> Result<VacuumModel, String> {
    let mut m = *prepared;
    for e in effects {
        m = m.with_effect(e)?;
    }
    for (n, v) in &parent.internal {
        m.set(n, *v)?;
    }
    if parent.internal.iter().any(|(n, _)| n == "a1_pct") {
        m.rod_map = RodMap::Arctan;
    } else if parent.internal.iter().any(|(n, _)| n == "lin_k_pct_per_kPa") {
        m.rod_map = RodMap::Linear;
    }
    Ok(m)
}

/// Physics outside the catalogue the vacuum diagnosis tests for: a transport delay of the
/// duty (a driver or bus latency, a PWM stage that takes a new duty only at its next period).
/// Friction takes part of such a lag into a dead band, so the nearest catalogue effect gains
/// on it; the probe says what is missing instead. And a travel that ends inside the stroke
/// (a linkage or flap stop, a position sensor at the end of its range): the position stays
/// flat while the chamber pressure goes on, which a clearance's dead band half mimics.
pub const PROBES: [Probe; 2] = [
    Probe {
        name: "duty-delay",
        what: "a transport delay of the duty command (driver, bus or PWM-stage latency, or a long pneumatic line, between the logged duty and the actuator)",
        // A delay of one log sample or more is physics; shorter is within the sampled model's hold.
        min_samples: Some(1.0),
        only_above_floor: false,
    },
    Probe {
        name: "travel-stop",
        what: "a travel that ends inside the stroke: the measured position stops at a level the pressure would carry it past, or rests above the stroke's start (a linkage, flap or wastegate stop, a rod that does not return to rest, or a position sensor with an offset or at the end of its range)",
        min_samples: None,
        // A stop changes nothing where the model already reaches the floor.
        only_above_floor: true,
    },
];

fn is_pressure_param(name: &str) -> bool {
    matches!(
        name,
        "k1_kPa_per_pct" | "p01_kPa" | "k2_kPa_per_pct" | "p02_kPa" | "k3_kPa_per_pct3" | "u0_pct" | "tau_rise_s"
    )
}

impl Family for VacuumFamily {
    fn plant(&self) -> Plant {
        Plant::Vacuum
    }
    fn output(&self) -> &'static str {
        "x_pct"
    }
    fn formulation(&self) -> &'static str {
        "simulation: the valve + actuator model run open loop from the logged duty, supply voltage, ambient and tank pressure; pressure parameters on the p_act_kPa simulation error (when logged), rod parameters on the x_pct simulation error"
    }
    fn effects(&self) -> &'static [&'static str] {
        &["supply-voltage", "pressure-direction", "coulomb-friction", "backlash"]
    }
    /// Within the fitted 95 % intervals of neutral: a pressure effect also starts from the
    /// prepared rod ([`VacuumFamily::calibrate`]), which lowers the cost of the rest of the
    /// model whether or not the effect is there (a τfall/τrise of 0.99 ± 0.02 gained 26 % that
    /// way on a unit without it).
    fn is_off(&self, effect: &str, fit: &Fit) -> bool {
        let ci95 = |name: &str| {
            fit.params
                .iter()
                .position(|(n, _)| n == name)
                .and_then(|k| fit.ci95.get(k).copied().flatten())
        };
        crate::diagnose::catalogue::is_off_within(Plant::Vacuum, effect, &fit.internal, ci95)
    }

    /// The parent's values are read by name (`model_of`), and friction and clearance stand in
    /// for each other's dead band, so a pair's fit from the one's optimum may end in another
    /// valley than from the other's (an LPT unit, 103947: friction + clearance from friction's
    /// optimum 0.285 % on validation, from the clearance's lower on estimation).
    fn starts_from_other_nested(&self) -> bool {
        true
    }

    fn fit(&self, effects: &[&str], parent: Option<&Fit>, est: &Log, val: &Log) -> Result<Fit, String> {
        let (model, names, ci95, iterations, last) = self.calibrate(est, effects, parent)?;
        if effects.is_empty() {
            if let Ok(mut guard) = self.baseline_cache.lock() {
                *guard = Some((fingerprint(est), model));
            }
        }
        self.record(
            &Fit::label(effects),
            (model, names, ci95, iterations, last),
            parent,
            val,
        )
    }

    fn probes(&self) -> &'static [Probe] {
        &PROBES
    }

    /// The duty-delay probe fits any set of effects (its start: the parent's values by name,
    /// a new effect at its neutral value).
    fn selects_beside_probes(&self) -> bool {
        true
    }

    /// The duty-delay probe: the final model with a transport delay of the duty (linear
    /// between samples, 0-0.5 s), every parameter refitted from the final model's optimum; the
    /// delay starts at the best of a coarse grid with those parameters and is fitted with the
    /// pressure model where the chamber pressure is logged (the pressure follows the duty
    /// without the rod's friction in between).
    fn fit_probe(&self, probe: &str, effects: &[&str], parent: &Fit, est: &Log, val: &Log) -> Result<Fit, String> {
        if probe == PROBES[1].name {
            return self.fit_travel_stop(effects, parent, est, val);
        }
        if probe != PROBES[0].name {
            return Err(format!("no probe `{probe}` for the vacuum actuator"));
        }
        let data = self.est_data(est)?;
        let prepared = self.prepared(est, &data)?.model;
        let mut start = model_of(&prepared, effects, parent)?;
        let mut names = start.parameter_names(effects)?;
        let which = if data.p.is_some() {
            Residuals::Pressure
        } else {
            Residuals::Position
        };
        let names_now: Vec<&'static str> = if data.p.is_some() {
            names.iter().copied().filter(|n| in_pressure_stage(n)).collect()
        } else {
            names.clone()
        };
        let cost_only = LsqOptions {
            max_iterations: 0,
            ..self.lsq.clone()
        };
        let mut best = (f64::INFINITY, 0.0);
        for samples in [0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0] {
            let delay_s = samples * data.io.dt_s;
            if delay_s > model::DUTY_DELAY_MAX_S {
                break;
            }
            let mut m = start;
            m.duty_delay_s = delay_s;
            if let Ok((_, r)) = self.fit_stage(&m, &names_now, &data, which, &cost_only) {
                if r.cost < best.0 {
                    best = (r.cost, delay_s);
                }
            }
        }
        start.duty_delay_s = best.1;
        names.push("duty_delay_s");
        let c = self.calibrate_from(&data, start, &names, true)?;
        self.record(&format!("probe: {probe}"), c, Some(parent), val)
    }

    fn regressors<'a>(&self, val: &'a Log) -> Vec<(String, Cow<'a, [f64]>)> {
        // The log's columns borrowed, derived series owned (moved in, not cloned).
        (|| -> Vec<(String, Cow<'a, [f64]>)> {
            let Ok(io) = Inputs::from_log(val) else {
                return Vec::new();
            };
            let n = io.len();
            let mut out: Vec<(String, Cow<'a, [f64]>)> = vec![
                ("supply voltage".to_string(), Cow::Owned(io.u_batt.clone())),
                ("duty".to_string(), Cow::Borrowed(io.duty)),
                (
                    "duty x voltage".to_string(),
                    Cow::Owned(io.duty.iter().zip(&io.u_batt).map(|(d, u)| d * u).collect()),
                ),
            ];
            // Direction of motion from a smoothed difference (±1, 0 when still).
            let direction = |y: &[f64], still: f64| -> Vec<f64> {
                let w = ((0.05 / val.dt_s).round() as usize).max(1);
                (0..n)
                    .map(|k| {
                        let d = y[(k + w).min(n - 1)] - y[k.saturating_sub(w)];
                        if d > still {
                            1.0
                        } else if d < -still {
                            -1.0
                        } else {
                            0.0
                        }
                    })
                    .collect()
            };
            if let Some(p) = val.col("p_act_kPa") {
                let now = direction(p, 1.0);
                // Hysteresis remembers the last direction: friction and clearance both offset x
                // by its sign; friction by Fc times the map's slope (wide where the map is steep),
                // the clearance by a constant half-width. The slope comes from the baseline.
                let mut held = now.clone();
                for k in 1..n {
                    if held[k] == 0.0 {
                        held[k] = held[k - 1];
                    }
                }
                let baseline = self
                    .baseline_cache
                    .lock()
                    .ok()
                    .and_then(|g| g.as_ref().and_then(|(_, m)| m.actuator(self.h_max_s).ok()));
                if let Some(a) = baseline {
                    let slope: Vec<f64> = (0..n)
                        .map(|k| {
                            (a.static_position_pct(p[k] + 0.5, io.p_amb[k])
                                - a.static_position_pct(p[k] - 0.5, io.p_amb[k]))
                            .abs()
                        })
                        .collect();
                    out.push((
                        "last pressure direction x map slope (friction)".into(),
                        Cow::Owned(held.iter().zip(&slope).map(|(d, s)| d * s).collect()),
                    ));
                }
                out.push(("last pressure direction (friction, clearance)".into(), Cow::Owned(held)));
                out.push(("pressure rate sign".into(), Cow::Owned(now)));
                out.push(("actuator pressure".into(), Cow::Borrowed(p)));
            }
            if let Some(x) = val.col("x_pct") {
                out.push(("position direction".into(), Cow::Owned(direction(x, 1.0))));
            }
            // The other inputs: the vacuum supply and the ambient pressure (smoothed as
            // simulated), in their place after the duty (moved in once the slope has used them).
            out.insert(3, ("tank pressure (vacuum supply)".to_string(), Cow::Owned(io.p_tank)));
            out.insert(4, ("ambient pressure".to_string(), Cow::Owned(io.p_amb)));
            out
        })()
    }
}

#[cfg(test)]
mod tests;
