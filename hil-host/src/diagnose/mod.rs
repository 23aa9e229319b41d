//! `diagnose`: from measured data to the named cause, the extended model and the measured gain.
//!
//! Each plant has a *family*: a baseline model (the paper's model with the catalogue's effects
//! left out) and one extension per catalogue effect (DATA-FORMAT.md). The family calibrates each
//! on the estimation data and predicts the validation data; this module does the rest, the same
//! for every plant: residual tests on the baseline, the ranking of the candidates with a penalty
//! for extra parameters, the significance test that keeps noise from being named a cause, the
//! preference for the simpler of two nested explanations, and the report.

pub mod ehvva;
pub mod evvt;
pub mod positioner;
pub mod report;
pub mod vacuum;

use crate::log::{Log, Plant};
use crate::residuals::{cross_check, fit_pct, rmse, whiteness, CrossCheck, Whiteness};

/// One calibrated model and how it does on the validation data.
#[derive(Clone, Debug)]
pub struct Fit {
    /// `baseline` or the catalogue effect's name.
    pub effect: String,
    pub params: Vec<(String, f64)>,
    /// 95 % half-widths, same order as `params`.
    pub ci95: Vec<Option<f64>>,
    /// Measured and predicted output on the validation data (same length).
    pub measured: Vec<f64>,
    pub predicted: Vec<f64>,
    pub rmse: f64,
    pub fit_pct: f64,
    /// Solver iterations (0 for closed-form fits).
    pub iterations: usize,
}

impl Fit {
    pub fn new(effect: &str, params: Vec<(String, f64)>, ci95: Vec<Option<f64>>, measured: Vec<f64>, predicted: Vec<f64>, iterations: usize) -> Self {
        let e: Vec<f64> = measured.iter().zip(&predicted).map(|(y, p)| y - p).collect();
        Fit { effect: effect.to_string(), params, ci95, rmse: rmse(&e), fit_pct: fit_pct(&measured, &predicted), measured, predicted, iterations }
    }
    pub fn residual(&self) -> Vec<f64> {
        self.measured.iter().zip(&self.predicted).map(|(y, p)| y - p).collect()
    }
    pub fn n_params(&self) -> usize {
        self.params.len()
    }
}

/// A plant's models for the diagnosis.
pub trait Family {
    fn plant(&self) -> Plant;
    /// The column (or derived quantity) whose error is reported.
    fn output(&self) -> &'static str;
    /// How the model meets closed-loop data: "simulation" or "equation-error (...)".
    fn formulation(&self) -> &'static str;
    fn effects(&self) -> &'static [&'static str];
    /// Pairs (simpler, richer) where the richer effect contains the simpler one.
    fn nested(&self) -> &'static [(&'static str, &'static str)] {
        &[]
    }
    /// Calibrates the baseline (`effect` = None) or baseline + effect on `est`, predicts `val`.
    fn fit(&self, effect: Option<&str>, est: &Log, val: &Log) -> Result<Fit, String>;
    /// Signals of the validation data to correlate the residual with (inputs and candidate
    /// regressors), aligned with the fit's `measured`.
    fn regressors(&self, val: &Log) -> Vec<(String, Vec<f64>)>;
}

/// Decision thresholds.
#[derive(Clone, Debug)]
pub struct Rules {
    /// A cause must lower the validation RMSE by at least this much.
    pub min_gain_pct: f64,
    /// And the improvement must stand out from noise by this many standard errors.
    pub min_z: f64,
    /// Rank penalty per extra parameter (relative RMSE).
    pub penalty_per_param: f64,
    /// A richer nested effect is named over the simpler one only if its gain exceeds the
    /// simpler one's by this many percentage points (of the baseline RMSE), significantly:
    /// "explains the data about equally" is judged against what the baseline got wrong.
    pub nested_margin_pct: f64,
}

impl Default for Rules {
    fn default() -> Self {
        Rules { min_gain_pct: 5.0, min_z: 4.0, penalty_per_param: 0.01, nested_margin_pct: 10.0 }
    }
}

/// How clearly model B's errors beat model A's, as a z-score. The validation record is cut
/// into 40 blocks, so the residuals' autocorrelation does not pass for thousands of
/// independent samples; two tests of "B is better" are made on the blocks' mean squared-error
/// differences and the larger score is returned:
/// - the t-statistic of their mean (sensitive when the improvement is even), and
/// - the sign test of how many blocks B wins (robust when the improvement is concentrated in
///   some blocks, e.g. friction that only shows while the load moves).
pub fn improvement_z(e_a: &[f64], e_b: &[f64]) -> f64 {
    let n = e_a.len().min(e_b.len());
    let blocks = 40.min(n);
    if blocks < 2 {
        return 0.0;
    }
    let size = n / blocks;
    let means: Vec<f64> = (0..blocks)
        .map(|b| (b * size..(b + 1) * size).map(|t| e_a[t] * e_a[t] - e_b[t] * e_b[t]).sum::<f64>() / size as f64)
        .collect();
    let m = means.iter().sum::<f64>() / blocks as f64;
    let var = means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (blocks - 1) as f64;
    let se = (var / blocks as f64).sqrt();
    let t = if se == 0.0 {
        if m > 0.0 {
            f64::INFINITY
        } else {
            0.0
        }
    } else {
        m / se
    };
    let wins = means.iter().filter(|&&d| d > 0.0).count() as f64;
    let ties = means.iter().filter(|&&d| d == 0.0).count() as f64;
    let decided = blocks as f64 - ties;
    let sign = if decided > 0.0 { (wins - decided / 2.0) / (decided / 4.0).sqrt() } else { 0.0 };
    t.max(sign)
}

/// One candidate's standing.
#[derive(Clone, Debug)]
pub struct Candidate {
    pub fit: Fit,
    pub gain_pct: f64,
    pub z: f64,
    pub eligible: bool,
}

/// Everything the diagnosis found.
#[derive(Clone, Debug)]
pub struct Diagnosis {
    pub plant: Plant,
    pub output: String,
    pub formulation: String,
    pub estimation: (String, usize),
    pub validation: (String, usize),
    pub validation_is_tail: bool,
    pub baseline: Fit,
    pub whiteness: Whiteness,
    pub cross: Vec<CrossCheck>,
    pub candidates: Vec<Candidate>,
    pub cause: String,
    pub extended: Fit,
    pub gain_pct: f64,
    /// Sentences for the human summary.
    pub evidence: Vec<String>,
}

/// Splits one log into estimation head and validation tail (`tail` fraction held out).
pub fn split_tail(log: &Log, tail: f64) -> (Log, Log) {
    let n = log.len();
    let cut = ((n as f64) * (1.0 - tail)).round() as usize;
    let part = |r: std::ops::Range<usize>, suffix: &str| {
        let mut l = log.clone();
        for v in l.columns.values_mut() {
            *v = v[r.clone()].to_vec();
        }
        l.file = format!("{}{}", log.file, suffix);
        l
    };
    (part(0..cut, " (first 70 %)"), part(cut..n, " (last 30 %, held out)"))
}

/// Runs the whole diagnosis. `progress` is told each fit as it starts.
pub fn diagnose(family: &dyn Family, est: &Log, val: &Log, validation_is_tail: bool, rules: &Rules, progress: &mut dyn FnMut(&str)) -> Result<Diagnosis, String> {
    progress("baseline");
    let baseline = family.fit(None, est, val)?;
    let e0 = baseline.residual();
    let lags = (e0.len() / 20).clamp(5, 50);
    let white = whiteness(&e0, lags);
    let cross: Vec<CrossCheck> = family.regressors(val).iter().map(|(name, u)| cross_check(name, &e0, u, lags)).collect();

    let mut candidates = Vec::new();
    for effect in family.effects() {
        progress(effect);
        let fit = match family.fit(Some(effect), est, val) {
            Ok(f) => f,
            Err(e) => {
                // A candidate that cannot be fitted is reported, not fatal.
                let mut f = baseline.clone();
                f.effect = format!("{effect}");
                f.rmse = f64::INFINITY;
                f.fit_pct = f64::NEG_INFINITY;
                f.params = vec![(format!("error: {e}"), f64::NAN)];
                candidates.push(Candidate { fit: f, gain_pct: f64::NEG_INFINITY, z: 0.0, eligible: false });
                continue;
            }
        };
        let gain_pct = 100.0 * (baseline.rmse - fit.rmse) / baseline.rmse;
        let z = improvement_z(&e0, &fit.residual());
        let eligible = gain_pct >= rules.min_gain_pct && z >= rules.min_z;
        candidates.push(Candidate { fit, gain_pct, z, eligible });
    }

    // Rank by penalised validation error.
    let score = |c: &Candidate| c.fit.rmse * (1.0 + rules.penalty_per_param * c.fit.n_params().saturating_sub(baseline.n_params()) as f64);
    let mut best: Option<usize> = None;
    for (i, c) in candidates.iter().enumerate() {
        if c.eligible && best.is_none_or(|b| score(c) < score(&candidates[b])) {
            best = Some(i);
        }
    }
    let mut evidence = Vec::new();
    // Prefer the simpler of two nested explanations unless the richer is clearly better.
    if let Some(b) = best {
        for (simple, rich) in family.nested() {
            if candidates[b].fit.effect == *rich {
                if let Some(s) = candidates.iter().position(|c| c.fit.effect == *simple && c.eligible) {
                    let extra = candidates[b].gain_pct - candidates[s].gain_pct;
                    let over = 100.0 * (candidates[s].fit.rmse - candidates[b].fit.rmse) / candidates[s].fit.rmse;
                    let z = improvement_z(&candidates[s].fit.residual(), &candidates[b].fit.residual());
                    if extra < rules.nested_margin_pct || z < rules.min_z {
                        evidence.push(format!(
                            "`{rich}` nests `{simple}`; it adds {extra:.1} points of gain (its RMSE is {over:.1} % below `{simple}`'s, z = {z:.1}), under the {} point margin: the simpler `{simple}` is named",
                            rules.nested_margin_pct
                        ));
                        best = Some(s);
                    } else {
                        evidence.push(format!(
                            "`{rich}` adds {extra:.1} points of gain over the nested `{simple}` (z = {z:.1}): named"
                        ));
                    }
                }
            }
        }
    }

    if white.pass {
        evidence.push(format!("baseline residual is white (Ljung-Box Q = {:.1} < {:.1})", white.ljung_box_q, white.ljung_box_limit));
    } else {
        evidence.push(format!(
            "baseline residual is not white: Ljung-Box Q = {:.1} > {:.1}, largest autocorrelation {:.2} at lag {} (band ±{:.3})",
            white.ljung_box_q, white.ljung_box_limit, white.max_abs_rho, white.max_lag, white.band
        ));
    }
    for c in cross.iter().filter(|c| !c.pass) {
        evidence.push(format!("residual correlates with {} ({:.2} at lag {}, band ±{:.3})", c.name, c.max_abs, c.at_lag, c.band));
    }
    let (cause, extended, gain_pct) = match best {
        Some(b) => {
            let c = &candidates[b];
            evidence.push(format!(
                "`{}` lowers the validation RMSE from {:.4} to {:.4} ({:.1} %, z = {:.1})",
                c.fit.effect, baseline.rmse, c.fit.rmse, c.gain_pct, c.z
            ));
            (c.fit.effect.clone(), c.fit.clone(), c.gain_pct)
        }
        None => {
            evidence.push(format!(
                "no extension lowers the validation RMSE by ≥ {} % with z ≥ {}: cause `none`",
                rules.min_gain_pct, rules.min_z
            ));
            (String::from("none"), baseline.clone(), 0.0)
        }
    };
    Ok(Diagnosis {
        plant: family.plant(),
        output: family.output().to_string(),
        formulation: family.formulation().to_string(),
        estimation: (est.file.clone(), est.len()),
        validation: (val.file.clone(), val.len()),
        validation_is_tail,
        baseline,
        whiteness: white,
        cross,
        candidates,
        cause,
        extended,
        gain_pct,
        evidence,
    })
}

/// The family for a plant.
pub fn family_for(plant: Plant) -> Result<Box<dyn Family>, String> {
    match plant {
        Plant::Evvt => Ok(Box::new(evvt::EvvtFamily::default())),
        Plant::Positioner => Ok(Box::new(positioner::PositionerFamily::default())),
        Plant::Vacuum => Ok(Box::new(vacuum::VacuumFamily::default())),
        Plant::Ehvva => Ok(Box::new(ehvva::EhvvaFamily::default())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn improvement_z_separates_signal_from_noise() {
        let noise = |k: usize, s: f64| ((k as f64 * 12.9898 + s).sin() * 43758.5453).rem_euclid(1.0) - 0.5;
        let a: Vec<f64> = (0..4000).map(|k| noise(k, 1.0)).collect();
        let b: Vec<f64> = (0..4000).map(|k| noise(k, 2.0)).collect();
        // Two equally good models: no significant difference.
        assert!(improvement_z(&a, &b).abs() < 4.0);
        // B halves A's errors: clearly significant.
        let half: Vec<f64> = a.iter().map(|v| v * 0.5).collect();
        assert!(improvement_z(&a, &half) > 10.0);
    }
}
