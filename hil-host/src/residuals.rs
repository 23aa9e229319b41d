//! Residual analysis: is what the model leaves over noise, or missing physics?
//!
//! - Error measures: RMSE and fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖).
//! - Whiteness: the normalised autocorrelation of the residual at lags 1..L against the 99 %
//!   band ±2.58/√N, and the Ljung-Box statistic Q = N(N+2) Σ ρ_k²/(N−k) against the χ²(L)
//!   99 % quantile.
//! - Cross-correlation of the residual with each input and candidate regressor at lags
//!   −L..L, against the same band.
//! - The residual grouped by operating condition: its mean and RMSE in each group of a
//!   condition signal (each value of a sign or flag, else the signal's low, middle and high
//!   third), and whether the group means differ by more than noise explains.

use crate::signal::dot;
use rayon::prelude::*;

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
    let at = |k: usize| if r0 > 0.0 { dot(&c[..n - k], &c[k..]) / r0 } else { 0.0 };
    let lags = 0..=max_lag.min(n.saturating_sub(1));
    if n * lags.clone().count() >= PARALLEL_PRODUCTS {
        lags.into_par_iter().map(at).collect()
    } else {
        lags.map(at).collect()
    }
}

/// A correlation over more products than this runs its lags on rayon's pool: each lag's sum is
/// the same computation either way (the same bits), and the centred series are shared, not
/// copied (the residual tests of a 200 000-row record were the longest stretch of its
/// diagnosis on one core; whole tests on threads of their own, per regressor or the baseline's
/// beside the extended model's, each held centred copies of the series: 105 B a row of peak
/// memory against the goal's 100).
const PARALLEL_PRODUCTS: usize = 1 << 22;

/// Normalised cross-correlation between `e` and `u` at lags −max_lag..=max_lag
/// (index `max_lag + k` holds lag k: e(t) against u(t − k)).
pub fn cross_correlation(e: &[f64], u: &[f64], max_lag: usize) -> Vec<f64> {
    let n = e.len().min(u.len());
    let (ce, cu) = (centred(&e[..n]), centred(&u[..n]));
    let den = (ce.iter().map(|v| v * v).sum::<f64>() * cu.iter().map(|v| v * v).sum::<f64>()).sqrt();
    let lag = max_lag.min(n.saturating_sub(1)) as isize;
    let at = |k: isize| {
        if den == 0.0 {
            return 0.0;
        }
        // Σ e(t) u(t − k) over the t where both exist.
        let s = if k >= 0 {
            let k = k as usize;
            dot(&ce[k..], &cu[..n - k])
        } else {
            let k = k.unsigned_abs();
            dot(&ce[..n - k], &cu[k..])
        };
        s / den
    };
    if n * (2 * lag as usize + 1) >= PARALLEL_PRODUCTS {
        (-lag..=lag).into_par_iter().map(at).collect()
    } else {
        (-lag..=lag).map(at).collect()
    }
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
    Whiteness {
        lags: used,
        band,
        max_abs_rho,
        max_lag,
        outside,
        ljung_box_q: q,
        ljung_box_limit: limit,
        pass,
    }
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
    /// The normalised cross-correlation at lags −L..=L (index L is lag 0), for the plot.
    pub correlation: Vec<f64>,
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
    CrossCheck {
        name: name.to_string(),
        max_abs,
        at_lag,
        band,
        pass: max_abs <= band,
        correlation: c,
    }
}

/// The residual in one group of an operating condition.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    pub label: String,
    pub samples: usize,
    pub mean: f64,
    pub rmse: f64,
}

/// The residual grouped by one operating condition.
#[derive(Clone, Debug)]
pub struct GroupCheck {
    pub name: String,
    pub groups: Vec<Group>,
    /// The largest difference between two group means, in standard errors.
    pub z: f64,
    /// Passes when no two group means differ by `Z_GROUPS` standard errors or more.
    pub pass: bool,
}

/// Group means this many standard errors apart are a bias tied to the condition: the 99 % level
/// of the other residual tests, two-sided, for a standard error from 40 blocks (Student t with
/// 39 degrees of freedom: 2.71).
pub const Z_GROUPS: f64 = 2.71;

/// Groups smaller than this share of the samples (or than 30 samples) are left out: their means
/// are too uncertain to say anything.
const MIN_GROUP_SHARE: f64 = 0.02;

/// The residual `e` grouped by `condition` (same length). A condition with at most three
/// distinct values (signs, flags) is grouped by value; others into thirds by their 1/3 and 2/3
/// quantiles. The residual is correlated from sample to sample and the conditions come in
/// stretches (stitched test points), so the standard error of a difference of group means is
/// cluster-robust: the record is cut into 40 contiguous blocks and the difference's variance is
/// estimated from the blocks' contributions (as `improvement_z` does for two models), not from
/// thousands of samples taken as independent.
pub fn group_check(name: &str, e: &[f64], condition: &[f64]) -> GroupCheck {
    let n = e.len().min(condition.len());
    let (e, c) = (&e[..n], &condition[..n]);
    // Up to four distinct values are enough to tell a flag from a quantity (no sorted copy of
    // the whole condition for that: it was a validation-length copy held through the check).
    let mut values: Vec<f64> = Vec::new();
    for &v in c.iter().filter(|v| v.is_finite()) {
        if !values.contains(&v) {
            values.push(v);
            if values.len() > 3 {
                break;
            }
        }
    }
    values.sort_by(f64::total_cmp);
    type GroupOf = Box<dyn Fn(f64) -> Option<usize>>;
    let (labels, group_of): (Vec<String>, GroupOf) = if values.len() <= 3 {
        let vals = values.clone();
        (
            values.iter().map(|v| format!("= {v}")).collect(),
            Box::new(move |x: f64| vals.iter().position(|v| *v == x)),
        )
    } else {
        let mut sorted: Vec<f64> = c.iter().copied().filter(|v| v.is_finite()).collect();
        sorted.sort_by(f64::total_cmp);
        let q = |f: f64| sorted[((sorted.len() - 1) as f64 * f).round() as usize];
        let (q1, q2) = (q(1.0 / 3.0), q(2.0 / 3.0));
        (
            vec![
                format!("low (< {})", short(q1)),
                format!("middle ({}..{})", short(q1), short(q2)),
                format!("high (≥ {})", short(q2)),
            ],
            Box::new(move |x: f64| {
                x.is_finite().then_some(if x < q1 {
                    0
                } else if x < q2 {
                    1
                } else {
                    2
                })
            }),
        )
    };
    let blocks = 40.min(n / 10).max(2);
    let size = n.div_ceil(blocks).max(1);
    // Per group and block: count and residual sum; per group: sum of squares.
    let mut count = vec![vec![0usize; blocks]; labels.len()];
    let mut sum = vec![vec![0.0f64; blocks]; labels.len()];
    let mut sum2 = vec![0.0f64; labels.len()];
    for (k, (&r, &x)) in e.iter().zip(c).enumerate() {
        if let Some(g) = group_of(x) {
            count[g][k / size] += 1;
            sum[g][k / size] += r;
            sum2[g] += r * r;
        }
    }
    let min_samples = ((n as f64 * MIN_GROUP_SHARE).ceil() as usize).max(30);
    let mut groups = Vec::new();
    let mut kept = Vec::new();
    for (g, label) in labels.into_iter().enumerate() {
        let total: usize = count[g].iter().sum();
        if total < min_samples {
            continue;
        }
        let mean = sum[g].iter().sum::<f64>() / total as f64;
        groups.push(Group {
            label,
            samples: total,
            mean,
            rmse: (sum2[g] / total as f64).sqrt(),
        });
        kept.push(g);
    }
    let mut z = 0.0f64;
    for (a, &i) in kept.iter().enumerate() {
        for (b, &j) in kept.iter().enumerate().skip(a + 1) {
            let (mi, mj) = (groups[a].mean, groups[b].mean);
            let (ni, nj) = (groups[a].samples as f64, groups[b].samples as f64);
            // Linearised contribution of each block to the difference of the two means.
            let var: f64 = (0..blocks)
                .map(|k| {
                    ((sum[i][k] - mi * count[i][k] as f64) / ni - (sum[j][k] - mj * count[j][k] as f64) / nj).powi(2)
                })
                .sum::<f64>()
                * blocks as f64
                / (blocks - 1) as f64;
            let d = (mi - mj).abs();
            z = z.max(if var > 0.0 {
                d / var.sqrt()
            } else if d > 0.0 {
                f64::INFINITY
            } else {
                0.0
            });
        }
    }
    GroupCheck {
        name: name.to_string(),
        groups,
        z,
        pass: z < Z_GROUPS,
    }
}

/// A group boundary for a label: 4 significant digits.
fn short(x: f64) -> String {
    format!("{}", (x * 1e4).round() / 1e4).chars().take(10).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A long record's correlations (its lags on the pool) are bit for bit the sums of the
    /// short path, lag by lag: the report does not depend on how many cores computed it.
    #[test]
    fn long_correlations_on_the_pool_are_the_same_bits_lag_by_lag() {
        let (n, lags) = (30_000, 150);
        assert!(n * (2 * lags + 1) >= PARALLEL_PRODUCTS && n * (lags + 1) >= PARALLEL_PRODUCTS);
        let e = white(n, 0x2545_F491_4F6C_DD1D);
        let u: Vec<f64> = white(n, 0x9E37_79B9_7F4A_7C15)
            .iter()
            .enumerate()
            .map(|(i, w)| w + 0.3 * e[i.saturating_sub(7)])
            .collect();
        let (ce, cu) = (centred(&e), centred(&u));
        let sq = |c: &[f64]| c.iter().map(|v| v * v).sum::<f64>();
        let den = (sq(&ce) * sq(&cu)).sqrt();
        let cross = cross_correlation(&e, &u, lags);
        for (i, k) in (-(lags as isize)..=lags as isize).enumerate() {
            let m = k.unsigned_abs();
            let s = if k >= 0 {
                dot(&ce[m..], &cu[..n - m])
            } else {
                dot(&ce[..n - m], &cu[m..])
            };
            assert_eq!(cross[i].to_bits(), (s / den).to_bits(), "lag {k}");
        }
        // The planted lag stands out (the sums are the correlations, not just equal numbers).
        // u(t) holds e(t − 7): e(t) meets it in u(t − k) at k = −7.
        assert!(
            cross[lags - 7] > 0.2 && cross[lags].abs() < 0.05,
            "{} {}",
            cross[lags - 7],
            cross[lags]
        );
        let auto = autocorrelation(&e, lags);
        let r0 = sq(&ce);
        for (k, a) in auto.iter().enumerate() {
            assert_eq!(a.to_bits(), (dot(&ce[..n - k], &ce[k..]) / r0).to_bits(), "lag {k}");
        }
    }

    #[test]
    fn grouped_residual_finds_a_bias_in_one_condition() {
        let noise = white(6000, 0x9E37_79B9_7F4A_7C15);
        // A slow operating condition (a supply voltage stepping between levels).
        let volt: Vec<f64> = (0..6000).map(|k| 10.0 + ((k / 500) % 4) as f64).collect();
        let plain = group_check("supply voltage", &noise, &volt);
        assert!(plain.pass && plain.groups.len() == 3, "{plain:?}");
        // The same noise plus an offset of a third of its RMS where the voltage is high (the
        // upper third: 12 and 13 V of the four levels).
        let biased: Vec<f64> = noise
            .iter()
            .zip(&volt)
            .map(|(e, v)| e + if *v >= 12.0 { 0.1 } else { 0.0 })
            .collect();
        let g = group_check("supply voltage", &biased, &volt);
        assert!(!g.pass && g.z > 8.0, "{g:?}");
        let high = g.groups.iter().find(|g| g.label.starts_with("high")).unwrap();
        assert!((high.mean - 0.1).abs() < 0.02 && high.samples == 3000, "{high:?}");
        // A sign is grouped by value; a group too small to judge is left out.
        let mut sign: Vec<f64> = (0..6000).map(|k| if (k / 300) % 2 == 0 { 1.0 } else { -1.0 }).collect();
        sign[17] = 0.0;
        let s = group_check("velocity sign", &noise, &sign);
        assert_eq!(
            s.groups.iter().map(|g| g.label.as_str()).collect::<Vec<_>>(),
            ["= -1", "= 1"]
        );
        assert!(s.pass, "{s:?}");
        // A slowly wandering residual: its correlation widens the standard error, so a slow
        // drift that happens to line up with a condition is not called a bias as easily.
        let mut y = 0.0;
        let drift: Vec<f64> = noise
            .iter()
            .map(|&v| {
                y = 0.995 * y + 0.1 * v;
                y
            })
            .collect();
        let d = group_check("supply voltage", &drift, &volt);
        let naive_se = (d.groups.iter().map(|g| g.rmse * g.rmse / g.samples as f64).sum::<f64>()).sqrt();
        let spread = d.groups.iter().map(|g| g.mean).fold(f64::MIN, f64::max)
            - d.groups.iter().map(|g| g.mean).fold(f64::MAX, f64::min);
        assert!(
            d.z < spread / naive_se / 5.0,
            "z {} vs naive {}",
            d.z,
            spread / naive_se
        );
    }

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
        let coloured: Vec<f64> = w
            .iter()
            .map(|&v| {
                y = 0.9 * y + v;
                y
            })
            .collect();
        let wt = whiteness(&coloured, 50);
        assert!(!wt.pass && wt.max_lag == 1 && wt.max_abs_rho > 0.85, "{wt:?}");
    }

    #[test]
    fn cross_correlation_finds_a_delayed_input() {
        let u = white(4000, 7);
        // Residual = input delayed by 5 samples + independent noise.
        let noise = white(4000, 99);
        let e: Vec<f64> = (0..4000)
            .map(|t| if t >= 5 { u[t - 5] } else { 0.0 } + 0.5 * noise[t])
            .collect();
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
