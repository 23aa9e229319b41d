//! The identified conditions as the ECU's tables: td, τp and Cd interpolated over supply
//! pressure and oil temperature, with the report's text and JSON.

use super::*;

/// The identified tables.
#[derive(Clone, Debug, Default)]
pub struct Identified {
    pub conditions: Vec<ConditionFit>,
    /// Conditions where the valve never opened to 1 % of its stroke after a command (a unit
    /// near force balance, a raised back pressure): no td to read, left out and reported, as
    /// "Ph MPa / T °C (n events)".
    pub not_opening: Vec<String>,
}

/// Interpolates per-condition values at (p, t): bilinear on the grid of the conditions' distinct
/// pressures and temperatures when every grid point was tested (clamped outside it), otherwise
/// inverse-distance weighting of the nearest conditions (1 MPa ~ 20 °C).
fn interpolate(points: &[(f64, f64, f64)], p: f64, t: f64) -> f64 {
    let mut ps: Vec<f64> = Vec::new();
    let mut ts: Vec<f64> = Vec::new();
    for &(pp, tt, _) in points {
        if !ps.iter().any(|x| (x - pp).abs() <= SAME_P_MPA) {
            ps.push(pp);
        }
        if !ts.iter().any(|x| (x - tt).abs() <= SAME_T_C) {
            ts.push(tt);
        }
    }
    ps.sort_by(f64::total_cmp);
    ts.sort_by(f64::total_cmp);
    let at = |pp: f64, tt: f64| {
        points
            .iter()
            .find(|q| (q.0 - pp).abs() <= SAME_P_MPA && (q.1 - tt).abs() <= SAME_T_C)
            .map(|q| q.2)
    };
    let complete = ps.iter().all(|&pp| ts.iter().all(|&tt| at(pp, tt).is_some()));
    if complete && !ps.is_empty() {
        let bracket = |g: &[f64], x: f64| -> (usize, usize, f64) {
            if g.len() == 1 || x <= g[0] {
                return (0, 0, 0.0);
            }
            if x >= g[g.len() - 1] {
                return (g.len() - 1, g.len() - 1, 0.0);
            }
            let i = g.windows(2).position(|w| x >= w[0] && x <= w[1]).unwrap_or(0);
            (i, i + 1, (x - g[i]) / (g[i + 1] - g[i]))
        };
        let (i0, i1, fp) = bracket(&ps, p);
        let (j0, j1, ft) = bracket(&ts, t);
        let v = |i: usize, j: usize| at(ps[i], ts[j]).unwrap_or(f64::NAN);
        let a = v(i0, j0) * (1.0 - ft) + v(i0, j1) * ft;
        let b = v(i1, j0) * (1.0 - ft) + v(i1, j1) * ft;
        return a * (1.0 - fp) + b * fp;
    }
    let mut num = 0.0;
    let mut den = 0.0;
    for &(pp, tt, v) in points {
        let d2 = (pp - p).powi(2) + ((tt - t) / 20.0).powi(2);
        if d2 < 1e-12 {
            return v;
        }
        num += v / d2;
        den += 1.0 / d2;
    }
    num / den
}

/// Whether a condition's fit can enter the tables: its pass 1 (the paper's method) must not
/// end with Cd on its lower bound. There the reduced model's own response is so slow that the
/// onset td, the measured onset less that response, is no calibration (a unit at 5 MPa ended
/// at Cd 0.05 with td VC 0.15 ms). τp on a bound stays: the onset td beside it is still the
/// measured onset less a bounded response time, and at low supply pressure those conditions
/// carry the pressure dependence of td that the tables exist for.
///
/// Nor may its joint fit (pass 2) have slid along the td-τp ridge ([`slid_along_the_ridge`]).
pub fn enters_tables(c: &ConditionFit) -> bool {
    let cd = &CONDITION_KNOBS[1];
    c.cd_onset > cd.lo + 1e-3 * (cd.hi - cd.lo) && !slid_along_the_ridge(c)
}

/// How far a condition's joint td may lie from its onset td, ms, beyond three of its 95 %
/// half-widths: on the reduced model's logs the two agree within a few tenths of a
/// millisecond.
const RIDGE_SLIDE_MS: f64 = 0.5;

/// Whether the joint fit moved td VO or VC away from its onset reading by more than
/// [`RIDGE_SLIDE_MS`] and three of its 95 % half-widths: τp took the rest (a valve near its
/// force balance at 5 MPa, whose slow opening the lift cannot tell from a slower pressure
/// rise: td VO 1.1 ms early with τp 0.37 ms, four times its neighbours'). Such a set
/// reproduces the condition's lift but is no delay for the ECU's tables.
pub fn slid_along_the_ridge(c: &ConditionFit) -> bool {
    let slid = |joint: f64, onset: f64, ci95: Option<f64>| {
        (joint - onset).abs() > RIDGE_SLIDE_MS.max(3.0 * ci95.unwrap_or(0.0))
    };
    slid(c.td_open_ms, c.td_open_onset_ms, c.td_open_ci95) || slid(c.td_close_ms, c.td_close_onset_ms, c.td_close_ci95)
}

impl Identified {
    /// The conditions whose values make the tables ([`enters_tables`]; all of them if none
    /// would).
    fn tabled(&self) -> Vec<&ConditionFit> {
        let good: Vec<&ConditionFit> = self.conditions.iter().filter(|c| enters_tables(c)).collect();
        if good.is_empty() {
            self.conditions.iter().collect()
        } else {
            good
        }
    }

    /// The conditions left out of the tables, as "Ph MPa / T °C".
    pub fn left_out(&self) -> Vec<String> {
        let tabled = self.tabled();
        self.conditions
            .iter()
            .filter(|c| !tabled.iter().any(|t| std::ptr::eq(*t, *c)))
            .map(|c| format!("{:.2} MPa / {:.1} °C", c.p_supply_mpa, c.temp_c))
            .collect()
    }

    fn points(&self, f: impl Fn(&ConditionFit) -> f64) -> Vec<(f64, f64, f64)> {
        self.tabled()
            .into_iter()
            .map(|c| (c.p_supply_mpa, c.temp_c, f(c)))
            .collect()
    }

    /// Cd(T): the mean over the conditions at each temperature, interpolated linearly in T
    /// (clamped outside the tested range).
    pub fn cd_at(&self, t: f64) -> f64 {
        let mut by_t: Vec<(f64, f64, usize)> = Vec::new();
        for c in self.tabled() {
            match by_t.iter_mut().find(|(tt, _, _)| (tt - c.temp_c).abs() <= SAME_T_C) {
                Some(e) => {
                    e.1 += c.cd;
                    e.2 += 1;
                }
                None => by_t.push((c.temp_c, c.cd, 1)),
            }
        }
        let mut pts: Vec<(f64, f64)> = by_t.into_iter().map(|(t, s, n)| (t, s / n as f64)).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        if pts.is_empty() {
            return f64::NAN;
        }
        if t <= pts[0].0 {
            return pts[0].1;
        }
        for w in pts.windows(2) {
            if t <= w[1].0 {
                return w[0].1 + (w[1].1 - w[0].1) * (t - w[0].0) / (w[1].0 - w[0].0);
            }
        }
        pts[pts.len() - 1].1
    }

    /// The tables on model-core's breakpoints (paper's grid), ready for `EhvvaParams::tables`:
    /// td from the joint fit (the reduced model's parameter set, consistent with its τp).
    pub fn table_data(&self) -> EhvvaTableData {
        self.tables_with_td(|c| c.td_open_ms, |c| c.td_close_ms)
    }

    /// As [`Self::table_data`] with td from the command edges to the lift onset (pass 1, the
    /// paper's method; τp and Cd stay the joint fit's). On a plant that is not the reduced
    /// model (the ninth-order one) the two differ: the joint fit moves td along the td-τp
    /// ridge to fit the rise with the reduced model's first-order lag.
    pub fn table_data_onset_td(&self) -> EhvvaTableData {
        self.tables_with_td(|c| c.td_open_onset_ms, |c| c.td_close_onset_ms)
    }

    fn tables_with_td(
        &self,
        open: impl Fn(&ConditionFit) -> f64,
        close: impl Fn(&ConditionFit) -> f64,
    ) -> EhvvaTableData {
        let mut d = EhvvaTableData::paper_default();
        let vo = self.points(open);
        let vc = self.points(close);
        let tau = self.points(|c| c.tau_p_ms);
        for (i, &p) in d.td_p_supply_mpa.iter().enumerate() {
            for (j, &t) in d.td_temp_c.iter().enumerate() {
                d.td_open_ms[i][j] = interpolate(&vo, p, t);
                d.td_close_ms[i][j] = interpolate(&vc, p, t);
            }
        }
        for (i, &p) in d.tau_p_supply_mpa.iter().enumerate() {
            for (j, &t) in d.tau_temp_c.iter().enumerate() {
                d.tau_ms[i][j] = interpolate(&tau, p, t);
            }
        }
        for (k, &t) in d.cd_temp_c.iter().enumerate() {
            d.cd[k] = self.cd_at(t);
        }
        d
    }

    /// The human-readable report: per condition (solver evidence), then the tables.
    pub fn text(&self) -> String {
        let mut s = String::from("per test condition. Pass 1 (onset; Li 2018's method): td from the command edges to the lift onset, tau_p and Cd by trust-region least squares on the lift under it. Pass 2 (joint): td VO, td VC, tau_p and Cd together by the same solver from pass 1 (95 % CIs); r = correlation of td with tau_p:\n");
        s.push_str("  Ph MPa   T °C  ev | onset: td VO   td VC   tau_p    Cd     | joint: td VO ms (± 95 %)   td VC ms (± 95 %)   tau_p ms (± 95 %)    Cd (± 95 %)        r VO   r VC   it  cost (initial)\n");
        let ci = |c: Option<f64>| c.map_or("   n/a".to_string(), |v| format!("{v:.4}"));
        let r = |c: Option<f64>| c.map_or("  n/a".to_string(), |v| format!("{v:+.2}"));
        for c in &self.conditions {
            s.push_str(&format!(
                "  {:6.2} {:6.1} {:3} |      {:6.3}  {:6.3}  {:.4}  {:.4} |        {:.3} ± {:<8}   {:.3} ± {:<8}   {:.4} ± {:<8}  {:.4} ± {:<8}  {:>5}  {:>5}  {:3}  {:.3e} ({:.3e})\n",
                c.p_supply_mpa,
                c.temp_c,
                c.events,
                c.td_open_onset_ms,
                c.td_close_onset_ms,
                c.tau_p_onset_ms,
                c.cd_onset,
                c.td_open_ms,
                ci(c.td_open_ci95),
                c.td_close_ms,
                ci(c.td_close_ci95),
                c.tau_p_ms,
                ci(c.tau_p_ci95),
                c.cd,
                ci(c.cd_ci95),
                r(c.corr_td_open_tau_p),
                r(c.corr_td_close_tau_p),
                c.iterations,
                c.cost,
                c.initial_cost,
            ));
        }
        let d = self.table_data();
        let grid = |title: &str, ps: &[f64], ts: &[f64], v: &dyn Fn(usize, usize) -> f64| {
            let mut g = format!("\n{title}\n  Ph \\ T °C");
            for t in ts {
                g.push_str(&format!("{t:>9.0}"));
            }
            g.push('\n');
            for (i, p) in ps.iter().enumerate() {
                g.push_str(&format!("  {p:>6.1} MPa"));
                for j in 0..ts.len() {
                    g.push_str(&format!("{:>9.3}", v(i, j)));
                }
                g.push('\n');
            }
            g
        };
        let o = self.table_data_onset_td();
        if !self.not_opening.is_empty() {
            s.push_str(&format!(
                "\nnot identified (the valve never opened to 1 % of its stroke after a command there: no delay to read): {}\n",
                self.not_opening.join(", ")
            ));
        }
        let left = self.left_out();
        if !left.is_empty() {
            s.push_str(&format!(
                "\nleft out of the tables (pass 1 ended with Cd on its lower bound: the reduced model could not follow the lift there; or the joint fit slid along the td-tau_p ridge, td more than {RIDGE_SLIDE_MS} ms from its onset reading: no delay for the tables): {}; the tables interpolate the other conditions there\n",
                left.join(", ")
            ));
        }
        s.push_str("\ntd has two readings: onset (pass 1) = command edge to the lift onset (1 % / 99 % of the stroke) less the reduced model's own response time at pass 1's tau_p and Cd (Li 2018's td); joint (pass 2) = td fitted with tau_p and Cd, the set that best reproduces the whole lift in the reduced model (td and tau_p trade off along a ridge, r above). On reduced-model logs they agree; on another plant (ninth-order model) the onset td is its td, the joint set one consistent reduced-model calibration. The tau_p and Cd tables below are the joint fit's.\n");
        s.push_str(&grid(
            "td VO (ms) from the lift onset, on model-core's breakpoints",
            &o.td_p_supply_mpa,
            &o.td_temp_c,
            &|i, j| o.td_open_ms[i][j],
        ));
        s.push_str(&grid(
            "td VC (ms) from the lift onset",
            &o.td_p_supply_mpa,
            &o.td_temp_c,
            &|i, j| o.td_close_ms[i][j],
        ));
        s.push_str(&grid(
            "td VO (ms) joint fit with tau_p and Cd",
            &d.td_p_supply_mpa,
            &d.td_temp_c,
            &|i, j| d.td_open_ms[i][j],
        ));
        s.push_str(&grid(
            "td VC (ms) joint fit",
            &d.td_p_supply_mpa,
            &d.td_temp_c,
            &|i, j| d.td_close_ms[i][j],
        ));
        s.push_str(&grid("tau_p (ms)", &d.tau_p_supply_mpa, &d.tau_temp_c, &|i, j| {
            d.tau_ms[i][j]
        }));
        s.push_str("\nCd(T)\n  T °C    ");
        for t in d.cd_temp_c {
            s.push_str(&format!("{t:>9.0}"));
        }
        s.push_str("\n  Cd      ");
        for c in d.cd {
            s.push_str(&format!("{c:>9.3}"));
        }
        s.push('\n');
        s
    }

    /// The JSON report: per condition, the tables at the tested points, and `EhvvaTableData`.
    pub fn json(&self) -> Value {
        let d = self.table_data();
        let o = self.table_data_onset_td();
        json!({
            "td_definitions": "pass 1 (the paper's method), td_*_onset_ms and td_onset_tables: command edge to the lift onset (1 % rising, 99 % falling of the stroke) less the reduced model's own response time at pass 1's tau_p_onset_ms and cd_onset, which are fitted under that td; pass 2, td_*_ms and ehvva_table_data: td fitted jointly with tau_p and Cd from pass 1 (one consistent reduced-model calibration; td and tau_p correlate, corr_*). On reduced-model logs they agree; on another plant the onset td is its td",
            "left_out_of_tables": self.left_out(),
            "not_opening": self.not_opening,
            "td_onset_tables": {
                "td_p_supply_mpa": o.td_p_supply_mpa,
                "td_temp_c": o.td_temp_c,
                "td_open_ms": o.td_open_ms,
                "td_close_ms": o.td_close_ms,
            },
            "conditions": self.conditions.iter().map(|c| json!({
                "p_supply_MPa": c.p_supply_mpa,
                "temp_C": c.temp_c,
                "events": c.events,
                "td_open_ms": c.td_open_ms,
                "td_close_ms": c.td_close_ms,
                "td_open_ci95_ms": c.td_open_ci95,
                "td_close_ci95_ms": c.td_close_ci95,
                "td_open_onset_ms": c.td_open_onset_ms,
                "td_close_onset_ms": c.td_close_onset_ms,
                "tau_p_onset_ms": c.tau_p_onset_ms,
                "cd_onset": c.cd_onset,
                "corr_td_open_tau_p": c.corr_td_open_tau_p,
                "corr_td_close_tau_p": c.corr_td_close_tau_p,
                "tau_p_ms": c.tau_p_ms,
                "tau_p_ci95_ms": c.tau_p_ci95,
                "cd": c.cd,
                "cd_ci95": c.cd_ci95,
                "iterations": c.iterations,
                "cost": c.cost,
                "initial_cost": c.initial_cost,
            })).collect::<Vec<_>>(),
            "ehvva_table_data": {
                "td_p_supply_mpa": d.td_p_supply_mpa,
                "td_temp_c": d.td_temp_c,
                "td_open_ms": d.td_open_ms,
                "td_close_ms": d.td_close_ms,
                "tau_p_supply_mpa": d.tau_p_supply_mpa,
                "tau_temp_c": d.tau_temp_c,
                "tau_ms": d.tau_ms,
                "cd_temp_c": d.cd_temp_c,
                "cd": d.cd,
            }
        })
    }
}
