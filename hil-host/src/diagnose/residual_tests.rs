//! The residual tests of a model's validation residual (whiteness, correlation with the inputs
//! and states, grouping by operating condition), judged against the noise floor, and where the
//! remainder lives in words a calibration engineer can act on (`remainder.evidence`).

use std::borrow::Cow;

use crate::residuals::{cross_check, group_check, rmse, whiteness, CrossCheck, GroupCheck, Whiteness};

/// Structure a part of the residual must account for to matter: half the noise floor (RMS).
const MATERIAL_SHARE: f64 = 0.5;

/// The residual tests of one model's validation residual, judged against the noise floor: a
/// test fails when its statistic is significant (99 %) *and* the structure it finds is material,
/// i.e. accounts for more than half the noise floor's RMS. On oversampled, quantized or
/// closed-loop data every model short of the truth leaves statistically significant structure;
/// what a calibration engineer needs is whether it matters next to the sensor's own noise.
pub(super) struct ResidualTests {
    pub(super) white: Whiteness,
    pub(super) cross: Vec<CrossCheck>,
    pub(super) grouped: Vec<GroupCheck>,
    pub(super) floor: f64,
    pub(super) rmse: f64,
}

impl ResidualTests {
    pub(super) fn run(e: &[f64], regressors: &[(String, Cow<[f64]>)], lags: usize, floor: f64) -> Self {
        let rmse_e = rmse(e);
        let excess = (rmse_e * rmse_e - floor * floor).max(0.0).sqrt();
        let mut white = whiteness(e, lags);
        // Colour that accounts for less than the material share beyond the noise is immaterial.
        white.pass = white.pass || excess <= 1.5 * MATERIAL_SHARE * floor;
        // Structure is material when it accounts for more than the material share of the floor
        // and the residual exceeds the floor by as much (what a perfect model leaves may have
        // structure of its own, e.g. an equation-error formulation's filter artefacts).
        let small = excess <= MATERIAL_SHARE * floor;
        let mut cross: Vec<CrossCheck> = regressors.iter().map(|(n, u)| cross_check(n, e, u, lags)).collect();
        for c in &mut cross {
            c.pass = c.pass || small || c.max_abs * rmse_e <= MATERIAL_SHARE * floor;
        }
        let mut grouped: Vec<GroupCheck> = regressors.iter().map(|(n, u)| group_check(n, e, u)).collect();
        for g in &mut grouped {
            let all = g.groups.iter().map(|m| m.samples).sum::<usize>().max(1) as f64;
            let mean = g.groups.iter().map(|m| m.mean * m.samples as f64).sum::<f64>() / all;
            // The RMS the group means account for.
            let between = (g
                .groups
                .iter()
                .map(|m| (m.mean - mean).powi(2) * m.samples as f64)
                .sum::<f64>()
                / all)
                .sqrt();
            g.pass = g.pass || small || between <= MATERIAL_SHARE * floor;
        }
        ResidualTests {
            white,
            cross,
            grouped,
            floor,
            rmse: rmse_e,
        }
    }

    /// The material failures in a few words each (cross-correlation and grouping: the colour
    /// alone is judged by the ratio to the floor).
    pub(super) fn material_failures(&self) -> Vec<String> {
        let mut out = Vec::new();
        for c in self.cross.iter().filter(|c| !c.pass) {
            out.push(format!("follows {}", c.name));
        }
        for g in self.grouped.iter().filter(|g| !g.pass) {
            out.push(format!("differs by {}", g.name));
        }
        out
    }

    pub(super) fn describe(&self, what: &str, evidence: &mut Vec<String>) {
        let w = &self.white;
        if w.pass {
            evidence.push(format!(
                "{what}: no material colour (Ljung-Box Q = {:.1}, limit {:.1}; RMSE {:.4} against a floor of {:.4})",
                w.ljung_box_q, w.ljung_box_limit, self.rmse, self.floor
            ));
        } else {
            evidence.push(format!(
                "{what} is not white: Ljung-Box Q = {:.1} > {:.1}, largest autocorrelation {:.2} at lag {} (band ±{:.3}); RMSE {:.4} against a floor of {:.4}",
                w.ljung_box_q, w.ljung_box_limit, w.max_abs_rho, w.max_lag, w.band, self.rmse, self.floor
            ));
        }
        for c in self.cross.iter().filter(|c| !c.pass) {
            evidence.push(format!(
                "{what} correlates with {} ({:.2} at lag {}, band ±{:.3})",
                c.name, c.max_abs, c.at_lag, c.band
            ));
        }
        for g in self.grouped.iter().filter(|g| !g.pass) {
            let means: Vec<String> = g
                .groups
                .iter()
                .map(|m| format!("{} {:+.4} (RMSE {:.4}, {} samples)", m.label, m.mean, m.rmse, m.samples))
                .collect();
            evidence.push(format!(
                "{what}: mean differs by {} (z = {:.1}): {}",
                g.name,
                g.z,
                means.join("; ")
            ));
        }
    }
}

/// At which lag a remainder follows a signal, for [`locate`]. A slow signal (a set-point held
/// through each event, an oil temperature) correlates alike at every lag of the window, and its
/// largest value falls on the window's edge by chance: that is its level, not a timing, and
/// said so. A peak on the edge of a correlation that falls towards lag 0 is a lag at least
/// that long.
fn lag_words(c: &CrossCheck, dt_s: f64) -> String {
    let half = (c.correlation.len() / 2) as isize;
    let at = |lag: isize| c.correlation.get((half + lag) as usize).copied().unwrap_or(0.0);
    let peak = at(c.at_lag);
    let on_edge = half > 0 && c.at_lag.abs() == half;
    // Every lag of the window within a fifth of the peak, of its sign.
    let flat = half > 0 && (-half..=half).all(|k| at(k) * peak.signum() >= 0.8 * peak.abs());
    let window = secs(half as f64 * dt_s);
    if flat {
        return format!(
            ", alike at every lag within ±{half} samples = ±{window}: it follows the signal's level, not its timing"
        );
    }
    let lag_s = c.at_lag as f64 * dt_s;
    let beyond = if on_edge {
        " or more (the edge of the ±{half}-sample window searched)".replace("{half}", &half.to_string())
    } else {
        String::new()
    };
    if c.at_lag == 0 {
        ", at no lag".to_string()
    } else if c.at_lag > 0 {
        format!(", the signal leading by {} samples = {}{beyond}", c.at_lag, secs(lag_s))
    } else {
        format!(
            ", the signal lagging by {} samples = {}{beyond}",
            -c.at_lag,
            secs(-lag_s)
        )
    }
}

/// Where a remainder lives, in words a calibration engineer can act on: the signals it follows
/// (and at which lag), the regimes where its mean or its size differs, and its colour (the lag
/// of its strongest self-correlation and its dominant period).
pub(super) fn locate(t: &ResidualTests, e: &[f64], floor: f64, dt_s: f64) -> Vec<String> {
    let mut out = Vec::new();
    let mut cross: Vec<&CrossCheck> = t.cross.iter().filter(|c| !c.pass).collect();
    cross.sort_by(|a, b| b.max_abs.total_cmp(&a.max_abs));
    for c in cross.iter().take(3) {
        out.push(format!(
            "it follows {} (correlation {:+.2}{}; accounts for an RMS of about {:.3} against a noise floor of {:.3})",
            c.name,
            c.correlation
                .get((c.correlation.len() / 2) as isize as usize)
                .and_then(|_| c
                    .correlation
                    .get(((c.correlation.len() / 2) as isize + c.at_lag) as usize))
                .copied()
                .unwrap_or(c.max_abs),
            lag_words(c, dt_s),
            c.max_abs * t.rmse,
            floor
        ));
    }
    let mut grouped: Vec<&GroupCheck> = t.grouped.iter().filter(|g| !g.pass).collect();
    grouped.sort_by(|a, b| b.z.total_cmp(&a.z));
    for g in grouped.iter().take(3) {
        let parts: Vec<String> = g
            .groups
            .iter()
            .map(|m| format!("{} {:+.4} (RMSE {:.4})", m.label, m.mean, m.rmse))
            .collect();
        out.push(format!("its mean depends on {}: {}", g.name, parts.join(", ")));
    }
    // Regimes where the remainder is much larger than elsewhere, even with a zero mean.
    for g in &t.grouped {
        let (lo, hi) = g.groups.iter().fold(
            (None::<&crate::residuals::Group>, None::<&crate::residuals::Group>),
            |(lo, hi), m| {
                (
                    if lo.is_none_or(|l| m.rmse < l.rmse) {
                        Some(m)
                    } else {
                        lo
                    },
                    if hi.is_none_or(|h| m.rmse > h.rmse) {
                        Some(m)
                    } else {
                        hi
                    },
                )
            },
        );
        if let (Some(lo), Some(hi)) = (lo, hi) {
            if hi.rmse > 2.0 * lo.rmse.max(floor) && hi.rmse > 2.0 * floor {
                out.push(format!(
                    "it is largest where {} is {} (RMSE {:.4}, against {:.4} where it is {})",
                    g.name, hi.label, hi.rmse, lo.rmse, lo.label
                ));
            }
        }
    }
    // Colour: the correlation time and a dominant period.
    let lags = (e.len() / 4).min(2000);
    let rho = crate::residuals::autocorrelation(e, lags);
    if let Some(k) = rho.iter().position(|r| *r < 1.0 / std::f64::consts::E) {
        if k > 1 && t.rmse > 1.5 * floor {
            out.push(format!(
                "it is slow next to the noise: correlated over {} samples = {} (a missing dynamic or a drift rather than noise)",
                k,
                secs(k as f64 * dt_s)
            ));
        }
        // The first local maximum after the first negative excursion: a period.
        if let Some(z) = rho.iter().position(|r| *r < 0.0) {
            let peak = (z..rho.len().saturating_sub(1))
                .filter(|&i| rho[i] > rho[i - 1] && rho[i] >= rho[i + 1])
                .max_by(|&a, &b| rho[a].total_cmp(&rho[b]));
            if let Some(p) = peak.filter(|&p| rho[p] > 0.3) {
                out.push(format!(
                    "it repeats with a period of {} samples = {} ({:.3} Hz; autocorrelation {:.2} there)",
                    p,
                    secs(p as f64 * dt_s),
                    1.0 / (p as f64 * dt_s),
                    rho[p]
                ));
            }
        }
    }
    out
}

/// Seconds in a readable unit.
fn secs(s: f64) -> String {
    if s.abs() < 1e-3 {
        format!("{:.1} µs", s * 1e6)
    } else if s.abs() < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.3} s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slow_signals_level_is_not_reported_as_a_lag() {
        let n = 8000;
        // A remainder that is a slow signal's level (held for 2000 samples at a time, as an oil
        // temperature through a run of events) plus a little white-ish wiggle: its correlation
        // is flat over the window, its largest value wherever the wiggle puts it.
        let level: Vec<f64> = (0..n).map(|k| if (k / 2000) % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let e: Vec<f64> = level
            .iter()
            .enumerate()
            .map(|(k, l)| l + 0.05 * ((k * 7919 % 101) as f64 / 50.0 - 1.0))
            .collect();
        let c = cross_check("temp_C", &e, &level, 50);
        let w = lag_words(&c, 5e-5);
        assert!(w.contains("alike at every lag within ±50 samples"), "{w}");
        // A remainder that is a fast signal delayed by 10 samples: a lag, and its length.
        let fast: Vec<f64> = (0..n).map(|k| ((k * 7919 % 101) as f64 / 50.0) - 1.0).collect();
        let delayed: Vec<f64> = (0..n).map(|k| if k >= 10 { fast[k - 10] } else { 0.0 }).collect();
        let c = cross_check("duty_pct", &delayed, &fast, 50);
        let w = lag_words(&c, 1e-3);
        assert_eq!(c.at_lag, 10, "{w}");
        assert!(w.contains("leading by 10 samples") && !w.contains("edge"), "{w}");
        // A smooth signal delayed by more than the window: the peak sits on its edge, and that
        // is said.
        let smooth: Vec<f64> = (0..n).map(|k| (k as f64 * 0.02).sin()).collect();
        let late_smooth: Vec<f64> = (0..n).map(|k| if k >= 60 { smooth[k - 60] } else { 0.0 }).collect();
        let c = cross_check("duty_pct", &late_smooth, &smooth, 50);
        let w = lag_words(&c, 1e-3);
        assert!(w.contains("leading by 50 samples") && w.contains("or more"), "{w}");
    }
}
