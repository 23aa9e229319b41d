//! The plant steps whose instructions the emulated target counts (`hil-host target-bench`),
//! defined once so that the firmware and the host's check of its results run the very same
//! sequence: the operating points of the criterion plant benches (`benches/plants.rs`), a
//! warm-up that puts the EHVVA mid-opening, then steps one at a time. The host compares the
//! final states: bit for bit in Q32 (integer arithmetic) and in f32.
//!
//! Inputs are converted to `R` before the steps (on the target `from_f64` is soft-float
//! double arithmetic that the plant steps themselves never do), so a counted step is the
//! model's work only.

use crate::ehvva::{EhvvaInputs, EhvvaParams, EhvvaPlant, EhvvaReduced};
use crate::evvt::{EvvtParams, EvvtPlant};
use crate::real::Real;
use crate::vacuum::{VacuumInputs, VacuumParams, VacuumValveActuator};

/// EHVVA steps (10 µs, pilot on) before the counted ones: 4 ms, mid-opening.
pub const EHVVA_WARMUP_STEPS: u32 = 400;
/// Counted steps of each model (the firmware counts each; the host repeats the sequence).
pub const COUNTED_STEPS: u32 = 8;
/// Numbers in [`PlantBench::state`].
pub const N_STATE: usize = 11;

/// One of each plant at its bench operating point.
#[derive(Clone, Debug)]
pub struct PlantBench<R: Real> {
    pub ehvva: EhvvaReduced<R>,
    pub evvt: EvvtPlant<R>,
    pub vacuum: VacuumValveActuator<R>,
    ehvva_in: EhvvaInputs<R>,
    vacuum_in: VacuumInputs<R>,
    evvt_cmd_rpm: R,
    evvt_u_batt_v: R,
    evvt_dt_s: R,
    vacuum_dt_s: R,
    evvt_steps: u32,
}

impl<R: Real> PlantBench<R> {
    pub fn new() -> Result<Self, &'static str> {
        let f = R::from_f64;
        let ehvva_in = EhvvaInputs {
            p_supply_mpa: f(7.0),
            p_back_mpa: f(1.0),
            temp_c: f(22.0),
            lift_high: true,
            snubber_on: true,
        };
        let mut ehvva = EhvvaReduced::new(&EhvvaParams::paper_default(), &ehvva_in, 0.01)
            .map_err(|_| "EHVVA reduced model parameters")?;
        for _ in 0..EHVVA_WARMUP_STEPS {
            ehvva.step(true, &ehvva_in);
        }
        Ok(Self {
            ehvva,
            evvt: EvvtPlant::new(&EvvtParams::default()).map_err(|_| "EVVT plant parameters")?,
            vacuum: VacuumValveActuator::new(&VacuumParams::hpt()).map_err(|_| "vacuum HPT parameters")?,
            ehvva_in,
            vacuum_in: VacuumInputs {
                duty_pct: f(55.0),
                u_batt_v: f(12.5),
                p_amb_kpa: f(100.0),
                p_tank_kpa: f(30.0),
            },
            evvt_cmd_rpm: f(40.0),
            evvt_u_batt_v: f(12.0),
            evvt_dt_s: f(0.01),
            vacuum_dt_s: f(0.001),
            evvt_steps: 0,
        })
    }

    /// The engine speed of the next EVVT step: it changes every step, so the plant
    /// recomputes its zero-order hold (the worst case, as in the criterion bench).
    pub fn next_engine_rpm(&mut self) -> R {
        self.evvt_steps = self.evvt_steps.wrapping_add(1);
        R::from_f64(800.0 + f64::from(self.evvt_steps % 600))
    }

    /// One 10 µs step of the reduced nonlinear model, eq. (12), pilot on; the lift in mm.
    pub fn step_ehvva(&mut self) -> R {
        self.ehvva.step(true, &self.ehvva_in)
    }

    /// One 10 ms EVVT plant step at `engine_rpm`; the cam phase in degrees.
    pub fn step_evvt(&mut self, engine_rpm: R) -> R {
        self.evvt
            .step(self.evvt_cmd_rpm, engine_rpm, self.evvt_u_batt_v, self.evvt_dt_s)
    }

    /// One 1 ms step of the HPT vacuum valve and actuator; the position in %.
    pub fn step_vacuum(&mut self) -> R {
        self.vacuum.step(&self.vacuum_in, self.vacuum_dt_s).x_pct
    }

    /// EHVVA lift, velocity, Pmo, Ph, Pl; EVVT phase and phase rate; vacuum actuator
    /// pressure, position, membrane position, friction.
    pub fn state(&self) -> [R; N_STATE] {
        [
            self.ehvva.lift_mm(),
            self.ehvva.velocity_m_s(),
            self.ehvva.p_mo_mpa(),
            self.ehvva.p_high_mpa(),
            self.ehvva.p_low_mpa(),
            self.evvt.phase_deg(),
            self.evvt.phase_rate_deg_per_s(),
            self.vacuum.p_act_kpa(),
            self.vacuum.x_pct(),
            self.vacuum.x_membrane_pct(),
            self.vacuum.friction_kpa(),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Q32;

    /// The bench's plants move (a bench of plants at rest would count idle paths), and the
    /// f32 and Q32 runs of the same sequence stay close.
    #[test]
    fn bench_sequence_moves_every_plant_and_types_agree() {
        let mut a = PlantBench::<f32>::new().unwrap();
        let mut b = PlantBench::<Q32>::new().unwrap();
        let lift0 = a.ehvva.lift_mm();
        assert!(lift0 > 0.1, "EHVVA not opening after the warm-up: {lift0} mm");
        for _ in 0..8 {
            a.step_ehvva();
            b.step_ehvva();
            let (na, nb) = (a.next_engine_rpm(), b.next_engine_rpm());
            a.step_evvt(na);
            b.step_evvt(nb);
            a.step_vacuum();
            b.step_vacuum();
        }
        let (sa, sb) = (a.state(), b.state());
        // Lift rising, cam phase moving, actuator pressure pulled down from ambient (the rod
        // does not move yet in 8 ms).
        assert!(sa[0] > lift0 && sa[5] != 0.0 && sa[7] < 99.0, "{sa:?}");
        for (k, (x, y)) in sa.iter().zip(sb.iter()).enumerate() {
            let (x, y) = (f64::from(*x), y.to_f64());
            assert!((x - y).abs() <= 1e-3 * (1.0 + y.abs()), "state {k}: f32 {x} vs Q32 {y}");
        }
    }
}
