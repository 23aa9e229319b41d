//! Bounded trust-region nonlinear least squares: the one solver behind `diagnose`, `identify
//! evvt` and `identify ehvva` (Li 2018, eqs. (16)-(20)).
//!
//! Minimises J(x) = ½‖r(x)‖² subject to lo ≤ x ≤ hi. Each iteration builds the quadratic model
//! M(h) = J + hᵀg + ½hᵀHh with g = Jᵀr and the Gauss-Newton Hessian H = JᵀJ (eq. (17)), solves
//! it inside the trust region ‖D h‖ ≤ Δ (eq. (18)) by the Levenberg-Marquardt parameter that
//! puts the step on the region's edge, keeps the step inside the bounds, and adapts Δ from the
//! ratio ρ of actual to predicted decrease (eqs. (19)-(20): Δ·2 when ρ > 0.75, Δ·0.25 when
//! ρ < 0.25; the step is rejected when the cost does not fall). D scales each parameter by its
//! Jacobian column norm (Moré 1978), so parameters of different units are treated alike.
//! Parameters sitting on a bound with the gradient pushing outwards are held for that step.
//!
//! A residual function may fail (a simulation that diverges): it returns `Err`, and the solver
//! treats the point as infinitely costly (a rejected step, a smaller region).

use std::cell::RefCell;
use std::fmt;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use crate::signal::dot;

/// Told the number of each solver iteration as it starts (a progress display's feed).
pub type IterationObserver = Arc<dyn Fn(usize) + Send + Sync>;

thread_local! {
    /// The observer of the fits that run on this thread (see [`with_iteration_observer`]).
    static ITERATION_OBSERVER: RefCell<Option<IterationObserver>> = const { RefCell::new(None) };
}

/// Runs `body` with `observer` told of every iteration of every [`solve`] called on this
/// thread inside it; the previous observer is restored afterwards (also on a panic). The
/// fits' own code (the families) need not know: the progress of a long diagnosis is fed from
/// here.
pub fn with_iteration_observer<T>(observer: IterationObserver, body: impl FnOnce() -> T) -> T {
    struct Restore(Option<IterationObserver>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let previous = self.0.take();
            ITERATION_OBSERVER.with(|o| *o.borrow_mut() = previous);
        }
    }
    let _restore = Restore(ITERATION_OBSERVER.with(|o| o.borrow_mut().replace(observer)));
    body()
}

fn notify_iteration(iteration: usize) {
    // Cloned out first, so an observer that starts a fit of its own cannot hit the borrow.
    if let Some(observer) = ITERATION_OBSERVER.with(|o| o.borrow().clone()) {
        observer(iteration);
    }
}

/// 95 % confidence half-widths from s²(JᵀJ)⁻¹ with `jac` the Jacobian at `x` (column-major,
/// `n` residuals); `None` on a bound or where JᵀJ is singular.
fn intervals(jac: &[f64], x: &[f64], lo: &[f64], hi: &[f64], cost: f64, n: usize) -> Vec<Option<f64>> {
    let p = x.len();
    let h_mat = jtj(jac, n, p);
    let dof = n.saturating_sub(p).max(1) as f64;
    let s2 = 2.0 * cost / dof;
    let inv = invert_spd(&h_mat, p);
    (0..p)
        .map(|j| {
            let on_bound = x[j] <= lo[j] || x[j] >= hi[j];
            match (&inv, on_bound) {
                (Some(m), false) if m[j * p + j] > 0.0 => Some(1.96 * (s2 * m[j * p + j]).sqrt()),
                _ => None,
            }
        })
        .collect()
}

/// Options; the defaults suit simulation-error fits of a handful of parameters.
#[derive(Clone, Debug)]
pub struct LsqOptions {
    pub max_iterations: usize,
    /// Stop when the relative cost decrease of an accepted step is below this.
    pub cost_tolerance: f64,
    /// Stop when the scaled step is below this relative to the scaled parameters.
    pub step_tolerance: f64,
    /// Relative finite-difference step for the Jacobian.
    pub fd_step: f64,
    /// Evaluate Jacobian columns on this many threads (simulations are independent).
    pub threads: usize,
    /// Give the 95 % intervals at the solution (`LsqResult::ci95`), from a Jacobian there:
    /// the last iteration's where the solver stopped without moving since (a step too
    /// small, a collapsed region), a fresh one otherwise. `false` for a stage whose
    /// intervals nobody reads (a fit's first approach), which then ends without that
    /// Jacobian's simulations and reports no intervals.
    pub intervals: bool,
}

impl Default for LsqOptions {
    fn default() -> Self {
        Self {
            max_iterations: 60,
            cost_tolerance: 1e-10,
            step_tolerance: 1e-9,
            fd_step: 1e-6,
            threads: 2,
            intervals: true,
        }
    }
}

/// What the solver found, with the evidence a user needs to trust it.
#[derive(Clone, Debug)]
pub struct LsqResult {
    pub x: Vec<f64>,
    /// ½‖r‖² at `x`.
    pub cost: f64,
    pub initial_cost: f64,
    pub iterations: usize,
    pub evaluations: usize,
    /// 95 % confidence half-widths from s²(JᵀJ)⁻¹, s² = ‖r‖²/(n − p); `None` for a parameter
    /// on a bound or not identifiable (singular JᵀJ).
    pub ci95: Vec<Option<f64>>,
    pub residuals: usize,
    pub stop: StopReason,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    CostConverged,
    StepConverged,
    MaxIterations,
    /// The trust region shrank below any useful step.
    RegionCollapsed,
}

#[derive(Clone, Debug, PartialEq)]
pub enum LsqError {
    /// Bounds or start are inconsistent; the index names the parameter.
    BadBounds {
        index: usize,
        message: String,
    },
    /// The residual function failed at the starting point.
    StartFailed(String),
    NoResiduals,
}

impl fmt::Display for LsqError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LsqError::BadBounds { index, message } => write!(f, "parameter {index}: {message}"),
            LsqError::StartFailed(m) => write!(f, "the model failed at the starting parameters: {m}"),
            LsqError::NoResiduals => write!(f, "no residuals to fit"),
        }
    }
}

impl std::error::Error for LsqError {}

/// Solves min ½‖r(x)‖², lo ≤ x ≤ hi, from `x0` (clamped into the bounds).
/// `residual(x, out)` fills `out` (its length fixed by the first call's `n_residuals`).
pub fn solve<F>(
    residual: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    n_residuals: usize,
    opts: &LsqOptions,
) -> Result<LsqResult, LsqError>
where
    F: Fn(&[f64], &mut [f64]) -> Result<(), String> + Sync,
{
    let p = x0.len();
    if lo.len() != p || hi.len() != p {
        return Err(LsqError::BadBounds {
            index: p.min(lo.len()).min(hi.len()),
            message: "bounds and start differ in length".into(),
        });
    }
    for i in 0..p {
        if !(lo[i] <= hi[i]) || !x0[i].is_finite() {
            return Err(LsqError::BadBounds {
                index: i,
                message: format!("lower {} / upper {} / start {}", lo[i], hi[i], x0[i]),
            });
        }
    }
    if n_residuals == 0 {
        return Err(LsqError::NoResiduals);
    }
    let mut x: Vec<f64> = (0..p).map(|i| x0[i].clamp(lo[i], hi[i])).collect();
    let mut r = vec![0.0; n_residuals];
    let mut evaluations = 1;
    residual(&x, &mut r).map_err(LsqError::StartFailed)?;
    let mut cost = half_norm2(&r);
    if !cost.is_finite() {
        return Err(LsqError::StartFailed("non-finite residuals".into()));
    }
    let initial_cost = cost;
    let mut jac = vec![0.0; n_residuals * p]; // column-major: column j at j*n
    let mut scale = vec![0.0f64; p];
    let mut delta = 0.0;
    let mut iterations = 0;
    let mut stop = StopReason::MaxIterations;
    let mut r_try = vec![0.0; n_residuals];
    // Whether `jac` is the Jacobian at `x` (no step accepted since it was made).
    let mut jac_at_x = false;

    'outer: while iterations < opts.max_iterations {
        iterations += 1;
        notify_iteration(iterations);
        evaluations += jacobian(&residual, &x, &r, lo, hi, opts, &mut jac);
        jac_at_x = true;
        let h_mat = jtj(&jac, n_residuals, p);
        let g = jtr(&jac, &r, n_residuals, p);
        for j in 0..p {
            scale[j] = scale[j].max(h_mat[j * p + j].sqrt()).max(1e-12);
        }
        if iterations == 1 {
            let dx: f64 = x.iter().zip(&scale).map(|(xi, d)| (xi * d).powi(2)).sum::<f64>().sqrt();
            delta = if dx > 0.0 { dx } else { 1.0 };
        }
        // Hold parameters on a bound whose gradient points out of the box.
        let free: Vec<usize> = (0..p)
            .filter(|&j| !((x[j] <= lo[j] && g[j] > 0.0) || (x[j] >= hi[j] && g[j] < 0.0)))
            .collect();
        if free.is_empty() {
            stop = StopReason::StepConverged;
            break;
        }
        loop {
            let h = trust_step(&h_mat, &g, &scale, &free, p, delta);
            // Keep the step inside the bounds.
            let x_try: Vec<f64> = (0..p).map(|j| (x[j] + h[j]).clamp(lo[j], hi[j])).collect();
            let step: Vec<f64> = (0..p).map(|j| x_try[j] - x[j]).collect();
            let step_norm = norm_scaled(&step, &scale);
            let x_norm = norm_scaled(&x, &scale);
            if step_norm <= opts.step_tolerance * (x_norm + opts.step_tolerance) {
                stop = StopReason::StepConverged;
                break 'outer;
            }
            // Predicted decrease M(0) − M(h) = −(gᵀh + ½hᵀHh) for the step actually taken.
            let mut predicted = 0.0;
            for j in 0..p {
                predicted -= g[j] * step[j];
                for k in 0..p {
                    predicted -= 0.5 * step[j] * h_mat[j * p + k] * step[k];
                }
            }
            evaluations += 1;
            let actual_cost = match residual(&x_try, &mut r_try) {
                Ok(()) => half_norm2(&r_try),
                Err(_) => f64::INFINITY,
            };
            let rho = if predicted > 0.0 {
                (cost - actual_cost) / predicted
            } else {
                -1.0
            };
            // Eq. (20).
            if rho > 0.75 {
                delta = delta.max(2.0 * step_norm);
            } else if rho < 0.25 {
                delta = 0.25 * step_norm.min(delta);
            }
            if actual_cost.is_finite() && actual_cost < cost {
                let rel = (cost - actual_cost) / cost.max(f64::MIN_POSITIVE);
                x = x_try;
                jac_at_x = false;
                std::mem::swap(&mut r, &mut r_try);
                cost = actual_cost;
                if rel < opts.cost_tolerance || cost == 0.0 {
                    stop = StopReason::CostConverged;
                    break 'outer;
                }
                break;
            }
            if delta < 1e-14 * (x_norm + 1e-14) {
                stop = StopReason::RegionCollapsed;
                break 'outer;
            }
        }
    }

    // Confidence intervals at the solution, from the Jacobian there: the last iteration's
    // where no step was accepted since (the same numbers a fresh one gives: the same point
    // and residuals), else a fresh one; none where not asked for.
    let ci95 = if opts.intervals {
        if !jac_at_x {
            evaluations += jacobian(&residual, &x, &r, lo, hi, opts, &mut jac);
        }
        intervals(&jac, &x, lo, hi, cost, n_residuals)
    } else {
        vec![None; p]
    };
    Ok(LsqResult {
        x,
        cost,
        initial_cost,
        iterations,
        evaluations,
        ci95,
        residuals: n_residuals,
        stop,
    })
}

fn half_norm2(r: &[f64]) -> f64 {
    0.5 * r.iter().map(|v| v * v).sum::<f64>()
}

fn norm_scaled(v: &[f64], d: &[f64]) -> f64 {
    v.iter().zip(d).map(|(a, b)| (a * b).powi(2)).sum::<f64>().sqrt()
}

/// Forward-difference Jacobian, columns spread over threads; steps point into the box.
/// Returns the number of residual evaluations.
fn jacobian<F>(residual: &F, x: &[f64], r0: &[f64], lo: &[f64], hi: &[f64], opts: &LsqOptions, jac: &mut [f64]) -> usize
where
    F: Fn(&[f64], &mut [f64]) -> Result<(), String> + Sync,
{
    let n = r0.len();
    let p = x.len();
    let threads = opts.threads.clamp(1, p.max(1));
    let columns: Vec<(usize, &mut [f64])> = jac.chunks_mut(n).enumerate().collect();
    let mut buckets: Vec<Vec<(usize, &mut [f64])>> = (0..threads).map(|_| Vec::new()).collect();
    for (k, c) in columns.into_iter().enumerate() {
        buckets[k % threads].push(c);
    }
    std::thread::scope(|s| {
        for bucket in buckets {
            s.spawn(move || {
                let mut xp = x.to_vec();
                let mut rp = vec![0.0; n];
                for (j, col) in bucket {
                    let mut h = opts.fd_step * x[j].abs().max(1e-3);
                    if x[j] + h > hi[j] {
                        h = -h;
                    }
                    if x[j] + h < lo[j] {
                        // A degenerate box (lo == hi): the parameter cannot move.
                        col.iter_mut().for_each(|v| *v = 0.0);
                        continue;
                    }
                    xp[j] = x[j] + h;
                    match residual(&xp, &mut rp) {
                        Ok(()) => {
                            for i in 0..n {
                                let d = (rp[i] - r0[i]) / h;
                                col[i] = if d.is_finite() { d } else { 0.0 };
                            }
                        }
                        Err(_) => col.iter_mut().for_each(|v| *v = 0.0),
                    }
                    xp[j] = x[j];
                }
            });
        }
    });
    p
}

/// Rows of the Jacobian a block of JᵀJ sums: the block's columns stay in the cache while
/// every pair of them is multiplied (one pass over the Jacobian instead of one per pair).
const JTJ_BLOCK_ROWS: usize = 2048;

/// The row blocks of JᵀJ are summed in this many contiguous parts, one partial JᵀJ each (the
/// order in which the 400 000-row diagnosis and the EHVVA sweeps of session 22 were measured).
const JTJ_PARTS: usize = 8;

/// JᵀJ of the column-major `jac` (`n` rows, `p` columns), its parts added in order. On the
/// calling thread: spread over the cores (on threads of its own or rayon's) the EVVT
/// diagnosis of 425 000 rows peaked at up to 105 B a row instead of 91-98 (each thread's
/// malloc arena keeps freed residual buffers), and in lanes and blocks it is a small part of
/// a fit's time.
fn jtj(jac: &[f64], n: usize, p: usize) -> Vec<f64> {
    let blocks = n.div_ceil(JTJ_BLOCK_ROWS).max(1);
    let blocks_per_part = blocks.div_ceil(JTJ_PARTS);
    let mut partial = vec![0.0; JTJ_PARTS * p * p];
    for (part, h) in partial.chunks_mut(p * p).enumerate() {
        for b in part * blocks_per_part..((part + 1) * blocks_per_part).min(blocks) {
            let rows = b * JTJ_BLOCK_ROWS..((b + 1) * JTJ_BLOCK_ROWS).min(n);
            for a in 0..p {
                let col_a = &jac[a * n..(a + 1) * n][rows.clone()];
                for c in a..p {
                    h[a * p + c] += dot(col_a, &jac[c * n..(c + 1) * n][rows.clone()]);
                }
            }
        }
    }
    let mut h = vec![0.0; p * p];
    for part in partial.chunks(p * p) {
        for a in 0..p {
            for c in a..p {
                h[a * p + c] += part[a * p + c];
            }
        }
    }
    for a in 0..p {
        for c in 0..a {
            h[a * p + c] = h[c * p + a];
        }
    }
    h
}

fn jtr(jac: &[f64], r: &[f64], n: usize, p: usize) -> Vec<f64> {
    (0..p).map(|j| dot(&jac[j * n..(j + 1) * n], r)).collect()
}

/// The step minimising the model on the free parameters with ‖D h‖ ≤ Δ: the Gauss-Newton step
/// when it fits, otherwise (H + λD²)h = −g with λ found by bisection on log λ.
fn trust_step(h_mat: &[f64], g: &[f64], d: &[f64], free: &[usize], p: usize, delta: f64) -> Vec<f64> {
    let m = free.len();
    let solve_with = |lambda: f64| -> Option<Vec<f64>> {
        let mut a = vec![0.0; m * m];
        let mut b = vec![0.0; m];
        for (ii, &i) in free.iter().enumerate() {
            for (kk, &k) in free.iter().enumerate() {
                a[ii * m + kk] = h_mat[i * p + k];
            }
            a[ii * m + ii] += lambda * d[i] * d[i] + 1e-12 * (h_mat[i * p + i] + 1e-300);
            b[ii] = -g[i];
        }
        let sol = cholesky_solve(&a, &b, m)?;
        let mut h = vec![0.0; p];
        for (ii, &i) in free.iter().enumerate() {
            h[i] = sol[ii];
        }
        Some(h)
    };
    if let Some(h) = solve_with(0.0) {
        if norm_scaled(&h, d) <= delta {
            return h;
        }
    }
    // ‖D h(λ)‖ falls monotonically in λ: bracket and bisect in log space.
    let (mut lo, mut hi) = (1e-12f64, 1.0f64);
    while solve_with(hi).is_none_or(|h| norm_scaled(&h, d) > delta) && hi < 1e30 {
        lo = hi;
        hi *= 100.0;
    }
    let mut best = solve_with(hi).unwrap_or_else(|| vec![0.0; p]);
    for _ in 0..40 {
        let mid = (lo * hi).sqrt();
        match solve_with(mid) {
            Some(h) if norm_scaled(&h, d) <= delta => {
                best = h;
                hi = mid;
            }
            _ => lo = mid,
        }
        if hi / lo < 1.01 {
            break;
        }
    }
    best
}

/// Solves A x = b for symmetric positive definite A (row-major m×m) by nalgebra's Cholesky
/// factorization; `None` when A is not positive definite.
fn cholesky_solve(a: &[f64], b: &[f64], m: usize) -> Option<Vec<f64>> {
    let chol = DMatrix::from_row_slice(m, m, a).cholesky()?;
    let x = chol.solve(&DVector::from_column_slice(b));
    x.iter().all(|v| v.is_finite()).then(|| x.as_slice().to_vec())
}

/// Inverse of a symmetric positive definite matrix (row-major m×m) from its Cholesky factor,
/// `None` when it is not positive definite (singular).
pub fn invert_spd(a: &[f64], m: usize) -> Option<Vec<f64>> {
    let inv = DMatrix::from_row_slice(m, m, a).cholesky()?.inverse();
    // Row-major out; the inverse is symmetric, so the column-major storage is the same up to
    // rounding, but transpose to be exact about the layout.
    let inv = inv.transpose();
    inv.iter().all(|v| v.is_finite()).then(|| inv.as_slice().to_vec())
}

/// Linear least squares min ‖A X − Y‖ for several right-hand sides at once (A row-major
/// n×p, Y row-major n×k, n >= p) by Householder QR (nalgebra): A = QR, X = R⁻¹QᵀY, without
/// forming AᵀA (whose condition number is the square of A's). `None` when A's columns are
/// dependent (a diagonal entry of R below 1e-12 of the largest). X row-major p×k.
pub fn linear_lsq_qr(a: &[f64], n: usize, p: usize, y: &[f64], k: usize) -> Option<Vec<f64>> {
    if p == 0 || n < p || a.len() != n * p || y.len() != n * k {
        return None;
    }
    let qr = DMatrix::from_row_slice(n, p, a).qr();
    let r = qr.r();
    let largest = r.diagonal().iter().fold(0.0f64, |m, d| m.max(d.abs()));
    if !(largest > 0.0) || r.diagonal().iter().any(|d| !(d.abs() > 1e-12 * largest)) {
        return None;
    }
    // QᵀY by the Householder reflectors themselves (Q is never formed).
    let mut qty = DMatrix::from_row_slice(n, k, y);
    qr.q_tr_mul(&mut qty);
    let x = r.solve_upper_triangular(&qty.rows(0, p).into_owned())?.transpose();
    x.iter().all(|v| v.is_finite()).then(|| x.as_slice().to_vec())
}

/// Ordinary linear least squares min ‖A x − y‖ (A given by its columns, n×p) by QR
/// ([`linear_lsq_qr`]); `None` when A has dependent columns. For regressions such as the
/// inverse-model fits.
pub fn linear_lsq(a_cols: &[Vec<f64>], y: &[f64]) -> Option<Vec<f64>> {
    let p = a_cols.len();
    let n = y.len();
    if a_cols.iter().any(|c| c.len() != n) {
        return None;
    }
    let a: Vec<f64> = (0..n).flat_map(|i| a_cols.iter().map(move |c| c[i])).collect();
    linear_lsq_qr(&a, n, p, y, 1)
}

/// The stop reason and effort of a solver run, for a report ("converged (cost) after 12
/// iterations", "iteration limit (30) reached": not converged).
pub fn convergence_text(r: &LsqResult) -> String {
    let how = match r.stop {
        StopReason::CostConverged => "converged (cost)",
        StopReason::StepConverged => "converged (step)",
        StopReason::MaxIterations => "not converged: iteration limit reached",
        StopReason::RegionCollapsed => "converged (trust region collapsed: no further decrease)",
    };
    format!("{how} after {} iterations", r.iterations)
}

/// Indices of the parameters that ended on (within 1e-6 of the range of) a bound.
pub fn at_bounds(x: &[f64], lo: &[f64], hi: &[f64]) -> Vec<usize> {
    (0..x.len().min(lo.len()).min(hi.len()))
        .filter(|&j| {
            let range = if (hi[j] - lo[j]).is_finite() {
                hi[j] - lo[j]
            } else {
                x[j].abs().max(1.0)
            };
            let tol = 1e-6 * range;
            x[j] <= lo[j] + tol || x[j] >= hi[j] - tol
        })
        .collect()
}

/// Indices of the parameters the data cannot identify at the optimum: off their bounds but
/// without a confidence interval (singular information matrix), or with a 95 % half-width
/// wider than half their search range (the data move the cost too little to tell).
pub fn not_identifiable(r: &LsqResult, lo: &[f64], hi: &[f64]) -> Vec<usize> {
    let bound = at_bounds(&r.x, lo, hi);
    (0..r.x.len())
        .filter(|j| !bound.contains(j))
        .filter(|&j| match r.ci95.get(j).copied().flatten() {
            None => true,
            Some(c) => {
                let range = hi.get(j).zip(lo.get(j)).map_or(f64::INFINITY, |(h, l)| h - l);
                range.is_finite() && c > 0.5 * range
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> LsqOptions {
        LsqOptions {
            max_iterations: 200,
            ..Default::default()
        }
    }

    #[test]
    fn jtj_in_parts_is_the_plain_product() {
        // Small integers: every partial sum is exact, so the blocks, parts and lanes must give
        // the plain JᵀJ exactly; the row counts end inside a block, on a part's edge, and give
        // fewer blocks than parts.
        for n in [5usize, 2048, 9 * 2048 + 5, 17 * 2048 - 1] {
            let p = 3;
            let jac: Vec<f64> = (0..n * p).map(|i| ((i * 37 + 11) % 7) as f64 - 3.0).collect();
            let h = jtj(&jac, n, p);
            for a in 0..p {
                for b in 0..p {
                    let plain: f64 = (0..n).map(|i| jac[a * n + i] * jac[b * n + i]).sum();
                    assert_eq!(h[a * p + b], plain, "n = {n}, ({a}, {b})");
                }
            }
        }
    }

    #[test]
    fn intervals_come_from_the_jacobian_at_the_solution_and_can_be_left_out() {
        // A decay fitted to noisy samples (the cost stays above 0), stopped once by the cost
        // and once by the step: the intervals are those of a fresh Jacobian at the solution
        // (a start there with no iteration gives exactly them), whether or not the last
        // iteration's could serve; without intervals the same solution, none reported, and
        // the fresh Jacobian's two simulations saved where the cost stopped it.
        let t: Vec<f64> = (0..40).map(|k| k as f64 * 0.1).collect();
        let y: Vec<f64> = (0..40)
            .map(|k| 2.0 * (-0.7 * t[k]).exp() + 0.01 * ((k * 7919 % 13) as f64 - 6.0))
            .collect();
        let f = |x: &[f64], out: &mut [f64]| {
            for k in 0..t.len() {
                out[k] = x[0] * (-x[1] * t[k]).exp() - y[k];
            }
            Ok(())
        };
        let (lo, hi) = ([0.0, 0.0], [10.0, 10.0]);
        let by_cost = opts();
        let by_step = LsqOptions {
            cost_tolerance: 0.0,
            step_tolerance: 1e-4,
            ..opts()
        };
        let mut stops = Vec::new();
        for o in [by_cost, by_step] {
            let full = solve(f, &[1.0, 1.0], &lo, &hi, t.len(), &o).unwrap();
            let there = LsqOptions {
                max_iterations: 0,
                ..o.clone()
            };
            let fresh = solve(f, &full.x, &lo, &hi, t.len(), &there).unwrap();
            assert_eq!(full.ci95, fresh.ci95, "{:?}", full.stop);
            assert!(full.ci95.iter().all(Option::is_some));
            let bare = solve(f, &[1.0, 1.0], &lo, &hi, t.len(), &LsqOptions { intervals: false, ..o }).unwrap();
            assert_eq!((bare.x.clone(), bare.cost), (full.x.clone(), full.cost));
            assert!(bare.ci95.iter().all(Option::is_none));
            let saved = if full.stop == StopReason::CostConverged { 2 } else { 0 };
            assert_eq!(bare.evaluations + saved, full.evaluations, "{:?}", full.stop);
            stops.push(full.stop);
        }
        assert_eq!(stops, [StopReason::CostConverged, StopReason::StepConverged]);
    }

    #[test]
    fn solves_rosenbrock_from_the_classic_start() {
        let r = |x: &[f64], out: &mut [f64]| {
            out[0] = 10.0 * (x[1] - x[0] * x[0]);
            out[1] = 1.0 - x[0];
            Ok(())
        };
        let res = solve(r, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], 2, &opts()).unwrap();
        assert!(
            (res.x[0] - 1.0).abs() < 1e-6 && (res.x[1] - 1.0).abs() < 1e-6,
            "{:?}",
            res
        );
        assert!(res.cost < 1e-12);
    }

    /// The observer hears every iteration of the solves inside its scope, in order, and no
    /// other: not those of another thread, not those after the scope.
    #[test]
    fn iteration_observer_hears_each_iteration_inside_its_scope() {
        use std::sync::Mutex;
        let r = |x: &[f64], out: &mut [f64]| {
            out[0] = 10.0 * (x[1] - x[0] * x[0]);
            out[1] = 1.0 - x[0];
            Ok(())
        };
        let heard = Arc::new(Mutex::new(Vec::new()));
        let sink = heard.clone();
        let observer: IterationObserver = Arc::new(move |i| sink.lock().unwrap().push(i));
        let (a, b) = with_iteration_observer(observer, || {
            let a = solve(r, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], 2, &opts()).unwrap();
            // A fit on another thread is not this scope's.
            std::thread::spawn(move || solve(r, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], 2, &opts()).unwrap())
                .join()
                .unwrap();
            let b = solve(r, &[0.5, 0.5], &[-5.0, -5.0], &[5.0, 5.0], 2, &opts()).unwrap();
            (a, b)
        });
        solve(r, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], 2, &opts()).unwrap();
        let expected: Vec<usize> = (1..=a.iterations).chain(1..=b.iterations).collect();
        assert!(a.iterations > 5, "{}", a.iterations);
        assert_eq!(*heard.lock().unwrap(), expected);
    }

    #[test]
    fn respects_bounds_and_stops_on_the_active_one() {
        // Unconstrained optimum x = 3; bound at 2.
        let r = |x: &[f64], out: &mut [f64]| {
            out[0] = x[0] - 3.0;
            out[1] = 0.5 * (x[1] + 1.0);
            Ok(())
        };
        let res = solve(r, &[0.0, 0.0], &[-1.0, -1.0], &[2.0, 1.0], 2, &opts()).unwrap();
        assert_eq!(res.x[0], 2.0);
        assert!((res.x[1] + 1.0).abs() < 1e-9);
        assert!(res.ci95[0].is_none(), "a parameter on its bound has no interval");
    }

    #[test]
    fn fits_an_exponential_and_its_confidence_interval_covers_the_truth() {
        // y = a e^{-b t} + noise (deterministic pseudo-noise), a = 2, b = 0.7.
        let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.05).collect();
        let noise = |k: usize| ((k as f64 * 12.9898).sin() * 43758.5453).rem_euclid(1.0) * 0.02 - 0.01;
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(k, &t)| 2.0 * (-0.7 * t).exp() + noise(k))
            .collect();
        let r = |x: &[f64], out: &mut [f64]| {
            for k in 0..t.len() {
                out[k] = x[0] * (-x[1] * t[k]).exp() - y[k];
            }
            Ok(())
        };
        let res = solve(r, &[1.0, 0.1], &[0.0, 0.0], &[10.0, 10.0], t.len(), &opts()).unwrap();
        let (ca, cb) = (res.ci95[0].unwrap(), res.ci95[1].unwrap());
        assert!(
            (res.x[0] - 2.0).abs() < 3.0 * ca && ca < 0.02,
            "a {} ± {}",
            res.x[0],
            ca
        );
        assert!(
            (res.x[1] - 0.7).abs() < 3.0 * cb && cb < 0.02,
            "b {} ± {}",
            res.x[1],
            cb
        );
        assert!(res.cost < res.initial_cost * 1e-3);
    }

    #[test]
    fn survives_a_model_that_fails_in_part_of_the_box() {
        // The "simulation" diverges for x > 1.5; the optimum is at 1.
        let r = |x: &[f64], out: &mut [f64]| {
            if x[0] > 1.5 {
                return Err("diverged".into());
            }
            out[0] = x[0] - 1.0;
            Ok(())
        };
        let res = solve(r, &[0.0], &[0.0], &[100.0], 1, &opts()).unwrap();
        assert!((res.x[0] - 1.0).abs() < 1e-6);
        assert!(matches!(
            solve(r, &[2.0], &[0.0], &[100.0], 1, &opts()),
            Err(LsqError::StartFailed(_))
        ));
    }

    #[test]
    fn bad_bounds_name_the_parameter() {
        let r = |_: &[f64], out: &mut [f64]| {
            out[0] = 0.0;
            Ok(())
        };
        let e = solve(r, &[0.0, 0.0], &[0.0, 1.0], &[1.0, 0.0], 1, &opts()).unwrap_err();
        assert_eq!(
            e,
            LsqError::BadBounds {
                index: 1,
                message: "lower 1 / upper 0 / start 0".into()
            }
        );
    }

    #[test]
    fn linear_lsq_recovers_a_line() {
        let x: Vec<f64> = (0..50).map(|k| k as f64).collect();
        let ones = vec![1.0; 50];
        let y: Vec<f64> = x.iter().map(|x| 3.0 * x - 2.0).collect();
        let c = linear_lsq(&[x, ones], &y).unwrap();
        assert!((c[0] - 3.0).abs() < 1e-9 && (c[1] + 2.0).abs() < 1e-9);
        // Dependent columns are refused, not solved into noise.
        let twice: Vec<f64> = (0..50).map(|k| 2.0 * k as f64).collect();
        let x: Vec<f64> = (0..50).map(|k| k as f64).collect();
        assert!(linear_lsq(&[x, twice], &y).is_none());
    }

    /// QR keeps the digits the normal equations lose: a polynomial fit on 1..2 in powers up to
    /// 7 (condition number of A about 1e7, of AᵀA about 1e14) comes back to 1e-6.
    #[test]
    fn qr_least_squares_on_an_ill_conditioned_basis() {
        let (n, p) = (200, 8);
        let t: Vec<f64> = (0..n).map(|i| 1.0 + i as f64 / (n - 1) as f64).collect();
        let truth: Vec<f64> = (0..p).map(|j| (j as f64 - 3.5) / 2.0).collect();
        let a: Vec<f64> = t.iter().flat_map(|&x| (0..p).map(move |j| x.powi(j as i32))).collect();
        let y: Vec<f64> = (0..n).map(|i| (0..p).map(|j| a[i * p + j] * truth[j]).sum()).collect();
        let c = linear_lsq_qr(&a, n, p, &y, 1).unwrap();
        for j in 0..p {
            assert!(
                (c[j] - truth[j]).abs() < 1e-6,
                "coefficient {j}: {} vs {}",
                c[j],
                truth[j]
            );
        }
    }

    #[test]
    fn spd_inverse_and_refusal() {
        let a = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let inv = invert_spd(&a, 3).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let e: f64 = (0..3).map(|k| a[i * 3 + k] * inv[k * 3 + j]).sum();
                assert!((e - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        assert!(invert_spd(&[1.0, 2.0, 2.0, 1.0], 2).is_none(), "indefinite");
    }
}
