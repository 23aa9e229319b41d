//! The diagnosis report: JSON in the shape DATA-FORMAT.md fixes (plus evidence), and the short
//! human summary.
//!
//! Numbers read as people write them (hil_host::numbers: 5 significant digits in text, JSON
//! rounded to 6). A number that cannot be computed is never NaN, infinity, null or a perfect
//! score by accident: the text says `not computable (why)`, the JSON leaves the member out and
//! names it with the reason in the object's `not_computable` map. The cases: an output that
//! does not vary on the validation data (no excitation: fit % is 0/0), a baseline that already
//! matches exactly (gain % is 0/0), a candidate whose fit failed, a parameter at a bound or not
//! identifiable (no 95 % interval).

use serde_json::{json, Map, Value};

use super::{Candidate, Diagnosis, Fit};
use crate::numbers::{json_num, num, pct, sig, NOT_COMPUTABLE};

/// A JSON object whose numbers that cannot be computed go to its `not_computable` map.
#[derive(Default)]
struct Obj {
    map: Map<String, Value>,
    missing: Map<String, Value>,
}

impl Obj {
    fn num(&mut self, key: &str, x: f64, why: Option<&str>) -> &mut Self {
        match why {
            Some(reason) => self.missing(key, reason),
            None if x.is_finite() => {
                self.map.insert(key.into(), json_num(x));
            }
            None => self.missing(key, "not computable from this data"),
        }
        self
    }
    fn missing(&mut self, key: &str, reason: &str) {
        self.missing.insert(key.into(), Value::String(reason.into()));
    }
    fn put(&mut self, key: &str, v: Value) -> &mut Self {
        self.map.insert(key.into(), v);
        self
    }
    fn done(&mut self) -> Value {
        let mut map = std::mem::take(&mut self.map);
        if !self.missing.is_empty() {
            map.insert(NOT_COMPUTABLE.into(), Value::Object(std::mem::take(&mut self.missing)));
        }
        Value::Object(map)
    }
}

/// Why the numbers of a diagnosis cannot be computed, where they cannot.
struct Why {
    /// Fit % (and so the comparison of fits) is undefined: the output does not vary.
    fit: Option<String>,
    /// The same, short, for the lines after the warning that gives `fit` in full.
    fit_short: Option<&'static str>,
    /// Gain % is undefined: the baseline's validation RMSE is zero (or the fit % reason).
    gain: Option<String>,
}

fn why(d: &Diagnosis) -> Why {
    let fit = d.baseline.measured_is_constant().then(|| {
        let mut s = format!("{} does not vary on the validation data", d.output);
        if !d.unexcited.is_empty() {
            s += &format!(": no excitation in {}", d.unexcited.join(", "));
        }
        s
    });
    let gain = match &fit {
        Some(f) => Some(f.clone()),
        None if !(d.baseline.rmse > 0.0) => Some("the baseline's validation RMSE is 0".into()),
        None => None,
    };
    let fit_short = fit.as_ref().map(|_| "no excitation, see the warning above");
    Why { fit, gain, fit_short }
}

/// The error of a candidate whose fit failed (the diagnosis keeps it as a parameter named
/// `error: ...`), if it failed.
fn failed(fit: &Fit) -> Option<String> {
    if fit.rmse.is_finite() {
        return None;
    }
    Some(
        fit.params
            .iter()
            .find_map(|(k, _)| k.strip_prefix("error: "))
            .map_or_else(|| "the fit failed".into(), |e| format!("the fit failed: {e}")),
    )
}

const NO_CI: &str = "at a bound or not identifiable from this data";

fn params_json(fit: &Fit) -> (Value, Value) {
    let mut params = Obj::default();
    let mut ci = Obj::default();
    for ((k, v), c) in fit.params.iter().zip(&fit.ci95) {
        if k.starts_with("error: ") {
            continue;
        }
        params.num(k, *v, None);
        match c {
            Some(c) => ci.num(k, *c, None),
            None => ci.num(k, f64::NAN, Some(NO_CI)),
        };
    }
    (params.done(), ci.done())
}

fn fit_json(fit: &Fit, w: &Why, obj: &mut Obj) {
    let (params, ci) = params_json(fit);
    obj.put("params", params)
        .put("ci95", ci)
        .put("effects", json!(fit.effects))
        .put("convergence", json!(fit.convergence))
        .put("at_bound", json!(fit.at_bound))
        .put("impossible", json!(fit.impossible))
        .put("not_identifiable", json!(fit.not_identifiable));
    obj.num("estimation_cost", fit.est_cost, None);
    match failed(fit) {
        Some(e) => {
            obj.put("error", Value::String(e.clone()));
            obj.num("rmse", f64::NAN, Some(&e)).num("fit_pct", f64::NAN, Some(&e));
        }
        None => {
            obj.num("rmse", fit.rmse, None)
                .num("fit_pct", fit.fit_pct, w.fit.as_deref());
        }
    }
}

fn candidate_json(c: &Candidate, w: &Why) -> Value {
    let mut o = Obj::default();
    o.put("effect", json!(c.fit.effect));
    fit_json(&c.fit, w, &mut o);
    match failed(&c.fit) {
        Some(e) => o.num("gain_pct", f64::NAN, Some(&e)),
        None => o.num("gain_pct", c.gain_pct, w.gain.as_deref()),
    };
    let z_why = (c.z == f64::INFINITY).then_some("unbounded: the candidate wins every block by the same margin");
    o.num("z", c.z, z_why).put("eligible", json!(c.eligible));
    o.done()
}

pub fn to_json(d: &Diagnosis) -> Value {
    let w = why(d);
    let candidates: Vec<Value> = d.candidates.iter().map(|c| candidate_json(c, &w)).collect();
    let rounds: Vec<Value> = d
        .rounds
        .iter()
        .map(|r| {
            json!({
                "base": r.base,
                "candidates": r.candidates.iter().map(|c| candidate_json(c, &w)).collect::<Vec<_>>(),
                "added": r.added,
            })
        })
        .collect();
    let cross: Vec<Value> = d
        .cross
        .iter()
        .map(|c| {
            let mut o = Obj::default();
            o.put("signal", json!(c.name))
                .num("max_abs", c.max_abs, None)
                .put("lag", json!(c.at_lag))
                .num("band", c.band, None)
                .put("pass", json!(c.pass));
            o.done()
        })
        .collect();
    let grouped: Vec<Value> = d
        .grouped
        .iter()
        .map(|g| {
            let groups: Vec<Value> = g
                .groups
                .iter()
                .map(|m| {
                    let mut o = Obj::default();
                    o.put("group", json!(m.label))
                        .put("samples", json!(m.samples))
                        .num("mean", m.mean, None)
                        .num("rmse", m.rmse, None);
                    o.done()
                })
                .collect();
            let mut o = Obj::default();
            o.put("condition", json!(g.name))
                .put("groups", Value::Array(groups))
                .num("z", g.z, None)
                .put("pass", json!(g.pass));
            o.done()
        })
        .collect();
    let mut baseline = Obj::default();
    fit_json(&d.baseline, &w, &mut baseline);
    let mut extended = Obj::default();
    fit_json(&d.extended, &w, &mut extended);
    let mut tests = Obj::default();
    tests
        .put("whiteness_pass", json!(d.whiteness.pass))
        .put("input_correlation_pass", json!(d.cross.iter().all(|c| c.pass)))
        .num("ljung_box_q", d.whiteness.ljung_box_q, None)
        .num("ljung_box_limit_99", d.whiteness.ljung_box_limit, None)
        .num("max_autocorrelation", d.whiteness.max_abs_rho, None)
        .put("max_autocorrelation_lag", json!(d.whiteness.max_lag))
        .num("band_99", d.whiteness.band, None)
        .put("cross_correlation", Value::Array(cross))
        .put("grouped_by_condition_pass", json!(d.grouped.iter().all(|g| g.pass)))
        .put("grouped_by_condition", Value::Array(grouped));
    let mut top = Obj::default();
    top.put("plant", json!(d.plant.name()))
        .put("output", json!(d.output))
        .put("formulation", json!(d.formulation))
        .put("estimation", json!({"file": d.estimation.0, "samples": d.estimation.1}))
        .put("validation", {
            let mut v =
                json!({"file": d.validation.0, "samples": d.validation.1, "held_out_tail": d.validation_is_tail});
            // The part scored, when a regime the estimation log never holds was left out.
            if let Some(s) = &d.validation_scope {
                v["scope"] = json!({
                    "left_out": s.left_out,
                    "of": s.of,
                    "unit": s.what,
                    "kept_rows": s.kept_rows.iter().map(|r| [r.start, r.end]).collect::<Vec<_>>(),
                    "reason": s.reason,
                });
            }
            v
        })
        .put("baseline", baseline.done())
        .put("residual_tests", tests.done())
        .put("candidates", Value::Array(candidates))
        .put("selection_rounds", Value::Array(rounds))
        .put("cause", json!(d.cause))
        .put("causes", json!(d.causes))
        .put("extended", extended.done());
    let mut floor = Obj::default();
    floor
        .num("rmse", d.noise_floor.rmse, None)
        .put("method", json!(d.noise_floor.method));
    let mut remainder = Obj::default();
    remainder
        .num("rmse", d.remainder.rmse, None)
        .num("ratio_to_floor", d.remainder.ratio_to_floor, None)
        .put("evidence", json!(d.remainder.evidence))
        .put("whiteness_pass", json!(d.remainder_whiteness.pass))
        .put(
            "input_correlation_pass",
            json!(d.remainder_cross.iter().all(|c| c.pass)),
        )
        .put(
            "grouped_by_condition_pass",
            json!(d.remainder_grouped.iter().all(|g| g.pass)),
        );
    top.put("noise_floor", floor.done())
        .put("remainder", remainder.done())
        .put("verdict", json!(d.verdict));
    // With cause `none` the gain is 0 by definition (DATA-FORMAT.md), computable or not.
    let gain_why = if d.cause == "none" { None } else { w.gain.as_deref() };
    top.num("gain_pct", d.gain_pct, gain_why)
        .put("evidence", json!(d.evidence))
        .put("unexcited_inputs", json!(d.unexcited));
    top.done()
}

/// `not computable (why)`.
fn not_computable(why: &str) -> String {
    format!("not computable ({why})")
}

/// What a user reads on the terminal.
pub fn summary(d: &Diagnosis) -> String {
    let w = why(d);
    let fit_text = |f: &Fit| match (failed(f), w.fit_short) {
        (Some(e), _) => not_computable(&e),
        (None, Some(why)) => not_computable(why),
        (None, None) => pct(f.fit_pct),
    };
    let mut s = String::new();
    s.push_str(&format!(
        "plant {} — output {} — {}\nestimation: {} ({} samples)\nvalidation: {} ({} samples)\n\n",
        d.plant, d.output, d.formulation, d.estimation.0, d.estimation.1, d.validation.0, d.validation.1
    ));
    if let Some(why) = &w.fit {
        s.push_str(&format!("warning: nothing can be diagnosed from these data: {why}\n\n"));
    }
    s.push_str(&format!(
        "baseline: RMSE {}, fit {} ({})\n",
        num(d.baseline.rmse),
        fit_text(&d.baseline),
        d.baseline.convergence
    ));
    for f in d.baseline.flags() {
        s.push_str(&format!("  WARNING baseline calibration {f}\n"));
    }
    if d.baseline.fit_pct < 0.0 && d.baseline.fit_pct.is_finite() {
        s.push_str("  WARNING baseline fit below 0 %: worse than the output's mean\n");
    }
    s.push_str(&format!(
        "noise floor: RMSE {} ({})\n",
        num(d.noise_floor.rmse),
        d.noise_floor.method
    ));
    s.push_str("what the baseline gets wrong:\n");
    for e in &d.evidence {
        s.push_str(&format!("  - {e}\n"));
    }
    s.push_str("\ncandidates (validation RMSE, gain, significance):\n");
    for c in &d.candidates {
        let mark = if d.causes.first() == Some(&c.fit.effect) {
            "  <- first cause"
        } else {
            ""
        };
        match failed(&c.fit) {
            Some(e) => s.push_str(&format!("  {:<22} {}\n", c.fit.effect, not_computable(&e))),
            None => {
                let gain = match &w.gain {
                    Some(_) => "n/a".to_string(),
                    None => pct(c.gain_pct),
                };
                let z = if c.z == f64::INFINITY {
                    "unbounded".to_string()
                } else {
                    format!("{:.1}", c.z)
                };
                s.push_str(&format!(
                    "  {:<22} RMSE {:>10}  gain {:>8}  z {:>6}{mark}\n",
                    c.fit.effect,
                    num(c.fit.rmse),
                    gain,
                    z
                ));
            }
        }
    }
    if let Some(why) = w.fit_short.or(w.gain.as_deref()) {
        s.push_str(&format!("  (gain {})\n", not_computable(why)));
    }
    for (i, r) in d.rounds.iter().enumerate() {
        s.push_str(&format!("\nround {} on top of {}:\n", i + 2, r.base.join(" + ")));
        for c in &r.candidates {
            s.push_str(&format!(
                "  {:<40} RMSE {:>10}  gain {:>8}  z {:>6.1}{}\n",
                c.fit.effect,
                num(c.fit.rmse),
                pct(c.gain_pct),
                c.z,
                if c.eligible && r.added.is_some() && r.added.as_deref().is_some_and(|a| c.fit.effect.ends_with(a)) {
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
    let mut no_ci = Vec::new();
    for ((k, v), c) in d.extended.params.iter().zip(&d.extended.ci95) {
        match c {
            Some(c) => s.push_str(&format!("  {k} = {} ± {}\n", num(*v), sig(*c, 3))),
            None => {
                s.push_str(&format!("  {k} = {}\n", num(*v)));
                no_ci.push(k.as_str());
            }
        }
    }
    if !no_ci.is_empty() {
        s.push_str(&format!("  (no 95 % interval for {}: {NO_CI})\n", no_ci.join(", ")));
    }
    match (w.fit_short, &w.gain) {
        (Some(why), _) => s.push_str(&format!(
            "gain: validation RMSE {} -> {}, fit and gain {}\n",
            num(d.baseline.rmse),
            num(d.extended.rmse),
            not_computable(why)
        )),
        (None, Some(why)) if d.cause != "none" => s.push_str(&format!(
            "gain: {}, fit {} -> {}\n",
            not_computable(why),
            fit_text(&d.baseline),
            fit_text(&d.extended)
        )),
        _ => s.push_str(&format!(
            "gain: validation RMSE {} -> {} ({}), fit {} -> {}\n",
            num(d.baseline.rmse),
            num(d.extended.rmse),
            pct(d.gain_pct),
            fit_text(&d.baseline),
            fit_text(&d.extended)
        )),
    }
    if !d.causes.is_empty() {
        for f in d.extended.flags() {
            s.push_str(&format!("  WARNING extended calibration {f}\n"));
        }
    }
    let ratio = if d.remainder.ratio_to_floor.is_finite() {
        format!("{:.2}x the noise floor", d.remainder.ratio_to_floor)
    } else {
        "the noise floor is 0: ratio not computable".to_string()
    };
    s.push_str(&format!(
        "verdict: {} (remainder RMSE {} = {ratio})\n",
        d.verdict,
        num(d.remainder.rmse)
    ));
    for e in &d.remainder.evidence {
        s.push_str(&format!("  where the remainder lives: {e}\n"));
    }
    s
}
