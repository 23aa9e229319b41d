//! 1-D and 2-D lookup tables with linear interpolation and clamped ends, as calibration
//! engineers know them from ECU maps. Breakpoints must be strictly increasing; that is checked
//! once, at construction, so evaluation never fails.

use crate::real::Real;

/// Why a table could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LutError {
    /// Breakpoints are not strictly increasing at this index (the axis: 0 = x, 1 = y).
    NotIncreasing { axis: u8, index: usize },
    /// A table needs at least two breakpoints per axis.
    TooFewPoints,
    /// In fixed point, a table value beyond 1/16 of the type's range (index in row-major
    /// order): the interpolation's products are then proven in range (see `check_values`).
    ValueOutOfRange { index: usize },
}

/// Index of the interval holding `x` and the interpolation weight in it, clamped to the ends.
/// `inv_dx[i]` = 1/(axis[i+1] − axis[i]), precomputed so a look-up divides nothing (a
/// fixed-point division is a long software division on the target).
fn locate<R: Real, const N: usize>(axis: &[R; N], inv_dx: &[R; N], x: R) -> (usize, R) {
    if x <= axis[0] {
        return (0, R::ZERO);
    }
    if x >= axis[N - 1] {
        return (N - 2, R::ONE);
    }
    // Tables are small (<= 16 points): a linear scan is cheaper than bisection on the target.
    let mut i = 0;
    while i + 2 < N && x >= axis[i + 1] {
        i += 1;
    }
    // In range: 0 <= x − axis[i] <= the spacing and inv_dx[i] its reciprocal (rounded by at
    // most half an LSB), so the weight is within [0, 2) in any type (see `check_values`).
    let w = (x - axis[i]).mul_floor_in_range(inv_dx[i]);
    (i, w)
}

/// The reciprocal breakpoint spacings of `axis` (the last entry unused, 0).
fn inverse_spacing<R: Real, const N: usize>(axis: &[f64; N]) -> [R; N] {
    let mut inv = [R::ZERO; N];
    for i in 0..N.saturating_sub(1) {
        inv[i] = R::from_f64(1.0 / (axis[i + 1] - axis[i]));
    }
    inv
}

/// In fixed point, every table value within 1/16 of the range (2048 in Q16.16): the look-ups
/// then multiply without the saturation test ([`Real::mul_in_range`]). Why it holds: a weight
/// `w = (x − x_i)·(1/Δx)` is at most `(Δx + 1 LSB)·(1/Δx + ½ LSB)`, below 2 for any spacing
/// the type holds; with |z| <= L an interpolated value `(1 − w)·z_a + w·z_b` stays within 3L,
/// a difference of two within 6L, and a weight times it within 12L < the range. The floats
/// take any table.
fn check_values<R: Real>(values: impl Iterator<Item = f64>) -> Result<(), LutError> {
    if R::IS_FLOAT {
        return Ok(());
    }
    let limit = R::RANGE_ABS / 16.0;
    match values.enumerate().find(|(_, v)| !(v.abs() <= limit)) {
        Some((index, _)) => Err(LutError::ValueOutOfRange { index }),
        None => Ok(()),
    }
}

fn check_axis(axis: &[f64], which: u8) -> Result<(), LutError> {
    if axis.len() < 2 {
        return Err(LutError::TooFewPoints);
    }
    for i in 1..axis.len() {
        // Written so NaN fails too.
        if !(axis[i] > axis[i - 1]) {
            return Err(LutError::NotIncreasing { axis: which, index: i });
        }
    }
    Ok(())
}

/// y = f(x) by linear interpolation between `N` breakpoints, constant beyond the ends.
#[derive(Clone, Copy, Debug)]
pub struct Lut1<R: Real, const N: usize> {
    x: [R; N],
    inv_dx: [R; N],
    y: [R; N],
}

impl<R: Real, const N: usize> Lut1<R, N> {
    pub fn new(x: [f64; N], y: [f64; N]) -> Result<Self, LutError> {
        check_axis(&x, 0)?;
        check_values::<R>(y.iter().copied())?;
        Ok(Self {
            x: x.map(R::from_f64),
            inv_dx: inverse_spacing(&x),
            y: y.map(R::from_f64),
        })
    }
    pub fn eval(&self, x: R) -> R {
        let (i, w) = locate(&self.x, &self.inv_dx, x);
        self.y[i] + w.mul_floor_in_range(self.y[i + 1] - self.y[i])
    }
    /// Where `x` lies on the breakpoints, for [`Self::eval_at`]: tables on the same
    /// breakpoints then share one look-up.
    #[inline]
    pub fn locate(&self, x: R) -> LutPoint<R, N> {
        let (i, w) = locate(&self.x, &self.inv_dx, x);
        LutPoint { i, w }
    }
    /// The value at a point located on this table's breakpoints (or on equal ones):
    /// `t.eval_at(t.locate(x)) == t.eval(x)`.
    #[inline]
    pub fn eval_at(&self, p: LutPoint<R, N>) -> R {
        let LutPoint { i, w } = p;
        self.y[i] + w.mul_floor_in_range(self.y[i + 1] - self.y[i])
    }
    pub fn breakpoints(&self) -> &[R; N] {
        &self.x
    }
    pub fn values(&self) -> &[R; N] {
        &self.y
    }
}

/// A point located on the breakpoints of an `N`-point [`Lut1`]: the interval (below N − 1) and
/// the weight in it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LutPoint<R, const N: usize> {
    i: usize,
    w: R,
}

/// A point located on the grid of an `NX` × `NY` [`Lut2`]: the cells (below NX − 1, NY − 1)
/// and the weights in them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LutPoint2<R, const NX: usize, const NY: usize> {
    i: usize,
    wx: R,
    j: usize,
    wy: R,
}

/// z = f(x, y) by bilinear interpolation on an `NX` × `NY` grid, clamped at the edges.
/// `z[i][j]` is the value at `(x[i], y[j])`.
#[derive(Clone, Copy, Debug)]
pub struct Lut2<R: Real, const NX: usize, const NY: usize> {
    x: [R; NX],
    y: [R; NY],
    inv_dx: [R; NX],
    inv_dy: [R; NY],
    z: [[R; NY]; NX],
}

impl<R: Real, const NX: usize, const NY: usize> Lut2<R, NX, NY> {
    pub fn new(x: [f64; NX], y: [f64; NY], z: [[f64; NY]; NX]) -> Result<Self, LutError> {
        check_axis(&x, 0)?;
        check_axis(&y, 1)?;
        check_values::<R>(z.iter().flatten().copied())?;
        Ok(Self {
            x: x.map(R::from_f64),
            y: y.map(R::from_f64),
            inv_dx: inverse_spacing(&x),
            inv_dy: inverse_spacing(&y),
            z: z.map(|row| row.map(R::from_f64)),
        })
    }
    pub fn eval(&self, x: R, y: R) -> R {
        let (i, wx) = locate(&self.x, &self.inv_dx, x);
        let (j, wy) = locate(&self.y, &self.inv_dy, y);
        let z0 = self.z[i][j] + wy.mul_floor_in_range(self.z[i][j + 1] - self.z[i][j]);
        let z1 = self.z[i + 1][j] + wy.mul_floor_in_range(self.z[i + 1][j + 1] - self.z[i + 1][j]);
        z0 + wx.mul_floor_in_range(z1 - z0)
    }
    /// Where `(x, y)` lies on the grid, for [`Self::eval_at`]: tables on the same breakpoints
    /// then share one look-up.
    #[inline]
    pub fn locate(&self, x: R, y: R) -> LutPoint2<R, NX, NY> {
        let (i, wx) = locate(&self.x, &self.inv_dx, x);
        let (j, wy) = locate(&self.y, &self.inv_dy, y);
        LutPoint2 { i, wx, j, wy }
    }
    /// The value at a point located on this table's grid (or on an equal one):
    /// `t.eval_at(t.locate(x, y)) == t.eval(x, y)`.
    #[inline]
    pub fn eval_at(&self, p: LutPoint2<R, NX, NY>) -> R {
        let LutPoint2 { i, wx, j, wy } = p;
        let z0 = self.z[i][j] + wy.mul_floor_in_range(self.z[i][j + 1] - self.z[i][j]);
        let z1 = self.z[i + 1][j] + wy.mul_floor_in_range(self.z[i + 1][j + 1] - self.z[i + 1][j]);
        z0 + wx.mul_floor_in_range(z1 - z0)
    }
    /// The table along x at a fixed `y`: `slice_y(y).eval(x) == eval(x, y)` bit for bit (the
    /// same operations: the slice holds the values interpolated along y), for a model whose y
    /// (an oil temperature) stays put while x changes every step.
    pub fn slice_y(&self, y: R) -> Lut1<R, NX> {
        let (j, wy) = locate(&self.y, &self.inv_dy, y);
        Lut1 {
            x: self.x,
            inv_dx: self.inv_dx,
            y: core::array::from_fn(|i| self.z[i][j] + wy.mul_floor_in_range(self.z[i][j + 1] - self.z[i][j])),
        }
    }
    pub fn x_breakpoints(&self) -> &[R; NX] {
        &self.x
    }
    pub fn y_breakpoints(&self) -> &[R; NY] {
        &self.y
    }
    /// The grid value at `(x[i], y[j])`; `None` outside the grid.
    pub fn at(&self, i: usize, j: usize) -> Option<R> {
        self.z.get(i).and_then(|row| row.get(j)).copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn fixed_point_tables_keep_their_values_within_a_sixteenth_of_the_range() {
        use crate::real::Q16;
        assert_eq!(
            Lut2::<Q16, 2, 2>::new([0.0, 1.0], [0.0, 1.0], [[0.0, 2048.0], [-2048.5, 0.0]]).unwrap_err(),
            LutError::ValueOutOfRange { index: 2 }
        );
        assert_eq!(
            Lut1::<Q16, 2>::new([0.0, 1.0], [0.0, f64::NAN]).unwrap_err(),
            LutError::ValueOutOfRange { index: 1 }
        );
        assert!(Lut1::<f32, 2>::new([0.0, 1.0], [0.0, 1e30]).is_ok());
    }

    proptest! {
        /// The range proof of `check_values`, tried: Q16.16 look-ups of any table it accepts,
        /// on any breakpoints (spacings down to a fraction of an LSB) and anywhere on or off
        /// the grid, give the bits of the same interpolation with saturating products (rounded
        /// down, as the look-ups' products are: `Real::mul_floor_in_range`).
        #[test]
        fn q16_lookups_equal_the_saturating_interpolation(
            x0 in -30000.0f64..30000.0, dxs in proptest::collection::vec(1e-6f64..5000.0, 2),
            y0 in -30000.0f64..30000.0, dys in proptest::collection::vec(1e-6f64..5000.0, 2),
            z in proptest::collection::vec(-2048.0f64..=2048.0, 9),
            px in -40000.0f64..40000.0, py in -40000.0f64..40000.0, pick in 0usize..3,
        ) {
            use crate::real::Q16;
            // The full product rounded down, saturated to the range.
            let mul = |a: Q16, b: Q16| {
                let p = (i64::from(a.to_bits()) * i64::from(b.to_bits())) >> 16;
                Q16::from_bits(p.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32)
            };
            let xs = [x0, x0 + dxs[0], x0 + dxs[0] + dxs[1]];
            let ys = [y0, y0 + dys[0], y0 + dys[0] + dys[1]];
            let zz = [[z[0], z[1], z[2]], [z[3], z[4], z[5]], [z[6], z[7], z[8]]];
            let t = Lut2::<Q16, 3, 3>::new(xs, ys, zz).unwrap();
            // Points on the grid's cells as well as anywhere.
            let (qx, qy) = match pick {
                0 => (Q16::from_f64(px), Q16::from_f64(py)),
                _ => (Q16::from_f64(xs[pick] - 1e-5), Q16::from_f64(ys[pick - 1] + 1e-5)),
            };
            let (i, wx) = locate(&t.x, &t.inv_dx, qx);
            let (j, wy) = locate(&t.y, &t.inv_dy, qy);
            let z0 = t.z[i][j] + mul(wy, t.z[i][j + 1] - t.z[i][j]);
            let z1 = t.z[i + 1][j] + mul(wy, t.z[i + 1][j + 1] - t.z[i + 1][j]);
            prop_assert_eq!(t.eval(qx, qy), z0 + mul(wx, z1 - z0));
            let s = t.slice_y(qy);
            let y = [s.y[i], s.y[i + 1]];
            prop_assert_eq!(s.eval(qx), y[0] + mul(wx, y[1] - y[0]));
        }
    }

    #[test]
    fn rejects_unsorted_and_nan_breakpoints() {
        assert_eq!(
            Lut1::<f32, 3>::new([0.0, 2.0, 1.0], [0.0; 3]).unwrap_err(),
            LutError::NotIncreasing { axis: 0, index: 2 }
        );
        assert!(Lut1::<f32, 2>::new([0.0, f64::NAN], [0.0; 2]).is_err());
        assert_eq!(
            Lut2::<f64, 2, 2>::new([0.0, 1.0], [1.0, 1.0], [[0.0; 2]; 2]).unwrap_err(),
            LutError::NotIncreasing { axis: 1, index: 1 }
        );
    }

    #[test]
    fn hits_breakpoints_and_clamps_ends() {
        let t = Lut1::<f64, 3>::new([0.0, 1.0, 3.0], [10.0, 20.0, 0.0]).unwrap();
        assert_eq!(t.eval(0.0), 10.0);
        assert_eq!(t.eval(1.0), 20.0);
        assert_eq!(t.eval(2.0), 10.0);
        assert_eq!(t.eval(-5.0), 10.0);
        assert_eq!(t.eval(9.0), 0.0);
    }

    proptest! {
        /// A slice at fixed y gives the 2-D table's bits, also when tables share a located point.
        #[test]
        fn slices_and_shared_points_give_the_same_bits(x in -1.0f64..5.0, y in -2.0f64..2.0, a in -5.0f64..5.0) {
            let xs = [0.0, 1.0, 2.5, 4.0];
            let ys = [-1.0, 0.0, 0.3, 1.0];
            let z = xs.map(|x| ys.map(|y| libm::sin(a * x + y) + x * y));
            let t = Lut2::<f64, 4, 4>::new(xs, ys, z).unwrap();
            let s = t.slice_y(y);
            prop_assert_eq!(s.eval(x).to_bits(), t.eval(x, y).to_bits());
            let u = Lut2::<f32, 4, 4>::new(xs, ys, z).unwrap();
            prop_assert_eq!(u.slice_y(y as f32).eval(x as f32).to_bits(), u.eval(x as f32, y as f32).to_bits());
            let w2 = Lut2::<f64, 4, 4>::new(xs, ys, z.map(|r| r.map(|v| 2.0 - v))).unwrap();
            prop_assert_eq!(w2.eval_at(t.locate(x, y)).to_bits(), w2.eval(x, y).to_bits());
            let w = w2.slice_y(y);
            prop_assert_eq!(w.eval_at(s.locate(x)).to_bits(), w.eval(x).to_bits());
        }

        /// A bilinear function is reproduced exactly inside the grid.
        #[test]
        fn lut2_reproduces_bilinear_functions(x in 0.0f64..4.0, y in -1.0f64..1.0,
                                              a in -5.0f64..5.0, b in -5.0f64..5.0, c in -5.0f64..5.0) {
            let xs = [0.0, 1.0, 2.5, 4.0];
            let ys = [-1.0, 0.0, 1.0];
            let f = |x: f64, y: f64| a * x + b * y + c;
            let z = xs.map(|x| ys.map(|y| f(x, y)));
            let t = Lut2::<f64, 4, 3>::new(xs, ys, z).unwrap();
            prop_assert!((t.eval(x, y) - f(x, y)).abs() < 1e-9);
        }

        /// Interpolated values never leave the range of the table values.
        #[test]
        fn lut1_stays_within_table_range(x in -10.0f32..10.0) {
            let t = Lut1::<f32, 4>::new([-2.0, 0.0, 1.0, 5.0], [3.0, -1.0, 4.0, 2.0]).unwrap();
            let v = t.eval(x);
            prop_assert!((-1.0..=4.0).contains(&v));
        }
    }
}
