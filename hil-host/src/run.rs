//! `hil-host run`: the control code from model-core in closed loop with the plant models, all
//! three actuators at once, natively on the host.
//!
//! A scenario (TOML) gives the operating conditions over time as piecewise-linear profiles;
//! the run writes one DATA-FORMAT log per actuator (so its output feeds `diagnose`), a summary
//! and SVG plots.
//!
//! - EVVT: the scheduled phase controller every 10 ms on the 1-degree-quantized phase, the
//!   plant stepped at 1 ms.
//! - Vacuum (HPT wastegate): the position controller at 80 Hz (inverse model + supply-voltage
//!   compensation + PI), the valve/actuator at 1 ms, the tank and the pump switched on the
//!   pressure the actuator needs.
//! - EHVVA: one valve event per engine cycle at requested crank angles; the command edges are
//!   advanced by the calibrated actuation delays td(Ph, T) so that the valve moves at the
//!   requested angle; the reduced nonlinear model (eq. 12) is the plant. The timing error is
//!   measured in crank degrees where the valve starts to move: the lift rises through 1 % of
//!   the stroke (opening) and falls through 99 % (closing).

use std::path::{Path, PathBuf};

use model_core::control::evvt_phase::{EvvtFault, EvvtPhaseConfig, EvvtPhaseController, EvvtPhaseInputs};
use model_core::control::vacuum_position::{VacuumPositionConfig, VacuumPositionController, VacuumPositionFault, VacuumPositionInputs};
use model_core::ehvva::{EhvvaInputs, EhvvaParams, EhvvaPlant, EhvvaReduced, EhvvaTables};
use model_core::evvt::{quantize_phase_deg, EvvtParams, EvvtPlant};
use model_core::vacuum::{VacuumInputs, VacuumParams, VacuumTank, VacuumTankParams, VacuumValveActuator};
use serde::Deserialize;

use crate::log::format_log;
use crate::plot::{line_plot, Series};

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
        for w in self.0.windows(2) {
            if !(w[1].0 > w[0].0) {
                return Err(format!("profile `{name}`: times must increase ({} then {})", w[0].0, w[1].0));
            }
        }
        if self.0.iter().any(|(t, v)| !t.is_finite() || !v.is_finite()) {
            return Err(format!("profile `{name}` has a non-finite value"));
        }
        Ok(())
    }
}

fn constant(v: f64) -> Profile {
    Profile(vec![(0.0, v)])
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
    #[serde(default = "d_temp")]
    pub temp_c: Profile,
    #[serde(default = "d_ph")]
    pub p_supply_mpa: Profile,
    #[serde(default = "d_pl")]
    pub p_back_mpa: Profile,
    #[serde(default = "d_amb")]
    pub p_amb_kpa: Profile,
    #[serde(default = "d_phase")]
    pub cam_phase_setpoint_deg: Profile,
    #[serde(default = "d_wg")]
    pub wastegate_setpoint_pct: Profile,
    /// Requested valve opening and closing, crank degrees after the cycle's start.
    #[serde(default = "d_open")]
    pub valve_open_deg: Profile,
    #[serde(default = "d_close")]
    pub valve_close_deg: Profile,
    #[serde(default)]
    pub lift_high: bool,
    #[serde(default)]
    pub snubber_on: bool,
}

fn d_engine() -> Profile {
    Profile(vec![(0.0, 800.0), (3.0, 800.0), (5.0, 1400.0), (8.0, 1400.0), (9.0, 1100.0)])
}
fn d_batt() -> Profile {
    constant(14.0)
}
fn d_temp() -> Profile {
    constant(60.0)
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
fn d_phase() -> Profile {
    Profile(vec![(0.0, 10.0), (1.0, 10.0), (1.001, 30.0), (5.0, 30.0), (5.001, 15.0)])
}
fn d_wg() -> Profile {
    Profile(vec![(0.0, 20.0), (2.0, 20.0), (2.001, 60.0), (6.0, 60.0), (6.001, 40.0)])
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
            p_supply_mpa: d_ph(),
            p_back_mpa: d_pl(),
            p_amb_kpa: d_amb(),
            cam_phase_setpoint_deg: d_phase(),
            wastegate_setpoint_pct: d_wg(),
            valve_open_deg: d_open(),
            valve_close_deg: d_close(),
            lift_high: true,
            snubber_on: true,
        }
    }

    pub fn from_toml(file: &Path, text: &str) -> Result<Self, String> {
        let s: Scenario = toml::from_str(text).map_err(|e| format!("{}: {e}", file.display()))?;
        s.check().map_err(|e| format!("{}: {e}", file.display()))?;
        Ok(s)
    }

    fn check(&self) -> Result<(), String> {
        if !(self.duration_s > 0.0 && self.duration_s <= 3600.0) {
            return Err(format!("duration_s = {} must lie in (0, 3600]", self.duration_s));
        }
        for (name, p) in [
            ("engine_rpm", &self.engine_rpm),
            ("u_batt_v", &self.u_batt_v),
            ("temp_c", &self.temp_c),
            ("p_supply_mpa", &self.p_supply_mpa),
            ("p_back_mpa", &self.p_back_mpa),
            ("p_amb_kpa", &self.p_amb_kpa),
            ("cam_phase_setpoint_deg", &self.cam_phase_setpoint_deg),
            ("wastegate_setpoint_pct", &self.wastegate_setpoint_pct),
            ("valve_open_deg", &self.valve_open_deg),
            ("valve_close_deg", &self.valve_close_deg),
        ] {
            p.check(name)?;
        }
        Ok(())
    }
}

/// What the run measured.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub evvt_rms_error_deg: f64,
    pub evvt_settling_s: Vec<(f64, Option<f64>)>,
    pub vacuum_rms_error_pct: f64,
    pub vacuum_pump_on_fraction: f64,
    pub ehvva_events: usize,
    pub ehvva_open_error_deg: (f64, f64),
    pub ehvva_close_error_deg: (f64, f64),
    pub ehvva_seating_velocity_m_s: Option<f64>,
    pub simulated_s: f64,
    pub wall_s: f64,
}

impl Summary {
    pub fn text(&self, name: &str) -> String {
        let mut s = format!("scenario `{name}`: {:.1} s simulated in {:.2} s wall ({:.1} simulated s per wall s)\n", self.simulated_s, self.wall_s, self.simulated_s / self.wall_s.max(1e-9));
        s += &format!("EVVT   cam phase tracking: RMS error {:.2} deg\n", self.evvt_rms_error_deg);
        for (t, settle) in &self.evvt_settling_s {
            match settle {
                Some(d) => s += &format!("       step at {t:.2} s settled (±1 deg) in {d:.2} s\n"),
                None => s += &format!("       step at {t:.2} s did not settle (±1 deg)\n"),
            }
        }
        s += &format!("vacuum wastegate tracking: RMS error {:.2} %, pump on {:.0} % of the time\n", self.vacuum_rms_error_pct, 100.0 * self.vacuum_pump_on_fraction);
        s += &format!(
            "EHVVA  {} valve events: opening error mean {:+.2} / max |{:.2}| crank deg, closing error mean {:+.2} / max |{:.2}| crank deg\n",
            self.ehvva_events, self.ehvva_open_error_deg.0, self.ehvva_open_error_deg.1, self.ehvva_close_error_deg.0, self.ehvva_close_error_deg.1
        );
        if let Some(v) = self.ehvva_seating_velocity_m_s {
            s += &format!("       seating velocity {:.2} m/s (largest)\n", v);
        }
        s
    }
}

const EVVT_CONTROL_S: f64 = 0.01;
const VACUUM_CONTROL_S: f64 = 1.0 / 80.0;
/// 0.5 ms: both control periods (10 ms, 12.5 ms) are whole multiples, so logs are uniform.
const PLANT_S: f64 = 0.0005;
const EHVVA_DT_MS: f64 = 0.01;
/// Valve model steps per logged sample (10 kHz log).
const EHVVA_LOG_EVERY: usize = 10;

/// Runs the scenario; writes logs and plots into `out` when given.
pub fn run(sc: &Scenario, out: Option<&Path>) -> Result<Summary, String> {
    let started = std::time::Instant::now();
    let err = |e: &dyn std::fmt::Debug| format!("{e:?}");

    // EVVT.
    let mut evvt = EvvtPlant::<f32>::new(&EvvtParams::default()).map_err(|e| err(&e))?;
    evvt.reset(sc.cam_phase_setpoint_deg.at(0.0) as f32);
    let mut phase_ctl = EvvtPhaseController::<f32>::new(&EvvtPhaseConfig::default()).map_err(|e| err(&e))?;
    // Vacuum.
    let wg_params = VacuumParams::hpt();
    let mut wg = VacuumValveActuator::<f32>::new(&wg_params).map_err(|e| err(&e))?;
    let mut wg_ctl = VacuumPositionController::<f32>::new(&VacuumPositionConfig::for_actuator(wg_params)).map_err(|e| err(&e))?;
    let mut tank = VacuumTank::<f32>::new(&VacuumTankParams::paper(), 40.0).map_err(|e| err(&e))?;
    // EHVVA.
    let ehvva_params = EhvvaParams::paper_default();
    let tables = EhvvaTables::<f32>::new(&ehvva_params).map_err(|e| err(&e))?;
    let inputs_at = |t: f64| EhvvaInputs::<f32> {
        p_supply_mpa: sc.p_supply_mpa.at(t) as f32,
        p_back_mpa: sc.p_back_mpa.at(t) as f32,
        temp_c: sc.temp_c.at(t) as f32,
        lift_high: sc.lift_high,
        snubber_on: sc.snubber_on,
    };
    let mut valve = EhvvaReduced::<f32>::new(&ehvva_params, &inputs_at(0.0), EHVVA_DT_MS).map_err(|e| err(&e))?;

    let n = (sc.duration_s / PLANT_S).round() as usize;
    let evvt_every = (EVVT_CONTROL_S / PLANT_S).round() as usize;
    let mut evvt_log: Vec<[f64; 6]> = Vec::new();
    let mut vac_log: Vec<[f64; 7]> = Vec::new();
    let mut valve_log: Vec<[f64; 8]> = Vec::new();
    let (mut motor_cmd, mut duty, mut pump_on) = (0.0f32, 0.0f32, false);
    let vacuum_every = (VACUUM_CONTROL_S / PLANT_S).round() as usize;
    let (mut evvt_se, mut evvt_n, mut vac_se, mut vac_n, mut pump_steps) = (0.0, 0usize, 0.0, 0usize, 0usize);

    // EHVVA scheduling state: crank angle integrates engine speed; each cycle (720 deg) gets
    // one event whose command edges are advanced by td.
    let mut crank_deg = 0.0f64;
    let mut cycle_start_t = 0.0f64;
    let mut pilot_on_at: Option<f64> = None;
    let mut pilot_off_at: Option<f64> = None;
    let mut u_pilot = false;
    let mut requested: Option<(f64, f64)> = None; // (open deg, close deg) of this cycle
    let mut open_errors = Vec::new();
    let mut close_errors = Vec::new();
    let mut opened_this_cycle = false;
    let mut closed_this_cycle = false;
    let mut prev_lift = 0.0f64;
    let mut worst_seat: Option<f64> = None;
    let valve_steps_per_plant = (PLANT_S * 1000.0 / EHVVA_DT_MS).round() as usize;

    for k in 0..n {
        let t = k as f64 * PLANT_S;
        let rpm = sc.engine_rpm.at(t);
        let u_batt = sc.u_batt_v.at(t);
        let p_amb = sc.p_amb_kpa.at(t);

        // --- EVVT, 100 Hz control.
        if k % evvt_every == 0 {
            let meas = quantize_phase_deg(evvt.phase_deg(), 1.0f32);
            let sp = sc.cam_phase_setpoint_deg.at(t);
            let o = phase_ctl.update(
                &EvvtPhaseInputs { setpoint_deg: sp as f32, measured_phase_deg: meas, engine_rpm: rpm as f32, u_batt_v: u_batt as f32, cranking: false, fault: EvvtFault::None },
                EVVT_CONTROL_S as f32,
            );
            motor_cmd = o.motor_cmd_rpm;
            let e = sp - evvt.phase_deg() as f64;
            evvt_se += e * e;
            evvt_n += 1;
            evvt_log.push([t, motor_cmd as f64, rpm, u_batt, sp, meas as f64]);
        }
        evvt.step(motor_cmd, rpm as f32, u_batt as f32, PLANT_S as f32);

        // --- Vacuum, 80 Hz control.
        if k % vacuum_every == 0 {
            let sp = sc.wastegate_setpoint_pct.at(t);
            let o = wg_ctl.step(
                &VacuumPositionInputs {
                    setpoint_pct: sp as f32,
                    measured_x_pct: wg.x_pct(),
                    p_amb_kpa: p_amb as f32,
                    p_tank_kpa: tank.p_tank_kpa(),
                    u_batt_v: u_batt as f32,
                    enabled: true,
                    fault: VacuumPositionFault::None,
                },
                VACUUM_CONTROL_S as f32,
            );
            duty = o.duty_pct;
            // Pump with hysteresis around the needed tank pressure (Sec. 5.3).
            if o.pump_request {
                pump_on = true;
            } else if tank.p_tank_kpa() < o.p_tank_needed_kpa - 10.0 {
                pump_on = false;
            }
            let e = sp - wg.x_pct() as f64;
            vac_se += e * e;
            vac_n += 1;
            vac_log.push([t, duty as f64, u_batt, p_amb, tank.p_tank_kpa() as f64, wg.x_pct() as f64, wg.p_act_kpa() as f64]);
        }
        let vo = wg.step(&VacuumInputs { duty_pct: duty, u_batt_v: u_batt as f32, p_amb_kpa: p_amb as f32, p_tank_kpa: tank.p_tank_kpa() }, PLANT_S as f32);
        tank.step(pump_on, vo.flow_to_tank_mg_s, p_amb as f32, PLANT_S as f32);
        if pump_on {
            pump_steps += 1;
        }

        // --- EHVVA: crank angle, scheduling in the crank domain, the valve at 10 µs.
        let deg_per_s = rpm * 6.0;
        let new_crank = crank_deg + deg_per_s * PLANT_S;
        if requested.is_none() || new_crank >= 720.0 {
            if new_crank >= 720.0 {
                cycle_start_t = t + (720.0 - crank_deg) / deg_per_s;
                crank_deg = new_crank - 720.0;
            } else {
                crank_deg = new_crank;
            }
            let (open_deg, close_deg) = (sc.valve_open_deg.at(t), sc.valve_close_deg.at(t));
            let inp = inputs_at(t);
            let td_open_s = tables.t_delay_ms(inp.p_supply_mpa, inp.temp_c, true) as f64 / 1000.0;
            let td_close_s = tables.t_delay_ms(inp.p_supply_mpa, inp.temp_c, false) as f64 / 1000.0;
            // Time of the requested angles at the present speed, minus the delays.
            pilot_on_at = Some(cycle_start_t + open_deg / deg_per_s - td_open_s);
            pilot_off_at = Some(cycle_start_t + close_deg / deg_per_s - td_close_s);
            requested = Some((open_deg, close_deg));
            opened_this_cycle = false;
            closed_this_cycle = false;
        } else {
            crank_deg = new_crank;
        }
        let inp = inputs_at(t);
        for j in 0..valve_steps_per_plant {
            let tj = t + j as f64 * EHVVA_DT_MS / 1000.0;
            if pilot_on_at.is_some_and(|on| tj >= on) && pilot_off_at.is_some_and(|off| tj < off) {
                u_pilot = true;
            } else if pilot_off_at.is_some_and(|off| tj >= off) {
                u_pilot = false;
            }
            let lift = valve.step(u_pilot, &inp) as f64;
            let stroke = if sc.lift_high { 7.5 } else { 4.0 };
            let angle = crank_deg + (j as f64 * EHVVA_DT_MS / 1000.0) * deg_per_s;
            if let Some((open_deg, close_deg)) = requested {
                if !opened_this_cycle && prev_lift < 0.01 * stroke && lift >= 0.01 * stroke {
                    opened_this_cycle = true;
                    open_errors.push(wrap_deg(angle - open_deg));
                }
                if opened_this_cycle && !closed_this_cycle && prev_lift > 0.99 * stroke && lift <= 0.99 * stroke {
                    closed_this_cycle = true;
                    close_errors.push(wrap_deg(angle - close_deg));
                }
            }
            if let Some(v) = valve.take_seat_velocity() {
                let v = (v as f64).abs();
                worst_seat = Some(worst_seat.map_or(v, |w: f64| w.max(v)));
            }
            prev_lift = lift;
            // The valve log at 10 kHz: valve events last a few ms.
            if j % EHVVA_LOG_EVERY == 0 {
                valve_log.push([tj, u_pilot as u8 as f64, inp.p_supply_mpa as f64, inp.p_back_mpa as f64, inp.temp_c as f64, sc.lift_high as u8 as f64, sc.snubber_on as u8 as f64, lift]);
            }
        }
    }

    let stats = |v: &[f64]| -> (f64, f64) {
        if v.is_empty() {
            return (f64::NAN, f64::NAN);
        }
        (v.iter().sum::<f64>() / v.len() as f64, v.iter().fold(0.0f64, |a, x| a.max(x.abs())))
    };
    let mut summary = Summary {
        evvt_rms_error_deg: (evvt_se / evvt_n.max(1) as f64).sqrt(),
        evvt_settling_s: settling_times(&evvt_log, 1.0),
        vacuum_rms_error_pct: (vac_se / vac_n.max(1) as f64).sqrt(),
        vacuum_pump_on_fraction: pump_steps as f64 / n.max(1) as f64,
        ehvva_events: open_errors.len(),
        ehvva_open_error_deg: stats(&open_errors),
        ehvva_close_error_deg: stats(&close_errors),
        ehvva_seating_velocity_m_s: worst_seat,
        simulated_s: sc.duration_s,
        wall_s: 0.0,
    };
    if let Some(dir) = out {
        write_outputs(sc, dir, &evvt_log, &vac_log, &valve_log).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    summary.wall_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

fn wrap_deg(d: f64) -> f64 {
    (d + 360.0).rem_euclid(720.0) - 360.0
}

/// For each setpoint step in the EVVT log, the time until the measured phase stays within
/// `band` of the setpoint.
fn settling_times(log: &[[f64; 6]], band: f64) -> Vec<(f64, Option<f64>)> {
    let mut out = Vec::new();
    for i in 1..log.len() {
        if (log[i][4] - log[i - 1][4]).abs() > 2.0 * band {
            let t0 = log[i][0];
            let sp = log[i][4];
            let end = (i + 1..log.len()).find(|&j| (log[j][4] - sp).abs() > 1e-9).unwrap_or(log.len());
            // Last sample outside the band before the next step.
            let last_out = (i..end).rev().find(|&j| (log[j][5] - sp).abs() > band);
            let settled = match last_out {
                None => Some(0.0),
                Some(j) if j + 1 < end => Some(log[j + 1][0] - t0),
                Some(_) => None,
            };
            out.push((t0, settled));
        }
    }
    out
}

fn write_outputs(sc: &Scenario, dir: &Path, evvt: &[[f64; 6]], vac: &[[f64; 7]], valve: &[[f64; 8]]) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    // Times to the nanosecond: sums of steps carry float noise a log should not show.
    let round_t = |mut rows: Vec<Vec<f64>>| {
        for r in rows.iter_mut() {
            r[0] = (r[0] * 1e9).round() / 1e9;
        }
        rows
    };
    let column = |data: &Vec<Vec<f64>>, i: usize| data[i].clone();
    let transpose = |rows: Vec<Vec<f64>>, m: usize| -> Vec<Vec<f64>> { (0..m).map(|i| rows.iter().map(|r| r[i]).collect()).collect() };
    let meta = |plant: &str, rate: f64, extra: Vec<(String, String)>| {
        let mut m = vec![
            ("plant".to_string(), plant.to_string()),
            ("source".into(), format!("hil-host run, scenario `{}` (native closed loop, model-core controllers against model-core plants)", sc.name)),
            ("sample_rate_hz".into(), format!("{rate}")),
        ];
        m.extend(extra);
        m
    };
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> std::io::Result<()> {
        let p = dir.join(name);
        std::fs::write(&p, text)?;
        written.push(p);
        Ok(())
    };
    let e = transpose(round_t(evvt.iter().map(|r| r.to_vec()).collect()), 6);
    put(
        "evvt.csv",
        format_log(
            &meta("evvt", 1.0 / EVVT_CONTROL_S, vec![("controller".into(), "model-core EvvtPhaseController, scheduled PI (default config)".into()), ("control_period_s".into(), format!("{EVVT_CONTROL_S}"))]),
            &[("t_s", &column(&e, 0)), ("motor_cmd_rpm", &e[1]), ("engine_rpm", &e[2]), ("u_batt_V", &e[3]), ("phase_ref_deg", &e[4]), ("phase_deg", &e[5])],
        ),
    )?;
    let v = transpose(round_t(vac.iter().map(|r| r.to_vec()).collect()), 7);
    put(
        "vacuum.csv",
        format_log(
            &meta("vacuum", 80.0, vec![("controller".into(), "model-core VacuumPositionController (HPT wastegate)".into())]),
            &[("t_s", &v[0]), ("duty_pct", &v[1]), ("u_batt_V", &v[2]), ("p_amb_kPa", &v[3]), ("p_tank_kPa", &v[4]), ("x_pct", &v[5]), ("p_act_kPa", &v[6])],
        ),
    )?;
    let w = transpose(round_t(valve.iter().map(|r| r.to_vec()).collect()), 8);
    put(
        "ehvva.csv",
        format_log(
            &meta("ehvva", 1000.0 / (EHVVA_DT_MS * EHVVA_LOG_EVERY as f64), vec![]),
            &[("t_s", &w[0]), ("u_pilot", &w[1]), ("p_supply_MPa", &w[2]), ("p_back_MPa", &w[3]), ("temp_C", &w[4]), ("lift_high", &w[5]), ("snubber_on", &w[6]), ("lift_mm", &w[7])],
        ),
    )?;
    put(
        "evvt.svg",
        line_plot(
            "EVVT cam phase",
            "time (s)",
            "phase (crank deg)",
            &[Series { label: "setpoint", colour: "black", x: &e[0], y: &e[4] }, Series { label: "measured", colour: "#1f77b4", x: &e[0], y: &e[5] }],
            &[],
        ),
    )?;
    put(
        "vacuum.svg",
        line_plot(
            "wastegate position",
            "time (s)",
            "position (%)",
            &[
                Series { label: "measured", colour: "#1f77b4", x: &v[0], y: &v[5] },
                Series { label: "duty (%)", colour: "#2ca02c", x: &v[0], y: &v[1] },
                Series { label: "battery (V)", colour: "#d62728", x: &v[0], y: &v[2] },
            ],
            &[],
        ),
    )?;
    // One cycle of lift is what a reader wants to see; the whole run would be a solid band.
    let one: usize = w[0].len().min(2000);
    put(
        "ehvva.svg",
        line_plot(
            "EHVVA valve lift (first 0.2 s)",
            "time (s)",
            "lift (mm)",
            &[Series { label: "lift", colour: "#1f77b4", x: &w[0][..one], y: &w[7][..one] }, Series { label: "pilot", colour: "black", x: &w[0][..one], y: &w[1][..one] }],
            &[],
        ),
    )?;
    Ok(written)
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
        let ok = Scenario::from_toml(Path::new("s.toml"), "name = \"x\"\nduration_s = 1.0\nu_batt_v = [[0.0, 14.0], [0.5, 9.0]]\n").unwrap();
        assert_eq!(ok.u_batt_v.at(0.25), 11.5);
    }
}
