//! The identified points as the LPV tables α(N, V), β(N, V) on their breakpoints, as text
//! and as JSON.

use super::*;

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

/// Three breakpoints from values that form three clusters: by `tol` as [`breakpoints`], or,
/// where jitter spreads a cluster wider than `tol` (a bench's test points 806, 838 and 856
/// rpm), split at the two largest gaps when every cluster is narrower than half the smaller
/// of those gaps (clearly separated).
fn breakpoints3(values: &[f64], tol: f64) -> Vec<f64> {
    let by_tol = breakpoints(values, tol);
    if by_tol.len() == 3 || values.len() < 3 {
        return by_tol;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let mut gaps: Vec<(f64, usize)> = v.windows(2).enumerate().map(|(i, w)| (w[1] - w[0], i + 1)).collect();
    gaps.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut cut, smaller_gap) = ([gaps[0].1, gaps[1].1], gaps[1].0);
    cut.sort_unstable();
    let clusters = [&v[..cut[0]], &v[cut[0]..cut[1]], &v[cut[1]..]];
    let separated = clusters.iter().all(|c| c[c.len() - 1] - c[0] < 0.5 * smaller_gap);
    if separated {
        clusters.iter().map(|c| mean(c)).collect()
    } else {
        by_tol
    }
}

/// The model-core table from the points when they form a 3×3 grid of engine speed (groups
/// within 50 rpm, or split at the two largest gaps: `breakpoints3`) and battery voltage (groups within 0.5 V, likewise); several
/// points in a cell are averaged. The breakpoints are the group means.
pub fn lpv_table(points: &[EvvtPointResult]) -> Result<EvvtLpvTable, String> {
    let speeds = breakpoints3(&points.iter().map(|p| p.engine_rpm).collect::<Vec<_>>(), 50.0);
    let volts = breakpoints3(&points.iter().map(|p| p.u_batt_v).collect::<Vec<_>>(), 0.5);
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
        "{:>10} {:>8} {:>6} {:>10} {:>9} {:>10} {:>9}  method",
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
        let map = |v: f64, w: usize| {
            if v.is_finite() {
                format!("{v:>w$.4}")
            } else {
                format!("{:>w$}", "-")
            }
        };
        let _ = writeln!(
            s,
            "{:>10.1} {:>8.2} {:>6} {:>10.4} {:>9.4} {} {}  {} segment {} ({:.1}..{:.1} s)",
            p.engine_rpm,
            p.u_batt_v,
            p.order,
            p.alpha,
            p.beta,
            map(p.alpha_map, 10),
            map(p.beta_map, 9),
            p.method.name(),
            p.segment,
            p.t_start_s,
            p.t_end_s
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
/// "method", "segment", "t_start_s", "t_end_s", ...}]}` (the grid table follows from the points with [`lpv_table`]).
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
                "method": p.method.name(),
                "segment": p.segment,
                "t_start_s": p.t_start_s,
                "t_end_s": p.t_end_s,
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
