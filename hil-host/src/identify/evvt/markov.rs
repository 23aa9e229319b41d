//! The paper's route for one PRBS log (module doc of `identify::evvt`, steps 2-5): PRBS
//! correlation → lifted Markov parameters → Hankel SVD realization → indirect approach → pole
//! map, refined by the frequency-response fit.

use super::*;

// ---------------------------------------------------------------------------------------------
// Linear algebra and complex numbers: nalgebra (SVD, Schur eigenvalues, LU) and num-complex.

pub(super) type C64 = Complex64;

pub(super) fn expj(w: f64) -> C64 {
    C64::from_polar(1.0, w)
}

/// Eigenvalues of a square matrix by nalgebra's real Schur decomposition.
pub(super) fn eigenvalues(a: &DMatrix<f64>) -> Result<Vec<C64>, String> {
    let schur = Schur::try_new(a.clone(), f64::EPSILON, 100_000)
        .ok_or("the Schur decomposition of the realization did not converge")?;
    Ok(schur.complex_eigenvalues().iter().copied().collect())
}

// ---------------------------------------------------------------------------------------------
// Step 1: the log.

pub(super) struct PrbsData {
    pub(super) hold: usize,
    /// Index of the first full clock interval.
    pub(super) offset: usize,
    /// PRBS values minus the centre, one per full clock interval.
    pub(super) values: Vec<f64>,
    pub(super) centre: f64,
    pub(super) amplitude: f64,
}

/// Finds the PRBS clock from the reference: two levels, switching only on a common grid.
pub(super) fn prbs_of(file: &str, reference: &[f64], min_values: usize) -> Result<PrbsData, String> {
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

pub(super) fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

// ---------------------------------------------------------------------------------------------
// ---------------------------------------------------------------------------------------------
// Steps 2-5.

/// The held-pulse response s(k), k = 0..J·p − 1, by the lifted FIR regression (module doc,
/// step 2), solved by QR for the p phases at once ([`lsq::linear_lsq_qr`]: one factorization
/// of the PRBS regressor, p right-hand sides).
pub(super) fn pulse_response(prbs: &PrbsData, phase: &[f64], lags: usize) -> Result<Vec<f64>, String> {
    let p = prbs.hold;
    let r = &prbs.values;
    let rows: Vec<usize> = (lags - 1..r.len())
        .filter(|&n| prbs.offset + n * p + p - 1 < phase.len())
        .collect();
    if rows.len() < 2 * (lags + 1) {
        return Err(format!("{} PRBS values are too few for {lags} lags", r.len()));
    }
    let q = lags + 1;
    let x: Vec<f64> = rows
        .iter()
        .flat_map(|&n| (0..q).map(move |i| if i == lags { 1.0 } else { r[n - i] }))
        .collect();
    let y: Vec<f64> = rows
        .iter()
        .flat_map(|&n| (0..p).map(move |phi| phase[prbs.offset + n * p + phi]))
        .collect();
    let theta = lsq::linear_lsq_qr(&x, rows.len(), q, &y, p).ok_or("the PRBS regression is singular")?;
    let mut s = vec![0.0; lags * p];
    for j in 0..lags {
        for phi in 0..p {
            s[j * p + phi] = theta[j * p + phi];
        }
    }
    Ok(s)
}

/// A realization (A n×n, B, C; D = 0).
pub(super) struct StateSpace {
    pub(super) a: DMatrix<f64>,
    pub(super) b: DVector<f64>,
    pub(super) c: DVector<f64>,
}

impl StateSpace {
    fn n(&self) -> usize {
        self.b.len()
    }
    /// Markov parameters C A^(k−1) B, k = 1..=count (D = 0).
    pub(super) fn markov(&self, count: usize) -> Vec<f64> {
        let mut x = self.b.clone();
        let mut out = Vec::with_capacity(count);
        for _ in 0..count {
            out.push(self.c.dot(&x));
            x = &self.a * x;
        }
        out
    }
    /// Poles: the eigenvalues of A.
    pub(super) fn poles(&self) -> Result<Vec<C64>, String> {
        eigenvalues(&self.a)
    }
    /// Frequency response C (zI − A)⁻¹ B by a complex LU solve; `None` at a pole.
    pub(super) fn response(&self, z: C64) -> Option<C64> {
        let n = self.n();
        let m = DMatrix::<C64>::from_fn(n, n, |i, j| {
            let d = if i == j { z } else { C64::new(0.0, 0.0) };
            d - C64::new(self.a[(i, j)], 0.0)
        });
        let b = DVector::<C64>::from_fn(n, |i, _| C64::new(self.b[i], 0.0));
        let x = m.lu().solve(&b)?;
        Some((0..n).map(|i| x[i] * self.c[i]).sum())
    }
    /// Residue of C (zI − A)⁻¹ B at the simple pole `poles[i]`, by the determinant lemma
    /// 1 + C (zI − A)⁻¹ B = det(zI − A + BC)/det(zI − A): with μ the eigenvalues of A − BC,
    /// the residue at λ_i is Π_j (λ_i − μ_j) / Π_{j≠i} (λ_i − λ_j).
    pub(super) fn residue(&self, poles: &[C64], i: usize) -> Result<C64, String> {
        let a_bc = &self.a - &self.b * self.c.transpose();
        let mu = eigenvalues(&a_bc)?;
        let lam = poles[i];
        let num = mu.iter().fold(C64::new(1.0, 0.0), |acc, m| acc * (lam - m));
        let den = poles
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .fold(C64::new(1.0, 0.0), |acc, (_, l)| acc * (lam - l));
        Ok(num / den)
    }
}

/// The Hankel SVD, order choice and realization (module doc, step 3).
pub(super) fn realize(
    s: &[f64],
    hold: usize,
    rows: usize,
    max_order: usize,
) -> Result<(StateSpace, Vec<f64>, usize), String> {
    let g = &s[hold..];
    let rows = rows.min(g.len() / 3);
    let cols = g.len() - rows - 1;
    if rows < max_order + 2 {
        return Err("the pulse response is too short for the Hankel matrix".into());
    }
    // H0 (rows × cols) and its thin SVD H0 = U Σ Vᵀ (nalgebra, singular values descending).
    let h0 = DMatrix::from_fn(rows, cols, |i, j| g[i + j]);
    let svd = SVD::new(h0, true, true);
    let (u, vt) = match (&svd.u, &svd.v_t) {
        (Some(u), Some(vt)) => (u, vt),
        _ => return Err("the Hankel SVD gave no singular vectors".into()),
    };
    let sigma: Vec<f64> = svd.singular_values.iter().copied().collect();
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
    if sq.iter().any(|&x| !(x > 0.0)) {
        return Err("zero Hankel singular value within the chosen order".into());
    }
    // O = U_n Σ^½ (rows × n), Ctrl = Σ^½ V_nᵀ (n × cols); A = Σ^-½ U_nᵀ H1 V_n Σ^-½ with H1
    // the shifted Hankel (shift invariance).
    let un = u.columns(0, n);
    let vtn = vt.rows(0, n);
    let h1 = DMatrix::from_fn(rows, cols, |i, j| g[i + j + 1]);
    let core = un.transpose() * h1 * vtn.transpose();
    let a = DMatrix::from_fn(n, n, |k, l| core[(k, l)] / (sq[k] * sq[l]));
    let c = DVector::from_fn(n, |k, _| un[(0, k)] * sq[k]);
    let b_tilde = DVector::from_fn(n, |k, _| vtn[(k, 0)] * sq[k]);
    // B = (I + A + … + A^{p−1})⁻¹ B̃.
    let mut sum = DMatrix::<f64>::zeros(n, n);
    let mut pow = DMatrix::<f64>::identity(n, n);
    for _ in 0..hold {
        sum += &pow;
        pow = &pow * &a;
    }
    let b = sum
        .lu()
        .solve(&b_tilde)
        .filter(|b| b.iter().all(|v| v.is_finite()))
        .ok_or("I + A + … + A^(p−1) is singular: the realization has a pole on the PRBS clock's aliasing circle")?;
    Ok((StateSpace { a, b, c }, sigma, order))
}

/// Model response to one held unit pulse of `hold` samples, k = 0..len−1.
pub(super) fn held_pulse_response(ss: &StateSpace, hold: usize, len: usize) -> Vec<f64> {
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
pub(super) fn model_response(alpha: f64, beta: f64, tau_s: f64, t_s: f64, w_rad_s: f64) -> C64 {
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
    let z = expj(w_rad_s * t_s);
    let zi = expj(-w_rad_s * t_s);
    let g1 = zi * gamma1.0 + gamma0.0;
    let g2 = zi * gamma1.1 + gamma0.1;
    let num = (z - full.ad22) * g1 + g2 * full.ad12_s;
    let den = (z - 1.0) * (z - full.ad22);
    num / den * expj(-w_rad_s * t_s * d)
}

/// One segment by the paper's method (module doc, steps 2-5).
pub(super) fn identify_by_markov(
    lp: &ClosedLoop,
    seg: &Segment,
    prbs: &PrbsData,
    opts: &EvvtIdentifyOptions,
) -> Result<EvvtPointResult, String> {
    let file = lp.file;
    let (kp, t_s, cam_events) = (lp.kp, lp.t_s, lp.cam_events);
    let phase = &lp.phase[seg.rows.clone()];
    let (engine_rpm, u_batt_v) = (seg.engine_rpm, seg.u_batt_v);
    let measurement_delay_s = measurement_delay_s(lp, engine_rpm, file)?;
    let mut res = base_result(lp, seg, EvvtMethod::PrbsMarkov, measurement_delay_s);
    let p = prbs.hold;
    let lags = ((opts.markov_horizon_s / (p as f64 * t_s)).ceil() as usize).max(opts.hankel_rows / p.max(1) + 4);
    let s = pulse_response(prbs, phase, lags).map_err(|e| format!("{file}: {e}"))?;
    let (cl, sigma, order) = realize(&s, p, opts.hankel_rows, opts.max_order).map_err(|e| format!("{file}: {e}"))?;
    let fit = held_pulse_response(&cl, p, s.len());
    let s_mean = mean(&s);
    let ss_tot: f64 = s.iter().map(|x| (x - s_mean).powi(2)).sum();
    let ss_res: f64 = s.iter().zip(&fit).map(|(a, b)| (a - b).powi(2)).sum();
    let vaf = 100.0 * (1.0 - ss_res / ss_tot.max(1e-300));

    // Indirect approach: G = (A + BC, B/kp, C).
    let g = StateSpace {
        a: &cl.a + &cl.b * cl.c.transpose(),
        b: &cl.b / kp,
        c: cl.c.clone(),
    };
    let cl_poles = cl.poles().map_err(|e| format!("{file}: {e}"))?;
    let ol_poles = g.poles().map_err(|e| format!("{file}: {e}"))?;
    let integ_i = (0..ol_poles.len())
        .min_by(|&x, &y| (ol_poles[x] - 1.0).norm().total_cmp(&(ol_poles[y] - 1.0).norm()))
        .ok_or_else(|| format!("{file}: the realization has no poles"))?;
    let integ = ol_poles[integ_i];
    let s_poles: Vec<C64> = ol_poles.iter().map(|z| z.ln() / t_s).collect();
    let integrator_pole_s = (integ.ln() / t_s).re;
    // Paper map: slowest other real (or nearly real) stable pole.
    let beta_map = s_poles
        .iter()
        .zip(&ol_poles)
        .enumerate()
        .filter(|(i, (_, z))| *i != integ_i && z.im.abs() < 1e-6 && z.re > 0.0)
        .map(|(_, (s, _))| -s.re)
        .filter(|b| *b > 0.0)
        .fold(f64::NAN, |m: f64, b| if m.is_nan() || b < m { b } else { m });
    let residue = g.residue(&ol_poles, integ_i).map_err(|e| format!("{file}: {e}"))?;
    let velocity_gain = residue.re / t_s;
    let alpha_map = beta_map * velocity_gain;

    // Crossover of kp·G and the fit band.
    let g_at = |w: f64| g.response(expj(w * t_s)).unwrap_or(C64::new(f64::NAN, f64::NAN));
    let h_at = |w: f64| cl.response(expj(w * t_s)).unwrap_or(C64::new(f64::NAN, f64::NAN));
    let nyquist = std::f64::consts::PI / t_s;
    let (mut lo, mut hi) = (1e-3f64, 0.5 * nyquist);
    if !(g_at(lo).norm() * kp >= 1.0 && g_at(hi).norm() * kp <= 1.0) {
        return Err(format!("{file}: the identified loop kp·G has no crossover between {lo} and {hi} rad/s: the identification failed (order {order}, Hankel singular values {:?})", &sigma[..sigma.len().min(6)]));
    }
    for _ in 0..100 {
        let mid = (lo * hi).sqrt();
        if g_at(mid).norm() * kp > 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let wc = (lo * hi).sqrt();
    let w_hi = (5.0 * wc).min(0.2 * nyquist);
    let w_lo = wc / 10.0;
    let freqs: Vec<f64> = (0..40).map(|i| w_lo * (w_hi / w_lo).powf(i as f64 / 39.0)).collect();
    let targets: Vec<(C64, f64)> = freqs
        .iter()
        .map(|&w| {
            let h = h_at(w);
            (g_at(w), (h * (1.0 - h)).norm())
        })
        .collect();
    let residual = |x: &[f64], out: &mut [f64]| -> Result<(), String> {
        for (i, (&w, (gid, wt))) in freqs.iter().zip(&targets).enumerate() {
            let e = (model_response(x[0], x[1], measurement_delay_s, t_s, w) / gid - 1.0) * *wt;
            out[2 * i] = e.re;
            out[2 * i + 1] = e.im;
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
        phase.len()
    );
    let _ = writeln!(
        rep,
        "  PRBS: {} values of ±{:.3} deg around {:.3} deg, clock {} control periods ({:.3} s); command saturated in {:.2} % of rows",
        prbs.values.len(),
        prbs.amplitude,
        prbs.centre,
        p,
        p as f64 * t_s,
        res.saturated_pct
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
    let fmt_z = |v: &[C64]| {
        v.iter()
            .map(|z| {
                if z.im.abs() < 1e-9 {
                    format!("{:.5}", z.re)
                } else {
                    format!("{:.5}{:+.5}i", z.re, z.im)
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

    res.prbs_hold_periods = p;
    res.prbs_values = prbs.values.len();
    res.prbs_amplitude_deg = prbs.amplitude;
    res.prbs_centre_deg = prbs.centre;
    res.pulse_response = s;
    res.hankel_sv = sigma;
    res.order = order;
    res.realization_vaf_pct = vaf;
    res.closed_loop_poles_z = cl_poles.iter().map(|z| (z.re, z.im)).collect();
    res.open_loop_poles_z = ol_poles.iter().map(|z| (z.re, z.im)).collect();
    res.integrator_pole_s = integrator_pole_s;
    res.alpha_map = alpha_map;
    res.beta_map = beta_map;
    res.alpha = fit_res.x[0];
    res.beta = fit_res.x[1];
    res.alpha_ci95 = fit_res.ci95[0];
    res.beta_ci95 = fit_res.ci95[1];
    res.crossover_rad_s = wc;
    res.fit_iterations = fit_res.iterations;
    res.fit_initial_cost = fit_res.initial_cost;
    res.fit_cost = fit_res.cost;
    res.report = rep;
    Ok(res)
}
