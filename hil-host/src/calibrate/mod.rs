//! `hil-host calibrate <log>... --out DIR`: from a unit's bench logs to the ECU's calibration
//! image (model-core's [`model_core::ecu::calibration`]).
//!
//! Each log is read strictly and goes to its plant's tool:
//! - `ehvva` valve-bench logs: `diagnose` first (its extended model is the unit's own valve:
//!   spring, mass, areas, flow paths, and names the extension), then `identify ehvva` on that
//!   valve (Li 2018 Sec. 5.2, per test condition td VO/VC, τp and Cd) gives the td, τp and Cd
//!   tables on the ECU's grid; the effect gains are set to 1 (the tables hold the measured
//!   dependence on supply pressure, direction and temperature); the valve-motion tables are
//!   computed from the unit's valve with those tables. (On the paper's valve a unit's other
//!   spring and areas went into td: an image that put its valve events 10 crank degrees off,
//!   worse than the paper defaults, docs/calibration.md);
//! - `evvt` closed-loop PRBS logs: `identify evvt` (Yang 2015) per operating point, the 3×3
//!   α/β tables; the scheduled PI gains they imply are recomputed and stored;
//! - `vacuum` logs: `diagnose` (baseline and the catalogue's extensions, its last 30 % held
//!   out) gives the actuator's static valve map, position map, time constants and, where the
//!   named extension is found, its friction, backlash or direction-dependent time constant;
//!   the map shapes tell which actuator (LPT, HPT, HPC) the log is of.
//!
//! Every value nothing learned keeps the paper default, and `calibration.json` says which is
//! which. The image is checked whole ([`EcuCalibration::check`]: limits, axes, consistency)
//! before anything is written: a bad calibration is refused with the name of the value.

pub mod a2l;

use std::path::{Path, PathBuf};

use model_core::ecu::calibration::{
    CalibrationImage, EcuCalibration, Shape, VacuumActuatorCalibration, CHARACTERISTICS, FORMAT_VERSION, IMAGE_BYTES,
};
use model_core::ecu::lockstep::EcuCoreConfig;
use model_core::ehvva::{EhvvaParams, ValveMotionData, VALVE_MOTION_P_BACK_MPA};
use model_core::vacuum::VacuumParams;
use serde_json::{json, Map, Value};

use crate::diagnose::vacuum::VacuumModel;
use crate::log::{read_log_mapped, Log, Plant};
use crate::run::Unit;

/// The calibration sector's address in the ECU's flash (STM32F405 sector 11; `memory.x`).
pub const FLASH_BASE: u32 = 0x080E_0000;

/// Where a characteristic's value came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    /// The logs it was learned from (empty: the paper default).
    pub logs: Vec<String>,
    /// How (`identify ehvva`, `diagnose vacuum: coulomb-friction`, ...), or `paper default`.
    pub method: String,
}

/// A calibration learned from logs.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub calibration: EcuCalibration,
    /// Per characteristic (in [`CHARACTERISTICS`] order), where it came from.
    pub sources: Vec<Source>,
    /// What the tools reported, one line per step.
    pub notes: Vec<String>,
}

impl Outcome {
    fn set_source(&mut self, prefix: &str, logs: &[String], method: &str) {
        for (c, s) in CHARACTERISTICS.iter().zip(self.sources.iter_mut()) {
            if c.name.starts_with(prefix) {
                *s = Source {
                    logs: logs.to_vec(),
                    method: method.to_string(),
                };
            }
        }
    }
}

/// Learns the calibration from `paths` (any mix of plants); `progress` is told each step.
pub fn calibrate(paths: &[PathBuf], progress: &mut dyn FnMut(&str)) -> Result<Outcome, String> {
    calibrate_mapped(paths, None, progress)
}

/// [`calibrate`] with the logs read through a channel map (a logger's or a bench tool's own
/// channel and column names, `--channel-map`).
pub fn calibrate_mapped(
    paths: &[PathBuf],
    map: Option<&crate::mf4::ChannelMap>,
    progress: &mut dyn FnMut(&str),
) -> Result<Outcome, String> {
    if paths.is_empty() {
        return Err("calibrate takes one or more bench logs".into());
    }
    let mut out = Outcome {
        calibration: EcuCalibration::paper_defaults(),
        sources: CHARACTERISTICS
            .iter()
            .map(|_| Source {
                logs: Vec::new(),
                method: "paper default".into(),
            })
            .collect(),
        notes: Vec::new(),
    };
    let mut by_plant: Vec<(Plant, Vec<Log>)> = Vec::new();
    for p in paths {
        let log = read_log_mapped(p, None, map).map_err(|e| e.to_string())?;
        match by_plant.iter_mut().find(|(pl, _)| *pl == log.plant) {
            Some((_, v)) => v.push(log),
            None => by_plant.push((log.plant, vec![log])),
        }
    }
    for (plant, logs) in &by_plant {
        match plant {
            Plant::Ehvva => ehvva(logs, &mut out, progress)?,
            Plant::Evvt => evvt(logs, &mut out, progress)?,
            Plant::Vacuum => vacuum(logs, &mut out, progress)?,
            Plant::Positioner => out.notes.push(format!(
                "{}: positioner logs calibrate nothing on this ECU (no positioner task); ignored",
                names(logs).join(", ")
            )),
        }
    }
    out.calibration.evvt_kp_rpm_per_deg = out.calibration.implied_kp().map_err(|e| e.to_string())?;
    out.calibration.check().map_err(|e| format!("refused: {e}"))?;
    Ok(out)
}

/// Points per supply-pressure interval at which the valve motion is computed for the fit of
/// the ECU's motion tables ([`ValveMotionData::fitted_from_model`]): every 0.125 MPa.
const MOTION_POINTS_PER_INTERVAL: usize = 8;

fn names(logs: &[Log]) -> Vec<String> {
    logs.iter().map(|l| l.file.clone()).collect()
}

fn ehvva(logs: &[Log], out: &mut Outcome, progress: &mut dyn FnMut(&str)) -> Result<(), String> {
    use crate::diagnose::ehvva::Events;
    use crate::identify::ehvva as id;
    let files = names(logs);
    let sets = logs
        .iter()
        .map(Events::from_log)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("EHVVA logs: {e}"))?;
    // The diagnosis first: its baseline is the unit's own valve (spring, mass, areas, flow
    // paths), and it names the extension the tables carry (e.g. td against supply pressure).
    // Where the diagnosis cannot run (a log too short to hold out validation events), the
    // tables are identified on the paper's valve, and the notes say why.
    progress("diagnose ehvva");
    let diagnosed = ehvva_extension(logs);
    progress("identify ehvva");
    let mut tick = |k: usize, n: usize| progress(&format!("identify ehvva: condition {k}/{n}"));
    let (found, kept_unit, valve_note, extension) = match diagnosed {
        Ok((extension, unit)) => {
            let (found, choice) = id::identify_unit_or_paper(&unit, &sets, &id::default_options(), &mut tick)?;
            (found, choice.kept_unit.then_some(unit), choice.text(), extension)
        }
        Err(e) => (
            id::identify(&sets, &id::default_options(), &mut tick)?,
            None,
            format!("the conditions fitted on the paper's valve: the diagnosis could not fit the unit's ({e})"),
            format!("none ({e})"),
        ),
    };
    // The valve the kept tables were identified on is the one their motion is computed on.
    let unit = kept_unit.unwrap_or_else(EhvvaParams::paper_default);
    let tables = found.table_data();
    let cal = &mut out.calibration;
    cal.ehvva_tables = tables;
    cal.ehvva_pressure_delay_gain = 1.0;
    cal.ehvva_direction_delay_gain = 1.0;
    cal.ehvva_viscosity_gain = 1.0;
    cal.check()
        .map_err(|e| format!("refused: {e} (identify ehvva on {})", files.join(", ")))?;
    progress("EHVVA valve motion from the identified tables");
    // The unit valve's motion with the identified tables; where the reduced model cannot run
    // them (a td longer than its delay line holds), the paper valve's motion stays, said in
    // the sources.
    let mut unit_with_tables = unit;
    unit_with_tables.tables = cal.ehvva_tables;
    let motion =
        ValveMotionData::fitted_from_model(&unit_with_tables, VALVE_MOTION_P_BACK_MPA, MOTION_POINTS_PER_INTERVAL);
    if let Ok(m) = motion {
        cal.valve_motion = m;
    }
    out.notes.push(format!(
        "EHVVA: {} test conditions identified from {} (td VO/VC, tau_p, Cd per condition)",
        found.conditions.len(),
        files.join(", ")
    ));
    if !found.not_opening.is_empty() {
        out.notes.push(format!(
            "EHVVA: not identified, the valve never opened to 1 % of its stroke there (the tables interpolate the other conditions): {}",
            found.not_opening.join(", ")
        ));
    }
    out.notes
        .push(format!("EHVVA: diagnose on {}: {extension}", logs[0].file));
    out.notes.push(format!("EHVVA: {valve_note}"));
    let valve = if kept_unit.is_some() {
        "the unit's valve (diagnose's fit)"
    } else {
        "the paper's valve (the unit's as diagnosed did not reproduce the lift better, or could not be fitted)"
    };
    out.set_source(
        "ehvva.",
        &files,
        &format!(
            "identify ehvva on {valve}: per test condition td VO/VC (joint fit), tau_p, Cd; tables on the ECU's grid (diagnose: {extension})"
        ),
    );
    for gain in [
        "ehvva.pressure_delay_gain",
        "ehvva.direction_delay_gain",
        "ehvva.viscosity_gain",
    ] {
        set_source_exact(
            out,
            gain,
            &files,
            "1: the identified td and Cd tables hold the measured dependence as they are",
        );
    }
    set_source_exact(out, "ehvva.delay_nominal_p_supply_mpa", &[], "paper default");
    for name in CHARACTERISTICS
        .iter()
        .map(|c| c.name)
        .filter(|n| n.starts_with("ehvva.motion"))
    {
        match &motion {
            Ok(_) => set_source_exact(
                out,
                name,
                &files,
                &format!("derived: the reduced model's valve motion after td on {valve} with the identified tables, every 0.125 MPa, fitted for the ECU's linear interpolation between the breakpoints"),
            ),
            Err(e) => set_source_exact(
                out,
                name,
                &[],
                &format!("paper default: the reduced model cannot run the identified tables ({e:?})"),
            ),
        }
    }
    Ok(())
}

/// The unit's valve from `diagnose` ([`crate::identify::ehvva::unit_valve`]) and the named
/// cause with its fitted gain, as a phrase for the sources.
fn ehvva_extension(logs: &[Log]) -> Result<(String, EhvvaParams), String> {
    let u = crate::identify::ehvva::unit_valve(logs)?;
    if u.cause == "none" {
        return Ok(("no extension named: the tables as identified".into(), u.params));
    }
    let carried = match u.cause.as_str() {
        "pressure-delay" => "the td tables' fall with supply pressure, measured per condition",
        "direction-delay" => "td VO and VC, measured apart",
        "viscosity" => "Cd against temperature, measured per condition",
        _ => "no ECU table for it",
    };
    Ok((format!("cause `{}` ({}): {carried}", u.cause, u.gains_text()), u.params))
}

fn set_source_exact(out: &mut Outcome, name: &str, logs: &[String], method: &str) {
    if let Some(k) = CHARACTERISTICS.iter().position(|c| c.name == name) {
        out.sources[k] = Source {
            logs: logs.to_vec(),
            method: method.into(),
        };
    }
}

fn evvt(logs: &[Log], out: &mut Outcome, progress: &mut dyn FnMut(&str)) -> Result<(), String> {
    use crate::identify::evvt as id;
    let opts = id::EvvtIdentifyOptions::default();
    let mut points = Vec::new();
    // Each log may be one operating point (the paper's PRBS experiment) or a recording over
    // several (segmented by engine speed and voltage, transitions left out).
    for log in logs {
        progress(&format!("identify evvt: {}", log.file));
        let rec = id::identify_recording(log, &opts).map_err(|e| format!("{}: {e}", log.file))?;
        points.extend(rec.segments);
    }
    let table = id::lpv_table(&points).map_err(|e| format!("EVVT logs ({}): {e}", names(logs).join(", ")))?;
    out.calibration.evvt_lpv = table;
    let files = names(logs);
    out.notes.push(format!(
        "EVVT: alpha/beta at {} operating points from {}",
        points.len(),
        files.join(", ")
    ));
    out.notes.push(evvt_coverage(&table));
    let (designed_rad_s, designed_margin_deg) = (
        out.calibration.evvt_crossover_rad_s,
        out.calibration.evvt_min_phase_margin_deg,
    );
    out.notes.push(evvt_loop(&mut out.calibration)?);
    if out.calibration.evvt_min_phase_margin_deg != designed_margin_deg {
        set_source_exact(
            out,
            "evvt.min_phase_margin_deg",
            &files,
            "derived: the least phase margin the paper defaults run this unit at (below the design's, kept; at least 45 deg)",
        );
    }
    if out.calibration.evvt_crossover_rad_s != designed_rad_s {
        set_source_exact(
            out,
            "evvt.crossover_rad_s",
            &files,
            "derived: the paper defaults' crossover on this unit (faster than the design, kept)",
        );
    }
    for name in [
        "evvt.engine_speed_rpm",
        "evvt.battery_voltage_v",
        "evvt.alpha",
        "evvt.beta",
    ] {
        out.set_source(
            name,
            &files,
            "identify evvt: closed-loop PRBS, q-Markov cover per operating point",
        );
    }
    set_source_exact(
        out,
        "evvt.kp_rpm_per_deg",
        &files,
        "derived: the scheduled kp the identified alpha/beta imply",
    );
    Ok(())
}

/// What the identified EVVT table covers: the ECU holds its edge values beyond the outer
/// breakpoints (no extrapolation), so an engine speed or battery voltage outside the bench's
/// operating points runs on the nearest point's alpha/beta (a unit whose beta keeps falling
/// with speed gets a kp designed for more damping than it has there).
fn evvt_coverage(t: &model_core::evvt::EvvtLpvTable) -> String {
    let (n, v) = (t.engine_speed_rpm, t.battery_voltage_v);
    format!(
        "EVVT: the tables cover {:.0}-{:.0} rpm and {:.1}-{:.1} V (the recorded operating points); beyond them the ECU holds the edge values (no extrapolation): record the speeds and voltages the engine runs at",
        n[0], n[2], v[0], v[2]
    )
}

/// The least phase-margin floor `calibrate` lowers the EVVT schedule's to (deg).
const LEAST_PHASE_MARGIN_DEG: f64 = 45.0;

/// The EVVT loop's crossover for this unit, and a note on how it runs next to the paper
/// defaults. The paper defaults' kp was designed for the paper's α/β; on a slower unit it
/// runs the loop below the designed crossover, on a faster one above it. The image restores
/// the design on a slower unit and, on a faster one, keeps the speed the defaults already
/// run it at (the largest crossover the paper's kp gives at any of the identified table
/// points): a calibration must not detune a loop that the ECU it replaces runs faster,
/// since the phase tracking is what the engineer is after (docs/calibration.md measures both
/// choices). The schedule's phase-margin floor, which lowers the crossover where β is small,
/// is likewise lowered to the least margin the defaults run the unit at (not below
/// [`LEAST_PHASE_MARGIN_DEG`]).
fn evvt_loop(cal: &mut EcuCalibration) -> Result<String, String> {
    use model_core::control::evvt_phase::{p_loop_crossover_and_margin, EvvtPhaseController};
    let paper = EvvtPhaseController::<f64>::new(&EcuCalibration::paper_defaults().evvt_controller())
        .map_err(|_| "EVVT: the paper-default controller refused its own tables".to_string())?;
    let t = cal.evvt_lpv;
    let (mut by_paper, mut pm_paper) = (Vec::new(), Vec::new());
    for i in 0..3 {
        for j in 0..3 {
            let (a, b) = (t.alpha_deg_per_s2_rpm[i][j], t.beta_per_s[i][j]);
            let kp_paper = paper.gains_at(t.engine_speed_rpm[i], t.battery_voltage_v[j]).0;
            let (wc, pm) = p_loop_crossover_and_margin(kp_paper, a, b);
            by_paper.push(wc);
            pm_paper.push(pm);
        }
    }
    let range = |v: &[f64]| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let ((p_lo, p_hi), (m_lo, m_hi)) = (range(&by_paper), range(&pm_paper));
    let median = |v: &[f64]| {
        let mut sorted = v.to_vec();
        sorted.sort_by(f64::total_cmp);
        sorted[sorted.len() / 2]
    };
    if !(p_lo.is_finite() && p_hi.is_finite()) {
        return Err(format!(
            "EVVT: the identified table gives the paper's loop no crossover (crossovers {by_paper:?}): the identification failed"
        ));
    }
    let designed = cal.evvt_crossover_rad_s;
    // Within 5 % of the design is the identification's own scatter, not a faster unit.
    let faster = p_hi > 1.05 * designed;
    if faster {
        // Within the value's A2L limits, so an odd identification gives a usable image.
        let max = CHARACTERISTICS
            .iter()
            .find(|c| c.name == "evvt.crossover_rad_s")
            .map_or(f64::INFINITY, |c| f64::from(c.max));
        cal.evvt_crossover_rad_s = p_hi.min(max);
    }
    // The same on the margin side: where β is small the floor lowers the crossover, and a
    // floor above the margin the defaults already run this unit at would make the image the
    // slower loop there (again beyond the identification's 5 % scatter); never below 45 deg,
    // the usual least margin of a position loop.
    let designed_margin_deg = cal.evvt_min_phase_margin_deg;
    if m_lo < 0.95 * designed_margin_deg {
        cal.evvt_min_phase_margin_deg = m_lo.max(LEAST_PHASE_MARGIN_DEG);
    }
    let own_kp = cal.implied_kp().map_err(|e| e.to_string())?;
    let own: Vec<f64> = (0..9)
        .map(|k| {
            let (i, j) = (k / 3, k % 3);
            p_loop_crossover_and_margin(own_kp[i][j], t.alpha_deg_per_s2_rpm[i][j], t.beta_per_s[i][j]).0
        })
        .collect();
    let (o_lo, o_hi) = range(&own);
    let margin = if cal.evvt_min_phase_margin_deg < designed_margin_deg {
        format!(
            "; its phase-margin floor lowered from {designed_margin_deg:.0} to {:.1} deg, the least the defaults run it at{}",
            cal.evvt_min_phase_margin_deg,
            if m_lo < LEAST_PHASE_MARGIN_DEG {
                format!(" ({m_lo:.1} deg) held at {LEAST_PHASE_MARGIN_DEG:.0}")
            } else {
                String::new()
            }
        )
    } else {
        String::new()
    };
    let verdict = if faster {
        format!(
            "the paper's gains run this unit's loop faster than the designed {designed:.1} rad/s: this image keeps that speed (`evvt.crossover_rad_s` {:.2} rad/s, the fastest the defaults run it at any table point) rather than detune it",
            cal.evvt_crossover_rad_s
        )
    } else if median(&by_paper) < 0.9 * designed {
        format!("the paper's gains run this unit's loop slower than designed: this image restores the designed {designed:.1} rad/s")
    } else {
        "the paper's gains run this unit's loop about as designed".to_string()
    };
    Ok(format!(
        "EVVT: this image runs the unit's loop at a crossover of {o_lo:.2}-{o_hi:.2} rad/s over the table; the paper defaults would run it at {p_lo:.2}-{p_hi:.2} rad/s (phase margin {m_lo:.0}-{m_hi:.0} deg): {verdict}{margin}"
    ))
}

/// Which of the ECU's vacuum actuators a fitted model is, from its map shapes.
fn vacuum_index(params: &[(String, f64)]) -> usize {
    let has = |n: &str| params.iter().any(|(k, _)| k == n);
    if has("k3_kPa_per_pct3") {
        2
    } else if has("lin_k_pct_per_kPa") {
        0
    } else {
        1
    }
}

const VACUUM_NAMES: [&str; 3] = ["lpt", "hpt", "hpc"];

/// The model-core actuator of a fitted parameter list on the ECU's `index` actuator, with the
/// named extension `cause` (or none).
pub fn vacuum_params(index: usize, cause: Option<&str>, params: &[(String, f64)]) -> Result<VacuumParams, String> {
    let preset = [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()][index.min(2)];
    let mut m = VacuumModel::from_params(&preset.baseline());
    if let Some(effect) = cause {
        m = m.with_effect(effect)?;
    }
    for (name, v) in params {
        m.set(name, *v)?;
    }
    Ok(m.to_params())
}

fn vacuum(logs: &[Log], out: &mut Outcome, progress: &mut dyn FnMut(&str)) -> Result<(), String> {
    use crate::diagnose::{self, Rules};
    let mut best: [Option<(f64, String, VacuumParams)>; 3] = [None, None, None];
    for log in logs {
        progress(&format!("diagnose vacuum: {}", log.file));
        let family = diagnose::family_for(Plant::Vacuum)?;
        let (est, val) = diagnose::split_tail(log, 0.3);
        let d = diagnose::diagnose(family.as_ref(), &est, &val, true, &Rules::default(), &mut |_| {})
            .map_err(|e| format!("{}: {e}", log.file))?;
        let cause = (d.cause != "none").then(|| d.cause.clone());
        let k = vacuum_index(&d.extended.params);
        let p = vacuum_params(k, cause.as_deref(), &d.extended.params)?;
        out.notes.push(format!(
            "vacuum {}: {} ({}), fit {:.1} % on the held-out 30 %",
            VACUUM_NAMES[k].to_uppercase(),
            log.file,
            cause.as_deref().unwrap_or("no extension"),
            d.extended.fit_pct
        ));
        let method = format!(
            "diagnose vacuum: baseline{}",
            cause.as_deref().map(|c| format!(" + {c}")).unwrap_or_default()
        );
        if best[k].as_ref().is_none_or(|(fit, _, _)| d.extended.fit_pct > *fit) {
            best[k] = Some((d.extended.fit_pct, format!("{}\u{1f}{method}", log.file), p));
        }
    }
    for (k, b) in best.iter().enumerate() {
        let Some((_, tag, p)) = b else { continue };
        let (file, method) = tag.split_once('\u{1f}').unwrap_or((tag.as_str(), ""));
        out.calibration.vacuum[k] = VacuumActuatorCalibration::from_params(p);
        out.set_source(&format!("vacuum.{}.", VACUUM_NAMES[k]), &[file.to_string()], method);
        // Not in the log: the bench's U_ref and ambient reference stay the preset's.
        // The pressure-direction extension not found: one time constant both ways.
        if !p.effects.pressure_direction {
            out.calibration.vacuum[k].tau_fall_s = out.calibration.vacuum[k].tau_rise_s;
        }
        for kept in ["u_ref_v", "p_amb_ref_kpa"] {
            set_source_exact(out, &format!("vacuum.{}.{kept}", VACUUM_NAMES[k]), &[], "paper default");
        }
    }
    Ok(())
}

/// The values of `cal`, per characteristic, as JSON (maps as `[x][y]` nested arrays).
fn values_json(c: &model_core::ecu::calibration::Characteristic, v: &[f64]) -> Value {
    let r = |x: f64| f64::from(x as f32);
    match c.shape {
        Shape::Value => json!(r(v[0])),
        Shape::Map { ny, .. } => Value::Array(
            v.chunks(ny)
                .map(|row| json!(row.iter().map(|x| r(*x)).collect::<Vec<_>>()))
                .collect(),
        ),
        _ => json!(v.iter().map(|x| r(*x)).collect::<Vec<_>>()),
    }
}

/// `calibration.json`: `flash_base`, the image's size and CRC, and every characteristic by its
/// A2L name with its value(s), unit, address, limits and source.
pub fn json_report(o: &Outcome, image: &[u8], flash_base: u32) -> Value {
    let mut chars = Map::new();
    let mut k = 0;
    o.calibration.for_each(|c, v| {
        let s = &o.sources[k];
        k += 1;
        let source = if s.logs.is_empty() {
            json!({"from": "paper default", "method": s.method})
        } else {
            json!({"from": "log", "logs": s.logs, "method": s.method})
        };
        chars.insert(
            c.name.to_string(),
            json!({
                "value": values_json(c, v),
                "unit": c.unit,
                "address": format!("0x{:08X}", flash_base + c.offset() as u32),
                "limits": [c.min, c.max],
                "source": source,
            }),
        );
    });
    let crc = u32::from_le_bytes([
        image[IMAGE_BYTES - 4],
        image[IMAGE_BYTES - 3],
        image[IMAGE_BYTES - 2],
        image[IMAGE_BYTES - 1],
    ]);
    json!({
        "format_version": FORMAT_VERSION,
        "flash_base": flash_base,
        "flash_base_hex": format!("0x{flash_base:08X}"),
        "image_bytes": IMAGE_BYTES,
        "crc32": format!("0x{crc:08X}"),
        "notes": o.notes,
        "characteristics": chars,
    })
}

/// Writes `calibration.bin`, `calibration.json` and `calibration.a2l` into `dir`.
pub fn write_outputs(o: &Outcome, dir: &Path, flash_base: u32) -> Result<Vec<PathBuf>, String> {
    let mut image = vec![0u8; IMAGE_BYTES];
    CalibrationImage::serialize(&o.calibration, &mut image).map_err(|e| e.to_string())?;
    // What is written is what the ECU will read: parse it back whole.
    CalibrationImage::parse(&image).map_err(|e| format!("refused: {e}"))?;
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let files = [
        ("calibration.bin", image.clone()),
        (
            "calibration.json",
            (serde_json::to_string_pretty(&json_report(o, &image, flash_base)).map_err(|e| e.to_string())? + "\n")
                .into_bytes(),
        ),
        ("calibration.a2l", a2l::a2l_text(flash_base).into_bytes()),
    ];
    let mut written = Vec::new();
    for (name, bytes) in files {
        let p = dir.join(name);
        crate::output::write_atomic(&p, &bytes).map_err(|e| format!("{}: {e}", p.display()))?;
        written.push(p);
    }
    Ok(written)
}

/// The ECU configuration of an image file (`--calibration`): refused whole, with the reason
/// and the file, when any check fails.
pub fn ecu_config_from_image(path: &Path) -> Result<EcuCoreConfig, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("calibration {}: {e}", path.display()))?;
    let cal = CalibrationImage::parse(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(cal.config())
}

/// The unit `hil-host generate` described (`--unit truth.json`): the paper's plants with the
/// truth's plant replaced by the generated one.
pub fn unit_from_truth(path: &Path) -> Result<Unit, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("unit {}: {e}", path.display()))?;
    let v: Value = serde_json::from_str(&text).map_err(|e| format!("unit {}: {e}", path.display()))?;
    let bad = |what: &str| format!("unit {}: {what}", path.display());
    let plant = v["plant"].as_str().ok_or_else(|| bad("no `plant`"))?;
    let effect = v["effect"].as_str().ok_or_else(|| bad("no `effect`"))?;
    let params: Vec<(String, f64)> = v["params"]
        .as_object()
        .ok_or_else(|| bad("no `params` object"))?
        .iter()
        .map(|(k, x)| {
            x.as_f64()
                .map(|x| (k.clone(), x))
                .ok_or_else(|| bad(&format!("params.{k} is not a number")))
        })
        .collect::<Result<_, _>>()?;
    let mut unit = Unit::default();
    match plant {
        "ehvva" => {
            use crate::diagnose::ehvva::{effect_knob, BASELINE_KNOBS};
            let mut p = EhvvaParams::baseline();
            let mut knobs: Vec<_> = BASELINE_KNOBS.to_vec();
            if effect != "none" {
                knobs.push(effect_knob(effect).map_err(|e| bad(&e))?);
            }
            for k in knobs {
                let x = params
                    .iter()
                    .find(|(n, _)| n == k.name)
                    .ok_or_else(|| bad(&format!("params.{} missing", k.name)))?
                    .1;
                (k.apply)(&mut p, x);
            }
            // The rest of the unit, where the generator drew it (issue #12's real units).
            let get = |n: &str| params.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
            crate::generate::ehvva::apply_unit_geometry(&mut p, get);
            p.validate().map_err(|e| bad(&format!("{e:?}")))?;
            unit.ehvva = p;
        }
        "vacuum" => {
            let k = ["preset_LPT", "preset_HPT", "preset_HPC"]
                .iter()
                .position(|n| params.iter().any(|(p, _)| p == n))
                .ok_or_else(|| bad("no preset_LPT/HPT/HPC in params"))?;
            let cause = (effect != "none").then_some(effect);
            let fitted: Vec<(String, f64)> = params.into_iter().filter(|(n, _)| !n.starts_with("preset_")).collect();
            unit.vacuum[k] = vacuum_params(k, cause, &fitted).map_err(|e| bad(&e))?;
        }
        "evvt" => {
            let get = |n: &str| params.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
            unit.evvt = crate::generate::evvt::unit_from_truth(&get).map_err(|e| bad(&e))?;
        }
        other => {
            return Err(bad(&format!(
                "plant `{other}`: run simulates generated ehvva, evvt and vacuum units"
            )))
        }
    }
    Ok(unit)
}

/// A `--flash-base` value: hexadecimal, with or without `0x`.
pub fn parse_flash_base(v: &str) -> Result<u32, String> {
    let h = v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")).unwrap_or(v);
    u32::from_str_radix(h, 16).map_err(|_| format!("--flash-base {v}: not a hexadecimal address"))
}
