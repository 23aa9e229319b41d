//! `diagnose`: from measured data to the named cause, the extended model and the measured gain.
//!
//! Each plant has a *family*: a baseline model (the paper's model with the catalogue's effects
//! left out) and one extension per catalogue effect (DATA-FORMAT.md). The family calibrates each
//! on the estimation data and predicts the validation data; this module does the rest, the same
//! for every plant: residual tests on the baseline, the ranking of the candidates with a penalty
//! for extra parameters, the significance test that keeps noise from being named a cause, the
//! preference for the simpler of two nested explanations, and the report.

pub mod catalogue;
pub mod ehvva;
pub mod evvt;
mod fit;
mod none_eligible;
mod order_spectrum;
mod outside;
pub mod positioner;
mod probes;
pub mod progress;
pub mod report;
mod residual_tests;
mod selection;
mod significance;
mod verdict;
pub use probes::Probe;
pub mod vacuum;

pub use fit::{noise_floor_of, resolution, Fit, NoiseFloor};
pub use significance::{improvement_z, improvement_z_of};

use residual_tests::{locate, ResidualTests};

use std::borrow::Cow;
use std::cell::RefCell;
use std::sync::{mpsc, Arc};
use std::time::Instant;

use crate::log::{Log, Plant};
use crate::lsq::with_iteration_observer;
use crate::residuals::{CrossCheck, GroupCheck, Whiteness};

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
    /// The estimation log reduced to what this family's fits use; the default keeps all of it.
    /// A family that fits long records on a part of them (EHVVA: at most
    /// [`ehvva::MAX_FIT_EVENTS`] events) returns that part, so the rest of a long log is not
    /// held through the diagnosis; the log's name then says what was kept.
    fn estimation_part(&self, est: Log) -> Result<Log, String> {
        Ok(est)
    }
    /// The part of the validation log to score, where the family can tell that some of it
    /// lies in a regime the estimation log `est` never shows (`None`, the default: all of it).
    /// A model is calibrated only where the estimation data excite it; scored on a regime the
    /// estimation never held, a richer model that fits the estimation better can lose to a
    /// poorer one by extrapolating differently, and the candidates are judged on that instead
    /// of on the effect. What is left out is said in the report ([`ValidationScope`]).
    fn validation_scope(&self, _est: &Log, _val: &Log) -> Result<Option<ValidationScope>, String> {
        Ok(None)
    }
    /// Calibrates the baseline plus `effects` (empty: the baseline) on `est`, predicts `val`.
    /// `parent` is the calibrated model that this one extends (the baseline plus all but the
    /// last of `effects`): the fit starts from its optimum with the new effect at its neutral
    /// value (and may try other starts), so it never ends worse on the estimation data than
    /// the model it nests.
    fn fit(&self, effects: &[&str], parent: Option<&Fit>, est: &Log, val: &Log) -> Result<Fit, String>;
    /// Signals of the validation data to correlate the residual with (inputs and candidate
    /// regressors), aligned with the fit's `measured`.
    fn regressors<'a>(&self, val: &'a Log) -> Vec<(String, Cow<'a, [f64]>)>;
    /// Physics outside the catalogue this family can test for (see [`Probe`]); none by default.
    fn probes(&self) -> &'static [Probe] {
        &[]
    }
    /// Calibrates the model of `parent` (the baseline plus `effects`) with the probe's extra
    /// physics added, starting from `parent`'s optimum; predicts `val`.
    fn fit_probe(&self, probe: &str, _effects: &[&str], _parent: &Fit, _est: &Log, _val: &Log) -> Result<Fit, String> {
        Err(format!("no probe `{probe}` in this family"))
    }
    /// Whether, with a probe found, the causes are selected again with the probe's physics in
    /// every model ([`probes::causes_beside`]): outside physics that dominates the remainder
    /// can hide a catalogue effect's gain. Only for a family whose [`Self::fit_probe`] fits any
    /// set of effects with the probe, an effect the parent lacks from its neutral value.
    fn selects_beside_probes(&self) -> bool {
        false
    }
    /// Whether a model may also be started from another model it nests than its parent (the
    /// same effects but one of the parent's, an effect that competed with the parent's in an
    /// earlier round), passed to [`Self::fit`] as `parent` with the effects reordered so that
    /// the missing one comes last. Only for a family whose fit reads the parent's values by
    /// name (the order of `effects` does not matter to its result) and depends on its start.
    fn starts_from_other_nested(&self) -> bool {
        false
    }
    /// Whether [`Self::fit`] given a `parent` that holds every effect of the model and more
    /// starts from that fit's optimum (its values by name, the extra effects left out), so
    /// that the selection can refit a model whose solver stopped in another valley than a
    /// richer model reached with its extra effect switched off ([`Self::is_off`]) or barely
    /// on. Only for a family whose fits read the parent by name and depend on their start.
    fn refits_parent_from(&self) -> bool {
        false
    }
    /// Whether `effect` ended at its neutral value in `fit` (switched off: its gain comes from
    /// refitting the rest of the model). By default to 1e-6 ([`catalogue::is_off`]); a family
    /// whose starts can lower the cost of a practically neutral effect judges by the fitted
    /// 95 % intervals instead.
    fn is_off(&self, effect: &str, fit: &Fit) -> bool {
        catalogue::is_off(self.plant(), effect, &fit.internal)
    }
    /// What the measured inputs' own error costs even a perfect model on the validation data:
    /// the output's RMS error it causes (same units as the noise floor) and how it was found,
    /// where the family can tell (`None`: not estimated). The verdict's floor is the root sum
    /// of squares of this and [`Self::noise_floor`]; the forward selection stops on the
    /// sensor floor alone.
    fn input_floor(&self, _val: &Log, _fit: &Fit) -> Option<(f64, String)> {
        None
    }
    /// What a perfect model would score on the validation data, estimated from `fit`'s
    /// validation residual (the part of the output the model already explains is no noise)
    /// and the quantization of the measured output.
    fn noise_floor(&self, _val: &Log, fit: &Fit) -> NoiseFloor {
        noise_floor_of(&fit.residual(), resolution(&fit.measured))
    }
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
    /// The verdict is `explained` when the validation RMSE is at most this multiple of the
    /// noise floor (what is left beyond the noise is then below 1.7 σ of it): clean generated
    /// logs of healthy units end at 1.0-1.7× (a simulation from logged set-points does not
    /// reproduce every detail of a bench, e.g. the EHVVA's accumulator dips).
    pub explained_ratio: f64,
    /// Forward selection stops adding effects once the remainder is this close to the floor.
    pub stop_ratio: f64,
    /// At most this many effects are combined.
    pub max_causes: usize,
    /// Where no candidate is eligible, the effect with the largest gain is still added when
    /// its gain is at least this, its z at least `resolve_z`, and it turns a remainder that is
    /// not noise into one that is (step 2 of the docs).
    pub resolve_gain_pct: f64,
    pub resolve_z: f64,
    /// Where no candidate is eligible, the effect with the largest gain is also added when it
    /// takes the estimation cost down to at most this fraction of the model's without it (it
    /// explains most of what the estimation log's fit missed) and the validation data confirm
    /// it: gain at least `min_gain_pct`, z at least `resolve_z`.
    pub confirm_est_cost_ratio: f64,
}

impl Default for Rules {
    fn default() -> Self {
        Rules {
            min_gain_pct: 5.0,
            min_z: 4.0,
            penalty_per_param: 0.01,
            nested_margin_pct: 10.0,
            explained_ratio: 2.0,
            stop_ratio: 1.5,
            max_causes: 3,
            resolve_gain_pct: 20.0,
            resolve_z: 2.33,
            confirm_est_cost_ratio: 0.5,
        }
    }
}

/// One candidate's standing.
#[derive(Clone, Debug)]
pub struct Candidate {
    pub fit: Fit,
    /// Gain over the model it extends (the baseline in the first round), % of that model's
    /// validation RMSE.
    pub gain_pct: f64,
    pub z: f64,
    pub eligible: bool,
}

/// One round of the forward selection: every remaining effect tried on top of `base`.
#[derive(Clone, Debug)]
pub struct Round {
    /// The effects already selected (the model every candidate of this round extends).
    pub base: Vec<String>,
    pub candidates: Vec<Candidate>,
    /// The effect added in this round, if any.
    pub added: Option<String>,
}

/// What the final model leaves on the validation data.
#[derive(Clone, Debug)]
pub struct Remainder {
    pub rmse: f64,
    pub ratio_to_floor: f64,
    /// Where the remainder lives (input, state, direction, regime, lag or frequency).
    pub evidence: Vec<String>,
}

/// The validation rows the diagnosis scores, when a family leaves out a regime the estimation
/// log does not hold ([`Family::validation_scope`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationScope {
    /// Rows of the validation log that are scored, in order.
    pub kept_rows: Vec<std::ops::Range<usize>>,
    /// What was left out and why, in words a calibration engineer can act on.
    pub reason: String,
    /// How many of the log's parts (`what`, e.g. `valve events`) were left out, of how many.
    pub left_out: usize,
    pub of: usize,
    pub what: &'static str,
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
    /// The first round: every catalogue effect on top of the baseline.
    pub candidates: Vec<Candidate>,
    /// The later rounds of the forward selection.
    pub rounds: Vec<Round>,
    /// `causes[0]`, or `none`.
    pub cause: String,
    /// Every effect the data need, in the order added.
    pub causes: Vec<String>,
    pub extended: Fit,
    pub gain_pct: f64,
    pub noise_floor: NoiseFloor,
    pub remainder: Remainder,
    /// `explained` or `unexplained`.
    pub verdict: String,
    /// Residual tests on the extended model's validation residual.
    pub remainder_whiteness: Whiteness,
    pub remainder_cross: Vec<CrossCheck>,
    pub remainder_grouped: Vec<GroupCheck>,
    /// Sentences for the human summary.
    pub evidence: Vec<String>,
    /// Input columns that never vary in the estimation or the validation data, with where when
    /// only one is (`duty_pct`, `u_batt_V (validation data only)`): no excitation, so what depends on them cannot be
    /// computed (the report says so instead of printing NaN or a perfect fit).
    pub unexcited: Vec<String>,
    /// The part of the validation log that was scored, when not all of it
    /// ([`Family::validation_scope`]); `validation` is then that part's name and length.
    pub validation_scope: Option<ValidationScope>,
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

/// Where the validation log's output stays well inside the span the estimation log's covers
/// (its 0.5-99.5 % quantiles short by more than a tenth of the estimation's span at either
/// end), a line saying so: the verdict judges the validation data, so physics that acts only
/// beyond their span (a travel stop the validation never reaches, a regime it never enters)
/// is fitted on the estimation data and cannot show in the verdict.
pub fn output_coverage(output: &str, est: &Log, val: &Log) -> Option<String> {
    // On at most 20 000 evenly strided samples: a warning's quantiles need no more, and a
    // 400 000-row pair then costs neither a copy of its output nor a sort of it.
    let span = |log: &Log| {
        let col = log.col(output)?;
        let stride = col.len().div_ceil(20_000).max(1);
        let mut v: Vec<f64> = col.iter().step_by(stride).copied().filter(|x| x.is_finite()).collect();
        if v.len() < 2 {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Some((at(0.005), at(0.995)))
    };
    let ((e_lo, e_hi), (v_lo, v_hi)) = (span(est)?, span(val)?);
    let width = e_hi - e_lo;
    if !(width > 0.0) {
        return None;
    }
    let short_above = e_hi - v_hi > 0.1 * width;
    let short_below = v_lo - e_lo > 0.1 * width;
    if !(short_above || short_below) {
        return None;
    }
    let sig = |x: f64| crate::numbers::sig(x, 3);
    Some(format!(
        "validation coverage: {output} spans {}..{} in the validation data and {}..{} in the estimation data (0.5-99.5 % of the samples): what acts only {} the validation's span (a stop, a regime) is fitted on the estimation data but not judged by the verdict; validate on a log that covers the estimation's span",
        sig(v_lo),
        sig(v_hi),
        sig(e_lo),
        sig(e_hi),
        match (short_below, short_above) {
            (true, true) => "on either side of",
            (false, true) => "above",
            _ => "below",
        }
    ))
}

/// Splits a borrowed log into estimation head and validation tail (`tail` fraction held out).
/// It copies the samples; a caller that owns the log uses [`Log::split_tail`], which moves them.
pub fn split_tail(log: &Log, tail: f64) -> (Log, Log) {
    log.clone().split_tail(tail)
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
    Fit { name: String, index: usize, total: usize },
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
    diagnose_in(family, Cow::Borrowed(est), val, validation_is_tail, rules, progress)
}

/// [`diagnose`] given the estimation log to keep: it is freed as soon as the last fit is done,
/// before the residual tests of the validation data (on a long record the estimation log is
/// the largest thing held then; the command line diagnoses this way).
pub fn diagnose_owned(
    family: &dyn Family,
    est: Log,
    val: &Log,
    validation_is_tail: bool,
    rules: &Rules,
    progress: &mut (dyn FnMut(&Progress) + Send),
) -> Result<Diagnosis, String> {
    diagnose_in(family, Cow::Owned(est), val, validation_is_tail, rules, progress)
}

fn diagnose_in(
    family: &dyn Family,
    est: Cow<Log>,
    val: &Log,
    validation_is_tail: bool,
    rules: &Rules,
    progress: &mut (dyn FnMut(&Progress) + Send),
) -> Result<Diagnosis, String> {
    let est_id = (est.file.clone(), est.len());
    let unexcited = unexcited_inputs(&est, val);
    let scope = family.validation_scope(&est, val)?;
    let val_part = scope.as_ref().map(|s| {
        val.select_rows(
            &s.kept_rows,
            format!(
                "{} (scored: {} of its {} {})",
                val.file,
                s.of - s.left_out,
                s.of,
                s.what
            ),
        )
    });
    let val: &Log = val_part.as_ref().unwrap_or(val);
    let coverage = output_coverage(family.output(), &est, val);
    let est = RefCell::new(Some(est));
    let start = Instant::now();
    let (tx, rx) = mpsc::channel::<Tick>();
    std::thread::scope(|s| {
        s.spawn(move || {
            let (mut name, mut index, mut iteration, mut total) = (String::new(), 0, 0, 0);
            // Ends when the fitting side has dropped every sender.
            for tick in rx {
                match tick {
                    Tick::Fit {
                        name: n,
                        index: i,
                        total: t,
                    } => (name, index, iteration, total) = (n, i, 0, t),
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
        let fit = |effects: &[&str], parent: Option<&Fit>, index: usize, total: usize| -> Result<Fit, String> {
            let _ = tx.send(Tick::Fit {
                name: Fit::label(effects),
                index,
                total,
            });
            let iterations = tx.clone();
            let held = est.borrow();
            let est = held.as_deref().ok_or("the estimation log was freed before a fit")?;
            let mut fitted =
                with_iteration_observer(Arc::new(move |_| drop(iterations.send(Tick::Iteration))), || {
                    family.fit(effects, parent, est, val)
                })?;
            // One copy of the measured validation output for all fits.
            if let Some(shared) = parent.map(|p| &p.measured) {
                if shared[..] == fitted.measured[..] {
                    fitted.measured = shared.clone();
                }
            }
            Ok(fitted)
        };
        let probe = |name: &str, effects: &[&str], parent: &Fit, index: usize, total: usize| -> Result<Fit, String> {
            let _ = tx.send(Tick::Fit {
                name: format!("probe: {name}"),
                index,
                total,
            });
            let held = est.borrow();
            let est = held.as_deref().ok_or("the estimation log was freed before a fit")?;
            family.fit_probe(name, effects, parent, est, val)
        };
        let release = || drop(est.borrow_mut().take());
        let result = selection::diagnose_fits(
            family,
            (&est_id, unexcited),
            val,
            validation_is_tail,
            rules,
            (&fit, &probe),
            &release,
        );
        drop(tx);
        let mut d = result.map_err(|e| locate_error(e, &est_id.0, est.borrow().as_deref(), val))?;
        if let Some(line) = coverage {
            d.evidence.insert(0, line);
        }
        if let Some(s) = scope {
            d.evidence.insert(0, format!("validation scope: {}", s.reason));
            d.validation_scope = Some(s);
        }
        Ok(d)
    })
}

/// A fit's error as the user must read it: which files, and which inputs never moved (the
/// usual reason a fit cannot be computed), unless the message already names the file. `est`
/// is `None` once the estimation log was freed (its inputs are then not checked).
fn locate_error(message: String, est_file: &str, est: Option<&Log>, val: &Log) -> String {
    if message.starts_with(est_file) || message.starts_with(&val.file) {
        return message;
    }
    let files = if est_file == val.file {
        est_file.to_string()
    } else {
        format!("{est_file} (validation: {})", val.file)
    };
    let unexcited = est.map(|est| unexcited_inputs(est, val)).unwrap_or_default();
    if unexcited.is_empty() {
        format!("{files}: {message}")
    } else {
        format!("{files}: {message}; inputs that never vary: {}", unexcited.join(", "))
    }
}

/// A finished round's candidates without their validation series: the report keeps their
/// figures (RMSE, gain, z, parameters), while the series of every candidate held to the end
/// would cost a copy of the validation output per fit. The model that is carried on
/// (`current`) was cloned with its series before.
fn without_series(mut candidates: Vec<Candidate>) -> Vec<Candidate> {
    for c in &mut candidates {
        c.fit.measured = Arc::from([]);
        c.fit.predicted = Vec::new();
    }
    candidates
}

/// Calibrates one model (the baseline plus the effects, extending `parent`) as fit number
/// `index` of (so far) `total`, and reports it.
type FitOne<'a> = dyn Fn(&[&str], Option<&Fit>, usize, usize) -> Result<Fit, String> + 'a;

/// Calibrates the final model plus a [`Probe`]'s physics (probe name, effects, final model) as
/// fit number `index` of `total`.
pub(super) type FitProbe<'a> = dyn Fn(&str, &[&str], &Fit, usize, usize) -> Result<Fit, String> + 'a;

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
pub(crate) mod tests;
