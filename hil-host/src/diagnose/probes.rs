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
    /// Fitted only where the final model's validation RMSE is above
    /// [`Rules::explained_ratio`] times the verdict's floor (the sensor's and the logged
    /// inputs' own error, [`Family::input_floor`]): a probe that refits the whole model
    /// (the EHVVA's every valve event, a second or so on a long bench pair) runs where the
    /// remainder's size already says something is missing, not on every unit.
    pub only_above_floor: bool,
}

/// Fits every probe of `family` on top of `current` (the baseline plus `selected`), as fits
/// `index` of `total` (both advanced). Returns the probes found, each as (what is missing, the
/// sentence for the evidence and the remainder), and those the estimation data confirm and
/// the validation does not ([`Probed::pending`]); the probes not needed or not fitted are
/// reported in `evidence`, the found ones too.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    family: &dyn Family,
    rules: &Rules,
    selected: &[&str],
    current: &Fit,
    (val, floor_rmse): (&Log, f64),
    fit_probe: &FitProbe,
    (index, total): (&mut usize, &mut usize),
    evidence: &mut Vec<String>,
) -> Probed {
    let (mut found, mut pending) = (Vec::new(), Vec::new());
    let above_floor = current.rmse > rules.explained_ratio * floor_rmse;
    let probes: Vec<&Probe> = family
        .probes()
        .iter()
        .filter(|p| {
            let run = above_floor || !p.only_above_floor;
            if !run {
                evidence.push(format!(
                    "probe `{}` not fitted: the remainder (RMSE {:.4}) is within {} times the noise floor {:.4}",
                    p.name, current.rmse, rules.explained_ratio, floor_rmse
                ));
            }
            run
        })
        .collect();
    *total += probes.len();
    for probe in probes {
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
                // As the selection's confirmed gain (step 2): a large gain whose z a remainder
                // full of other structure holds under `min_z` (a spring beside unmodelled
                // friction: 43 % at z 3.4; a duty delay beside a clearance: 50 % at z 3.0)
                // counts where the estimation data confirm it, a time only at its size.
                let confirmed = (probe.min_samples.is_none() || large)
                    && gain_pct >= rules.resolve_gain_pct
                    && z >= rules.resolve_z
                    && p.est_cost <= rules.confirm_est_cost_ratio * current.est_cost;
                // A time the estimation data pin down counts where the validation data agree
                // (a gain at z > 0): its 95 % interval clears a sample period and the
                // estimation cost falls by `min_gain_pct`. A coarse quantization that
                // dominates the validation remainder hides a real delay's gain there (the
                // EVVT's 1 deg phase steps: 30-50 ms command delays fitted within 20 %, ±1.5 ms,
                // the estimation cost 10-16 % lower, 0.7-4.3 % on validation at z 0.5-3.9);
                // healthy units fit no delay (0-2 ms, at the bound).
                let pinned = match (probe.min_samples, p.params.last(), p.ci95.last()) {
                    (Some(samples), Some((_, v)), Some(Some(ci))) if large => {
                        v - ci >= samples * val.dt_s
                            && p.est_cost <= (1.0 - rules.min_gain_pct / 100.0) * current.est_cost
                            && gain_pct > 0.0
                            && z > 0.0
                    }
                    _ => false,
                };
                if (z >= rules.min_z && counts) || confirmed || pinned {
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
                        on_causes: selected.iter().map(|c| c.to_string()).collect(),
                    });
                } else if probe.min_samples.is_none()
                    && family.selects_beside_probes()
                    && p.est_cost <= rules.confirm_est_cost_ratio * current.est_cost
                {
                    evidence.push(format!(
                        "probe `{}` ({}) takes the estimation cost to {:.2}x the model's, but gains {gain_pct:.1} % (z = {z:.1}) on validation: tried with the causes selected beside it where no probe is found",
                        probe.name,
                        values.join(", "),
                        p.est_cost / current.est_cost
                    ));
                    pending.push(Found {
                        probe: *probe,
                        sentence: String::new(),
                        fit: p,
                        on_causes: selected.iter().map(|c| c.to_string()).collect(),
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
    // The probe that explains most first: the causes are selected beside it, and two probes
    // of one family can describe the same remainder (a long ripple and a spring).
    found.sort_by(|a, b| a.fit.rmse.total_cmp(&b.fit.rmse));
    evidence.extend(found.iter().map(|f| f.sentence.clone()));
    pending.sort_by(|a, b| a.fit.est_cost.total_cmp(&b.fit.est_cost));
    Probed { found, pending }
}

/// What [`run`] found.
pub(super) struct Probed {
    /// The probes that found their physics, the one that explains most first.
    pub found: Vec<Found>,
    /// Probes that take the estimation cost to at most [`Rules::confirm_est_cost_ratio`] of
    /// the final model's and do not gain on validation (non-time probes of a family that
    /// selects beside probes, [`Family::selects_beside_probes`], only; the lowest
    /// estimation cost first): outside physics whose model extrapolates badly while a catalogue
    /// effect it hid is missing (a lift growing with temperature hid a direction-dependent
    /// delay: the estimation cost fell 13x, the validation RMSE rose 20 %). Where the family
    /// selects beside probes, the causes are selected beside such a probe and the two models
    /// compared ([`judge_beside`]).
    pub pending: Vec<Found>,
}

/// A probe of [`Probed::pending`] with the causes selected beside it (`with_probe`: the probe
/// fitted with them), against `reference`, the best catalogue model (the selection's, or the
/// same causes without the probe): found where it gains by the selection's rules (gain
/// `min_gain_pct` at z `min_z`, or `resolve_gain_pct` at z `resolve_z` where its estimation
/// cost is at most `confirm_est_cost_ratio` of the reference's). Returns it as found, with
/// the evidence's sentence, or the sentence why not.
pub(super) fn judge_beside(
    family: &dyn Family,
    rules: &Rules,
    pending: &Found,
    causes: &[&str],
    with_probe: Fit,
    reference: &Fit,
) -> Result<Found, String> {
    let gain_pct = 100.0 * (reference.rmse - with_probe.rmse) / reference.rmse.max(f64::MIN_POSITIVE);
    let z = improvement_z_of(reference, &with_probe);
    let values: Vec<String> = with_probe
        .params
        .iter()
        .filter(|(n, _)| !reference.params.iter().any(|(r, _)| r == n))
        .filter(|(n, _)| {
            !causes
                .iter()
                .any(|c| super::catalogue::params(family.plant(), c).iter().any(|(p, _)| p == n))
        })
        .map(|(n, v)| format!("{n} = {}", crate::numbers::sig(*v, 3)))
        .collect();
    let beside = if causes.is_empty() {
        String::new()
    } else {
        format!(" with {} beside it", causes.join(" + "))
    };
    let significant = (gain_pct >= rules.min_gain_pct && z >= rules.min_z)
        || (gain_pct >= rules.resolve_gain_pct
            && z >= rules.resolve_z
            && with_probe.est_cost <= rules.confirm_est_cost_ratio * reference.est_cost);
    if significant {
        Ok(Found {
            probe: pending.probe,
            sentence: format!(
                "{} ({}){beside} lowers the validation RMSE from {:.4} (the catalogue's best) to {:.4} ({gain_pct:.1} %, z = {z:.1}): physics outside the catalogue",
                pending.probe.what,
                values.join(", "),
                reference.rmse,
                with_probe.rmse
            ),
            fit: with_probe,
            on_causes: causes.iter().map(|c| c.to_string()).collect(),
        })
    } else {
        Err(format!(
            "probe `{}`{beside}: {gain_pct:.1} % (z = {z:.1}) over the catalogue's best (validation RMSE {:.4}): not needed",
            pending.probe.name, reference.rmse
        ))
    }
}

/// A probe that found its physics: the probe, the evidence's sentence and its fit on top of
/// the final model.
pub(super) struct Found {
    pub probe: Probe,
    pub sentence: String,
    pub fit: Fit,
    /// The causes `fit` holds beside the probe (empty: the probe on the baseline).
    /// [`causes_beside`] starts from it on the baseline rather than fitting it again, and
    /// where it tries these causes beside the probe it keeps whichever of its own fit and
    /// `fit` ends lower on the estimation data: the same model, two starts.
    pub on_causes: Vec<String>,
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

/// Causes beside outside physics ([`Family::selects_beside_probes`]): with `found`, the
/// forward selection is run again with the probe's physics in every model, from the probe
/// fitted on the `baseline`: each catalogue effect not yet selected is fitted with the probe
/// and the selected effects and added by the selection's rules over the probe's model so far
/// (gain ≥ `min_gain_pct`, z ≥ `min_z`; of two nested effects the simpler unless the richer
/// adds `nested_margin_pct` points of the probe-on-baseline RMSE; the richer replaces a
/// selected simpler one only by that margin), until none is eligible or the model is at the
/// noise floor `floor_rmse` (`stop_ratio`, as step 2's stop). Its causes replace the
/// first selection's: outside physics that dominates the remainder hides a catalogue effect's
/// gain (a spring of a few hundred N/m over a 0.2 m travel leaves a Coulomb friction's 10-20 N
/// a few per cent of the remainder), and a catalogue effect can take part of the outside
/// physics (friction takes a duty delay's lag into a dead band). Returns the causes and the
/// probe's fit with them, or `None` where the probe cannot be fitted on the baseline (the
/// first selection stands).
#[allow(clippy::too_many_arguments)]
pub(super) fn causes_beside(
    family: &dyn Family,
    rules: &Rules,
    baseline: &Fit,
    found: &Found,
    fit_probe: &FitProbe,
    floor_rmse: f64,
    (index, total): (&mut usize, &mut usize),
    evidence: &mut Vec<String>,
) -> Option<(Vec<&'static str>, Fit)> {
    let on_baseline = if found.on_causes.is_empty() {
        Ok(found.fit.clone())
    } else {
        *total += 1;
        *index += 1;
        fit_probe(found.probe.name, &[], baseline, *index, *total)
    };
    let mut base = match on_baseline {
        Ok(f) => f,
        Err(err) => {
            evidence.push(format!(
                "the probe `{}` could not be fitted on the baseline: {err}",
                found.probe.name
            ));
            return None;
        }
    };
    let reference = base.rmse.max(f64::MIN_POSITIVE);
    let mut selected: Vec<&'static str> = Vec::new();
    // As the selection's floor stop (step 2): once the model is at the floor, only the effects
    // that held evidence in the round that reached it are tried (a duty delay's probe beside a
    // clearance at 1.1x the floor, friction eligible next to it: friction then gained nothing
    // and the pressure direction, without evidence before, took 10 % of the noise).
    let mut evidence_left: Vec<&'static str> = Vec::new();
    for _ in 0..family.effects().len() {
        let at_floor = !selected.is_empty() && base.rmse <= rules.stop_ratio * floor_rmse;
        if at_floor && evidence_left.is_empty() {
            evidence.push(format!(
                "beside the probe `{}`, the model with {} is at the noise floor (validation RMSE {:.4}, floor {:.4}): the selection stops",
                found.probe.name,
                selected.join(" + "),
                base.rmse,
                floor_rmse
            ));
            break;
        }
        let nested_in_selected = |e: &str| {
            family
                .nested()
                .iter()
                .any(|(simple, rich)| selected.contains(rich) && e == *simple)
        };
        let remaining: Vec<&'static str> = family
            .effects()
            .iter()
            .copied()
            .filter(|e| !selected.contains(e) && !nested_in_selected(e))
            .filter(|e| !at_floor || evidence_left.contains(e))
            .collect();
        *total += remaining.len();
        let mut candidates: Vec<(&'static str, Fit, f64, f64)> = Vec::new();
        for e in remaining {
            *index += 1;
            // A richer effect replaces its selected simpler one (the model holds one of them).
            let mut effects: Vec<&str> = selected
                .iter()
                .copied()
                .filter(|s| !family.nested().iter().any(|(simple, rich)| *rich == e && s == simple))
                .collect();
            effects.push(e);
            let same_as_found = effects.len() == found.on_causes.len()
                && effects.iter().all(|e| found.on_causes.iter().any(|c| c == e));
            match fit_probe(found.probe.name, &effects, &base, *index, *total) {
                Ok(f) => {
                    // The probe's own fit on these causes started from the selection's model;
                    // this one from the probe's model with fewer causes. A fit that ends in a
                    // worse valley than a known point of the same model is not its optimum
                    // (a supply voltage fitted beside a travel stop at 0.53 where the probe on
                    // the supply-voltage model had reached 0.30: friction was then named to
                    // close the gap).
                    let f = if same_as_found && found.fit.est_cost < f.est_cost {
                        found.fit.clone()
                    } else {
                        f
                    };
                    let gain_pct = 100.0 * (base.rmse - f.rmse) / base.rmse.max(f64::MIN_POSITIVE);
                    let z = improvement_z_of(&base, &f);
                    candidates.push((e, f, gain_pct, z));
                }
                Err(err) => evidence.push(format!(
                    "`{e}` beside the probe `{}` could not be fitted: {err}",
                    found.probe.name
                )),
            }
        }
        // As in the selection: an effect that ends switched off gains only by refitting the rest
        // of the model, and every other effect must beat the best such refit by the same rules.
        let offs: Vec<bool> = candidates.iter().map(|c| family.is_off(c.0, &c.1)).collect();
        let mut refuted: Vec<&'static str> = Vec::new();
        let refit = candidates
            .iter()
            .zip(&offs)
            .filter(|(c, off)| **off && c.1.rmse.is_finite() && c.1.rmse < base.rmse)
            .map(|(c, _)| c)
            .min_by(|a, b| a.1.rmse.total_cmp(&b.1.rmse));
        // The effects whose evidence line says why (the others get the common one below).
        let mut said: Vec<&'static str> = Vec::new();
        for ((e, f, gain_pct, _), off) in candidates.iter().zip(&offs) {
            if *off {
                if *gain_pct >= rules.min_gain_pct {
                    evidence.push(format!(
                        "`{e}` beside the probe `{}` ends at its neutral value (switched off); its {gain_pct:.1} % come from refitting the rest of the model: not named",
                        found.probe.name
                    ));
                    said.push(e);
                }
                refuted.push(e);
            } else if let Some((_, r, _, _)) = refit {
                let gain_ref = 100.0 * (r.rmse - f.rmse) / r.rmse.max(f64::MIN_POSITIVE);
                let z_ref = improvement_z_of(r, f);
                if gain_ref < rules.min_gain_pct || z_ref < rules.min_z {
                    evidence.push(format!(
                        "`{e}` beside the probe `{}` gains {gain_ref:.1} % (z = {z_ref:.1}) over the same model refitted without it (validation RMSE {:.4}): not named",
                        found.probe.name, r.rmse
                    ));
                    said.push(e);
                    refuted.push(e);
                }
            }
        }
        let eligible =
            |c: &&(&str, Fit, f64, f64)| c.2 >= rules.min_gain_pct && c.3 >= rules.min_z && !refuted.contains(&c.0);
        for (e, f, gain_pct, z) in candidates.iter().filter(|c| !eligible(c) && !said.contains(&c.0)) {
            evidence.push(format!(
                "`{e}` beside the probe `{}`: {gain_pct:.1} % (z = {z:.1}, validation RMSE {:.4}): not named",
                found.probe.name, f.rmse
            ));
        }
        let Some(mut best) = candidates
            .iter()
            .filter(eligible)
            .min_by(|a, b| a.1.rmse.total_cmp(&b.1.rmse))
        else {
            break;
        };
        for (simple, rich) in family.nested() {
            if best.0 != *rich {
                continue;
            }
            let margin_over = |rmse: f64| 100.0 * (rmse - best.1.rmse) / reference;
            if let Some(s) = candidates.iter().filter(eligible).find(|c| c.0 == *simple) {
                if margin_over(s.1.rmse) < rules.nested_margin_pct {
                    evidence.push(format!(
                        "beside the probe `{}`, `{rich}` nests `{simple}` and adds {:.1} points (validation RMSE {:.4} against {:.4}), under the {} point margin: the simpler `{simple}`",
                        found.probe.name,
                        margin_over(s.1.rmse),
                        best.1.rmse,
                        s.1.rmse,
                        rules.nested_margin_pct
                    ));
                    best = s;
                }
            } else if selected.contains(simple) && margin_over(base.rmse) < rules.nested_margin_pct {
                evidence.push(format!(
                    "beside the probe `{}`, `{rich}` adds {:.1} points over the selected `{simple}`, under the {} point margin: `{simple}` kept",
                    found.probe.name,
                    margin_over(base.rmse),
                    rules.nested_margin_pct
                ));
                return Some((selected, base));
            }
        }
        let (e, fit, gain_pct, z) = best;
        evidence_left = candidates
            .iter()
            .filter(|c| c.0 != *e && !refuted.contains(&c.0))
            .filter(|c| eligible(c) || (c.2 >= rules.min_gain_pct && c.3 >= rules.resolve_z))
            .map(|c| c.0)
            .collect();
        evidence.push(format!(
            "beside the probe `{}`, `{e}` lowers the validation RMSE from {:.4} to {:.4} ({gain_pct:.1} %, z = {z:.1}): named",
            found.probe.name, base.rmse, fit.rmse
        ));
        selected.retain(|s| !family.nested().iter().any(|(simple, rich)| rich == e && s == simple));
        selected.push(e);
        base = fit.clone();
    }
    // As after the selection (step 2): a cause added early that the final model fitted back to
    // its neutral value is not named, the later causes describing what it took at first (a
    // clearance taken for a Dahl friction's pre-sliding lag beside a duty delay, then friction
    // added and the clearance fitted to 0).
    let off = super::selection::switched_off(family, &selected, &base);
    for (c, round) in &off {
        evidence.push(format!(
            "beside the probe `{}`, `{c}` is not named: it was added in round {round} but the final model fitted it back to its neutral value",
            found.probe.name
        ));
    }
    selected.retain(|c| !off.iter().any(|(o, _)| o == c));
    Some((selected, base))
}
