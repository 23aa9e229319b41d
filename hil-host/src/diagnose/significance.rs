//! Whether one model's validation errors beat another's by more than the noise: the
//! block-wise z-score the forward selection of [`super::diagnose`] decides with.
use super::Fit;

/// How clearly model B's errors beat model A's, as a z-score. The validation record is cut
/// into 40 blocks, so the residuals' autocorrelation does not pass for thousands of
/// independent samples; three tests of "B is better" are made on the blocks and the largest
/// score is returned:
/// - the t-statistic of the mean of the blocks' mean squared-error differences (sensitive when
///   the improvement is even);
/// - the sign test of how many blocks B wins (robust when the improvement is concentrated in
///   some blocks, e.g. friction that only shows while the load moves);
/// - the t-statistic of the mean log ratio of the blocks' mean squared errors (scale-free: a
///   large, consistent relative gain is not drowned by one block whose errors are large for
///   both models).
pub fn improvement_z(e_a: &[f64], e_b: &[f64]) -> f64 {
    improvement_z_with(e_a.len().min(e_b.len()), |t| e_a[t], |t| e_b[t])
}

/// [`improvement_z`] of two fits' validation residuals, computed sample by sample from their
/// shared measured output and their predictions: no residual series is made (on a 200 000-row
/// validation log each would be 1.6 MB held through the round). Same numbers as
/// `improvement_z(&a.residual(), &b.residual())`.
pub fn improvement_z_of(a: &Fit, b: &Fit) -> f64 {
    let n = a
        .measured
        .len()
        .min(a.predicted.len())
        .min(b.measured.len())
        .min(b.predicted.len());
    improvement_z_with(
        n,
        |t| a.measured[t] - a.predicted[t],
        |t| b.measured[t] - b.predicted[t],
    )
}

fn improvement_z_with(n: usize, e_a: impl Fn(usize) -> f64, e_b: impl Fn(usize) -> f64) -> f64 {
    let blocks = 40.min(n);
    if blocks < 2 {
        return 0.0;
    }
    let size = n / blocks;
    let mse = |e: &dyn Fn(usize) -> f64, b: usize| {
        (b * size..(b + 1) * size)
            .map(|t| {
                let v = e(t);
                v * v
            })
            .sum::<f64>()
            / size as f64
    };
    let (ma, mb): (Vec<f64>, Vec<f64>) = (0..blocks).map(|b| (mse(&e_a, b), mse(&e_b, b))).unzip();
    let means: Vec<f64> = ma.iter().zip(&mb).map(|(a, b)| a - b).collect();
    let t_of = |v: &[f64]| {
        let k = v.len();
        if k < 2 {
            return 0.0;
        }
        let m = v.iter().sum::<f64>() / k as f64;
        let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k - 1) as f64;
        let se = (var / k as f64).sqrt();
        if se == 0.0 {
            if m > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        } else {
            m / se
        }
    };
    let t = t_of(&means);
    let wins = means.iter().filter(|&&d| d > 0.0).count() as f64;
    let ties = means.iter().filter(|&&d| d == 0.0).count() as f64;
    let decided = blocks as f64 - ties;
    let sign = if decided > 0.0 {
        (wins - decided / 2.0) / (decided / 4.0).sqrt()
    } else {
        0.0
    };
    let logs: Vec<f64> = ma
        .iter()
        .zip(&mb)
        .filter(|(a, b)| **a > 0.0 && **b > 0.0)
        .map(|(a, b)| (a / b).ln())
        .collect();
    // Blocks that are identical for both models (e.g. samples neither predicts) say nothing.
    let logs: Vec<f64> = logs.into_iter().filter(|v| v.abs() > 1e-12).collect();
    let log_t = if logs.len() >= blocks / 2 { t_of(&logs) } else { 0.0 };
    t.max(sign).max(log_t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn improvement_z_of_two_fits_is_that_of_their_residuals() {
        let measured: Vec<f64> = (0..3001).map(|k| (k as f64 * 0.01).sin()).collect();
        let fit = |bias: f64, wobble: f64| {
            let predicted = measured
                .iter()
                .enumerate()
                .map(|(k, y)| y + bias + wobble * ((k as f64 * 0.37).cos()))
                .collect();
            Fit::new("baseline", Vec::new(), Vec::new(), measured.clone(), predicted, 0)
        };
        let (a, b) = (fit(0.02, 0.05), fit(0.01, 0.03));
        let z = improvement_z(&a.residual(), &b.residual());
        assert!(z > 4.0, "{z}");
        assert_eq!(improvement_z_of(&a, &b).to_bits(), z.to_bits());
        assert_eq!(
            improvement_z_of(&b, &a).to_bits(),
            improvement_z(&b.residual(), &a.residual()).to_bits()
        );
        assert_eq!(a.residual_len(), 3001);
    }

    #[test]
    fn improvement_z_separates_signal_from_noise() {
        let noise = |k: usize, s: f64| ((k as f64 * 12.9898 + s).sin() * 43758.5453).rem_euclid(1.0) - 0.5;
        let a: Vec<f64> = (0..4000).map(|k| noise(k, 1.0)).collect();
        let b: Vec<f64> = (0..4000).map(|k| noise(k, 2.0)).collect();
        // Two equally good models: no significant difference.
        assert!(improvement_z(&a, &b).abs() < 4.0);
        // B halves A's errors: clearly significant.
        let half: Vec<f64> = a.iter().map(|v| v * 0.5).collect();
        assert!(improvement_z(&a, &half) > 10.0);
    }
}
