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
        self.buf = [value; N];
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
        let whole = d.floor_nonneg_i32() as usize;
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

    /// The sample `delay_s` seconds ago for a line pushed every `dt_s` seconds.
    pub fn get_time(&self, delay_s: R, dt_s: R) -> R {
        self.get(delay_s / dt_s)
    }
}

/// Whole part of a non-negative value that fits in usize (the caller has clamped it to N-1).
#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Q32;
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
