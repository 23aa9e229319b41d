//! Residual analysis: is what the model leaves over noise, or missing physics?
//!
//! - Error measures: RMSE and fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖).
//! - Whiteness: the normalised autocorrelation of the residual at lags 1..L against the 99 %
//!   band ±2.58/√N, and the Ljung-Box statistic Q = N(N+2) Σ ρ_k²/(N−k) against the χ²(L)
//!   99 % quantile.
//! - Cross-correlation of the residual with each input and candidate regressor at lags
//!   −L..L, against the same band.

/// Root mean square of `e`.
pub fn rmse(e: &[f64]) -> f64 {
    if e.is_empty() {
        return 0.0;
    }
    (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
}

/// Fit in percent, 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) (DATA-FORMAT.md).
pub fn fit_pct(y: &[f64], y_model: &[f64]) -> f64 {
    let n = y.len().min(y_model.len());
    if n == 0 {
        return 0.0;
    }
    let mean = y[..n].iter().sum::<f64>() / n as f64;
    let num: f64 = (0..n).map(|i| (y[i] - y_model[i]).powi(2)).sum::<f64>().sqrt();
    let den: f64 = y[..n].iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    if den == 0.0 {
        return if num == 0.0 { 100.0 } else { f64::NEG_INFINITY };
    }
    100.0 * (1.0 - num / den)
}

fn centred(x: &[f64]) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    x.iter().map(|v| v - m).collect()
}

/// Normalised autocorrelation ρ_k, k = 0..=max_lag (ρ_0 = 1).
pub fn autocorrelation(e: &[f64], max_lag: usize) -> Vec<f64> {
    let c = centred(e);
    let n = c.len();
    let r0: f64 = c.iter().map(|v| v * v).sum();
    (0..=max_lag.min(n.saturating_sub(1)))
        .map(|k| if r0 > 0.0 { c[..n - k].iter().zip(&c[k..]).map(|(a, b)| a * b).sum::<f64>() / r0 } else { 0.0 })
        .collect()
}

/// Normalised cross-correlation between `e` and `u` at lags −max_lag..=max_lag
/// (index `max_lag + k` holds lag k: e(t) against u(t − k)).
pub fn cross_correlation(e: &[f64], u: &[f64], max_lag: usize) -> Vec<f64> {
    let n = e.len().min(u.len());
    let (ce, cu) = (centred(&e[..n]), centred(&u[..n]));
    let den = (ce.iter().map(|v| v * v).sum::<f64>() * cu.iter().map(|v| v * v).sum::<f64>()).sqrt();
    let lag = max_lag.min(n.saturating_sub(1)) as isize;
    (-lag..=lag)
        .map(|k| {
            if den == 0.0 {
                return 0.0;
            }
            let mut s = 0.0;
            for t in 0..n as isize {
                let j = t - k;
                if j >= 0 && j < n as isize {
                    s += ce[t as usize] * cu[j as usize];
                }
            }
            s / den
        })
        .collect()
}

/// The 99 % band for a correlation estimate from `n` samples.
pub fn band99(n: usize) -> f64 {
    2.58 / (n.max(1) as f64).sqrt()
}

/// χ² 99 % quantile by the Wilson-Hilferty approximation (accurate to ~1 % for k ≥ 3).
pub fn chi2_99(k: usize) -> f64 {
    let k = k.max(1) as f64;
    let z = 2.326_347_874;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// The whiteness verdict with its evidence.
#[derive(Clone, Debug)]
pub struct Whiteness {
    pub lags: usize,
    pub band: f64,
    /// Largest |ρ_k|, k ≥ 1, and its lag.
    pub max_abs_rho: f64,
    pub max_lag: usize,
    /// Lags outside the band.
    pub outside: usize,
    pub ljung_box_q: f64,
    pub ljung_box_limit: f64,
    pub pass: bool,
}

/// Whiteness test over lags 1..=lags. Passes when the Ljung-Box statistic is below its 99 %
/// limit and at most 1 % of the lags (at least one) leave the band.
pub fn whiteness(e: &[f64], lags: usize) -> Whiteness {
    let n = e.len();
    let rho = autocorrelation(e, lags);
    let band = band99(n);
    let mut q = 0.0;
    let (mut max_abs_rho, mut max_lag, mut outside) = (0.0f64, 0, 0);
    for (k, r) in rho.iter().enumerate().skip(1) {
        q += r * r / (n - k) as f64;
        if r.abs() > max_abs_rho {
            max_abs_rho = r.abs();
            max_lag = k;
        }
        if r.abs() > band {
            outside += 1;
        }
    }
    let used = rho.len().saturating_sub(1);
    let q = n as f64 * (n as f64 + 2.0) * q;
    let limit = chi2_99(used);
    let pass = q < limit && outside <= (used / 100).max(1);
    Whiteness { lags: used, band, max_abs_rho, max_lag, outside, ljung_box_q: q, ljung_box_limit: limit, pass }
}

/// Correlation of the residual with one signal, summarised.
#[derive(Clone, Debug)]
pub struct CrossCheck {
    pub name: String,
    pub max_abs: f64,
    /// Lag of the largest value (positive: the signal leads the residual).
    pub at_lag: isize,
    pub band: f64,
    pub pass: bool,
}

pub fn cross_check(name: &str, e: &[f64], u: &[f64], lags: usize) -> CrossCheck {
    let c = cross_correlation(e, u, lags);
    let l = (c.len() / 2) as isize;
    let (mut max_abs, mut at_lag) = (0.0f64, 0isize);
    for (i, v) in c.iter().enumerate() {
        if v.abs() > max_abs {
            max_abs = v.abs();
            at_lag = i as isize - l;
        }
    }
    let band = band99(e.len().min(u.len()));
    CrossCheck { name: name.to_string(), max_abs, at_lag, band, pass: max_abs <= band }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic white sequence (xorshift), zero mean.
    fn white(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn white_noise_passes_and_filtered_noise_fails() {
        let w = white(5000, 0x9E3779B97F4A7C15);
        assert!(whiteness(&w, 50).pass, "{:?}", whiteness(&w, 50));
        // First-order filtered noise is strongly correlated.
        let mut y = 0.0;
        let coloured: Vec<f64> = w.iter().map(|&v| { y = 0.9 * y + v; y }).collect();
        let wt = whiteness(&coloured, 50);
        assert!(!wt.pass && wt.max_lag == 1 && wt.max_abs_rho > 0.85, "{wt:?}");
    }

    #[test]
    fn cross_correlation_finds_a_delayed_input() {
        let u = white(4000, 7);
        // Residual = input delayed by 5 samples + independent noise.
        let noise = white(4000, 99);
        let e: Vec<f64> = (0..4000).map(|t| if t >= 5 { u[t - 5] } else { 0.0 } + 0.5 * noise[t]).collect();
        let c = cross_check("u", &e, &u, 20);
        assert!(!c.pass && c.at_lag == 5 && c.max_abs > 0.8, "{c:?}");
        let indep = cross_check("noise2", &white(4000, 1234), &u, 20);
        assert!(indep.pass, "{indep:?}");
    }

    #[test]
    fn fit_and_rmse_follow_their_definitions() {
        let y = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(fit_pct(&y, &y), 100.0);
        // Predicting the mean gives 0 %.
        assert!(fit_pct(&y, &[2.5; 4]).abs() < 1e-12);
        assert!((rmse(&[3.0, -4.0]) - (12.5f64).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn chi2_quantile_matches_tables() {
        // χ²(0.99): k=10 → 23.209, k=50 → 76.154.
        assert!((chi2_99(10) - 23.209).abs() < 0.1);
        assert!((chi2_99(50) - 76.154).abs() < 0.3);
    }
}
