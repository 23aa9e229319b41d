//! The vacuum family's model: the valve and actuator parameters the fits move (which map shapes,
//! which effects), their names and bounds, and how a parameter vector sets model-core's
//! `VacuumValveActuator`.

use model_core::vacuum::{
    PositionMap, StaticPressureMap, VacuumEffects, VacuumInputs, VacuumParams, VacuumValveActuator,
};

use std::ops::Range;

use super::Inputs;
use crate::diagnose::catalogue::{Effect, Neutral, VacuumEffect};

/// Shape of the duty-to-pressure map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValveMap {
    /// Eq. (2): min(k1·u + p01, k2·u + p02).
    PiecewiseLinear,
    /// Eq. (5): min(k1·u + p01, p_amb + k3·max(0, u − u0)³).
    Cubic,
}

/// Shape of the pressure-to-position map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RodMap {
    /// Eq. (8).
    Linear,
    /// Eq. (9).
    Arctan,
}

/// One valve + actuator model of the family, flat f64 (only the fields of its shapes and
/// effects are used).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumModel {
    pub valve_map: ValveMap,
    pub rod_map: RodMap,
    pub k1_kpa_per_pct: f64,
    pub p01_kpa: f64,
    pub k2_kpa_per_pct: f64,
    pub p02_kpa: f64,
    pub k3_kpa_per_pct3: f64,
    pub u0_pct: f64,
    pub lin_k_pct_per_kpa: f64,
    pub lin_x0_pct: f64,
    pub a1_pct: f64,
    pub a2_pct_per_rad: f64,
    pub a3_kpa: f64,
    pub a4_kpa: f64,
    pub tau_rise_s: f64,
    pub tau_fall_s: f64,
    pub mass_kpa_s2_per_pct: f64,
    pub damping_extend_kpa_s_per_pct: f64,
    pub damping_retract_kpa_s_per_pct: f64,
    /// κ of the `supply-voltage` extension (1 = eq. (1)).
    pub voltage_gain: f64,
    pub fc_kpa: f64,
    /// Dahl presliding distance Fc/σ.
    pub dahl_x_pct: f64,
    pub backlash_pct: f64,
    /// A transport delay of the duty command, s: physics outside the catalogue, fitted only by
    /// the `duty-delay` probe (0 in every catalogue model).
    pub duty_delay_s: f64,
    /// Where the rod's measured travel ends inside the model's stroke, %: a linkage or valve
    /// stop, or a position sensor at the end of its range. Physics outside the catalogue,
    /// fitted only by the `travel-stop` probe (±∞ in every catalogue model: no stop).
    pub x_stop_low_pct: f64,
    pub x_stop_high_pct: f64,
    pub u_ref_v: f64,
    pub p_amb_ref_kpa: f64,
    pub effects: VacuumEffects,
}

impl VacuumModel {
    /// The model of a model-core parameter set (the generator's truth).
    pub fn from_params(p: &VacuumParams) -> Self {
        let mut m = Self::baseline_guess(ValveMap::PiecewiseLinear, RodMap::Linear);
        match p.static_map {
            StaticPressureMap::PiecewiseLinear {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct,
                p02_kpa,
            } => {
                m.valve_map = ValveMap::PiecewiseLinear;
                (m.k1_kpa_per_pct, m.p01_kpa, m.k2_kpa_per_pct, m.p02_kpa) =
                    (k1_kpa_per_pct, p01_kpa, k2_kpa_per_pct, p02_kpa);
            }
            StaticPressureMap::Cubic {
                k1_kpa_per_pct,
                p01_kpa,
                k2_kpa_per_pct3,
                u0_pct,
            } => {
                m.valve_map = ValveMap::Cubic;
                (m.k1_kpa_per_pct, m.p01_kpa, m.k3_kpa_per_pct3, m.u0_pct) =
                    (k1_kpa_per_pct, p01_kpa, k2_kpa_per_pct3, u0_pct);
            }
        }
        match p.position_map {
            PositionMap::Linear { k_pct_per_kpa, x0_pct } => {
                m.rod_map = RodMap::Linear;
                (m.lin_k_pct_per_kpa, m.lin_x0_pct) = (k_pct_per_kpa, x0_pct);
            }
            PositionMap::Arctan {
                a1_pct,
                a2_pct_per_rad,
                a3_kpa,
                a4_kpa,
            } => {
                m.rod_map = RodMap::Arctan;
                (m.a1_pct, m.a2_pct_per_rad, m.a3_kpa, m.a4_kpa) = (a1_pct, a2_pct_per_rad, a3_kpa, a4_kpa);
            }
        }
        m.tau_rise_s = p.tau_rise_s;
        m.tau_fall_s = p.tau_fall_s;
        m.mass_kpa_s2_per_pct = p.mass_kpa_s2_per_pct;
        m.damping_extend_kpa_s_per_pct = p.damping_extend_kpa_s_per_pct;
        m.damping_retract_kpa_s_per_pct = p.damping_retract_kpa_s_per_pct;
        m.voltage_gain = 1.0;
        m.fc_kpa = p.fc_kpa;
        m.dahl_x_pct = if p.dahl_sigma_kpa_per_pct > 0.0 {
            p.fc_kpa / p.dahl_sigma_kpa_per_pct
        } else {
            0.5
        };
        m.backlash_pct = p.backlash_pct;
        m.u_ref_v = p.u_ref_v;
        m.p_amb_ref_kpa = p.p_amb_ref_kpa;
        m.effects = p.effects;
        m
    }

    /// Generic starting values (the paper's LPT/HPT/HPC ranges), all effects off.
    pub fn baseline_guess(valve_map: ValveMap, rod_map: RodMap) -> Self {
        Self {
            valve_map,
            rod_map,
            k1_kpa_per_pct: -0.4,
            p01_kpa: 107.0,
            k2_kpa_per_pct: -1.0,
            p02_kpa: 122.0,
            k3_kpa_per_pct3: -3.2e-4,
            u0_pct: 40.0,
            lin_k_pct_per_kpa: -2.0,
            lin_x0_pct: 180.0,
            a1_pct: 50.0,
            a2_pct_per_rad: 40.0,
            a3_kpa: 66.0,
            a4_kpa: 8.0,
            tau_rise_s: 0.05,
            tau_fall_s: 0.05,
            mass_kpa_s2_per_pct: 1.5e-4,
            damping_extend_kpa_s_per_pct: 0.01,
            damping_retract_kpa_s_per_pct: 0.02,
            voltage_gain: 0.0,
            fc_kpa: 0.0,
            dahl_x_pct: 0.3,
            backlash_pct: 0.0,
            duty_delay_s: 0.0,
            x_stop_low_pct: f64::NEG_INFINITY,
            x_stop_high_pct: f64::INFINITY,
            u_ref_v: 12.0,
            p_amb_ref_kpa: 100.0,
            effects: VacuumEffects::NONE,
        }
    }

    /// The model-core parameters of this model: the fields of its map shapes and effects. The
    /// leakage, chamber volumes and temperature only set the flows to the tank, which the fit
    /// does not use: the LPT preset's. Dahl's σ is Fc/`dahl_x_pct` (any valid value without
    /// friction). κ is not a model-core parameter: it enters through [`Self::inputs_at`].
    pub fn to_params(&self) -> VacuumParams {
        VacuumParams {
            u_ref_v: self.u_ref_v,
            static_map: match self.valve_map {
                ValveMap::PiecewiseLinear => StaticPressureMap::PiecewiseLinear {
                    k1_kpa_per_pct: self.k1_kpa_per_pct,
                    p01_kpa: self.p01_kpa,
                    k2_kpa_per_pct: self.k2_kpa_per_pct,
                    p02_kpa: self.p02_kpa,
                },
                ValveMap::Cubic => StaticPressureMap::Cubic {
                    k1_kpa_per_pct: self.k1_kpa_per_pct,
                    p01_kpa: self.p01_kpa,
                    k2_kpa_per_pct3: self.k3_kpa_per_pct3,
                    u0_pct: self.u0_pct,
                },
            },
            tau_rise_s: self.tau_rise_s,
            tau_fall_s: self.tau_fall_s,
            position_map: match self.rod_map {
                RodMap::Linear => PositionMap::Linear {
                    k_pct_per_kpa: self.lin_k_pct_per_kpa,
                    x0_pct: self.lin_x0_pct,
                },
                RodMap::Arctan => PositionMap::Arctan {
                    a1_pct: self.a1_pct,
                    a2_pct_per_rad: self.a2_pct_per_rad,
                    a3_kpa: self.a3_kpa,
                    a4_kpa: self.a4_kpa,
                },
            },
            p_amb_ref_kpa: self.p_amb_ref_kpa,
            mass_kpa_s2_per_pct: self.mass_kpa_s2_per_pct,
            damping_extend_kpa_s_per_pct: self.damping_extend_kpa_s_per_pct,
            damping_retract_kpa_s_per_pct: self.damping_retract_kpa_s_per_pct,
            fc_kpa: self.fc_kpa,
            dahl_sigma_kpa_per_pct: if self.fc_kpa > 0.0 {
                self.fc_kpa / self.dahl_x_pct.max(1e-9)
            } else {
                1.0
            },
            backlash_pct: self.backlash_pct,
            effects: self.effects,
            ..VacuumParams::lpt()
        }
    }

    /// The model-core actuator of this model, its rod integrated in steps of at most
    /// `rod_step_s`; an error names the parameter model-core rejects.
    pub fn actuator(&self, rod_step_s: f64) -> Result<VacuumValveActuator<f64>, String> {
        let invalid = |e: model_core::vacuum::VacuumParamError| format!("vacuum model: {e:?}");
        VacuumValveActuator::new(&self.to_params())
            .and_then(|a| a.with_rod_step_s(rod_step_s))
            .map_err(invalid)
    }

    /// The actuator's inputs at sample `k`. With `supply-voltage`, model-core's valve sees
    /// duty·U/U_ref (eq. (1)); the fitted κ (duty·(1 + κ(U/U_ref − 1)), κ = 1 being eq. (1) and
    /// κ = 0 the baseline) is the voltage the valve sees moved κ times as far from U_ref:
    /// U_ref + κ(U − U_ref).
    pub fn inputs_at(&self, io: &Inputs, k: usize) -> VacuumInputs<f64> {
        let u_batt_v = if self.effects.supply_voltage {
            self.u_ref_v + self.voltage_gain * (io.u_batt[k] - self.u_ref_v)
        } else {
            io.u_batt[k]
        };
        VacuumInputs {
            duty_pct: self.duty_at(io, k),
            u_batt_v,
            p_amb_kpa: io.p_amb[k],
            p_tank_kpa: io.p_tank[k],
        }
    }

    /// The duty the valve acts on at sample `k`: the logged one, or with a duty delay the one
    /// `duty_delay_s` earlier, linear between samples (the first sample before the log).
    fn duty_at(&self, io: &Inputs, k: usize) -> f64 {
        if self.duty_delay_s <= 0.0 {
            return io.duty[k];
        }
        let back = self.duty_delay_s / io.dt_s;
        let t = k as f64 - back;
        if t <= 0.0 {
            return io.duty[0];
        }
        let i = t.floor() as usize;
        let w = t - i as f64;
        let next = io.duty[(i + 1).min(k)];
        io.duty[i] + w * (next - io.duty[i])
    }

    /// The parameters a fit of this model's shapes and `effects` adjusts.
    pub fn parameter_names(&self, effects: &[&str]) -> Result<Vec<&'static str>, String> {
        let mut names = match self.valve_map {
            ValveMap::PiecewiseLinear => vec!["k1_kPa_per_pct", "p01_kPa", "k2_kPa_per_pct", "p02_kPa"],
            ValveMap::Cubic => vec!["k1_kPa_per_pct", "p01_kPa", "k3_kPa_per_pct3", "u0_pct"],
        };
        names.push("tau_rise_s");
        names.extend(self.rod_names().into_iter().filter(|n| !n.is_empty()));
        names.extend([
            "mass_kPa_s2_per_pct",
            "damping_extend_kPa_s_per_pct",
            "damping_retract_kPa_s_per_pct",
        ]);
        for e in effects {
            names.extend(effect_names(e)?);
        }
        Ok(names)
    }

    fn rod_names(&self) -> [&'static str; 4] {
        match self.rod_map {
            RodMap::Linear => ["lin_k_pct_per_kPa", "lin_x0_pct", "", ""],
            RodMap::Arctan => ["a1_pct", "a2_pct_per_rad", "a3_kPa", "a4_kPa"],
        }
    }

    fn field(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "k1_kPa_per_pct" => &mut self.k1_kpa_per_pct,
            "p01_kPa" => &mut self.p01_kpa,
            "k2_kPa_per_pct" => &mut self.k2_kpa_per_pct,
            "p02_kPa" => &mut self.p02_kpa,
            "k3_kPa_per_pct3" => &mut self.k3_kpa_per_pct3,
            "u0_pct" => &mut self.u0_pct,
            "tau_rise_s" => &mut self.tau_rise_s,
            "tau_fall_s" => &mut self.tau_fall_s,
            "lin_k_pct_per_kPa" => &mut self.lin_k_pct_per_kpa,
            "lin_x0_pct" => &mut self.lin_x0_pct,
            "a1_pct" => &mut self.a1_pct,
            "a2_pct_per_rad" => &mut self.a2_pct_per_rad,
            "a3_kPa" => &mut self.a3_kpa,
            "a4_kPa" => &mut self.a4_kpa,
            "mass_kPa_s2_per_pct" => &mut self.mass_kpa_s2_per_pct,
            "damping_extend_kPa_s_per_pct" => &mut self.damping_extend_kpa_s_per_pct,
            "damping_retract_kPa_s_per_pct" => &mut self.damping_retract_kpa_s_per_pct,
            "voltage_gain" => &mut self.voltage_gain,
            "fc_kPa" => &mut self.fc_kpa,
            "dahl_x_pct" => &mut self.dahl_x_pct,
            "backlash_pct" => &mut self.backlash_pct,
            "duty_delay_s" => &mut self.duty_delay_s,
            "x_stop_low_pct" => &mut self.x_stop_low_pct,
            "x_stop_high_pct" => &mut self.x_stop_high_pct,
            // Names come from `parameter_names`: an unknown one is no field.
            _ => return None,
        })
    }

    /// The parameter of this name (NaN for a name that is none of the model's: a solver start
    /// at NaN is refused by name).
    pub fn get(&self, name: &str) -> f64 {
        let mut m = *self;
        m.field(name).map_or(f64::NAN, |v| *v)
    }

    /// Sets the parameter of this name; an unknown name is an error naming it.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), String> {
        *self
            .field(name)
            .ok_or_else(|| format!("`{name}` is no parameter of the vacuum model"))? = value;
        Ok(())
    }

    /// The model with `effect` switched on at its starting magnitude.
    pub fn with_effect(&self, effect: &str) -> Result<Self, String> {
        let mut m = *self;
        match VacuumEffect::from_name(effect)? {
            VacuumEffect::SupplyVoltage => {
                m.effects.supply_voltage = true;
                m.voltage_gain = 1.0;
            }
            VacuumEffect::PressureDirection => {
                m.effects.pressure_direction = true;
                m.tau_fall_s = m.tau_rise_s;
            }
            VacuumEffect::CoulombFriction => {
                m.effects.coulomb_friction = true;
                m.fc_kpa = 2.0;
                m.dahl_x_pct = 0.3;
            }
            VacuumEffect::Backlash => {
                m.effects.backlash = true;
                m.backlash_pct = 4.0;
            }
        }
        Ok(m)
    }

    /// The model with `effect` switched on at its neutral value (the model unchanged): the
    /// start from which an extension cannot end above the model it extends.
    pub fn with_effect_neutral(&self, effect: &str) -> Result<Self, String> {
        let e = VacuumEffect::from_name(effect)?;
        let mut m = self.with_effect(effect)?;
        for (name, neutral) in e.params() {
            // A shape parameter (Dahl's presliding distance) has no neutral of its own.
            let v = match neutral {
                Neutral::Value(v) => *v,
                Neutral::SameAs(other) => m.get(other),
                Neutral::Shape => continue,
            };
            m.set(name, v)?;
        }
        Ok(m)
    }

    /// Simulates samples `range` of `io` from the steady state of the range's first inputs, the
    /// rod integrated in steps of at most `h_max_s`. Sample k holds the state before the step
    /// with inputs k (a bench samples the sensors as it applies the new command).
    /// With `mechanics` false only the pressure is simulated (x stays at its settled value).
    pub fn simulate(
        &self,
        io: &Inputs,
        range: Range<usize>,
        h_max_s: f64,
        mechanics: bool,
        x_out: &mut [f64],
        p_out: &mut [f64],
    ) -> Result<(), String> {
        let Some(k0) = range.clone().next() else { return Ok(()) };
        let mut a = self.actuator(h_max_s)?;
        a.settle(&self.inputs_at(io, k0));
        for (i, k) in range.enumerate() {
            // The stops limit what the position shows; with none (±∞) the value is unchanged
            // (`max`/`min`, not `clamp`, which panics on crossed bounds).
            x_out[i] = a.x_pct().max(self.x_stop_low_pct).min(self.x_stop_high_pct);
            p_out[i] = a.p_act_kpa();
            let inputs = self.inputs_at(io, k);
            if mechanics {
                a.advance(&inputs, io.dt_s);
            } else {
                a.advance_pressure(&inputs, io.dt_s);
            }
        }
        Ok(())
    }

    /// Named parameters for a report.
    pub fn named(&self, names: &[&'static str]) -> Vec<(String, f64)> {
        names.iter().map(|n| (n.to_string(), self.get(n))).collect()
    }
}

/// The parameters an effect adds: the catalogue's.
pub(super) fn effect_names(effect: &str) -> Result<Vec<&'static str>, String> {
    Ok(VacuumEffect::from_name(effect)?
        .params()
        .iter()
        .map(|(n, _)| *n)
        .collect())
}

/// The longest duty delay the `duty-delay` probe fits, s.
pub(super) const DUTY_DELAY_MAX_S: f64 = 0.5;

/// Bounds of each parameter: physical signs and generous ranges around the paper's actuators.
pub(super) fn bounds(name: &str) -> (f64, f64) {
    match name {
        "k1_kPa_per_pct" => (-10.0, -0.01),
        "p01_kPa" => (40.0, 1000.0),
        "k2_kPa_per_pct" => (-10.0, -0.01),
        "p02_kPa" => (40.0, 1000.0),
        "k3_kPa_per_pct3" => (-0.05, -1e-7),
        "u0_pct" => (0.0, 95.0),
        "tau_rise_s" | "tau_fall_s" => (0.003, 2.0),
        "lin_k_pct_per_kPa" => (-50.0, -0.05),
        "lin_x0_pct" => (-2000.0, 5000.0),
        "a1_pct" => (-50.0, 150.0),
        "a2_pct_per_rad" => (5.0, 500.0),
        "a3_kPa" => (0.0, 200.0),
        "a4_kPa" => (0.3, 500.0),
        "mass_kPa_s2_per_pct" => (1e-6, 5e-3),
        "damping_extend_kPa_s_per_pct" | "damping_retract_kPa_s_per_pct" => (1e-4, 1.0),
        "voltage_gain" => (-1.0, 3.0),
        "fc_kPa" => (0.0, 30.0),
        "dahl_x_pct" => (0.01, 10.0),
        "backlash_pct" => (0.0, 40.0),
        "duty_delay_s" => (0.0, DUTY_DELAY_MAX_S),
        // A stop inside the stroke: the lower one in its lower part, the upper one in its
        // upper part, each free to sit on its end (the columns' range is -5..105 %).
        "x_stop_low_pct" => (-5.0, 60.0),
        "x_stop_high_pct" => (40.0, 105.0),
        _ => (f64::NEG_INFINITY, f64::INFINITY),
    }
}
