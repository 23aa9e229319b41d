//! The fitted parameters of the EHVVA family ([`Knob`]s): the paper's four, the unit's own and
//! each catalogue effect's gain, and how each sets model-core's [`EhvvaParams`].

use model_core::ehvva::{EhvvaParams, EhvvaTables};

use super::{Effect, EhvvaEffect};

/// A fitted parameter: its name, bounds and how it sets the model's parameters.
#[derive(Clone, Copy, Debug)]
pub struct Knob {
    pub name: &'static str,
    pub lo: f64,
    pub hi: f64,
    pub apply: fn(&mut EhvvaParams, f64),
}

/// td at 7 MPa, 22 °C (mean of VO and VC), Cd at 22 °C and τp at 6.5 MPa, 22 °C of the paper's
/// tables: the values the baseline knobs scale.
pub fn reference_values() -> (f64, f64, f64) {
    let p = EhvvaParams::baseline();
    let t = EhvvaTables::<f64>::new(&p).expect("the paper's parameters are valid");
    (t.t_delay_ms(7.0, 22.0, true), t.cd(22.0), t.tau_p_ms(6.5, 22.0))
}

pub(super) fn scale_td(p: &mut EhvvaParams, td_ms: f64) {
    let base = EhvvaParams::baseline().tables;
    let s = td_ms / reference_values().0;
    for i in 0..4 {
        for j in 0..5 {
            p.tables.td_open_ms[i][j] = base.td_open_ms[i][j] * s;
            p.tables.td_close_ms[i][j] = base.td_close_ms[i][j] * s;
        }
    }
}
fn scale_cd(p: &mut EhvvaParams, cd: f64) {
    let base = EhvvaParams::baseline().tables;
    let s = cd / reference_values().1;
    for i in 0..4 {
        p.tables.cd[i] = (base.cd[i] * s).min(0.99);
    }
}
fn scale_tau(p: &mut EhvvaParams, tau_ms: f64) {
    let base = EhvvaParams::baseline().tables;
    let s = tau_ms / reference_values().2;
    for i in 0..2 {
        for j in 0..3 {
            p.tables.tau_ms[i][j] = base.tau_ms[i][j] * s;
        }
    }
}

/// The top snubber's fixed orifice and notch areas together, relative to the paper's: how
/// freely the oil leaves the top chamber on closing outside the snubbing zone, with the notch
/// that the `snubber` effect covers keeping its share (so the effect keeps its strength
/// relative to the unit's path). Applied before the switch orifice, which is its own knob.
fn scale_top_snubber_path(p: &mut EhvvaParams, scale: f64) {
    let base = EhvvaParams::baseline();
    p.area_top_orifice_mm2 = base.area_top_orifice_mm2 * scale;
    p.area_top_notch_mm2 = base.area_top_notch_mm2 * scale;
}

/// The bottom port and notch areas together, relative to the paper's (the notch's own shape
/// over its zone is kept): one unit's bottom flow path.
fn scale_bottom_path(p: &mut EhvvaParams, scale: f64) {
    let base = EhvvaParams::baseline();
    p.area_bottom_port_mm2 = base.area_bottom_port_mm2 * scale;
    p.area_bottom_notch_mm2 = base.area_bottom_notch_mm2 * scale;
    p.area_bottom_min_mm2 = base.area_bottom_min_mm2 * scale;
}

/// How much of the paper's temperature trend of td (Fig. 4: longer when cold) the unit has:
/// 0 a delay that does not depend on the oil temperature, 1 the paper's. Each column of the
/// (already scaled) tables moves toward the 22 °C column, so td at 22 °C stays the td knob's.
fn scale_td_temperature(p: &mut EhvvaParams, gain: f64) {
    const J_22C: usize = 2;
    for table in [&mut p.tables.td_open_ms, &mut p.tables.td_close_ms] {
        for row in table.iter_mut() {
            let at_22c = row[J_22C];
            for v in row.iter_mut() {
                *v = at_22c + gain * (*v - at_22c);
            }
        }
    }
}

/// Index of Cd among [`BASELINE_KNOBS`].
pub(super) const CD: usize = 1;

/// Knobs of the baseline (module doc).
pub const BASELINE_KNOBS: [Knob; 4] = [
    Knob {
        name: "td_ms_at_7MPa_22C",
        lo: 1.0,
        hi: 7.0,
        apply: scale_td,
    },
    Knob {
        name: "cd_at_22C",
        lo: 0.1,
        hi: 0.9,
        apply: scale_cd,
    },
    Knob {
        name: "tau_p_ms_at_6p5MPa_22C",
        lo: 0.02,
        hi: 0.5,
        apply: scale_tau,
    },
    Knob {
        name: "mass_kg",
        lo: 0.02,
        hi: 0.6,
        apply: |p, v| p.mass_kg = v,
    },
];

/// What varies from unit to unit beyond the four knobs of the paper's calibration: spring rate
/// and preload, friction, the bottom piston area, every flow path (main valve, the top
/// snubber's path, its switch orifice, the bottom port and notch) and how much of the paper's
/// temperature trend the delay has. The diagnosis fits them all with the baseline, from the
/// four knobs' optimum, and reports from the confidence intervals what the data cannot
/// identify. Bounds are wide: a valve of another design (a spring three times stiffer with a
/// quarter of the preload, a bottom area six times the paper's, a delay that does not depend
/// on temperature) is a unit too, and a bound that excludes it leaves every effect smaller
/// than the baseline's error.
///
/// The piston top area At is not among them: the reduced model is invariant to scaling the
/// moving mass, both piston areas, the spring, the friction and Cd by one factor (every force
/// of eq. (13) and the orifice losses ρ At³/(2 Cd² Aorit²) L'² scale alike, the chamber
/// pressure does not depend on them), so lift data cannot see that scale. At is held at the
/// paper's value as the reference and reported as not identifiable; the fitted mass, areas,
/// spring and friction are the unit's relative to it. With every flow path free, Cd is held
/// at the paper's value too (the losses see Cd·A only), and the areas are the unit's at it.
pub const UNIT_KNOBS: [Knob; 9] = [
    Knob {
        name: "td_temperature_gain",
        lo: 0.0,
        hi: 2.0,
        apply: scale_td_temperature,
    },
    Knob {
        name: "spring_N_per_mm",
        lo: 2.0,
        hi: 60.0,
        apply: |p, v| p.spring_n_per_mm = v,
    },
    Knob {
        name: "spring_preload_mm",
        lo: 2.0,
        hi: 60.0,
        apply: |p, v| p.spring_preload_mm = v,
    },
    Knob {
        name: "friction_N_per_m_s",
        lo: 0.0,
        hi: 100.0,
        apply: |p, v| p.friction_n_per_m_s = v,
    },
    Knob {
        name: "area_bottom_mm2",
        lo: 1.0,
        hi: 48.0,
        apply: |p, v| p.area_bottom_mm2 = v,
    },
    Knob {
        name: "area_main_mm2",
        lo: 2.0,
        hi: 40.0,
        apply: |p, v| p.area_main_mm2 = v,
    },
    Knob {
        name: "top_snubber_path_scale",
        lo: 0.05,
        hi: 30.0,
        apply: scale_top_snubber_path,
    },
    Knob {
        name: "area_top_switch_orifice_mm2",
        lo: 0.05,
        hi: 20.0,
        apply: |p, v| p.area_top_switch_orifice_mm2 = v,
    },
    Knob {
        name: "bottom_path_scale",
        lo: 0.1,
        hi: 30.0,
        apply: scale_bottom_path,
    },
];

/// The paper's value of a unit knob.
pub(super) fn unit_nominal(k: &Knob) -> f64 {
    let p = EhvvaParams::baseline();
    match k.name {
        "spring_N_per_mm" => p.spring_n_per_mm,
        "spring_preload_mm" => p.spring_preload_mm,
        "friction_N_per_m_s" => p.friction_n_per_m_s,
        "area_main_mm2" => p.area_main_mm2,
        "top_snubber_path_scale" => 1.0,
        "area_top_switch_orifice_mm2" => p.area_top_switch_orifice_mm2,
        "bottom_path_scale" => 1.0,
        "td_temperature_gain" => 1.0,
        _ => p.area_bottom_mm2,
    }
}

/// The knob each catalogue effect adds: its model-core gain, 0 (neutral, the baseline) to 2
/// (1 = the paper).
pub fn effect_knob(effect: &str) -> Result<Knob, String> {
    let e = EhvvaEffect::from_name(effect)?;
    let apply: fn(&mut EhvvaParams, f64) = match e {
        EhvvaEffect::Viscosity => |p, v| p.effect_viscosity = v,
        EhvvaEffect::PressureDelay => |p, v| p.effect_pressure_delay = v,
        EhvvaEffect::DirectionDelay => |p, v| p.effect_direction_delay = v,
        EhvvaEffect::Snubber => |p, v| p.effect_snubber = v,
    };
    // The snubbing zone is the paper's Ls1 (0.486 mm) times the gain: a unit's undercut may be
    // several times longer (up to ~3 mm, still inside the low lift's 4 mm stroke).
    let hi = if e == EhvvaEffect::Snubber { 6.0 } else { 2.0 };
    Ok(Knob {
        name: e.params()[0].0,
        lo: 0.0,
        hi,
        apply,
    })
}

/// The temperature about which [`LIFT_SCALE_KNOB`] scales the lift: the paper's reference
/// (Cd, td and τp are given at 22 °C).
pub const LIFT_SCALE_REFERENCE_C: f64 = 22.0;

/// The probe's knob for a lift that scales with the fluid temperature (outside the catalogue:
/// a stroke that grows with the actuator's temperature, or the lift sensor's gain drifting
/// with it): the simulated lift of each event is multiplied by 1 + k (T − 22 °C), k per °C.
/// It is no parameter of the valve ([`EhvvaParams`] does not change): the simulation's
/// callers apply it to the simulated lift ([`scale_lift_with_temperature`]). ±1 %/°C is ±60 %
/// over the paper's −20..100 °C.
pub const LIFT_SCALE_KNOB: Knob = Knob {
    name: "lift_scale_per_C",
    lo: -0.01,
    hi: 0.01,
    apply: |_, _| {},
};

/// The value of [`LIFT_SCALE_KNOB`] among `knobs` set to `x` (0, the lift as simulated, where
/// it is not among them).
pub fn lift_scale_per_c(knobs: &[Knob], x: &[f64]) -> f64 {
    knobs
        .iter()
        .zip(x)
        .find(|(k, _)| k.name == LIFT_SCALE_KNOB.name)
        .map_or(0.0, |(_, v)| *v)
}

/// Multiplies each event's simulated lift in `out` (the log's samples, as
/// [`super::simulate_all_on`] writes them) by 1 + `per_c` (T − 22 °C) at the event's mean
/// temperature ([`LIFT_SCALE_KNOB`]).
pub fn scale_lift_with_temperature(set: &super::Events, out: &mut [f64], per_c: f64) {
    if per_c == 0.0 {
        return;
    }
    for ev in &set.events {
        let scale = 1.0 + per_c * (ev.inputs.temp_c - LIFT_SCALE_REFERENCE_C);
        for y in &mut out[ev.start..ev.start + ev.lift_mm.len()] {
            *y *= scale;
        }
    }
}

/// `set` with each event's measured lift divided by 1 + `per_c` (T − 22 °C): the lift the
/// valve would show without [`LIFT_SCALE_KNOB`]'s scale.
pub fn with_lift_unscaled(set: &super::Events, per_c: f64) -> super::Events {
    let mut out = set.clone();
    for ev in &mut out.events {
        let scale = 1.0 + per_c * (ev.inputs.temp_c - LIFT_SCALE_REFERENCE_C);
        for y in &mut ev.lift_mm {
            *y /= scale;
        }
    }
    out
}

/// `base` with the knobs set to `x`.
pub fn apply_knobs(base: &EhvvaParams, knobs: &[Knob], x: &[f64]) -> EhvvaParams {
    let mut p = *base;
    for (k, &v) in knobs.iter().zip(x) {
        (k.apply)(&mut p, v);
    }
    p
}

/// The valve a fit describes, from its parameter vector ([`super::Fit::internal`]: knob names
/// and values in the order the fit applied them) on [`EhvvaParams::baseline`] (catalogue
/// effects the fit did not add stay off; a probe's [`LIFT_SCALE_KNOB`] is no parameter of the
/// valve and changes nothing). An unknown name is refused.
pub fn params_from_fit(internal: &[(String, f64)]) -> Result<EhvvaParams, String> {
    let mut p = EhvvaParams::baseline();
    for (name, v) in internal {
        let knob = BASELINE_KNOBS
            .iter()
            .chain(&UNIT_KNOBS)
            .copied()
            .chain(EhvvaEffect::NAMES.iter().filter_map(|e| effect_knob(e).ok()))
            .chain([LIFT_SCALE_KNOB])
            .find(|k| k.name == name.as_str())
            .ok_or_else(|| format!("EHVVA fit: no parameter named `{name}`"))?;
        (knob.apply)(&mut p, *v);
    }
    Ok(p)
}
