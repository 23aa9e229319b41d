//! The valve the conditions are fitted on: the unit's own from `diagnose`
//! ([`unit_valve`]), tried against the paper's ([`identify_unit_or_paper`]).

use model_core::ehvva::EhvvaParams;
use serde_json::{json, Value};

use super::{identify, identify_on, Identified};
use crate::diagnose::ehvva::Events;
use crate::log::{Log, Plant};
use crate::lsq::LsqOptions;

/// Which valve [`identify_unit_or_paper`] kept, and why: the summed cost (lift residual) of
/// the conditions' joint fits on each (infinite where a condition could not be fitted).
#[derive(Clone, Copy, Debug)]
pub struct ValveChoice {
    pub unit_cost: f64,
    pub paper_cost: f64,
    pub kept_unit: bool,
}

impl ValveChoice {
    /// One line for the report.
    pub fn text(&self) -> String {
        let cost = |c: f64| {
            if c.is_finite() {
                crate::numbers::sig(c, 4)
            } else {
                "none (a condition could not be fitted)".to_string()
            }
        };
        format!(
            "lift residual of the conditions' fits (sum of costs): {} on the unit's valve, {} on the paper's: the {} valve's tables kept",
            cost(self.unit_cost),
            cost(self.paper_cost),
            if self.kept_unit { "unit's" } else { "paper's" }
        )
    }

    /// A cost for JSON: the number, or why there is none.
    pub fn cost_json(c: f64) -> Value {
        if c.is_finite() {
            json!(c)
        } else {
            json!("not computable: a condition could not be fitted on this valve")
        }
    }
}

impl Identified {
    /// The conditions' summed cost (their joint fits' lift residual).
    pub fn total_cost(&self) -> f64 {
        self.conditions.iter().map(|c| c.cost).sum()
    }
}

/// [`identify_on`] the unit's valve and [`identify`] on the paper's; the tables whose fits
/// reproduce the measured lift better (smaller summed cost) are kept. The unit's valve wins
/// wherever the diagnosis found it (10-2 600x smaller on generated units); the paper's is the
/// fallback when that fit went wrong (a unit knob on a bound, a valve unlike the model).
pub fn identify_unit_or_paper(
    unit: &EhvvaParams,
    sets: &[Events],
    opts: &LsqOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Identified, ValveChoice), String> {
    // A valve on which a condition cannot be fitted at all (it never opens there) loses.
    let on_unit = identify_on(unit, sets, opts, &mut |k, n| progress(k, 2 * n));
    let on_paper = identify(sets, opts, &mut |k, n| progress(n + k, 2 * n));
    let cost = |r: &Result<Identified, String>| r.as_ref().map_or(f64::INFINITY, Identified::total_cost);
    let (unit_cost, paper_cost) = (cost(&on_unit), cost(&on_paper));
    let kept_unit = on_unit.is_ok() && !(paper_cost < unit_cost);
    let choice = ValveChoice {
        unit_cost,
        paper_cost,
        kept_unit,
    };
    let kept = if kept_unit { on_unit } else { on_paper };
    Ok((kept?, choice))
}

/// The unit's own valve, as `diagnose` fitted it, for [`identify_on`].
#[derive(Clone, Debug)]
pub struct UnitValve {
    /// The extended model's valve with the delay and Cd effects at gain 1 (the per-condition
    /// tables carry the measured dependences as they are); the snubbing zone stays the fit's.
    pub params: EhvvaParams,
    /// The cause `diagnose` named (`none` for none) and the effect gains of its fit.
    pub cause: String,
    pub gains: Vec<(String, f64)>,
    /// The unit knobs of the fit (spring, preload, friction, mass, areas, flow paths).
    pub unit_values: Vec<(String, f64)>,
    /// `explained` or `unexplained`: whether that model reaches the noise floor.
    pub verdict: String,
}

impl UnitValve {
    /// The named effects' gains, `name value, ...` (3 decimals).
    pub fn gains_text(&self) -> String {
        let g: Vec<String> = self.gains.iter().map(|(k, v)| format!("{k} {v:.3}")).collect();
        g.join(", ")
    }

    /// One paragraph for the report: the valve the tables were identified on.
    pub fn text(&self) -> String {
        let values: Vec<String> = self
            .unit_values
            .iter()
            .map(|(k, v)| format!("{k} {}", crate::numbers::sig(*v, 4)))
            .collect();
        let cause = if self.cause == "none" {
            "no extension named".to_string()
        } else {
            format!("extension `{}` ({})", self.cause, self.gains_text())
        };
        format!(
            "valve: the unit's, as diagnose fitted it ({cause}; verdict {}): {}\n",
            self.verdict,
            values.join(", ")
        )
    }

    /// The same as JSON: `cause`, `gains`, `verdict`, `params` (the unit knobs).
    pub fn json(&self) -> Value {
        let obj = |v: &[(String, f64)]| Value::Object(v.iter().map(|(k, x)| (k.clone(), json!(x))).collect());
        json!({
            "from": "diagnose",
            "cause": self.cause,
            "gains": obj(&self.gains),
            "verdict": self.verdict,
            "params": obj(&self.unit_values),
        })
    }
}

/// `diagnose` on the EHVVA logs (the second log as validation data, else the first one's last
/// 30 %) and the valve of its extended model: a baseline without the named effect absorbs it
/// into wrong unit values (a supply-pressure-dependent delay into τp and the main valve's
/// area, seen on a generated unit: the main valve on its 40 mm² bound against 10.3).
pub fn unit_valve(logs: &[Log]) -> Result<UnitValve, String> {
    use crate::diagnose::{self, Rules};
    let family = diagnose::family_for(Plant::Ehvva)?;
    let (est, val, tail) = match logs {
        [a, b, ..] => (a.clone(), b.clone(), false),
        [a] => {
            let (e, v) = diagnose::split_tail(a, 0.3);
            (e, v, true)
        }
        [] => return Err("no EHVVA log".into()),
    };
    let d = diagnose::diagnose(family.as_ref(), &est, &val, tail, &Rules::default(), &mut |_| {})
        .map_err(|e| format!("diagnose ehvva ({}): {e}", est.file))?;
    let mut params = crate::diagnose::ehvva::params_from_fit(&d.extended.internal)
        .map_err(|e| format!("diagnose ehvva ({}): {e}", est.file))?;
    params.effect_viscosity = 1.0;
    params.effect_pressure_delay = 1.0;
    params.effect_direction_delay = 1.0;
    let (gains, unit_values) = d
        .extended
        .params
        .iter()
        .cloned()
        .partition(|(k, _)| k.ends_with("_gain") && k != "td_temperature_gain");
    Ok(UnitValve {
        params,
        cause: d.cause.clone(),
        gains,
        unit_values,
        verdict: d.verdict.clone(),
    })
}
