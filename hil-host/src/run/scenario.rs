//! A `run` scenario: the TOML file's profiles, switches and injected faults, their defaults,
//! ranges and checks (every error names the key and its line).

use std::path::Path;

use serde::Deserialize;

use super::*;

/// A profile: (time s, value) breakpoints, linear in between, constant beyond the ends.
#[derive(Clone, Debug, Deserialize)]
pub struct Profile(pub Vec<(f64, f64)>);

impl Profile {
    pub fn at(&self, t: f64) -> f64 {
        let p = &self.0;
        match p.iter().position(|&(tk, _)| tk > t) {
            None => p.last().map_or(0.0, |&(_, v)| v),
            Some(0) => p[0].1,
            Some(i) => {
                let (t0, v0) = p[i - 1];
                let (t1, v1) = p[i];
                v0 + (v1 - v0) * (t - t0) / (t1 - t0)
            }
        }
    }
    fn check(&self, name: &str) -> Result<(), String> {
        if self.0.is_empty() {
            return Err(format!("profile `{name}` is empty"));
        }
        if self.0.len() > MAX_PROFILE_POINTS {
            return Err(format!(
                "profile `{name}` has {} points; at most {MAX_PROFILE_POINTS}",
                self.0.len()
            ));
        }
        if let Some((t, v)) = self.0.iter().find(|(t, v)| !t.is_finite() || !v.is_finite()) {
            return Err(format!("profile `{name}` has a non-finite value ([{t}, {v}])"));
        }
        if let Some((t, _)) = self.0.iter().find(|(t, _)| *t < 0.0) {
            return Err(format!("profile `{name}`: time {t} s is before the start (0 s)"));
        }
        for w in self.0.windows(2) {
            if w[1].0 <= w[0].0 {
                return Err(format!(
                    "profile `{name}`: times must increase ({} then {})",
                    w[0].0, w[1].0
                ));
            }
        }
        Ok(())
    }

    /// [`Profile::check`], then every value within `lo..=hi` (`unit` for the message).
    fn check_range(&self, name: &str, (lo, hi): (f64, f64), unit: &str) -> Result<(), String> {
        self.check(name)?;
        if let Some((t, v)) = self.0.iter().find(|(_, v)| !(lo..=hi).contains(v)) {
            return Err(format!(
                "profile `{name}` at {t} s: {v} {unit} is outside {lo}..{hi} {unit}"
            ));
        }
        Ok(())
    }
}

/// An on/off request over time: `true` / `false`, or a profile of 0 and 1 values
/// (`[[0.0, 1.0], [0.5, 0.0]]`: on, off from 0.5 s).
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum Switch {
    Constant(bool),
    Profile(Profile),
}

impl Default for Switch {
    fn default() -> Self {
        Switch::Constant(false)
    }
}

impl Switch {
    pub fn at(&self, t: f64) -> bool {
        match self {
            Switch::Constant(on) => *on,
            Switch::Profile(p) => p.at(t) >= 0.5,
        }
    }
    fn check(&self, name: &str) -> Result<(), String> {
        let Switch::Profile(p) = self else { return Ok(()) };
        p.check(name)?;
        if let Some((t, v)) = p.0.iter().find(|(_, v)| *v != 0.0 && *v != 1.0) {
            return Err(format!("switch `{name}` at {t} s: {v} is neither 0 (off) nor 1 (on)"));
        }
        Ok(())
    }
}

fn constant(v: f64) -> Profile {
    Profile(vec![(0.0, v)])
}

/// What a `[[fault]]` injects.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// The battery falls to `u_batt_v` (0.1 s ramps in and out).
    BatterySag,
    /// Supply pressure sensor wire open: 0 counts.
    SupplyPressureOpen,
    /// Supply pressure sensor shorted to its supply: 4095 counts.
    SupplyPressureShort,
    /// No crank tooth edges (the cam sensor still works).
    CrankLost,
    /// The `actuator`'s rod stops where it is (its chamber pressure still follows the valve).
    VacuumStuck,
    /// The pump runs when switched on but moves no air.
    VacuumPumpFailure,
    /// The EVVT motor driver's fault pin is active.
    MotorDriverFault,
}

impl FaultKind {
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::BatterySag => "battery_sag",
            FaultKind::SupplyPressureOpen => "supply_pressure_open",
            FaultKind::SupplyPressureShort => "supply_pressure_short",
            FaultKind::CrankLost => "crank_lost",
            FaultKind::VacuumStuck => "vacuum_stuck",
            FaultKind::VacuumPumpFailure => "vacuum_pump_failure",
            FaultKind::MotorDriverFault => "motor_driver_fault",
        }
    }
}

/// The three vacuum actuators, in the ECU's order.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum VacuumActuator {
    /// Low-pressure turbine wastegate.
    Lpt,
    /// High-pressure turbine bypass.
    Hpt,
    /// High-pressure compressor bypass.
    Hpc,
}

impl VacuumActuator {
    pub fn index(self) -> usize {
        self as usize
    }
}

/// One injected fault, active from `start_s` until `end_s` (or the end of the run).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    pub kind: FaultKind,
    pub start_s: f64,
    #[serde(default)]
    pub end_s: Option<f64>,
    /// `battery_sag` only: the battery voltage in the sag.
    #[serde(default)]
    pub u_batt_v: Option<f64>,
    /// `vacuum_stuck` only: which actuator (default the wastegate, `lpt`).
    #[serde(default)]
    pub actuator: Option<VacuumActuator>,
}

impl FaultSpec {
    pub(super) fn active(&self, t: f64) -> bool {
        t >= self.start_s && self.end_s.is_none_or(|e| t < e)
    }
    fn check(&self, i: usize, duration_s: f64) -> Result<(), String> {
        let at = |what: String| Err(format!("fault #{} (`{}`): {what}", i + 1, self.kind.name()));
        if !(self.start_s.is_finite() && self.start_s >= 0.0) {
            return at(format!("start_s = {} must be a time ≥ 0", self.start_s));
        }
        if self.start_s >= duration_s {
            return at(format!(
                "start_s = {} is not within the run (duration_s = {duration_s}): the fault would never act",
                self.start_s
            ));
        }
        if let Some(e) = self.end_s {
            if !(e.is_finite() && e > self.start_s) {
                return at(format!("end_s = {e} must come after start_s = {}", self.start_s));
            }
        }
        match (self.kind, self.u_batt_v) {
            (FaultKind::BatterySag, None) => return at("needs `u_batt_v` (the battery voltage in the sag)".into()),
            (FaultKind::BatterySag, Some(u)) if !(u.is_finite() && (0.0..=30.0).contains(&u)) => {
                return at(format!("u_batt_v = {u} must lie in 0..30 V"))
            }
            (FaultKind::BatterySag, _) => {}
            (_, Some(_)) => return at("`u_batt_v` belongs to `battery_sag` only".into()),
            (_, None) => {}
        }
        if self.actuator.is_some() && self.kind != FaultKind::VacuumStuck {
            return at("`actuator` belongs to `vacuum_stuck` only".into());
        }
        Ok(())
    }
}

/// A scenario file. Every profile has a default, so a file names only what it changes.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    pub duration_s: f64,
    #[serde(default = "d_engine")]
    pub engine_rpm: Profile,
    #[serde(default = "d_batt")]
    pub u_batt_v: Profile,
    /// Hydraulic fluid (oil) temperature.
    #[serde(default = "d_temp")]
    pub temp_c: Profile,
    /// ECU board temperature (its internal sensor).
    #[serde(default = "d_temp_ecu")]
    pub temp_ecu_c: Profile,
    /// Set-points of the EHVVA supply and back pressure regulation.
    #[serde(default = "d_ph")]
    pub p_supply_mpa: Profile,
    #[serde(default = "d_pl")]
    pub p_back_mpa: Profile,
    #[serde(default = "d_amb")]
    pub p_amb_kpa: Profile,
    #[serde(default = "d_tank")]
    pub p_tank_initial_kpa: f64,
    #[serde(default = "d_phase")]
    pub cam_phase_setpoint_deg: Profile,
    /// LPT wastegate position set-point.
    #[serde(default = "d_wg")]
    pub wastegate_setpoint_pct: Profile,
    #[serde(default = "d_bypass")]
    pub hpt_bypass_setpoint_pct: Profile,
    #[serde(default = "d_bypass")]
    pub hpc_bypass_setpoint_pct: Profile,
    /// Requested valve opening and closing, crank degrees after the cycle's start.
    #[serde(default = "d_open")]
    pub valve_open_deg: Profile,
    #[serde(default = "d_close")]
    pub valve_close_deg: Profile,
    /// Requested lift valve (high lift) and snubber switch (soft seating) states.
    #[serde(default)]
    pub lift_high: Switch,
    #[serde(default)]
    pub snubber_on: Switch,
    #[serde(default, rename = "fault")]
    pub faults: Vec<FaultSpec>,
}

/// Shortest run: 10 EVVT log rows (10 ms each), several engine cycles at idle.
pub const MIN_DURATION_S: f64 = 0.1;
/// Most breakpoints in one profile (each step looks its value up).
pub const MAX_PROFILE_POINTS: usize = 10_000;
/// Longest scenario name (it names the output folder).
pub const MAX_NAME_CHARS: usize = 64;

/// A scenario's name names its output folder (`out/<name>`): a name, never a path. Letters,
/// digits, `-`, `_` and `.`, not starting with `.` (so no `..`, no hidden folder), no separators.
pub fn check_name(name: &str) -> Result<(), String> {
    let bad = |why: &str| {
        Err(format!(
            "name = {name:?} {why}; a name is letters, digits, `-`, `_` and `.`"
        ))
    };
    if name.is_empty() {
        return bad("is empty");
    }
    if name.chars().count() > MAX_NAME_CHARS {
        return bad(&format!("is longer than {MAX_NAME_CHARS} characters"));
    }
    if name.contains(['/', '\\']) {
        return bad("contains a path separator");
    }
    if name.starts_with('.') {
        return bad("starts with `.` (`..` or a hidden folder)");
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return bad(&format!("contains {c:?}"));
    }
    Ok(())
}

/// The physical range and unit of each profile: what the plant models and the ECU are made
/// for, and within the ranges of the log columns they end up in (DATA-FORMAT.md).
fn profile_range(name: &str) -> ((f64, f64), &'static str) {
    match name {
        "engine_rpm" => ((0.0, 12_000.0), "rpm"),
        "u_batt_v" => ((0.0, 32.0), "V"),
        "temp_c" => ((-40.0, 150.0), "°C"),
        "temp_ecu_c" => ((-40.0, 125.0), "°C"),
        "p_supply_mpa" => ((0.5, 25.0), "MPa"),
        "p_back_mpa" => ((0.0, 5.0), "MPa"),
        "p_amb_kpa" => ((50.0, 110.0), "kPa"),
        "cam_phase_setpoint_deg" => ((-30.0, 90.0), "crank deg"),
        "valve_open_deg" | "valve_close_deg" => ((0.0, 720.0), "crank deg"),
        // the three vacuum set-points
        _ => ((0.0, 100.0), "%"),
    }
}

/// The line where `key` is set in a scenario's TOML (`fault#n`: the n-th `[[fault]]`).
fn key_line(text: &str, key: &str) -> Option<usize> {
    if let Some(n) = key.strip_prefix("fault#").and_then(|n| n.parse::<usize>().ok()) {
        return text
            .lines()
            .enumerate()
            .filter(|(_, l)| l.trim_start().starts_with("[[fault]]"))
            .nth(n.checked_sub(1)?)
            .map(|(i, _)| i + 1);
    }
    text.lines()
        .position(|l| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|rest| rest.trim_start().starts_with('='))
        })
        .map(|i| i + 1)
}

fn d_engine() -> Profile {
    Profile(vec![
        (0.0, 800.0),
        (3.0, 800.0),
        (5.0, 1400.0),
        (8.0, 1400.0),
        (9.0, 1100.0),
    ])
}
fn d_batt() -> Profile {
    constant(14.0)
}
fn d_temp() -> Profile {
    constant(60.0)
}
fn d_temp_ecu() -> Profile {
    constant(45.0)
}
fn d_ph() -> Profile {
    constant(7.0)
}
fn d_pl() -> Profile {
    constant(1.0)
}
fn d_amb() -> Profile {
    constant(100.0)
}
fn d_tank() -> f64 {
    40.0
}
fn d_phase() -> Profile {
    Profile(vec![
        (0.0, 10.0),
        (1.0, 10.0),
        (1.001, 30.0),
        (5.0, 30.0),
        (5.001, 15.0),
    ])
}
fn d_wg() -> Profile {
    Profile(vec![
        (0.0, 20.0),
        (2.0, 20.0),
        (2.001, 60.0),
        (6.0, 60.0),
        (6.001, 40.0),
    ])
}
fn d_bypass() -> Profile {
    constant(0.0)
}
fn d_open() -> Profile {
    constant(360.0)
}
fn d_close() -> Profile {
    constant(540.0)
}

impl Scenario {
    /// The built-in scenario of the main job: speed ramps, a battery sag 14 → 9.5 → 14 V,
    /// phase and wastegate steps.
    pub fn default_scenario() -> Self {
        Scenario {
            name: "default".into(),
            duration_s: 10.0,
            engine_rpm: d_engine(),
            u_batt_v: Profile(vec![(0.0, 14.0), (8.0, 14.0), (8.2, 9.5), (9.0, 9.5), (9.2, 14.0)]),
            temp_c: d_temp(),
            temp_ecu_c: d_temp_ecu(),
            p_supply_mpa: d_ph(),
            p_back_mpa: d_pl(),
            p_amb_kpa: d_amb(),
            p_tank_initial_kpa: d_tank(),
            cam_phase_setpoint_deg: d_phase(),
            wastegate_setpoint_pct: d_wg(),
            hpt_bypass_setpoint_pct: d_bypass(),
            hpc_bypass_setpoint_pct: d_bypass(),
            valve_open_deg: d_open(),
            valve_close_deg: d_close(),
            lift_high: Switch::Constant(true),
            snubber_on: Switch::Constant(true),
            faults: Vec::new(),
        }
    }

    /// Parses and checks a scenario; every error starts with the file name and, where the
    /// problem has one, the line (from the TOML parser, or the line of the key at fault).
    pub fn from_toml(file: &Path, text: &str) -> Result<Self, String> {
        let s: Scenario = toml::from_str(text).map_err(|e| format!("{}: {e}", file.display()))?;
        s.check().map_err(|(key, e)| match key_line(text, &key) {
            Some(line) => format!("{}:{line}: {e}", file.display()),
            None => format!("{}: {e}", file.display()),
        })?;
        Ok(s)
    }

    /// Every value against its physical range before a run (so that a run cannot write a log
    /// its own `check` refuses, or a summary of NaN). The error comes with the key it is about
    /// (`fault` for the n-th `[[fault]]`, as `fault#n`).
    fn check(&self) -> Result<(), (String, String)> {
        fn key(k: &str) -> impl Fn(String) -> (String, String) + '_ {
            move |e| (k.to_string(), e)
        }
        check_name(&self.name).map_err(key("name"))?;
        // The logs are held in memory until written (the EHVVA log at 20 kHz: ~90 B a row);
        // the shortest run still gives every log enough rows for its summary.
        if !(self.duration_s >= MIN_DURATION_S && self.duration_s <= MAX_DURATION_S) {
            return Err(key("duration_s")(format!(
                "duration_s = {} must lie in {MIN_DURATION_S}..{MAX_DURATION_S} s",
                self.duration_s
            )));
        }
        if !(self.p_tank_initial_kpa.is_finite() && (1.0..=110.0).contains(&self.p_tank_initial_kpa)) {
            return Err(key("p_tank_initial_kpa")(format!(
                "p_tank_initial_kpa = {} must lie in 1..110 kPa",
                self.p_tank_initial_kpa
            )));
        }
        for (name, p) in self.profiles() {
            let (range, unit) = profile_range(name);
            p.check_range(name, range, unit).map_err(key(name))?;
        }
        // The back pressure stays below the supply (both piecewise linear: their breakpoints
        // are where the difference can be least).
        for &(t, _) in self.p_supply_mpa.0.iter().chain(&self.p_back_mpa.0) {
            let (ph, pl) = (self.p_supply_mpa.at(t), self.p_back_mpa.at(t));
            if !(ph > pl) {
                return Err(key("p_back_mpa")(format!(
                    "at {t} s the back pressure p_back_mpa = {pl} MPa is not below the supply p_supply_mpa = {ph} MPa"
                )));
            }
        }
        self.lift_high.check("lift_high").map_err(key("lift_high"))?;
        self.snubber_on.check("snubber_on").map_err(key("snubber_on"))?;
        for (i, f) in self.faults.iter().enumerate() {
            f.check(i, self.duration_s).map_err(key(&format!("fault#{}", i + 1)))?;
        }
        Ok(())
    }

    fn profiles(&self) -> [(&'static str, &Profile); 13] {
        [
            ("engine_rpm", &self.engine_rpm),
            ("u_batt_v", &self.u_batt_v),
            ("temp_c", &self.temp_c),
            ("temp_ecu_c", &self.temp_ecu_c),
            ("p_supply_mpa", &self.p_supply_mpa),
            ("p_back_mpa", &self.p_back_mpa),
            ("p_amb_kpa", &self.p_amb_kpa),
            ("cam_phase_setpoint_deg", &self.cam_phase_setpoint_deg),
            ("wastegate_setpoint_pct", &self.wastegate_setpoint_pct),
            ("hpt_bypass_setpoint_pct", &self.hpt_bypass_setpoint_pct),
            ("hpc_bypass_setpoint_pct", &self.hpc_bypass_setpoint_pct),
            ("valve_open_deg", &self.valve_open_deg),
            ("valve_close_deg", &self.valve_close_deg),
        ]
    }

    /// Battery voltage at `t` with any sag applied.
    pub fn u_batt_at(&self, t: f64) -> f64 {
        let mut u = self.u_batt_v.at(t);
        for f in self.faults.iter().filter(|f| f.kind == FaultKind::BatterySag) {
            let Some(u_sag) = f.u_batt_v else { continue };
            // Depth 0..1 with linear ramps in and out.
            let into = ((t - f.start_s) / SAG_RAMP_S).clamp(0.0, 1.0);
            let out = f.end_s.map_or(1.0, |e| 1.0 - ((t - e) / SAG_RAMP_S).clamp(0.0, 1.0));
            let depth = into.min(out);
            if depth > 0.0 {
                u = u.min(u + (u_sag - u) * depth);
            }
        }
        u
    }

    pub(super) fn fault_active(&self, kind: FaultKind, t: f64) -> bool {
        self.faults.iter().any(|f| f.kind == kind && f.active(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_interpolate_and_hold_their_ends() {
        let p = Profile(vec![(1.0, 10.0), (3.0, 30.0)]);
        assert_eq!(p.at(0.0), 10.0);
        assert_eq!(p.at(2.0), 20.0);
        assert_eq!(p.at(9.0), 30.0);
        assert!(Profile(vec![(1.0, 0.0), (1.0, 1.0)]).check("x").is_err());
    }

    #[test]
    fn scenario_errors_name_the_file_and_the_problem() {
        let e = Scenario::from_toml(Path::new("s.toml"), "name = \"x\"\nduration_s = 2.0\nbogus = 1\n").unwrap_err();
        assert!(e.starts_with("s.toml:") && e.contains("bogus"), "{e}");
        let e = Scenario::from_toml(Path::new("s.toml"), "name = \"x\"\nduration_s = -1.0\n").unwrap_err();
        assert!(e.contains("duration_s"), "{e}");
        let ok = Scenario::from_toml(
            Path::new("s.toml"),
            "name = \"x\"\nduration_s = 1.0\nu_batt_v = [[0.0, 14.0], [0.5, 9.0]]\n",
        )
        .unwrap();
        assert_eq!(ok.u_batt_v.at(0.25), 11.5);
    }
}
