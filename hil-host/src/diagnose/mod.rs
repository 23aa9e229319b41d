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
pub mod progress;
pub mod report;
pub mod vacuum;

use std::sync::{mpsc, Arc};
use std::time::Instant;

use crate::log::{Log, Plant};
use crate::lsq::with_iteration_observer;
use crate::residuals::{cross_check, fit_pct, group_check, rmse, whiteness, CrossCheck, GroupCheck, Whiteness};

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
    pub fn new(
        effect: &str,
        params: Vec<(String, f64)>,
        ci95: Vec<Option<f64>>,
        measured: Vec<f64>,
        predicted: Vec<f64>,
        iterations: usize,
    ) -> Self {
        let e: Vec<f64> = measured.iter().zip(&predicted).map(|(y, p)| y - p).collect();
        Fit {
            effect: effect.to_string(),
            params,
            ci95,
            rmse: rmse(&e),
            fit_pct: fit_pct(&measured, &predicted),
            measured,
            predicted,
            iterations,
        }
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
        Rules {
            min_gain_pct: 5.0,
            min_z: 4.0,
            penalty_per_param: 0.01,
            nested_margin_pct: 10.0,
        }
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
        .map(|b| {
            (b * size..(b + 1) * size)
                .map(|t| e_a[t] * e_a[t] - e_b[t] * e_b[t])
                .sum::<f64>()
                / size as f64
        })
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
    let sign = if decided > 0.0 {
        (wins - decided / 2.0) / (decided / 4.0).sqrt()
    } else {
        0.0
    };
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
    /// The baseline residual grouped by each regressor as an operating condition.
    pub grouped: Vec<GroupCheck>,
    pub candidates: Vec<Candidate>,
    pub cause: String,
    pub extended: Fit,
    pub gain_pct: f64,
    /// Sentences for the human summary.
    pub evidence: Vec<String>,
    /// Input columns that never vary in the estimation or the validation data, with where when
    /// only one is (`duty_pct`, `u_batt_V (validation data only)`): no excitation, so what depends on them cannot be
    /// computed (the report says so instead of printing NaN or a perfect fit).
    pub unexcited: Vec<String>,
}

/// The plant's input columns that are constant in `est` or `val` (see [`Diagnosis::unexcited`]).
pub fn unexcited_inputs(est: &Log, val: &Log) -> Vec<String> {
    let constant = |log: &Log, name: &str| {
        log.columns
            .get(name)
            .is_some_and(|v| v.iter().all(|x| *x == v[0] || (x.is_nan() && v[0].is_nan())))
    };
    est.plant
        .columns()
        .iter()
        .filter(|(_, role)| *role == crate::log::Role::Input)
        .filter_map(|(name, _)| match (constant(est, name), constant(val, name)) {
            (true, true) => Some(name.to_string()),
            (true, false) => Some(format!("{name} (estimation data only)")),
            (false, true) => Some(format!("{name} (validation data only)")),
            (false, false) => None,
        })
        .collect()
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

/// Where a diagnosis stands, for a progress display ([`progress::ProgressLine`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Progress<'a> {
    /// `baseline` or the catalogue effect being fitted.
    pub fit: &'a str,
    /// Position of this fit, 1-based (the baseline is 1), among `total` = 1 + candidates.
    pub index: usize,
    pub total: usize,
    /// Solver iterations of this fit so far, over all its solver stages (0 as it starts).
    pub iteration: usize,
    /// Seconds since the diagnosis began.
    pub elapsed_s: f64,
}

/// What the fitting thread tells the progress relay.
enum Tick {
    Fit { name: String, index: usize },
    Iteration,
}

/// Runs the whole diagnosis. `progress` is told each fit as it starts (iteration 0) and each
/// solver iteration of it (heard through [`crate::lsq::with_iteration_observer`], so the
/// families need not report). It is called in order from a helper thread while the fits run
/// on this one, and never after `diagnose` returns.
pub fn diagnose(
    family: &dyn Family,
    est: &Log,
    val: &Log,
    validation_is_tail: bool,
    rules: &Rules,
    progress: &mut (dyn FnMut(&Progress) + Send),
) -> Result<Diagnosis, String> {
    let start = Instant::now();
    let total = 1 + family.effects().len();
    let (tx, rx) = mpsc::channel::<Tick>();
    std::thread::scope(|s| {
        s.spawn(move || {
            let (mut name, mut index, mut iteration) = (String::new(), 0, 0);
            // Ends when the fitting side has dropped every sender.
            for tick in rx {
                match tick {
                    Tick::Fit { name: n, index: i } => (name, index, iteration) = (n, i, 0),
                    Tick::Iteration => iteration += 1,
                }
                progress(&Progress {
                    fit: &name,
                    index,
                    total,
                    iteration,
                    elapsed_s: start.elapsed().as_secs_f64(),
                });
            }
        });
        let fit = |effect: Option<&str>, index: usize| -> Result<Fit, String> {
            let _ = tx.send(Tick::Fit {
                name: effect.unwrap_or("baseline").to_string(),
                index,
            });
            let iterations = tx.clone();
            with_iteration_observer(Arc::new(move |_| drop(iterations.send(Tick::Iteration))), || {
                family.fit(effect, est, val)
            })
        };
        let result = diagnose_fits(family, est, val, validation_is_tail, rules, &fit);
        drop(tx);
        result
    })
}

/// Calibrates one model (`None`: the baseline) as fit number `index`, and reports it.
type FitOne<'a> = dyn Fn(Option<&str>, usize) -> Result<Fit, String> + 'a;

/// The diagnosis proper; `fit(effect, index)` calibrates one model (and reports it).
fn diagnose_fits(
    family: &dyn Family,
    est: &Log,
    val: &Log,
    validation_is_tail: bool,
    rules: &Rules,
    fit: &FitOne,
) -> Result<Diagnosis, String> {
    let baseline = fit(None, 1)?;
    let e0 = baseline.residual();
    let lags = (e0.len() / 20).clamp(5, 50);
    let white = whiteness(&e0, lags);
    let regressors = family.regressors(val);
    let cross: Vec<CrossCheck> = regressors
        .iter()
        .map(|(name, u)| cross_check(name, &e0, u, lags))
        .collect();
    let grouped: Vec<GroupCheck> = regressors.iter().map(|(name, u)| group_check(name, &e0, u)).collect();

    let mut candidates = Vec::new();
    for (i, effect) in family.effects().iter().enumerate() {
        let fit = match fit(Some(effect), 2 + i) {
            Ok(f) => f,
            Err(e) => {
                // A candidate that cannot be fitted is reported, not fatal.
                let mut f = baseline.clone();
                f.effect = effect.to_string();
                f.rmse = f64::INFINITY;
                f.fit_pct = f64::NEG_INFINITY;
                f.params = vec![(format!("error: {e}"), f64::NAN)];
                candidates.push(Candidate {
                    fit: f,
                    gain_pct: f64::NEG_INFINITY,
                    z: 0.0,
                    eligible: false,
                });
                continue;
            }
        };
        let gain_pct = 100.0 * (baseline.rmse - fit.rmse) / baseline.rmse;
        let z = improvement_z(&e0, &fit.residual());
        let eligible = gain_pct >= rules.min_gain_pct && z >= rules.min_z;
        candidates.push(Candidate {
            fit,
            gain_pct,
            z,
            eligible,
        });
    }

    // Rank by penalised validation error.
    let score = |c: &Candidate| {
        c.fit.rmse * (1.0 + rules.penalty_per_param * c.fit.n_params().saturating_sub(baseline.n_params()) as f64)
    };
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
        evidence.push(format!(
            "baseline residual is white (Ljung-Box Q = {:.1} < {:.1})",
            white.ljung_box_q, white.ljung_box_limit
        ));
    } else {
        evidence.push(format!(
            "baseline residual is not white: Ljung-Box Q = {:.1} > {:.1}, largest autocorrelation {:.2} at lag {} (band ±{:.3})",
            white.ljung_box_q, white.ljung_box_limit, white.max_abs_rho, white.max_lag, white.band
        ));
    }
    for c in cross.iter().filter(|c| !c.pass) {
        evidence.push(format!(
            "residual correlates with {} ({:.2} at lag {}, band ±{:.3})",
            c.name, c.max_abs, c.at_lag, c.band
        ));
    }
    for g in grouped.iter().filter(|g| !g.pass) {
        let means: Vec<String> = g
            .groups
            .iter()
            .map(|m| format!("{} {:+.4} (RMSE {:.4}, {} samples)", m.label, m.mean, m.rmse, m.samples))
            .collect();
        evidence.push(format!(
            "residual mean differs by {} (z = {:.1}): {}",
            g.name,
            g.z,
            means.join("; ")
        ));
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
        grouped,
        candidates,
        cause,
        extended,
        gain_pct,
        evidence,
        unexcited: unexcited_inputs(est, val),
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

    /// A family whose fits are small solver runs: y = a·u (+ b·u² with the effect), so the
    /// progress reports can be checked against the solver's own iteration counts.
    struct Quadratic;

    impl Family for Quadratic {
        fn plant(&self) -> Plant {
            Plant::Positioner
        }
        fn output(&self) -> &'static str {
            "pos_m"
        }
        fn formulation(&self) -> &'static str {
            "test"
        }
        fn effects(&self) -> &'static [&'static str] {
            &["square", "square-again"]
        }
        fn fit(&self, effect: Option<&str>, _est: &Log, _val: &Log) -> Result<Fit, String> {
            let u: Vec<f64> = (0..200).map(|k| k as f64 / 100.0).collect();
            let y: Vec<f64> = u
                .iter()
                .map(|u| 2.0 * u + 0.5 * u * u + 0.01 * (u * 977.0).sin())
                .collect();
            let with_b = effect.is_some();
            let model = |x: &[f64], u: f64| x[0] * u + if with_b { x[1] * u * u } else { 0.0 };
            let r = crate::lsq::solve(
                |x: &[f64], out: &mut [f64]| {
                    for (k, o) in out.iter_mut().enumerate() {
                        // Exponentiated so the fit is nonlinear and takes several iterations.
                        *o = model(&[x[0].exp(), x[1].exp()], u[k]) - y[k];
                    }
                    Ok(())
                },
                &[-2.0, -3.0],
                &[-10.0, -10.0],
                &[10.0, 10.0],
                u.len(),
                &crate::lsq::LsqOptions::default(),
            )
            .map_err(|e| e.to_string())?;
            let x = [r.x[0].exp(), r.x[1].exp()];
            let predicted = u.iter().map(|&u| model(&x, u)).collect();
            Ok(Fit::new(
                effect.unwrap_or("baseline"),
                vec![("a".into(), x[0]), ("b".into(), x[1])],
                vec![None, None],
                y,
                predicted,
                r.iterations,
            ))
        }
        fn regressors(&self, _val: &Log) -> Vec<(String, Vec<f64>)> {
            Vec::new()
        }
    }

    #[test]
    fn progress_reports_every_fit_and_each_solver_iteration() {
        let log = crate::log::parse_log(
            "p.csv",
            "# plant: positioner\nt_s,force_N,pos_m\n0,0,0\n0.001,1,0\n",
            None,
        )
        .unwrap();
        let mut seen: Vec<(String, usize, usize, usize, f64)> = Vec::new();
        let d = diagnose(&Quadratic, &log, &log, false, &Rules::default(), &mut |p: &Progress| {
            seen.push((p.fit.to_string(), p.index, p.total, p.iteration, p.elapsed_s))
        })
        .unwrap();
        assert_eq!(d.cause, "square");
        let fits = [
            ("baseline", &d.baseline),
            ("square", &d.candidates[0].fit),
            ("square-again", &d.candidates[1].fit),
        ];
        for (i, (name, fit)) in fits.iter().enumerate() {
            let reports: Vec<usize> = seen.iter().filter(|s| s.1 == i + 1).map(|s| s.3).collect();
            assert!(seen.iter().filter(|s| s.1 == i + 1).all(|s| s.0 == *name && s.2 == 3));
            // The fit's start, then one report per solver iteration, counted up.
            let expected: Vec<usize> = (0..=fit.iterations).collect();
            assert!(fit.iterations > 2, "{name}: {} iterations", fit.iterations);
            assert_eq!(reports, expected, "{name}");
        }
        // In order of the fits, and time never runs backwards.
        assert!(seen.windows(2).all(|w| w[0].1 <= w[1].1 && w[0].4 <= w[1].4));
        assert_eq!(seen.len(), fits.iter().map(|f| f.1.iterations + 1).sum::<usize>());
    }

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
