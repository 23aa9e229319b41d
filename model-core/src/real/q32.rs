//! [`Q32`]: Q32.32 fixed point through the `fixed` crate, and its ln, exp and sin.

use fixed::types::I32F32;

use super::*;

/// Signed Q32.32 fixed point with saturating arithmetic: overflow clamps to the range limits
/// and division by zero gives the limit of the dividend's sign, so no operation can panic.
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
pub struct Q32(pub I32F32);

impl Q32 {
    pub const MAX: Q32 = Q32(I32F32::MAX);
    pub const MIN: Q32 = Q32(I32F32::MIN);
    /// Resolution: one least significant bit.
    pub const LSB: Q32 = Q32(I32F32::DELTA);
    pub fn to_bits(self) -> i64 {
        self.0.to_bits()
    }
    pub fn from_bits(bits: i64) -> Self {
        Q32(I32F32::from_bits(bits))
    }
}

impl Add for Q32 {
    type Output = Q32;
    fn add(self, rhs: Q32) -> Q32 {
        Q32(self.0.saturating_add(rhs.0))
    }
}
impl Sub for Q32 {
    type Output = Q32;
    fn sub(self, rhs: Q32) -> Q32 {
        Q32(self.0.saturating_sub(rhs.0))
    }
}
impl Mul for Q32 {
    type Output = Q32;
    fn mul(self, rhs: Q32) -> Q32 {
        Q32(self.0.saturating_mul(rhs.0))
    }
}
impl Div for Q32 {
    type Output = Q32;
    fn div(self, rhs: Q32) -> Q32 {
        if rhs.0 == I32F32::ZERO {
            if self.0 < I32F32::ZERO {
                Q32::MIN
            } else if self.0 > I32F32::ZERO {
                Q32::MAX
            } else {
                Q32(I32F32::ZERO)
            }
        } else {
            Q32(self.0.saturating_div(rhs.0))
        }
    }
}
impl Neg for Q32 {
    type Output = Q32;
    fn neg(self) -> Q32 {
        Q32(self.0.saturating_neg())
    }
}
impl AddAssign for Q32 {
    fn add_assign(&mut self, rhs: Q32) {
        *self = *self + rhs;
    }
}
impl SubAssign for Q32 {
    fn sub_assign(&mut self, rhs: Q32) {
        *self = *self - rhs;
    }
}
impl MulAssign for Q32 {
    fn mul_assign(&mut self, rhs: Q32) {
        *self = *self * rhs;
    }
}

impl Real for Q32 {
    const ZERO: Self = Q32(I32F32::ZERO);
    const ONE: Self = Q32(I32F32::ONE);
    const NAME: &'static str = "Q32.32";
    const IS_FLOAT: bool = false;
    const RANGE_ABS: f64 = 2147483648.0;
    const ABS_RESOLUTION: f64 = 1.0 / 4294967296.0;
    type Divisor = Q32;
    fn divisor(d: Self) -> Self {
        d
    }
    fn div_by(self, d: Self) -> Self {
        self / d
    }
    fn from_f64(x: f64) -> Self {
        // NaN maps to zero; out-of-range values saturate.
        Q32(I32F32::saturating_from_num(if x.is_nan() { 0.0 } else { x }))
    }
    fn to_f64(self) -> f64 {
        self.0.to_num::<f64>()
    }
    fn floor_i32(self) -> i32 {
        (self.0.to_bits() >> 32) as i32
    }
    fn from_i32(n: i32) -> Self {
        Q32::from_bits(i64::from(n) << 32)
    }
    fn sqrt(self) -> Self {
        if self.0 > I32F32::ZERO {
            Q32(self.0.sqrt())
        } else {
            Self::ZERO
        }
    }
    fn exp(self) -> Self {
        q32_exp(self)
    }
    fn atan(self) -> Self {
        atan_series(self)
    }
    fn sin(self) -> Self {
        q32_sin(self)
    }
    fn ln(self) -> Self {
        q32_ln(self)
    }
}

/// ln in fixed point: `x = m · 2^k` with m in [1, 2), `ln m = 2 atanh((m-1)/(m+1))` by its odd
/// series (|z| <= 1/3, terms to z^15: error < 1e-9).
fn q32_ln(x: Q32) -> Q32 {
    if x <= Q32::ZERO {
        return Q32::MIN;
    }
    let mut m = x;
    let mut k: i32 = 0;
    let two = q(2.0);
    while m >= two {
        m = Q32(m.0 >> 1u32);
        k += 1;
    }
    while m < Q32::ONE {
        m = Q32(m.0 << 1u32);
        k -= 1;
    }
    let z = (m - Q32::ONE) / (m + Q32::ONE);
    let z2 = z * z;
    let mut s = Q32::ZERO;
    let mut n: i32 = 15;
    while n >= 1 {
        s = Q32::ONE / q(n as f64) + z2 * s;
        n -= 2;
    }
    q(2.0) * z * s + Q32(q(core::f64::consts::LN_2).0.saturating_mul_int(k as i64))
}

fn q(x: f64) -> Q32 {
    Q32::from_f64(x)
}

/// exp in fixed point: `2^k · exp(r)`, `|r| <= ln2/2`, Taylor series to r^9 (error < 1e-9).
fn q32_exp(x: Q32) -> Q32 {
    // exp(21.49) is the largest value below 2^31.
    if x > q(21.48) {
        return Q32::MAX;
    }
    if x < q(-22.2) {
        return Q32::ZERO;
    }
    let ln2 = q(core::f64::consts::LN_2);
    let mut k: i32 = 0;
    let mut r = x;
    let half_ln2 = q(core::f64::consts::LN_2 / 2.0);
    while r > half_ln2 {
        r -= ln2;
        k += 1;
    }
    while r < -half_ln2 {
        r += ln2;
        k -= 1;
    }
    // Horner evaluation of sum r^n/n!, n = 0..9.
    let mut y = Q32::ONE;
    let mut n = 9;
    while n >= 1 {
        y = Q32::ONE + r * y / q(n as f64);
        n -= 1;
    }
    if k >= 0 {
        Q32(y.0.saturating_mul_int(1i64 << k))
    } else {
        Q32(y.0 >> (-k) as u32)
    }
}

/// sin in fixed point: reduction to [-π/2, π/2] and the Taylor series to x^13.
fn q32_sin(x: Q32) -> Q32 {
    let pi = q(core::f64::consts::PI);
    let two_pi = q(2.0 * core::f64::consts::PI);
    let half_pi = q(core::f64::consts::FRAC_PI_2);
    // Reduce to [-π, π] by whole turns (division keeps this O(1) for large angles).
    let turns = ((x + pi) / two_pi).0.floor();
    let mut r = x - Q32(turns) * two_pi;
    if r > half_pi {
        r = pi - r;
    } else if r < -half_pi {
        r = -pi - r;
    }
    let r2 = r * r;
    let mut s = Q32::ONE;
    let mut n: i32 = 13;
    while n >= 3 {
        // s = 1 - r²/((n-1) n) · s
        s = Q32::ONE - r2 * s / q(((n - 1) * n) as f64);
        n -= 2;
    }
    r * s
}
