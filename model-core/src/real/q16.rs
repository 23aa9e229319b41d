//! [`Q16`]: Q16.16 fixed point for the FPU-less ECUs, and the integer routines of its
//! functions (square root, exp, ln, sin, atan, tan in Q2.30).

use super::*;

/// Signed Q16.16 fixed point in an `i32`: range ±32768, resolution 1.5e-5, saturating like
/// [`Q32`]. Made for the FPU-less Cortex-M0+/M3 ECUs: a product is one 32×32→64 multiply
/// (`smull`, a single instruction on the M3/M4) and a shift, so a model step costs a small
/// multiple of its f32 step, where Q32.32 needs 128-bit intermediates (about 30×).
///
/// Models that run in it keep their signals within the range and well above the resolution;
/// each plant's tests measure its error against f64 over its operating envelope.
/// Products round to nearest (an integrator fed truncated products would drift by half an
/// LSB per step); the functions work in Q2.30 internally, errors in `real/tests.rs`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Q16(pub(super) i32);

impl Q16 {
    /// The largest value, 32767.99998.
    pub const MAX: Q16 = Q16(i32::MAX);
    /// The most negative value, -32768.
    pub const MIN: Q16 = Q16(i32::MIN);
    /// Resolution: one least significant bit, 2^-16.
    pub const LSB: Q16 = Q16(1);
    /// Fractional bits.
    pub const FRAC_BITS: u32 = 16;

    /// The raw integer (value · 2^16).
    pub const fn to_bits(self) -> i32 {
        self.0
    }
    /// From the raw integer (value · 2^16).
    pub const fn from_bits(bits: i32) -> Self {
        Q16(bits)
    }

    #[inline(always)]
    pub(super) fn saturate(x: i64) -> Q16 {
        // It fits when the high word is the low word's sign extension (two 32-bit compares of
        // a 64-bit clamp cost twice as many instructions); else the limit of x's sign.
        let hi = (x >> 32) as i32;
        let lo = x as i32;
        if hi != (lo >> 31) {
            Q16((hi >> 31) ^ i32::MAX)
        } else {
            Q16(lo)
        }
    }
}

/// A Q16.16 divisor prepared for repeated division ([`Real::divisor`], [`Real::div_by`]): a
/// reciprocal normalised to 30 bits and its shift.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Q16Divisor {
    m: i32,
    shift: u32,
    /// Half the shift's unit, for rounding.
    half: i64,
}

impl Add for Q16 {
    type Output = Q16;
    #[inline(always)]
    fn add(self, rhs: Q16) -> Q16 {
        Q16(self.0.saturating_add(rhs.0))
    }
}
impl Sub for Q16 {
    type Output = Q16;
    #[inline(always)]
    fn sub(self, rhs: Q16) -> Q16 {
        Q16(self.0.saturating_sub(rhs.0))
    }
}
impl Mul for Q16 {
    type Output = Q16;
    #[inline(always)]
    fn mul(self, rhs: Q16) -> Q16 {
        let p = i64::from(self.0) * i64::from(rhs.0) + (1 << 15);
        // Bits 16..47 of the product; it fits when bits 47..63 all equal the sign (checked on
        // the high word alone: a few instructions, where a 64-bit clamp takes a dozen).
        let hi = (p >> 32) as i32;
        let r = (p >> 16) as i32;
        if (hi >> 15) != (r >> 31) {
            // MAX for a positive product, MIN for a negative one: the sign of a·b, from the
            // factors' signs (the product is far from zero here). Taken from `p`, the compiler
            // multiplied a second time to compare it with zero: 16 instructions a product
            // on the Cortex-M4, 11 this way.
            Q16(((self.0 ^ rhs.0) >> 31) ^ i32::MAX)
        } else {
            Q16(r)
        }
    }
}
impl Div for Q16 {
    type Output = Q16;
    fn div(self, rhs: Q16) -> Q16 {
        let (a, b) = (self.0, rhs.0);
        if b == 0 {
            return match a.cmp(&0) {
                core::cmp::Ordering::Less => Q16::MIN,
                core::cmp::Ordering::Greater => Q16::MAX,
                core::cmp::Ordering::Equal => Q16(0),
            };
        }
        // |a| < 0.5: the shifted dividend fits 32 bits, one hardware division (truncating,
        // like the path below).
        if a > -(1 << 15) && a < (1 << 15) {
            return Q16((a << 16) / b);
        }
        // |a|·2^16 / |b| truncated, with the sign after: what `(a << 16) / b` in i64 gives,
        // without the 64-bit division routine (about 270 instructions on the Cortex-M).
        let q = div_48_by_32(u64::from(a.unsigned_abs()) << 16, b.unsigned_abs());
        if (a < 0) != (b < 0) {
            if q > 1 << 31 {
                Q16::MIN
            } else {
                Q16((q as u32).wrapping_neg() as i32)
            }
        } else if q > i32::MAX as u64 {
            Q16::MAX
        } else {
            Q16(q as i32)
        }
    }
}

/// Σ aₖ·bₖ times 2^32 plus half of Q16.16's LSB (2^15): the exact sum, ready to be shifted
/// by 16 and rounded once. Each product is below 2^61 by the callers' contract
/// ([`Real::sum_of_products`]), so four cannot overflow; debug builds check every addition.
#[inline(always)]
fn exact_sum_of_products<const K: usize>(terms: [(Q16, Q16); K]) -> i64 {
    const { assert!(K >= 1 && K <= 4, "sum_of_products: one to four terms") };
    // Unrolled by hand (constant indices): a loop stays a loop at the firmware's opt-level.
    let term = |k: usize| {
        let p = i64::from(terms[k].0 .0) * i64::from(terms[k].1 .0);
        debug_assert!(p.unsigned_abs() < 1 << 61, "sum_of_products: a term above 2^29");
        p
    };
    let mut sum: i64 = (1 << 15) + term(0);
    if K > 1 {
        sum = sum.wrapping_add(term(1));
    }
    if K > 2 {
        sum = sum.wrapping_add(term(2));
    }
    if K > 3 {
        sum = sum.wrapping_add(term(3));
    }
    sum
}

/// `n / d` truncated for `n < 2^48` and `d > 0`, or `2^32` when the quotient does not fit 32
/// bits: long division in two base-2^16 digits (Knuth's algorithm D for a two-digit divisor),
/// each digit estimated by one 32-bit hardware division and corrected at most twice.
#[inline(always)]
fn div_48_by_32(n: u64, d: u32) -> u64 {
    if (n >> 32) as u32 >= d {
        return 1 << 32;
    }
    // Normalise: the divisor's top bit set (n < d·2^32 still fits 64 bits after the shift).
    let s = d.leading_zeros();
    let d = d << s;
    let n = n << s;
    let (dh, dl) = (d >> 16, d & 0xFFFF);
    let n1 = (n >> 32) as u32;
    let n0 = n as u32;
    let digit = |top: u32, next: u32| -> (u32, u32) {
        // top < d; the digit q = (top·2^16 + next) / d < 2^16, estimated from dh alone
        // (too large by at most 2).
        let mut q = top / dh;
        let mut r = top - q * dh;
        while q >= 1 << 16 || q * dl > ((r << 16) | next) {
            q -= 1;
            r += dh;
            if r >= 1 << 16 {
                break;
            }
        }
        // The remainder, below d: exact in wrapping arithmetic.
        (q, ((top << 16) | next).wrapping_sub(q.wrapping_mul(d)))
    };
    // A quotient below 2^16 (a fraction's: τ/(τ + h)) has no high digit: n1 < dh puts
    // n1·2^16 + the next 16 bits below d, so the high digit is 0 and that is its remainder.
    let (q1, r1) = if n1 < dh {
        (0, (n1 << 16) | (n0 >> 16))
    } else {
        digit(n1, n0 >> 16)
    };
    let (q0, _) = digit(r1, n0 & 0xFFFF);
    (u64::from(q1) << 16) | u64::from(q0)
}
impl Neg for Q16 {
    type Output = Q16;
    #[inline(always)]
    fn neg(self) -> Q16 {
        Q16(self.0.saturating_neg())
    }
}
impl AddAssign for Q16 {
    #[inline(always)]
    fn add_assign(&mut self, rhs: Q16) {
        *self = *self + rhs;
    }
}
impl SubAssign for Q16 {
    #[inline(always)]
    fn sub_assign(&mut self, rhs: Q16) {
        *self = *self - rhs;
    }
}
impl MulAssign for Q16 {
    #[inline(always)]
    fn mul_assign(&mut self, rhs: Q16) {
        *self = *self * rhs;
    }
}

impl Real for Q16 {
    const ZERO: Self = Q16(0);
    const ONE: Self = Q16(1 << 16);
    const NAME: &'static str = "Q16.16";
    const IS_FLOAT: bool = false;
    const RANGE_ABS: f64 = 32768.0;
    const ABS_RESOLUTION: f64 = 1.0 / 65536.0;
    type Divisor = Q16Divisor;
    /// `m = round(2^(30+p) / |d|)` with p the index of |d|'s leading one, so m is in
    /// [2^29, 2^30] (carrying d's sign) and `x / d = x · m / 2^(14+p)`: relative error below
    /// 2^-29, far under the result's LSB. A zero divisor keeps `m = i32::MAX` and no shift, so
    /// any nonzero dividend saturates towards its sign (1 LSB of -1 gives MIN + 1).
    #[inline]
    fn divisor(d: Self) -> Q16Divisor {
        let ud = d.0.unsigned_abs();
        if ud == 0 {
            return Q16Divisor {
                m: i32::MAX,
                shift: 0,
                half: 0,
            };
        }
        let p = 31 - ud.leading_zeros();
        // The dividend's high word, 2^(p-2), is below ud >= 2^p: the quotient fits 32 bits and
        // the two-digit long division applies, where the 64-bit division routine takes about
        // 270 instructions (a divisor made at run time: a rate's first step). A constant
        // divisor made this way is no longer folded by the compiler: the hot paths keep
        // theirs in the state, made once.
        let m = div_48_by_32((1u64 << (30 + p)) + u64::from(ud / 2), ud) as i32;
        Q16Divisor {
            m: if d.0 < 0 { -m } else { m },
            shift: 14 + p,
            half: 1 << (13 + p),
        }
    }
    #[inline(always)]
    fn div_by(self, d: Q16Divisor) -> Self {
        let p = i64::from(self.0) * i64::from(d.m);
        Q16::saturate((p + d.half) >> d.shift)
    }
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        // Constants fold at compile time; a run-time conversion is soft-float on the M0+/M3.
        // `as` saturates and maps NaN to 0.
        let s = x * 65536.0;
        Q16::saturate((if s >= 0.0 { s + 0.5 } else { s - 0.5 }) as i64)
    }
    fn to_f64(self) -> f64 {
        f64::from(self.0) / 65536.0
    }
    fn floor_i32(self) -> i32 {
        self.0 >> 16
    }
    fn from_i32(n: i32) -> Self {
        Q16::saturate(i64::from(n) << 16)
    }
    #[inline(always)]
    fn mul_in_range(self, rhs: Self) -> Self {
        let p = i64::from(self.0) * i64::from(rhs.0) + (1 << 15);
        debug_assert!(
            (p >> 16) == i64::from((p >> 16) as i32),
            "mul_in_range: {} * {} leaves the Q16.16 range",
            self.to_f64(),
            rhs.to_f64()
        );
        Q16((p >> 16) as i32)
    }
    #[inline(always)]
    fn mul_floor_in_range(self, rhs: Self) -> Self {
        let p = i64::from(self.0) * i64::from(rhs.0);
        debug_assert!(
            (p >> 16) == i64::from((p >> 16) as i32),
            "mul_floor_in_range: {} * {} leaves the Q16.16 range",
            self.to_f64(),
            rhs.to_f64()
        );
        Q16((p >> 16) as i32)
    }
    #[inline(always)]
    fn mul_pow2(self, exp: i32) -> Self {
        debug_assert!((-16..=16).contains(&exp), "mul_pow2: exponent {exp} outside -16..=16");
        if exp >= 0 {
            // The product x·2^e is exact; it only saturates.
            Q16::saturate(i64::from(self.0) << exp)
        } else {
            // The product rounds (x·2^(16+e) + 2^15) >> 16 = floor((x + 2^(n-1)) / 2^n) for
            // n = -e: the shifted value plus the last bit shifted out, without the sum's overflow.
            let n = (-exp) as u32;
            Q16((self.0 >> n) + ((self.0 >> (n - 1)) & 1))
        }
    }
    #[inline(always)]
    fn sum_of_products<const K: usize>(terms: [(Self, Self); K]) -> Self {
        let sum = exact_sum_of_products(terms);
        // As `*`'s test: bits 16..47 fit when bits 47..63 all equal the sign; else the limit
        // of the sum's sign.
        let hi = (sum >> 32) as i32;
        let r = (sum >> 16) as i32;
        if (hi >> 15) != (r >> 31) {
            Q16((hi >> 31) ^ i32::MAX)
        } else {
            Q16(r)
        }
    }
    #[inline(always)]
    fn sum_of_products_in_range<const K: usize>(terms: [(Self, Self); K]) -> Self {
        let p = exact_sum_of_products(terms) >> 16;
        debug_assert!(
            p == i64::from(p as i32),
            "sum_of_products_in_range leaves the Q16.16 range"
        );
        Q16(p as i32)
    }
    #[inline(always)]
    fn split_pow2(self, exp: u32) -> (Self, Self) {
        let whole = self.mul_pow2(-(exp as i32));
        // self − whole·2^exp is in [−2^(exp−1), 2^(exp−1)]: exact modulo 2^32.
        (whole, Q16(self.0.wrapping_sub(whole.0.wrapping_shl(exp))))
    }
    #[inline(always)]
    fn mul_shr(self, rhs: Self, exp: u32) -> Self {
        debug_assert!(exp <= 16, "mul_shr: exponent {exp} outside 0..=16");
        // As `*` with the result's bits 16 + exp.. of the product: it fits when the bits from
        // 47 + exp up all equal its sign (|p| < 2^62, so neither the rounding nor the shifts
        // overflow).
        let p = i64::from(self.0) * i64::from(rhs.0) + (1 << (15 + exp));
        let hi = (p >> (32 + exp)) as i32;
        let r = (p >> (16 + exp)) as i32;
        if (hi >> 15) != (r >> 31) {
            Q16(((self.0 ^ rhs.0) >> 31) ^ i32::MAX)
        } else {
            Q16(r)
        }
    }
    #[inline(always)]
    fn mul_shr_in_range(self, rhs: Self, exp: u32) -> Self {
        debug_assert!(exp <= 16, "mul_shr_in_range: exponent {exp} outside 0..=16");
        debug_assert!(
            u64::from(rhs.0.unsigned_abs()) < 1 << (16 + exp),
            "mul_shr_in_range: |{}| is not below 2^{exp}",
            rhs.to_f64()
        );
        let p = i64::from(self.0) * i64::from(rhs.0) + (1 << (15 + exp));
        Q16((p >> (16 + exp)) as i32)
    }
    fn step_times(self, k: Self, x: Self) -> Self {
        // |k| < 1 where this is used (a reciprocal mass in m/s per ms per N), so k·x cannot
        // overflow where x does not.
        self * (k * x)
    }
    fn sqrt(self) -> Self {
        Q16(q16_sqrt(self.0))
    }
    fn exp(self) -> Self {
        Q16(q16_exp(self.0))
    }
    fn atan(self) -> Self {
        Q16(q16_atan(self.0))
    }
    fn sin(self) -> Self {
        Q16(q16_sin(self.0))
    }
    fn ln(self) -> Self {
        Q16(q16_ln(self.0))
    }
    fn tan(self) -> Self {
        Q16(q16_tan(self.0))
    }
}

/// Horner's scheme on integer coefficients `$c` (highest degree first) with the product
/// `$mul`: `s = c[0]`, then `s = c[k] + mul(x, s)` for the listed k, written out (a loop is
/// not unrolled in the size-optimised firmware: ~5 instructions an iteration).
macro_rules! horner_int {
    ($mul:expr, $x:expr, $c:expr; $($k:literal),+) => {{
        let mut s = $c[0];
        $(s = $c[$k] + $mul($x, s);)+
        s
    }};
}

/// `a·b` of two Q2.30 numbers, rounded.
#[inline(always)]
fn mul30(a: i32, b: i32) -> i32 {
    ((i64::from(a) * i64::from(b) + (1 << 29)) >> 30) as i32
}

/// `round(y · 2^shift)` of a non-negative `y`, saturating (shift may be negative).
#[inline(always)]
fn shift_round(y: i64, shift: i32) -> i32 {
    let v = if shift >= 0 {
        if shift > 31 {
            return i32::MAX;
        }
        y << shift
    } else if shift < -62 {
        0
    } else {
        (y + (1 << (-shift - 1))) >> -shift
    };
    v.min(i64::from(i32::MAX)) as i32
}

/// sqrt of a raw Q16.16: normalised to a 32-bit radicand `n` in [2^30, 2^32) with an even
/// shift, its integer root (in [2^15, 2^16]) by two Newton steps on the hardware's 32-bit
/// division from the best straight line through sqrt on that range (relative error < 3.1 %,
/// then < 5e-4, < 1.2e-7), corrected to the exact floor and rounded once: below 1.0 the
/// correctly rounded root, above it 16 result bits (relative error < 2^-16). The bit-by-bit
/// root it replaces took 16 rounds of about 7 instructions.
fn q16_sqrt(x: i32) -> i32 {
    if x <= 0 {
        return 0;
    }
    // sqrt(x·2^-16)·2^16 = sqrt(x·2^16) = sqrt(x·2^s)·2^((16-s)/2), s even, x·2^s in [2^30, 2^32).
    let lz = x.leading_zeros() as i32; // >= 1
    let s = lz & !1;
    let n = (x as u32) << s;
    // 2^15 (0.686 + 0.34375 n/2^30): within 3.1 % of sqrt(n) on the range.
    let mut r = 22_479 + (((n >> 15) * 11) >> 5);
    // r > 2^14 and n < 2^32 keep n / r < 2^18 and the sum within 32 bits. Integer Newton
    // steps end at or above floor(sqrt(n)) whatever the start.
    r = (r + n / r) >> 1;
    r = (r + n / r) >> 1;
    // At most one above the floor here (2^16 · 1.2e-7 < 1); r·r fits 32 bits below 2^16.
    while r >= 1 << 16 || r * r > n {
        r -= 1;
    }
    let shift = (16 - s) / 2;
    // Round to nearest once: below 1.0 (a right shift) the floor root shifted with rounding
    // is the rounded result; above, the root itself is rounded (its next bit is 1 when
    // n - r² > r) and scaled up exactly.
    if shift >= 0 && n - r * r > r {
        r += 1;
    }
    shift_round(i64::from(r), shift)
}

/// exp of a raw Q16.16: `2^k · e^r`, `|r| <= ln2/2` in Q2.30, Taylor polynomial to r^7
/// (truncation < 3e-9 relative).
fn q16_exp(x: i32) -> i32 {
    // e^10.3972 = 32768: above saturates; below -11.8 the result rounds to 0.
    if x > 681_391 {
        return i32::MAX;
    }
    if x < -773_325 {
        return 0;
    }
    // k = round(x / ln2): 1/ln2 in Q0.16 · x, rounded at bit 32.
    let k = ((i64::from(x) * 94_548 + (1 << 31)) >> 32) as i32;
    const LN2_Q30: i64 = 744_261_118;
    let r = ((i64::from(x) << 14) - i64::from(k) * LN2_Q30) as i32;
    // 1/n! in Q2.30, n = 7..0.
    const C: [i32; 8] = [
        213_044,
        1_491_308,
        8_947_849,
        44_739_243,
        178_956_971,
        536_870_912,
        1_073_741_824,
        1_073_741_824,
    ];
    let y = horner_int!(mul30, r, C; 1, 2, 3, 4, 5, 6, 7);
    // y in Q2.30 → Q16.16 · 2^k
    shift_round(i64::from(y), k - 14)
}

/// ln of a raw Q16.16: `x = 2^e · m`, `m = (1 + i/16)(1 + t)` with the table below and
/// `|t| < 1/16`, `ln(1+t)` by its series to t^6 (error < 3e-9).
fn q16_ln(x: i32) -> i32 {
    if x <= 0 {
        return i32::MIN;
    }
    // m in [1, 2) as Q2.30.
    let top = 31 - x.leading_zeros() as i32; // bit index of the leading one, 0..=30
    let m = ((x as u32) << (30 - top)) as i32;
    let i = ((m >> 26) & 15) as usize; // m ≈ 1 + i/16
                                       // t = m / (1 + i/16) − 1 = (m − c)·(1/c), in Q2.30.
    let c = (1 << 30) + ((i as i32) << 26);
    let t = mul30(m - c, INV_1_PLUS_I16_Q30[i]);
    // ln(1+t) = t − t²/2 + t³/3 − … (Horner from t^6).
    const C: [i32; 6] = [
        -178_956_971,
        214_748_365,
        -268_435_456,
        357_913_941,
        -536_870_912,
        1_073_741_824,
    ];
    let s = horner_int!(mul30, t, C; 1, 2, 3, 4, 5);
    let ln_m = i64::from(mul30(t, s)) + i64::from(LN_1_PLUS_I16_Q30[i]);
    // ln x = ln m + (top − 16)·ln2, back to Q16.16 (rounded).
    const LN2_Q30: i64 = 744_261_118;
    let v = ln_m + i64::from(top - 16) * LN2_Q30;
    ((v + (1 << 13)) >> 14) as i32
}

/// `1/(1 + i/16)` in Q2.30, i = 0..15.
const INV_1_PLUS_I16_Q30: [i32; 16] = {
    let mut t = [0i32; 16];
    let mut i = 0;
    while i < 16 {
        // 2^30·16/(16+i), rounded.
        let num: i64 = (1i64 << 34) + (16 + i as i64) / 2;
        t[i] = (num / (16 + i as i64)) as i32;
        i += 1;
    }
    t
};

/// `ln(1 + i/16)` in Q2.30, i = 0..15 (values of libm::log, rounded).
const LN_1_PLUS_I16_Q30: [i32; 16] = [
    0,
    65_095_192,
    126_468_572,
    184_522_808,
    239_598_564,
    291_986_604,
    341_937_090,
    389_666_807,
    435_364_845,
    479_197_128,
    521_310_048,
    561_833_416,
    600_882_877,
    638_561_895,
    674_963_409,
    710_171_213,
];

/// sin of a raw Q16.16: the angle as a fraction of a turn (exact wrap-around in a u32), folded
/// to [-π/2, π/2], Taylor polynomial to r^11 in Q4.28 (truncation < 2.4e-7).
fn q16_sin(x: i32) -> i32 {
    // turns · 2^32 = x · 2^16 / (2π): the constant 2^32/(2π) = 683 565 275.576 as its whole
    // part and its fraction in 1/65536 (the whole part alone, rounded, was 6e-10 off: at
    // 30 000 rad that turned the angle by 1.8e-5 rad, more than the result's LSB).
    const TURN_WHOLE: i64 = 683_565_275;
    const TURN_FRAC_Q16: i64 = 37_777;
    let x64 = i64::from(x);
    let phase = ((x64 * TURN_WHOLE + ((x64 * TURN_FRAC_Q16) >> 16) + (1 << 15)) >> 16) as u32;
    // Fold: sin(π − a) = sin a; work on a signed quarter-turn in [-1/4, 1/4] of a turn.
    let mut p = phase as i32; // [-1/2, 1/2) turn
    if p > (1 << 30) {
        p = (1i32 << 31).wrapping_sub(p); // π − a
    } else if p < -(1 << 30) {
        p = (-(1i64 << 31) - i64::from(p)) as i32; // −π − a
    }
    // r in rad, Q4.28: p · 2π / 2^32 · 2^28 = p · 2π / 16.
    const TWO_PI_Q28: i64 = 1_686_629_713;
    let r = ((i64::from(p) * TWO_PI_Q28 + (1 << 31)) >> 32) as i32;
    let mul28 = |a: i32, b: i32| ((i64::from(a) * i64::from(b) + (1 << 27)) >> 28) as i32;
    let r2 = mul28(r, r);
    // sin r = r(1 − r²/6 + r⁴/120 − …), coefficients (−1)^n/(2n+1)! in Q4.28, n = 5..0.
    const C: [i32; 6] = [-7, 740, -53_261, 2_236_962, -44_739_243, 268_435_456];
    let mut s = C[0];
    for &c in &C[1..] {
        s = c + mul28(r2, s);
    }
    let y = i64::from(mul28(r, s));
    ((y + (1 << 11)) >> 12) as i32
}

/// atan of a raw Q16.16: |x| > 1 through π/2 − atan(1/x), then the polynomial of Abramowitz
/// and Stegun 4.4.49 on [0, 1] (error < 1e-5 rad), in Q2.30.
fn q16_atan(x: i32) -> i32 {
    let neg = x < 0;
    let a = i64::from(x).abs();
    let inverted = a > (1 << 16);
    // a in Q2.30, in [0, 1].
    let a30 = if inverted {
        ((1i64 << 46) / a) as i32
    } else {
        (a << 14) as i32
    };
    const C: [i32; 5] = [22_371_518, -91_410_863, 193_424_926, -354_656_388, 1_073_597_943];
    let a2 = mul30(a30, a30);
    let s = horner_int!(mul30, a2, C; 1, 2, 3, 4);
    let mut y = mul30(a30, s);
    if inverted {
        const HALF_PI_Q30: i32 = 1_686_629_713;
        y = HALF_PI_Q30 - y;
    }
    let y16 = (y + (1 << 13)) >> 14;
    if neg {
        -y16
    } else {
        y16
    }
}

/// The step of Q16.16's tangent table, 2^-7 rad: a segment's index is the angle's raw bits
/// shifted right by 9.
const TAN_STEP_RAD: f64 = 1.0 / 128.0;
/// Segments of the table: [0, 1.5] rad (the range the arctan spring uses, [`q16_tan`]).
const TAN_SEGMENTS: usize = 192;
/// Fraction bits of the table's coefficients: Q5.26 holds tan(1.5) = 14.1 with room.
const TAN_COEFF_FRAC: i32 = 26;

/// sin x and cos x for |x| <= 1.6 by their Taylor series to the 40th power (the last term
/// below 1e-40): the table's values, in f64 at compile time.
const fn sin_cos_series(x: f64) -> (f64, f64) {
    let (mut sin, mut cos) = (0.0, 0.0);
    let (mut term_sin, mut term_cos) = (x, 1.0);
    let mut k = 0;
    while k < 20 {
        sin += term_sin;
        cos += term_cos;
        let n = 2.0 * k as f64;
        term_sin *= -x * x / ((n + 2.0) * (n + 3.0));
        term_cos *= -x * x / ((n + 1.0) * (n + 2.0));
        k += 1;
    }
    (sin, cos)
}

/// `v` in Q5.26, rounded to nearest (const: `f64::round` is not).
const fn q5_26(v: f64) -> i32 {
    let s = v * (1u32 << TAN_COEFF_FRAC) as f64;
    (if s >= 0.0 { s + 0.5 } else { s - 0.5 }) as i32
}

/// Per segment the cubic Hermite interpolant of tan through both ends with their slopes
/// 1 + tan², as coefficients of u in [0, 1] (c0 + u(c1 + u(c2 + u c3))), Q5.26.
const TAN_TABLE: [[i32; 4]; TAN_SEGMENTS] = {
    let mut table = [[0; 4]; TAN_SEGMENTS];
    let h = TAN_STEP_RAD;
    let mut i = 0;
    while i < TAN_SEGMENTS {
        let (s0, c0) = sin_cos_series(i as f64 * h);
        let (s1, c1) = sin_cos_series((i + 1) as f64 * h);
        let (t0, t1) = (s0 / c0, s1 / c1);
        let (d0, d1) = (h * (1.0 + t0 * t0), h * (1.0 + t1 * t1));
        table[i] = [
            q5_26(t0),
            q5_26(d0),
            q5_26(3.0 * (t1 - t0) - 2.0 * d0 - d1),
            q5_26(2.0 * (t0 - t1) + d0 + d1),
        ];
        i += 1;
    }
    table
};

/// tan of a raw Q16.16 angle, |x| limited to 1.5 rad (tan 14.1; the vacuum actuator's
/// arctan spring keeps its angle there): a cubic Hermite table of 192 segments of 2^-7 rad
/// (3 KiB of constants computed at compile time), three products a call. Error relative to
/// max(1, |tan|) below 8.1e-6: the interpolant's, largest at 1.5 rad where tan's fourth
/// derivative is, and the rounding. The series with two double-angle steps and a long
/// division it replaces took about 150 instructions on the Cortex-M4, and a vacuum rod
/// step takes one a sub-step.
fn q16_tan(x: i32) -> i32 {
    const LIM: u32 = 98_304; // 1.5 · 2^16
    let a = x.unsigned_abs().min(LIM);
    // Segment index and the position in it, u in Q2.30 (a = LIM is the last segment's end).
    let i = ((a >> 9) as usize).min(TAN_SEGMENTS - 1);
    let u = ((a - ((i as u32) << 9)) << 21) as i32;
    let c = TAN_TABLE[i];
    let mut p = c[2] + mul30(u, c[3]);
    p = c[1] + mul30(u, p);
    p = c[0] + mul30(u, p);
    // Q5.26 to Q16.16, rounded.
    let q = (p + (1 << 9)) >> 10;
    if x < 0 {
        -q
    } else {
        q
    }
}
