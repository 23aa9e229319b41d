//! EHVVA cases: the camless valve actuator (model-core's reduced model of eq. (12),
//! Li 2018) on a valve bench, one valve event per test condition, logged at 20 kHz.
//!
//! Each event: the valve at rest for `PRE_MS`, the pilot on for the dwell, then off until the
//! valve has seated (12 ms, 4 ms more per MPa of back pressure above 1); the model starts from rest at each event's set-points (the bench
//! waits for the accumulators between tests). Logged: the pilot command, the supply and back
//! pressures as the accumulators give them (they dip while the valve moves), the fluid
//! temperature, the two valve states and the lift.
//!
//! - Estimation: a Table 1-like matrix: the 4 × 5 grid of supply pressure (5/6/7/8 MPa) and
//!   temperature (−20/0/22/60/100 °C), each jittered, in random order, dwell 8 or 20 ms, back
//!   pressure: the 8 MPa row sweeps it as tests 12-15 do (1, 2, 3 and 4 MPa and one more
//!   between 2 and 4, shuffled over its temperatures), the other rows at 1 MPa but a quarter
//!   of their events at 2-4 MPa; lift and switch valve states at random; where the valve could not reach its lift stop, high lift becomes
//!   low lift, then the back pressure 1 MPa, then the supply pressure rises (Table 1 runs high
//!   lift from 6 MPa and high back pressure at 8 MPa only).
//! - Validation: other excitation: 24 events at conditions drawn anywhere in the ranges
//!   (5-8 MPa, −20-100 °C, back pressure 1-3.5 MPa) with dwells of 3-10 ms.
//!
//! Baseline plant: the paper's calibration with every catalogue effect off, td scaled by
//! 0.85-1.15, Cd by 0.85-1.15, τp by 0.8-1.25, moving mass 0.165-0.2 kg; and the rest of a real
//! unit (issue #12): spring rate and preload ±15 %, friction ±30 %, piston areas ±12 %, the
//! top and bottom orifices ±13 % (not all of which the diagnosis fits). The hidden effect is
//! its model-core gain (1 = the paper's magnitude) drawn in 0.6-1.5 (`snubber`: 1-2, since it
//! shows only in the last half millimetre of each closing).
//! Sensors: lift noise σ 2-6 µm on a 2 µm resolution; pressures σ 0.01 MPa on 5 kPa;
//! temperature σ 0.3 °C on 0.1 °C.

use model_core::ehvva::{EhvvaInputs, EhvvaParams, EhvvaPlant, EhvvaReduced};

use super::{quantize, Case, Rng};
use crate::diagnose::ehvva::{apply_knobs, effect_knob, reference_values, BASELINE_KNOBS, PRE_MS};
use crate::log::{format_log, Plant};

/// Log period, ms (20 kHz).
pub const DT_MS: f64 = 0.05;
/// Time after the command goes off that each event is logged, ms: enough for the valve to
/// seat (later at a higher back pressure, Fig. 10), and little more, so that the log is mostly
/// valve motion.
fn post_ms(p_back_mpa: f64) -> f64 {
    12.0 + 4.0 * (p_back_mpa - 1.0).max(0.0)
}

/// One test of the bench.
#[derive(Clone, Copy, Debug)]
pub struct Test {
    pub inputs: EhvvaInputs<f64>,
    pub dwell_ms: f64,
}

/// Draws the plant and the truth.
pub fn draw_params(effects: &[&str], rng: &mut Rng) -> Result<(EhvvaParams, Vec<(String, f64)>), String> {
    let (td0, cd0, tau0) = reference_values();
    let x = [
        td0 * rng.uniform(0.85, 1.15),
        cd0 * rng.uniform(0.85, 1.15),
        tau0 * rng.uniform(0.8, 1.25),
        rng.uniform(0.165, 0.2),
    ];
    let mut p = apply_knobs(&EhvvaParams::baseline(), &BASELINE_KNOBS, &x);
    let mut truth: Vec<(String, f64)> = BASELINE_KNOBS
        .iter()
        .zip(x)
        .map(|(k, v)| (k.name.to_string(), v))
        .collect();
    // The rest of the unit, as real units differ from the paper's (issue #12): spring rate and
    // preload ±15 %, friction ±30 %, piston areas ±12 %, orifices ±13 %. Drawn from a stream of
    // their own (the seed's other draws, the test matrix included, stay as they were).
    let mut unit = Rng::new(rng.clone().next_u64() ^ 0x0E4A_11E5);
    let mut scale = |v: &mut f64, rel: f64| *v *= unit.uniform(1.0 - rel, 1.0 + rel);
    scale(&mut p.spring_n_per_mm, 0.15);
    scale(&mut p.spring_preload_mm, 0.15);
    scale(&mut p.friction_n_per_m_s, 0.3);
    scale(&mut p.area_top_mm2, 0.12);
    scale(&mut p.area_bottom_mm2, 0.12);
    scale(&mut p.area_main_mm2, 0.13);
    scale(&mut p.area_top_orifice_mm2, 0.13);
    scale(&mut p.area_top_switch_orifice_mm2, 0.13);
    scale(&mut p.area_bottom_port_mm2, 0.13);
    truth.extend([
        ("spring_N_per_mm".to_string(), p.spring_n_per_mm),
        ("spring_preload_mm".into(), p.spring_preload_mm),
        ("friction_N_per_m_s".into(), p.friction_n_per_m_s),
        ("area_top_mm2".into(), p.area_top_mm2),
        ("area_bottom_mm2".into(), p.area_bottom_mm2),
        ("area_main_mm2".into(), p.area_main_mm2),
        ("area_top_orifice_mm2".into(), p.area_top_orifice_mm2),
        ("area_top_switch_orifice_mm2".into(), p.area_top_switch_orifice_mm2),
        ("area_bottom_port_mm2".into(), p.area_bottom_port_mm2),
    ]);
    for effect in effects
        .iter()
        .copied()
        .filter(|e| crate::diagnose::catalogue::check(Plant::Ehvva, e).is_ok())
    {
        let knob = effect_knob(effect)?;
        // The snubber shows only in the last half millimetre of each closing: drawn from the
        // paper's zone up to the model's largest (1-2), the others around the paper's 0.6-1.5.
        let gain = if effect == "snubber" {
            rng.uniform(1.0, 2.0)
        } else {
            rng.uniform(0.6, 1.5)
        };
        (knob.apply)(&mut p, gain);
        truth.push((knob.name.to_string(), gain));
    }
    Ok((p, truth))
}

/// The plant of a case from its truth (every drawn parameter, the effect gains included).
pub fn params_from_truth(truth: &[(String, f64)]) -> EhvvaParams {
    let get = |k: &str| truth.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
    let x: Vec<f64> = BASELINE_KNOBS.iter().map(|k| get(k.name).unwrap_or(f64::NAN)).collect();
    let mut p = apply_knobs(&EhvvaParams::baseline(), &BASELINE_KNOBS, &x);
    for e in crate::diagnose::ehvva::EFFECTS {
        if let Ok(k) = effect_knob(e) {
            if let Some(v) = get(k.name) {
                (k.apply)(&mut p, v);
            }
        }
    }
    apply_unit_geometry(&mut p, get);
    p
}

/// Sets the unit's spring, friction and areas that a truth.json names (the real-unit draws of
/// issue #12), leaving the others at their values in `p`.
pub fn apply_unit_geometry(p: &mut EhvvaParams, get: impl Fn(&str) -> Option<f64>) {
    let fields: [(&str, &mut f64); 9] = [
        ("spring_N_per_mm", &mut p.spring_n_per_mm),
        ("spring_preload_mm", &mut p.spring_preload_mm),
        ("friction_N_per_m_s", &mut p.friction_n_per_m_s),
        ("area_top_mm2", &mut p.area_top_mm2),
        ("area_bottom_mm2", &mut p.area_bottom_mm2),
        ("area_main_mm2", &mut p.area_main_mm2),
        ("area_top_orifice_mm2", &mut p.area_top_orifice_mm2),
        ("area_top_switch_orifice_mm2", &mut p.area_top_switch_orifice_mm2),
        ("area_bottom_port_mm2", &mut p.area_bottom_port_mm2),
    ];
    for (name, field) in fields {
        if let Some(v) = get(name) {
            *field = v;
        }
    }
}

/// Least net force that holds the valve on its lift stop, N: with less the valve floats short
/// of the stop, where its lift hangs on every force (a test a bench engineer would not run;
/// Table 1 runs high lift only from 6 MPa and high back pressure only at 8 MPa).
const STOP_MARGIN_N: f64 = 25.0;

/// Makes a test one whose valve reaches its lift stop: high lift becomes low lift, then the
/// back pressure falls to 1 MPa, then the supply pressure rises, until the net force at full
/// stroke, At·Ph − Ab·Pl − ks (ds + S) (eq. (1)), is at least `STOP_MARGIN_N`.
fn reaching_the_stop(mut t: Test) -> Test {
    let p = EhvvaParams::baseline();
    let margin = |t: &Test| {
        let s = p.stroke_mm(t.inputs.lift_high);
        p.area_top_mm2 * t.inputs.p_supply_mpa
            - p.area_bottom_mm2 * t.inputs.p_back_mpa
            - p.spring_n_per_mm * (p.spring_preload_mm + s)
    };
    if margin(&t) < STOP_MARGIN_N {
        t.inputs.lift_high = false;
    }
    if margin(&t) < STOP_MARGIN_N {
        t.inputs.p_back_mpa = t.inputs.p_back_mpa.min(1.0);
    }
    let short = STOP_MARGIN_N - margin(&t);
    if short > 0.0 {
        t.inputs.p_supply_mpa += short / p.area_top_mm2;
    }
    t
}

/// The estimation matrix (module doc).
pub fn estimation_tests(rng: &mut Rng) -> Vec<Test> {
    // Table 1's back-pressure sweep (tests 12-15: 1-4 MPa at 8 MPa supply) on the 8 MPa row,
    // from a stream of its own so that every other draw of a seed's matrix is unchanged.
    let mut sweep_rng = Rng::new(rng.clone().next_u64() ^ 0x0BAC_4E55);
    let mut sweep = [1.0, 2.0, 3.0, 4.0, sweep_rng.uniform(2.0, 4.0)];
    sweep_rng.shuffle(&mut sweep);
    let mut tests = Vec::new();
    for ph in [5.0, 6.0, 7.0, 8.0] {
        for (k, t) in [-20.0, 0.0, 22.0, 60.0, 100.0].into_iter().enumerate() {
            let drawn = if rng.unit() < 0.25 {
                [2.0, 3.0, 4.0][(rng.next_u64() % 3) as usize]
            } else {
                1.0
            };
            let pl = if ph == 8.0 { sweep[k] } else { drawn };
            tests.push(reaching_the_stop(Test {
                inputs: EhvvaInputs {
                    p_supply_mpa: ph + rng.uniform(-0.1, 0.1),
                    p_back_mpa: pl,
                    temp_c: t + rng.uniform(-2.0, 2.0),
                    lift_high: rng.coin(),
                    snubber_on: rng.coin(),
                },
                dwell_ms: if rng.coin() { 8.0 } else { 20.0 },
            }));
        }
    }
    rng.shuffle(&mut tests);
    tests
}

/// The validation tests (module doc).
pub fn validation_tests(rng: &mut Rng, count: usize) -> Vec<Test> {
    (0..count)
        .map(|_| {
            reaching_the_stop(Test {
                inputs: EhvvaInputs {
                    p_supply_mpa: rng.uniform(5.0, 8.0),
                    p_back_mpa: rng.uniform(1.0, 3.5),
                    temp_c: rng.uniform(-20.0, 100.0),
                    lift_high: rng.coin(),
                    snubber_on: rng.coin(),
                },
                dwell_ms: rng.uniform(3.0, 10.0),
            })
        })
        .collect()
}

/// Logged columns.
#[derive(Clone, Debug, Default)]
pub struct Columns {
    pub u: Vec<f64>,
    pub ph: Vec<f64>,
    pub pl: Vec<f64>,
    pub temp: Vec<f64>,
    pub high: Vec<f64>,
    pub snub: Vec<f64>,
    pub lift: Vec<f64>,
}

/// What a plant must give the bench besides the lift: the accumulator pressures.
pub trait BenchPlant: EhvvaPlant<f64> {
    fn pressures(&self) -> (f64, f64);
}
impl<const N: usize> BenchPlant for EhvvaReduced<f64, N> {
    fn pressures(&self) -> (f64, f64) {
        (self.p_high_mpa(), self.p_low_mpa())
    }
}
impl<const N: usize> BenchPlant for model_core::ehvva::EhvvaFull<f64, N> {
    fn pressures(&self) -> (f64, f64) {
        (self.p_high_mpa(), self.p_low_mpa())
    }
}

/// Sensor noise of the bench; all zero for an ideal bench.
#[derive(Clone, Copy, Debug)]
pub struct Sensors {
    pub lift_sigma_mm: f64,
    pub lift_lsb_mm: f64,
    pub p_sigma_mpa: f64,
    pub p_lsb_mpa: f64,
    pub temp_sigma_c: f64,
    pub temp_lsb_c: f64,
}

/// Runs `tests` one after another, each on a fresh plant from `make` (at rest at its
/// set-points), and logs them at `dt_ms` with `sensors`.
pub fn run_bench<P: BenchPlant>(
    tests: &[Test],
    dt_ms: f64,
    sensors: &Sensors,
    rng: &mut Rng,
    mut make: impl FnMut(&EhvvaInputs<f64>) -> Result<P, String>,
) -> Result<Columns, String> {
    let mut c = Columns::default();
    let noisy = |rng: &mut Rng, x: f64, sigma: f64, lsb: f64| {
        let v = x + sigma * rng.normal();
        if lsb > 0.0 {
            quantize(v, lsb)
        } else {
            v
        }
    };
    for t in tests {
        let mut plant = make(&t.inputs)?;
        let pre = (PRE_MS / dt_ms).round() as usize;
        let on = (t.dwell_ms / dt_ms).round() as usize;
        let post = (post_ms(t.inputs.p_back_mpa) / dt_ms).round() as usize;
        for k in 0..pre + on + post {
            let u = k >= pre && k < pre + on;
            let y = plant.step(u, &t.inputs);
            let (ph, pl) = plant.pressures();
            c.u.push(if u { 1.0 } else { 0.0 });
            c.ph.push(noisy(rng, ph, sensors.p_sigma_mpa, sensors.p_lsb_mpa).max(0.0));
            c.pl.push(noisy(rng, pl, sensors.p_sigma_mpa, sensors.p_lsb_mpa).max(0.0));
            c.temp
                .push(noisy(rng, t.inputs.temp_c, sensors.temp_sigma_c, sensors.temp_lsb_c));
            c.high.push(if t.inputs.lift_high { 1.0 } else { 0.0 });
            c.snub.push(if t.inputs.snubber_on { 1.0 } else { 0.0 });
            c.lift.push(noisy(rng, y, sensors.lift_sigma_mm, sensors.lift_lsb_mm));
        }
    }
    Ok(c)
}

/// The log text of a bench run.
pub fn log_text(source: &str, dt_ms: f64, c: &Columns) -> String {
    let t: Vec<f64> = (0..c.lift.len())
        .map(|k| (k as f64 * dt_ms * 1e4).round() / 1e7)
        .collect();
    let meta = vec![
        ("plant".to_string(), "ehvva".to_string()),
        ("source".into(), source.to_string()),
        ("sample_rate_hz".into(), format!("{}", 1e3 / dt_ms)),
    ];
    format_log(
        &meta,
        &[
            ("t_s", &t),
            ("u_pilot", &c.u),
            ("p_supply_MPa", &c.ph),
            ("p_back_MPa", &c.pl),
            ("temp_C", &c.temp),
            ("lift_high", &c.high),
            ("snubber_on", &c.snub),
            ("lift_mm", &c.lift),
        ],
    )
}

pub fn generate(effect: &str, seed: u64) -> Result<Case, String> {
    generate_effects(&super::parse_effects(Plant::Ehvva, effect)?, seed)
}

/// A case with the given hidden effects (catalogue or outside).
pub fn generate_effects(parts: &[&str], seed: u64) -> Result<Case, String> {
    generate_repeated(parts, seed, 1)
}

/// A case whose estimation matrix (20 events) and validation programme (24 events) are run
/// `repeats` times, each time with newly drawn set-points: a long bench pair (about 22 000
/// rows per repeat at 20 kHz) for timing and memory measurements.
pub fn generate_repeated(parts: &[&str], seed: u64, repeats: usize) -> Result<Case, String> {
    let repeats = repeats.max(1);
    let effect = if parts.is_empty() {
        "none".to_string()
    } else {
        parts.join("+")
    };
    let mut rng = Rng::new(seed);
    let (params, mut truth) = draw_params(parts, &mut rng)?;
    let sensors = Sensors {
        lift_sigma_mm: rng.uniform(0.002, 0.006),
        lift_lsb_mm: 0.002,
        p_sigma_mpa: 0.01,
        p_lsb_mpa: 0.005,
        temp_sigma_c: 0.3,
        temp_lsb_c: 0.1,
    };
    // Outside the catalogue: the stroke grows with fluid temperature, 0.1-0.2 %/°C about
    // 22 °C (the whole lift profile scales; re-quantized on the sensor's grid).
    let growth_per_c = if parts.contains(&"thermal-stroke") {
        let g = rng.uniform(0.001, 0.002);
        truth.push(("stroke_growth_per_C".into(), g));
        g
    } else {
        0.0
    };
    let grow = |c: &mut Columns| {
        if growth_per_c != 0.0 {
            for (y, t) in c.lift.iter_mut().zip(&c.temp) {
                *y = quantize(*y * (1.0 + growth_per_c * (t - 22.0)), sensors.lift_lsb_mm);
            }
        }
    };
    let make = |i: &EhvvaInputs<f64>| EhvvaReduced::<f64, 1024>::new(&params, i, DT_MS).map_err(|e| format!("{e:?}"));
    let mut est_tests = Vec::new();
    for _ in 0..repeats {
        est_tests.extend(estimation_tests(&mut rng));
    }
    let mut est = run_bench(&est_tests, DT_MS, &sensors, &mut rng, make)?;
    let val_tests = validation_tests(&mut rng, 24 * repeats);
    let mut val = run_bench(&val_tests, DT_MS, &sensors, &mut rng, make)?;
    grow(&mut est);
    grow(&mut val);
    Ok(Case {
        plant: Plant::Ehvva,
        seed,
        effect,
        truth,
        estimation_csv: log_text(
            &format!(
                "hil-host generate, estimation experiment (simulated valve bench, Table 1-like matrix, seed {seed})"
            ),
            DT_MS,
            &est,
        ),
        validation_csv: log_text(
            &format!("hil-host generate, validation experiment (simulated valve bench, seed {seed})"),
            DT_MS,
            &val,
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logs_read_back_and_cover_the_matrix() {
        let case = generate("none", 5).unwrap();
        let (est, val) = case.logs().expect("generated logs read back");
        assert_eq!(est.plant, Plant::Ehvva);
        assert!((est.dt_s - DT_MS * 1e-3).abs() < 1e-12);
        let ev = crate::diagnose::ehvva::Events::from_log(&est).unwrap();
        assert_eq!(ev.events.len(), 20);
        let ph: Vec<f64> = ev.events.iter().map(|e| e.inputs.p_supply_mpa).collect();
        let t: Vec<f64> = ev.events.iter().map(|e| e.inputs.temp_c).collect();
        // The set-points are read back from the rest samples within the sensor's noise.
        assert!(
            ph.iter().all(|&p| (4.85..8.15).contains(&p)) && ph.iter().any(|&p| p < 5.2) && ph.iter().any(|&p| p > 7.8)
        );
        assert!(t.iter().any(|&x| x < -15.0) && t.iter().any(|&x| x > 95.0));
        // Every event opens and seats again.
        for e in &ev.events {
            let max = e.lift_mm.iter().cloned().fold(0.0, f64::max);
            assert!(max > 3.5, "event at {} never opened", e.start);
            assert!(e.lift_mm.last().unwrap().abs() < 0.05);
        }
        assert_eq!(crate::diagnose::ehvva::Events::from_log(&val).unwrap().events.len(), 24);
        assert_ne!(case.estimation_csv, generate("none", 6).unwrap().estimation_csv);
    }

    /// The estimation log loads the bottom path and the closing against the back pressure
    /// over the validation's range on every unit: before the 8 MPa row swept it, a quarter of
    /// the events drawn at random left a unit with one event above 1 MPa (viscosity+snubber
    /// seed 24757), whose flow paths were then fitted where the back pressure barely loads them.
    #[test]
    fn every_estimation_matrix_sweeps_the_back_pressure_at_8_mpa() {
        for seed in [5, 24757, 72271] {
            let mut rng = Rng::new(seed);
            let tests = estimation_tests(&mut rng);
            let mut at_8: Vec<f64> = tests
                .iter()
                .filter(|t| t.inputs.p_supply_mpa > 7.85)
                .map(|t| t.inputs.p_back_mpa)
                .collect();
            at_8.sort_by(f64::total_cmp);
            assert_eq!(at_8.len(), 5, "seed {seed}: the 8 MPa row {at_8:?}");
            assert_eq!(&at_8[..1], &[1.0], "seed {seed}: {at_8:?}");
            for p in [2.0, 3.0, 4.0] {
                assert!(at_8.contains(&p), "seed {seed}: no {p} MPa in the 8 MPa row {at_8:?}");
            }
            assert!((2.0..=4.0).contains(&at_8[2]), "seed {seed}: {at_8:?}");
        }
        // Read back from a generated log: the set-points as the bench logs them.
        let case = generate("none", 24757).unwrap();
        let (est, _) = case.logs().unwrap();
        let ev = crate::diagnose::ehvva::Events::from_log(&est).unwrap();
        let loaded = ev.events.iter().filter(|e| e.inputs.p_back_mpa > 1.9).count();
        assert!(loaded >= 4, "{loaded} events above 1.9 MPa back pressure");
        assert!(ev.events.iter().any(|e| e.inputs.p_back_mpa > 3.9));
    }
}
