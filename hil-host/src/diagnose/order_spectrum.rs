//! The order spectrum of a residual against crank angle: where a disturbance locked to the
//! engine's rotation (the EVVT belt vibration) shows whatever the engine speed, its order and
//! its sinusoid's coefficients. Used by the EVVT family (`diagnose/evvt.rs`).
use std::f64::consts::PI;

/// Σ (r_k − mean) e^{−2πi o θ_k} by direct summation (the centred series is not copied).
fn order_dft(r: &[f64], mean: f64, revs: impl Iterator<Item = f64>, order: f64) -> (f64, f64) {
    let (mut c, mut s) = (0.0, 0.0);
    for (x, th) in r.iter().zip(revs) {
        let v = x - mean;
        let (sn, cs) = (2.0 * PI * (order * th).fract()).sin_cos();
        c += v * cs;
        s += v * sn;
    }
    (c, s)
}

/// The peak of the residual's order spectrum (power against cycles per engine revolution) in
/// `lo..hi`: the residual is gridded onto `8·hi` bins per revolution (nearest bin, phase error
/// ≤ π/8), zero-padded 2× and transformed; the best bin is refined by golden-section search on
/// the direct transform at the exact crank angles. Returns the order and the amplitude of the
/// order's sinusoid in the residual.
///
/// A long record is transformed in segments of [`ORDER_SEGMENT_BINS`] bins whose power spectra
/// are averaged (Bartlett), then the coarse peak is located on the direct transform of the whole
/// record: one transform of a 425 000-row record's 2^21 points held about 100 MB (its re/im, the
/// FFT's complex buffer and scratch); the segments hold the real grid and 2 MB.
///
/// `revs` yields the crank revolutions at each sample of `r` and is walked once per pass (the
/// EVVT family makes them from the engine speed as they are read instead of holding a series).
pub(super) fn order_peak<I>(r: &[f64], revs: I, lo: f64, hi: f64) -> Option<(f64, f64)>
where
    I: Iterator<Item = f64> + Clone,
{
    order_peak_in_segments(r, revs, lo, hi, ORDER_SEGMENT_BINS)
}

/// Grid bins per transform of [`order_peak`] (a power of two).
const ORDER_SEGMENT_BINS: usize = 1 << 16;

fn order_peak_in_segments<I>(r: &[f64], revs: I, lo: f64, hi: f64, segment_bins: usize) -> Option<(f64, f64)>
where
    I: Iterator<Item = f64> + Clone,
{
    let total = revs.clone().last()?;
    if !(hi > lo && total > 20.0 && r.len() == revs.clone().count()) {
        return None;
    }
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let per_rev = (8.0 * hi).ceil();
    let bins = (total * per_rev).ceil() as usize + 2;
    // One transform of the whole record (2× zero-padded) when it fits a segment, else the
    // averaged power of segments.
    let whole = (2 * bins).next_power_of_two() <= 2 * segment_bins;
    let (seg, nfft) = if whole {
        (bins, (2 * bins).next_power_of_two())
    } else {
        (segment_bins, 2 * segment_bins)
    };
    let bin_order = per_rev / nfft as f64;
    let (m_lo, m_hi) = (
        (lo / bin_order).ceil() as usize,
        ((hi / bin_order).floor() as usize).min(nfft / 2),
    );
    if m_lo > m_hi {
        return None;
    }
    let mut power_sum = vec![0.0; m_hi - m_lo + 1];
    // One real-input plan, its buffers and scratch for all segments (a real transform holds
    // half of a complex one's: about 3 MB for 2^17 points). Each segment's bins are gridded
    // straight into the transform's input (a pass over the samples per segment; no grid of
    // the whole record is held).
    let plan = realfft::RealFftPlanner::<f64>::new().plan_fft_forward(nfft);
    let (mut x, mut spectrum, mut scratch) = (plan.make_input_vec(), plan.make_output_vec(), plan.make_scratch_vec());
    for first in (0..bins).step_by(seg) {
        let end = (first + seg).min(bins);
        // The transform uses its input as work space: zero it for every segment.
        x.fill(0.0);
        for (v, th) in r.iter().zip(revs.clone()) {
            let i = (th * per_rev).round() as usize;
            if (first..end).contains(&i) {
                x[i - first] += v - mean;
            }
        }
        plan.process_with_scratch(&mut x, &mut spectrum, &mut scratch).ok()?;
        for (m, p) in (m_lo..=m_hi).zip(power_sum.iter_mut()) {
            *p += spectrum[m].norm_sqr();
        }
    }
    drop((x, spectrum, scratch, plan));
    let best = m_lo + (0..power_sum.len()).max_by(|&a, &b| power_sum[a].total_cmp(&power_sum[b]))?;
    let power = |o: f64| {
        let (c, s) = order_dft(r, mean, revs.clone(), o);
        c * c + s * s
    };
    let (mut a, mut b) = ((best as f64 - 1.0) * bin_order, (best as f64 + 1.0) * bin_order);
    if !whole {
        // A segment's bin is many of the whole record's main lobes (1/total orders) wide: scan
        // the whole record's transform over it at a quarter lobe, then refine around the best.
        let step = 0.25 / total;
        let n = ((b - a) / step).ceil() as usize;
        let at = (0..=n)
            .map(|k| a + k as f64 * step)
            .max_by(|x, y| power(*x).total_cmp(&power(*y)))?;
        (a, b) = (at - step, at + step);
    }
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (power(x1), power(x2));
    for _ in 0..24 {
        if f1 > f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = power(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = power(x2);
        }
    }
    let order = 0.5 * (a + b);
    Some((order, 2.0 * power(order).sqrt() / r.len() as f64))
}

/// Least-squares (c, s) of `r ≈ c cos(2π o θ) + s sin(2π o θ)`.
pub(super) fn project_sinusoid(r: &[f64], revs: impl Iterator<Item = f64>, order: f64) -> (f64, f64) {
    let (mut cc, mut ss, mut cs, mut rc, mut rs) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (v, th) in r.iter().zip(revs) {
        let (sn, c) = (2.0 * PI * (order * th).fract()).sin_cos();
        cc += c * c;
        ss += sn * sn;
        cs += c * sn;
        rc += v * c;
        rs += v * sn;
    }
    let det = cc * ss - cs * cs;
    if det.abs() < 1e-12 {
        return (0.0, 0.0);
    }
    ((rc * ss - rs * cs) / det, (rs * cc - rc * cs) / det)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::Rng;

    #[test]
    fn order_peak_finds_a_crank_locked_sinusoid() {
        let mut rng = Rng::new(8);
        let dt = 0.01;
        let mut revs = Vec::new();
        let mut th = 0.0;
        for k in 0..20_000 {
            revs.push(th);
            th += [820.0, 1370.0, 1090.0, 950.0][k / 5000] / 60.0 * dt;
        }
        let r: Vec<f64> = revs
            .iter()
            .map(|t| 0.7 * (2.0 * PI * 1.37 * t + 0.4).sin() + 0.5 * rng.normal())
            .collect();
        let (o, amp) = order_peak(&r, revs.iter().copied(), 0.25, 2.1).unwrap();
        assert!((o - 1.37).abs() < 2e-4, "order {o}");
        assert!((amp - 0.7).abs() < 0.05, "amplitude {amp}");
        // The same record in segments of 4096 bins (a long record's path: 15 segments here)
        // finds the same peak.
        let (os, amps) = order_peak_in_segments(&r, revs.iter().copied(), 0.25, 2.1, 1 << 12).unwrap();
        assert!((os - 1.37).abs() < 2e-4, "order in segments {os}");
        assert!((amps - 0.7).abs() < 0.05, "amplitude in segments {amps}");
        let (c, s) = project_sinusoid(&r, revs.iter().copied(), o);
        assert!((c.hypot(s) - 0.7).abs() < 0.05 && (c.atan2(s) - 0.4).abs() < 0.1);
    }
}
