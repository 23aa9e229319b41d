//! `identify evvt`: the EVVT plant α/(s(s+β)) per operating point from closed-loop PRBS logs,
//! by the method of Yang et al. 2015 (Section II, IV): PRBS q-Markov COVER identification of
//! the closed loop, the open-loop model by the indirect approach of eq. (2), its
//! continuous-time form with the integrator pole set to zero, and the LPV tables α(N, V),
//! β(N, V) over the points.
//!
//! Per log (one operating point: the means of its `engine_rpm` and `u_batt_V` columns):
//!
//! 1. **Multi-rate data.** The reference is the inverse PRBS (eqs. (6)-(8)) held for `p`
//!    control periods (the PRBS clock, found from the reference's switching instants); the
//!    command runs at the control period T (`# control_period_s:`, which must be the log's
//!    period); the phase is computed per cam event (`# cam_events_per_cycle:` per 720 crank
//!    degrees, so every 120/(N·events) s) and the controller holds the last value: on the
//!    control grid the logged phase is a sample-and-hold of the quantized phase. The hold has a
//!    mean age of half the cam-event period; its frequency response `(1 − e^{−sTc})/(sTc)` has
//!    the phase of the pure delay τ = Tc/2 and a gain within 0.1 % of one in the loop's band,
//!    so it is modelled as that delay (step 5). Without the metadata key the phase is taken as
//!    sampled at every control instant (τ = 0).
//! 2. **Markov parameters from the PRBS correlation** (multi-rate, lifted): for each of the p
//!    phases φ of the control grid within a PRBS clock interval, the phase samples at
//!    `clock start + φ` are regressed on the last J PRBS values (an FIR model at the PRBS rate,
//!    plus an intercept). Its normal equations are the PRBS autocorrelation (eq. (10):
//!    a²·(I + O(1/m)) over full periods, so the estimate is the correlation divided by a² up
//!    to the small eq. (10) terms, which the solve removes) and the reference–phase
//!    cross-correlation. Interleaving the p phases gives s(k), the fast-rate closed loop's
//!    response to one held PRBS pulse, k = 0..J·p−1.
//! 3. **q-Markov COVER realization.** For k ≥ p the pulse has ended and
//!    s(p + j) = C A^j B̃, B̃ = (I + A + … + A^{p−1}) B: the Markov parameters of the
//!    fast-rate closed loop (A, B̃, C). Their Hankel matrix (rows: the first R lags, columns:
//!    the rest) is factored by a one-sided Jacobi SVD; for a white (PRBS) input its singular
//!    values are the square roots of those of the q-Markov cover's output-correlation matrix
//!    R_q − H_q H_qᵀ (= O_q X O_qᵀ), whose gap the paper's Fig. 6 uses for the order. The
//!    order n is the largest gap σ_n/σ_{n+1} for n in 2..=6 (the plant has at least two
//!    states). A, C, B̃ come from the balanced factors (shift invariance), B from B̃, D = 0
//!    (the phase at t_k is measured before the command computed from it).
//! 4. **Indirect approach, eq. (2).** With K = kp (rpm per crank degree, `# kp:`) at the
//!    control period, H = GK(I + GK)⁻¹ gives GK = H(I − H)⁻¹: in state space, positive unit
//!    feedback around H, G = (A + BC, B/kp, C, 0). G is the map from `motor_cmd_rpm` to the
//!    logged phase, so it contains the measurement hold.
//! 5. **Continuous time.** Pole mapping z → s = ln(z)/T: the pole nearest z = 1 is the
//!    integrator (the paper: "one pole very close to zero … manually set to zero"); the
//!    slowest remaining real pole gives β; α = β·v with v the velocity gain, the residue of G
//!    at the integrator pole divided by T (the ZOH image of v/s is vT/(z − 1)). That is the
//!    paper's map. It cannot separate the measurement delay from the plant (a 2nd-order G
//!    absorbs the delay into β), so α, β are then refined with `lsq::solve`: the exact ZOH
//!    discretization at T of α·e^{−sτ}/(s(s+β)) (integrator exactly at 0, τ from step 1) is
//!    fitted to G's frequency response at 40 log-spaced frequencies from ωc/10 to 5ωc (ωc the
//!    crossover of kp·G), on the relative error weighted by |H(1 − H)| (so the error counts
//!    as it does in the closed loop, where the data determine G). The refined values are the
//!    result; the map's values are printed beside them.
//!
//! Units: phase in crank degrees, command in rpm, so α in crank-deg/(s²·rpm) and β in 1/s,
//! as model-core's [`EvvtLpvTable`] takes them.

use std::fmt::Write as _;
use std::path::Path;

use model_core::evvt::{zoh, EvvtLpvTable};

use crate::log::{read_log, Log, Plant};
use crate::lsq::{self, LsqOptions};

/// Settings of the identification (defaults: the values the tests and README use).
#[derive(Clone, Debug)]
pub struct EvvtIdentifyOptions {
    /// Length of the closed-loop held-pulse response estimated, s (the slowest design loop,
    /// 1400 rpm / 9.5 V with kp = 25, decays to about 1 % in 6 s).
    pub markov_horizon_s: f64,
    /// Hankel rows (lags of the observability side).
    pub hankel_rows: usize,
    /// Largest realization order considered.
    pub max_order: usize,
    /// Fewest full PRBS clock intervals accepted.
    pub min_prbs_values: usize,
}

impl Default for EvvtIdentifyOptions {
    fn default() -> Self {
        Self {
            markov_horizon_s: 6.0,
            hankel_rows: 40,
            max_order: 6,
            min_prbs_values: 300,
        }
    }
}

/// The result for one log (one operating point).
#[derive(Clone, Debug)]
pub struct EvvtPointResult {
    pub file: String,
    pub engine_rpm: f64,
    pub u_batt_v: f64,
    pub kp_rpm_per_deg: f64,
    pub control_period_s: f64,
    /// Control periods per PRBS value.
    pub prbs_hold_periods: usize,
    pub prbs_values: usize,
    pub prbs_amplitude_deg: f64,
    pub prbs_centre_deg: f64,
    pub cam_events_per_cycle: Option<f64>,
    /// Mean age of the held phase, τ, s.
    pub measurement_delay_s: f64,
    /// Closed-loop response to one held unit PRBS pulse at the control rate, s(k).
    pub pulse_response: Vec<f64>,
    /// Hankel singular values, largest first.
    pub hankel_sv: Vec<f64>,
    pub order: usize,
    /// Share of the pulse response's variance the realization reproduces, %.
    pub realization_vaf_pct: f64,
    /// Closed-loop poles (z, real and imaginary parts).
    pub closed_loop_poles_z: Vec<(f64, f64)>,
    /// Open-loop poles of G = H(I − H)⁻¹K⁻¹ (z).
    pub open_loop_poles_z: Vec<(f64, f64)>,
    /// The integrator pole mapped to continuous time (before it is set to zero), 1/s.
    pub integrator_pole_s: f64,
    /// The paper's pole map (integrator set to zero, slowest other pole, velocity gain).
    pub alpha_map: f64,
    pub beta_map: f64,
    /// The delay-aware continuous-time fit: the result.
    pub alpha: f64,
    pub beta: f64,
    pub alpha_ci95: Option<f64>,
    pub beta_ci95: Option<f64>,
    pub crossover_rad_s: f64,
    pub fit_iterations: usize,
    pub fit_initial_cost: f64,
    pub fit_cost: f64,
    /// Rows whose command is at the saturation limit, %.
    pub saturated_pct: f64,
    /// The lines of the per-log report.
    pub report: String,
}

// ---------------------------------------------------------------------------------------------
// Small complex arithmetic and polynomials (for poles and frequency responses).

#[derive(Clone, Copy, Debug, PartialEq)]
struct Cx(f64, f64);

impl Cx {
    fn add(self, o: Cx) -> Cx {
        Cx(self.0 + o.0, self.1 + o.1)
    }
    fn sub(self, o: Cx) -> Cx {
        Cx(self.0 - o.0, self.1 - o.1)
    }
    fn mul(self, o: Cx) -> Cx {
        Cx(self.0 * o.0 - self.1 * o.1, self.0 * o.1 + self.1 * o.0)
    }
    fn scale(self, k: f64) -> Cx {
        Cx(self.0 * k, self.1 * k)
    }
    fn div(self, o: Cx) -> Cx {
        let d = o.0 * o.0 + o.1 * o.1;
        Cx((self.0 * o.0 + self.1 * o.1) / d, (self.1 * o.0 - self.0 * o.1) / d)
    }
    fn abs(self) -> f64 {
        self.0.hypot(self.1)
    }
    fn expj(w: f64) -> Cx {
        Cx(w.cos(), w.sin())
    }
    fn ln(self) -> Cx {
        Cx(self.abs().ln(), self.1.atan2(self.0))
    }
}

/// Coefficients of det(zI − A), lowest power first (A row-major n×n), by Faddeev–LeVerrier
/// (exact in exact arithmetic; fine in f64 for the orders used here, n <= 8).
fn char_poly(a: &[f64], n: usize) -> Vec<f64> {
    let mut c = vec![0.0; n + 1];
    c[n] = 1.0;
    let mut m = vec![0.0; n * n];
    for k in 1..=n {
        // M_k = A M_{k−1} + c_{n−k+1} I
        let mut next = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let mut s = 0.0;
                for l in 0..n {
                    s += a[i * n + l] * m[l * n + j];
                }
                next[i * n + j] = s + if i == j { c[n - k + 1] } else { 0.0 };
            }
        }
        m = next;
        let mut tr = 0.0;
        for i in 0..n {
            for l in 0..n {
                tr += a[i * n + l] * m[l * n + i];
            }
        }
        c[n - k] = -tr / k as f64;
    }
    c
}

fn poly_eval(c: &[f64], z: Cx) -> Cx {
    c.iter()
        .rev()
        .fold(Cx(0.0, 0.0), |acc, &ci| acc.mul(z).add(Cx(ci, 0.0)))
}

fn poly_deriv(c: &[f64]) -> Vec<f64> {
    c.iter().enumerate().skip(1).map(|(i, &ci)| i as f64 * ci).collect()
}

/// Roots of a monic polynomial (lowest power first) by the Durand–Kerner iteration.
fn poly_roots(c: &[f64]) -> Vec<Cx> {
    let n = c.len().saturating_sub(1);
    if n == 0 {
        return Vec::new();
    }
    let bound = 1.0 + c[..n].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    // Starting points spread on a spiral (the usual (0.4 + 0.9i)^k), scaled to the root bound.
    let mut z = Vec::with_capacity(n);
    let mut w = Cx(1.0, 0.0);
    for _ in 0..n {
        w = w.mul(Cx(0.4, 0.9));
        z.push(w.scale(bound.min(2.0)));
    }
    for _ in 0..2000 {
        let mut moved = 0.0f64;
        for i in 0..n {
            let mut den = Cx(1.0, 0.0);
            for j in 0..n {
                if i != j {
                    den = den.mul(z[i].sub(z[j]));
                }
            }
            if den.abs() == 0.0 {
                den = Cx(1e-12, 0.0);
            }
            let step = poly_eval(c, z[i]).div(den);
            z[i] = z[i].sub(step);
            moved = moved.max(step.abs());
        }
        if moved < 1e-15 {
            break;
        }
    }
    z
}

// ---------------------------------------------------------------------------------------------
// Dense linear algebra (row-major), small sizes.

fn mat_mul(a: &[f64], b: &[f64], n: usize, k: usize, m: usize) -> Vec<f64> {
    let mut c = vec![0.0; n * m];
    for i in 0..n {
        for l in 0..k {
            let x = a[i * k + l];
            if x != 0.0 {
                for j in 0..m {
                    c[i * m + j] += x * b[l * m + j];
                }
            }
        }
    }
    c
}

/// Solves A x = b (n×n) by Gaussian elimination with partial pivoting; `None` when singular.
fn solve_linear(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| m[i * n + col].abs().total_cmp(&m[j * n + col].abs()))?;
        if m[piv * n + col].abs() < 1e-300 {
            return None;
        }
        if piv != col {
            for j in 0..n {
                m.swap(col * n + j, piv * n + j);
            }
            x.swap(col, piv);
        }
        for i in col + 1..n {
            let f = m[i * n + col] / m[col * n + col];
            if f != 0.0 {
                for j in col..n {
                    m[i * n + j] -= f * m[col * n + j];
                }
                x[i] -= f * x[col];
            }
        }
    }
    for i in (0..n).rev() {
        let mut s = x[i];
        for j in i + 1..n {
            s -= m[i * n + j] * x[j];
        }
        x[i] = s / m[i * n + i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Thin SVD of an m×n matrix (row-major) with m >= n by one-sided Jacobi (Hestenes):
/// orthogonalizes the columns by plane rotations until every pair is orthogonal to 1e-13.
/// Returns (U m×n, σ n, V n×n), σ descending, U's columns unit (zero for σ = 0).
pub fn svd_jacobi(a: &[f64], m: usize, n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    // Work on columns stored contiguously.
    let mut cols: Vec<Vec<f64>> = (0..n).map(|j| (0..m).map(|i| a[i * n + j]).collect()).collect();
    let mut v: Vec<Vec<f64>> = (0..n)
        .map(|j| (0..n).map(|i| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    for _sweep in 0..60 {
        let mut rotated = false;
        for p in 0..n {
            for q in p + 1..n {
                let (alpha, beta, gamma) = cols[p]
                    .iter()
                    .zip(&cols[q])
                    .fold((0.0, 0.0, 0.0), |(a, b, g), (x, y)| (a + x * x, b + y * y, g + x * y));
                if gamma == 0.0 || gamma.abs() <= 1e-13 * (alpha * beta).sqrt() {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                let (cp, cq) = two_mut(&mut cols, p, q);
                for (x, y) in cp.iter_mut().zip(cq.iter_mut()) {
                    let (xp, yq) = (*x, *y);
                    *x = c * xp - s * yq;
                    *y = s * xp + c * yq;
                }
                let (vp, vq) = two_mut(&mut v, p, q);
                for (x, y) in vp.iter_mut().zip(vq.iter_mut()) {
                    let (xp, yq) = (*x, *y);
                    *x = c * xp - s * yq;
                    *y = s * xp + c * yq;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let mut idx: Vec<usize> = (0..n).collect();
    let norms: Vec<f64> = cols
        .iter()
        .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
        .collect();
    idx.sort_by(|&i, &j| norms[j].total_cmp(&norms[i]));
    let mut u = vec![0.0; m * n];
    let mut vv = vec![0.0; n * n];
    let mut sigma = vec![0.0; n];
    for (k, &j) in idx.iter().enumerate() {
        sigma[k] = norms[j];
        for i in 0..m {
            u[i * n + k] = if norms[j] > 0.0 { cols[j][i] / norms[j] } else { 0.0 };
        }
        for i in 0..n {
            vv[i * n + k] = v[j][i];
        }
    }
    (u, sigma, vv)
}

fn two_mut<T>(v: &mut [T], p: usize, q: usize) -> (&mut T, &mut T) {
    let (lo, hi) = v.split_at_mut(q);
    (&mut lo[p], &mut hi[0])
}

// ---------------------------------------------------------------------------------------------
// Step 1: the log.

struct PrbsData {
    hold: usize,
    /// Index of the first full clock interval.
    offset: usize,
    /// PRBS values minus the centre, one per full clock interval.
    values: Vec<f64>,
    centre: f64,
    amplitude: f64,
}

/// Finds the PRBS clock from the reference: two levels, switching only on a common grid.
fn prbs_of(file: &str, reference: &[f64], min_values: usize) -> Result<PrbsData, String> {
    let mut levels: Vec<f64> = Vec::new();
    for &r in reference {
        if !levels.iter().any(|&l| (l - r).abs() <= 1e-9 * (1.0 + l.abs())) {
            levels.push(r);
            if levels.len() > 2 {
                return Err(format!("{file}: column phase_ref_deg is not a two-level PRBS reference (more than two values, e.g. {}, {}, {}): identify evvt needs the PRBS identification experiment", levels[0], levels[1], levels[2]));
            }
        }
    }
    if levels.len() < 2 {
        return Err(format!("{file}: column phase_ref_deg is constant: no PRBS excitation"));
    }
    let switches: Vec<usize> = (1..reference.len())
        .filter(|&k| reference[k] != reference[k - 1])
        .collect();
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let hold = switches.windows(2).fold(0, |g, w| gcd(g, w[1] - w[0]));
    if hold == 0 || switches.len() < 10 {
        return Err(format!(
            "{file}: phase_ref_deg switches only {} times: not a PRBS experiment",
            switches.len()
        ));
    }
    let offset = switches[0] % hold;
    let count = (reference.len() - offset) / hold;
    let centre = 0.5 * (levels[0] + levels[1]);
    let amplitude = 0.5 * (levels[0] - levels[1]).abs();
    let values: Vec<f64> = (0..count).map(|i| reference[offset + i * hold] - centre).collect();
    if count < min_values {
        return Err(format!(
            "{file}: only {count} PRBS values (clock {hold} samples); at least {min_values} are needed"
        ));
    }
    Ok(PrbsData {
        hold,
        offset,
        values,
        centre,
        amplitude,
    })
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

// ---------------------------------------------------------------------------------------------
// Steps 2-5.

/// The held-pulse response s(k), k = 0..J·p − 1, by the lifted FIR regression (module doc,
/// step 2).
fn pulse_response(prbs: &PrbsData, phase: &[f64], lags: usize) -> Result<Vec<f64>, String> {
    let p = prbs.hold;
    let r = &prbs.values;
    let rows: Vec<usize> = (lags - 1..r.len())
        .filter(|&n| prbs.offset + n * p + p - 1 < phase.len())
        .collect();
    if rows.len() < 2 * (lags + 1) {
        return Err(format!("{} PRBS values are too few for {lags} lags", r.len()));
    }
    let q = lags + 1;
    let mut ata = vec![0.0; q * q];
    for &n in &rows {
        for i in 0..q {
            let xi = if i == lags { 1.0 } else { r[n - i] };
            for j in 0..=i {
                let xj = if j == lags { 1.0 } else { r[n - j] };
                ata[i * q + j] += xi * xj;
            }
        }
    }
    for i in 0..q {
        for j in i + 1..q {
            ata[i * q + j] = ata[j * q + i];
        }
    }
    let inv = lsq::invert_spd(&ata, q).ok_or("the PRBS regression is singular")?;
    let mut s = vec![0.0; lags * p];
    for phi in 0..p {
        let mut aty = vec![0.0; q];
        for &n in &rows {
            let y = phase[prbs.offset + n * p + phi];
            for i in 0..lags {
                aty[i] += r[n - i] * y;
            }
            aty[lags] += y;
        }
        for j in 0..lags {
            s[j * p + phi] = (0..q).map(|l| inv[j * q + l] * aty[l]).sum();
        }
    }
    Ok(s)
}

/// A realization (A row-major n×n, B, C).
struct StateSpace {
    n: usize,
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
}

impl StateSpace {
    /// Markov parameters C A^(k−1) B, k = 1..=count (D = 0).
    fn markov(&self, count: usize) -> Vec<f64> {
        let mut x = self.b.clone();
        let mut out = Vec::with_capacity(count);
        for _ in 0..count {
            out.push(self.c.iter().zip(&x).map(|(c, x)| c * x).sum());
            x = mat_mul(&self.a, &x, self.n, self.n, 1);
        }
        out
    }
    /// Transfer function numerator and denominator (lowest power first), D = 0:
    /// C adj(zI − A) B = det(zI − A + BC) − det(zI − A).
    fn tf(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.n;
        let den = char_poly(&self.a, n);
        let mut abc = self.a.clone();
        for i in 0..n {
            for j in 0..n {
                abc[i * n + j] -= self.b[i] * self.c[j];
            }
        }
        let num: Vec<f64> = char_poly(&abc, n).iter().zip(&den).map(|(x, y)| x - y).collect();
        (num, den)
    }
}

/// The Hankel SVD, order choice and realization (module doc, step 3).
fn realize(s: &[f64], hold: usize, rows: usize, max_order: usize) -> Result<(StateSpace, Vec<f64>, usize), String> {
    let g = &s[hold..];
    let rows = rows.min(g.len() / 3);
    let cols = g.len() - rows - 1;
    if rows < max_order + 2 {
        return Err("the pulse response is too short for the Hankel matrix".into());
    }
    // H0ᵀ (cols × rows): its SVD gives H0's factors with U and V swapped.
    let mut h0t = vec![0.0; cols * rows];
    for i in 0..rows {
        for j in 0..cols {
            h0t[j * rows + i] = g[i + j];
        }
    }
    let (ut, sigma, vt) = svd_jacobi(&h0t, cols, rows);
    // H0 = Uh Σ Vhᵀ with Uh = vt (rows × rows), Vh = ut (cols × rows).
    let top = max_order.min(rows - 1);
    let mut order = 2;
    let mut best = 0.0;
    for n in 2..=top {
        let ratio = sigma[n - 1] / sigma[n].max(1e-300);
        if ratio > best {
            best = ratio;
            order = n;
        }
    }
    let n = order;
    let sq: Vec<f64> = sigma[..n].iter().map(|x| x.sqrt()).collect();
    if sq.iter().any(|&x| x <= 0.0) {
        return Err("zero Hankel singular value within the chosen order".into());
    }
    // O = Uh_n Σ^½ (rows × n), Ctrl = Σ^½ Vh_nᵀ (n × cols).
    let obs: Vec<f64> = (0..rows)
        .flat_map(|i| (0..n).map(move |k| (i, k)))
        .map(|(i, k)| vt[i * rows + k] * sq[k])
        .collect();
    let ctrl: Vec<f64> = (0..n)
        .flat_map(|k| (0..cols).map(move |j| (k, j)))
        .map(|(k, j)| ut[j * rows + k] * sq[k])
        .collect();
    // A = Σ^-½ Uhᵀ H1 Vh Σ^-½ with H1 the shifted Hankel.
    let mut a = vec![0.0; n * n];
    for k in 0..n {
        for l in 0..n {
            let mut acc = 0.0;
            for i in 0..rows {
                let u = vt[i * rows + k];
                if u == 0.0 {
                    continue;
                }
                let mut inner = 0.0;
                for j in 0..cols {
                    inner += g[i + j + 1] * ut[j * rows + l];
                }
                acc += u * inner;
            }
            a[k * n + l] = acc / (sq[k] * sq[l]);
        }
    }
    let c: Vec<f64> = obs[..n].to_vec();
    let b_tilde: Vec<f64> = (0..n).map(|k| ctrl[k * cols]).collect();
    // B = (I + A + … + A^{p−1})⁻¹ B̃.
    let mut sum = vec![0.0; n * n];
    let mut pow: Vec<f64> = (0..n * n).map(|i| if i % (n + 1) == 0 { 1.0 } else { 0.0 }).collect();
    for _ in 0..hold {
        sum.iter_mut().zip(&pow).for_each(|(s, p)| *s += p);
        pow = mat_mul(&pow, &a, n, n, n);
    }
    let b = solve_linear(&sum, &b_tilde, n)
        .ok_or("I + A + … + A^(p−1) is singular: the realization has a pole on the PRBS clock's aliasing circle")?;
    Ok((StateSpace { n, a, b, c }, sigma, order))
}

/// Model response to one held unit pulse of `hold` samples, k = 0..len−1.
fn held_pulse_response(ss: &StateSpace, hold: usize, len: usize) -> Vec<f64> {
    let h = ss.markov(len);
    let mut s = vec![0.0; len];
    for (k, sk) in s.iter_mut().enumerate() {
        // s(k) = Σ_{m = 0}^{min(k, hold−1)} h(k − m), h(0) = 0, h(j) = C A^{j−1} B.
        for m in 0..hold.min(k + 1) {
            let j = k - m;
            if j >= 1 {
                *sk += h[j - 1];
            }
        }
    }
    s
}

/// Frequency response of α e^{−sτ}/(s(s+β)) sampled with a ZOH at period T, exactly: with
/// τ = dT + ε, x⁺ = Φx + Γ0 u(k−d) + Γ1 u(k−d−1), Γ0 = Bd(T−ε), Γ1 = Ad(T−ε)Bd(ε).
fn model_response(alpha: f64, beta: f64, tau_s: f64, t_s: f64, w_rad_s: f64) -> Cx {
    let d = (tau_s / t_s).floor();
    let eps = tau_s - d * t_s;
    let full = zoh(alpha, beta, t_s);
    let g0 = zoh(alpha, beta, t_s - eps);
    let ge = zoh(alpha, beta, eps);
    let gamma0 = (g0.bd1_deg_per_rpm, g0.bd2_deg_per_s_rpm);
    let gamma1 = (
        ge.bd1_deg_per_rpm + g0.ad12_s * ge.bd2_deg_per_s_rpm,
        g0.ad22 * ge.bd2_deg_per_s_rpm,
    );
    let z = Cx::expj(w_rad_s * t_s);
    let zi = Cx::expj(-w_rad_s * t_s);
    let g1 = Cx(gamma0.0, 0.0).add(zi.scale(gamma1.0));
    let g2 = Cx(gamma0.1, 0.0).add(zi.scale(gamma1.1));
    let num = z.sub(Cx(full.ad22, 0.0)).mul(g1).add(g2.scale(full.ad12_s));
    let den = z.sub(Cx(1.0, 0.0)).mul(z.sub(Cx(full.ad22, 0.0)));
    num.div(den).mul(Cx::expj(-w_rad_s * t_s * d))
}

/// Identifies one log.
pub fn identify_log(log: &Log, opts: &EvvtIdentifyOptions) -> Result<EvvtPointResult, String> {
    let file = log.file.as_str();
    if log.plant != Plant::Evvt {
        return Err(format!(
            "{file}: plant is `{}`, identify evvt needs an `evvt` log",
            log.plant
        ));
    }
    let reference = log.col("phase_ref_deg").ok_or_else(|| {
        format!("{file}: no phase_ref_deg column: this is an open-loop log; identify evvt needs the closed-loop PRBS experiment (phase_ref_deg and `# kp:`)")
    })?;
    let kp = log.meta_f64("kp").map_err(|e| e.to_string())?.ok_or_else(|| {
        format!("{file}: no `# kp:` metadata: the proportional gain of the closed loop (rpm per crank degree) is needed for the indirect approach G = H(I - H)^-1 K^-1")
    })?;
    if kp <= 0.0 {
        return Err(format!("{file}: metadata `kp` is {kp}; it must be positive"));
    }
    let t_s = match log.meta_f64("control_period_s").map_err(|e| e.to_string())? {
        Some(tc) if (tc - log.dt_s).abs() > 0.01 * log.dt_s => {
            return Err(format!("{file}: metadata control_period_s {tc} s differs from the log's period {} s: identify evvt needs the log on the control grid", log.dt_s));
        }
        Some(tc) if tc > 0.0 => tc,
        _ => log.dt_s,
    };
    let cam_events = log.meta_f64("cam_events_per_cycle").map_err(|e| e.to_string())?;
    let (cmd, phase, rpm, volt) = match (
        log.col("motor_cmd_rpm"),
        log.col("phase_deg"),
        log.col("engine_rpm"),
        log.col("u_batt_V"),
    ) {
        (Some(c), Some(p), Some(n), Some(v)) => (c, p, n, v),
        _ => return Err(format!("{file}: a required evvt column is missing")),
    };
    // The log must obey the law it states (otherwise K is not what the metadata says).
    let cmd_max = log
        .meta_f64("motor_cmd_max_rpm")
        .map_err(|e| e.to_string())?
        .unwrap_or(f64::INFINITY);
    let mut disobey = 0usize;
    let mut first_bad = None;
    let mut saturated = 0usize;
    for k in 0..log.len() {
        let law = kp * (reference[k] - phase[k]);
        if law.abs() >= cmd_max {
            saturated += 1;
        }
        let expect = law.clamp(-cmd_max, cmd_max);
        if (cmd[k] - expect).abs() > 1e-6 * (1.0 + expect.abs()) {
            disobey += 1;
            first_bad.get_or_insert(k);
        }
    }
    if disobey * 20 > log.len() {
        return Err(format!(
            "{file}: motor_cmd_rpm does not follow kp (phase_ref_deg - phase_deg) with kp = {kp} in {disobey} of {} rows (first at data row {}): not the closed loop the metadata states (an open-loop log?)",
            log.len(),
            first_bad.unwrap_or(0) + 1
        ));
    }
    let engine_rpm = mean(rpm);
    let u_batt_v = mean(volt);
    let measurement_delay_s = match cam_events {
        Some(e) if e > 0.0 && engine_rpm > 0.0 => 0.5 * 120.0 / (engine_rpm * e),
        Some(e) => {
            return Err(format!(
                "{file}: metadata cam_events_per_cycle {e} (or the engine speed {engine_rpm} rpm) is not positive"
            ))
        }
        None => 0.0,
    };
    let prbs = prbs_of(file, reference, opts.min_prbs_values)?;
    let p = prbs.hold;
    let lags = ((opts.markov_horizon_s / (p as f64 * t_s)).ceil() as usize).max(opts.hankel_rows / p.max(1) + 4);
    let s = pulse_response(&prbs, phase, lags).map_err(|e| format!("{file}: {e}"))?;
    let (cl, sigma, order) = realize(&s, p, opts.hankel_rows, opts.max_order).map_err(|e| format!("{file}: {e}"))?;
    let fit = held_pulse_response(&cl, p, s.len());
    let s_mean = mean(&s);
    let ss_tot: f64 = s.iter().map(|x| (x - s_mean).powi(2)).sum();
    let ss_res: f64 = s.iter().zip(&fit).map(|(a, b)| (a - b).powi(2)).sum();
    let vaf = 100.0 * (1.0 - ss_res / ss_tot.max(1e-300));

    // Indirect approach: G = (A + BC, B/kp, C).
    let n = cl.n;
    let mut a_ol = cl.a.clone();
    for i in 0..n {
        for j in 0..n {
            a_ol[i * n + j] += cl.b[i] * cl.c[j];
        }
    }
    let g = StateSpace {
        n,
        a: a_ol,
        b: cl.b.iter().map(|x| x / kp).collect(),
        c: cl.c.clone(),
    };
    let (h_num, h_den) = cl.tf();
    let (g_num, g_den) = g.tf();
    let cl_poles = poly_roots(&h_den);
    let ol_poles = poly_roots(&g_den);
    let integ = ol_poles
        .iter()
        .copied()
        .min_by(|x, y| x.sub(Cx(1.0, 0.0)).abs().total_cmp(&y.sub(Cx(1.0, 0.0)).abs()))
        .ok_or("no poles")?;
    let s_poles: Vec<Cx> = ol_poles.iter().map(|z| z.ln().scale(1.0 / t_s)).collect();
    let integrator_pole_s = integ.ln().scale(1.0 / t_s).0;
    // Paper map: slowest other real (or nearly real) stable pole.
    let beta_map = s_poles
        .iter()
        .zip(&ol_poles)
        .filter(|(_, z)| **z != integ && z.1.abs() < 1e-6 && z.0 > 0.0)
        .map(|(s, _)| -s.0)
        .filter(|b| *b > 0.0)
        .fold(f64::NAN, |m: f64, b| if m.is_nan() || b < m { b } else { m });
    let residue = poly_eval(&g_num, integ).div(poly_eval(&poly_deriv(&g_den), integ));
    let velocity_gain = residue.0 / t_s;
    let alpha_map = beta_map * velocity_gain;

    // Crossover of kp·G and the fit band.
    let g_at = |w: f64| {
        let z = Cx::expj(w * t_s);
        poly_eval(&g_num, z).div(poly_eval(&g_den, z))
    };
    let h_at = |w: f64| {
        let z = Cx::expj(w * t_s);
        poly_eval(&h_num, z).div(poly_eval(&h_den, z))
    };
    let nyquist = std::f64::consts::PI / t_s;
    let (mut lo, mut hi) = (1e-3f64, 0.5 * nyquist);
    if g_at(lo).abs() * kp < 1.0 || g_at(hi).abs() * kp > 1.0 {
        return Err(format!("{file}: the identified loop kp·G has no crossover between {lo} and {hi} rad/s: the identification failed (order {order}, Hankel singular values {:?})", &sigma[..sigma.len().min(6)]));
    }
    for _ in 0..100 {
        let mid = (lo * hi).sqrt();
        if g_at(mid).abs() * kp > 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let wc = (lo * hi).sqrt();
    let w_hi = (5.0 * wc).min(0.2 * nyquist);
    let w_lo = wc / 10.0;
    let freqs: Vec<f64> = (0..40).map(|i| w_lo * (w_hi / w_lo).powf(i as f64 / 39.0)).collect();
    let targets: Vec<(Cx, f64)> = freqs
        .iter()
        .map(|&w| {
            let h = h_at(w);
            (g_at(w), h.mul(Cx(1.0, 0.0).sub(h)).abs())
        })
        .collect();
    let residual = |x: &[f64], out: &mut [f64]| -> Result<(), String> {
        for (i, (&w, (gid, wt))) in freqs.iter().zip(&targets).enumerate() {
            let e = model_response(x[0], x[1], measurement_delay_s, t_s, w)
                .div(*gid)
                .sub(Cx(1.0, 0.0))
                .scale(*wt);
            out[2 * i] = e.0;
            out[2 * i + 1] = e.1;
        }
        Ok(())
    };
    // Start: the paper map where it gave numbers, else the crossover (|kpG(jωc)| = 1 with
    // β = ωc).
    let start = if alpha_map.is_finite() && beta_map.is_finite() && alpha_map > 0.0 {
        [alpha_map, beta_map]
    } else {
        [wc * wc * std::f64::consts::SQRT_2 / kp, wc]
    };
    let fit_res = lsq::solve(
        residual,
        &start,
        &[1e-5, 0.0],
        &[100.0, 500.0],
        2 * freqs.len(),
        &LsqOptions {
            max_iterations: 100,
            ..Default::default()
        },
    )
    .map_err(|e| format!("{file}: continuous-time fit: {e}"))?;

    let mut rep = String::new();
    let _ = writeln!(
        rep,
        "{file}: N = {engine_rpm:.1} rpm, V = {u_batt_v:.2} V, kp = {kp} rpm/deg, control period {t_s} s, {} rows",
        log.len()
    );
    let _ = writeln!(
        rep,
        "  PRBS: {} values of ±{:.3} deg around {:.3} deg, clock {} control periods ({:.3} s); command saturated in {:.2} % of rows",
        prbs.values.len(),
        prbs.amplitude,
        prbs.centre,
        p,
        p as f64 * t_s,
        100.0 * saturated as f64 / log.len() as f64
    );
    match cam_events {
        Some(e) => {
            let _ = writeln!(rep, "  phase sampled per cam event ({e} per cycle: every {:.2} ms), held on the control grid: measurement delay τ = {:.2} ms", 2e3 * measurement_delay_s, 1e3 * measurement_delay_s);
        }
        None => {
            let _ = writeln!(
                rep,
                "  no cam_events_per_cycle metadata: phase taken as sampled at every control instant (τ = 0)"
            );
        }
    }
    let shown: Vec<String> = (0..s.len())
        .step_by((s.len() / 12).max(1))
        .map(|k| format!("s({k})={:.4}", s[k]))
        .collect();
    let _ = writeln!(
        rep,
        "  closed-loop held-pulse response from the PRBS correlation, {} Markov parameters at {} s: {}",
        s.len(),
        t_s,
        shown.join(" ")
    );
    let svs: Vec<String> = sigma.iter().take(10).map(|x| format!("{x:.4e}")).collect();
    let _ = writeln!(
        rep,
        "  Hankel singular values ({}×{}): {}",
        opts.hankel_rows.min((s.len() - p) / 3),
        s.len() - p - opts.hankel_rows.min((s.len() - p) / 3) - 1,
        svs.join(" ")
    );
    let _ = writeln!(rep, "  order {order} (largest gap σ{order}/σ{} = {:.1} over orders 2..={}); realization reproduces s(k) with VAF {vaf:.2} %", order + 1, sigma[order - 1] / sigma[order].max(1e-300), opts.max_order);
    let fmt_z = |v: &[Cx]| {
        v.iter()
            .map(|z| {
                if z.1.abs() < 1e-9 {
                    format!("{:.5}", z.0)
                } else {
                    format!("{:.5}{:+.5}i", z.0, z.1)
                }
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(rep, "  closed-loop poles z: {}", fmt_z(&cl_poles));
    let _ = writeln!(
        rep,
        "  open-loop G = H(I-H)^-1 K^-1 poles z: {}; s = ln(z)/T: {}",
        fmt_z(&ol_poles),
        fmt_z(&s_poles)
    );
    let _ = writeln!(rep, "  integrator pole s = {integrator_pole_s:.4} 1/s set to 0; velocity gain α/β = {velocity_gain:.5} deg/s per rpm");
    let _ = writeln!(rep, "  paper pole map: α = {alpha_map:.4}, β = {beta_map:.4}");
    let _ = writeln!(
        rep,
        "  continuous fit of α e^(-sτ)/(s(s+β)) to G over {w_lo:.2}..{w_hi:.2} rad/s (crossover {wc:.3} rad/s): {} iterations, cost {:.3e} -> {:.3e}",
        fit_res.iterations, fit_res.initial_cost, fit_res.cost
    );
    let ci = |c: Option<f64>| c.map_or("n/a".to_string(), |c| format!("{c:.2e}"));
    let _ = writeln!(
        rep,
        "  α = {:.4} ± {} crank-deg/(s²·rpm), β = {:.4} ± {} 1/s (95 % CI)",
        fit_res.x[0],
        ci(fit_res.ci95[0]),
        fit_res.x[1],
        ci(fit_res.ci95[1])
    );

    Ok(EvvtPointResult {
        file: file.to_string(),
        engine_rpm,
        u_batt_v,
        kp_rpm_per_deg: kp,
        control_period_s: t_s,
        prbs_hold_periods: p,
        prbs_values: prbs.values.len(),
        prbs_amplitude_deg: prbs.amplitude,
        prbs_centre_deg: prbs.centre,
        cam_events_per_cycle: cam_events,
        measurement_delay_s,
        pulse_response: s,
        hankel_sv: sigma,
        order,
        realization_vaf_pct: vaf,
        closed_loop_poles_z: cl_poles.iter().map(|z| (z.0, z.1)).collect(),
        open_loop_poles_z: ol_poles.iter().map(|z| (z.0, z.1)).collect(),
        integrator_pole_s,
        alpha_map,
        beta_map,
        alpha: fit_res.x[0],
        beta: fit_res.x[1],
        alpha_ci95: fit_res.ci95[0],
        beta_ci95: fit_res.ci95[1],
        crossover_rad_s: wc,
        fit_iterations: fit_res.iterations,
        fit_initial_cost: fit_res.initial_cost,
        fit_cost: fit_res.cost,
        saturated_pct: 100.0 * saturated as f64 / log.len() as f64,
        report: rep,
    })
}

/// Reads and identifies each file.
pub fn identify_files(paths: &[&Path], opts: &EvvtIdentifyOptions) -> Result<Vec<EvvtPointResult>, String> {
    paths
        .iter()
        .map(|p| {
            let log = read_log(p, Some(Plant::Evvt)).map_err(|e| e.to_string())?;
            identify_log(&log, opts)
        })
        .collect()
}

/// Groups values within `tol` of each other; returns the sorted group means.
fn breakpoints(values: &[f64], tol: f64) -> Vec<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let mut groups: Vec<Vec<f64>> = Vec::new();
    for x in v {
        match groups.last_mut() {
            Some(g) if x - g[0] <= tol => g.push(x),
            _ => groups.push(vec![x]),
        }
    }
    groups.iter().map(|g| mean(g)).collect()
}

/// The model-core table from the points when they form a 3×3 grid of engine speed (groups
/// within 5 % of 1000 rpm... 50 rpm) and battery voltage (groups within 0.5 V); several
/// points in a cell are averaged. The breakpoints are the group means.
pub fn lpv_table(points: &[EvvtPointResult]) -> Result<EvvtLpvTable, String> {
    let speeds = breakpoints(&points.iter().map(|p| p.engine_rpm).collect::<Vec<_>>(), 50.0);
    let volts = breakpoints(&points.iter().map(|p| p.u_batt_v).collect::<Vec<_>>(), 0.5);
    if speeds.len() != 3 || volts.len() != 3 {
        return Err(format!(
            "the points give {} engine speeds and {} battery voltages; model-core's EvvtLpvTable needs a 3×3 grid",
            speeds.len(),
            volts.len()
        ));
    }
    let nearest = |v: &[f64], x: f64| {
        (0..v.len())
            .min_by(|&i, &j| (v[i] - x).abs().total_cmp(&(v[j] - x).abs()))
            .unwrap_or(0)
    };
    let mut sum = [[(0.0, 0.0, 0usize); 3]; 3];
    for p in points {
        let (i, j) = (nearest(&speeds, p.engine_rpm), nearest(&volts, p.u_batt_v));
        sum[i][j].0 += p.alpha;
        sum[i][j].1 += p.beta;
        sum[i][j].2 += 1;
    }
    let mut table = EvvtLpvTable::PAPER_DESIGN;
    for i in 0..3 {
        for j in 0..3 {
            let (a, b, c) = sum[i][j];
            if c == 0 {
                return Err(format!(
                    "no point at {:.0} rpm, {:.2} V: the 3×3 grid is incomplete",
                    speeds[i], volts[j]
                ));
            }
            table.alpha_deg_per_s2_rpm[i][j] = a / c as f64;
            table.beta_per_s[i][j] = b / c as f64;
        }
    }
    table.engine_speed_rpm = [speeds[0], speeds[1], speeds[2]];
    table.battery_voltage_v = [volts[0], volts[1], volts[2]];
    Ok(table)
}

/// The points as a text table and, when they form a grid, the model-core table as Rust.
pub fn tables_text(points: &[EvvtPointResult]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:>10} {:>8} {:>6} {:>10} {:>9} {:>10} {:>9}",
        "N rpm", "V", "order", "alpha", "beta", "alpha map", "beta map"
    );
    let mut sorted: Vec<&EvvtPointResult> = points.iter().collect();
    // By engine speed (to 50 rpm: the logged speed is noisy), then voltage.
    sorted.sort_by(|a, b| {
        (a.engine_rpm / 50.0)
            .round()
            .total_cmp(&(b.engine_rpm / 50.0).round())
            .then(a.u_batt_v.total_cmp(&b.u_batt_v))
    });
    for p in sorted {
        let _ = writeln!(
            s,
            "{:>10.1} {:>8.2} {:>6} {:>10.4} {:>9.4} {:>10.4} {:>9.4}",
            p.engine_rpm, p.u_batt_v, p.order, p.alpha, p.beta, p.alpha_map, p.beta_map
        );
    }
    match lpv_table(points) {
        Ok(t) => {
            let row = |m: &[[f64; 3]; 3]| {
                m.iter()
                    .map(|r| format!("[{:.4}, {:.4}, {:.4}]", r[0], r[1], r[2]))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let _ = writeln!(
                s,
                "LPV table for model_core::evvt::EvvtLpvTable (rows: engine speed, columns: battery voltage):"
            );
            let _ = writeln!(s, "EvvtLpvTable {{");
            let _ = writeln!(
                s,
                "    engine_speed_rpm: [{:.1}, {:.1}, {:.1}],",
                t.engine_speed_rpm[0], t.engine_speed_rpm[1], t.engine_speed_rpm[2]
            );
            let _ = writeln!(
                s,
                "    battery_voltage_v: [{:.2}, {:.2}, {:.2}],",
                t.battery_voltage_v[0], t.battery_voltage_v[1], t.battery_voltage_v[2]
            );
            let _ = writeln!(s, "    alpha_deg_per_s2_rpm: [{}],", row(&t.alpha_deg_per_s2_rpm));
            let _ = writeln!(s, "    beta_per_s: [{}],", row(&t.beta_per_s));
            let _ = writeln!(s, "}}");
        }
        Err(e) => {
            let _ = writeln!(s, "no model-core table: {e}");
        }
    }
    s
}

/// The `--json` document: `{"points": [{"engine_rpm", "u_batt_V", "alpha", "beta", "order",
/// ...}]}` (the grid table follows from the points with [`lpv_table`]).
pub fn to_json(points: &[EvvtPointResult]) -> serde_json::Value {
    let pts: Vec<serde_json::Value> = points
        .iter()
        .map(|p| {
            serde_json::json!({
                "engine_rpm": p.engine_rpm,
                "u_batt_V": p.u_batt_v,
                "alpha": p.alpha,
                "beta": p.beta,
                "order": p.order,
                "file": p.file,
                "alpha_ci95": p.alpha_ci95,
                "beta_ci95": p.beta_ci95,
                "alpha_pole_map": p.alpha_map,
                "beta_pole_map": p.beta_map,
                "kp": p.kp_rpm_per_deg,
                "measurement_delay_s": p.measurement_delay_s,
                "hankel_singular_values": p.hankel_sv.iter().take(10).collect::<Vec<_>>(),
                "realization_vaf_pct": p.realization_vaf_pct,
                "fit_iterations": p.fit_iterations,
                "fit_cost": p.fit_cost,
            })
        })
        .collect();
    serde_json::json!({ "points": pts })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_svd_reconstructs_and_orders() {
        let (m, n) = (7, 4);
        let a: Vec<f64> = (0..m * n).map(|i| ((i * 37 % 11) as f64 - 5.0) / 3.0).collect();
        let (u, s, v) = svd_jacobi(&a, m, n);
        assert!(s.windows(2).all(|w| w[0] >= w[1]));
        for i in 0..m {
            for j in 0..n {
                let r: f64 = (0..n).map(|k| u[i * n + k] * s[k] * v[j * n + k]).sum();
                assert!((r - a[i * n + j]).abs() < 1e-12, "{r} vs {}", a[i * n + j]);
            }
        }
        // VᵀV = I.
        for p in 0..n {
            for q in 0..n {
                let d: f64 = (0..n).map(|i| v[i * n + p] * v[i * n + q]).sum();
                assert!((d - if p == q { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn poles_of_a_known_polynomial() {
        // (z − 1)(z − 0.9)(z² − z + 0.5)
        let a = [
            0.9, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.5, 0.0, 0.0, 1.0, 1.0,
        ];
        let c = char_poly(&a, 4);
        let mut roots = poly_roots(&c);
        roots.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)));
        let expect = [Cx(0.5, -0.5), Cx(0.5, 0.5), Cx(0.9, 0.0), Cx(1.0, 0.0)];
        for (r, e) in roots.iter().zip(&expect) {
            assert!(r.sub(*e).abs() < 1e-9, "{r:?} vs {e:?}");
        }
    }

    #[test]
    fn model_response_without_delay_is_the_zoh_transfer_function() {
        let (alpha, beta, t) = (0.4, 5.0, 0.01);
        let z = zoh(alpha, beta, t);
        for &w in &[0.3, 3.0, 30.0] {
            let g = model_response(alpha, beta, 0.0, t, w);
            let zz = Cx::expj(w * t);
            let num = zz
                .sub(Cx(z.ad22, 0.0))
                .scale(z.bd1_deg_per_rpm)
                .add(Cx(z.ad12_s * z.bd2_deg_per_s_rpm, 0.0));
            let den = zz.sub(Cx(1.0, 0.0)).mul(zz.sub(Cx(z.ad22, 0.0)));
            assert!(g.sub(num.div(den)).abs() < 1e-12 * g.abs());
            // A delay of one period is z^-1 exactly.
            let gd = model_response(alpha, beta, t, t, w);
            assert!(gd.sub(g.mul(Cx::expj(-w * t))).abs() < 1e-9 * g.abs());
        }
    }
}
