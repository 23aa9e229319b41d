//! One calibrated model's record ([`Fit`]: parameters, confidence, solver outcome, validation
//! prediction and error) and the noise floor a perfect model would score on the same data.

use std::sync::Arc;

use crate::residuals::fit_pct;

/// One calibrated model and how it does on the validation data.
#[derive(Clone, Debug)]
pub struct Fit {
    /// `baseline`, the catalogue effect's name, or the effects joined by `+`.
    pub effect: String,
    /// The catalogue effects of this model, in the order they were added (empty: baseline).
    pub effects: Vec<String>,
    pub params: Vec<(String, f64)>,
    /// 95 % half-widths, same order as `params`.
    pub ci95: Vec<Option<f64>>,
    /// Measured and predicted output on the validation data (same length). Empty in the
    /// candidates of a [`Diagnosis`](super::Diagnosis) (their figures are kept, not their series); the baseline
    /// and the extended model keep theirs. Shared: every fit of one diagnosis measures the same
    /// validation output, so it is held once ([`diagnose`](super::diagnose) joins equal copies).
    pub measured: Arc<[f64]>,
    pub predicted: Vec<f64>,
    pub rmse: f64,
    pub fit_pct: f64,
    /// Solver iterations (0 for closed-form fits).
    pub iterations: usize,
    /// The family's own parameter vector at the optimum (internal names), from which a richer
    /// model that extends this one starts.
    pub internal: Vec<(String, f64)>,
    /// The solver's cost at the optimum on the estimation data (½‖r‖², the family's
    /// residuals), NaN when not known: a model never ends above the one it extends.
    pub est_cost: f64,
    /// How the fit ended (the solver's stop reason per stage, or `closed form`).
    pub convergence: String,
    /// Parameters that ended on a bound of their search range.
    pub at_bound: Vec<String>,
    /// Parameters with a physically impossible value (a negative mass), with the value.
    pub impossible: Vec<String>,
    /// Parameters (or directions) the data cannot identify: a singular information matrix or a
    /// 95 % interval wider than half the parameter's search range.
    pub not_identifiable: Vec<String>,
}

impl Fit {
    pub fn new(
        effect: &str,
        params: Vec<(String, f64)>,
        ci95: Vec<Option<f64>>,
        measured: Vec<f64>,
        predicted: Vec<f64>,
        iterations: usize,
    ) -> Self {
        Self::with_shared(effect, params, ci95, measured.into(), predicted, iterations)
    }

    /// [`Fit::new`] with the measured output already shared (e.g. the parent fit's copy, when
    /// equal): no second validation-length copy is made.
    pub fn with_shared(
        effect: &str,
        params: Vec<(String, f64)>,
        ci95: Vec<Option<f64>>,
        measured: Arc<[f64]>,
        predicted: Vec<f64>,
        iterations: usize,
    ) -> Self {
        // rmse(y - ŷ) without making the residual series (a validation-length copy).
        let n = measured.len().min(predicted.len());
        let rmse = if n == 0 {
            0.0
        } else {
            let sum: f64 = measured.iter().zip(&predicted).map(|(y, p)| (y - p) * (y - p)).sum();
            (sum / n as f64).sqrt()
        };
        let effects = if effect == "baseline" {
            Vec::new()
        } else {
            effect.split('+').map(str::to_string).collect()
        };
        Fit {
            effect: effect.to_string(),
            effects,
            internal: params.clone(),
            params,
            ci95,
            rmse,
            fit_pct: fit_pct(&measured, &predicted),
            measured,
            predicted,
            iterations,
            est_cost: f64::NAN,
            convergence: if iterations == 0 {
                "closed form".into()
            } else {
                format!("{iterations} iterations")
            },
            at_bound: Vec::new(),
            impossible: Vec::new(),
            not_identifiable: Vec::new(),
        }
    }
    pub fn residual(&self) -> Vec<f64> {
        self.measured.iter().zip(&self.predicted).map(|(y, p)| y - p).collect()
    }
    /// The measured validation output a new fit holds: `parent`'s copy when it is the same
    /// (every fit of one diagnosis measures the same output), else a new one.
    pub fn shared_measured(parent: Option<&Fit>, measured: &[f64]) -> Arc<[f64]> {
        match parent {
            Some(f) if f.measured[..] == *measured => f.measured.clone(),
            _ => measured.into(),
        }
    }
    /// The length of [`Fit::residual`], without making it.
    pub fn residual_len(&self) -> usize {
        self.measured.len().min(self.predicted.len())
    }
    pub fn n_params(&self) -> usize {
        self.params.len()
    }
    /// The value of the internal parameter `name` at the optimum ([`Fit::internal`]).
    pub fn internal_value(&self, name: &str) -> Option<f64> {
        self.internal.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }
    /// The label of a model with `effects` (`baseline` when empty).
    pub fn label(effects: &[&str]) -> String {
        if effects.is_empty() {
            "baseline".into()
        } else {
            effects.join("+")
        }
    }
    /// Records what a solver run says about the fit: its stop reason, the parameters at a
    /// bound and those the data cannot identify (`names`, `lo`, `hi` in the solver's order).
    pub fn with_solver(mut self, names: &[String], lo: &[f64], hi: &[f64], r: &crate::lsq::LsqResult) -> Self {
        self.est_cost = r.cost;
        self.convergence = crate::lsq::convergence_text(r);
        for i in crate::lsq::at_bounds(&r.x, lo, hi) {
            if let Some(n) = names.get(i) {
                self.at_bound.push(n.clone());
            }
        }
        for i in crate::lsq::not_identifiable(r, lo, hi) {
            if let Some(n) = names.get(i) {
                self.not_identifiable.push(n.clone());
            }
        }
        self
    }
    /// Whether the measured output is the same at every validation sample: no excitation,
    /// nothing a model can be judged on (the report's warning, the probes not fitted).
    pub fn measured_is_constant(&self) -> bool {
        self.measured.iter().all(|v| *v == self.measured[0])
    }

    /// Is anything about this calibration not good (a bound, an impossible value, a direction
    /// the data cannot see)?
    pub fn flags(&self) -> Vec<String> {
        let mut f = Vec::new();
        if !self.at_bound.is_empty() {
            f.push(format!("at a bound: {}", self.at_bound.join(", ")));
        }
        if !self.impossible.is_empty() {
            f.push(format!("physically impossible: {}", self.impossible.join(", ")));
        }
        if !self.not_identifiable.is_empty() {
            f.push(format!(
                "not identifiable from these data: {}",
                self.not_identifiable.join(", ")
            ));
        }
        f
    }
}

/// What a perfect model would score on the validation data.
#[derive(Clone, Debug)]
pub struct NoiseFloor {
    pub rmse: f64,
    pub method: String,
}

/// The noise floor from the data themselves: the sensor noise from the second differences of a
/// model's validation residual `y` (what the model already explains is removed; a smooth
/// remainder's second difference is small next to white noise's, whose variance it multiplies
/// by 6), as a trimmed RMS of the 80 % smallest |Δ²y| (robust to the few samples where a
/// remainder moves fast; corrected for the trimming of a Gaussian), and at least the
/// quantization error q/√12 of the measured output's step `q`: what a perfect model would
/// leave. The diagnosis takes the smallest over the baseline and each model it selects.
pub fn noise_floor_of(y: &[f64], q: f64) -> NoiseFloor {
    let mut d: Vec<f64> = y.windows(3).map(|w| (w[0] - 2.0 * w[1] + w[2]).abs()).collect();
    let sigma = if d.len() >= 10 {
        d.sort_by(f64::total_cmp);
        let keep = (d.len() as f64 * 0.8).round() as usize;
        let ms = d[..keep].iter().map(|v| v * v).sum::<f64>() / keep as f64;
        // E[x² | |x| < z_0.9] = 1 - 2 z φ(z) / 0.8 for a unit Gaussian, z = 1.2816.
        (ms / 0.4377 / 6.0).sqrt()
    } else {
        0.0
    };
    let quant = q / 12f64.sqrt();
    NoiseFloor {
        rmse: sigma.max(quant),
        method: format!(
            "sensor noise from the second differences of the validation residual (trimmed RMS of the 80 % smallest, /√6): σ = {}; quantization step of the output q = {} (q/√12 = {}); floor = the larger",
            sig(sigma),
            sig(q),
            sig(quant)
        ),
    }
}

/// The quantization step of a signal: the smallest spacing between its distinct values
/// (0 for a signal with too few repeats to tell).
pub fn resolution(y: &[f64]) -> f64 {
    let mut v: Vec<f64> = y.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 2 || v.len() * 4 > y.len() {
        // Nearly every sample distinct: no visible quantizer.
        return 0.0;
    }
    let span = v[v.len() - 1] - v[0];
    let min_gap = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > span * 1e-9)
        .fold(f64::INFINITY, f64::min);
    if min_gap.is_finite() {
        min_gap
    } else {
        0.0
    }
}

/// A number with 4 significant digits for a sentence.
fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let digits = (3 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.digits$}")
}
