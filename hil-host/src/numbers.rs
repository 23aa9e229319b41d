//! Numbers as people read them: a fixed count of significant digits in text reports, JSON
//! numbers rounded the same way (no `0.009999999999999787`), and no NaN, infinity or null in a
//! report: what cannot be computed is said in words.

use serde_json::{Map, Value};

/// Significant digits of the numbers in text reports.
pub const TEXT_DIGITS: usize = 5;
/// Significant digits of the numbers in JSON reports.
pub const JSON_DIGITS: usize = 6;
/// The key under which a JSON object lists its members that could not be computed (each with
/// the reason), instead of carrying them as null.
pub const NOT_COMPUTABLE: &str = "not_computable";

/// `x` with `digits` significant digits, trailing zeros dropped: `0.01`, `123.46`, `95.1`;
/// scientific notation below 1e-4 and from 1e6 on (`1.2346e-7`). A value that is not finite
/// reads `not computable`.
pub fn sig(x: f64, digits: usize) -> String {
    let digits = digits.max(1);
    if !x.is_finite() {
        return "not computable".into();
    }
    let x = round_sig(x, digits);
    if x == 0.0 {
        return "0".into();
    }
    let e = x.abs().log10().floor() as i32;
    if (-4..6).contains(&e) {
        let decimals = (digits as i32 - 1 - e).max(0) as usize;
        trim_fraction(format!("{x:.decimals$}"))
    } else {
        let s = format!("{:.*e}", digits - 1, x);
        match s.split_once('e') {
            Some((mantissa, exp)) => format!("{}e{exp}", trim_fraction(mantissa.to_string())),
            None => s,
        }
    }
}

/// [`sig`] with [`TEXT_DIGITS`].
pub fn num(x: f64) -> String {
    sig(x, TEXT_DIGITS)
}

/// A percentage with one decimal (`88.1 %`), or why it is missing.
pub fn pct(x: f64) -> String {
    if x.is_finite() {
        let s = format!("{x:.1}");
        if s == "-0.0" {
            "0.0 %".into()
        } else {
            s + " %"
        }
    } else {
        "not computable".into()
    }
}

fn trim_fraction(s: String) -> String {
    if !s.contains('.') {
        return s;
    }
    let t = s.trim_end_matches('0').trim_end_matches('.');
    if t == "-0" {
        "0".into()
    } else {
        t.to_string()
    }
}

/// `x` rounded to `digits` significant digits (through its decimal form, so that the shortest
/// representation of the result is short: `0.009999999999999787` becomes `0.01`). Values that
/// are not finite are returned as they are.
pub fn round_sig(x: f64, digits: usize) -> f64 {
    if !x.is_finite() || x == 0.0 {
        return x;
    }
    format!("{:.*e}", digits.max(1) - 1, x).parse().unwrap_or(x)
}

/// A JSON number rounded to [`JSON_DIGITS`], or null when `x` is not finite (which
/// [`tidy_json`] turns into a `not_computable` entry).
pub fn json_num(x: f64) -> Value {
    serde_json::Number::from_f64(round_sig(x, JSON_DIGITS)).map_or(Value::Null, Value::Number)
}

/// Makes a JSON report readable and free of nulls: every float is rounded to [`JSON_DIGITS`]
/// significant digits; a null member of an object is removed and named, with the reason
/// `not computable from this data` (unless the object already gives one), in that object's
/// [`NOT_COMPUTABLE`] map; a null inside an array becomes the string `not computable`.
pub fn tidy_json(v: &mut Value) {
    match v {
        Value::Number(n) => {
            if let (true, Some(x)) = (n.is_f64(), n.as_f64()) {
                *v = json_num(x);
            }
        }
        Value::Array(items) => {
            for item in items.iter_mut() {
                if item.is_null() {
                    *item = Value::String("not computable".into());
                } else {
                    tidy_json(item);
                }
            }
        }
        Value::Object(map) => {
            let nulls: Vec<String> = map
                .iter()
                .filter(|(_, x)| x.is_null())
                .map(|(k, _)| k.clone())
                .collect();
            for k in &nulls {
                map.remove(k);
            }
            for item in map.values_mut() {
                tidy_json(item);
            }
            if !nulls.is_empty() {
                let entry = map.entry(NOT_COMPUTABLE).or_insert_with(|| Value::Object(Map::new()));
                if let Value::Object(reasons) = entry {
                    for k in nulls {
                        reasons
                            .entry(k)
                            .or_insert_with(|| Value::String("not computable from this data".into()));
                    }
                }
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits_without_float_noise() {
        assert_eq!(sig(0.009999999999999787, 5), "0.01");
        assert_eq!(sig(95.123456, 5), "95.123");
        assert_eq!(sig(203.5, 5), "203.5");
        assert_eq!(sig(-3.2, 5), "-3.2");
        assert_eq!(sig(1234567.0, 4), "1.235e6");
        assert_eq!(sig(0.00001234567, 4), "1.235e-5");
        assert_eq!(sig(0.0, 4), "0");
        assert_eq!(sig(-1e-20, 4), "-1e-20");
        assert_eq!(sig(99999.7, 5), "100000");
        assert_eq!(sig(f64::NAN, 4), "not computable");
        assert_eq!(sig(f64::NEG_INFINITY, 4), "not computable");
        assert_eq!(pct(-0.01), "0.0 %");
        assert_eq!(pct(f64::NAN), "not computable");
    }

    #[test]
    fn json_is_rounded_and_nulls_are_named() {
        let mut v = serde_json::json!({
            "a": 0.009999999999999787,
            "n": 12,
            "nested": {"x": null, "y": [1.23456789, null]},
            "z": null,
            "not_computable": {"z": "no excitation in duty_pct"},
        });
        tidy_json(&mut v);
        let text = serde_json::to_string(&v).unwrap();
        assert!(!text.contains("null"), "{text}");
        assert_eq!(v["a"], serde_json::json!(0.01));
        assert_eq!(v["n"], serde_json::json!(12));
        assert_eq!(v["nested"]["y"][0], serde_json::json!(1.23457));
        assert_eq!(v["nested"]["y"][1], "not computable");
        assert_eq!(v["nested"]["not_computable"]["x"], "not computable from this data");
        // A reason given by the report is kept.
        assert_eq!(v["not_computable"]["z"], "no excitation in duty_pct");
        assert!(v.get("z").is_none());
    }
}
