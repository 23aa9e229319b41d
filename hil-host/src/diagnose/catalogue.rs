//! The catalogue of effects (DATA-FORMAT.md), typed: per plant one enum, each effect with its
//! catalogue name, what the data shows, and the parameters it adds with their neutral values
//! (the values at which the extended model is the baseline). The families, the generators and
//! the report take names and parameters from here; a name that is not in a plant's enum is an
//! error naming the plant's catalogue, never a silent scratch field.

use crate::log::Plant;

/// The value of an effect parameter that switches the effect off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Neutral {
    /// This value.
    Value(f64),
    /// Equal to the named baseline parameter (e.g. a second time constant equal to the first).
    SameAs(&'static str),
    /// A shape parameter without a neutral value of its own: the effect is off by its
    /// magnitude (e.g. Dahl's presliding distance when the friction level is 0).
    Shape,
}

/// One plant's catalogue.
pub trait Effect: Copy + Eq + Sized + 'static {
    /// The plant whose catalogue this is.
    const PLANT: Plant;
    /// Every effect, in catalogue order.
    const ALL: &'static [Self];
    /// The catalogue name (DATA-FORMAT.md).
    fn name(self) -> &'static str;
    /// What the data show (DATA-FORMAT.md's table).
    fn shows(self) -> &'static str;
    /// The parameters the effect adds to the baseline (the family's names) and their neutral
    /// values.
    fn params(self) -> &'static [(&'static str, Neutral)];
    /// The effect of this name, or an error naming the plant's catalogue.
    fn from_name(name: &str) -> Result<Self, String> {
        Self::ALL.iter().copied().find(|e| e.name() == name).ok_or_else(|| {
            format!(
                "`{name}` is not in the {} catalogue ({})",
                Self::PLANT.name(),
                Self::ALL.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")
            )
        })
    }
}

macro_rules! catalogue {
    ($(#[$doc:meta])* $ty:ident, $plant:expr, [$($var:ident => $name:literal, $shows:literal, [$(($p:literal, $n:expr)),*]);+ $(;)?]) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $ty {
            $(#[doc = $shows] $var),+
        }
        impl $ty {
            /// The catalogue names, in catalogue order.
            pub const NAMES: [&'static str; [$($name),+].len()] = [$($name),+];
            /// The catalogue name (usable in constants).
            pub const fn name(self) -> &'static str {
                match self {
                    $($ty::$var => $name),+
                }
            }
        }
        impl Effect for $ty {
            const PLANT: Plant = $plant;
            const ALL: &'static [Self] = &[$($ty::$var),+];
            fn name(self) -> &'static str {
                $ty::name(self)
            }
            fn shows(self) -> &'static str {
                match self {
                    $($ty::$var => $shows),+
                }
            }
            fn params(self) -> &'static [(&'static str, Neutral)] {
                match self {
                    $($ty::$var => &[$(($p, $n)),*]),+
                }
            }
        }
    };
}

catalogue!(
    /// The vacuum actuator's catalogue.
    VacuumEffect, Plant::Vacuum, [
    SupplyVoltage => "supply-voltage", "the solenoid's static map shifts with the supply voltage (the valve sees duty × U/U_ref)",
        [("voltage_gain", Neutral::Value(0.0))];
    PressureDirection => "pressure-direction", "actuator pressure rises and falls with different time constants",
        [("tau_fall_s", Neutral::SameAs("tau_rise_s"))];
    CoulombFriction => "coulomb-friction", "position lags pressure with hysteresis (Coulomb or Dahl friction on the rod)",
        [("fc_kPa", Neutral::Value(0.0)), ("dahl_x_pct", Neutral::Shape)];
    Backlash => "backlash", "a clearance in the linkage: the valve stalls while the membrane reverses",
        [("backlash_pct", Neutral::Value(0.0))];
]);

catalogue!(
    /// The EHVVA's catalogue (model-core's effect gains: 0 off, 1 the paper).
    EhvvaEffect, Plant::Ehvva, [
    Viscosity => "viscosity", "the discharge coefficient depends on fluid temperature",
        [("viscosity_gain", Neutral::Value(0.0))];
    PressureDelay => "pressure-delay", "the actuation delay depends on supply pressure",
        [("pressure_delay_gain", Neutral::Value(0.0))];
    DirectionDelay => "direction-delay", "the opening and closing delays differ",
        [("direction_delay_gain", Neutral::Value(0.0))];
    Snubber => "snubber", "the top snubber slows the valve near its seat, more with the switch valve on",
        [("snubber_gain", Neutral::Value(0.0))];
]);

catalogue!(
    /// The EVVT's catalogue.
    EvvtEffect, Plant::Evvt, [
    SupplyVoltage => "supply-voltage", "gain and pole move with battery voltage (motor torque)",
        [("alpha_rel_slope_per_V", Neutral::Value(0.0)), ("beta_rel_slope_per_V", Neutral::Value(0.0))];
    EngineSpeed => "engine-speed", "gain and pole move with engine speed",
        [("alpha_rel_slope_per_1000rpm", Neutral::Value(0.0)), ("beta_rel_slope_per_1000rpm", Neutral::Value(0.0))];
    Direction => "direction", "advancing is slower than retarding",
        [("advance_alpha_factor", Neutral::Value(1.0))];
    BeltVibration => "belt-vibration", "a periodic phase disturbance locked to crank angle",
        [("belt_order", Neutral::Shape), ("belt_cos_deg", Neutral::Value(0.0)), ("belt_sin_deg", Neutral::Value(0.0))];
]);

catalogue!(
    /// The positioner's catalogue.
    PositionerEffect, Plant::Positioner, [
    CoulombFriction => "coulomb-friction", "a constant friction force opposing the motion",
        [("Fc_N", Neutral::Value(0.0))];
    AsymmetricFriction => "asymmetric-friction", "viscous and Coulomb friction differ between the two directions of motion",
        [("Fv_pos_Ns_per_m", Neutral::SameAs("Fv_Ns_per_m")), ("Fv_neg_Ns_per_m", Neutral::SameAs("Fv_Ns_per_m")), ("Fc_pos_N", Neutral::SameAs("Fc_N")), ("Fc_neg_N", Neutral::SameAs("Fc_N"))];
]);

/// A plant's catalogue names.
pub fn names(plant: Plant) -> &'static [&'static str] {
    match plant {
        Plant::Vacuum => &VacuumEffect::NAMES,
        Plant::Ehvva => &EhvvaEffect::NAMES,
        Plant::Evvt => &EvvtEffect::NAMES,
        Plant::Positioner => &PositionerEffect::NAMES,
    }
}

/// The parameters `effect` adds, with their neutral values (empty for a name outside the
/// plant's catalogue).
pub fn params(plant: Plant, effect: &str) -> &'static [(&'static str, Neutral)] {
    fn of<E: Effect>(name: &str) -> &'static [(&'static str, Neutral)] {
        E::from_name(name).map_or(&[], |e| e.params())
    }
    match plant {
        Plant::Vacuum => of::<VacuumEffect>(effect),
        Plant::Ehvva => of::<EhvvaEffect>(effect),
        Plant::Evvt => of::<EvvtEffect>(effect),
        Plant::Positioner => of::<PositionerEffect>(effect),
    }
}

/// Is `effect` switched off in a fit (every parameter with a neutral value at it, within
/// 1e-6)? `values` are the fit's parameters by name. An extension whose effect ends off gains
/// only by refitting the rest: it is no evidence for the effect.
pub fn is_off(plant: Plant, effect: &str, values: &[(String, f64)]) -> bool {
    is_off_within(plant, effect, values, |_| None)
}

/// [`is_off`] with each parameter's 95 % half-width `ci95(name)` where the fit knows it: an
/// effect whose parameters are within their intervals of the neutral values is off (the data
/// cannot tell it from neutral), whatever its refitted model gains.
pub fn is_off_within(plant: Plant, effect: &str, values: &[(String, f64)], ci95: impl Fn(&str) -> Option<f64>) -> bool {
    let get = |n: &str| values.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
    let near = |a: f64, b: f64, ci: f64| (a - b).abs() <= (1e-6 * b.abs().max(1.0)).max(ci);
    let half = |n: &str| ci95(n).filter(|c| c.is_finite()).unwrap_or(0.0);
    let ps = params(plant, effect);
    !ps.is_empty()
        && ps.iter().all(|(name, neutral)| match neutral {
            Neutral::Shape => true,
            Neutral::Value(v) => get(name).is_some_and(|x| near(x, *v, half(name))),
            Neutral::SameAs(other) => match (get(name), get(other)) {
                (Some(x), Some(y)) => near(x, y, half(name) + half(other)),
                _ => false,
            },
        })
}

/// Checks a name against a plant's catalogue.
pub fn check(plant: Plant, name: &str) -> Result<(), String> {
    match plant {
        Plant::Vacuum => VacuumEffect::from_name(name).map(drop),
        Plant::Ehvva => EhvvaEffect::from_name(name).map(drop),
        Plant::Evvt => EvvtEffect::from_name(name).map(drop),
        Plant::Positioner => PositionerEffect::from_name(name).map(drop),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_refused_with_the_catalogue() {
        for plant in Plant::ALL {
            for n in names(plant) {
                assert!(check(plant, n).is_ok(), "{plant} {n}");
            }
        }
        assert_eq!(VacuumEffect::from_name("backlash"), Ok(VacuumEffect::Backlash));
        let e = EhvvaEffect::from_name("backlash").unwrap_err();
        assert!(
            e.contains("`backlash`") && e.contains("ehvva") && e.contains("snubber"),
            "{e}"
        );
        // Every effect adds parameters, each with a neutral value.
        assert!(VacuumEffect::ALL.iter().all(|e| !e.params().is_empty()));
        assert!(EvvtEffect::ALL.iter().all(|e| !e.shows().is_empty()));
    }

    #[test]
    fn an_effect_at_its_neutral_values_is_off() {
        let v = |pairs: &[(&str, f64)]| pairs.iter().map(|(k, x)| (k.to_string(), *x)).collect::<Vec<_>>();
        // Friction off at Fc = 0 whatever Dahl's (shape) distance; on at Fc > 0.
        assert!(is_off(
            Plant::Vacuum,
            "coulomb-friction",
            &v(&[("fc_kPa", 0.0), ("dahl_x_pct", 0.01)])
        ));
        assert!(!is_off(
            Plant::Vacuum,
            "coulomb-friction",
            &v(&[("fc_kPa", 1.6), ("dahl_x_pct", 0.3)])
        ));
        // A second time constant equal to the first is the baseline.
        assert!(is_off(
            Plant::Vacuum,
            "pressure-direction",
            &v(&[("tau_rise_s", 0.05), ("tau_fall_s", 0.05)])
        ));
        assert!(!is_off(
            Plant::Vacuum,
            "pressure-direction",
            &v(&[("tau_rise_s", 0.05), ("tau_fall_s", 0.12)])
        ));
        // A parameter missing from the fit is not taken as neutral; unknown effects are never off.
        assert!(!is_off(Plant::Ehvva, "snubber", &v(&[])));
        assert!(!is_off(Plant::Ehvva, "duty-delay", &v(&[])));
    }

    #[test]
    fn an_effect_within_its_fitted_intervals_of_neutral_is_off() {
        let v = |pairs: &[(&str, f64)]| pairs.iter().map(|(k, x)| (k.to_string(), *x)).collect::<Vec<_>>();
        // τfall/τrise = 0.99: off when the two intervals (±0.001 each) cover the difference,
        // on when they are ten times narrower.
        let taus = v(&[("tau_rise_s", 0.0500), ("tau_fall_s", 0.0495)]);
        assert!(is_off_within(Plant::Vacuum, "pressure-direction", &taus, |_| Some(
            0.001
        )));
        assert!(!is_off_within(Plant::Vacuum, "pressure-direction", &taus, |_| Some(
            0.0001
        )));
        // A value parameter: Fc = 0.02 ± 0.05 kPa is off, 1.6 ± 0.05 is not; an unknown or
        // non-finite interval falls back to 1e-6.
        let fc = |x: f64| v(&[("fc_kPa", x), ("dahl_x_pct", 0.3)]);
        assert!(is_off_within(Plant::Vacuum, "coulomb-friction", &fc(0.02), |_| Some(
            0.05
        )));
        assert!(!is_off_within(Plant::Vacuum, "coulomb-friction", &fc(1.6), |_| Some(
            0.05
        )));
        assert!(!is_off_within(Plant::Vacuum, "coulomb-friction", &fc(0.02), |_| Some(
            f64::NAN
        )));
        assert!(!is_off_within(Plant::Vacuum, "coulomb-friction", &fc(0.02), |_| None));
    }
}
