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
//! **Recordings.** A log may hold several operating points (a bench recording that sweeps the
//! nine (N, V) points in one file) and any persistently exciting reference (PRBS, steps,
//! chirps). [`identify_recording`] first checks the stated law in every row to the log's own
//! resolution (`motor_cmd_rpm` logged in whole rpm is within ±0.5 rpm of kp (r − y): the step
//! the command is logged in is found from its values, [`logged_resolution`]), then cuts the log
//! into segments: engine speed and battery voltage are smoothed by a running mean over
//! ±`settle_window_s`, and a row where either moves by more than its tolerance within that
//! window belongs to a transition, which is left out and reported; steady stretches shorter than
//! `min_segment_s` are left out too. A log that is one segment with a two-level PRBS reference is
//! the paper's experiment and goes steps 2-5 ([`EvvtMethod::PrbsMarkov`]). Every other segment
//! (several points in one log, or steps, chirps, a PRBS too short for the correlation) is fitted
//! by the **simulation error of the stated closed loop** ([`EvvtMethod::ClosedLoopSimulation`]):
//! the PRBS-correlation Markov estimate needs a white two-level input, a closed-loop output-error
//! fit needs only an input that excites. The logged reference drives u = clamp(kp (r − y_m),
//! ±max) into α/(s(s+β)) discretized exactly at T, with the measured phase y_m the plant's phase
//! τ earlier (the cam hold, step 1); α, β, the initial phase and rate are fitted by `lsq::solve`
//! to the logged phase from the best point of a coarse (β, α/β) grid. The reference is external
//! to the loop, so the sensor noise and quantization, which the feedback carries into the
//! command, do not bias the fit (the indirect approach again, in the time domain). A segment
//! whose reference does not excite (standard deviation below `min_reference_std_deg`, or a 95 %
//! CI of α or β beyond `max_relative_ci95`) is refused by name.
//!
//! Numerics: the Hankel SVD, the Schur eigenvalues (poles), the LU solves (frequency responses,
//! B from B̃) are nalgebra's, the PRBS regression is solved by QR ([`lsq::linear_lsq_qr`]), the
//! complex arithmetic is num-complex's.
//!
//! Units: phase in crank degrees, command in rpm, so α in crank-deg/(s²·rpm) and β in 1/s,
//! as model-core's [`EvvtLpvTable`] takes them.

use std::fmt::Write as _;
use std::ops::Range;
use std::path::Path;

use model_core::evvt::{zoh, EvvtLpvTable};
use nalgebra::{DMatrix, DVector, Schur, SVD};
use num_complex::Complex64;

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
    /// Fewest full PRBS clock intervals for the paper's method (fewer: the simulation fit).
    pub min_prbs_values: usize,
    /// Segmentation: engine speed counts as steady within the larger of this, rpm, ...
    pub rpm_tolerance: f64,
    /// ... and this share of the speed, %.
    pub rpm_tolerance_pct: f64,
    /// Battery voltage counts as steady within this, V.
    pub voltage_tolerance_v: f64,
    /// Half-width of the running mean and of the steadiness window, s.
    pub settle_window_s: f64,
    /// Shortest segment identified, s (shorter steady stretches are left out and reported).
    pub min_segment_s: f64,
    /// Least standard deviation of the reference over a segment for the simulation fit, deg.
    pub min_reference_std_deg: f64,
    /// Largest 95 % CI of α and β of the simulation fit relative to the value.
    pub max_relative_ci95: f64,
}

impl Default for EvvtIdentifyOptions {
    fn default() -> Self {
        Self {
            markov_horizon_s: 6.0,
            hankel_rows: 40,
            max_order: 6,
            min_prbs_values: 300,
            rpm_tolerance: 25.0,
            rpm_tolerance_pct: 2.5,
            voltage_tolerance_v: 0.25,
            settle_window_s: 0.5,
            min_segment_s: 10.0,
            min_reference_std_deg: 0.25,
            max_relative_ci95: 0.2,
        }
    }
}

/// The result for one operating point (a log, or a segment of a recording).
#[derive(Clone, Debug)]
pub struct EvvtPointResult {
    pub file: String,
    pub method: EvvtMethod,
    /// 1-based segment of the log, its rows (0-based, end exclusive) and times.
    pub segment: usize,
    pub rows: Range<usize>,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// The step `motor_cmd_rpm` is logged in (0: full precision).
    pub cmd_resolution_rpm: f64,
    /// Standard deviation of the reference over the segment, deg.
    pub reference_std_deg: f64,
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
    /// Simulation fit only (NaN otherwise): share of the phase's variance it explains, %, and
    /// the rms residual, deg.
    pub fit_vaf_pct: f64,
    pub fit_rms_deg: f64,
    /// Rows whose command is at the saturation limit, %.
    pub saturated_pct: f64,
    /// The lines of the per-log report.
    pub report: String,
}

mod markov;
use markov::*;
mod recording;
mod table;
pub use recording::logged_resolution;
use recording::*;
pub use table::{lpv_table, tables_text, to_json};

// ---------------------------------------------------------------------------------------------
// The closed loop a log states, its operating-point segments and the simulation-error fit.

/// How a segment's α, β were found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvvtMethod {
    /// The paper's: PRBS correlation → Markov parameters → Hankel SVD realization → indirect
    /// approach → pole map, refined by the frequency-response fit (module doc, steps 2-5).
    /// Used when the log is one operating point with a two-level PRBS reference.
    PrbsMarkov,
    /// α, β (and the initial phase and rate) by the simulation error of the stated closed loop
    /// from the logged reference (module doc, "Recordings"). Any persistently exciting reference.
    ClosedLoopSimulation,
}

impl EvvtMethod {
    pub fn name(self) -> &'static str {
        match self {
            EvvtMethod::PrbsMarkov => "prbs-markov",
            EvvtMethod::ClosedLoopSimulation => "closed-loop-simulation",
        }
    }
}

/// One stretch of rows at one operating point.
#[derive(Clone, Debug)]
pub struct Segment {
    /// 1-based, in log order.
    pub index: usize,
    /// Rows of the log (0-based, end exclusive; data row = index + 1).
    pub rows: Range<usize>,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Means over the segment.
    pub engine_rpm: f64,
    pub u_batt_v: f64,
}

impl Segment {
    fn describe(&self) -> String {
        format!(
            "segment {} (t = {:.2}..{:.2} s, data rows {}-{}, {:.0} rpm, {:.2} V)",
            self.index,
            self.t_start_s,
            self.t_end_s,
            self.rows.start + 1,
            self.rows.end,
            self.engine_rpm,
            self.u_batt_v
        )
    }
}

/// Rows left out of the identification, and why (a transition between operating points, or a
/// steady stretch too short to identify from).
#[derive(Clone, Debug)]
pub struct LeftOut {
    pub rows: Range<usize>,
    pub t_start_s: f64,
    pub t_end_s: f64,
    pub reason: String,
}

/// What the closed-loop simulation needs of a segment.
struct LoopData<'a> {
    reference: &'a [f64],
    phase: &'a [f64],
    kp: f64,
    cmd_max: f64,
    t_s: f64,
    tau_s: f64,
}

/// Simulates the stated loop from the logged reference with x = [α, β, phase0, rate0]:
/// u(k) = clamp(kp (r(k) − y_m(k)), ±max), the plant α/(s(s+β)) discretized exactly (ZOH) at T,
/// the measured phase y_m(k) = phase(kT − τ) (τ = dT + ε: the state d + 1 periods back moved on
/// by T − ε). Fills `out` with y_m − the logged phase.
fn simulate_loop(x: &[f64], d: &LoopData, out: &mut [f64]) -> Result<(), String> {
    let (alpha, beta, y0, v0) = (x[0], x[1], x[2], x[3]);
    let steps = (d.tau_s / d.t_s).floor();
    let eps = d.tau_s - steps * d.t_s;
    let back = steps as usize + 1;
    let full = zoh(alpha, beta, d.t_s);
    let part = zoh(alpha, beta, d.t_s - eps);
    let n = d.reference.len();
    let mut xs: Vec<(f64, f64)> = Vec::with_capacity(n + 1);
    let mut us: Vec<f64> = Vec::with_capacity(n);
    xs.push((y0, v0));
    for k in 0..n {
        let ym = if k >= back {
            let j = k - back;
            let (p, v) = xs[j];
            p + part.ad12_s * v + part.bd1_deg_per_rpm * us[j]
        } else {
            y0
        };
        if !ym.is_finite() || ym.abs() > 1e6 {
            return Err(format!("the simulated loop diverges at α = {alpha}, β = {beta}"));
        }
        let u = (d.kp * (d.reference[k] - ym)).clamp(-d.cmd_max, d.cmd_max);
        us.push(u);
        let (p, v) = xs[k];
        xs.push((
            p + full.ad12_s * v + full.bd1_deg_per_rpm * u,
            full.ad22 * v + full.bd2_deg_per_s_rpm * u,
        ));
        out[k] = ym - d.phase[k];
    }
    Ok(())
}

/// The simulation-error fit of one segment.
struct SimFit {
    x: Vec<f64>,
    ci95: Vec<Option<f64>>,
    start: [f64; 2],
    iterations: usize,
    initial_cost: f64,
    cost: f64,
    vaf_pct: f64,
    rms_deg: f64,
}

/// α, β, phase0, rate0 by `lsq::solve` on the simulation error, from the best of a coarse grid
/// over β (1..32 1/s) and the velocity gain α/β (0.01..0.32 deg/s per rpm).
fn fit_by_simulation(d: &LoopData) -> Result<SimFit, String> {
    let n = d.reference.len();
    let y0 = d.phase[0];
    let mut out = vec![0.0; n];
    let mut best = (f64::INFINITY, [0.3, 5.0]);
    for beta in [1.0, 2.0, 4.0, 8.0, 16.0, 32.0] {
        for gain in [0.01, 0.02, 0.04, 0.08, 0.16, 0.32] {
            let x = [gain * beta, beta, y0, 0.0];
            if simulate_loop(&x, d, &mut out).is_ok() {
                let cost: f64 = out.iter().map(|e| e * e).sum();
                if cost < best.0 {
                    best = (cost, [x[0], x[1]]);
                }
            }
        }
    }
    if !best.0.is_finite() {
        return Err("the simulated loop diverges for every starting α, β".into());
    }
    let (lo_y, hi_y) = d
        .phase
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
    let r = lsq::solve(
        |x: &[f64], out: &mut [f64]| simulate_loop(x, d, out),
        &[best.1[0], best.1[1], y0, 0.0],
        &[1e-5, 0.0, lo_y - 50.0, -1e4],
        &[100.0, 500.0, hi_y + 50.0, 1e4],
        n,
        &LsqOptions {
            max_iterations: 100,
            ..Default::default()
        },
    )
    .map_err(|e| format!("closed-loop simulation fit: {e}"))?;
    let m = mean(d.phase);
    let ss_tot: f64 = d.phase.iter().map(|y| (y - m).powi(2)).sum();
    Ok(SimFit {
        vaf_pct: 100.0 * (1.0 - 2.0 * r.cost / ss_tot.max(1e-300)),
        rms_deg: (2.0 * r.cost / n as f64).sqrt(),
        x: r.x,
        ci95: r.ci95,
        start: best.1,
        iterations: r.iterations,
        initial_cost: r.initial_cost,
        cost: r.cost,
    })
}

fn std_dev(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// Mean age of the held phase at engine speed `engine_rpm`, s (module doc, step 1).
fn measurement_delay_s(cl: &ClosedLoop, engine_rpm: f64, label: &str) -> Result<f64, String> {
    match cl.cam_events {
        Some(e) if engine_rpm > 0.0 => Ok(0.5 * 120.0 / (engine_rpm * e)),
        Some(_) => Err(format!(
            "{label}: the engine speed {engine_rpm} rpm is not positive: the cam-event sampling has no period"
        )),
        None => Ok(0.0),
    }
}

/// A result with the common fields filled and the method's fields empty.
fn base_result(cl: &ClosedLoop, seg: &Segment, method: EvvtMethod, tau_s: f64) -> EvvtPointResult {
    let rows = seg.rows.clone();
    let saturated = cl.saturated[rows.clone()].iter().filter(|s| **s).count();
    EvvtPointResult {
        file: cl.file.to_string(),
        method,
        segment: seg.index,
        t_start_s: seg.t_start_s,
        t_end_s: seg.t_end_s,
        rows: rows.clone(),
        engine_rpm: seg.engine_rpm,
        u_batt_v: seg.u_batt_v,
        kp_rpm_per_deg: cl.kp,
        control_period_s: cl.t_s,
        cmd_resolution_rpm: cl.cmd_resolution_rpm,
        reference_std_deg: std_dev(&cl.reference[rows.clone()]),
        prbs_hold_periods: 0,
        prbs_values: 0,
        prbs_amplitude_deg: f64::NAN,
        prbs_centre_deg: f64::NAN,
        cam_events_per_cycle: cl.cam_events,
        measurement_delay_s: tau_s,
        pulse_response: Vec::new(),
        hankel_sv: Vec::new(),
        order: 2,
        realization_vaf_pct: f64::NAN,
        closed_loop_poles_z: Vec::new(),
        open_loop_poles_z: Vec::new(),
        integrator_pole_s: f64::NAN,
        alpha_map: f64::NAN,
        beta_map: f64::NAN,
        alpha: f64::NAN,
        beta: f64::NAN,
        alpha_ci95: None,
        beta_ci95: None,
        crossover_rad_s: f64::NAN,
        fit_iterations: 0,
        fit_initial_cost: f64::NAN,
        fit_cost: f64::NAN,
        fit_vaf_pct: f64::NAN,
        fit_rms_deg: f64::NAN,
        saturated_pct: 100.0 * saturated as f64 / rows.len().max(1) as f64,
        report: String::new(),
    }
}

/// One segment by the closed-loop simulation error (any persistently exciting reference).
fn identify_by_simulation(
    cl: &ClosedLoop,
    seg: &Segment,
    opts: &EvvtIdentifyOptions,
) -> Result<EvvtPointResult, String> {
    let label = format!("{}: {}", cl.file, seg.describe());
    let tau = measurement_delay_s(cl, seg.engine_rpm, &label)?;
    let mut res = base_result(cl, seg, EvvtMethod::ClosedLoopSimulation, tau);
    let rows = seg.rows.clone();
    if !(res.reference_std_deg >= opts.min_reference_std_deg) {
        return Err(format!(
            "{label}: phase_ref_deg does not excite the loop: its standard deviation over the segment is {:.3} deg (at least {} deg needed): α and β cannot be identified from a constant reference; drive the reference with a PRBS, steps or a chirp",
            res.reference_std_deg, opts.min_reference_std_deg
        ));
    }
    let data = LoopData {
        reference: &cl.reference[rows.clone()],
        phase: &cl.phase[rows.clone()],
        kp: cl.kp,
        cmd_max: cl.cmd_max,
        t_s: cl.t_s,
        tau_s: tau,
    };
    let fit = fit_by_simulation(&data).map_err(|e| format!("{label}: {e}"))?;
    let (alpha, beta) = (fit.x[0], fit.x[1]);
    let rel = |ci: Option<f64>, v: f64| ci.map_or(f64::INFINITY, |c| c / v.abs().max(1e-300));
    let (ra, rb) = (rel(fit.ci95[0], alpha), rel(fit.ci95[1], beta));
    if !(ra <= opts.max_relative_ci95 && rb <= opts.max_relative_ci95) {
        return Err(format!(
            "{label}: α and β are not identifiable from this segment (95 % CI ±{:.1} % and ±{:.1} %, at most ±{:.0} % accepted): phase_ref_deg (standard deviation {:.3} deg) does not excite the loop enough",
            100.0 * ra,
            100.0 * rb,
            100.0 * opts.max_relative_ci95,
            res.reference_std_deg
        ));
    }
    let mut rep = String::new();
    let _ = writeln!(
        rep,
        "{}: {}: kp = {} rpm/deg, control period {} s, {} rows; command saturated in {:.2} % of rows",
        cl.file,
        seg.describe(),
        cl.kp,
        cl.t_s,
        rows.len(),
        res.saturated_pct
    );
    let switches = (1..data.reference.len())
        .filter(|&k| data.reference[k] != data.reference[k - 1])
        .count();
    let _ = writeln!(
        rep,
        "  reference: standard deviation {:.3} deg, {switches} changes; measurement delay τ = {:.2} ms ({})",
        res.reference_std_deg,
        1e3 * tau,
        match cl.cam_events {
            Some(e) => format!("half the cam-event period, {e} per cycle"),
            None => "phase sampled at every control instant".to_string(),
        }
    );
    let _ = writeln!(
        rep,
        "  closed-loop simulation-error fit of α e^(-sτ)/(s(s+β)) under the stated P law from phase_ref_deg to phase_deg (start α = {:.4}, β = {:.3} from a grid): {} iterations, cost {:.3e} -> {:.3e}, fit explains {:.2} % of the phase's variance, rms residual {:.3} deg",
        fit.start[0], fit.start[1], fit.iterations, fit.initial_cost, fit.cost, fit.vaf_pct, fit.rms_deg
    );
    let ci = |c: Option<f64>| c.map_or("n/a".to_string(), |c| format!("{c:.2e}"));
    let _ = writeln!(
        rep,
        "  α = {alpha:.4} ± {} crank-deg/(s²·rpm), β = {beta:.4} ± {} 1/s (95 % CI); initial phase {:.2} deg, rate {:.2} deg/s",
        ci(fit.ci95[0]),
        ci(fit.ci95[1]),
        fit.x[2],
        fit.x[3]
    );
    res.alpha = alpha;
    res.beta = beta;
    res.alpha_ci95 = fit.ci95[0];
    res.beta_ci95 = fit.ci95[1];
    res.fit_iterations = fit.iterations;
    res.fit_initial_cost = fit.initial_cost;
    res.fit_cost = fit.cost;
    res.fit_vaf_pct = fit.vaf_pct;
    res.fit_rms_deg = fit.rms_deg;
    res.report = rep;
    Ok(res)
}

/// Everything one log gave: its segments' results and what was left out.
#[derive(Clone, Debug)]
pub struct EvvtRecording {
    pub file: String,
    pub rows: usize,
    /// The step `motor_cmd_rpm` is logged in (0: full precision); the law is checked to half of it.
    pub cmd_resolution_rpm: f64,
    /// One result per operating-point segment, in log order.
    pub segments: Vec<EvvtPointResult>,
    /// Transitions and short stretches, in log order.
    pub left_out: Vec<LeftOut>,
    /// The recording's lines (the law check, segments, left-out stretches); each segment's
    /// own lines are in its `report`.
    pub report: String,
}

/// Identifies a log: one operating point or a recording over several (module doc,
/// "Recordings"). A log that is one segment with a two-level PRBS reference goes the paper's
/// way ([`EvvtMethod::PrbsMarkov`]); every other segment by the closed-loop simulation error.
pub fn identify_recording(log: &Log, opts: &EvvtIdentifyOptions) -> Result<EvvtRecording, String> {
    let cl = closed_loop(log)?;
    let (segs, left_out) = segment_rows(&cl, opts);
    let mut rep = String::new();
    let _ = writeln!(
        rep,
        "{}: {} rows; motor_cmd_rpm follows kp (phase_ref_deg - phase_deg) to the log's resolution (command logged {}); {} operating-point segment(s), {} stretch(es) left out",
        cl.file,
        log.len(),
        if cl.cmd_resolution_rpm > 0.0 {
            format!("in steps of {} rpm, checked to ±{} rpm", cl.cmd_resolution_rpm, 0.5 * cl.cmd_resolution_rpm)
        } else {
            "at full precision".to_string()
        },
        segs.len(),
        left_out.len()
    );
    for s in &segs {
        let _ = writeln!(rep, "  {}", s.describe());
    }
    for l in &left_out {
        let _ = writeln!(
            rep,
            "  left out: t = {:.2}..{:.2} s (data rows {}-{}): {}",
            l.t_start_s,
            l.t_end_s,
            l.rows.start + 1,
            l.rows.end,
            l.reason
        );
    }
    if segs.is_empty() {
        return Err(format!(
            "{}: no stretch of at least {} s at one operating point (engine speed within ±{} rpm or {} %, battery voltage within ±{} V):\n{rep}",
            cl.file, opts.min_segment_s, opts.rpm_tolerance, opts.rpm_tolerance_pct, opts.voltage_tolerance_v
        ));
    }
    let single = segs.len() == 1;
    let mut results = Vec::with_capacity(segs.len());
    for seg in &segs {
        let reference = &cl.reference[seg.rows.clone()];
        let r = match prbs_of(cl.file, reference, opts.min_prbs_values) {
            Ok(prbs) if single => identify_by_markov(&cl, seg, &prbs, opts)?,
            _ => identify_by_simulation(&cl, seg, opts)?,
        };
        results.push(r);
    }
    Ok(EvvtRecording {
        file: cl.file.to_string(),
        rows: log.len(),
        cmd_resolution_rpm: cl.cmd_resolution_rpm,
        segments: results,
        left_out,
        report: rep,
    })
}

/// Identifies a log of one operating point (the paper's per-point experiment, or any one
/// segment); a log with several is refused (use [`identify_recording`]).
pub fn identify_log(log: &Log, opts: &EvvtIdentifyOptions) -> Result<EvvtPointResult, String> {
    let mut rec = identify_recording(log, opts)?;
    if rec.segments.len() != 1 {
        return Err(format!(
            "{}: {} operating points in one log; identify_log takes one, identify_recording gives each:\n{}",
            rec.file,
            rec.segments.len(),
            rec.report
        ));
    }
    Ok(rec.segments.remove(0))
}

/// Reads and identifies each file ([`identify_recording`]); the points of all files, in order.
pub fn identify_files(paths: &[&Path], opts: &EvvtIdentifyOptions) -> Result<Vec<EvvtPointResult>, String> {
    let mut points = Vec::new();
    for p in paths {
        let log = read_log(p, Some(Plant::Evvt)).map_err(|e| e.to_string())?;
        points.extend(identify_recording(&log, opts)?.segments);
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Poles from nalgebra's Schur form, frequency response by the LU solve and the residue by
    /// the determinant lemma, against a system written as partial fractions:
    /// G(z) = 2/(z − 1) + 0.5/(z − 0.9) + (z − 0.2)/(z² − z + 0.5), a block-diagonal realization.
    #[test]
    fn poles_response_and_residue_of_a_known_system() {
        #[rustfmt::skip]
        let a = DMatrix::from_row_slice(4, 4, &[
            1.0, 0.0, 0.0, 0.0,
            0.0, 0.9, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
            0.0, 0.0, -0.5, 1.0,
        ]);
        let ss = StateSpace {
            a,
            b: DVector::from_column_slice(&[2.0, 0.5, 0.0, 1.0]),
            c: DVector::from_column_slice(&[1.0, 1.0, -0.2, 1.0]),
        };
        let mut poles = ss.poles().unwrap();
        poles.sort_by(|x, y| x.re.total_cmp(&y.re).then(x.im.total_cmp(&y.im)));
        let expect = [
            C64::new(0.5, -0.5),
            C64::new(0.5, 0.5),
            C64::new(0.9, 0.0),
            C64::new(1.0, 0.0),
        ];
        for (r, e) in poles.iter().zip(&expect) {
            assert!((r - e).norm() < 1e-12, "{r:?} vs {e:?}");
        }
        for z in [C64::new(0.3, 0.8), expj(0.7), C64::new(-1.5, 0.2)] {
            let direct = 2.0 / (z - 1.0) + 0.5 / (z - 0.9) + (z - 0.2) / (z * z - z + 0.5);
            let g = ss.response(z).unwrap();
            assert!((g - direct).norm() < 1e-12 * direct.norm(), "{g} vs {direct}");
        }
        let at = |p: C64| poles.iter().position(|q| (q - p).norm() < 1e-9).unwrap();
        assert!((ss.residue(&poles, at(C64::new(1.0, 0.0))).unwrap() - 2.0).norm() < 1e-9);
        assert!((ss.residue(&poles, at(C64::new(0.9, 0.0))).unwrap() - 0.5).norm() < 1e-9);
    }

    /// The realization of a known second-order pulse response (Markov parameters of a stable
    /// (A, B, C)) reproduces it, with the order found at the singular-value gap.
    #[test]
    fn hankel_realization_reproduces_a_known_system() {
        let truth = StateSpace {
            a: DMatrix::from_row_slice(2, 2, &[1.0, 0.01, 0.0, 0.95]),
            b: DVector::from_column_slice(&[0.0005, 0.1]),
            c: DVector::from_column_slice(&[1.0, 0.0]),
        };
        // Closed loop with unit feedback keeps it stable: A − BC.
        let cl = StateSpace {
            a: &truth.a - &truth.b * truth.c.transpose(),
            b: truth.b.clone(),
            c: truth.c.clone(),
        };
        let hold = 1;
        let s: Vec<f64> = std::iter::once(0.0).chain(cl.markov(400)).collect();
        let (ss, sigma, order) = realize(&s, hold, 40, 6).unwrap();
        assert_eq!(order, 2, "σ = {:?}", &sigma[..4]);
        assert!(sigma[1] > 1e6 * sigma[2]);
        let again = ss.markov(100);
        for k in 0..100 {
            assert!(
                (again[k] - s[k + 1]).abs() < 1e-9,
                "k {k}: {} vs {}",
                again[k],
                s[k + 1]
            );
        }
    }

    #[test]
    fn model_response_without_delay_is_the_zoh_transfer_function() {
        let (alpha, beta, t) = (0.4, 5.0, 0.01);
        let z = zoh(alpha, beta, t);
        for &w in &[0.3, 3.0, 30.0] {
            let g = model_response(alpha, beta, 0.0, t, w);
            let zz = expj(w * t);
            let num = (zz - z.ad22) * z.bd1_deg_per_rpm + z.ad12_s * z.bd2_deg_per_s_rpm;
            let den = (zz - 1.0) * (zz - z.ad22);
            assert!((g - num / den).norm() < 1e-12 * g.norm());
            // A delay of one period is z^-1 exactly.
            let gd = model_response(alpha, beta, t, t, w);
            assert!((gd - g * expj(-w * t)).norm() < 1e-9 * g.norm());
        }
    }

    #[test]
    fn logged_resolution_finds_the_step() {
        assert_eq!(logged_resolution(&[187.0, -3.0, 1000.0, 12.0]), 1.0);
        assert_eq!(logged_resolution(&[12.5, -37.5, 250.0]), 0.5);
        assert_eq!(logged_resolution(&[0.25, 0.5, 10.75]), 0.05);
        assert_eq!(logged_resolution(&[1.0 / 3.0, 2.0f64.sqrt(), 100.0]), 0.0);
        assert_eq!(logged_resolution(&[0.0, 0.0]), 0.0);
    }

    /// The closed-loop simulation with one period of delay at τ = T equals the one with the
    /// delay split as d = 0, ε = T (the same instant reached two ways), and the fit recovers
    /// α, β from its own noise-free output under a step reference.
    #[test]
    fn closed_loop_simulation_fit_recovers_its_own_parameters() {
        let reference: Vec<f64> = (0..3000)
            .map(
                |k| if (k / 300) % 2 == 0 { 20.0 } else { 30.0 } + if k > 1500 { (k as f64 * 0.01).sin() } else { 0.0 },
            )
            .collect();
        let zero = vec![0.0; reference.len()];
        let mut d = LoopData {
            reference: &reference,
            phase: &zero,
            kp: 25.0,
            cmd_max: 1000.0,
            t_s: 0.01,
            tau_s: 0.013,
        };
        let mut y = vec![0.0; reference.len()];
        simulate_loop(&[0.3, 4.0, 20.0, 0.0], &d, &mut y).unwrap();
        d.phase = &y;
        let fit = fit_by_simulation(&d).unwrap();
        assert!(
            (fit.x[0] / 0.3 - 1.0).abs() < 1e-5 && (fit.x[1] / 4.0 - 1.0).abs() < 1e-5,
            "{:?}",
            fit.x
        );
        assert!(fit.rms_deg < 1e-6);
    }
}
