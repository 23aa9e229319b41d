//! `identify ehvva`: the EHVVA calibration of Li 2018 Sec. 5.2 from bench logs of valve events
//! over a test matrix like Table 1: per test condition (supply pressure Ph, temperature T) the
//! actuation delays td (VO, VC), the main-valve time constant τp and the discharge coefficient
//! Cd by the trust-region solver on the lift simulation error (eqs. (16)-(20), the event
//! simulation `diagnose` uses); then the tables td(Ph, T), τp(Ph, T), Cd(T), also resampled
//! onto model-core's breakpoints ([`EhvvaTableData`]).
//!
//! Two passes. Pass 1 ([`fit_onset`]): τp and Cd by the solver, td read from the lift for every
//! (τp, Cd) tried: the delay from the rising command to 1 % of the stroke and from the falling
//! command to 99 %, less the time the model itself takes to those levels ([`td_from_onset`];
//! the logs carry no pilot pressure, from which the paper reads td). A longer τp is mostly a
//! later onset, so there td absorbs τp. Pass 2 ([`fit_joint`]): td VO, td VC, τp and Cd
//! together from pass 1's solution, with the td and τp tables shaped in Ph and T as pass 1's
//! tables about the condition ([`shape_about`]: the plant reads them at the supply pressure of
//! the moment, which dips while the accumulator feeds the piston). td and τp still correlate
//! at about −0.99 ([`correlation`], reported per condition): events at a raised back pressure
//! (another fraction of the pressure rise starts the piston) and the closing edges separate
//! them, and then τp is identified as tightly as the pressure set-points are known.
//!
//! The valve the conditions are fitted on: [`identify`] takes the paper's (geometry, spring,
//! mass, flow paths of `EhvvaParams::paper_default`; only the varying parameters calibrated,
//! as in the paper). [`identify_on`] takes any valve; the command line and `calibrate` give it
//! the unit's own from `diagnose` ([`unit_valve`]): on a unit whose spring and areas are not
//! the paper's, the paper's valve puts that difference into td (tables that jump by
//! milliseconds between neighbouring conditions).
//!
//! A condition is every event within 0.25 MPa and 3 °C of the condition's first event; its
//! value is the mean of its events'. Its events whose supply set-points agree within 0.02 MPa
//! are simulated at their mean set-point. Events of one condition may differ in back pressure, lift
//! and switch valve: the model takes those as inputs.

use model_core::ehvva::{EhvvaParams, EhvvaTableData, EhvvaTables};
use serde_json::{json, Value};

use crate::diagnose::ehvva::{apply_knobs, calibrate_with, edge_delays_ms, simulate_all, Events, Knob};
use crate::lsq::{invert_spd, LsqOptions};

mod tables;
mod valve;
pub use tables::*;
pub use valve::*;

/// Delay of the reference simulation in [`td_from_onset`], ms.
const REFERENCE_TD_MS: f64 = 1.0;
/// Events closer than these belong to one test condition.
const SAME_P_MPA: f64 = 0.25;
const SAME_T_C: f64 = 3.0;
/// Supply set-points of one condition closer than this are one set-point read with noise, MPa.
const SAME_SETPOINT_MPA: f64 = 0.02;

/// The calibrated knobs of one condition: uniform τp and Cd tables.
pub const CONDITION_KNOBS: [Knob; 2] = [
    Knob {
        name: "tau_p_ms",
        lo: 0.01,
        hi: 1.0,
        apply: |p, v| p.tables.tau_ms = [[v; 3]; 2],
    },
    Knob {
        name: "cd",
        lo: 0.05,
        hi: 0.95,
        apply: |p, v| p.tables.cd = [v; 4],
    },
];

/// Sets uniform td tables (VO and VC).
fn set_td(p: &mut EhvvaParams, td_open_ms: f64, td_close_ms: f64) {
    p.tables.td_open_ms = [[td_open_ms; 5]; 4];
    p.tables.td_close_ms = [[td_close_ms; 5]; 4];
}

/// The model for one condition: the paper's geometry with uniform tables.
pub fn condition_params(td_open_ms: f64, td_close_ms: f64, tau_p_ms: f64, cd: f64) -> EhvvaParams {
    condition_params_on(&EhvvaParams::paper_default(), td_open_ms, td_close_ms, tau_p_ms, cd)
}

/// As [`condition_params`] on the valve `base` (its geometry, mass, spring and flow paths).
pub fn condition_params_on(
    base: &EhvvaParams,
    td_open_ms: f64,
    td_close_ms: f64,
    tau_p_ms: f64,
    cd: f64,
) -> EhvvaParams {
    let mut p = *base;
    set_td(&mut p, td_open_ms, td_close_ms);
    apply_knobs(&p, &CONDITION_KNOBS, &[tau_p_ms, cd])
}

/// What one condition gave.
#[derive(Clone, Debug)]
pub struct ConditionFit {
    pub p_supply_mpa: f64,
    pub temp_c: f64,
    pub events: usize,
    /// td VO and VC fitted with τp and Cd, ms.
    pub td_open_ms: f64,
    pub td_close_ms: f64,
    /// 95 % half-widths of td VO, VC (None on a bound or not identifiable).
    pub td_open_ci95: Option<f64>,
    pub td_close_ci95: Option<f64>,
    /// Pass 1, the paper's method: td VO and VC from the command edges to the lift onset
    /// ([`td_from_onset`]) with τp and Cd fitted under it ([`fit_onset`]), ms; that τp and Cd.
    /// They start pass 2. On a plant other than the reduced model (the ninth-order one) these
    /// are the td to use: the joint fit moves td along the td-τp ridge (module doc).
    pub td_open_onset_ms: f64,
    pub td_close_onset_ms: f64,
    pub tau_p_onset_ms: f64,
    pub cd_onset: f64,
    pub tau_p_ms: f64,
    pub cd: f64,
    /// 95 % half-widths of τp and Cd (None on a bound or not identifiable).
    pub tau_p_ci95: Option<f64>,
    pub cd_ci95: Option<f64>,
    /// Correlation of td VO and of td VC with τp from the solution's (JᵀJ)⁻¹ (None when
    /// singular): near ±1 the lift cannot tell a later onset from a slower pressure rise.
    pub corr_td_open_tau_p: Option<f64>,
    pub corr_td_close_tau_p: Option<f64>,
    /// Of the last solver run.
    pub iterations: usize,
    pub cost: f64,
    pub initial_cost: f64,
}

/// td (VO, VC) of `set` for the model `p` (its td tables are ignored) with the model's own
/// response time removed (module doc); `None` when no event shows the edge.
pub fn td_from_onset(p: &EhvvaParams, set: &Events) -> Result<(Option<f64>, Option<f64>), String> {
    // The model's own response is taken at a reference delay, not at zero: at td = 0 the
    // delay line cannot interpolate inside the step and adds part of a step.
    let mut p0 = *p;
    set_td(&mut p0, REFERENCE_TD_MS, REFERENCE_TD_MS);
    let mut sim = vec![0.0; set.samples];
    simulate_all(&p0, set, &mut sim)?;
    let (mut on, mut off) = (Vec::new(), Vec::new());
    for ev in &set.events {
        let stroke = ev.stroke_mm(&p0);
        let (m_on, m_off) = edge_delays_ms(&ev.lift_mm, ev.on_index, ev.off_index, stroke, set.dt_ms);
        let (s_on, s_off) = edge_delays_ms(
            &sim[ev.start..ev.start + ev.lift_mm.len()],
            ev.on_index,
            ev.off_index,
            stroke,
            set.dt_ms,
        );
        if let (Some(m), Some(s)) = (m_on, s_on) {
            on.push(m - s + REFERENCE_TD_MS);
        }
        if let (Some(m), Some(s)) = (m_off, s_off) {
            off.push(m - s + REFERENCE_TD_MS);
        }
    }
    let mean = |v: &[f64]| (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64).max(0.0));
    Ok((mean(&on), mean(&off)))
}

/// Sets `p`'s td tables from the lift onset (VC = VO where no closing edge was logged).
fn derive_td(p: &mut EhvvaParams, set: &Events) -> Result<(f64, f64), String> {
    let (on, off) = td_from_onset(p, set)?;
    let on = on.ok_or_else(|| {
        format!(
            "{}: the valve never opens to 1 % of its stroke after a command at this condition",
            set.file
        )
    })?;
    let off = off.unwrap_or(on);
    set_td(p, on, off);
    Ok((on, off))
}

/// The joint knobs of one condition: td VO, td VC, τp, Cd (uniform tables).
pub const JOINT_KNOBS: [Knob; 4] = [
    Knob {
        name: "td_open_ms",
        lo: 0.1,
        hi: 9.0,
        apply: |p, v| p.tables.td_open_ms = [[v; 5]; 4],
    },
    Knob {
        name: "td_close_ms",
        lo: 0.1,
        hi: 9.0,
        apply: |p, v| p.tables.td_close_ms = [[v; 5]; 4],
    },
    CONDITION_KNOBS[0],
    CONDITION_KNOBS[1],
];
/// As [`JOINT_KNOBS`] when no event shows a closing edge: one td for both edges.
const JOINT_KNOBS_ONE_TD: [Knob; 3] = [
    Knob {
        name: "td_ms",
        lo: 0.1,
        hi: 9.0,
        apply: |p, v| set_td(p, v, v),
    },
    CONDITION_KNOBS[0],
    CONDITION_KNOBS[1],
];

/// Replaces `p`'s uniform td and τp tables (the condition's values) by `shape` scaled so that
/// it takes those values at the condition (p_c, t_c): inside an event the supply pressure dips
/// as the accumulator feeds the piston, and the plant reads td(Ph) and τp(Ph) at that pressure.
pub fn shape_about(p: &mut EhvvaParams, shape: &EhvvaTableData, p_c: f64, t_c: f64) {
    let (vo, vc, tau) = (
        p.tables.td_open_ms[0][0],
        p.tables.td_close_ms[0][0],
        p.tables.tau_ms[0][0],
    );
    let mut q = EhvvaParams::paper_default();
    q.tables = *shape;
    let Ok(t) = EhvvaTables::<f64>::new(&q) else { return };
    let (so, sc) = t.t_delay_pair_ms(p_c, t_c);
    let st = t.tau_p_ms(p_c, t_c);
    for i in 0..4 {
        for j in 0..5 {
            p.tables.td_open_ms[i][j] = shape.td_open_ms[i][j] * vo / so;
            p.tables.td_close_ms[i][j] = shape.td_close_ms[i][j] * vc / sc;
        }
    }
    for i in 0..2 {
        for j in 0..3 {
            p.tables.tau_ms[i][j] = shape.tau_ms[i][j] * tau / st;
        }
    }
}

/// Correlation matrix (row-major p×p) of the parameters at `x` from the Gauss-Newton
/// covariance (JᵀJ)⁻¹ of the lift residual, J by central differences (relative step 1e-4);
/// `None` when JᵀJ is singular. The solver's CIs come from the same matrix; the correlation
/// says which parameters trade off against each other.
pub fn correlation(
    base: &EhvvaParams,
    knobs: &[Knob],
    x: &[f64],
    set: &Events,
    derive: &dyn Fn(&mut EhvvaParams) -> Result<(), String>,
) -> Result<Option<Vec<f64>>, String> {
    let params = |x: &[f64]| -> Result<EhvvaParams, String> {
        let mut p = apply_knobs(base, knobs, x);
        derive(&mut p)?;
        Ok(p)
    };
    let p = x.len();
    let mut jac = vec![vec![0.0; set.samples]; p];
    let (mut up, mut down) = (vec![0.0; set.samples], vec![0.0; set.samples]);
    for j in 0..p {
        let h = 1e-4 * x[j].abs().max(1e-3);
        let mut xu = x.to_vec();
        let mut xd = x.to_vec();
        xu[j] += h;
        xd[j] -= h;
        simulate_all(&params(&xu)?, set, &mut up)?;
        simulate_all(&params(&xd)?, set, &mut down)?;
        for k in 0..set.samples {
            jac[j][k] = (up[k] - down[k]) / (2.0 * h);
        }
    }
    let mut jtj = vec![0.0; p * p];
    for a in 0..p {
        for b in 0..p {
            jtj[a * p + b] = jac[a].iter().zip(&jac[b]).map(|(u, v)| u * v).sum();
        }
    }
    Ok(invert_spd(&jtj, p).map(|c| {
        let mut r = vec![0.0; p * p];
        for a in 0..p {
            for b in 0..p {
                r[a * p + b] = c[a * p + b] / (c[a * p + a] * c[b * p + b]).sqrt();
            }
        }
        r
    }))
}

/// The condition's mean supply pressure and temperature.
fn condition_point(set: &Events) -> (f64, f64) {
    let n = set.events.len() as f64;
    (
        set.events.iter().map(|e| e.inputs.p_supply_mpa).sum::<f64>() / n,
        set.events.iter().map(|e| e.inputs.temp_c).sum::<f64>() / n,
    )
}

/// First stage of a condition: τp and Cd by the solver with td read from the lift onset for
/// every (τp, Cd) tried ([`td_from_onset`]), from a coarse Cd scan at τp = 0.1 ms. Its td is
/// the onset estimate; it starts [`fit_joint`].
pub fn fit_onset(set: &Events, opts: &LsqOptions) -> Result<ConditionFit, String> {
    fit_onset_on(&EhvvaParams::paper_default(), set, opts)
}

/// As [`fit_onset`] on the valve `base` (its geometry; its tables are replaced).
pub fn fit_onset_on(base: &EhvvaParams, set: &Events, opts: &LsqOptions) -> Result<ConditionFit, String> {
    if set.events.is_empty() {
        return Err(format!("{}: a condition without events", set.file));
    }
    let base = *base;
    // Start: Cd from a coarse scan at τp = 0.1 ms (from a Cd far off, the first steps can
    // drive τp onto its bound, where the solver holds it).
    let measured = set.measured();
    let mut sim = vec![0.0; set.samples];
    let mut start = (f64::INFINITY, 0.4);
    for cd in [0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9] {
        let mut p = apply_knobs(&base, &CONDITION_KNOBS, &[0.1, cd]);
        if derive_td(&mut p, set).is_err() || simulate_all(&p, set, &mut sim).is_err() {
            continue;
        }
        let cost: f64 = sim.iter().zip(&measured).map(|(a, b)| (a - b).powi(2)).sum();
        if cost < start.0 {
            start = (cost, cd);
        }
    }
    let r = calibrate_with(&base, &CONDITION_KNOBS, &[0.1, start.1], set, opts, &|p| {
        derive_td(p, set).map(|_| ())
    })?;
    let mut p = apply_knobs(&base, &CONDITION_KNOBS, &r.x);
    let td = derive_td(&mut p, set)?;
    let (p_c, t_c) = condition_point(set);
    Ok(ConditionFit {
        p_supply_mpa: p_c,
        temp_c: t_c,
        events: set.events.len(),
        td_open_ms: td.0,
        td_close_ms: td.1,
        td_open_ci95: None,
        td_close_ci95: None,
        td_open_onset_ms: td.0,
        td_close_onset_ms: td.1,
        tau_p_onset_ms: r.x[0],
        cd_onset: r.x[1],
        tau_p_ms: r.x[0],
        cd: r.x[1],
        tau_p_ci95: r.ci95[0],
        cd_ci95: r.ci95[1],
        corr_td_open_tau_p: None,
        corr_td_close_tau_p: None,
        iterations: r.iterations,
        cost: r.cost,
        initial_cost: r.initial_cost,
    })
}

/// Second stage of a condition: td VO, td VC, τp and Cd together by the solver on the lift,
/// from the first stage's solution `start`. With `shape` (tables from the first stage over
/// all conditions) the model's td and τp tables keep that shape about the condition
/// ([`shape_about`]): the plant reads them at the supply pressure of the moment, which dips
/// during an event; without it they are uniform.
pub fn fit_joint(
    set: &Events,
    start: &ConditionFit,
    shape: Option<&EhvvaTableData>,
    opts: &LsqOptions,
) -> Result<ConditionFit, String> {
    fit_joint_on(&EhvvaParams::paper_default(), set, start, shape, opts)
}

/// As [`fit_joint`] on the valve `base` (its geometry; its tables are replaced).
pub fn fit_joint_on(
    base: &EhvvaParams,
    set: &Events,
    start: &ConditionFit,
    shape: Option<&EhvvaTableData>,
    opts: &LsqOptions,
) -> Result<ConditionFit, String> {
    let base = *base;
    let has_close = set.events.iter().any(|e| e.off_index.is_some());
    let (p_c, t_c) = condition_point(set);
    let (knobs, x0): (&[Knob], Vec<f64>) = if has_close {
        (
            &JOINT_KNOBS,
            vec![start.td_open_ms, start.td_close_ms, start.tau_p_ms, start.cd],
        )
    } else {
        (&JOINT_KNOBS_ONE_TD, vec![start.td_open_ms, start.tau_p_ms, start.cd])
    };
    let derive = |p: &mut EhvvaParams| -> Result<(), String> {
        if let Some(shape) = shape {
            shape_about(p, shape, p_c, t_c);
        }
        Ok(())
    };
    let r = calibrate_with(&base, knobs, &x0, set, opts, &derive)?;
    let corr = correlation(&base, knobs, &r.x, set, &derive)?;
    let m = knobs.len();
    let (tau_i, cd_i, close_i) = (m - 2, m - 1, usize::from(has_close));
    Ok(ConditionFit {
        p_supply_mpa: p_c,
        temp_c: t_c,
        events: set.events.len(),
        td_open_ms: r.x[0],
        td_close_ms: r.x[close_i],
        td_open_ci95: r.ci95[0],
        td_close_ci95: r.ci95[close_i],
        td_open_onset_ms: start.td_open_onset_ms,
        td_close_onset_ms: start.td_close_onset_ms,
        tau_p_onset_ms: start.tau_p_onset_ms,
        cd_onset: start.cd_onset,
        tau_p_ms: r.x[tau_i],
        cd: r.x[cd_i],
        tau_p_ci95: r.ci95[tau_i],
        cd_ci95: r.ci95[cd_i],
        corr_td_open_tau_p: corr.as_ref().map(|c| c[tau_i]),
        corr_td_close_tau_p: corr.as_ref().map(|c| c[close_i * m + tau_i]),
        iterations: start.iterations + r.iterations,
        cost: r.cost,
        initial_cost: start.initial_cost,
    })
}

/// One condition on its own: [`fit_onset`], then [`fit_joint`] with uniform tables.
pub fn fit_condition(set: &Events, opts: &LsqOptions) -> Result<ConditionFit, String> {
    fit_joint(set, &fit_onset(set, opts)?, None, opts)
}

/// Groups the events of several logs into test conditions (module doc).
pub fn conditions(sets: &[Events]) -> Vec<Events> {
    let mut groups: Vec<(f64, f64, Events)> = Vec::new();
    for set in sets {
        for (i, ev) in set.events.iter().enumerate() {
            let (p, t) = (ev.inputs.p_supply_mpa, ev.inputs.temp_c);
            let one = set.subset(|e| std::ptr::eq(e, &set.events[i]));
            match groups
                .iter_mut()
                .find(|(gp, gt, g)| (gp - p).abs() <= SAME_P_MPA && (gt - t).abs() <= SAME_T_C && g.dt_ms == set.dt_ms)
            {
                Some((_, _, g)) => {
                    let mut e = one.events[0].clone();
                    e.start = g.samples;
                    g.samples += e.lift_mm.len();
                    g.events.push(e);
                }
                None => groups.push((p, t, one)),
            }
        }
    }
    // By supply pressure, then temperature: pressures within SAME_P_MPA of the group before
    // count as one (the first event's reading is noisy; a plain sort on it would mix the
    // temperatures of one pressure in a recording whose conditions come in any order).
    groups.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut level = f64::NEG_INFINITY;
    let mut keyed: Vec<(f64, f64, Events)> = Vec::with_capacity(groups.len());
    for (p, t, g) in groups {
        if p - level > SAME_P_MPA {
            level = p;
        }
        keyed.push((level, t, g));
    }
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let groups = keyed;
    groups
        .into_iter()
        .map(|(_, _, mut g)| {
            // Events of a condition whose supply set-points (each read from 1 ms at rest) agree
            // within SAME_SETPOINT_MPA share one: the mean of theirs. The fit does not see
            // set-point errors and slides along the td-τp ridge to absorb them; pooling shrinks
            // them (τp 12 % → 5 % at a 0.01 MPa sensor noise, `tests/identify_ehvva.rs`).
            let setpoints: Vec<f64> = g.events.iter().map(|e| e.inputs.p_supply_mpa).collect();
            for e in &mut g.events {
                let own = e.inputs.p_supply_mpa;
                let near: Vec<f64> = setpoints
                    .iter()
                    .copied()
                    .filter(|p| (p - own).abs() <= SAME_SETPOINT_MPA)
                    .collect();
                e.inputs.p_supply_mpa = near.iter().sum::<f64>() / near.len() as f64;
            }
            g
        })
        .collect()
}

/// Solver settings of the per-condition fits.
pub fn default_options() -> LsqOptions {
    LsqOptions {
        max_iterations: 40,
        cost_tolerance: 1e-13,
        step_tolerance: 1e-12,
        fd_step: 1e-5,
        ..LsqOptions::default()
    }
}

/// Identifies the tables from the events of several logs; `progress` is told each condition.
pub fn identify(
    sets: &[Events],
    opts: &LsqOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Identified, String> {
    identify_on(&EhvvaParams::paper_default(), sets, opts, progress)
}

/// As [`identify`] on the valve `base` instead of the paper's: a unit whose spring, mass,
/// areas and flow paths differ from the paper's (`calibrate` takes them from the diagnosis's
/// baseline fit) moves and lags otherwise, and with the paper's valve the per-condition fits
/// would put that difference into td, τp and Cd.
pub fn identify_on(
    base: &EhvvaParams,
    sets: &[Events],
    opts: &LsqOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Identified, String> {
    let all = conditions(sets);
    if all.is_empty() {
        return Err("no valve events in the logs".into());
    }
    // A condition whose valve never opens has no delay to identify: left out, reported.
    let opens = |g: &Events| {
        g.events.iter().any(|ev| {
            edge_delays_ms(&ev.lift_mm, ev.on_index, ev.off_index, ev.stroke_mm(base), g.dt_ms)
                .0
                .is_some()
        })
    };
    let (groups, shut): (Vec<Events>, Vec<Events>) = all.into_iter().partition(|g| opens(g));
    let not_opening: Vec<String> = shut
        .iter()
        .map(|g| {
            let (p, t) = condition_point(g);
            format!("{p:.2} MPa / {t:.1} °C ({} events)", g.events.len())
        })
        .collect();
    if groups.is_empty() {
        return Err(format!(
            "the valve never opens to 1 % of its stroke after a command in any test condition ({})",
            not_opening.join(", ")
        ));
    }
    // Pass 1: onset td with τp and Cd per condition; its tables give the shape in Ph and T
    // that pass 2 keeps about each condition.
    let mut first = Vec::with_capacity(groups.len());
    for (k, g) in groups.iter().enumerate() {
        progress(k + 1, 2 * groups.len());
        first.push(fit_onset_on(base, g, opts)?);
    }
    let shape = Identified {
        conditions: first.clone(),
        ..Identified::default()
    }
    .table_data();
    let mut out = Vec::with_capacity(groups.len());
    for (k, (g, start)) in groups.iter().zip(&first).enumerate() {
        progress(groups.len() + k + 1, 2 * groups.len());
        out.push(fit_joint_on(base, g, start, Some(&shape), opts)?);
    }
    Ok(Identified {
        conditions: out,
        not_opening,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn condition(p_supply_mpa: f64, temp_c: f64, td_onset_ms: f64, tau_p_onset_ms: f64, cd_onset: f64) -> ConditionFit {
        ConditionFit {
            p_supply_mpa,
            temp_c,
            events: 4,
            td_open_ms: td_onset_ms,
            td_close_ms: td_onset_ms,
            td_open_ci95: None,
            td_close_ci95: None,
            td_open_onset_ms: td_onset_ms,
            td_close_onset_ms: td_onset_ms,
            tau_p_onset_ms,
            cd_onset,
            tau_p_ms: tau_p_onset_ms,
            cd: cd_onset,
            tau_p_ci95: None,
            cd_ci95: None,
            corr_td_open_tau_p: None,
            corr_td_close_tau_p: None,
            iterations: 1,
            cost: 0.0,
            initial_cost: 1.0,
        }
    }

    #[test]
    fn a_condition_with_cd_on_its_lower_bound_is_left_out_and_tau_p_on_a_bound_is_kept() {
        let (tau, cd) = (&CONDITION_KNOBS[0], &CONDITION_KNOBS[1]);
        // A grid of 5 and 8 MPa at -20 and 100 °C whose td falls with pressure; the 5 MPa, -20 °C
        // condition ends with tau_p on its upper bound (kept: its td is the pressure dependence),
        // the 5 MPa, 100 °C one with Cd on its lower bound and a td of 0.15 ms (left out).
        let id = Identified {
            conditions: vec![
                condition(5.0, -20.0, 4.0, tau.hi, 0.3),
                condition(5.0, 100.0, 0.15, 0.1, cd.lo),
                condition(8.0, -20.0, 2.5, 0.1, 0.4),
                condition(8.0, 100.0, 2.0, 0.1, 0.4),
            ],
            ..Identified::default()
        };
        assert!(enters_tables(&id.conditions[0]));
        assert!(!enters_tables(&id.conditions[1]));
        // A joint fit that slid along the td-τp ridge (td VO 1.1 ms from its onset reading,
        // well beyond its interval) is left out too; one within a few tenths stays.
        let mut slid = condition(5.0, -20.0, 4.3, 0.08, 0.45);
        slid.td_open_ms = 3.2;
        slid.td_open_ci95 = Some(0.18);
        assert!(!enters_tables(&slid));
        slid.td_open_ms = 4.0;
        assert!(enters_tables(&slid));
        assert_eq!(id.left_out(), vec!["5.00 MPa / 100.0 °C".to_string()]);
        let t = id.table_data_onset_td();
        // The kept condition sets the 5 MPa, -20 °C entry; the left-out one's 0.15 ms appears
        // nowhere (every entry is interpolated from 2.0-4.0 ms).
        assert!((t.td_open_ms[0][0] - 4.0).abs() < 1e-9, "{:?}", t.td_open_ms);
        for row in t.td_open_ms.iter().chain(t.td_close_ms.iter()) {
            for &v in row {
                assert!((2.0..=4.0).contains(&v), "{:?}", t.td_open_ms);
            }
        }
        assert!(id.text().contains("left out of the tables"));
    }
}
