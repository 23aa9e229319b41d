//! The `evvt` family (electric cam phaser, Yang 2015) by simulation error.
//!
//! The plant is an integrator, so the logs are closed-loop and a one-step predictor would say
//! little about α and β; every model is therefore *simulated* over the whole record and its
//! phase compared with the measured one:
//!
//! - Closed loop (the log has `phase_ref_deg`, `# kp:` and its command obeys the stated law):
//!   the simulated phase is quantized like the measurement (resolution found from the logged
//!   phase), the controller `motor_cmd = sat(kp (phase_ref − quantized phase))` runs every
//!   `control_period_s`, and the plant model moves under that command. Given the plant's true
//!   parameters this reproduces the bench sample for sample.
//! - Otherwise: the logged command drives the model open-loop over windows of
//!   `open_loop_window_s`, each starting from the measured phase (the rate is carried over), so
//!   the integrator cannot drift away over the record.
//!
//! Models (eq. (12), `x1' = x2`, `x2' = −β x2 + α u`, exact zero-order hold of model-core,
//! mechanical stops at 0 and 40 deg widened to the measured range):
//! - baseline: one α and one β for the whole log (LTI);
//! - `supply-voltage`: α, β affine in battery voltage about the estimation record's mean,
//!   `α(V) = α (1 + a_V (V − V̄))`, `β(V) = β (1 + b_V (V − V̄))`;
//! - `engine-speed`: the same in engine speed (per 1000 rpm about the mean);
//! - `direction`: α × `advance_factor` while the command advances (Section IV-C);
//! - `belt-vibration`: `A sin(2π o θ + φ)` added to the phase, θ the crank revolutions
//!   integrated from `engine_rpm`; the order o comes from the peak of the baseline residual's
//!   order spectrum (the residual gridded on crank angle, FFT, refined by a direct transform),
//!   then o, A, φ, α, β are fitted together. The log does not record the crank angle at its
//!   start, so the disturbance's phase on the validation record is re-estimated there (an
//!   initial condition, like a simulation's initial state); order and amplitude come from the
//!   estimation data.
//!
//! All parameters are fitted by the one trust-region solver (`crate::lsq`). The baseline
//! starts from a coarse (α, β) grid; each extension starts from the baseline's solution with
//! its effect switched off.

use std::borrow::Cow;
use std::collections::hash_map::DefaultHasher;
use std::f64::consts::PI;
use std::hash::{Hash, Hasher};
use std::sync::Mutex;

use super::catalogue::{Effect, EvvtEffect};
use super::order_spectrum::{order_peak, project_sinusoid};
use super::{Family, Fit, Probe};
use crate::log::{Log, Plant};
use crate::lsq::{solve, LsqOptions, LsqResult};

mod model;
use model::*;

/// The catalogue effects of this family (DATA-FORMAT.md), from the typed catalogue.
pub const EFFECTS: [&str; 4] = EvvtEffect::NAMES;

/// Physics outside the catalogue the EVVT diagnosis tests for: a transport delay of the motor
/// command (driver or bus latency). A second-order model absorbs a delay of tens of ms into
/// lower α and β at a remainder close to the floor, so the remainder alone does not show it.
///
/// And a clearance between the phaser's drive and the camshaft (gear backlash: Section IV-C
/// puts the bench's 1-degree spikes down to it): after each reversal the cam stands still
/// until the drive has crossed the clearance. Under the 1-degree phase resolution a model
/// without it leaves a remainder that follows the command's direction, often within twice
/// the quantization floor.
pub const PROBES: [Probe; 2] = [
    Probe {
        name: "command-delay",
        what: "a transport delay of the motor command (driver or bus latency between the ECU's command and the phaser)",
        // A delay of one log sample (the control period) or more is physics; the quantized
        // phase (1 deg) dominates the remainder, so a 30-40 ms delay gains only 2-4 % RMSE.
        min_samples: Some(1.0),
        only_above_floor: false,
    },
    Probe {
        name: "gear-backlash",
        what: "a clearance between the phaser's drive and the camshaft (gear or belt backlash: after each reversal the cam phase stands still until the drive has crossed it)",
        min_samples: None,
        only_above_floor: false,
    },
];

/// The longest command delay the probe fits, s.
const PROBE_MAX_DELAY_S: f64 = 0.5;

/// The widest drive-to-cam clearance the backlash probe fits, crank deg (a tenth of the
/// phaser's 40-degree range).
const PROBE_MAX_BACKLASH_DEG: f64 = 4.0;

/// Settings of the family.
#[derive(Debug)]
pub struct EvvtFamily {
    /// Open-loop windows (logs without a usable controller), s.
    pub open_loop_window_s: f64,
    /// Order range searched for the belt disturbance (cycles per engine revolution). The upper
    /// end is further limited by the log's Nyquist frequency at its highest engine speed.
    pub min_order: f64,
    pub max_order: f64,
    /// The simulated controller sees the phase through the measurement's quantizer with its
    /// steps softened into linear ramps this many LSB wide (0 = exact rounding). With exact
    /// rounding the loop's chatter between two levels (a non-integer reference) is chaotic:
    /// its timing jumps with the last digit of a parameter, so the simulation error is a rough
    /// function of the parameters (about 10 % apart for parameters 0.5 % apart) and the
    /// solver and the comparison of candidates would be judging that roughness. Ramps keep
    /// where the phase hovers (at the level boundary) and make the error continuous.
    pub quantizer_ramp_lsb: f64,
    pub lsq: LsqOptions,
    /// The last baseline fit (key of the estimation log, α, β): every extension starts from
    /// it, and `regressors` uses it.
    baseline: Mutex<Option<(u64, f64, f64)>>,
}

impl Default for EvvtFamily {
    fn default() -> Self {
        Self {
            open_loop_window_s: 2.0,
            min_order: 0.25,
            max_order: 4.0,
            quantizer_ramp_lsb: 0.5,
            lsq: LsqOptions {
                max_iterations: 40,
                cost_tolerance: 1e-7,
                ..LsqOptions::default()
            },
            baseline: Mutex::new(None),
        }
    }
}

/// How the model is driven.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Drive {
    ClosedLoop { kp: f64, cmd_max: f64, hold: usize },
    OpenLoop { window: usize },
}

/// Residuals a fit scores at most (see `EvvtFamily::solve_model`).
const MAX_FIT_RESIDUALS: usize = 65_536;

/// One log, ready to simulate. The columns are the log's own (borrowed: on a 425 000-row pair
/// five copies of them were 40 B a row of the diagnosis's peak).
#[derive(Clone, Debug)]
struct Data<'a> {
    dt: f64,
    y: &'a [f64],
    cmd: &'a [f64],
    rpm: &'a [f64],
    volt: &'a [f64],
    /// Empty when the loop is not used (open-loop windows).
    reference: &'a [f64],
    drive: Drive,
    /// Phase resolution of the measurement (0: not quantized).
    lsb: f64,
    /// Width of the simulated quantizer's ramps between levels, in LSB (0: exact rounding).
    ramp: f64,
    stop_lo: f64,
    stop_hi: f64,
}

/// The resolution the phase was logged with: the smallest step between distinct values, if
/// every value is a whole multiple of it; 0 otherwise.
fn detect_resolution(y: &[f64]) -> f64 {
    let mut v: Vec<f64> = y.to_vec();
    v.sort_by(f64::total_cmp);
    v.dedup();
    let step = v.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    if !(step.is_finite() && step >= 1e-3) {
        return 0.0;
    }
    // Snap to a decimal-looking value (1, 0.5, 0.25, 0.1 ...) and verify.
    let lsb = (step * 1e6).round() / 1e6;
    if v.iter().all(|x| ((x / lsb) - (x / lsb).round()).abs() < 1e-6) {
        lsb
    } else {
        0.0
    }
}

impl<'a> Data<'a> {
    /// Crank revolutions from the start of the log to each sample, integrated from the engine
    /// speed as they are read: a held series of them was 8 B a row of a long record's peak,
    /// and a pass of the order spectrum or a belt simulation costs far more than the sum.
    fn revs(&self) -> impl Iterator<Item = f64> + Clone + '_ {
        let dt = self.dt;
        self.rpm.iter().scan(0.0, move |theta: &mut f64, &n| {
            let at = *theta;
            *theta += n.max(0.0) / 60.0 * dt;
            Some(at)
        })
    }

    fn from_log(log: &'a Log, window_s: f64, ramp_lsb: f64) -> Result<Self, String> {
        let col = |name: &str| log.col(name).ok_or_else(|| format!("{}: no `{name}` column", log.file));
        let y = col("phase_deg")?;
        let cmd = col("motor_cmd_rpm")?;
        let rpm = col("engine_rpm")?;
        let volt = col("u_batt_V")?;
        if y.len() < 10 {
            return Err(format!("{}: {} samples are too few to simulate", log.file, y.len()));
        }
        let dt = log.dt_s;
        let meta = |k: &str| log.meta_f64(k).map_err(|e| e.to_string());
        let lsb = detect_resolution(y);
        let (ymin, ymax) = y
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let mut drive = Drive::OpenLoop {
            window: ((window_s / dt).round() as usize).max(1),
        };
        let mut reference: &'a [f64] = &[];
        if let (Some(r), Some(kp)) = (log.col("phase_ref_deg"), meta("kp")?) {
            let cmd_max = meta("motor_cmd_max_rpm")?.filter(|m| *m > 0.0).unwrap_or(f64::INFINITY);
            let hold = ((meta("control_period_s")?.unwrap_or(dt) / dt).round() as usize).max(1);
            // Use the loop only if the logged command obeys the stated law (with the logged,
            // quantized phase) at the control instants.
            let mut checked = 0usize;
            let mut obeyed = 0usize;
            for k in (0..y.len()).step_by(hold) {
                let law = (kp * (r[k] - y[k])).clamp(-cmd_max, cmd_max);
                checked += 1;
                if (cmd[k] - law).abs() <= 0.5 + 1e-3 * law.abs() {
                    obeyed += 1;
                }
            }
            if kp > 0.0 && obeyed as f64 >= 0.99 * checked as f64 {
                drive = Drive::ClosedLoop { kp, cmd_max, hold };
                reference = r;
            }
        }
        Ok(Data {
            dt,
            y,
            cmd,
            rpm,
            volt,
            reference,
            drive,
            lsb,
            ramp: ramp_lsb,
            stop_lo: ymin.min(0.0),
            stop_hi: ymax.max(40.0),
        })
    }

    fn key(&self) -> u64 {
        let mut h = DefaultHasher::new();
        self.y.len().hash(&mut h);
        self.dt.to_bits().hash(&mut h);
        for v in self.y.iter().chain(self.cmd).chain(self.rpm).chain(self.volt) {
            v.to_bits().hash(&mut h);
        }
        h.finish()
    }

    fn mean(x: &[f64]) -> f64 {
        x.iter().sum::<f64>() / x.len().max(1) as f64
    }
}

const ALPHA_BOUNDS: (f64, f64) = (1e-4, 100.0);
const BETA_BOUNDS: (f64, f64) = (0.0, 500.0);

impl EvvtFamily {
    fn opts(&self) -> LsqOptions {
        self.lsq.clone()
    }

    /// The solver on the simulation error of the whole record; a record longer than
    /// [`MAX_FIT_RESIDUALS`] samples is simulated whole but scored at every `stride`-th sample
    /// (the solver's Jacobian of a 292 500-sample record with five parameters was 11.7 MB, the
    /// largest thing a long diagnosis held). The stride depends on the record's length only, so
    /// a model and the one it extends are scored on the same samples.
    fn solve_model(&self, effects: &[EvvtEffect], d: &Data, ctx: &Ctx, spec: &Spec) -> Result<LsqResult, String> {
        self.solve_built(&|x: &[f64]| model_from(effects, x, ctx), d, spec)
    }

    /// [`Self::solve_model`] for any map from the parameter vector to a model.
    fn solve_built(
        &self,
        build: &(dyn Fn(&[f64]) -> Model + Sync),
        d: &Data,
        spec: &Spec,
    ) -> Result<LsqResult, String> {
        let n = d.y.len();
        let stride = n.div_ceil(MAX_FIT_RESIDUALS).max(1);
        let solved = if stride == 1 {
            let r = |x: &[f64], out: &mut [f64]| sim_error(&build(x), d, out);
            solve(r, &spec.x0, &spec.lo, &spec.hi, n, &self.opts())
        } else {
            let r = |x: &[f64], out: &mut [f64]| {
                let mut whole = vec![0.0; n];
                sim_error(&build(x), d, &mut whole)?;
                for (o, e) in out.iter_mut().zip(whole.iter().step_by(stride)) {
                    *o = *e;
                }
                Ok(())
            };
            solve(r, &spec.x0, &spec.lo, &spec.hi, n.div_ceil(stride), &self.opts())
        };
        solved.map_err(|e| e.to_string())
    }

    /// The baseline (α, β) on the estimation data: the best point of a coarse grid, refined by
    /// the solver. Cached per estimation log.
    fn baseline(&self, d: &Data, ctx: &Ctx) -> Result<(f64, f64, LsqResult), String> {
        let mut out = vec![0.0; d.y.len()];
        let mut best = (f64::INFINITY, 0.5, 5.0);
        for i in 0..10 {
            let alpha = 0.02 * 2f64.powi(i);
            for beta in [0.5, 1.5, 4.0, 10.0, 25.0, 60.0] {
                if sim_error(&Model::lti(alpha, beta), d, &mut out).is_ok() {
                    let cost = out.iter().map(|e| e * e).sum::<f64>();
                    if cost < best.0 {
                        best = (cost, alpha, beta);
                    }
                }
            }
        }
        let spec = Spec {
            x0: vec![best.1, best.2],
            lo: vec![ALPHA_BOUNDS.0, BETA_BOUNDS.0],
            hi: vec![ALPHA_BOUNDS.1, BETA_BOUNDS.1],
        };
        let res = self.solve_model(&[], d, ctx, &spec)?;
        if let Ok(mut g) = self.baseline.lock() {
            *g = Some((d.key(), res.x[0], res.x[1]));
        }
        Ok((res.x[0], res.x[1], res))
    }

    fn cached_baseline(&self, d: &Data) -> Option<(f64, f64)> {
        let key = d.key();
        self.baseline
            .lock()
            .ok()
            .and_then(|g| g.filter(|(k, _, _)| *k == key).map(|(_, a, b)| (a, b)))
    }

    fn order_range(&self, d: &Data) -> (f64, f64) {
        let n_max = d.rpm.iter().fold(0.0f64, |m, &v| m.max(v));
        let nyquist_order = if n_max > 0.0 {
            0.49 / d.dt / (n_max / 60.0)
        } else {
            self.max_order
        };
        (self.min_order, self.max_order.min(nyquist_order))
    }

    /// The parameters `effect` adds ([`param_names`]) to a model with `before`, their start
    /// and bounds; `parent` is the model it extends (the belt disturbance's order is read off
    /// its residual).
    fn spec(&self, before: &[EvvtEffect], effect: EvvtEffect, d: &Data, parent: &Model) -> Result<Spec, String> {
        let (mut x0, mut lo, mut hi) = match effect {
            EvvtEffect::SupplyVoltage => (vec![0.0, 0.0], vec![-1.0, -1.0], vec![1.0, 1.0]),
            EvvtEffect::EngineSpeed => (vec![0.0, 0.0], vec![-3.0, -3.0], vec![3.0, 3.0]),
            EvvtEffect::Direction => (vec![1.0], vec![0.1], vec![4.0]),
            EvvtEffect::BeltVibration => {
                let mut resid = vec![0.0; d.y.len()];
                sim_error(parent, d, &mut resid)?;
                // The residual is model − measured; the disturbance is in the measurement.
                for e in resid.iter_mut() {
                    *e = -*e;
                }
                let (olo, ohi) = self.order_range(d);
                let (order, _) = order_peak(&resid, d.revs(), olo, ohi).ok_or(
                    "no order spectrum: the log is too short or its sample rate too low for orders above the minimum",
                )?;
                let (c, s) = project_sinusoid(&resid, d.revs(), order);
                // The order is refined within the peak's main lobe (± 1/total revolutions).
                let lobe = 1.0 / d.revs().last().unwrap_or(1.0).max(1.0);
                (
                    vec![order, c, s],
                    vec![order - lobe, -20.0, -20.0],
                    vec![order + lobe, 20.0, 20.0],
                )
            }
        };
        if completes_schedule(before, effect) {
            x0.extend([0.0; 2]);
            lo.extend([-3.0; 2]);
            hi.extend([3.0; 2]);
        }
        Ok(Spec { x0, lo, hi })
    }

    /// A fit's inputs: the typed effects, both records and the scheduling effects' reference
    /// point (the estimation record's mean voltage and speed).
    fn prepare<'a>(
        &self,
        effects: &[&str],
        est: &'a Log,
        val: &'a Log,
    ) -> Result<(Vec<EvvtEffect>, Data<'a>, Data<'a>, Ctx), String> {
        let effects: Vec<EvvtEffect> = effects
            .iter()
            .map(|e| EvvtEffect::from_name(e))
            .collect::<Result<_, _>>()?;
        let de = Data::from_log(est, self.open_loop_window_s, self.quantizer_ramp_lsb)?;
        let dv = Data::from_log(val, self.open_loop_window_s, self.quantizer_ramp_lsb)?;
        let ctx = Ctx {
            v_ref: Data::mean(de.volt),
            n_ref_krpm: Data::mean(de.rpm) / 1000.0,
        };
        Ok((effects, de, dv, ctx))
    }

    /// The report's names of α and β and the effects' parameters (α and β are named at the
    /// reference point of a scheduling effect).
    fn report_names(effects: &[EvvtEffect], ctx: &Ctx) -> Vec<String> {
        let mut names = vec!["alpha_deg_per_s2_rpm".to_string(), "beta_per_s".to_string()];
        let mut at = Vec::new();
        if effects.contains(&EvvtEffect::SupplyVoltage) {
            at.push(format!("{:.2}V", ctx.v_ref));
        }
        if effects.contains(&EvvtEffect::EngineSpeed) {
            at.push(format!("{:.0}rpm", ctx.n_ref_krpm * 1000.0));
        }
        if !at.is_empty() {
            for n in names.iter_mut() {
                *n = format!("{n}_at_{}", at.join("_"));
            }
        }
        names.extend(effect_param_names(effects).into_iter().map(String::from));
        names
    }

    /// Prediction on the validation record. The belt disturbance's phase is re-estimated there
    /// (module doc); everything else is as fitted.
    fn predict(&self, m: &Model, d: &Data) -> Result<Vec<f64>, String> {
        let mut out = vec![0.0; d.y.len()];
        if m.belt_on() {
            let off = Model {
                belt_cos: 0.0,
                belt_sin: 0.0,
                ..*m
            };
            simulate(&off, d, &mut out)?;
            let resid: Vec<f64> = d.y.iter().zip(&out).map(|(y, p)| y - p).collect();
            let (c, s) = project_sinusoid(&resid, d.revs(), m.belt_order);
            let amp = m.belt_cos.hypot(m.belt_sin);
            let phase = c.atan2(s);
            let on = Model {
                belt_cos: amp * phase.sin(),
                belt_sin: amp * phase.cos(),
                ..*m
            };
            simulate(&on, d, &mut out)?;
        } else {
            simulate(m, d, &mut out)?;
        }
        Ok(out)
    }
}

impl Family for EvvtFamily {
    fn plant(&self) -> Plant {
        Plant::Evvt
    }
    fn output(&self) -> &'static str {
        "phase_deg"
    }
    fn formulation(&self) -> &'static str {
        "simulation error: the known closed loop (motor_cmd = sat(kp (phase_ref - quantized simulated phase)) each control period) when phase_ref_deg and kp are logged and the logged command obeys that law; otherwise the logged command open-loop over 2 s windows re-initialised from the measured phase. Belt disturbance phase re-estimated on the validation record (crank angle origin not logged)"
    }
    fn effects(&self) -> &'static [&'static str] {
        &EFFECTS
    }

    fn fit(&self, effects: &[&str], parent: Option<&Fit>, est: &Log, val: &Log) -> Result<Fit, String> {
        let (effects, de, dv, ctx) = self.prepare(effects, est, val)?;
        let (alpha, beta, base_res) = match self.cached_baseline(&de).filter(|_| !effects.is_empty()) {
            Some((a, b)) => (a, b, None),
            None => {
                let (a, b, r) = self.baseline(&de, &ctx)?;
                (a, b, Some(r))
            }
        };
        let mut lo = vec![ALPHA_BOUNDS.0, BETA_BOUNDS.0];
        let mut hi = vec![ALPHA_BOUNDS.1, BETA_BOUNDS.1];
        let internal_names: Vec<String> = ["alpha", "beta"]
            .iter()
            .map(|s| s.to_string())
            .chain(effect_param_names(&effects).into_iter().map(String::from))
            .collect();
        let r = match effects.split_last() {
            None => base_res.ok_or("baseline fit missing")?,
            Some((last, before)) => {
                // Start from the parent's optimum (the model this one extends), the new effect
                // at its neutral start: the solver only accepts steps that lower the cost, so
                // the extension cannot end above its parent.
                let mut x0: Vec<f64> = match parent {
                    Some(f) if f.internal.len() >= 2 => f.internal.iter().map(|(_, v)| *v).collect(),
                    _ => vec![alpha, beta],
                };
                let parent_len = x0.len();
                let mut neutral = Vec::new();
                for (i, e) in before.iter().enumerate() {
                    // Bounds of the effects already in (their values come from the parent;
                    // without one, from their own starts).
                    let s = self.spec(&before[..i], *e, &de, &model_from(&[], &x0, &ctx))?;
                    lo.extend(s.lo);
                    hi.extend(s.hi);
                    neutral.extend(s.x0);
                }
                if parent_len < lo.len() {
                    x0.truncate(2);
                    x0.extend(neutral);
                }
                x0.truncate(lo.len());
                let parent_model = model_from(before, &x0, &ctx);
                let spec = self.spec(before, *last, &de, &parent_model)?;
                x0.extend(spec.x0);
                lo.extend(spec.lo);
                hi.extend(spec.hi);
                for (i, v) in x0.iter_mut().enumerate() {
                    *v = v.clamp(lo[i], hi[i]);
                }
                self.solve_model(
                    &effects,
                    &de,
                    &ctx,
                    &Spec {
                        x0,
                        lo: lo.clone(),
                        hi: hi.clone(),
                    },
                )?
            }
        };
        let x = r.x.clone();
        let model = model_from(&effects, &x, &ctx);
        let predicted = self.predict(&model, &dv)?;
        let names = Self::report_names(&effects, &ctx);
        let (mut params, mut ci95): (Vec<(String, f64)>, Vec<Option<f64>>) =
            (names.into_iter().zip(x.iter().copied()).collect(), r.ci95.clone());
        if let Some(pos) = effects.iter().position(|e| *e == EvvtEffect::BeltVibration) {
            // Report amplitude and phase instead of the cos/sin pair (same count).
            let at = 2 + (0..pos).map(|i| param_names(&effects, i).len()).sum::<usize>();
            let (c, s) = (x[at + 1], x[at + 2]);
            let amp = c.hypot(s);
            let (cc, cs) = (ci95[at + 1], ci95[at + 2]);
            params[at + 1] = ("belt_amplitude_deg".into(), amp);
            params[at + 2] = ("belt_phase_rad_at_log_start".into(), c.atan2(s));
            let (ci_a, ci_p) = match (cc, cs) {
                (Some(u), Some(v)) if amp > 0.0 => (
                    Some(((c * u).powi(2) + (s * v).powi(2)).sqrt() / amp),
                    Some(((s * u).powi(2) + (c * v).powi(2)).sqrt() / (amp * amp)),
                ),
                _ => (None, None),
            };
            ci95[at + 1] = ci_a;
            ci95[at + 2] = ci_p;
        }
        let labels: Vec<&str> = effects.iter().map(|e| e.name()).collect();
        let measured = Fit::shared_measured(parent, dv.y);
        let mut fit = Fit::with_shared(&Fit::label(&labels), params, ci95, measured, predicted, r.iterations)
            .with_solver(&internal_names, &lo, &hi, &r);
        fit.internal = internal_names.into_iter().zip(x).collect();
        Ok(fit)
    }

    fn probes(&self) -> &'static [Probe] {
        &PROBES
    }

    /// The probes: the final model with a transport delay of the motor command (linear
    /// between samples, 0-0.5 s) or with a drive-to-cam clearance (0-4 crank deg), every
    /// parameter refitted from the final model's optimum; the probe's value starts at the best
    /// of a coarse grid with those parameters.
    fn fit_probe(&self, probe: &str, effects: &[&str], parent: &Fit, est: &Log, val: &Log) -> Result<Fit, String> {
        // The probe's value: its start grid, upper bound, name, and where it enters the model.
        type Enter = fn(Model, f64) -> Model;
        let (grid, max, name, enter): (&[f64], f64, &str, Enter) = if probe == PROBES[0].name {
            (
                &[0.0, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32],
                PROBE_MAX_DELAY_S,
                "command_delay_s",
                |m, v| Model { cmd_delay_s: v, ..m },
            )
        } else if probe == PROBES[1].name {
            (
                &[0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0],
                PROBE_MAX_BACKLASH_DEG,
                "backlash_deg",
                |m, v| Model { backlash_deg: v, ..m },
            )
        } else {
            return Err(format!("no probe `{probe}` for the EVVT"));
        };
        let (effects, de, dv, ctx) = self.prepare(effects, est, val)?;
        let mut x0: Vec<f64> = parent.internal.iter().map(|(_, v)| *v).collect();
        if x0.len() < 2 {
            return Err("the final model has no parameters to start from".into());
        }
        let mut lo = vec![ALPHA_BOUNDS.0, BETA_BOUNDS.0];
        let mut hi = vec![ALPHA_BOUNDS.1, BETA_BOUNDS.1];
        for (i, e) in effects.iter().enumerate() {
            let s = self.spec(&effects[..i], *e, &de, &model_from(&[], &x0, &ctx))?;
            lo.extend(s.lo);
            hi.extend(s.hi);
        }
        x0.truncate(lo.len());
        let with_probe = |x: &[f64]| {
            let (value, rest) = x.split_last().unwrap_or((&0.0, x));
            enter(model_from(&effects, rest, &ctx), *value)
        };
        let mut out = vec![0.0; de.y.len()];
        let mut start = (f64::INFINITY, 0.0);
        for &value in grid {
            let mut x = x0.clone();
            x.push(value);
            if sim_error(&with_probe(&x), &de, &mut out).is_ok() {
                let cost = out.iter().map(|e| e * e).sum::<f64>();
                if cost < start.0 {
                    start = (cost, value);
                }
            }
        }
        x0.push(start.1);
        lo.push(0.0);
        hi.push(max);
        let r = self.solve_built(
            &with_probe,
            &de,
            &Spec {
                x0,
                lo: lo.clone(),
                hi: hi.clone(),
            },
        )?;
        let predicted = self.predict(&with_probe(&r.x), &dv)?;
        let mut names = Self::report_names(&effects, &ctx);
        names.push(name.into());
        let params: Vec<(String, f64)> = names.iter().cloned().zip(r.x.iter().copied()).collect();
        let measured = Fit::shared_measured(Some(parent), dv.y);
        let mut fit = Fit::with_shared(
            &format!("probe: {probe}"),
            params,
            r.ci95.clone(),
            measured,
            predicted,
            r.iterations,
        )
        .with_solver(&names, &lo, &hi, &r);
        fit.internal = names.into_iter().zip(r.x.iter().copied()).collect();
        Ok(fit)
    }

    fn regressors<'a>(&self, val: &'a Log) -> Vec<(String, Cow<'a, [f64]>)> {
        // The log's columns borrowed, derived series owned.
        (|| -> Vec<(String, Cow<'a, [f64]>)> {
            let Ok(d) = Data::from_log(val, self.open_loop_window_s, self.quantizer_ramp_lsb) else {
                return Vec::new();
            };
            let mut out: Vec<(String, Cow<'a, [f64]>)> = vec![
                ("battery voltage u_batt_V".into(), Cow::Borrowed(d.volt)),
                ("engine speed engine_rpm".into(), Cow::Borrowed(d.rpm)),
                ("motor_cmd_rpm".into(), Cow::Borrowed(d.cmd)),
                (
                    "advancing (motor_cmd_rpm > 0)".into(),
                    Cow::Owned(d.cmd.iter().map(|&u| if u > 0.0 { 1.0 } else { 0.0 }).collect()),
                ),
            ];
            if !d.reference.is_empty() {
                out.push(("phase_ref_deg".into(), Cow::Borrowed(d.reference)));
            }
            let (_, ohi) = self.order_range(&d);
            let sinusoid = |o: f64, f: fn(f64) -> f64| {
                Cow::Owned(d.revs().map(|th| f(2.0 * PI * (o * th).fract())).collect::<Vec<f64>>())
            };
            // The peak of the baseline residual's order spectrum on this record: a disturbance
            // locked to crank angle shows here whatever the engine speed.
            let last = self.baseline.lock().ok().and_then(|g| *g);
            if let Some((_, a, b)) = last {
                let ctx = Model::lti(a, b);
                let mut pred = vec![0.0; d.y.len()];
                if simulate(&ctx, &d, &mut pred).is_ok() {
                    let resid: Vec<f64> = d.y.iter().zip(&pred).map(|(y, p)| y - p).collect();
                    if let Some((o, amp)) = order_peak(&resid, d.revs(), self.min_order, ohi) {
                        out.push((format!("sin(2π·{o:.3}·crank revolutions) (order-spectrum peak of the baseline residual, {amp:.2} deg)"), sinusoid(o, f64::sin)));
                        out.push((
                            format!("cos(2π·{o:.3}·crank revolutions) (order-spectrum peak)"),
                            sinusoid(o, f64::cos),
                        ));
                    }
                }
            }
            for o in [0.5, 1.0, 1.5, 2.0] {
                if o <= ohi {
                    out.push((format!("sin(2π·{o}·crank revolutions)"), sinusoid(o, f64::sin)));
                    out.push((format!("cos(2π·{o}·crank revolutions)"), sinusoid(o, f64::cos)));
                }
            }
            out
        })()
    }
}

#[cfg(test)]
mod tests;
