//! The `positioner` family (EMPS-like: motor, screw, load) by the inverse dynamic model, the
//! equation-error formulation of the EMPS description (IDIM-LS, Sec. 3):
//!
//!   force = M q̈ + Fv q̇ + Fc sign(q̇) + offset
//!
//! is linear in the parameters, so each model is one least-squares regression of the measured
//! force on functions of the measured position: no simulation of the closed loop is needed, and
//! the controller does not bias the estimate because position is measured with little noise.
//! Position is filtered forward and backward (Butterworth, no lag) and differentiated by
//! central differences; every column is then low-passed and decimated alike. The reported
//! output is the force the model reconstructs, on the validation data.
//!
//! Baseline: M, Fv, offset. `coulomb-friction`: + Fc. `asymmetric-friction`: viscous and
//! Coulomb coefficients per direction, M, Fv+, Fv−, Fc+, Fc− (EMPS description eq. (12)).

use std::borrow::Cow;

use super::catalogue::{Effect, PositionerEffect};
use super::{noise_floor_of, Family, Fit, NoiseFloor};
use crate::log::{Log, Plant};
use crate::lsq::{invert_spd, linear_lsq};
use crate::signal::{derivative, downsample, Butterworth};

/// Asymmetric friction contains Coulomb friction.
const NESTED: [(&str, &str); 1] = [(
    PositionerEffect::CoulombFriction.name(),
    PositionerEffect::AsymmetricFriction.name(),
)];

/// Filter settings. Defaults reproduce the published EMPS IDIM-LS estimates.
#[derive(Clone, Debug)]
pub struct PositionerFamily {
    /// Position filter cut-off (rule of thumb: ≥ 5× the closed loop's highest mode).
    pub position_cutoff_hz: f64,
    /// Decimation factor of the parallel filter.
    pub decimation: usize,
    /// Speeds below this count as standing still for the sign of the velocity.
    pub v_still_m_s: f64,
}

impl Default for PositionerFamily {
    fn default() -> Self {
        Self {
            position_cutoff_hz: 80.0,
            decimation: 20,
            v_still_m_s: 1e-4,
        }
    }
}

/// Filtered motion, and the log's force.
struct Motion<'a> {
    acc: Vec<f64>,
    vel: Vec<f64>,
    force: &'a [f64],
    pos: Vec<f64>,
}

impl PositionerFamily {
    fn motion<'a>(&self, log: &'a Log) -> Result<Motion<'a>, String> {
        let q = log.col("pos_m").ok_or("no pos_m column")?;
        let f = log.col("force_N").ok_or("no force_N column")?;
        let fs = 1.0 / log.dt_s;
        let q_filter = Butterworth::lowpass(4, self.position_cutoff_hz.min(0.4 * fs), fs)?;
        let qf = q_filter.filtfilt(q);
        let vel = derivative(&qf, log.dt_s);
        let acc = derivative(&vel, log.dt_s);
        Ok(Motion {
            acc,
            vel,
            force: f,
            pos: qf,
        })
    }

    /// The decimate process applied to one column. The parallel low-pass keeps 80 % of the
    /// new Nyquist band, as MATLAB's decimate does; sign columns are built before it and
    /// filtered like every other column. The filter's settling span is then dropped at both
    /// ends: a record cut out of a longer run starts in motion, and indicator columns have no
    /// meaningful reflection.
    fn decimate(&self, x: &[f64], fs: f64) -> Result<Vec<f64>, String> {
        let nd = self.decimation.max(1);
        let lp = Butterworth::lowpass(8, 0.8 * 0.5 * fs / nd as f64, fs)?;
        let v = if nd == 1 {
            lp.filtfilt(x)
        } else {
            downsample(&lp.filtfilt(x), nd)
        };
        let trim = lp.settling_samples().div_ceil(nd);
        Ok(if v.len() > 4 * trim {
            v[trim..v.len() - trim].to_vec()
        } else {
            v
        })
    }

    /// The regressor columns of a model, already decimated, and their parameter names. Each
    /// column is made at full rate and decimated before the next is made (on a long record the
    /// full-rate columns held together were the family's peak).
    fn columns(&self, m: &Motion, effect: Option<&str>, fs: f64) -> Result<Regression, String> {
        let still = self.v_still_m_s;
        let pos = |v: f64| if v > still { 1.0 } else { 0.0 };
        let neg = |v: f64| if v < -still { 1.0 } else { 0.0 };
        let mut names: Vec<String> = Vec::new();
        let mut data: Vec<Vec<f64>> = Vec::new();
        let mut add = |name: &str, column: &[f64]| -> Result<(), String> {
            data.push(self.decimate(column, fs)?);
            names.push(name.into());
            Ok(())
        };
        let derived = |f: &dyn Fn(f64) -> f64| m.vel.iter().map(|&v| f(v)).collect::<Vec<f64>>();
        add("M_kg", &m.acc)?;
        match effect {
            None | Some("coulomb-friction") => add("Fv_Ns_per_m", &m.vel)?,
            Some("asymmetric-friction") => {
                add("Fv_pos_Ns_per_m", &derived(&|v| v * pos(v)))?;
                add("Fv_neg_Ns_per_m", &derived(&|v| v * neg(v)))?;
            }
            Some(other) => return Err(format!("unknown positioner effect `{other}`")),
        }
        match effect {
            None => add("offset_N", &vec![1.0; m.acc.len()])?,
            Some("coulomb-friction") => {
                add("Fc_N", &derived(&|v| pos(v) - neg(v)))?;
                add("offset_N", &vec![1.0; m.acc.len()])?;
            }
            // Eq. (12): Fc+ sign(0+(q̇)) + Fc− sign(0−(q̇)); the two Coulomb levels absorb the
            // offset (a separate offset would be collinear with them while the load moves).
            Some(_) => {
                add("Fc_pos_N", &derived(&|v| pos(v)))?;
                add("Fc_neg_N", &derived(&|v| -neg(v)))?;
            }
        }
        Ok((data, names, self.decimate(m.force, fs)?))
    }
}

impl PositionerFamily {
    /// The IDIM-LS regression of a log for `effect` (`None`: the baseline): the decimated
    /// regressor columns and force, as `fit` solves them. Public for the peer benchmark, which
    /// times the least-squares solve alone next to scipy's `least_squares` on the same matrix.
    pub fn idim_regression(&self, log: &Log, effect: Option<&str>) -> Result<(Vec<Vec<f64>>, Vec<f64>), String> {
        let (cols, _, y) = self.columns(&self.motion(log)?, effect, 1.0 / log.dt_s)?;
        Ok((cols, y))
    }

    /// The RMS force error of the formulation itself (see `noise_floor`).
    fn formulation_error(&self, val: &Log, fit: &Fit) -> Result<f64, String> {
        let get = |k: &str| fit.params.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
        let mass = get("M_kg").filter(|m| *m > 0.0).ok_or("no positive mass")?;
        let fv = |v: f64| {
            if v >= 0.0 {
                get("Fv_pos_Ns_per_m").or(get("Fv_Ns_per_m")).unwrap_or(0.0)
            } else {
                get("Fv_neg_Ns_per_m").or(get("Fv_Ns_per_m")).unwrap_or(0.0)
            }
        };
        let fc = |v: f64| {
            if v > self.v_still_m_s {
                get("Fc_pos_N").or(get("Fc_N")).unwrap_or(0.0) + get("offset_N").unwrap_or(0.0)
            } else if v < -self.v_still_m_s {
                -get("Fc_neg_N").or(get("Fc_N")).unwrap_or(0.0) + get("offset_N").unwrap_or(0.0)
            } else {
                get("offset_N").unwrap_or(0.0)
            }
        };
        let q = val.col("pos_m").ok_or("no pos_m column")?;
        let f = val.col("force_N").ok_or("no force_N column")?;
        let lsb = super::resolution(q);
        let sub = 10;
        let h = val.dt_s / sub as f64;
        let (mut x, mut v) = (q.first().copied().unwrap_or(0.0), 0.0);
        let mut synth = val.clone();
        let mut pos = Vec::with_capacity(q.len());
        for &force in f {
            pos.push(if lsb > 0.0 { (x / lsb).round() * lsb } else { x });
            for _ in 0..sub {
                // Friction cannot reverse the motion within a step (a stuck load stays stuck).
                let a = (force - fv(v) * v - fc(v)) / mass;
                let v_new = v + a * h;
                v = if v != 0.0 && v_new.signum() != v.signum() {
                    0.0
                } else {
                    v_new
                };
                x += v * h;
            }
        }
        synth.columns.insert("pos_m".into(), pos);
        let m = self.motion(&synth)?;
        let effect = if fit.effects.iter().any(|e| e == "asymmetric-friction") {
            Some("asymmetric-friction")
        } else if fit.effects.iter().any(|e| e == "coulomb-friction") {
            Some("coulomb-friction")
        } else {
            None
        };
        let (cols, names, y) = self.columns(&m, effect, 1.0 / val.dt_s)?;
        let theta: Vec<f64> = names.iter().map(|n| get(n).unwrap_or(0.0)).collect();
        let e: Vec<f64> = (0..y.len())
            .map(|i| y[i] - cols.iter().zip(&theta).map(|(c, t)| c[i] * t).sum::<f64>())
            .collect();
        Ok(crate::residuals::rmse(&e))
    }
}

/// A linear regression problem: the regressor columns, their parameter names, the target (the
/// measured force), all decimated alike.
type Regression = (Vec<Vec<f64>>, Vec<String>, Vec<f64>);

impl Family for PositionerFamily {
    fn plant(&self) -> Plant {
        Plant::Positioner
    }
    fn output(&self) -> &'static str {
        "force_N"
    }
    fn formulation(&self) -> &'static str {
        "equation-error: inverse dynamic model (IDIM-LS) — force reconstructed from the filtered, differentiated measured position; no closed-loop simulation"
    }
    fn effects(&self) -> &'static [&'static str] {
        &PositionerEffect::NAMES
    }
    fn nested(&self) -> &'static [(&'static str, &'static str)] {
        &NESTED
    }

    fn fit(&self, effects: &[&str], _parent: Option<&Fit>, est: &Log, val: &Log) -> Result<Fit, String> {
        // Linear least squares finds the global optimum of every model at once, so a richer
        // model is never worse on the estimation data than the one it nests; asymmetric
        // friction contains Coulomb friction (the set of both is the asymmetric model).
        for e in effects {
            PositionerEffect::from_name(e)?;
        }
        let effect = if effects.contains(&PositionerEffect::AsymmetricFriction.name()) {
            Some(PositionerEffect::AsymmetricFriction.name())
        } else if effects.contains(&PositionerEffect::CoulombFriction.name()) {
            Some(PositionerEffect::CoulombFriction.name())
        } else {
            None
        };
        let (cols, names, y) = self.columns(&self.motion(est)?, effect, 1.0 / est.dt_s)?;
        let theta =
            linear_lsq(&cols, &y).ok_or("the regressors are linearly dependent (no motion in the estimation data?)")?;
        // Confidence intervals: s² (ΦᵀΦ)⁻¹ on the decimated estimation data.
        let p = cols.len();
        let n = y.len();
        let resid: Vec<f64> = (0..n)
            .map(|i| y[i] - (0..p).map(|j| cols[j][i] * theta[j]).sum::<f64>())
            .collect();
        let s2 = resid.iter().map(|r| r * r).sum::<f64>() / (n.saturating_sub(p).max(1)) as f64;
        let mut ata = vec![0.0; p * p];
        for a in 0..p {
            for b in 0..p {
                ata[a * p + b] = cols[a].iter().zip(&cols[b]).map(|(u, v)| u * v).sum();
            }
        }
        let inv = invert_spd(&ata, p);
        let ci95 = (0..p)
            .map(|j| inv.as_ref().map(|m| 1.96 * (s2 * m[j * p + j]).sqrt()))
            .collect();
        let (vcols, _, vy) = self.columns(&self.motion(val)?, effect, 1.0 / val.dt_s)?;
        let pred: Vec<f64> = (0..vy.len())
            .map(|i| (0..p).map(|j| vcols[j][i] * theta[j]).sum())
            .collect();
        let mut fit = Fit::new(
            &Fit::label(effects),
            names.into_iter().zip(theta).collect(),
            ci95,
            vy,
            pred,
            0,
        );
        fit.est_cost = 0.5 * resid.iter().map(|r| r * r).sum::<f64>();
        // A mass, a viscous or a Coulomb coefficient below zero is no physical positioner.
        for (k, v) in &fit.params {
            // Fc± hold the offset too (eq. (12)): either may be negative.
            if *v < 0.0 && (k.starts_with("M_") || k.starts_with("Fv") || k == "Fc_N") {
                fit.impossible.push(format!("{k} = {v:.4}"));
            }
        }
        for (c, (k, _)) in fit.ci95.iter().zip(&fit.params) {
            if c.is_none() {
                fit.not_identifiable.push(k.clone());
            }
        }
        Ok(fit)
    }

    /// What a perfect model would leave in the equation-error formulation: the force noise
    /// (second differences of the residual, as every family) and the formulation's own error,
    /// measured on a log the fitted model itself writes: the model is run under the logged
    /// force (10 sub-steps per sample), its position quantized like the encoder, and the same
    /// filters, derivatives and decimation turn it back into a force with the same parameters.
    /// What that reconstruction misses (filter roll-off at the acceleration's jumps, the
    /// encoder's steps through two derivatives) a perfect model would miss too.
    fn noise_floor(&self, val: &Log, fit: &Fit) -> NoiseFloor {
        let noise = noise_floor_of(&fit.residual(), 0.0);
        match self.formulation_error(val, fit) {
            Ok(art) => NoiseFloor {
                rmse: noise.rmse.hypot(art),
                method: format!(
                    "{}; with the equation-error formulation's own error on a log the fitted model writes itself (its position through the same filters and derivatives, encoder-quantized): {:.4}; floor = their root sum of squares",
                    noise.method, art
                ),
            },
            Err(_) => noise,
        }
    }

    fn regressors<'a>(&self, val: &'a Log) -> Vec<(String, Cow<'a, [f64]>)> {
        // Derived series, owned.
        let owned = (|| -> Vec<(String, Vec<f64>)> {
            let Ok(m) = self.motion(val) else { return Vec::new() };
            let fs = 1.0 / val.dt_s;
            let still = self.v_still_m_s;
            let sign: Vec<f64> = m
                .vel
                .iter()
                .map(|&v| {
                    if v > still {
                        1.0
                    } else if v < -still {
                        -1.0
                    } else {
                        0.0
                    }
                })
                .collect();
            let dir_pos: Vec<f64> = m.vel.iter().map(|&v| if v > still { 1.0 } else { 0.0 }).collect();
            [
                ("velocity sign", sign),
                ("direction of motion (positive)", dir_pos),
                ("velocity", m.vel),
                ("acceleration", m.acc),
                ("position", m.pos),
            ]
            .into_iter()
            .filter_map(|(name, x)| self.decimate(&x, fs).ok().map(|d| (name.to_string(), d)))
            .collect()
        })();
        owned.into_iter().map(|(n, v)| (n, Cow::Owned(v))).collect()
    }
}
