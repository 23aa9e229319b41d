//! The diagnosis report: JSON in the shape DATA-FORMAT.md fixes (plus evidence), and the short
//! human summary.

use serde_json::{json, Map, Value};

use super::{Diagnosis, Fit};

fn params_json(fit: &Fit) -> Value {
    let mut m = Map::new();
    for (k, v) in &fit.params {
        m.insert(k.clone(), json_number(*v));
    }
    Value::Object(m)
}

/// A calibrated model: parameters, intervals, errors and what is not good about it.
fn model_json(fit: &Fit) -> Value {
    json!({
        "effects": fit.effects,
        "params": params_json(fit),
        "ci95": ci_json(fit),
        "rmse": json_number(fit.rmse),
        "fit_pct": json_number(fit.fit_pct),
        "convergence": fit.convergence,
        "estimation_cost": json_number(fit.est_cost),
        "at_bound": fit.at_bound,
        "impossible": fit.impossible,
        "not_identifiable": fit.not_identifiable,
    })
}

fn candidate_json(c: &super::Candidate) -> Value {
    let mut v = model_json(&c.fit);
    if let Value::Object(m) = &mut v {
        m.insert("effect".into(), json!(c.fit.effect));
        m.insert("gain_pct".into(), json_number(c.gain_pct));
        m.insert("z".into(), json_number(c.z));
        m.insert("eligible".into(), json!(c.eligible));
    }
    v
}

fn ci_json(fit: &Fit) -> Value {
    let mut m = Map::new();
    for ((k, _), c) in fit.params.iter().zip(&fit.ci95) {
        m.insert(k.clone(), c.map_or(Value::Null, json_number));
    }
    Value::Object(m)
}

/// JSON has no infinity or NaN: those become null.
fn json_number(x: f64) -> Value {
    serde_json::Number::from_f64(x).map_or(Value::Null, Value::Number)
}

pub fn to_json(d: &Diagnosis) -> Value {
    let candidates: Vec<Value> = d.candidates.iter().map(candidate_json).collect();
    let rounds: Vec<Value> = d
        .rounds
        .iter()
        .map(|r| {
            json!({
                "base": r.base,
                "candidates": r.candidates.iter().map(candidate_json).collect::<Vec<_>>(),
                "added": r.added,
            })
        })
        .collect();
    let cross: Vec<Value> = d
        .cross
        .iter()
        .map(|c| json!({"signal": c.name, "max_abs": json_number(c.max_abs), "lag": c.at_lag, "band": json_number(c.band), "pass": c.pass}))
        .collect();
    let grouped: Vec<Value> = d
        .grouped
        .iter()
        .map(|g| {
            let groups: Vec<Value> = g
                .groups
                .iter()
                .map(|m| json!({"group": m.label, "samples": m.samples, "mean": json_number(m.mean), "rmse": json_number(m.rmse)}))
                .collect();
            json!({"condition": g.name, "groups": groups, "z": json_number(g.z), "pass": g.pass})
        })
        .collect();
    json!({
        "plant": d.plant.name(),
        "output": d.output,
        "formulation": d.formulation,
        "estimation": {"file": d.estimation.0, "samples": d.estimation.1},
        "validation": {"file": d.validation.0, "samples": d.validation.1, "held_out_tail": d.validation_is_tail},
        "baseline": model_json(&d.baseline),
        "residual_tests": {
            "whiteness_pass": d.whiteness.pass,
            "input_correlation_pass": d.cross.iter().all(|c| c.pass),
            "ljung_box_q": json_number(d.whiteness.ljung_box_q),
            "ljung_box_limit_99": json_number(d.whiteness.ljung_box_limit),
            "max_autocorrelation": json_number(d.whiteness.max_abs_rho),
            "max_autocorrelation_lag": d.whiteness.max_lag,
            "band_99": json_number(d.whiteness.band),
            "cross_correlation": cross,
            "grouped_by_condition_pass": d.grouped.iter().all(|g| g.pass),
            "grouped_by_condition": grouped,
        },
        "candidates": candidates,
        "selection_rounds": rounds,
        "cause": d.cause,
        "causes": d.causes,
        "extended": model_json(&d.extended),
        "gain_pct": json_number(d.gain_pct),
        "noise_floor": {"rmse": json_number(d.noise_floor.rmse), "method": d.noise_floor.method},
        "remainder": {
            "rmse": json_number(d.remainder.rmse),
            "ratio_to_floor": json_number(d.remainder.ratio_to_floor),
            "evidence": d.remainder.evidence,
            "whiteness_pass": d.remainder_whiteness.pass,
            "input_correlation_pass": d.remainder_cross.iter().all(|c| c.pass),
            "grouped_by_condition_pass": d.remainder_grouped.iter().all(|g| g.pass),
        },
        "verdict": d.verdict,
        "evidence": d.evidence,
    })
}

/// What a user reads on the terminal.
pub fn summary(d: &Diagnosis) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "plant {} — output {} — {}\nestimation: {} ({} samples)\nvalidation: {} ({} samples)\n\n",
        d.plant, d.output, d.formulation, d.estimation.0, d.estimation.1, d.validation.0, d.validation.1
    ));
    s.push_str(&format!(
        "baseline: RMSE {:.5}, fit {:.1} % ({})\n",
        d.baseline.rmse, d.baseline.fit_pct, d.baseline.convergence
    ));
    for f in d.baseline.flags() {
        s.push_str(&format!("  WARNING baseline calibration {f}\n"));
    }
    if d.baseline.fit_pct < 0.0 {
        s.push_str("  WARNING baseline fit below 0 %: worse than the output's mean\n");
    }
    s.push_str(&format!(
        "noise floor: RMSE {:.5} ({})\n",
        d.noise_floor.rmse, d.noise_floor.method
    ));
    s.push_str("what the baseline gets wrong:\n");
    for e in &d.evidence {
        s.push_str(&format!("  - {e}\n"));
    }
    s.push_str("\ncandidates (validation RMSE, gain, significance):\n");
    for c in &d.candidates {
        s.push_str(&format!(
            "  {:<22} RMSE {:>10.5}  gain {:>6.1} %  z {:>6.1}{}\n",
            c.fit.effect,
            c.fit.rmse,
            c.gain_pct,
            c.z,
            if d.causes.first() == Some(&c.fit.effect) {
                "  <- first cause"
            } else {
                ""
            }
        ));
    }
    for (i, r) in d.rounds.iter().enumerate() {
        s.push_str(&format!("\nround {} on top of {}:\n", i + 2, r.base.join(" + ")));
        for c in &r.candidates {
            s.push_str(&format!(
                "  {:<40} RMSE {:>10.5}  gain {:>6.1} %  z {:>6.1}{}\n",
                c.fit.effect,
                c.fit.rmse,
                c.gain_pct,
                c.z,
                if r.added.as_deref() == c.fit.effects.last().map(String::as_str) {
                    "  <- added"
                } else {
                    ""
                }
            ));
        }
    }
    s.push_str(&format!(
        "\ncause: {}\ncauses: {}\n",
        d.cause,
        if d.causes.is_empty() {
            "none".to_string()
        } else {
            d.causes.join(" + ")
        }
    ));
    s.push_str("extended model parameters (± 95 %):\n");
    for ((k, v), c) in d.extended.params.iter().zip(&d.extended.ci95) {
        match c {
            Some(c) => s.push_str(&format!("  {k} = {v:.4} ± {c:.4}\n")),
            None => s.push_str(&format!("  {k} = {v:.4}\n")),
        }
    }
    s.push_str(&format!(
        "gain: validation RMSE {:.5} -> {:.5} ({:.1} %), fit {:.1} % -> {:.1} %\n",
        d.baseline.rmse, d.extended.rmse, d.gain_pct, d.baseline.fit_pct, d.extended.fit_pct
    ));
    if !d.causes.is_empty() {
        for f in d.extended.flags() {
            s.push_str(&format!("  WARNING extended calibration {f}\n"));
        }
    }
    s.push_str(&format!(
        "verdict: {} (remainder RMSE {:.5} = {:.2}x the noise floor)\n",
        d.verdict, d.remainder.rmse, d.remainder.ratio_to_floor
    ));
    for e in &d.remainder.evidence {
        s.push_str(&format!("  where the remainder lives: {e}\n"));
    }
    s
}
