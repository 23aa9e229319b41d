//! The phaser model the EVVT family fits: eq. (12) with the catalogue's extensions, its
//! simulation over a record (closed loop or open-loop windows), and the map from a parameter
//! vector to a model.

use std::f64::consts::PI;

use model_core::evvt::{quantize_phase_deg, zoh};

use super::{Data, Drive};
use crate::diagnose::catalogue::{Effect, EvvtEffect};

/// A phaser model: eq. (12) with the catalogue's extensions (all off = baseline).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Model {
    pub(super) alpha: f64,
    pub(super) beta: f64,
    pub(super) v_ref: f64,
    pub(super) alpha_per_v: f64,
    pub(super) beta_per_v: f64,
    pub(super) n_ref_krpm: f64,
    pub(super) alpha_per_krpm: f64,
    pub(super) beta_per_krpm: f64,
    /// Relative slopes per V·1000 rpm: with both scheduling effects, how the voltage
    /// dependence changes with speed ([`SCHEDULE_INTERACTION`]).
    pub(super) alpha_per_v_krpm: f64,
    pub(super) beta_per_v_krpm: f64,
    pub(super) advance_factor: f64,
    pub(super) belt_order: f64,
    /// Belt disturbance `c cos(2π o θ) + s sin(2π o θ)` = `A sin(2π o θ + φ)`.
    pub(super) belt_cos: f64,
    pub(super) belt_sin: f64,
    /// Transport delay between the controller's command and the phaser, s (the
    /// command-delay probe only; 0 in every catalogue model).
    pub(super) cmd_delay_s: f64,
    /// Clearance between the phaser's drive and the camshaft, crank deg (the gear-backlash
    /// probe only; 0 in every catalogue model): the measured cam phase follows the model's
    /// phase only once the clearance is taken up.
    pub(super) backlash_deg: f64,
}

impl Model {
    pub(super) fn lti(alpha: f64, beta: f64) -> Self {
        Model {
            alpha,
            beta,
            v_ref: 12.0,
            alpha_per_v: 0.0,
            beta_per_v: 0.0,
            n_ref_krpm: 1.1,
            alpha_per_krpm: 0.0,
            beta_per_krpm: 0.0,
            alpha_per_v_krpm: 0.0,
            beta_per_v_krpm: 0.0,
            advance_factor: 1.0,
            belt_order: 0.5,
            belt_cos: 0.0,
            belt_sin: 0.0,
            cmd_delay_s: 0.0,
            backlash_deg: 0.0,
        }
    }

    /// α and β at engine speed `n` (rpm) and battery voltage `v`; the affine factors are kept
    /// positive (α ≥ 2 % of its reference, β ≥ 0) so that no parameter set flips the plant.
    pub(super) fn alpha_beta(&self, n: f64, v: f64) -> (f64, f64) {
        let dn = n / 1000.0 - self.n_ref_krpm;
        let dv = v - self.v_ref;
        let fa = (1.0 + self.alpha_per_v * dv + self.alpha_per_krpm * dn + self.alpha_per_v_krpm * dv * dn).max(0.02);
        let fb = (1.0 + self.beta_per_v * dv + self.beta_per_krpm * dn + self.beta_per_v_krpm * dv * dn).max(0.0);
        (self.alpha * fa, self.beta * fb)
    }

    pub(super) fn belt_on(&self) -> bool {
        self.belt_cos != 0.0 || self.belt_sin != 0.0
    }

    pub(super) fn belt_deg(&self, revs: f64) -> f64 {
        let (s, c) = (2.0 * PI * (self.belt_order * revs).fract()).sin_cos();
        self.belt_cos * c + self.belt_sin * s
    }
}

/// Simulates the model over the log (module doc), writing the phase at each sample into
/// `out` (quantization not applied: the model's phase).
pub(super) fn simulate(m: &Model, d: &Data, out: &mut [f64]) -> Result<(), String> {
    let n = d.y.len().min(out.len());
    let belt_on = m.belt_on();
    // The revolutions start at 0 (`Data::revs`).
    let mut revs = d.revs();
    let mut belt = || {
        if belt_on {
            m.belt_deg(revs.next().unwrap_or(0.0))
        } else {
            0.0
        }
    };
    let b0 = if belt_on { m.belt_deg(0.0) } else { 0.0 };
    let mut x1 = (d.y[0] - b0).clamp(d.stop_lo, d.stop_hi);
    // The cam within the clearance (the play's half width each side of the drive's phase,
    // the belt's vibration left out).
    let half_play = 0.5 * m.backlash_deg.max(0.0);
    let mut cam = x1;
    let mut x2 = 0.0;
    let mut u_held = 0.0;
    let mut key = (f64::NAN, f64::NAN);
    let mut z = zoh(0.0, 0.0, d.dt);
    // The command history, kept only for a delayed command (linear between samples).
    let delay_samples = (m.cmd_delay_s / d.dt).max(0.0);
    let mut history: Vec<f64> = if delay_samples > 0.0 {
        Vec::with_capacity(n)
    } else {
        Vec::new()
    };
    let (delay_whole, delay_frac) = (delay_samples.floor() as usize, delay_samples.fract());
    for (k, slot) in out.iter_mut().enumerate().take(n) {
        let b = belt();
        if let Drive::OpenLoop { window } = d.drive {
            if k % window == 0 {
                x1 = (d.y[k] - b).clamp(d.stop_lo, d.stop_hi);
                cam = x1;
            }
        }
        // The belt's vibration reaches the cam past the drive's clearance.
        let phase = if half_play > 0.0 {
            cam = cam.clamp(x1 - half_play, x1 + half_play);
            cam + b
        } else {
            x1 + b
        };
        *slot = phase;
        let u = match d.drive {
            Drive::ClosedLoop { kp, cmd_max, hold } => {
                if k % hold == 0 {
                    u_held = (kp * (d.reference[k] - quantizer(phase, d.lsb, d.ramp))).clamp(-cmd_max, cmd_max);
                }
                u_held
            }
            Drive::OpenLoop { .. } => d.cmd[k],
        };
        let u = if delay_samples > 0.0 {
            history.push(u);
            // Before the record the command is taken as its first value.
            let at = |back: usize| history[k.saturating_sub(back)];
            (1.0 - delay_frac) * at(delay_whole) + delay_frac * at(delay_whole + 1)
        } else {
            u
        };
        let (mut a, beta) = m.alpha_beta(d.rpm[k], d.volt[k]);
        if u > 0.0 {
            a *= m.advance_factor;
        }
        if (a, beta) != key {
            z = zoh(a, beta, d.dt);
            key = (a, beta);
        }
        let next = x1 + z.ad12_s * x2 + z.bd1_deg_per_rpm * u;
        x2 = z.ad22 * x2 + z.bd2_deg_per_s_rpm * u;
        x1 = next;
        if x1 >= d.stop_hi {
            x1 = d.stop_hi;
            x2 = x2.min(0.0);
        } else if x1 <= d.stop_lo {
            x1 = d.stop_lo;
            x2 = x2.max(0.0);
        }
        if !(x1.is_finite() && x2.is_finite()) {
            return Err(format!("simulation diverged at sample {k}"));
        }
    }
    Ok(())
}

/// The measurement's quantizer as the simulated controller sees it: exact rounding
/// (`ramp` = 0), or levels joined by linear ramps `ramp` LSB wide (1: no quantization).
pub(super) fn quantizer(x: f64, lsb: f64, ramp: f64) -> f64 {
    if lsb <= 0.0 {
        return x;
    }
    if ramp <= 0.0 {
        return quantize_phase_deg(x, lsb);
    }
    let u = x / lsb;
    let f = u - u.floor();
    (u.floor() + ((f - 0.5) / ramp.min(1.0) + 0.5).clamp(0.0, 1.0)) * lsb
}

pub(super) fn sim_error(m: &Model, d: &Data, out: &mut [f64]) -> Result<(), String> {
    simulate(m, d, out)?;
    for (o, y) in out.iter_mut().zip(d.y) {
        *o -= y;
    }
    Ok(())
}

/// Parameter vector layout of one model.
pub(super) struct Spec {
    pub(super) x0: Vec<f64>,
    pub(super) lo: Vec<f64>,
    pub(super) hi: Vec<f64>,
}

/// What the extensions' parameterisation needs from the estimation data.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ctx {
    pub(super) v_ref: f64,
    pub(super) n_ref_krpm: f64,
}

/// With both scheduling effects (`supply-voltage` and `engine-speed`) α and β also move with
/// the product of the voltage and speed deviations: the paper's table is not a sum of a
/// voltage and a speed part (Section IV-D: α/β halves from 14 to 9.5 V at high engine speed,
/// while at 1100 rpm α and β move together; the phaser slows with speed at low voltage, and
/// the table moves only 10 % with speed at 14 V). The second of the two to enter a model adds
/// these two relative slopes (per V·1000 rpm, neutral 0) after its own: the pair's bilinear
/// part, which neither effect has alone.
pub(super) const SCHEDULE_INTERACTION: [&str; 2] = ["alpha_rel_slope_per_V_1000rpm", "beta_rel_slope_per_V_1000rpm"];

/// Whether `effect`, entering a model that has `before`, completes the two scheduling effects
/// (and so adds [`SCHEDULE_INTERACTION`]).
pub(super) fn completes_schedule(before: &[EvvtEffect], effect: EvvtEffect) -> bool {
    match effect {
        EvvtEffect::SupplyVoltage => before.contains(&EvvtEffect::EngineSpeed),
        EvvtEffect::EngineSpeed => before.contains(&EvvtEffect::SupplyVoltage),
        _ => false,
    }
}

/// The parameter names the `i`-th of `effects` adds: its catalogue parameters, then the
/// scheduling interaction if it completes the pair.
pub(super) fn param_names(effects: &[EvvtEffect], i: usize) -> Vec<&'static str> {
    let mut names: Vec<&'static str> = effects[i].params().iter().map(|(n, _)| *n).collect();
    if completes_schedule(&effects[..i], effects[i]) {
        names.extend(SCHEDULE_INTERACTION);
    }
    names
}

/// All parameter names after α and β, in order.
pub(super) fn effect_param_names(effects: &[EvvtEffect]) -> Vec<&'static str> {
    (0..effects.len()).flat_map(|i| param_names(effects, i)).collect()
}

/// The model of the baseline plus `effects`; `x` is α, β, then each effect's parameters in
/// the order of `effects` ([`param_names`]: the catalogue's parameters of each, and the
/// scheduling interaction after the second scheduling effect).
pub(super) fn model_from(effects: &[EvvtEffect], x: &[f64], ctx: &Ctx) -> Model {
    let mut m = Model {
        v_ref: ctx.v_ref,
        n_ref_krpm: ctx.n_ref_krpm,
        ..Model::lti(x[0], x[1])
    };
    let mut at = 2;
    for (i, e) in effects.iter().enumerate() {
        let v = |i: usize| x.get(at + i).copied().unwrap_or(0.0);
        match e {
            EvvtEffect::SupplyVoltage => {
                m.alpha_per_v = v(0);
                m.beta_per_v = v(1);
            }
            EvvtEffect::EngineSpeed => {
                m.alpha_per_krpm = v(0);
                m.beta_per_krpm = v(1);
            }
            EvvtEffect::Direction => m.advance_factor = v(0),
            EvvtEffect::BeltVibration => {
                m.belt_order = v(0);
                m.belt_cos = v(1);
                m.belt_sin = v(2);
            }
        }
        let own = e.params().len();
        if completes_schedule(&effects[..i], *e) {
            m.alpha_per_v_krpm = v(own);
            m.beta_per_v_krpm = v(own + 1);
        }
        at += param_names(effects, i).len();
    }
    m
}
