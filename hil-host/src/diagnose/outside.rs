//! The step after the forward selection (step 8 of docs/diagnosis.md): the family's probes for
//! physics outside the catalogue are fitted on top of the model selected ([`probes::run`]),
//! and beside a probe that is found the causes are selected again with its physics in every
//! model, or a single cause is dropped that the probe's physics make unnecessary.
use super::selection::Selection;
use super::{probes, Family, Fit, FitOne, FitProbe, Rules};
use crate::log::Log;

/// What the probes' step hands to the verdict.
pub(super) struct Outside {
    /// The probes found: each makes the verdict `unexplained`, whatever the remainder's size.
    pub(super) found: Vec<probes::Found>,
    /// The input floor ([`Family::input_floor`]) computed here on the model the selection
    /// ended with, kept for the verdict while that model stays the one named (`None`: not
    /// computed, or the model changed).
    pub(super) input_floor_of_current: Option<Option<(f64, String)>>,
}

/// Runs the family's probes on the model `s` selected and, beside a probe found (or one the
/// estimation data confirm and the validation does not), the causes again; `s` ends with the
/// causes named and their model.
pub(super) fn probe_step(
    family: &dyn Family,
    val: &Log,
    rules: &Rules,
    (fit, fit_probe): (&FitOne, &FitProbe),
    s: &mut Selection,
) -> Result<Outside, String> {
    // Physics outside the catalogue (`probes::run`): a probe found makes the verdict
    // `unexplained`, whatever the remainder's size.
    // A probe run only above the floor (`Probe::only_above_floor`) is judged against the floor
    // the verdict will use, the logged inputs' own error included (computed only where the
    // sensor floor alone would let it run): a valve near its force balance misses by more than
    // the sensor's noise and is explained by that, not by outside physics.
    // The input floor computed here is kept for the verdict where `current` stays the model
    // it was computed on (on a 400 000-row EHVVA pair it is five simulations of the
    // validation events, 0.3 s).
    let mut input_floor_of_current: Option<Option<(f64, String)>> = None;
    // An output that does not vary on the validation data leaves nothing to diagnose (the
    // report says so): a probe would meet it exactly (the vacuum's travel stop at the constant
    // level, a z without bound) and name physics where the data hold none.
    if s.current.measured_is_constant() {
        s.evidence.push(format!(
            "probes not fitted: {} does not vary on the validation data",
            family.output()
        ));
        return Ok(Outside {
            found: Vec::new(),
            input_floor_of_current,
        });
    }
    let probe_floor = if family.probes().iter().any(|p| p.only_above_floor)
        && s.current.rmse > rules.explained_ratio * s.floor.rmse
    {
        let input = family.input_floor(val, &s.current);
        let rmse = input
            .as_ref()
            .map_or(s.floor.rmse, |(input_rmse, _)| s.floor.rmse.hypot(*input_rmse));
        input_floor_of_current = Some(input);
        rmse
    } else {
        s.floor.rmse
    };
    let probes::Probed {
        found: mut probes_found,
        pending,
    } = probes::run(
        family,
        rules,
        &s.selected,
        &s.current,
        (val, probe_floor),
        fit_probe,
        (&mut s.index, &mut s.total),
        &mut s.evidence,
    );

    // Next to outside physics, the causes are selected again with the probe's physics in every
    // model (families whose probe fits take any effects); else a single cause is kept only if
    // it still gains with the probe's physics fitted on the baseline too.
    let mut beside = probes_found
        .first()
        .filter(|_| family.selects_beside_probes())
        .and_then(|found| {
            probes::causes_beside(
                family,
                rules,
                &s.baseline,
                found,
                fit_probe,
                s.floor.rmse,
                (&mut s.index, &mut s.total),
                &mut s.evidence,
            )
        })
        .map(|(causes, _)| causes);
    // The catalogue model of `beside`'s causes, where it was fitted to judge a pending probe.
    let mut catalogue_of_beside: Option<Fit> = None;
    // A probe the estimation data confirm and the validation does not: its model may lack a
    // catalogue effect it hid; judged with the causes selected beside it against the best
    // catalogue model (`probes::judge_beside`).
    if let Some(pending) = pending
        .first()
        .filter(|_| probes_found.is_empty() && family.selects_beside_probes())
    {
        if let Some((causes, with_probe)) = probes::causes_beside(
            family,
            rules,
            &s.baseline,
            pending,
            fit_probe,
            s.floor.rmse,
            (&mut s.index, &mut s.total),
            &mut s.evidence,
        ) {
            let catalogue = if causes == s.selected {
                s.baseline.clone()
            } else {
                catalogue_model(fit, &causes, s)?
            };
            let reference = if causes == s.selected || s.current.rmse <= catalogue.rmse {
                &s.current
            } else {
                &catalogue
            };
            match probes::judge_beside(family, rules, pending, &causes, with_probe, reference) {
                Ok(found) => {
                    s.evidence.push(found.sentence.clone());
                    probes_found.push(found);
                    if causes != s.selected {
                        catalogue_of_beside = Some(catalogue);
                    }
                    beside = Some(causes);
                }
                Err(sentence) => s.evidence.push(sentence),
            }
        }
    }
    if let Some(causes) = beside {
        if causes != s.selected {
            let said = |c: &[&str]| {
                if c.is_empty() {
                    "none".to_string()
                } else {
                    c.join(" + ")
                }
            };
            s.evidence.push(format!(
                "beside the probe's physics the causes are {} (the selection without it: {})",
                said(&causes),
                said(&s.selected)
            ));
            input_floor_of_current = None;
            s.current = match catalogue_of_beside {
                Some(c) => c,
                None => catalogue_model(fit, &causes, s)?,
            };
            s.selected = causes;
        }
    } else if let ([cause], Some(found)) = (s.selected.as_slice(), probes_found.first()) {
        if let Some(sentence) = probes::cause_not_needed(
            rules,
            cause,
            found,
            &s.baseline,
            fit_probe,
            (&mut s.index, &mut s.total),
        ) {
            s.evidence.push(sentence);
            s.selected.clear();
            input_floor_of_current = None;
            s.current = s.baseline.clone();
        }
    }
    Ok(Outside {
        found: probes_found,
        input_floor_of_current,
    })
}

/// The catalogue model of `causes` (without the probe's physics): the baseline extended by
/// one cause at a time, each fit starting from the one before.
fn catalogue_model(fit: &FitOne, causes: &[&str], s: &mut Selection) -> Result<Fit, String> {
    let mut model = s.baseline.clone();
    for k in 1..=causes.len() {
        s.total += 1;
        s.index += 1;
        model = fit(&causes[..k], Some(&model), s.index, s.total)?;
    }
    Ok(model)
}
