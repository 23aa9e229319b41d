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
    let candidates: Vec<Value> = d
        .candidates
        .iter()
        .map(|c| {
            json!({
                "effect": c.fit.effect,
                "params": params_json(&c.fit),
                "ci95": ci_json(&c.fit),
                "rmse": json_number(c.fit.rmse),
                "fit_pct": json_number(c.fit.fit_pct),
                "gain_pct": json_number(c.gain_pct),
                "z": json_number(c.z),
                "eligible": c.eligible,
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
        "baseline": {
            "params": params_json(&d.baseline),
            "ci95": ci_json(&d.baseline),
            "rmse": json_number(d.baseline.rmse),
            "fit_pct": json_number(d.baseline.fit_pct),
        },
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
        "cause": d.cause,
        "extended": {
            "params": params_json(&d.extended),
            "ci95": ci_json(&d.extended),
            "rmse": json_number(d.extended.rmse),
            "fit_pct": json_number(d.extended.fit_pct),
        },
        "gain_pct": json_number(d.gain_pct),
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
        "baseline: RMSE {:.5}, fit {:.1} %\n",
        d.baseline.rmse, d.baseline.fit_pct
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
            if c.fit.effect == d.cause { "  <- cause" } else { "" }
        ));
    }
    s.push_str(&format!("\ncause: {}\n", d.cause));
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
    s
}
