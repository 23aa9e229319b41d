//! Probes for physics outside the catalogue (step 8 of docs/diagnosis.md): after the forward
//! selection, each of the family's probes is fitted on top of the final model and judged by
//! the selection's rules.
use super::{improvement_z_of, Family, Fit, FitProbe, Rules};
use crate::log::Log;

/// A test for physics outside the catalogue: after the selection, the final model with this
/// physics added is fitted; if it beats the final model by the selection's rules, the verdict
/// is `unexplained` and `what` says what is missing. A probe is never a cause (the catalogue
/// changes only through DATA-FORMAT.md): it says where the remainder lives when the remainder
/// alone is too close to the floor to show it (a small delay absorbed into the parameters).
#[derive(Clone, Copy, Debug)]
pub struct Probe {
    /// Short name (the fit's label, `probe: <name>`).
    pub name: &'static str,
    /// What is missing, in a calibration engineer's words.
    pub what: &'static str,
    /// Where the probe's physics is a time (a delay, s): the value, in sample periods of the
    /// validation log, from which it counts, significance given (z >= min_z), whatever its
    /// RMSE gain (the gain is small next to a coarse quantization that dominates the
    /// remainder; a delay of a sample or more is physics, shorter is within the sampled
    /// model's own hold, and a gain with a shorter one comes from the refit's other
    /// parameters). `None`: the gain rule only.
    pub min_samples: Option<f64>,
}

/// Fits every probe of `family` on top of `current` (the baseline plus `selected`), as fits
/// `index` of `total` (both advanced). Returns the probes found, each as (what is missing, the
/// sentence for the evidence and the remainder); the probes not needed or not fitted are
/// reported in `evidence`, the found ones too.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    family: &dyn Family,
    rules: &Rules,
    selected: &[&str],
    current: &Fit,
    val: &Log,
    fit_probe: &FitProbe,
    (index, total): (&mut usize, &mut usize),
    evidence: &mut Vec<String>,
) -> Vec<Found> {
    let mut found = Vec::new();
    *total += family.probes().len();
    for probe in family.probes() {
        *index += 1;
        match fit_probe(probe.name, selected, current, *index, *total) {
            Ok(p) => {
                let gain_pct = 100.0 * (current.rmse - p.rmse) / current.rmse;
                let z = improvement_z_of(current, &p);
                let values: Vec<String> = p
                    .params
                    .iter()
                    .skip(current.params.len())
                    .map(|(n, v)| format!("{n} = {}", crate::numbers::sig(*v, 3)))
                    .collect();
                let large = match (probe.min_samples, p.params.last()) {
                    (Some(samples), Some((_, v))) if p.params.len() > current.params.len() => *v >= samples * val.dt_s,
                    _ => false,
                };
                // A time counts on its size alone: a refit that gains with a negligible delay
                // (a vacuum friction unit: 1.8 µs, 7.8 % from the refit's other parameters)
                // found another optimum of the catalogue model, not the probe's physics.
                let counts = if probe.min_samples.is_some() {
                    large
                } else {
                    gain_pct >= rules.min_gain_pct
                };
                if z >= rules.min_z && counts {
                    found.push(Found {
                        probe: *probe,
                        sentence: format!(
                            "{} ({}) lowers the validation RMSE from {:.4} to {:.4} ({gain_pct:.1} %, z = {z:.1}): physics outside the catalogue",
                            probe.what,
                            values.join(", "),
                            current.rmse,
                            p.rmse
                        ),
                        fit: p,
                    });
                } else {
                    evidence.push(format!(
                        "probe `{}`: {gain_pct:.1} % (z = {z:.1}, {}): not needed",
                        probe.name,
                        values.join(", ")
                    ));
                }
            }
            Err(e) => evidence.push(format!("probe `{}` could not be fitted: {e}", probe.name)),
        }
    }
    evidence.extend(found.iter().map(|f| f.sentence.clone()));
    found
}

/// A probe that found its physics: the probe, the evidence's sentence and its fit on top of
/// the final model.
pub(super) struct Found {
    pub probe: Probe,
    pub sentence: String,
    pub fit: Fit,
}

/// With a probe found, is the one cause the selection named still needed? The probe is
/// fitted on top of the baseline too: if the cause does not gain under the selection's rules
/// over that fit, the cause was taking part of the missing physics (friction takes a transport
/// delay's lag into a dead band) and is not named: returns the evidence's sentence saying so.
/// A probe that cannot be fitted on the baseline keeps the cause.
pub(super) fn cause_not_needed(
    rules: &Rules,
    cause: &str,
    found: &Found,
    baseline: &Fit,
    fit_probe: &FitProbe,
    (index, total): (&mut usize, &mut usize),
) -> Option<String> {
    *total += 1;
    *index += 1;
    let without = fit_probe(found.probe.name, &[], baseline, *index, *total).ok()?;
    let gain_pct = 100.0 * (without.rmse - found.fit.rmse) / without.rmse;
    let z = improvement_z_of(&without, &found.fit);
    (z < rules.min_z || gain_pct < rules.min_gain_pct).then(|| {
        format!(
            "`{cause}` is not named: with the probe `{}` fitted on the baseline too (validation RMSE {:.4}), `{cause}` gains {gain_pct:.1} % (z = {z:.1}) on top of it, short of the selection's rules: it took part of the missing physics",
            found.probe.name, without.rmse
        )
    })
}
