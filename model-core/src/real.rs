//! The number types the plants and controllers run on.
//!
//! Every model in this crate is written once, generic over [`Real`], and runs in three
//! number types:
//! - `f32`: what the target runs (Cortex-M4F single-precision FPU); transcendental functions
//!   come from `micromath`, so host and target compute the same bits.
//! - `f64`: the host reference (`libm`), against which the other two are measured.
//! - [`Q32`]: signed Q32.32 fixed point with saturating arithmetic, for targets or code paths
//!   that must be bit-exact and free of floating point.
//!
//! Models therefore work in engineering units (mm, ms, MPa, kPa, crank degrees, rpm) chosen so
//! that every intermediate stays between about 1e-6 and 1e6: Q32.32 resolves 2.3e-10 and
//! saturates at ±2.1e9.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// Horner's scheme `c0 + x·(c1 + x·(c2 + …))` in the number type `$R` with literal f64
/// coefficients, unrolled by the macro so that every coefficient converts at compile time: in
/// a loop, `R::from_f64` runs at run time, which on the target is soft-float double arithmetic
/// (hundreds of instructions per coefficient).
macro_rules! horner {
    ($R:ty, $x:expr; $c0:expr) => {
        <$R as $crate::real::Real>::from_f64($c0)
    };
    ($R:ty, $x:expr; $c0:expr, $($c:expr),+) => {
        <$R as $crate::real::Real>::from_f64($c0) + $x * horner!($R, $x; $($c),+)
    };
}
pub(crate) use horner;

/// [`horner!`] with [`Real::mul_in_range`] products: for an argument and coefficients whose
/// partial sums stay far inside the type's range (|x| <= 2 and coefficients below 1, as in the
/// callers' series; each caller says why).
macro_rules! horner_in_range {
    ($R:ty, $x:expr; $c0:expr) => {
        <$R as $crate::real::Real>::from_f64($c0)
    };
    ($R:ty, $x:expr; $c0:expr, $($c:expr),+) => {
        <$R as $crate::real::Real>::from_f64($c0)
            + $crate::real::Real::mul_in_range($x, horner_in_range!($R, $x; $($c),+))
    };
}
pub(crate) use horner_in_range;

/// A real number as the models need it: field operations plus the few functions the physics
/// uses. All functions are total: `sqrt` of a negative number is 0, division by zero saturates.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    const ZERO: Self;
    const ONE: Self;
    /// Short name for reports and benchmark labels.
    const NAME: &'static str;
    /// The floats (f32, f64): IEEE arithmetic, where a division is one FPU instruction and
    /// `x·0` is not always 0 (signed zeros, NaN). Models keep their float code exactly as it
    /// is, and with it the operations of their f64 results; where this is false (fixed point:
    /// a long division of about a hundred instructions, a product of ten, `x·0 + y == y`
    /// exactly) they may take forms with fewer divisions, or skip products with zero.
    const IS_FLOAT: bool;
    /// The largest magnitude the type holds (fixed point saturates there).
    const RANGE_ABS: f64;
    /// The spacing of a fixed-point type's values (Q16.16: 2^-16), 0 for the floats, whose
    /// spacing is relative. A constant given to a fixed-point model is off by up to half of it.
    const ABS_RESOLUTION: f64;

    /// Converts a constant (parameters, table values). Out-of-range values saturate.
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    fn from_f32(x: f32) -> Self {
        Self::from_f64(x as f64)
    }
    fn to_f32(self) -> f32 {
        self.to_f64() as f32
    }
    /// The largest integer not above `self`, saturating at the i32 range (NaN gives 0). The
    /// types override it with their own instructions (through f64 it is soft-float on the
    /// target).
    fn floor_i32(self) -> i32 {
        libm::floor(self.to_f64()) as i32
    }
    /// [`Real::floor_i32`] of a value known not to be negative (an index): the floats truncate,
    /// one instruction, where `floor_i32` must also step down for negative non-integers. A
    /// negative value gives some integer, no panic.
    fn floor_nonneg_i32(self) -> i32 {
        self.floor_i32()
    }
    /// An integer as `Self` (exact where the type holds it; saturating).
    fn from_i32(n: i32) -> Self {
        Self::from_f64(f64::from(n))
    }
    /// `self · k · x` for a small step `self` times a small gain `k` (a time step times a
    /// reciprocal mass). Floats multiply left to right; a narrow fixed-point type overrides it
    /// to form `k · x` first, because `self · k` alone can be a few LSB (10 µs over 0.18 kg is
    /// 1.8 LSB of Q16.16, rounded to 2: an 11 % faster piston).
    fn step_times(self, k: Self, x: Self) -> Self {
        self * k * x
    }
    /// `self · rhs` where the caller has proven the product within the type's range (a weight
    /// in [0, 1] times a value, a series term below 1; the proof in a comment at the call):
    /// the bits of `*` there. Q16.16 rounds as `*` does but skips the saturation test, which
    /// costs 7 of its product's 11 instructions on the Cortex-M4 and keeps the compiler from
    /// folding the rest; debug builds assert the claim.
    #[inline(always)]
    fn mul_in_range(self, rhs: Self) -> Self {
        self * rhs
    }
    /// [`Real::mul_in_range`] rounded down (towards −∞) in fixed point: an error of at most one
    /// LSB, always the same way, for 3 instructions where rounding to nearest takes 5 on the
    /// Cortex-M4. For the arithmetic of coefficients (a table's interpolation, a series, a
    /// discretization), whose error enters the model as a relative error of the coefficient;
    /// never for an increment that an integrator sums (it would drift). The floats round as `*`.
    #[inline(always)]
    fn mul_floor_in_range(self, rhs: Self) -> Self {
        self.mul_in_range(rhs)
    }
    /// `self · 2^exp` for a constant `exp` in -16..=16: the scalings of the models' scaled
    /// states (a time in 1/1024 s, a position in 1/1024 m). The bits of `self ·
    /// from_f64(2^exp)` in every type; Q16.16 shifts instead of multiplying (3 instructions for
    /// the product's 11 on the Cortex-M4).
    #[inline(always)]
    fn mul_pow2(self, exp: i32) -> Self {
        self * Self::from_f64(pow2_f64(exp))
    }

    /// `a₀·b₀ + a₁·b₁ + …` over `terms` (at least one), left to right: the floats' bits of
    /// that expression (write a difference as the sum with a negated factor: IEEE's `x + (−y)`
    /// is `x − y`). Fixed point sums the exact products and rounds and saturates once, where
    /// each product alone would round and saturate (on the Cortex-M4, 11 instructions a
    /// product; here one multiply-accumulate a term and one saturation). Fixed point's
    /// contract: every product below 2^29 in magnitude (one factor of each pair a unit
    /// constant below 2^13, the other any value of Q16.16), so the exact sum of four cannot
    /// overflow its accumulator; debug builds check it.
    #[inline(always)]
    fn sum_of_products<const K: usize>(terms: [(Self, Self); K]) -> Self {
        // Unrolled by hand with constant indices: at the firmware's size-optimised level a
        // loop over the array stayed a loop through the stack.
        const { assert!(K >= 1 && K <= 4, "sum_of_products: one to four terms") };
        let mut sum = terms[0].0 * terms[0].1;
        if K > 1 {
            sum += terms[1].0 * terms[1].1;
        }
        if K > 2 {
            sum += terms[2].0 * terms[2].1;
        }
        if K > 3 {
            sum += terms[3].0 * terms[3].1;
        }
        sum
    }
    /// [`Real::sum_of_products`] where the caller has proven the sum within the type's range
    /// (weights in [0, 1] that add up to at most 1, times values): rounded once, not
    /// saturated; debug builds assert the claim.
    #[inline(always)]
    fn sum_of_products_in_range<const K: usize>(terms: [(Self, Self); K]) -> Self {
        Self::sum_of_products(terms)
    }

    /// `self · 2^-exp` rounded to the type (`whole`, as [`Real::mul_pow2`] gives it) and what
    /// that rounding left, `self − whole · 2^exp` (`rest`), for a constant `exp` in 0..=16:
    /// an increment held times 2^exp split into the part a state can take now and the part
    /// carried to the next step. The rest is exact (|rest| ≤ 2^(exp−1) LSB), so Q16.16 forms
    /// it in wrapping arithmetic even where `whole · 2^exp` alone would leave the range.
    #[inline(always)]
    fn split_pow2(self, exp: u32) -> (Self, Self) {
        let whole = self.mul_pow2(-(exp as i32));
        (whole, self - whole.mul_pow2(exp as i32))
    }

    /// `self · rhs · 2^-exp` (`exp` in 0..=16) for a factor held times 2^exp because the type
    /// would round it too coarsely (a 5 µs sub-step is 327.5 LSB of Q16.16: 0.15 % off). The
    /// floats multiply and scale, exactly as `(self * rhs).mul_pow2(-exp)`; Q16.16 shifts its
    /// 64-bit product by 16 + exp and rounds once, at the cost of `*`, saturating as `*` does.
    #[inline(always)]
    fn mul_shr(self, rhs: Self, exp: u32) -> Self {
        (self * rhs).mul_pow2(-(exp as i32))
    }

    /// [`Real::mul_shr`] where `|rhs| < 2^exp`, so that the product is below `|self|` and in
    /// range whatever `self` is (a constant of a sub-step held times 2^exp because it is a
    /// fraction of an LSB, times a force or a pressure): the bits of `mul_shr` there, without
    /// its saturation test (7 of Q16.16's 13 instructions on the Cortex-M4); debug builds
    /// assert the claim. The caller's constructor refuses a constant that breaks it.
    #[inline(always)]
    fn mul_shr_in_range(self, rhs: Self, exp: u32) -> Self {
        self.mul_shr(rhs, exp)
    }

    /// Square root; 0 for negative arguments (never NaN).
    fn sqrt(self) -> Self;
    /// Exponential; saturates instead of overflowing.
    fn exp(self) -> Self;
    /// Arc tangent in radians.
    fn atan(self) -> Self;
    /// Sine of an angle in radians.
    fn sin(self) -> Self;
    /// Natural logarithm; the most negative finite value for arguments <= 0 (never NaN).
    fn ln(self) -> Self;
    /// Tangent of an angle in radians for |θ| <= 1.5 (callers keep it there: beyond, the
    /// result is finite but not promised to be accurate). By default the odd series at θ/4 and
    /// two double-angle steps in `Self`; Q16.16 interpolates a table of cubic segments.
    fn tan(self) -> Self {
        tan_series(self)
    }

    fn abs(self) -> Self {
        if self < Self::ZERO {
            -self
        } else {
            self
        }
    }
    /// -1, 0 or +1 (0 at exactly zero, unlike `f32::signum`).
    fn sign(self) -> Self {
        if self > Self::ZERO {
            Self::ONE
        } else if self < Self::ZERO {
            -Self::ONE
        } else {
            Self::ZERO
        }
    }
    fn min(self, other: Self) -> Self {
        if other < self {
            other
        } else {
            self
        }
    }
    fn max(self, other: Self) -> Self {
        if other > self {
            other
        } else {
            self
        }
    }
    /// Clamps into `[lo, hi]` (expects `lo <= hi`).
    fn clamp(self, lo: Self, hi: Self) -> Self {
        self.max(lo).min(hi)
    }

    /// A divisor prepared once for many divisions by it ([`Real::div_by`]).
    type Divisor: Copy + Debug;
    /// Prepares `d` as a divisor. The floats keep `d` (their division is one FPU instruction,
    /// and [`Real::div_by`] then gives the bits of `/`); Q16.16 keeps a normalised reciprocal,
    /// so that each division is one multiply instead of a long division.
    fn divisor(d: Self) -> Self::Divisor;
    /// `self / d` for `d` from [`Real::divisor`]: the bits of `/` in f32, f64 and Q32.32; in
    /// Q16.16 the quotient rounded to nearest (`/` truncates), saturating.
    fn div_by(self, d: Self::Divisor) -> Self;
}

/// Whether the number type `R` holds `x` (> 0) as a nonzero value: false for a fixed-point
/// type whose resolution is coarser (Q16.16 for 1e-6). A series whose next term is below `x`
/// can stop there in such a type; folded at compile time.
#[inline(always)]
pub(crate) fn resolves<R: Real>(x: f64) -> bool {
    R::from_f64(x) != R::ZERO
}

/// 2^exp as an f64, exact for exp in the normal range (-1022..=1023); built from its bits so it
/// folds at compile time for a constant exp.
#[inline(always)]
const fn pow2_f64(exp: i32) -> f64 {
    f64::from_bits(((1023 + exp) as u64) << 52)
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const NAME: &'static str = "f32";
    const IS_FLOAT: bool = true;
    const RANGE_ABS: f64 = f32::MAX as f64;
    const ABS_RESOLUTION: f64 = 0.0;
    type Divisor = f32;
    #[inline(always)]
    fn divisor(d: Self) -> Self {
        d
    }
    #[inline(always)]
    fn div_by(self, d: Self) -> Self {
        self / d
    }
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn floor_i32(self) -> i32 {
        // `as` truncates towards zero (one vcvt) and saturates; step down for negative
        // non-integers.
        let t = self as i32;
        if (t as f32) > self {
            t - 1
        } else {
            t
        }
    }
    fn floor_nonneg_i32(self) -> i32 {
        self as i32
    }
    fn from_i32(n: i32) -> Self {
        n as f32
    }
    fn sqrt(self) -> Self {
        // libm's sqrtf is correctly rounded; micromath's is off by up to 6 % relative
        // (test `micromath_sqrt_error_measured`), which the orifice equations would amplify.
        if self > 0.0 {
            libm::sqrtf(self)
        } else {
            0.0
        }
    }
    fn exp(self) -> Self {
        // micromath's exp loses accuracy far from zero; split off powers of two so the
        // polynomial only sees |r| <= ln2/2.
        exp_by_halving(self, micromath::F32Ext::exp)
    }
    fn atan(self) -> Self {
        // micromath's own atan is off by up to 2.6e-3 rad (test `micromath_atan_error_measured`),
        // too coarse for the vacuum actuator's arctan position map.
        atan_series(self)
    }
    fn sin(self) -> Self {
        micromath::F32Ext::sin(self)
    }
    fn ln(self) -> Self {
        if self > 0.0 {
            libm::logf(self)
        } else {
            f32::MIN
        }
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const NAME: &'static str = "f64";
    const IS_FLOAT: bool = true;
    const RANGE_ABS: f64 = f64::MAX;
    const ABS_RESOLUTION: f64 = 0.0;
    type Divisor = f64;
    #[inline(always)]
    fn divisor(d: Self) -> Self {
        d
    }
    #[inline(always)]
    fn div_by(self, d: Self) -> Self {
        self / d
    }
    fn from_f64(x: f64) -> Self {
        x
    }
    fn to_f64(self) -> f64 {
        self
    }
    fn floor_nonneg_i32(self) -> i32 {
        self as i32
    }
    fn sqrt(self) -> Self {
        if self > 0.0 {
            libm::sqrt(self)
        } else {
            0.0
        }
    }
    fn exp(self) -> Self {
        libm::exp(self)
    }
    fn atan(self) -> Self {
        libm::atan(self)
    }
    fn sin(self) -> Self {
        libm::sin(self)
    }
    fn ln(self) -> Self {
        if self > 0.0 {
            libm::log(self)
        } else {
            f64::MIN
        }
    }
}

/// `exp(x) = 2^k · exp(r)` with `|r| <= ln2/2`, `base` evaluating `exp(r)`.
fn exp_by_halving(x: f32, base: impl Fn(f32) -> f32) -> f32 {
    const LN2: f32 = core::f32::consts::LN_2;
    if x > 88.0 {
        return f32::MAX;
    }
    if x < -87.0 {
        return 0.0;
    }
    let k = {
        let q = x / LN2;
        // round half away from zero without std
        if q >= 0.0 {
            (q + 0.5) as i32
        } else {
            (q - 0.5) as i32
        }
    };
    let r = x - k as f32 * LN2;
    let mut y = base(r);
    let step = if k >= 0 { 2.0 } else { 0.5 };
    for _ in 0..k.unsigned_abs() {
        y *= step;
    }
    y
}

/// tan θ for |θ| <= 1.5 without relying on the target's sin/cos: the odd Taylor series to
/// z¹⁵ at z = θ/4 and two double-angle steps (f64: < 1e-10 relative over the range).
///
/// θ/4 as θ·0.25 (the same bits in floating point; no division in fixed point) and the
/// coefficients through `horner!` (converted at compile time, not in a run-time loop).
pub(crate) fn tan_series<R: Real>(theta: R) -> R {
    let z = theta * R::from_f64(0.25);
    let z2 = z * z;
    // tan z = z(1 + z²/3 + 2z⁴/15 + 17z⁶/315 + 62z⁸/2835 + 1382z¹⁰/155925 + 21844z¹²/6081075
    //          + 929569z¹⁴/638512875)
    let s = horner!(R, z2; 1.0, 1.0 / 3.0, 2.0 / 15.0, 17.0 / 315.0, 62.0 / 2835.0, 1382.0 / 155925.0,
        21844.0 / 6081075.0, 929569.0 / 638512875.0);
    let t = z * s;
    if R::IS_FLOAT {
        let mut t = t;
        for _ in 0..2 {
            t = (t + t) / (R::ONE - t * t);
        }
        t
    } else {
        // Both double-angle steps at once, one division: tan 4z = 4t(1 − t²)/(1 − 6t² + t⁴).
        let t2 = t * t;
        let four_t = t * R::from_f64(4.0);
        (four_t * (R::ONE - t2)) / (R::ONE - R::from_f64(6.0) * t2 + t2 * t2)
    }
}

/// atan for f32 and Q32: octant reduction to |x| <= 1, two argument halvings
/// `atan x = 2 atan(x / (1 + sqrt(1 + x²)))` to |x| <= 0.2, then the odd Taylor series to x^11.
fn atan_series<R: Real>(x: R) -> R {
    let half_pi = R::from_f64(core::f64::consts::FRAC_PI_2);
    let neg = x < R::ZERO;
    let mut a = x.abs();
    let inverted = a > R::ONE;
    if inverted {
        a = R::ONE / a;
    }
    let mut scale = R::ONE;
    for _ in 0..2 {
        a = a / (R::ONE + (R::ONE + a * a).sqrt());
        scale = scale + scale;
    }
    let a2 = a * a;
    let mut s = R::ZERO;
    let mut n: i32 = 11;
    while n >= 1 {
        let term = R::ONE / R::from_f64(n as f64);
        let signed = if (n / 2) % 2 == 0 { term } else { -term };
        s = signed + a2 * s;
        n -= 2;
    }
    let mut y = scale * a * s;
    if inverted {
        y = half_pi - y;
    }
    if neg {
        -y
    } else {
        y
    }
}

// The fixed-point types, one file each.
mod q16;
mod q32;
pub use q16::{Q16Divisor, Q16};
pub use q32::Q32;

#[cfg(test)]
mod tests;
