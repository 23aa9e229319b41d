//! Positioner cases: the EMPS-like positioner in its known closed loop (the EMPS PD controller
//! at 1 kHz), plant sub-stepped at 10 kHz. Estimation: trapezoidal point-to-point moves
//! (bang-bang acceleration, as the EMPS estimation experiment). Validation: a different
//! trajectory, sinusoidal sweeps, with force pulses added to the controller output (as the
//! EMPS validation experiment). Sensors: encoder quantization on position, white noise on the
//! logged force.

use model_core::positioner::{EmpsController, EmpsControllerParams, Positioner, PositionerEffects, PositionerParams};

use super::{quantize, Case, Rng};
use crate::log::{format_log, Plant};

const DT_S: f64 = 0.001;
const SUBSTEPS: usize = 10;
const POS_LSB_M: f64 = 1e-6;
const FORCE_NOISE_N: f64 = 0.5;

/// Draws the plant: baseline M, Fv, offset; the hidden effect's magnitude on top.
fn draw_params(effects: &[&str], rng: &mut Rng) -> (PositionerParams, Vec<(String, f64)>) {
    let mut p = PositionerParams::emps().baseline();
    p.mass_kg = rng.uniform(60.0, 130.0);
    p.fv_n_s_per_m = rng.uniform(120.0, 300.0);
    p.offset_n = rng.uniform(-5.0, 5.0);
    p.fc_n = 0.0;
    let mut truth = vec![
        ("M_kg".to_string(), p.mass_kg),
        ("Fv_Ns_per_m".into(), p.fv_n_s_per_m),
        ("offset_N".into(), p.offset_n),
    ];
    // The two catalogue effects nest: the richer one decides.
    let effect = if effects.contains(&"asymmetric-friction") {
        "asymmetric-friction"
    } else if effects.contains(&"coulomb-friction") {
        "coulomb-friction"
    } else {
        "none"
    };
    match effect {
        "coulomb-friction" => {
            p.fc_n = rng.uniform(8.0, 35.0);
            p.effects = PositionerEffects {
                coulomb_friction: true,
                asymmetric_friction: false,
            };
            truth.push(("Fc_N".into(), p.fc_n));
        }
        "asymmetric-friction" => {
            // Viscous friction differs by 1.8..3× between directions and Coulomb levels differ
            // too; which direction is stiffer is random. EMPS itself shows 240/167 = 1.44 with
            // 20 N Coulomb, where the symmetric Coulomb model explains most of the error and
            // is rightly named; here the asymmetry is the dominant missing physics.
            let ratio = rng.uniform(1.8, 3.0);
            let (lo, hi) = (p.fv_n_s_per_m / ratio.sqrt(), p.fv_n_s_per_m * ratio.sqrt());
            let (fv_pos, fv_neg) = if rng.coin() { (lo, hi) } else { (hi, lo) };
            p.fv_pos_n_s_per_m = fv_pos;
            p.fv_neg_n_s_per_m = fv_neg;
            p.fc_pos_n = rng.uniform(4.0, 20.0);
            p.fc_neg_n = rng.uniform(4.0, 20.0);
            p.effects = PositionerEffects {
                coulomb_friction: true,
                asymmetric_friction: true,
            };
            truth.extend([
                ("Fv_pos_Ns_per_m".into(), fv_pos),
                ("Fv_neg_Ns_per_m".into(), fv_neg),
                ("Fc_pos_N".into(), p.fc_pos_n),
                ("Fc_neg_N".into(), p.fc_neg_n),
            ]);
        }
        _ => {}
    }
    (p, truth)
}

/// Trapezoidal moves between random targets in 0..0.24 m.
fn estimation_reference(rng: &mut Rng, duration_s: f64) -> Vec<f64> {
    let n = (duration_s / DT_S) as usize;
    let mut r = Vec::with_capacity(n);
    let mut pos: f64 = 0.0;
    while r.len() < n {
        let target = rng.uniform(0.0, 0.24);
        let v_max = rng.uniform(0.04, 0.16);
        let a_max = rng.uniform(0.5, 2.0);
        let dist = target - pos;
        let dir = dist.signum();
        let d = dist.abs();
        // Triangular profile when the move is too short to reach v_max.
        let v_peak = v_max.min((d * a_max).sqrt());
        let t_acc = v_peak / a_max;
        let t_cruise = if v_peak > 0.0 {
            (d - v_peak * t_acc) / v_peak
        } else {
            0.0
        };
        let t_move = 2.0 * t_acc + t_cruise.max(0.0);
        let steps = (t_move / DT_S).ceil() as usize;
        for k in 1..=steps {
            let t = k as f64 * DT_S;
            let s = if t < t_acc {
                0.5 * a_max * t * t
            } else if t < t_acc + t_cruise {
                0.5 * a_max * t_acc * t_acc + v_peak * (t - t_acc)
            } else {
                let td = (t_move - t).max(0.0);
                d - 0.5 * a_max * td * td
            };
            r.push(pos + dir * s.min(d));
        }
        pos = target;
        let dwell = (rng.uniform(0.1, 0.5) / DT_S) as usize;
        r.extend(std::iter::repeat_n(pos, dwell));
    }
    r.truncate(n);
    r
}

/// Sinusoidal sweeps about mid-stroke with changing amplitude and frequency.
fn validation_reference(rng: &mut Rng, duration_s: f64) -> Vec<f64> {
    let n = (duration_s / DT_S) as usize;
    let mut r = Vec::with_capacity(n);
    let mut phase: f64 = 0.0;
    let mut seg_left = 0usize;
    let (mut amp, mut freq) = (0.05, 0.3);
    for _ in 0..n {
        if seg_left == 0 {
            amp = rng.uniform(0.02, 0.10);
            freq = rng.uniform(0.15, 0.6);
            seg_left = (rng.uniform(2.0, 4.0) / DT_S) as usize;
        }
        seg_left -= 1;
        phase += 2.0 * std::f64::consts::PI * freq * DT_S;
        r.push(0.12 + amp * phase.sin());
    }
    // Start at rest at the first value.
    r
}

/// Position-dependent forces on the load that the model does not have (outside the catalogue):
/// a return spring −k (q − q0) (`position-spring`) and a force ripple periodic in position,
/// A sin(2π q / λ + φ) (`force-ripple`: a screw's or a motor's cogging). Zero without them.
#[derive(Clone, Copy, Default)]
struct OutsideForce {
    spring_n_per_m: f64,
    spring_rest_m: f64,
    ripple_n: f64,
    ripple_pitch_m: f64,
    ripple_phase_rad: f64,
}

impl OutsideForce {
    fn at(&self, pos_m: f64) -> f64 {
        let ripple = if self.ripple_n == 0.0 {
            0.0
        } else {
            self.ripple_n * (std::f64::consts::TAU * pos_m / self.ripple_pitch_m + self.ripple_phase_rad).sin()
        };
        -self.spring_n_per_m * (pos_m - self.spring_rest_m) + ripple
    }
}

/// Runs the closed loop; returns (force logged, position logged). `outside` acts on the load
/// beside the motor force.
fn run_loop(
    p: &PositionerParams,
    reference: &[f64],
    pulses: &[f64],
    outside: OutsideForce,
    rng: &mut Rng,
) -> Result<(Vec<f64>, Vec<f64>), String> {
    let ctrl_p = EmpsControllerParams::emps();
    let mut plant = Positioner::<f64>::new(p).map_err(|e| format!("{e:?}"))?;
    let pos0 = reference.first().copied().unwrap_or(0.0);
    plant.set_state(pos0, 0.0);
    let mut ctrl = EmpsController::<f64>::new(&ctrl_p, pos0).map_err(|e| format!("{e:?}"))?;
    let mut force_log = Vec::with_capacity(reference.len());
    let mut pos_log = Vec::with_capacity(reference.len());
    for (k, &r) in reference.iter().enumerate() {
        let pos_meas = quantize(plant.pos_m(), POS_LSB_M);
        let force = (ctrl.update(r, pos_meas) + pulses.get(k).copied().unwrap_or(0.0))
            .clamp(-ctrl_p.force_max_n, ctrl_p.force_max_n);
        force_log.push(force + FORCE_NOISE_N * rng.normal());
        pos_log.push(pos_meas);
        for _ in 0..SUBSTEPS {
            plant.step(force + outside.at(plant.pos_m()), DT_S / SUBSTEPS as f64);
        }
    }
    Ok((force_log, pos_log))
}

fn log_text(kind: &str, seed: u64, reference: &[f64], force: &[f64], pos: &[f64]) -> String {
    let c = EmpsControllerParams::emps();
    let t: Vec<f64> = (0..reference.len())
        .map(|k| (k as f64 * DT_S * 1e6).round() / 1e6)
        .collect();
    let meta = vec![
        ("plant".to_string(), "positioner".to_string()),
        (
            "source".into(),
            format!("hil-host generate, {kind} experiment (simulated bench, seed {seed})"),
        ),
        ("sample_rate_hz".into(), format!("{}", 1.0 / DT_S)),
        ("gtau".into(), format!("{}", c.gtau_n_per_v)),
        ("kp".into(), format!("{}", c.kp_per_s)),
        ("kv".into(), format!("{}", c.kv_v_s_per_m)),
        ("control_period_s".into(), format!("{}", c.control_period_s)),
        ("force_max_N".into(), format!("{}", c.force_max_n)),
        (
            "controller".into(),
            "EMPS PD: force = gtau (kp kv (ref - pos) - kv v), v from the 2-tap FIR position".into(),
        ),
    ];
    format_log(
        &meta,
        &[("t_s", &t), ("force_N", force), ("ref_m", reference), ("pos_m", pos)],
    )
}

pub fn generate(effect: &str, seed: u64) -> Result<Case, String> {
    generate_sized(effect, seed, 25.0, 15.0)
}

/// A case with chosen experiment lengths in seconds (1 kHz: 100 s is a 100 000-sample log).
pub fn generate_sized(effect: &str, seed: u64, estimation_s: f64, validation_s: f64) -> Result<Case, String> {
    let parts = super::parse_effects(Plant::Positioner, effect)?;
    generate_parts(&parts, seed, estimation_s, validation_s)
}

/// A case with the given hidden effects (catalogue or outside), default lengths.
pub fn generate_effects(parts: &[&str], seed: u64) -> Result<Case, String> {
    generate_parts(parts, seed, 25.0, 15.0)
}

fn generate_parts(parts: &[&str], seed: u64, estimation_s: f64, validation_s: f64) -> Result<Case, String> {
    let effect = if parts.is_empty() {
        "none".to_string()
    } else {
        parts.join("+")
    };
    let mut rng = Rng::new(seed);
    let (params, mut truth) = draw_params(parts, &mut rng);
    // Outside the catalogue: a return spring about the middle of the travel, a force ripple
    // (each drawn only where hidden, so the other draws stay those of its seed).
    let mut outside = OutsideForce::default();
    if parts.contains(&"position-spring") {
        outside.spring_n_per_m = rng.uniform(300.0, 900.0);
        outside.spring_rest_m = 0.12;
        truth.push(("spring_N_per_m".into(), outside.spring_n_per_m));
    }
    if parts.contains(&"force-ripple") {
        // A ball screw's lead is 5-20 mm; the ripple a few percent of the motor's force range,
        // comparable to the Coulomb friction.
        outside.ripple_n = rng.uniform(8.0, 20.0);
        outside.ripple_pitch_m = rng.uniform(0.005, 0.02);
        outside.ripple_phase_rad = rng.uniform(0.0, std::f64::consts::TAU);
        truth.push(("ripple_N".into(), outside.ripple_n));
        truth.push(("ripple_pitch_m".into(), outside.ripple_pitch_m));
        truth.push(("ripple_phase_rad".into(), outside.ripple_phase_rad));
    }
    let est_ref = estimation_reference(&mut rng, estimation_s);
    let (ef, ep) = run_loop(&params, &est_ref, &[], outside, &mut rng)?;
    let val_ref = validation_reference(&mut rng, validation_s);
    // Force pulses on the controller output: 50 ms, ±40..120 N, every 1-2 s.
    let mut pulses = vec![0.0; val_ref.len()];
    let mut k = 500;
    while k < pulses.len() {
        let a = rng.uniform(40.0, 120.0) * if rng.coin() { 1.0 } else { -1.0 };
        for v in pulses.iter_mut().skip(k).take(50) {
            *v = a;
        }
        k += (rng.uniform(1.0, 2.0) / DT_S) as usize;
    }
    let (vf, vp) = run_loop(&params, &val_ref, &pulses, outside, &mut rng)?;
    Ok(Case {
        plant: Plant::Positioner,
        seed,
        effect,
        truth,
        estimation_csv: log_text("estimation", seed, &est_ref, &ef, &ep),
        validation_csv: log_text("validation", seed, &val_ref, &vf, &vp),
    })
}
