//! Pseudo-random binary signals for (closed-loop) system identification, as in Yang et al.
//! 2015 (EVVT), Section II, eqs. (3)-(10).
//!
//! - [`MSequence`]: the maximum-length sequence û(k) ∈ {0, 1} of eq. (5),
//!   `û(k+1) = p̂(z⁻¹) û(k) = a1 û(k) ⊕ a2 û(k−1) ⊕ … ⊕ an û(k−n+1)` (eq. (4): binary
//!   addition), started from `û(0) = 1`, `û(−1) = … = û(−n+1) = 0`. Its period is
//!   `m = 2ⁿ − 1` and it holds one more 1 than 0s per period.
//! - [`InversePrbs`]: the inverse PRBS of eqs. (6)-(8): `s(k) = a` for even k and `−a` for odd
//!   k, and `u(k) = s(k) ⊗ (−a + 2a·û(k))`, where ⊗ multiplies signs and keeps the magnitude
//!   a (eq. (8)). With m odd, `u(k + m) = −u(k)`, so u has period 2m, zero mean over it
//!   (eq. (9)) and the autocorrelation of eq. (10): `a²` at τ = 0, `−a²` at τ = m, `+a²/m` at
//!   odd τ and `−a²/m` at even τ. (The extracted text drops every digit '2'; "period of m" and
//!   the 1/m averages read 2m once the digit is restored, which is what the algebra gives.)
//! - [`Hold`]: holds each value of a signal for several control periods (a clock divider).
//!
//! The paper's Table I (nonzero coefficients per order) is garbled in the extracted text; the
//! feedback taps below are standard primitive polynomials (orders 2-11 the classic table the
//! paper cites, Peterson; 12-16 well-known maximal-length LFSR taps). The unit tests check that
//! every order reaches the full period 2ⁿ − 1, which is the proof of primitivity that matters
//! here. Table II of the paper uses order 9.
//!
//! Everything is a small state machine: no heap, `Iterator` implementations for convenience.

use crate::real::Real;

/// Smallest and largest supported orders n.
pub const MIN_ORDER: u8 = 2;
pub const MAX_ORDER: u8 = 16;

/// Tap sets (the i with a_i = 1 in eq. (3)) as a bit mask: bit i−1 set for a_i = 1. Index =
/// order − 2. Characteristic polynomial `1 + Σ a_i x^i`.
const TAP_MASKS: [u32; 15] = [
    taps(&[1, 2]),          // 2
    taps(&[2, 3]),          // 3
    taps(&[3, 4]),          // 4
    taps(&[3, 5]),          // 5
    taps(&[5, 6]),          // 6
    taps(&[6, 7]),          // 7
    taps(&[2, 3, 4, 8]),    // 8
    taps(&[5, 9]),          // 9
    taps(&[7, 10]),         // 10
    taps(&[9, 11]),         // 11
    taps(&[1, 4, 6, 12]),   // 12
    taps(&[1, 3, 4, 13]),   // 13
    taps(&[1, 3, 5, 14]),   // 14
    taps(&[14, 15]),        // 15
    taps(&[4, 13, 15, 16]), // 16
];

const fn taps(idx: &[u32]) -> u32 {
    let mut m = 0;
    let mut k = 0;
    while k < idx.len() {
        m |= 1 << (idx[k] - 1);
        k += 1;
    }
    m
}

/// Why a PRBS could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrbsError {
    /// `order` outside `MIN_ORDER..=MAX_ORDER`.
    Order(u8),
    /// `hold_periods` must be at least 1.
    HoldPeriods,
}

/// The m-sequence û(k) of eq. (5), as a shift register over GF(2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MSequence {
    /// Bit i holds û(k − i) for the next output index k.
    register: u32,
    tap_mask: u32,
    order: u8,
}

impl MSequence {
    /// Order n (period 2ⁿ − 1), with `û(0) = 1` and all earlier values 0.
    pub fn new(order: u8) -> Result<Self, PrbsError> {
        if !(MIN_ORDER..=MAX_ORDER).contains(&order) {
            return Err(PrbsError::Order(order));
        }
        let tap_mask = TAP_MASKS
            .get((order - MIN_ORDER) as usize)
            .copied()
            .ok_or(PrbsError::Order(order))?;
        Ok(Self {
            register: 1,
            tap_mask,
            order,
        })
    }

    pub fn order(&self) -> u8 {
        self.order
    }

    /// m = 2ⁿ − 1.
    pub fn period(&self) -> u32 {
        (1u32 << self.order) - 1
    }

    /// Returns û(k) and advances to k + 1 by eq. (5).
    pub fn next_bit(&mut self) -> bool {
        let out = self.register & 1 == 1;
        // û(k+1) = ⊕ a_i û(k+1−i): parity of the tapped history.
        let feedback = (self.register & self.tap_mask).count_ones() & 1;
        let mask = (1u32 << self.order) - 1;
        self.register = ((self.register << 1) | feedback) & mask;
        out
    }
}

impl Iterator for MSequence {
    type Item = bool;
    fn next(&mut self) -> Option<bool> {
        Some(self.next_bit())
    }
}

/// The inverse PRBS u(k) of eqs. (6)-(8), values ±a.
#[derive(Clone, Copy, Debug)]
pub struct InversePrbs<R: Real> {
    sequence: MSequence,
    amplitude: R,
    /// k is even (s(k) = +a).
    even: bool,
}

impl<R: Real> InversePrbs<R> {
    /// Order n of the underlying m-sequence and amplitude a (Section IV-B used a = 7.5 crank
    /// degrees around 25 degrees).
    pub fn new(order: u8, amplitude: R) -> Result<Self, PrbsError> {
        Ok(Self {
            sequence: MSequence::new(order)?,
            amplitude,
            even: true,
        })
    }

    /// 2m: the period of the inverse PRBS.
    pub fn period(&self) -> u32 {
        2 * self.sequence.period()
    }

    /// Returns u(k) and advances.
    pub fn next_value(&mut self) -> R {
        // −a + 2a û(k) is +a for û = 1, −a for û = 0; ⊗ with s(k) flips the sign on odd k.
        let positive = self.sequence.next_bit() == self.even;
        self.even = !self.even;
        if positive {
            self.amplitude
        } else {
            -self.amplitude
        }
    }
}

impl<R: Real> Iterator for InversePrbs<R> {
    type Item = R;
    fn next(&mut self) -> Option<R> {
        Some(self.next_value())
    }
}

/// Holds each value of an infinite signal for `hold_periods` calls, so a PRBS clocked at a
/// slower rate drives a faster control loop (the paper's multi-rate setup, Table II).
#[derive(Clone, Copy, Debug)]
pub struct Hold<I: Iterator> {
    source: I,
    hold_periods: u32,
    remaining: u32,
    current: Option<I::Item>,
}

impl<I: Iterator> Hold<I>
where
    I::Item: Copy,
{
    pub fn new(source: I, hold_periods: u32) -> Result<Self, PrbsError> {
        if hold_periods == 0 {
            return Err(PrbsError::HoldPeriods);
        }
        Ok(Self {
            source,
            hold_periods,
            remaining: 0,
            current: None,
        })
    }
}

impl<I: Iterator> Iterator for Hold<I>
where
    I::Item: Copy,
{
    type Item = I::Item;
    fn next(&mut self) -> Option<I::Item> {
        if self.remaining == 0 {
            self.current = self.source.next();
            self.remaining = self.hold_periods;
        }
        self.remaining -= 1;
        self.current
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Q32;
    use proptest::prelude::*;

    /// Every order reaches the maximal period 2ⁿ − 1 (the register never repeats earlier) and
    /// holds 2ⁿ⁻¹ ones and 2ⁿ⁻¹ − 1 zeros per period.
    #[test]
    fn every_order_is_maximal_length_and_balanced() {
        for n in MIN_ORDER..=MAX_ORDER {
            let mut s = MSequence::new(n).unwrap();
            let m = s.period();
            assert_eq!(m, (1 << n) - 1);
            let start = s;
            let mut ones = 0u32;
            let mut first_return = None;
            for k in 1..=m {
                if s.next_bit() {
                    ones += 1;
                }
                if s == start && first_return.is_none() {
                    first_return = Some(k);
                }
            }
            assert_eq!(first_return, Some(m), "order {n} returns after {first_return:?}");
            assert_eq!(ones, 1 << (n - 1), "order {n}");
            assert_eq!(m - ones, ones - 1);
        }
    }

    #[test]
    fn starts_with_one_then_follows_the_recurrence() {
        // Order 3, taps a2, a3: û(k+1) = û(k−1) ⊕ û(k−2). From û(0)=1, û(−1)=û(−2)=0:
        // û(1) = 0, û(2) = 1, û(3) = 1, û(4) = 1, û(5) = 0, û(6) = 0, then û(7) = û(0).
        let bits: [bool; 8] = core::array::from_fn({
            let mut s = MSequence::new(3).unwrap();
            move |_| s.next_bit()
        });
        assert_eq!(bits, [true, false, true, true, true, false, false, true]);
    }

    #[test]
    fn rejects_bad_orders_and_holds() {
        assert_eq!(MSequence::new(1).unwrap_err(), PrbsError::Order(1));
        assert_eq!(MSequence::new(17).unwrap_err(), PrbsError::Order(17));
        assert!(Hold::new(MSequence::new(4).unwrap(), 0).is_err());
    }

    #[test]
    fn hold_repeats_each_value() {
        let direct: [bool; 20] = core::array::from_fn({
            let mut s = MSequence::new(5).unwrap();
            move |_| s.next_bit()
        });
        let mut held = Hold::new(MSequence::new(5).unwrap(), 3).unwrap();
        for k in 0..60 {
            assert_eq!(held.next(), Some(direct[k / 3]));
        }
    }

    /// Mean, anti-periodicity and the autocorrelation of eqs. (9), (10), exactly (integers).
    fn check_inverse_prbs(n: u8) {
        let mut u = InversePrbs::<f64>::new(n, 1.0).unwrap();
        let m = (1usize << n) - 1;
        assert_eq!(u.period() as usize, 2 * m);
        let mut buf = [0i32; 2 * 2047];
        let period = 2 * m;
        for v in buf.iter_mut().take(period) {
            *v = u.next_value() as i32;
        }
        // Period 2m and u(k+m) = −u(k).
        for k in 0..period {
            assert_eq!(u.next_value() as i32, buf[k]);
        }
        for k in 0..m {
            assert_eq!(buf[k + m], -buf[k]);
        }
        assert_eq!(buf[..period].iter().sum::<i32>(), 0);
        for tau in 0..period {
            let r: i32 = (0..period).map(|k| buf[(k + tau) % period] * buf[k]).sum();
            // R(τ)·2m with a = 1: 2m, −2m, +2, −2.
            let expect = if tau == 0 {
                period as i32
            } else if tau == m {
                -(period as i32)
            } else if tau % 2 == 1 {
                2
            } else {
                -2
            };
            assert_eq!(r, expect, "order {n}, tau {tau}");
        }
    }

    #[test]
    fn inverse_prbs_mean_and_autocorrelation_orders_2_to_11() {
        for n in 2..=11 {
            check_inverse_prbs(n);
        }
    }

    proptest! {
        /// u(k) is always ±a, in fixed point too, and anti-periodic with half-period m.
        #[test]
        fn inverse_prbs_values_are_plus_minus_a(n in 2u8..=12, a in 0.1f64..50.0, k0 in 0usize..4000) {
            let mut u = InversePrbs::<Q32>::new(n, Q32::from_f64(a)).unwrap();
            let m = (1usize << n) - 1;
            let qa = Q32::from_f64(a);
            for _ in 0..k0 { u.next_value(); }
            // u(k0 + j) against u(k0 + j + m) for the first m values: a full buffer would need
            // the heap, so compare against a second generator running m ahead.
            let mut ahead = u;
            for _ in 0..m { ahead.next_value(); }
            for _ in 0..m {
                let (now, later) = (u.next_value(), ahead.next_value());
                prop_assert!(now == qa || now == -qa);
                prop_assert_eq!(later, -now);
            }
        }
    }
}
