//! Self-contained HTML reports (`diagnose --report`, `run --report`): one page, the plots
//! inline as SVG, a small inline style sheet, no script, nothing fetched from the network.
//!
//! The diagnosis page is drawn from the report JSON (`diagnose::report::to_json`), so fields
//! the report gains (`verdict`, `causes`, `noise_floor`, `remainder`, `at_bound`,
//! `not_identifiable`) are shown when present, and any other top-level field is listed under
//! "more fields" rather than dropped.

use std::fmt::Write as _;

use serde_json::Value;

/// Text escaped for HTML element content and attribute values.
pub fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

const STYLE: &str = "
body{font-family:sans-serif;margin:0 auto;max-width:1120px;padding:16px 24px;color:#222;line-height:1.4}
h1{font-size:1.5em;margin:.2em 0}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ccc}
.verdict{border:2px solid #888;border-radius:6px;padding:10px 16px;margin:12px 0;background:#f7f7f7}
.verdict.good{border-color:#2ca02c;background:#eef8ee}.verdict.bad{border-color:#d62728;background:#fbeeee}
.verdict.found{border-color:#1f77b4;background:#eef4fa}
.verdict .big{font-size:1.4em;font-weight:bold}
table{border-collapse:collapse;margin:6px 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}
td.num{text-align:right;font-variant-numeric:tabular-nums}
.flag{color:#b00;font-weight:bold}.pass{color:#2ca02c}.fail{color:#d62728}
figure{margin:12px 0}figure svg{max-width:100%;height:auto}
pre{background:#f4f4f4;padding:8px;overflow-x:auto;font-size:.85em}
.muted{color:#666;font-size:.9em}
";

fn page(title: &str, body: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{body}</body>\n</html>\n",
        escape(title)
    )
}

fn num(v: &Value) -> String {
    match v {
        Value::Number(n) => match n.as_f64() {
            Some(x) if n.is_f64() => {
                if x != 0.0 && (x.abs() >= 1e5 || x.abs() < 1e-3) {
                    format!("{x:.4e}")
                } else {
                    format!("{x:.4}")
                }
            }
            _ => n.to_string(),
        },
        Value::Null => "n/a".into(),
        Value::String(s) => escape(s),
        Value::Bool(b) => b.to_string(),
        other => escape(&other.to_string()),
    }
}

fn strings(v: Option<&Value>) -> Vec<String> {
    v.and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .map(|x| x.as_str().map_or_else(|| x.to_string(), str::to_string))
                .collect()
        })
        .unwrap_or_default()
}

fn figures(out: &mut String, plots: &[(String, String)]) {
    for (name, svg) in plots {
        let start = svg.find("<svg").unwrap_or(0);
        let _ = writeln!(
            out,
            "<figure id=\"plot-{}\">{}<figcaption class=\"muted\">{}</figcaption></figure>",
            escape(name.trim_end_matches(".svg")),
            &svg[start..],
            escape(name)
        );
    }
}

/// A model's parameters: value, 95 % half-width and relative confidence, and flags
/// (`at_bound`, `not_identifiable`, or no confidence interval).
fn params_table(out: &mut String, model: &Value) {
    let Some(params) = model.get("params").and_then(Value::as_object) else {
        return;
    };
    let at_bound = strings(model.get("at_bound"));
    let unident = strings(model.get("not_identifiable"));
    out.push_str("<table><tr><th>parameter</th><th>value</th><th>± 95 %</th><th>relative</th><th>flags</th></tr>\n");
    for (k, v) in params {
        let ci = model.get("ci95").and_then(|c| c.get(k)).unwrap_or(&Value::Null);
        let rel = match (v.as_f64(), ci.as_f64()) {
            (Some(x), Some(c)) if x != 0.0 => format!("{:.1} %", 100.0 * c / x.abs()),
            _ => "n/a".into(),
        };
        let mut flags = Vec::new();
        if at_bound.iter().any(|b| b == k) {
            flags.push("at a bound");
        }
        if unident.iter().any(|b| b == k) {
            flags.push("not identifiable");
        }
        if ci.is_null() && model.get("ci95").is_some() {
            flags.push("no confidence interval");
        }
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{rel}</td><td class=\"flag\">{}</td></tr>",
            escape(k),
            num(v),
            num(ci),
            flags.join(", ")
        );
    }
    out.push_str("</table>\n");
    // Flags that name something other than one parameter (e.g. a ratio) are listed too.
    for (what, list) in [("at a bound", &at_bound), ("not identifiable", &unident)] {
        let others: Vec<&String> = list.iter().filter(|n| !params.contains_key(n.as_str())).collect();
        if !others.is_empty() {
            let _ = writeln!(
                out,
                "<p class=\"flag\">{what}: {}</p>",
                others.iter().map(|s| escape(s)).collect::<Vec<_>>().join(", ")
            );
        }
    }
}

/// The diagnosis page: verdict and causes first, then the evidence, the plots, the
/// parameters with their confidence and flags, the gain, the candidates, the residual tests,
/// and the terminal summary.
pub fn diagnosis_page(report: &Value, summary_text: &str, plots: &[(String, String)]) -> String {
    let get = |k: &str| report.get(k);
    let s = |k: &str| get(k).and_then(Value::as_str).unwrap_or("").to_string();
    let (plant, output, cause) = (s("plant"), s("output"), s("cause"));
    let mut causes = strings(get("causes"));
    if causes.is_empty() && !cause.is_empty() && cause != "none" {
        causes.push(cause.clone());
    }
    let verdict = get("verdict").and_then(Value::as_str).map(str::to_string);
    let mut b = String::new();
    let _ = writeln!(
        b,
        "<h1>Diagnosis: {} — output <code>{}</code></h1>",
        escape(&plant),
        escape(&output)
    );
    let _ = writeln!(
        b,
        "<p class=\"muted\">estimation: {} ({} samples); validation: {} ({} samples). {}</p>",
        escape(report.pointer("/estimation/file").and_then(Value::as_str).unwrap_or("")),
        num(report.pointer("/estimation/samples").unwrap_or(&Value::Null)),
        escape(report.pointer("/validation/file").and_then(Value::as_str).unwrap_or("")),
        num(report.pointer("/validation/samples").unwrap_or(&Value::Null)),
        escape(&s("formulation"))
    );

    // The verdict first.
    let class = match verdict.as_deref() {
        Some("explained") => "good",
        Some("unexplained") => "bad",
        _ if !causes.is_empty() => "found",
        _ => "good",
    };
    let headline = match (&verdict, causes.is_empty()) {
        (Some(v), true) => format!("verdict: {v}; no catalogue effect needed"),
        (Some(v), false) => format!("verdict: {v}; causes: {}", causes.join(", ")),
        (None, true) => "cause: none (the baseline model explains the data)".to_string(),
        (None, false) => format!("cause: {}", causes.join(", ")),
    };
    let _ = writeln!(
        b,
        "<div class=\"verdict {class}\" id=\"verdict\"><div class=\"big\">{}</div>",
        escape(&headline)
    );
    let gain = get("gain_pct").map(num).unwrap_or_default();
    let _ = writeln!(
        b,
        "<div>validation RMSE {} → {} ({} % gain); fit {} % → {} %</div>",
        num(report.pointer("/baseline/rmse").unwrap_or(&Value::Null)),
        num(report.pointer("/extended/rmse").unwrap_or(&Value::Null)),
        gain,
        num(report.pointer("/baseline/fit_pct").unwrap_or(&Value::Null)),
        num(report.pointer("/extended/fit_pct").unwrap_or(&Value::Null)),
    );
    if let Some(nf) = get("noise_floor") {
        let _ = writeln!(
            b,
            "<div>noise floor: RMSE {} ({})</div>",
            num(nf.get("rmse").unwrap_or(&Value::Null)),
            escape(nf.get("method").and_then(Value::as_str).unwrap_or("method not given"))
        );
    }
    if let Some(r) = get("remainder") {
        let _ = writeln!(
            b,
            "<div>remainder: RMSE {}, {} × the noise floor</div>",
            num(r.get("rmse").unwrap_or(&Value::Null)),
            num(r.get("ratio_to_floor").unwrap_or(&Value::Null))
        );
    }
    b.push_str("</div>\n");

    // The evidence.
    b.push_str("<h2>Evidence</h2>\n");
    let remainder_evidence = strings(report.pointer("/remainder/evidence"));
    if !remainder_evidence.is_empty() {
        b.push_str("<p>Where the remainder lives:</p><ul>\n");
        for e in &remainder_evidence {
            let _ = writeln!(b, "<li>{}</li>", escape(e));
        }
        b.push_str("</ul>\n");
    }
    let evidence = strings(get("evidence"));
    if !evidence.is_empty() {
        b.push_str("<p>What the baseline model gets wrong:</p><ul>\n");
        for e in &evidence {
            let _ = writeln!(b, "<li>{}</li>", escape(e));
        }
        b.push_str("</ul>\n");
    }
    if let Some(rt) = get("residual_tests").and_then(Value::as_object) {
        b.push_str("<table><tr><th>residual test (baseline)</th><th>result</th></tr>\n");
        for (k, v) in rt.iter().filter(|(_, v)| !v.is_array()) {
            let cell = match v {
                Value::Bool(true) => "<span class=\"pass\">pass</span>".to_string(),
                Value::Bool(false) => "<span class=\"fail\">fail</span>".to_string(),
                other => num(other),
            };
            let _ = writeln!(b, "<tr><td>{}</td><td class=\"num\">{cell}</td></tr>", escape(k));
        }
        b.push_str("</table>\n");
    }

    b.push_str("<h2>Plots</h2>\n");
    figures(&mut b, plots);

    b.push_str("<h2>Parameters</h2>\n");
    for (name, key) in [("baseline model", "baseline"), ("extended model", "extended")] {
        if let Some(m) = get(key) {
            let _ = writeln!(
                b,
                "<h3>{name}</h3><p class=\"muted\">validation RMSE {}, fit {} %</p>",
                num(m.get("rmse").unwrap_or(&Value::Null)),
                num(m.get("fit_pct").unwrap_or(&Value::Null))
            );
            params_table(&mut b, m);
        }
    }

    b.push_str("<h2>Gain and candidates</h2>\n");
    let _ = writeln!(
        b,
        "<p>gain = 100 × (baseline RMSE − extended RMSE) / baseline RMSE = <b>{gain} %</b></p>"
    );
    if let Some(cands) = get("candidates").and_then(Value::as_array) {
        b.push_str("<table><tr><th>effect</th><th>validation RMSE</th><th>fit %</th><th>gain %</th><th>z</th><th>eligible</th></tr>\n");
        for c in cands {
            let effect = c.get("effect").and_then(Value::as_str).unwrap_or("");
            let mark = if causes.iter().any(|x| x == effect) {
                " ← cause"
            } else {
                ""
            };
            let _ = writeln!(
                b,
                "<tr><td>{}{mark}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td></tr>",
                escape(effect),
                num(c.get("rmse").unwrap_or(&Value::Null)),
                num(c.get("fit_pct").unwrap_or(&Value::Null)),
                num(c.get("gain_pct").unwrap_or(&Value::Null)),
                num(c.get("z").unwrap_or(&Value::Null)),
                num(c.get("eligible").unwrap_or(&Value::Null)),
            );
        }
        b.push_str("</table>\n");
    }

    // Fields this page does not lay out are shown, not dropped.
    const SHOWN: [&str; 16] = [
        "plant",
        "output",
        "formulation",
        "estimation",
        "validation",
        "baseline",
        "residual_tests",
        "candidates",
        "cause",
        "causes",
        "verdict",
        "extended",
        "gain_pct",
        "evidence",
        "noise_floor",
        "remainder",
    ];
    if let Some(obj) = report.as_object() {
        let more: Vec<(&String, &Value)> = obj.iter().filter(|(k, _)| !SHOWN.contains(&k.as_str())).collect();
        if !more.is_empty() {
            b.push_str("<h2>More fields</h2>\n");
            for (k, v) in more {
                let _ = writeln!(
                    b,
                    "<h3>{}</h3><pre>{}</pre>",
                    escape(k),
                    escape(&serde_json::to_string_pretty(v).unwrap_or_default())
                );
            }
        }
    }
    b.push_str("<h2>Summary as printed</h2>\n");
    let _ = writeln!(b, "<pre>{}</pre>", escape(summary_text));
    page(&format!("Diagnosis: {plant} ({})", headline), &b)
}

/// The run page: the summary, then the plots.
pub fn run_page(name: &str, summary_text: &str, plots: &[(String, String)]) -> String {
    let mut b = String::new();
    let _ = writeln!(b, "<h1>Closed-loop run: scenario <code>{}</code></h1>", escape(name));
    let faults = summary_text
        .lines()
        .filter(|l| l.starts_with("faults"))
        .map(escape)
        .collect::<Vec<_>>()
        .join("<br>");
    let _ = writeln!(b, "<div class=\"verdict found\" id=\"verdict\">{faults}</div>");
    let _ = writeln!(b, "<h2>Summary</h2>\n<pre>{}</pre>", escape(summary_text));
    b.push_str("<h2>Plots</h2>\n");
    figures(&mut b, plots);
    page(&format!("Run: {name}"), &b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn new_report_fields_are_rendered_and_text_is_escaped() {
        let r = json!({
            "plant": "vacuum", "output": "x_pct", "cause": "backlash",
            "causes": ["backlash", "supply-voltage"], "verdict": "unexplained",
            "noise_floor": {"rmse": 0.14, "method": "difference <estimate>"},
            "remainder": {"rmse": 0.5, "ratio_to_floor": 3.6, "evidence": ["correlates with duty at lag 3"]},
            "baseline": {"params": {"cd": 0.7, "tau": 0.1}, "ci95": {"cd": 0.01, "tau": null}, "at_bound": ["cd"], "not_identifiable": ["At/Ab"], "rmse": 1.0, "fit_pct": 80.0},
            "gain_pct": 50.0,
            "surprise": {"k": 1}
        });
        let p = diagnosis_page(&r, "a < b", &[("fit.svg".into(), "<svg></svg>".into())]);
        assert!(p.contains("verdict: unexplained; causes: backlash, supply-voltage"));
        assert!(p.contains("difference &lt;estimate&gt;") && p.contains("a &lt; b"));
        assert!(p.contains("correlates with duty at lag 3"));
        assert!(p.contains("at a bound") && p.contains("not identifiable: At/Ab"));
        assert!(p.contains("no confidence interval"));
        assert!(p.contains("<h3>surprise</h3>"));
        assert!(!p.contains("<script") && !p.contains("http://") && !p.contains("https://"));
    }
}
