//! Delay line for fixed and time-varying transport delays, such as the EHVVA's actuation
//! delay td(Ph, T) (Li 2018, eqs. (11), (14)). Heapless: `N` samples of history in a ring.
//!
//! One sample is pushed per simulation step; `get(d)` returns the input `d` steps ago, with
//! linear interpolation between samples for fractional `d`. Delays outside `0..=N-1` are
//! clamped (the caller sizes `N` for the longest delay it expects; `max_delay_samples` tells).

use crate::real::Real;

#[derive(Clone, Debug)]
pub struct DelayLine<R: Real, const N: usize> {
    buf: [R; N],
    /// Index of the newest sample.
    head: usize,
}

impl<R: Real, const N: usize> DelayLine<R, N> {
    /// A line whose whole history is `initial` (the value held before the simulation began).
    pub fn new(initial: R) -> Self {
        // N = 0 would make every index invalid; it is rejected at compile time.
        const { assert!(N >= 2, "a delay line needs at least two samples") };
        Self {
            buf: [initial; N],
            head: 0,
        }
    }

    /// Forgets the history: every past sample becomes `value`.
    pub fn fill(&mut self, value: R) {
        // In place: `self.buf = [value; N]` builds the array aside and copies it in.
        self.buf.fill(value);
    }

    /// Appends the newest sample, dropping the oldest.
    pub fn push(&mut self, x: R) {
        self.head = (self.head + 1) % N;
        self.buf[self.head] = x;
    }

    /// The newest sample (delay 0).
    pub fn newest(&self) -> R {
        self.buf[self.head]
    }

    pub const fn max_delay_samples(&self) -> usize {
        N - 1
    }

    /// The sample `delay_samples` steps ago, linearly interpolated; clamped to `0..=N-1`.
    #[inline]
    pub fn get(&self, delay_samples: R) -> R {
        let max = R::from_f64((N - 1) as f64);
        // `!(d > 0)` also catches a NaN delay from a float caller.
        let d = if !(delay_samples > R::ZERO) {
            R::ZERO
        } else if delay_samples > max {
            max
        } else {
            delay_samples
        };
        // d is in [0, N-1]: its integer part indexes the line (no f64 on the way: that is
        // soft-float on the target). The ring index wraps rather than checks: it stays in
        // range whatever `whole` is (no clamp on the target's path, no panic).
        let whole = d_whole(d);
        let frac = d - R::from_i32(whole as i32);
        let at = (self.head + N).wrapping_sub(whole) % N;
        let newer = self.buf[at];
        if whole >= N - 1 || frac <= R::ZERO {
            return newer;
        }
        // The sample before, one place back in the ring.
        let older = self.buf[(at + N - 1) % N];
        // frac in [0, 1): its product with any value is in range.
        newer + frac.mul_in_range(older - newer)
    }

    /// The line as [`DelayLine::get`] reads it at `delay_samples − back` for every `back` in
    /// [0, 1): the reads of one step's sub-steps, between two pushes. The clamping, the index
    /// and the three samples such a read can touch are worked out once; `None` where a read
    /// could be clamped (a delay below one sample or within two of the line's end, or NaN),
    /// for which `get` itself is the way.
    #[inline]
    pub fn span(&self, delay_samples: R) -> Option<DelaySpan<R>> {
        // `!(d >= 1)` also refuses NaN.
        if !(delay_samples >= R::ONE) || delay_samples > R::from_i32(N as i32 - 2) {
            return None;
        }
        // d in [1, N − 2]: so is its integer part, and d − back is in (0, N − 2].
        let whole = d_whole(delay_samples);
        let at = |k: usize| self.buf[(self.head + N).wrapping_sub(k) % N];
        Some(DelaySpan {
            delay_samples,
            whole: R::from_i32(whole as i32),
            whole_less_one: R::from_i32(whole as i32 - 1),
            newer: at(whole - 1),
            mid: at(whole),
            older: at(whole + 1),
        })
    }

    /// The sample `delay_s` seconds ago for a line pushed every `dt_s` seconds.
    pub fn get_time(&self, delay_s: R, dt_s: R) -> R {
        self.get(delay_s / dt_s)
    }
}

/// Whole part of a delay in samples already known to be in the line's range.
#[inline]
fn d_whole<R: Real>(d: R) -> usize {
    d.floor_nonneg_i32() as usize
}

/// A [`DelayLine`] read between two pushes at a delay `d` less some `back` in [0, 1), from
/// [`DelayLine::span`]. `at(back)` returns exactly `get(d − back)`: the same subtraction, the
/// same integer part (`d`'s or one less, as `d − back` falls) and the same interpolation.
#[derive(Clone, Copy, Debug)]
pub struct DelaySpan<R: Real> {
    delay_samples: R,
    /// `d`'s integer part w and w − 1, as values.
    whole: R,
    whole_less_one: R,
    /// The samples w − 1, w and w + 1 steps ago.
    newer: R,
    mid: R,
    older: R,
}

impl<R: Real> DelaySpan<R> {
    /// The line's value `delay_samples − back` steps ago, `back` in [0, 1).
    #[inline]
    pub fn at(&self, back: R) -> R {
        let x = self.delay_samples - back;
        let (whole, newer, older) = if x >= self.whole {
            (self.whole, self.mid, self.older)
        } else {
            (self.whole_less_one, self.newer, self.mid)
        };
        let frac = x - whole;
        if frac <= R::ZERO {
            return newer;
        }
        // frac in (0, 1): its product with any value is in range.
        newer + frac.mul_in_range(older - newer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::{Q16, Q32};
    use proptest::prelude::*;

    #[test]
    fn integer_delay_returns_past_samples_exactly() {
        let mut d = DelayLine::<f32, 8>::new(-1.0);
        for k in 0..5 {
            d.push(k as f32);
        }
        assert_eq!(d.get(0.0), 4.0);
        assert_eq!(d.get(3.0), 1.0);
        assert_eq!(d.get(4.0), 0.0);
        // Before the first push the history is the initial value.
        assert_eq!(d.get(6.0), -1.0);
        // Clamped at both ends, NaN treated as zero delay.
        assert_eq!(d.get(100.0), -1.0);
        assert_eq!(d.get(-3.0), 4.0);
        assert_eq!(d.get(f32::NAN), 4.0);
    }

    #[test]
    fn time_varying_delay_tracks_a_ramp() {
        // x(t) = t pushed every 1 ms; a delay that grows from 2 to 5 ms gives t - delay.
        let mut d = DelayLine::<f64, 64>::new(0.0);
        for k in 0..40 {
            let t_ms = k as f64;
            d.push(t_ms);
            if k >= 10 {
                let delay_ms = 2.0 + 3.0 * (k - 10) as f64 / 30.0;
                assert!((d.get_time(delay_ms, 1.0) - (t_ms - delay_ms)).abs() < 1e-9);
            }
        }
    }

    /// The span's reads where `d − back` lands on a sample exactly (quarter-sample delays and
    /// offsets), and on a non-linear history, bit for bit as `get`'s.
    #[test]
    fn span_reads_whole_samples_as_get_does() {
        let mut f = DelayLine::<f64, 32>::new(0.0);
        for k in 0..40 {
            f.push(libm::sin(0.7 * k as f64) * 10.0 + 0.1 * (k * k) as f64);
        }
        for quarter in 4..=120 {
            let d = quarter as f64 / 4.0;
            let s = f.span(d).unwrap();
            for back in [0.0, 0.25, 0.5, 0.75] {
                assert_eq!(s.at(back).to_bits(), f.get(d - back).to_bits(), "d {d} back {back}");
            }
        }
        assert!(f.span(0.99).is_none() && f.span(30.01).is_none() && f.span(f64::NAN).is_none());
    }

    proptest! {
        /// Fractional delays interpolate a linear signal exactly, in every number type.
        #[test]
        fn fractional_delay_is_exact_on_linear_signals(delay in 0.0f64..30.0, slope in -3.0f64..3.0) {
            let mut f = DelayLine::<f64, 32>::new(0.0);
            let mut q = DelayLine::<Q32, 32>::new(Q32::ZERO);
            for k in 0..40 {
                f.push(slope * k as f64);
                q.push(Q32::from_f64(slope * k as f64));
            }
            let expect = slope * (39.0 - delay);
            prop_assert!((f.get(delay) - expect).abs() < 1e-9);
            prop_assert!((q.get(Q32::from_f64(delay)).to_f64() - expect).abs() < 1e-7);
        }

        /// A span reads exactly what `get` reads at every sub-step's offset, in floats and in
        /// fixed point; it is refused where a read could be clamped, and `get` serves those.
        #[test]
        fn span_reads_the_bits_get_reads(xs in proptest::collection::vec(-100.0f64..100.0, 20..40),
                                          delay in -2.0f64..40.0, substeps in 1usize..12) {
            let mut f = DelayLine::<f64, 32>::new(xs[0]);
            let mut g = DelayLine::<f32, 32>::new(xs[0] as f32);
            let mut q = DelayLine::<Q16, 32>::new(Q16::from_f64(xs[0]));
            for &x in &xs {
                f.push(x);
                g.push(x as f32);
                q.push(Q16::from_f64(x));
            }
            let (df, dg, dq) = (delay, delay as f32, Q16::from_f64(delay));
            let in_range = (1.0..=30.0).contains(&delay);
            prop_assert_eq!(f.span(df).is_some(), in_range);
            let (sf, sg, sq) = (f.span(df), g.span(dg), q.span(dq));
            let (mut bf, mut bg, mut bq) = (0.0f64, 0.0f32, Q16::ZERO);
            let (nf, ng, nq) = (1.0 / substeps as f64, 1.0 / substeps as f32, Q16::ONE / Q16::from_i32(substeps as i32));
            for _ in 0..substeps {
                if let Some(s) = sf { prop_assert_eq!(s.at(bf).to_bits(), f.get(df - bf).to_bits()); }
                if let Some(s) = sg { prop_assert_eq!(s.at(bg).to_bits(), g.get(dg - bg).to_bits()); }
                if let Some(s) = sq { prop_assert_eq!(s.at(bq), q.get(dq - bq)); }
                bf += nf;
                bg += ng;
                bq += nq;
            }
        }

        /// The output always lies between the smallest and largest sample pushed.
        #[test]
        fn never_leaves_the_range_of_its_input(xs in proptest::collection::vec(-100.0f32..100.0, 1..50),
                                                delay in -10.0f32..100.0) {
            let mut d = DelayLine::<f32, 16>::new(xs[0]);
            for &x in &xs { d.push(x); }
            let lo = xs.iter().cloned().fold(f32::MAX, f32::min);
            let hi = xs.iter().cloned().fold(f32::MIN, f32::max);
            let y = d.get(delay);
            prop_assert!(y >= lo - 1e-4 && y <= hi + 1e-4);
        }
    }
}
