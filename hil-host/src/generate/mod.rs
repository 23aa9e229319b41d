//! Bench-like logs from the plant models with one hidden effect, for testing `diagnose`.
//!
//! Each call draws random baseline parameters, a random magnitude of the hidden effect (or no
//! effect: the control case), and writes an estimation and a validation experiment with
//! different excitation, sensor noise and quantization, in the DATA-FORMAT log format. The
//! truth (effect and parameters) is returned separately and never written into the logs.
//! Everything follows from the seed, so a failing case is replayed from the seed a test prints.

pub mod ehvva;
pub mod evvt;
pub mod positioner;
pub mod vacuum;

use crate::diagnose::catalogue;
use crate::log::{parse_log, Log, Plant};

/// SplitMix64: small, fast, and good enough for test-data generation (not cryptography).
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x5DEE_CE66_D1CE_4E5B)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.unit().max(1e-300);
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    pub fn coin(&mut self) -> bool {
        self.next_u64() & 1 == 1
    }
    /// Shuffles `v` in place (Fisher-Yates, from the last element down).
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for i in (1..v.len()).rev() {
            let j = (self.next_u64() % (i as u64 + 1)) as usize;
            v.swap(i, j);
        }
    }
}

/// Quantizes to a multiple of `lsb` (a sensor's resolution).
pub fn quantize(x: f64, lsb: f64) -> f64 {
    (x / lsb).round() * lsb
}

/// A generated case: two logs and the hidden truth.
#[derive(Clone, Debug)]
pub struct Case {
    pub plant: Plant,
    pub seed: u64,
    /// The hidden effect's catalogue name, or `none`.
    pub effect: String,
    /// The true parameters (for the record and for parameter-recovery checks).
    pub truth: Vec<(String, f64)>,
    pub estimation_csv: String,
    pub validation_csv: String,
}

impl Case {
    /// The estimation and validation logs read back through the strict reader (as
    /// `diagnose` would read the files).
    pub fn logs(&self) -> Result<(Log, Log), String> {
        let est = parse_log("estimation.csv", &self.estimation_csv, None).map_err(|e| e.to_string())?;
        let val = parse_log("validation.csv", &self.validation_csv, None).map_err(|e| e.to_string())?;
        Ok((est, val))
    }
}

/// The effects a plant's generator can hide one at a time: `none` and the plant's catalogue
/// (from the typed catalogue, [`crate::diagnose::catalogue`]).
pub fn effects(plant: Plant) -> Vec<&'static str> {
    std::iter::once("none")
        .chain(catalogue::names(plant).iter().copied())
        .collect()
}

/// Physics the generator can hide that is *not* in the catalogue (DATA-FORMAT.md): the
/// diagnosis must call it `unexplained` and never name a catalogue effect for it. Kept out of
/// the catalogue on purpose.
pub fn outside_effects(plant: Plant) -> &'static [&'static str] {
    match plant {
        // The valve acts on the commanded duty 60-150 ms late (a long pneumatic line); the
        // rod's travel ends at 72-88 % of the stroke (a linkage or flap stop).
        Plant::Vacuum => &["duty-delay", "travel-stop"],
        // The motor follows its command 30-60 ms late (driver and CAN latency); a clearance of
        // 1.5-3 crank degrees between the phaser's drive and the camshaft.
        Plant::Evvt => &["command-delay", "gear-backlash"],
        // The lift stop moves with temperature (thermal growth of the stroke, 0.1-0.2 %/°C).
        Plant::Ehvva => &["thermal-stroke"],
        // A position-dependent force (a return spring or a cable, 300-900 N/m), and a force
        // ripple periodic in position (a screw's or a motor's cogging, 8-20 N every 5-20 mm).
        Plant::Positioner => &["position-spring", "force-ripple"],
    }
}

/// Two-effect cases a plant's generator writes (`a+b`): every pair of catalogue effects
/// that do not nest (the positioner's two nest: none).
pub fn effect_pairs(plant: Plant) -> Vec<String> {
    let names = catalogue::names(plant);
    if plant == Plant::Positioner {
        return Vec::new();
    }
    let mut out = Vec::new();
    for (i, a) in names.iter().enumerate() {
        for b in &names[i + 1..] {
            out.push(format!("{a}+{b}"));
        }
    }
    out
}

/// Cases of a catalogue effect next to physics outside the catalogue (`a+o`): every catalogue
/// effect with every outside effect of the plant. The catalogue effect is to be named, and the
/// verdict to be `unexplained`.
pub fn effects_beside_outside(plant: Plant) -> Vec<String> {
    let mut out = Vec::new();
    for a in catalogue::names(plant) {
        for o in outside_effects(plant) {
            out.push(format!("{a}+{o}"));
        }
    }
    out
}

/// The parts of an effect specification: `none`, one effect, or effects joined by `+`, each
/// in the plant's catalogue or among its outside effects. Unknown names are refused by name.
pub fn parse_effects(plant: Plant, spec: &str) -> Result<Vec<&'static str>, String> {
    if spec == "none" {
        return Ok(Vec::new());
    }
    let mut out: Vec<&'static str> = Vec::new();
    for part in spec.split('+') {
        let known = catalogue::names(plant)
            .iter()
            .chain(outside_effects(plant))
            .copied()
            .find(|n| *n == part);
        match known {
            Some(n) if !out.contains(&n) => out.push(n),
            Some(n) => return Err(format!("effect `{n}` twice in `{spec}`")),
            None => {
                return Err(format!(
                    "no generator for effect `{part}` of plant `{plant}` (available: none, {}; outside the catalogue: {}; two at once as a+b)",
                    catalogue::names(plant).join(", "),
                    outside_effects(plant).join(", ")
                ))
            }
        }
    }
    Ok(out)
}

/// Generates a case for `plant` with `effect` (`none`, a catalogue name, an outside effect, or
/// several joined by `+`) from `seed`.
pub fn generate(plant: Plant, effect: &str, seed: u64) -> Result<Case, String> {
    let parts = parse_effects(plant, effect)?;
    match plant {
        Plant::Evvt => evvt::generate_effects(&parts, seed),
        Plant::Positioner => positioner::generate_effects(&parts, seed),
        Plant::Vacuum => vacuum::generate_effects(&parts, seed),
        Plant::Ehvva => ehvva::generate_effects(&parts, seed),
    }
}

/// A case whose experiments are `repeat` times the default length (each plant's programme run
/// again with new draws, or its durations multiplied): long logs for timing and memory
/// measurements. `repeat` 1 is [`generate`].
pub fn generate_repeated(plant: Plant, effect: &str, seed: u64, repeat: usize) -> Result<Case, String> {
    if repeat <= 1 {
        return generate(plant, effect, seed);
    }
    let r = repeat as f64;
    match plant {
        Plant::Positioner => positioner::generate_sized(effect, seed, 25.0 * r, 15.0 * r),
        Plant::Evvt => {
            let d = evvt::Sizes::default();
            let sizes = evvt::Sizes {
                estimation_points: d.estimation_points * repeat,
                validation_points: d.validation_points * repeat,
                ..d
            };
            evvt::generate_sized(effect, seed, &sizes)
        }
        Plant::Vacuum => vacuum::generate_sized(effect, seed, repeat, 60.0 * r),
        Plant::Ehvva => ehvva::generate_repeated(&parse_effects(plant, effect)?, seed, repeat),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rng_is_deterministic_and_roughly_uniform_and_normal() {
        let mut a = Rng::new(42);
        let mut b = Rng::new(42);
        assert_eq!(a.next_u64(), b.next_u64());
        let mut r = Rng::new(7);
        let n = 20_000;
        let mean_u = (0..n).map(|_| r.unit()).sum::<f64>() / n as f64;
        assert!((mean_u - 0.5).abs() < 0.01);
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let m = xs.iter().sum::<f64>() / n as f64;
        let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64;
        assert!(m.abs() < 0.03 && (v - 1.0).abs() < 0.05, "mean {m} var {v}");
    }

    #[test]
    fn unknown_effects_are_refused_by_name() {
        let e = generate(Plant::Positioner, "backlash", 1).unwrap_err();
        assert!(e.contains("`backlash`") && e.contains("coulomb-friction"));
        assert!(parse_effects(Plant::Vacuum, "backlash+backlash").is_err());
        assert_eq!(
            parse_effects(Plant::Vacuum, "supply-voltage+duty-delay").unwrap(),
            ["supply-voltage", "duty-delay"]
        );
        // The outside effects are no catalogue names.
        for plant in Plant::ALL {
            for o in outside_effects(plant) {
                assert!(catalogue::check(plant, o).is_err(), "{o}");
            }
        }
    }
}
