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

/// The effects a plant's generator can hide (its catalogue plus `none`).
pub fn effects(plant: Plant) -> &'static [&'static str] {
    match plant {
        Plant::Evvt => &["none", "supply-voltage", "engine-speed", "direction", "belt-vibration"],
        Plant::Positioner => &["none", "coulomb-friction", "asymmetric-friction"],
        Plant::Vacuum => &[
            "none",
            "supply-voltage",
            "pressure-direction",
            "coulomb-friction",
            "backlash",
        ],
        Plant::Ehvva => &["none", "viscosity", "pressure-delay", "direction-delay", "snubber"],
    }
}

/// Generates a case for `plant` with `effect` (a catalogue name or `none`) from `seed`.
pub fn generate(plant: Plant, effect: &str, seed: u64) -> Result<Case, String> {
    if !effects(plant).contains(&effect) {
        return Err(format!(
            "no generator for effect `{effect}` of plant `{plant}` (available: {})",
            effects(plant).join(", ")
        ));
    }
    match plant {
        Plant::Evvt => evvt::generate(effect, seed),
        Plant::Positioner => positioner::generate(effect, seed),
        Plant::Vacuum => vacuum::generate(effect, seed),
        Plant::Ehvva => ehvva::generate(effect, seed),
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
    }
}
