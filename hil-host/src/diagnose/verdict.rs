//! The verdict (step 9 of docs/diagnosis.md): the floor the remainder is judged against (the
//! sensor's noise and what the logged inputs' own error costs), the residual tests of the
//! baseline and of the model named, and `explained` or `unexplained` with where the remainder
//! lives.
use super::outside::Outside;
use super::selection::Selection;
use super::*;

/// The diagnosis of the model `s` selected and of what the probes found (`outside`); reads
/// the validation log only.
pub(super) fn verdict(
    family: &dyn Family,
    (est_id, unexcited): (&(String, usize), Vec<String>),
    val: &Log,
    validation_is_tail: bool,
    rules: &Rules,
    s: Selection,
    outside: Outside,
) -> Diagnosis {
    let Selection {
        baseline,
        current,
        selected,
        mut floor,
        rounds,
        mut evidence,
        lags,
        dt_res,
        ..
    } = s;
    let Outside {
        found: probes_found,
        input_floor_of_current,
    } = outside;
    // The first round's candidates are the report's table; the later rounds follow it.
    let mut rounds = rounds.into_iter();
    let candidates = rounds.next().map(|r| r.candidates).unwrap_or_default();
    let rounds: Vec<Round> = rounds.collect();
    // What the logged inputs' own error costs a perfect model joins the floor of the verdict
    // (after the selection, which stops on the sensor floor: the causes do not depend on it).
    let input_floor = input_floor_of_current.unwrap_or_else(|| family.input_floor(val, &current));
    if let Some((input_rmse, how)) = input_floor {
        if input_rmse > 0.0 {
            floor = NoiseFloor {
                rmse: floor.rmse.hypot(input_rmse),
                method: format!("{}; {how}; floor = their root sum of squares", floor.method),
            };
        }
    }
    // Made after the fits, not held through them (the families' caches they read hold the
    // baseline from its fit).
    let regressors = family.regressors(val);
    let e0 = baseline.residual();
    let tests = ResidualTests::run(&e0, &regressors, lags, floor.rmse);
    tests.describe("baseline residual", &mut evidence);
    let causes: Vec<String> = selected.iter().map(|s| s.to_string()).collect();
    let extended = current;
    let gain_pct = if causes.is_empty() {
        0.0
    } else {
        100.0 * (baseline.rmse - extended.rmse) / baseline.rmse
    };
    if causes.is_empty() {
        evidence.push(format!(
            "no extension lowers the validation RMSE by ≥ {} % with z ≥ {}: cause `none`",
            rules.min_gain_pct, rules.min_z
        ));
    }
    let e_ext = extended.residual();
    let rest = ResidualTests::run(&e_ext, &regressors, lags, floor.rmse);
    let ratio = if floor.rmse > 0.0 {
        extended.rmse / floor.rmse
    } else {
        f64::INFINITY
    };
    let ratio_txt = if ratio.is_finite() {
        format!("{ratio:.2}×")
    } else {
        "not comparable with".to_string()
    };
    let material = rest.material_failures();
    let explained = ratio <= rules.explained_ratio && material.is_empty() && probes_found.is_empty();
    // An output that never moves on the validation data: the floor estimated from it is 0 and
    // no model can be judged on it, so nothing about missing physics can be said either.
    let flat = extended.measured_is_constant();
    let mut where_ = Vec::new();
    if flat {
        where_.push(format!(
            "{} does not vary on the validation data: nothing can be judged from it, inside the catalogue or outside it; record a log where the inputs move the actuator",
            family.output()
        ));
    } else if !explained {
        where_ = probes_found.iter().map(|f| f.sentence.clone()).collect();
        where_.extend(locate(&rest, &e_ext, floor.rmse, dt_res));
        if where_.is_empty() {
            where_.push(format!(
                "the remainder is {ratio_txt} the noise floor with no single input, state or regime it follows; look at the residual plot for what the catalogue does not describe"
            ));
        }
    }
    let verdict = if explained { "explained" } else { "unexplained" }.to_string();
    evidence.push(if flat {
        format!("verdict unexplained: {}", where_[0])
    } else if explained {
        format!(
            "verdict explained: the remainder (RMSE {:.4}) is {ratio_txt} the noise floor {:.4}, without material structure",
            extended.rmse, floor.rmse
        )
    } else {
        format!(
            "verdict unexplained: the remainder (RMSE {:.4}) is {ratio_txt} the noise floor {:.4}{}{}: physics outside the catalogue{}",
            extended.rmse,
            floor.rmse,
            if material.is_empty() {
                String::new()
            } else {
                format!(", with structure ({})", material.join("; "))
            },
            if probes_found.is_empty() {
                String::new()
            } else {
                format!(
                    "; a probe finds {}",
                    probes_found.iter().map(|f| f.probe.what).collect::<Vec<_>>().join(", ")
                )
            },
            if causes.is_empty() {
                String::new()
            } else {
                format!(" beyond {}", causes.join(" + "))
            }
        )
    });
    for (what, f) in
        std::iter::once(("baseline", &baseline)).chain((!causes.is_empty()).then_some(("extended", &extended)))
    {
        for flag in f.flags() {
            evidence.push(format!("{what} calibration: {flag}"));
        }
    }
    Diagnosis {
        plant: family.plant(),
        output: family.output().to_string(),
        formulation: family.formulation().to_string(),
        estimation: est_id.clone(),
        validation: (val.file.clone(), val.len()),
        validation_is_tail,
        baseline,
        whiteness: tests.white,
        cross: tests.cross,
        grouped: tests.grouped,
        candidates,
        rounds,
        cause: causes.first().cloned().unwrap_or_else(|| "none".into()),
        causes,
        extended,
        gain_pct,
        noise_floor: floor.clone(),
        remainder: Remainder {
            rmse: e_ext.iter().map(|v| v * v).sum::<f64>().sqrt() / (e_ext.len().max(1) as f64).sqrt(),
            ratio_to_floor: ratio,
            evidence: where_,
        },
        verdict,
        remainder_whiteness: rest.white,
        remainder_cross: rest.cross,
        remainder_grouped: rest.grouped,
        evidence,
        unexcited,
        validation_scope: None,
    }
}
