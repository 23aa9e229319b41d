//! EVVT cases: the electric cam phaser (model-core `EvvtPlant`, Yang 2015 eq. (12)) in the
//! paper's identification loop, the fixed proportional controller
//! (`EvvtPhaseConfig::paper_fixed_p` with the design gain), at a 10 ms control and log period.
//! The controller sees the phase quantized to 1 crank degree (Section IV-C), which is also
//! what the log records: quantization is the sensor noise.
//!
//! - Estimation: the bench's identification experiment (Section IV-B): the inverse PRBS of
//!   order 9 (eqs. (6)-(8)) on the phase reference, 25 ± 7.5 crank degrees, each value held for
//!   0.4..0.8 s, at nine stitched test points covering the paper's grid (800/1100/1400 rpm ×
//!   9.5..14 V, each jittered, in random order), so engine speed and battery voltage are not
//!   correlated with each other.
//! - Validation: a different excitation at other operating points: steps and ramps of the
//!   reference between 8 and 36 degrees at six (speed, voltage) points towards the corners of
//!   the range.
//!
//! Baseline plant: the design table scaled by random factors (α × 0.6..1.3, β × 0.7..1.3);
//! without a hidden effect it is frozen at one operating point (one α, one β: the LTI model).
//! The hidden effect's magnitude is drawn where it is the dominant missing physics:
//! - `supply-voltage`: the table's voltage dependence at a high engine speed (1200..1400 rpm,
//!   where the motor's power limit makes it strongest, Section IV-D: α/β, the velocity gain,
//!   halves from 14 V to 9.5 V; at 1100 rpm α and β move together and the closed loop hides
//!   most of it) with the plant's voltage scale 0.7..1;
//! - `engine-speed`: the table's speed dependence at a low nominal voltage (9.5..10 V, where
//!   the paper's phaser slows with speed, Section IV-D: at 14 V the table moves only 10 %)
//!   with the speed scale 0.7..1;
//! - `direction`: α × 0.5..0.75 while the command advances;
//! - `belt-vibration`: 0.6..1.5 deg at order 0.5..2 of engine revolutions (random, not only
//!   half orders; at most 2.0 so that 1400 rpm stays below the 50 Hz Nyquist frequency).
//!   The validation run starts at another crank angle: its disturbance phase differs.

use model_core::control::evvt_phase::{EvvtFault, EvvtPhaseConfig, EvvtPhaseController, EvvtPhaseInputs};
use model_core::evvt::{
    quantize_phase_deg, EvvtLpvTable, EvvtParams, EvvtPlant, PAPER_DESIGN_KP_RPM_PER_DEG, PHASE_RESOLUTION_DEG,
};
use model_core::prbs::InversePrbs;

use super::{Case, Rng};
use crate::log::{format_log, Plant};

/// Control and log period.
pub const DT_S: f64 = 0.01;
/// PRBS centre and amplitude (Section IV-B).
const PRBS_CENTRE_DEG: f64 = 25.0;
const PRBS_AMPLITUDE_DEG: f64 = 7.5;
const PRBS_ORDER: u8 = 9;

/// How long the experiments are.
#[derive(Clone, Copy, Debug)]
pub struct Sizes {
    pub estimation_points: usize,
    pub estimation_point_s: f64,
    pub validation_points: usize,
    pub validation_point_s: f64,
}

impl Default for Sizes {
    /// 9 × 25 s estimation (22 500 samples), 6 × 17 s validation (10 200 samples).
    fn default() -> Self {
        Sizes {
            estimation_points: 9,
            estimation_point_s: 25.0,
            validation_points: 6,
            validation_point_s: 17.0,
        }
    }
}

/// One operating point of the bench.
#[derive(Clone, Copy, Debug)]
struct Point {
    engine_rpm: f64,
    u_batt_v: f64,
}

/// What makes a generated EVVT unit: the scales of the designed table, the nominal point and
/// the catalogue effects' values (truth.json records them under these names).
#[derive(Clone, Copy, Debug)]
struct UnitValues {
    alpha_scale: f64,
    beta_scale: f64,
    nominal_voltage_v: f64,
    nominal_engine_rpm: f64,
    voltage_effect_scale: f64,
    engine_speed_effect_scale: f64,
    advance_alpha_factor: f64,
    belt_amplitude_deg: f64,
    belt_order: f64,
    belt_phase_rad: f64,
}

/// The plant of a unit: the designed table scaled; without the speed or voltage effect the
/// plant is LTI, one α and β (the scaled table at the nominal point, written as a uniform
/// table: what the baseline model assumes).
fn unit_params(v: &UnitValues) -> EvvtParams {
    let mut table = EvvtLpvTable::PAPER_DESIGN;
    for row in table.alpha_deg_per_s2_rpm.iter_mut() {
        row.iter_mut().for_each(|a| *a *= v.alpha_scale);
    }
    for row in table.beta_per_s.iter_mut() {
        row.iter_mut().for_each(|b| *b *= v.beta_scale);
    }
    let mut p = EvvtParams {
        lpv: table,
        voltage_effect_scale: v.voltage_effect_scale,
        engine_speed_effect_scale: v.engine_speed_effect_scale,
        nominal_voltage_v: v.nominal_voltage_v,
        nominal_engine_rpm: v.nominal_engine_rpm,
        advance_alpha_factor: v.advance_alpha_factor,
        belt_vibration_amplitude_deg: v.belt_amplitude_deg,
        ..EvvtParams::default()
    };
    if v.belt_amplitude_deg != 0.0 {
        p.belt_vibration_order = v.belt_order;
        p.belt_vibration_phase_rad = v.belt_phase_rad;
    }
    if p.voltage_effect_scale == 0.0 && p.engine_speed_effect_scale == 0.0 {
        let plant = EvvtPlant::<f64>::new(&p).ok();
        let (a, b) = plant.map_or((0.5, 6.0), |pl| {
            pl.alpha_beta(p.nominal_engine_rpm, p.nominal_voltage_v)
        });
        p.lpv = EvvtLpvTable::uniform(a, b);
    }
    p
}

/// The plant of the unit a generated truth.json describes (its `params`, looked up by `get`),
/// as `draw_params` made it for the estimation run; `hil-host run --unit` simulates it. A
/// truth with physics outside the catalogue the plant does not model (a command delay) is
/// refused by name.
pub fn unit_from_truth(get: &dyn Fn(&str) -> Option<f64>) -> Result<EvvtParams, String> {
    let need = |k: &str| get(k).ok_or_else(|| format!("params.{k} missing"));
    if get("command_delay_s").is_some() {
        return Err(
            "params.command_delay_s: the EVVT plant of `run` has no command delay (physics outside the catalogue)"
                .into(),
        );
    }
    let v = UnitValues {
        alpha_scale: need("alpha_scale_of_design")?,
        beta_scale: need("beta_scale_of_design")?,
        nominal_voltage_v: need("nominal_voltage_V")?,
        nominal_engine_rpm: need("nominal_engine_rpm")?,
        voltage_effect_scale: get("voltage_effect_scale").unwrap_or(0.0),
        engine_speed_effect_scale: get("engine_speed_effect_scale").unwrap_or(0.0),
        advance_alpha_factor: get("advance_alpha_factor").unwrap_or(1.0),
        belt_amplitude_deg: get("belt_amplitude_deg").unwrap_or(0.0),
        belt_order: get("belt_order").unwrap_or(0.0),
        belt_phase_rad: get("belt_phase_rad").unwrap_or(0.0),
    };
    let p = unit_params(&v);
    EvvtPlant::<f64>::new(&p).map_err(|e| format!("the unit's EVVT plant: {e:?}"))?;
    Ok(p)
}

/// Draws the plant for the estimation and the validation run (they differ only in the belt
/// disturbance's phase) and the truth.
fn draw_params(effects: &[&str], rng: &mut Rng) -> (EvvtParams, EvvtParams, Vec<(String, f64)>) {
    let alpha_scale = rng.uniform(0.6, 1.3);
    let beta_scale = rng.uniform(0.7, 1.3);
    let mut v = UnitValues {
        alpha_scale,
        beta_scale,
        nominal_voltage_v: rng.uniform(12.0, 14.0),
        nominal_engine_rpm: 1100.0,
        voltage_effect_scale: 0.0,
        engine_speed_effect_scale: 0.0,
        advance_alpha_factor: 1.0,
        belt_amplitude_deg: 0.0,
        belt_order: 0.0,
        belt_phase_rad: 0.0,
    };
    let mut truth = vec![
        ("alpha_scale_of_design".to_string(), alpha_scale),
        ("beta_scale_of_design".into(), beta_scale),
    ];
    let mut belt_phase_validation = 0.0;
    for effect in effects {
        match *effect {
            "supply-voltage" => {
                v.nominal_engine_rpm = rng.uniform(1200.0, 1400.0);
                v.voltage_effect_scale = rng.uniform(0.7, 1.0);
                truth.push(("voltage_effect_scale".into(), v.voltage_effect_scale));
            }
            "engine-speed" => {
                v.nominal_voltage_v = rng.uniform(9.5, 10.0);
                v.engine_speed_effect_scale = rng.uniform(0.7, 1.0);
                truth.push(("engine_speed_effect_scale".into(), v.engine_speed_effect_scale));
            }
            "direction" => {
                v.advance_alpha_factor = rng.uniform(0.5, 0.75);
                truth.push(("advance_alpha_factor".into(), v.advance_alpha_factor));
            }
            "belt-vibration" => {
                v.belt_amplitude_deg = rng.uniform(0.6, 1.5);
                v.belt_order = rng.uniform(0.5, 2.0);
                v.belt_phase_rad = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
                belt_phase_validation = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
                truth.extend([
                    ("belt_amplitude_deg".into(), v.belt_amplitude_deg),
                    ("belt_order".into(), v.belt_order),
                    ("belt_phase_rad".into(), v.belt_phase_rad),
                    ("belt_phase_validation_rad".into(), belt_phase_validation),
                ]);
            }
            _ => {}
        }
    }
    let p = unit_params(&v);
    let (a, b) = EvvtPlant::<f64>::new(&p).map_or((f64::NAN, f64::NAN), |pl| {
        pl.alpha_beta(p.nominal_engine_rpm, p.nominal_voltage_v)
    });
    truth.extend([
        ("alpha_at_nominal_deg_per_s2_rpm".into(), a),
        ("beta_at_nominal_per_s".into(), b),
        ("nominal_voltage_V".into(), p.nominal_voltage_v),
        ("nominal_engine_rpm".into(), p.nominal_engine_rpm),
    ]);
    let validation = EvvtParams {
        belt_vibration_phase_rad: belt_phase_validation,
        ..p
    };
    (p, validation, truth)
}

/// The estimation test points: the 3 × 3 grid (jittered), shuffled; more than nine points
/// repeat the grid with new jitter.
fn estimation_points(rng: &mut Rng, count: usize) -> Vec<Point> {
    let speeds = [(800.0, 860.0), (1070.0, 1130.0), (1340.0, 1400.0)];
    let volts = [(9.5, 10.0), (11.5, 12.0), (13.5, 14.0)];
    let mut points = Vec::with_capacity(count);
    while points.len() < count {
        let mut grid: Vec<Point> = speeds
            .iter()
            .flat_map(|s| volts.iter().map(move |v| (*s, *v)))
            .map(|((s0, s1), (v0, v1))| Point {
                engine_rpm: rng.uniform(s0, s1),
                u_batt_v: rng.uniform(v0, v1),
            })
            .collect();
        rng.shuffle(&mut grid);
        points.extend(grid);
    }
    points.truncate(count);
    points
}

/// Validation points towards the corners of the operating range (voltage 9.5..10.8 or
/// 12.8..14 V, engine speed 800..950 or 1250..1400 rpm; the first four points visit all
/// four corners, in random order): away from the middle, where an LTI model fitted to the
/// whole range is right by construction, so that what a scheduling effect explains shows in
/// most of the record and not only at one of five points.
fn validation_points(rng: &mut Rng, count: usize) -> Vec<Point> {
    let (a, b) = (rng.next_u64() % 2, rng.next_u64() % 2);
    let mut points: Vec<Point> = (0..count as u64)
        .map(|i| {
            let v_high = (i + a) % 2 == 0;
            let n_high = (i / 2 + i + b) % 2 == 0;
            Point {
                engine_rpm: if n_high {
                    rng.uniform(1250.0, 1400.0)
                } else {
                    rng.uniform(800.0, 950.0)
                },
                u_batt_v: if v_high {
                    rng.uniform(12.8, 14.0)
                } else {
                    rng.uniform(9.5, 10.8)
                },
            }
        })
        .collect();
    rng.shuffle(&mut points);
    points
}

/// PRBS reference, one stream across all points (the test points are stitched).
fn prbs_reference(rng: &mut Rng, samples: usize) -> Result<Vec<f64>, String> {
    let mut prbs = InversePrbs::<f64>::new(PRBS_ORDER, PRBS_AMPLITUDE_DEG).map_err(|e| format!("{e:?}"))?;
    for _ in 0..(rng.next_u64() % prbs.period() as u64) {
        prbs.next_value();
    }
    let hold = (rng.uniform(0.4, 0.8) / DT_S).round() as usize;
    let mut r = Vec::with_capacity(samples);
    while r.len() < samples {
        let v = PRBS_CENTRE_DEG + prbs.next_value();
        r.extend(std::iter::repeat_n(v, hold));
    }
    r.truncate(samples);
    Ok(r)
}

/// Steps and ramps between random levels in 8..36 degrees, each held 0.6..2 s, starting with
/// a hold at 20.
fn step_ramp_reference(rng: &mut Rng, samples: usize) -> Vec<f64> {
    let mut r = vec![20.0; ((1.0 / DT_S) as usize).min(samples)];
    let mut level = 20.0;
    while r.len() < samples {
        let target = rng.uniform(8.0, 36.0);
        if rng.coin() {
            // Ramp at 3..12 deg/s.
            let rate = rng.uniform(3.0, 12.0);
            let steps = ((target - level).abs() / rate / DT_S).ceil().max(1.0) as usize;
            for k in 1..=steps {
                r.push(level + (target - level) * k as f64 / steps as f64);
            }
        }
        level = target;
        let hold = (rng.uniform(0.6, 2.0) / DT_S) as usize;
        r.extend(std::iter::repeat_n(level, hold));
    }
    r.truncate(samples);
    r
}

/// The logged columns of one run.
struct Run {
    cmd: Vec<f64>,
    rpm: Vec<f64>,
    volt: Vec<f64>,
    reference: Vec<f64>,
    phase: Vec<f64>,
}

/// Physics outside the catalogue between the controller and the cam (none by default).
#[derive(Clone, Copy, Debug, Default)]
struct Outside {
    /// The plant moves with the command of this many periods earlier (the outside effect
    /// `command-delay`; the log shows the command as sent).
    delay: usize,
    /// Clearance between the phaser's drive and the camshaft, crank deg (the outside effect
    /// `gear-backlash`): the cam follows the drive only once the clearance is taken up, so
    /// after each reversal of the drive the measured phase stands still.
    backlash_deg: f64,
}

/// Runs the bench: each sample the controller reads the quantized phase and commands the
/// motor; the plant moves for one period with the command, as `outside` has it.
fn run_bench(
    p: &EvvtParams,
    points: &[Point],
    point_samples: usize,
    reference: &[f64],
    outside: Outside,
) -> Result<Run, String> {
    let delay = outside.delay;
    let half_clearance = 0.5 * outside.backlash_deg;
    let n = reference.len();
    let initial = reference
        .first()
        .copied()
        .unwrap_or(PRBS_CENTRE_DEG)
        .round()
        .clamp(p.phase_min_deg, p.phase_max_deg);
    let mut plant = EvvtPlant::<f64>::new(&EvvtParams {
        initial_phase_deg: initial,
        ..*p
    })
    .map_err(|e| format!("{e:?}"))?;
    let mut ctrl = EvvtPhaseController::<f64>::new(&EvvtPhaseConfig::paper_fixed_p(PAPER_DESIGN_KP_RPM_PER_DEG))
        .map_err(|e| format!("{e:?}"))?;
    let mut run = Run {
        cmd: Vec::with_capacity(n),
        rpm: Vec::with_capacity(n),
        volt: Vec::with_capacity(n),
        reference: reference.to_vec(),
        phase: Vec::with_capacity(n),
    };
    let mut cam = plant.phase_deg() - plant.belt_disturbance_deg();
    for (k, &r) in reference.iter().enumerate() {
        let pt = points
            .get(k / point_samples.max(1))
            .or(points.last())
            .copied()
            .ok_or("no operating points")?;
        let measured = if half_clearance > 0.0 {
            // The cam sits anywhere within the clearance; the drive pushes it at either flank.
            // The belt's vibration reaches the cam as before (it is the ring's, measured at the
            // cam; the clearance is in the phaser's drive).
            let belt = plant.belt_disturbance_deg();
            let drive = plant.phase_deg() - belt;
            cam = cam.clamp(drive - half_clearance, drive + half_clearance);
            quantize_phase_deg(cam + belt, PHASE_RESOLUTION_DEG)
        } else {
            plant.measured_phase_deg()
        };
        let out = ctrl.update(
            &EvvtPhaseInputs {
                setpoint_deg: r,
                measured_phase_deg: measured,
                engine_rpm: pt.engine_rpm,
                u_batt_v: pt.u_batt_v,
                cranking: false,
                fault: EvvtFault::None,
            },
            DT_S,
        );
        run.cmd.push(out.motor_cmd_rpm);
        run.rpm.push(pt.engine_rpm);
        run.volt.push(pt.u_batt_v);
        run.phase.push(measured);
        let applied = if delay == 0 {
            out.motor_cmd_rpm
        } else {
            k.checked_sub(delay).map_or(0.0, |j| run.cmd[j])
        };
        plant.step(applied, pt.engine_rpm, pt.u_batt_v, DT_S);
    }
    Ok(run)
}

fn log_text(kind: &str, seed: u64, run: &Run) -> String {
    let c = EvvtPhaseConfig::paper_fixed_p(PAPER_DESIGN_KP_RPM_PER_DEG);
    let t: Vec<f64> = (0..run.phase.len())
        .map(|k| (k as f64 * DT_S * 1e6).round() / 1e6)
        .collect();
    let meta = vec![
        ("plant".to_string(), "evvt".to_string()),
        ("source".into(), format!("hil-host generate, {kind} experiment (simulated bench, seed {seed})")),
        ("sample_rate_hz".into(), format!("{}", 1.0 / DT_S)),
        ("kp".into(), format!("{PAPER_DESIGN_KP_RPM_PER_DEG}")),
        ("control_period_s".into(), format!("{DT_S}")),
        ("motor_cmd_max_rpm".into(), format!("{}", c.motor_cmd_max_rpm)),
        ("controller".into(), format!("fixed P: motor_cmd_rpm = kp (phase_ref_deg - phase_deg), phase quantized to {PHASE_RESOLUTION_DEG} crank deg, saturated")),
    ];
    format_log(
        &meta,
        &[
            ("t_s", &t),
            ("motor_cmd_rpm", &run.cmd),
            ("engine_rpm", &run.rpm),
            ("u_batt_V", &run.volt),
            ("phase_ref_deg", &run.reference),
            ("phase_deg", &run.phase),
        ],
    )
}

/// A case with the default sizes.
pub fn generate(effect: &str, seed: u64) -> Result<Case, String> {
    generate_sized(effect, seed, &Sizes::default())
}

/// A case with chosen experiment lengths (e.g. a long log for timing the diagnosis).
pub fn generate_sized(effect: &str, seed: u64, sizes: &Sizes) -> Result<Case, String> {
    let parts = super::parse_effects(Plant::Evvt, effect)?;
    generate_parts(&parts, seed, sizes)
}

/// A case with the given hidden effects (catalogue or outside), default sizes.
pub fn generate_effects(parts: &[&str], seed: u64) -> Result<Case, String> {
    generate_parts(parts, seed, &Sizes::default())
}

fn generate_parts(parts: &[&str], seed: u64, sizes: &Sizes) -> Result<Case, String> {
    let effect = if parts.is_empty() {
        "none".to_string()
    } else {
        parts.join("+")
    };
    let mut rng = Rng::new(seed);
    let (est_params, val_params, mut truth) = draw_params(parts, &mut rng);
    let est_points = estimation_points(&mut rng, sizes.estimation_points.max(1));
    let est_per_point = (sizes.estimation_point_s / DT_S).round().max(1.0) as usize;
    let est_ref = prbs_reference(&mut rng, est_per_point * est_points.len())?;
    let val_points = validation_points(&mut rng, sizes.validation_points.max(1));
    let val_per_point = (sizes.validation_point_s / DT_S).round().max(1.0) as usize;
    let val_ref = step_ramp_reference(&mut rng, val_per_point * val_points.len());
    // Outside the catalogue, drawn last (each only where hidden, so the other draws stay
    // those of its seed): a command delay, a clearance in the phaser's gears.
    let mut outside = Outside::default();
    if parts.contains(&"command-delay") {
        outside.delay = (rng.uniform(0.03, 0.06) / DT_S).round() as usize;
        truth.push(("command_delay_s".into(), outside.delay as f64 * DT_S));
    }
    if parts.contains(&"gear-backlash") {
        // Section IV-C blames the 1-degree spikes of the bench's responses on backlash
        // between the gears and the belt: a clearance of 1.5-3 crank degrees.
        outside.backlash_deg = rng.uniform(1.5, 3.0);
        truth.push(("backlash_deg".into(), outside.backlash_deg));
    }
    let est = run_bench(&est_params, &est_points, est_per_point, &est_ref, outside)?;
    let val = run_bench(&val_params, &val_points, val_per_point, &val_ref, outside)?;
    Ok(Case {
        plant: Plant::Evvt,
        seed,
        effect,
        truth,
        estimation_csv: log_text("estimation", seed, &est),
        validation_csv: log_text("validation", seed, &val),
    })
}

/// How the measured phase reaches the controller and the log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhaseSampling {
    /// A fresh (quantized) phase at every control instant (the diagnosis cases above).
    ControlPeriod,
    /// The bench's cam sensor (Section IV-A: "four pulses per engine cycle"): the phase is
    /// computed at each cam event, `events_per_cycle` per 720 crank degrees, so its sample
    /// instants follow engine speed (every 30 ms at 1000 rpm with 4 events); the controller
    /// holds the last value until the next event, and the log's `phase_deg` is that held value
    /// on the control grid (what the controller saw, so the logged law still holds).
    CamEvents { events_per_cycle: u32 },
}

/// One closed-loop PRBS identification experiment at one operating point (Section IV-B):
/// the inverse PRBS (eqs. (6)-(8)) on the phase reference, clocked every
/// `prbs_hold_periods` control periods, the fixed proportional controller, the plant at
/// constant engine speed and battery voltage.
#[derive(Clone, Copy, Debug)]
pub struct IdentificationExperiment {
    /// The plant; α and β at (`engine_rpm`, `u_batt_v`) are the truth.
    pub params: EvvtParams,
    pub engine_rpm: f64,
    pub u_batt_v: f64,
    pub kp_rpm_per_deg: f64,
    pub control_period_s: f64,
    pub prbs_order: u8,
    /// Control periods per PRBS value (the PRBS clock is this times the control period).
    pub prbs_hold_periods: usize,
    /// Log length in PRBS periods (2·(2ⁿ − 1) values each).
    pub prbs_periods: f64,
    /// Gaussian noise on the phase before the 1-degree quantization, standard deviation.
    pub phase_noise_deg: f64,
    pub phase_sampling: PhaseSampling,
    pub seed: u64,
}

impl Default for IdentificationExperiment {
    /// The design plant at 1100 rpm and 14 V, kp = 25 rpm/deg, 10 ms control period, order-9
    /// PRBS clocked at 100 ms (two periods: 204 s), 0.3 deg sensor noise, 4 cam events per cycle.
    fn default() -> Self {
        Self {
            params: EvvtParams::default(),
            engine_rpm: 1100.0,
            u_batt_v: 14.0,
            kp_rpm_per_deg: PAPER_DESIGN_KP_RPM_PER_DEG,
            control_period_s: DT_S,
            prbs_order: PRBS_ORDER,
            prbs_hold_periods: 10,
            prbs_periods: 2.0,
            phase_noise_deg: 0.3,
            phase_sampling: PhaseSampling::CamEvents { events_per_cycle: 4 },
            seed: 1,
        }
    }
}

/// Writes the `evvt` log of one identification experiment (metadata `kp`,
/// `control_period_s`, `motor_cmd_max_rpm`, and `cam_events_per_cycle` with cam-event
/// sampling).
pub fn identification_log(x: &IdentificationExperiment) -> Result<String, String> {
    let mut rng = Rng::new(x.seed);
    let dt = x.control_period_s;
    if !(dt > 0.0 && dt.is_finite()) || x.prbs_hold_periods == 0 || x.prbs_periods.is_nan() || x.prbs_periods <= 0.0 {
        return Err("identification experiment: control period, PRBS hold and length must be positive".into());
    }
    let mut prbs = InversePrbs::<f64>::new(x.prbs_order, PRBS_AMPLITUDE_DEG).map_err(|e| format!("{e:?}"))?;
    let values = (prbs.period() as f64 * x.prbs_periods).round() as usize;
    let reference: Vec<f64> = (0..values)
        .flat_map(|_| std::iter::repeat_n(PRBS_CENTRE_DEG + prbs.next_value(), x.prbs_hold_periods))
        .collect();
    let cam_period_s = match x.phase_sampling {
        PhaseSampling::ControlPeriod => None,
        PhaseSampling::CamEvents { events_per_cycle } => {
            if events_per_cycle == 0 || x.engine_rpm.is_nan() || x.engine_rpm <= 0.0 {
                return Err("cam-event sampling needs events_per_cycle > 0 and a positive engine speed".into());
            }
            // 720 crank degrees per cycle at 6·N crank degrees per second.
            Some(120.0 / (x.engine_rpm * events_per_cycle as f64))
        }
    };
    let mut plant = EvvtPlant::<f64>::new(&EvvtParams {
        initial_phase_deg: PRBS_CENTRE_DEG,
        ..x.params
    })
    .map_err(|e| format!("{e:?}"))?;
    let mut ctrl = EvvtPhaseController::<f64>::new(&EvvtPhaseConfig::paper_fixed_p(x.kp_rpm_per_deg))
        .map_err(|e| format!("{e:?}"))?;
    let noise_sd = x.phase_noise_deg.max(0.0);
    let measure = |phase: f64, rng: &mut Rng| {
        quantize_phase_deg(phase + noise_sd * rng.normal(), PHASE_RESOLUTION_DEG).clamp(-30.0, 90.0)
    };
    let mut held = measure(plant.phase_deg(), &mut rng);
    // First cam event at a random crank angle.
    let mut next_event_s = cam_period_s.map_or(f64::INFINITY, |tc| rng.uniform(0.0, tc));
    let n = reference.len();
    let mut run = Run {
        cmd: Vec::with_capacity(n),
        rpm: Vec::with_capacity(n),
        volt: Vec::with_capacity(n),
        reference,
        phase: Vec::with_capacity(n),
    };
    for k in 0..n {
        let t = k as f64 * dt;
        if cam_period_s.is_none() {
            held = measure(plant.phase_deg(), &mut rng);
        }
        let out = ctrl.update(
            &EvvtPhaseInputs {
                setpoint_deg: run.reference[k],
                measured_phase_deg: held,
                engine_rpm: x.engine_rpm,
                u_batt_v: x.u_batt_v,
                cranking: false,
                fault: EvvtFault::None,
            },
            dt,
        );
        run.cmd.push(out.motor_cmd_rpm);
        run.rpm.push((x.engine_rpm + 3.0 * rng.normal()).max(0.0));
        run.volt.push((x.u_batt_v + 0.03 * rng.normal()).max(0.0));
        run.phase.push(held);
        // Move the plant through the period, stopping at each cam event to sample it; an
        // event at the period's end is seen at the next control instant.
        let t_end = t + dt;
        let mut t_now = t;
        while next_event_s <= t_end {
            plant.step(out.motor_cmd_rpm, x.engine_rpm, x.u_batt_v, next_event_s - t_now);
            t_now = next_event_s;
            held = measure(plant.phase_deg(), &mut rng);
            next_event_s += cam_period_s.unwrap_or(f64::INFINITY);
        }
        plant.step(out.motor_cmd_rpm, x.engine_rpm, x.u_batt_v, t_end - t_now);
    }
    let t: Vec<f64> = (0..n).map(|k| (k as f64 * dt * 1e6).round() / 1e6).collect();
    let mut meta = vec![
        ("plant".to_string(), "evvt".to_string()),
        ("source".into(), format!("hil-host generate, closed-loop PRBS identification experiment (simulated bench, seed {})", x.seed)),
        ("sample_rate_hz".into(), format!("{}", 1.0 / dt)),
        ("kp".into(), format!("{}", x.kp_rpm_per_deg)),
        ("control_period_s".into(), format!("{dt}")),
        ("motor_cmd_max_rpm".into(), format!("{}", EvvtPhaseConfig::paper_fixed_p(x.kp_rpm_per_deg).motor_cmd_max_rpm)),
        ("controller".into(), format!("fixed P: motor_cmd_rpm = kp (phase_ref_deg - phase_deg), phase quantized to {PHASE_RESOLUTION_DEG} crank deg, saturated")),
    ];
    if let PhaseSampling::CamEvents { events_per_cycle } = x.phase_sampling {
        meta.push(("cam_events_per_cycle".into(), format!("{events_per_cycle}")));
    }
    Ok(format_log(
        &meta,
        &[
            ("t_s", &t),
            ("motor_cmd_rpm", &run.cmd),
            ("engine_rpm", &run.rpm),
            ("u_batt_V", &run.volt),
            ("phase_ref_deg", &run.reference),
            ("phase_deg", &run.phase),
        ],
    ))
}

/// The paper's nine identification logs (Section IV-B: 800/1100/1400 rpm × 9.5/11.5/14 V) of
/// the design table, default experiment, as (file name, log text).
pub fn identification_grid(seed: u64) -> Result<Vec<(String, String)>, String> {
    let design = EvvtLpvTable::PAPER_DESIGN;
    let mut logs = Vec::with_capacity(9);
    for (i, &n) in design.engine_speed_rpm.iter().enumerate() {
        for (j, &v) in design.battery_voltage_v.iter().enumerate() {
            let x = IdentificationExperiment {
                engine_rpm: n,
                u_batt_v: v,
                seed: seed.wrapping_add(3 * i as u64 + j as u64),
                ..Default::default()
            };
            logs.push((format!("prbs-{n}rpm-{v}V.csv"), identification_log(&x)?));
        }
    }
    Ok(logs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logs_read_back_with_the_stated_loop_and_cover_the_grid() {
        let case = generate("none", 5).unwrap();
        let (est, val) = case.logs().expect("generated logs read back");
        assert_eq!(est.plant, Plant::Evvt);
        assert_eq!((est.len(), val.len()), (22_500, 10_200));
        assert!((est.dt_s - DT_S).abs() < 1e-12);
        // The log obeys the controller law it states, from the quantized phase.
        let kp = est.meta_f64("kp").unwrap().unwrap();
        let (c, r, y) = (
            est.col("motor_cmd_rpm").unwrap(),
            est.col("phase_ref_deg").unwrap(),
            est.col("phase_deg").unwrap(),
        );
        for k in 0..est.len() {
            assert_eq!(c[k], (kp * (r[k] - y[k])).clamp(-1000.0, 1000.0));
            assert_eq!(y[k], y[k].round(), "phase quantized to 1 deg");
        }
        // PRBS levels 25 ± 7.5; the phase follows them within a few degrees.
        assert!(r.iter().all(|&v| v == 17.5 || v == 32.5));
        let mean_y = y.iter().sum::<f64>() / y.len() as f64;
        assert!((mean_y - 25.0).abs() < 3.0, "mean phase {mean_y}");
        // The stitched points span the paper's grid, speed and voltage uncorrelated.
        let (n, v) = (est.col("engine_rpm").unwrap(), est.col("u_batt_V").unwrap());
        let (nmin, nmax) = n.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        let (vmin, vmax) = v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(nmin < 860.0 && nmax > 1340.0 && vmin < 10.0 && vmax > 13.5);
        let corr = crate::residuals::cross_correlation(n, v, 0)[0];
        assert!(corr.abs() < 0.3, "speed-voltage correlation {corr}");
        // Validation is a different excitation: not the two PRBS levels.
        assert!(val
            .col("phase_ref_deg")
            .unwrap()
            .iter()
            .any(|&x| x != 17.5 && x != 32.5 && x != 20.0));
    }

    #[test]
    fn hidden_effects_change_the_response_and_none_is_lti() {
        let (p, _, _) = draw_params(&[], &mut Rng::new(3));
        let plant = EvvtPlant::<f64>::new(&p).unwrap();
        assert_eq!(plant.alpha_beta(800.0, 9.5), plant.alpha_beta(1400.0, 14.0));
        let (p, _, _) = draw_params(&["supply-voltage"], &mut Rng::new(3));
        let plant = EvvtPlant::<f64>::new(&p).unwrap();
        let (lo, hi) = (plant.alpha_beta(1100.0, 9.5), plant.alpha_beta(1100.0, 14.0));
        assert!(hi.0 / lo.0 > 1.5 && hi.1 / lo.1 > 1.3, "{lo:?} {hi:?}");
        assert_eq!(plant.alpha_beta(800.0, 12.0), plant.alpha_beta(1400.0, 12.0));
        let (p, _, _) = draw_params(&["engine-speed"], &mut Rng::new(3));
        let plant = EvvtPlant::<f64>::new(&p).unwrap();
        let (slow, fast) = (plant.alpha_beta(1400.0, 12.0), plant.alpha_beta(800.0, 12.0));
        assert!(fast.0 / slow.0 > 1.5, "{slow:?} {fast:?}");
        assert_eq!(plant.alpha_beta(1100.0, 9.5), plant.alpha_beta(1100.0, 14.0));
        let (p, v, truth) = draw_params(&["belt-vibration"], &mut Rng::new(3));
        assert!(p.belt_vibration_amplitude_deg >= 0.6 && (0.5..=2.0).contains(&p.belt_vibration_order));
        assert_ne!(p.belt_vibration_phase_rad, v.belt_vibration_phase_rad);
        assert!(truth.iter().any(|(k, _)| k == "belt_order"));
    }

    #[test]
    fn same_seed_same_case() {
        let a = generate("direction", 9).unwrap();
        let b = generate("direction", 9).unwrap();
        assert_eq!(a.estimation_csv, b.estimation_csv);
        assert_eq!(a.validation_csv, b.validation_csv);
        assert_ne!(a.estimation_csv, generate("direction", 10).unwrap().estimation_csv);
    }

    #[test]
    fn the_unit_of_a_truth_is_the_plant_the_generator_drew() {
        for effects in [
            &[][..],
            &["supply-voltage"][..],
            &["engine-speed"][..],
            &["direction"][..],
            &["belt-vibration"][..],
            &["supply-voltage", "belt-vibration"][..],
        ] {
            for seed in [1, 29] {
                let (p, _, truth) = draw_params(effects, &mut Rng::new(seed));
                let get = |k: &str| truth.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
                assert_eq!(unit_from_truth(&get).unwrap(), p, "{effects:?}, seed {seed}");
            }
        }
        let e = unit_from_truth(&|k: &str| (k == "command_delay_s").then_some(0.04)).unwrap_err();
        assert!(e.contains("command_delay_s"), "{e}");
        assert!(unit_from_truth(&|_: &str| None)
            .unwrap_err()
            .contains("alpha_scale_of_design"));
    }
}
