//! Signal processing: resampling onto another time base (the log readers), and for
//! identification from measured data: Butterworth low-pass filters
//! (cascaded second-order sections by the bilinear transform), zero-phase forward-backward
//! filtering, central differences, and decimation (the EMPS description's "bandpass filtering"
//! and "decimate process", Sec. 3.1-3.2).

use std::f64::consts::PI;

/// `values` recorded at `t_from` onto the instants `t_to`: linear, or the last value at or
/// before each instant for flags. Instants outside the recorded span take the first or last
/// value; their count is returned. The recorded times must increase.
pub fn resample(t_from: &[f64], values: &[f64], t_to: &[f64], hold: bool) -> Result<(Vec<f64>, usize), String> {
    if t_from.is_empty() || t_from.len() != values.len() {
        return Err(format!("{} samples against {} time stamps", values.len(), t_from.len()));
    }
    if let Some(k) = t_from.windows(2).position(|w| !(w[1] > w[0])) {
        return Err(format!(
            "its time stamps do not increase at sample {} ({} then {})",
            k + 1,
            t_from[k],
            t_from[k + 1]
        ));
    }
    let last = t_from.len() - 1;
    let mut out = Vec::with_capacity(t_to.len());
    let mut outside = 0;
    let mut j = 0; // t_from[j] <= t < t_from[j + 1] for the current t (instants increase).
    for &t in t_to {
        if t < t_from[0] {
            outside += 1;
            out.push(values[0]);
            continue;
        }
        if t > t_from[last] {
            outside += 1;
            out.push(values[last]);
            continue;
        }
        while j < last && t_from[j + 1] <= t {
            j += 1;
        }
        if j == last || hold || t == t_from[j] {
            out.push(values[j]);
        } else {
            let w = (t - t_from[j]) / (t_from[j + 1] - t_from[j]);
            out.push(values[j] + w * (values[j + 1] - values[j]));
        }
    }
    Ok((out, outside))
}

/// `values` at the instants `t` with the samples that are not `valid(i)` replaced by the
/// valid ones resampled at their instants ([`resample`]: linear, or held for flags): a
/// logger's invalid samples, a sparse export's blank cells. With the count of replaced samples
/// outside the valid ones' span (they take the first or last valid value). An error where no
/// sample is valid or the instants do not increase.
pub fn fill_gaps(
    t: &[f64],
    values: &[f64],
    valid: impl Fn(usize) -> bool,
    hold: bool,
) -> Result<(Vec<f64>, usize), String> {
    if t.len() != values.len() {
        return Err(format!("{} samples against {} time stamps", values.len(), t.len()));
    }
    let (t_ok, v_ok): (Vec<f64>, Vec<f64>) = (0..t.len()).filter(|&i| valid(i)).map(|i| (t[i], values[i])).unzip();
    if t_ok.is_empty() {
        return Err("no valid sample".into());
    }
    let (filled, outside) = resample(&t_ok, &v_ok, t, hold)?;
    let out = filled
        .into_iter()
        .enumerate()
        .map(|(i, f)| if valid(i) { values[i] } else { f })
        .collect();
    Ok((out, outside))
}

/// Σ aᵢbᵢ over the common length, summed in eight interleaved lanes so that the compiler can
/// vectorise it (one running sum may not be reordered); the order is fixed, so the bits are
/// the same on every run and machine.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    const LANES: usize = 8;
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (a_chunks, b_chunks) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f64 = a_chunks
        .remainder()
        .iter()
        .zip(b_chunks.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut lanes = [0.0f64; LANES];
    for (x, y) in a_chunks.zip(b_chunks) {
        for i in 0..LANES {
            lanes[i] += x[i] * y[i];
        }
    }
    let [l0, l1, l2, l3, l4, l5, l6, l7] = lanes;
    (((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7))) + tail
}

/// One biquad section, direct form II transposed.
#[derive(Clone, Copy, Debug)]
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

/// A Butterworth low-pass of even order as cascaded biquads.
#[derive(Clone, Debug)]
pub struct Butterworth {
    sections: Vec<Biquad>,
    /// Samples of odd-reflection padding for `filtfilt`: about four periods of the cut-off,
    /// enough for the start-up transient to die out before the data begins.
    pad: usize,
}

impl Butterworth {
    /// Samples at each end of a `filtfilt` output still touched by the padding's start-up.
    pub fn settling_samples(&self) -> usize {
        self.pad
    }
}

impl Butterworth {
    /// `order` is rounded up to even; `fc_hz` must lie below the Nyquist frequency.
    pub fn lowpass(order: usize, fc_hz: f64, fs_hz: f64) -> Result<Self, String> {
        if !(fc_hz > 0.0 && fc_hz < fs_hz / 2.0) {
            return Err(format!("cut-off {fc_hz} Hz must lie in (0, {}) Hz", fs_hz / 2.0));
        }
        let pairs = order.max(2).div_ceil(2);
        let n = 2 * pairs;
        // Pre-warped analogue cut-off.
        let k = (PI * fc_hz / fs_hz).tan();
        let sections = (0..pairs)
            .map(|i| {
                // Pole pair angle of the analogue prototype: q = 1/(2 cos θ).
                let theta = PI * (2 * i + 1) as f64 / (2 * n) as f64;
                let q = 1.0 / (2.0 * theta.cos()).max(1e-12);
                let norm = 1.0 / (1.0 + k / q + k * k);
                let b0 = k * k * norm;
                Biquad {
                    b: [b0, 2.0 * b0, b0],
                    a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
                }
            })
            .collect();
        let pad = (4.0 * fs_hz / fc_hz).ceil() as usize;
        Ok(Self { sections, pad })
    }

    /// Causal filtering, the state starting at the first sample's steady state.
    pub fn filter(&self, x: &[f64]) -> Vec<f64> {
        let mut y = x.to_vec();
        self.filter_in_place(&mut y);
        y
    }

    /// [`Butterworth::filter`] over `y` itself (no copy of a long record).
    pub fn filter_in_place(&self, y: &mut [f64]) {
        for s in &self.sections {
            let x0 = y.first().copied().unwrap_or(0.0);
            // Steady state for a constant input x0 (unity DC gain): z1, z2 such that y = x0.
            let mut z1 = x0 * (1.0 - s.b[0]);
            let mut z2 = x0 * (s.b[2] - s.a[1]);
            for v in y.iter_mut() {
                let xin = *v;
                let out = s.b[0] * xin + z1;
                z1 = s.b[1] * xin - s.a[0] * out + z2;
                z2 = s.b[2] * xin - s.a[1] * out;
                *v = out;
            }
        }
    }

    /// Zero-phase filtering: forward, then backward (the magnitude response squared, no lag).
    /// Both ends are extended by odd reflection (2·x₀ − x_k), which continues the signal's
    /// level and slope, so a record that starts or ends in motion has no edge transient.
    pub fn filtfilt(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        if n < 2 {
            return x.to_vec();
        }
        let pad = self.pad.min(n - 1);
        let mut ext = Vec::with_capacity(n + 2 * pad);
        ext.extend((1..=pad).rev().map(|k| 2.0 * x[0] - x[k]));
        ext.extend_from_slice(x);
        ext.extend((1..=pad).map(|k| 2.0 * x[n - 1] - x[n - 1 - k]));
        // In place: one buffer of the record's length (four copies were held before).
        self.filter_in_place(&mut ext);
        ext.reverse();
        self.filter_in_place(&mut ext);
        ext.reverse();
        ext.truncate(pad + n);
        ext.drain(..pad);
        ext
    }
}

/// Central difference dx/dt, one-sided at the ends.
pub fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    (0..n)
        .map(|i| {
            if i == 0 {
                (x[1] - x[0]) / dt
            } else if i == n - 1 {
                (x[n - 1] - x[n - 2]) / dt
            } else {
                (x[i + 1] - x[i - 1]) / (2.0 * dt)
            }
        })
        .collect()
}

/// Keeps every `factor`-th sample (apply a low-pass below the new Nyquist first).
pub fn downsample(x: &[f64], factor: usize) -> Vec<f64> {
    x.iter().step_by(factor.max(1)).copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_are_filled_from_the_valid_samples_at_their_instants() {
        let t = [0.0, 1.0, 2.0, 4.0, 5.0, 6.0];
        let v = [0.0, 99.0, 99.0, 4.0, 5.0, 99.0];
        let valid = |i: usize| v[i] != 99.0;
        // Linear in time (not in index) between 0 at t = 0 and 4 at t = 4; the last sample
        // beyond the valid span takes the last valid value, and is counted.
        let (f, outside) = fill_gaps(&t, &v, valid, false).unwrap();
        assert_eq!((f, outside), (vec![0.0, 1.0, 2.0, 4.0, 5.0, 5.0], 1));
        let (f, _) = fill_gaps(&t, &v, valid, true).unwrap();
        assert_eq!(f, vec![0.0, 0.0, 0.0, 4.0, 5.0, 5.0]);
        assert!(fill_gaps(&t, &v, |_| false, false).is_err());
    }

    fn sine(f: f64, fs: f64, n: usize) -> Vec<f64> {
        (0..n).map(|k| (2.0 * PI * f * k as f64 / fs).sin()).collect()
    }

    fn amplitude(x: &[f64]) -> f64 {
        let m = &x[x.len() / 4..3 * x.len() / 4];
        m.iter().fold(0.0f64, |a, v| a.max(v.abs()))
    }

    #[test]
    fn dot_is_the_sum_of_products_at_every_length() {
        // Integers times powers of two: every partial sum is exact, so any order gives the
        // same value and the lanes and the tail must add up to the plain sum.
        for n in [0usize, 1, 7, 8, 9, 16, 23, 1000] {
            let a: Vec<f64> = (0..n).map(|i| (i as f64 - 3.0) * 0.5).collect();
            let b: Vec<f64> = (0..n + 3).map(|i| ((i * 7) % 11) as f64 - 5.0).collect();
            let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert_eq!(dot(&a, &b), plain, "n = {n}");
            assert_eq!(dot(&b, &a), plain, "n = {n}, the shorter slice second");
        }
    }

    #[test]
    fn butterworth_has_minus_3db_at_cutoff_and_passes_dc() {
        let fs = 1000.0;
        let f = Butterworth::lowpass(4, 50.0, fs).unwrap();
        let at_fc = amplitude(&f.filter(&sine(50.0, fs, 8000)));
        assert!(
            (at_fc - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01,
            "gain at cut-off {at_fc}"
        );
        let pass = amplitude(&f.filter(&sine(5.0, fs, 8000)));
        assert!((pass - 1.0).abs() < 0.01);
        // 4th order: -80 dB/decade, so a decade above is below 1e-4 (plus ripple margin).
        let stop = amplitude(&f.filter(&sine(500.0, fs, 8000)));
        assert!(stop < 1e-3, "stop band {stop}");
        let dc = f.filter(&[3.0; 100]);
        assert!(dc.iter().all(|v| (v - 3.0).abs() < 1e-9));
    }

    #[test]
    fn filtfilt_has_no_lag() {
        let fs = 1000.0;
        let x = sine(2.0, fs, 4000);
        let y = Butterworth::lowpass(4, 40.0, fs).unwrap().filtfilt(&x);
        let err = x[500..3500]
            .iter()
            .zip(&y[500..3500])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-3, "zero-phase error {err}");
    }

    #[test]
    fn filtfilt_of_a_ramp_has_no_edge_transient() {
        // A record that starts and ends in motion: the filtered slope must be right at the ends.
        let x: Vec<f64> = (0..2000).map(|k| 0.1 * k as f64 / 1000.0).collect();
        let y = Butterworth::lowpass(4, 20.0, 1000.0).unwrap().filtfilt(&x);
        let v = derivative(&y, 1e-3);
        let worst = v.iter().map(|v| (v - 0.1).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-3 * 0.1, "slope off by {worst} at the edges");
    }

    #[test]
    fn derivative_of_a_parabola_is_exact_inside() {
        let x: Vec<f64> = (0..10).map(|k| (k as f64 * 0.1).powi(2)).collect();
        let d = derivative(&x, 0.1);
        for (k, v) in d.iter().enumerate().take(9).skip(1) {
            assert!((v - 2.0 * k as f64 * 0.1).abs() < 1e-9);
        }
    }

    #[test]
    fn rejects_a_cutoff_above_nyquist() {
        assert!(Butterworth::lowpass(2, 600.0, 1000.0).is_err());
    }
}
