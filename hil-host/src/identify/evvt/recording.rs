//! A recording's closed loop: the control law its metadata state, checked row by row to the
//! log's own resolution, and the recording cut into steady operating points (engine speed and
//! battery voltage) with the transitions between them left out and reported.

use std::ops::Range;

use crate::log::Log;

use super::*;

/// The closed loop a log states (metadata) and obeys (checked row by row).
pub(super) struct ClosedLoop<'a> {
    pub(super) file: &'a str,
    pub(super) kp: f64,
    pub(super) t_s: f64,
    pub(super) cmd_max: f64,
    pub(super) cam_events: Option<f64>,
    pub(super) time_s: Vec<f64>,
    pub(super) reference: &'a [f64],
    pub(super) phase: &'a [f64],
    pub(super) rpm: &'a [f64],
    pub(super) volt: &'a [f64],
    /// The step `motor_cmd_rpm` is logged in (0: full precision).
    pub(super) cmd_resolution_rpm: f64,
    /// Rows whose law value is at or beyond the saturation limit.
    pub(super) saturated: Vec<bool>,
}

/// The step a column is logged in: the largest of 1, 2, 5 × 10^k (k = −6..=3), at most 1 % of
/// the largest magnitude, that every value is a whole multiple of; 0 when none is (values
/// logged at full precision).
pub fn logged_resolution(values: &[f64]) -> f64 {
    let largest = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for k in (-6..=3).rev() {
        for m in [5.0, 2.0, 1.0] {
            let q = m * 10f64.powi(k);
            if q > 0.01 * largest {
                continue;
            }
            if values.iter().all(|v| {
                let x = v / q;
                (x - x.round()).abs() <= 1e-6
            }) {
                return q;
            }
        }
    }
    0.0
}

/// The log-level checks: plant, columns, metadata, and the stated law
/// `motor_cmd_rpm = clamp(kp (phase_ref_deg − phase_deg), ±motor_cmd_max_rpm)` in every row to
/// the command's own logged resolution (half a step, plus 1e-6 relative).
pub(super) fn closed_loop(log: &Log) -> Result<ClosedLoop<'_>, String> {
    let file = log.file.as_str();
    if log.plant != Plant::Evvt {
        return Err(format!(
            "{file}: plant is `{}`, identify evvt needs an `evvt` log",
            log.plant
        ));
    }
    let reference = log.col("phase_ref_deg").ok_or_else(|| {
        format!("{file}: no phase_ref_deg column: this is an open-loop log; identify evvt needs a closed-loop recording (phase_ref_deg and `# kp:`)")
    })?;
    let kp = log.meta_f64("kp").map_err(|e| e.to_string())?.ok_or_else(|| {
        format!("{file}: no `# kp:` metadata: the proportional gain of the closed loop (rpm per crank degree) is needed for the indirect approach G = H(I - H)^-1 K^-1")
    })?;
    if !(kp > 0.0) {
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
    if let Some(e) = cam_events {
        if !(e > 0.0) {
            return Err(format!(
                "{file}: metadata cam_events_per_cycle is {e}; it must be positive"
            ));
        }
    }
    let (cmd, phase, rpm, volt) = match (
        log.col("motor_cmd_rpm"),
        log.col("phase_deg"),
        log.col("engine_rpm"),
        log.col("u_batt_V"),
    ) {
        (Some(c), Some(p), Some(n), Some(v)) => (c, p, n, v),
        _ => return Err(format!("{file}: a required evvt column is missing")),
    };
    let cmd_max = log
        .meta_f64("motor_cmd_max_rpm")
        .map_err(|e| e.to_string())?
        .unwrap_or(f64::INFINITY);
    // The log must obey the law it states (otherwise K is not what the metadata says), to the
    // resolution the command is logged in (a command logged in whole rpm is within ±0.5 rpm).
    let q = logged_resolution(cmd);
    let mut disobey = 0usize;
    let mut first_bad = None;
    let mut saturated = vec![false; log.len()];
    for k in 0..log.len() {
        let law = kp * (reference[k] - phase[k]);
        saturated[k] = law.abs() >= cmd_max;
        let expect = law.clamp(-cmd_max, cmd_max);
        if (cmd[k] - expect).abs() > 0.5 * q + 1e-6 * (1.0 + expect.abs()) {
            disobey += 1;
            first_bad.get_or_insert(k);
        }
    }
    if disobey * 20 > log.len() {
        let k = first_bad.unwrap_or(0);
        return Err(format!(
            "{file}: motor_cmd_rpm does not follow kp (phase_ref_deg - phase_deg) with kp = {kp} to the log's resolution (±{} rpm: the command is logged {}) in {disobey} of {} rows (first at data row {}: {} logged, {} by the law): not the closed loop the metadata states (an open-loop log?)",
            0.5 * q,
            if q > 0.0 { format!("in steps of {q} rpm") } else { "at full precision".to_string() },
            log.len(),
            k + 1,
            cmd[k],
            (kp * (reference[k] - phase[k])).clamp(-cmd_max, cmd_max)
        ));
    }
    let time_s = match log.col("t_s") {
        Some(t) => t.to_vec(),
        None => (0..log.len()).map(|k| k as f64 * log.dt_s).collect(),
    };
    Ok(ClosedLoop {
        file,
        kp,
        t_s,
        cmd_max,
        cam_events,
        time_s,
        reference,
        phase,
        rpm,
        volt,
        cmd_resolution_rpm: q,
        saturated,
    })
}

/// Mean of x over the window k − w..=k + w (clipped at the ends), from prefix sums.
pub(super) fn rolling_mean(x: &[f64], w: usize) -> Vec<f64> {
    let mut prefix = Vec::with_capacity(x.len() + 1);
    prefix.push(0.0);
    for v in x {
        prefix.push(prefix[prefix.len() - 1] + v);
    }
    (0..x.len())
        .map(|k| {
            let (lo, hi) = (k.saturating_sub(w), (k + w + 1).min(x.len()));
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

/// max − min of x over the window k − w..=k + w (clipped at the ends).
pub(super) fn rolling_range(x: &[f64], w: usize) -> Vec<f64> {
    (0..x.len())
        .map(|k| {
            let s = &x[k.saturating_sub(w)..(k + w + 1).min(x.len())];
            let (lo, hi) = s.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(*v), hi.max(*v))
            });
            hi - lo
        })
        .collect()
}

/// Cuts the log into operating-point segments (module doc, "Recordings"): engine speed and
/// battery voltage are smoothed by a running mean over ±`settle_window_s`; a row is moving
/// when either smoothed signal spans more than its tolerance within ±`settle_window_s` of it.
/// Moving rows are transitions, left out; a steady stretch whose level drifts beyond the
/// tolerance from its start is cut there; steady stretches shorter than `min_segment_s` are
/// left out.
pub(super) fn segment_rows(cl: &ClosedLoop, opts: &EvvtIdentifyOptions) -> (Vec<Segment>, Vec<LeftOut>) {
    let n = cl.rpm.len();
    let w = ((opts.settle_window_s / cl.t_s).round() as usize).max(1);
    let n_med = rolling_mean(cl.rpm, w);
    let v_med = rolling_mean(cl.volt, w);
    let n_rng = rolling_range(&n_med, w);
    let v_rng = rolling_range(&v_med, w);
    let tol_n = |level: f64| opts.rpm_tolerance.max(0.01 * opts.rpm_tolerance_pct * level.abs());
    let moving: Vec<bool> = (0..n)
        .map(|k| n_rng[k] > tol_n(n_med[k]) || v_rng[k] > opts.voltage_tolerance_v)
        .collect();
    let t = &cl.time_s;
    let stretch = |rows: Range<usize>, reason: String| LeftOut {
        t_start_s: t[rows.start],
        t_end_s: t[rows.end - 1],
        rows,
        reason,
    };
    let mut left_out = Vec::new();
    let mut pieces: Vec<Range<usize>> = Vec::new();
    let mut k = 0;
    while k < n {
        let start = k;
        while k < n && moving[k] == moving[start] {
            k += 1;
        }
        if moving[start] {
            left_out.push(stretch(
                start..k,
                format!(
                    "transition: engine speed {:.0} -> {:.0} rpm, battery {:.2} -> {:.2} V (moving by more than ±{:.0} rpm / ±{:.2} V within ±{} s)",
                    n_med[start],
                    n_med[k - 1],
                    v_med[start],
                    v_med[k - 1],
                    tol_n(n_med[start]),
                    opts.voltage_tolerance_v,
                    opts.settle_window_s
                ),
            ));
            continue;
        }
        // A steady run: cut where its level has drifted beyond the tolerance.
        let mut s = start;
        for j in start..k {
            if (n_med[j] - n_med[s]).abs() > tol_n(n_med[s]) || (v_med[j] - v_med[s]).abs() > opts.voltage_tolerance_v {
                pieces.push(s..j);
                s = j;
            }
        }
        pieces.push(s..k);
    }
    let mut segments = Vec::new();
    for rows in pieces {
        let dur_s = rows.len() as f64 * cl.t_s;
        if dur_s < opts.min_segment_s {
            left_out.push(stretch(
                rows.clone(),
                format!(
                    "steady at {:.0} rpm, {:.2} V for only {dur_s:.2} s (less than {} s)",
                    n_med[rows.start], v_med[rows.start], opts.min_segment_s
                ),
            ));
            continue;
        }
        segments.push(Segment {
            index: segments.len() + 1,
            t_start_s: t[rows.start],
            t_end_s: t[rows.end - 1],
            engine_rpm: mean(&cl.rpm[rows.clone()]),
            u_batt_v: mean(&cl.volt[rows.clone()]),
            rows,
        });
    }
    left_out.sort_by_key(|l| l.rows.start);
    (segments, left_out)
}
