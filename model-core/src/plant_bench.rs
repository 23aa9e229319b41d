//! The plant steps whose instructions the emulated target counts (`hil-host target-bench`),
//! defined once so that the firmware and the host's check of its results run the very same
//! sequence: the operating points of the criterion plant benches (`benches/plants.rs`), a
//! warm-up that puts the EHVVA models mid-opening, then steps one at a time. The host compares
//! the final states: bit for bit in the fixed-point types (integer arithmetic) and in f32.
//!
//! Inputs are converted to `R` before the steps (on the target `from_f64` is soft-float
//! double arithmetic that the plant steps themselves never do), so a counted step is the
//! model's work only.

use crate::ehvva::{EhvvaInputs, EhvvaLpv, EhvvaParams, EhvvaPlant, EhvvaReduced};
use crate::evvt::{EvvtParams, EvvtPlant};
use crate::positioner::{Positioner, PositionerParams};
use crate::real::Real;
use crate::vacuum::{VacuumInputs, VacuumOutputs, VacuumParams, VacuumValveActuator};

/// EHVVA steps (10 µs, pilot on) before the counted ones: 4 ms, mid-opening.
pub const EHVVA_WARMUP_STEPS: u32 = 400;
/// Counted steps of each model (the firmware counts each; the host repeats the sequence).
pub const COUNTED_STEPS: u32 = 8;
/// Numbers in [`PlantBench::state`].
pub const N_STATE: usize = 14;

/// The plants the bench steps, in stepping order (EHVVA reduced, LPV, EVVT, vacuum,
/// positioner: firmware-qemu's `bench.rs` and the host's `plant_bench_native`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchPlant {
    /// [`EhvvaReduced`], one 10 µs step.
    EhvvaReduced,
    /// [`EhvvaLpv`], one 10 µs step.
    EhvvaLpv,
    /// [`EvvtPlant`], one 10 ms step at a new engine speed.
    Evvt,
    /// [`VacuumValveActuator`] (HPT), one 1 ms step.
    Vacuum,
    /// [`Positioner`] (EMPS), one 1 ms step.
    Positioner,
}

impl BenchPlant {
    /// Every plant, in stepping order.
    pub const ALL: [BenchPlant; 5] = [
        BenchPlant::EhvvaReduced,
        BenchPlant::EhvvaLpv,
        BenchPlant::Evvt,
        BenchPlant::Vacuum,
        BenchPlant::Positioner,
    ];

    /// The plant's id in reports (`ehvva-reduced`, `ehvva-lpv`, `evvt`, `vacuum`, `positioner`).
    pub fn id(self) -> &'static str {
        match self {
            BenchPlant::EhvvaReduced => "ehvva-reduced",
            BenchPlant::EhvvaLpv => "ehvva-lpv",
            BenchPlant::Evvt => "evvt",
            BenchPlant::Vacuum => "vacuum",
            BenchPlant::Positioner => "positioner",
        }
    }

    /// The marker-name part: `pil_begin_<label>_plant_<number>`.
    pub fn label(self) -> &'static str {
        match self {
            BenchPlant::EhvvaReduced => "ehvva",
            BenchPlant::EhvvaLpv => "ehvva_lpv",
            BenchPlant::Evvt => "evvt",
            BenchPlant::Vacuum => "vacuum",
            BenchPlant::Positioner => "positioner",
        }
    }
}

/// One of each plant at its bench operating point.
#[derive(Clone, Debug)]
pub struct PlantBench<R: Real> {
    /// The EHVVA reduced model, mid-opening after the warm-up.
    pub ehvva: EhvvaReduced<R>,
    /// The EHVVA LPV model, warmed up alike.
    pub ehvva_lpv: EhvvaLpv<R>,
    /// The EVVT phaser.
    pub evvt: EvvtPlant<R>,
    /// The HPT vacuum valve and actuator.
    pub vacuum: VacuumValveActuator<R>,
    /// The EMPS positioner.
    pub positioner: Positioner<R>,
    ehvva_in: EhvvaInputs<R>,
    vacuum_in: VacuumInputs<R>,
    evvt_cmd_rpm: R,
    evvt_u_batt_v: R,
    evvt_dt_s: R,
    vacuum_dt_s: R,
    positioner_force_n: R,
    positioner_dt_s: R,
    evvt_steps: u32,
}

impl<R: Real> PlantBench<R> {
    /// Every plant at its operating point, the EHVVA models warmed up.
    pub fn new() -> Result<Self, &'static str> {
        let f = R::from_f64;
        let ehvva_in = EhvvaInputs {
            p_supply_mpa: f(7.0),
            p_back_mpa: f(1.0),
            temp_c: f(22.0),
            lift_high: true,
            snubber_on: true,
        };
        let ehvva_params = EhvvaParams::paper_default();
        // Built in place and warmed up there: the benches are 11-22 KB, and every move is a
        // copy on the target's stack.
        let mut b = Self {
            ehvva: EhvvaReduced::new(&ehvva_params, &ehvva_in, 0.01).map_err(|_| "EHVVA reduced model parameters")?,
            ehvva_lpv: EhvvaLpv::new(&ehvva_params, &ehvva_in, 0.01).map_err(|_| "EHVVA LPV model parameters")?,
            evvt: EvvtPlant::new(&EvvtParams::default()).map_err(|_| "EVVT plant parameters")?,
            vacuum: VacuumValveActuator::new(&VacuumParams::hpt()).map_err(|_| "vacuum HPT parameters")?,
            positioner: Positioner::new(&PositionerParams::emps()).map_err(|_| "positioner EMPS parameters")?,
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
            positioner_force_n: f(30.0),
            positioner_dt_s: f(0.001),
            evvt_steps: 0,
        };
        for _ in 0..EHVVA_WARMUP_STEPS {
            b.ehvva.step(true, &b.ehvva_in);
            b.ehvva_lpv.step(true, &b.ehvva_in);
        }
        Ok(b)
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

    /// One 10 µs step of the LPV model, pilot on; the lift in mm.
    pub fn step_ehvva_lpv(&mut self) -> R {
        self.ehvva_lpv.step(true, &self.ehvva_in)
    }

    /// One 1 ms step of the EMPS positioner under 30 N; the position in m.
    pub fn step_positioner(&mut self) -> R {
        self.positioner.step(self.positioner_force_n, self.positioner_dt_s)
    }

    /// One 10 ms EVVT plant step at `engine_rpm`; the cam phase in degrees.
    pub fn step_evvt(&mut self, engine_rpm: R) -> R {
        self.evvt
            .step(self.evvt_cmd_rpm, engine_rpm, self.evvt_u_batt_v, self.evvt_dt_s)
    }

    /// One 1 ms step of the HPT vacuum valve and actuator; all its outputs (a bench that kept
    /// only the position let the compiler drop part of the flow to the tank, which the step
    /// computes for the tank model only).
    pub fn step_vacuum(&mut self) -> VacuumOutputs<R> {
        self.vacuum.step(&self.vacuum_in, self.vacuum_dt_s)
    }

    /// EHVVA lift, velocity, Pmo, Ph, Pl; EVVT phase and phase rate; vacuum actuator
    /// pressure, position, membrane position, friction; LPV lift; positioner position and
    /// velocity.
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
            self.ehvva_lpv.lift_mm(),
            self.positioner.pos_m(),
            self.positioner.vel_m_s(),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Q16, Q32};

    /// The range of each state (unit as in [`PlantBench::state`]).
    const RANGE: [f64; N_STATE] = [
        10.0, 5.0, 10.0, 10.0, 10.0, 40.0, 100.0, 100.0, 100.0, 100.0, 10.0, 10.0, 0.5, 0.5,
    ];

    fn run<R: Real>() -> [f64; N_STATE] {
        let mut b = PlantBench::<R>::new().unwrap();
        for _ in 0..8 {
            b.step_ehvva();
            b.step_ehvva_lpv();
            let n = b.next_engine_rpm();
            b.step_evvt(n);
            b.step_vacuum();
            b.step_positioner();
        }
        b.state().map(R::to_f64)
    }

    /// The bench's plants move (a bench of plants at rest would count idle paths), and the
    /// f32 and fixed-point runs of the same sequence stay close.
    #[test]
    fn bench_sequence_moves_every_plant_and_types_agree() {
        let lift0 = PlantBench::<f32>::new().unwrap().ehvva.lift_mm();
        assert!(lift0 > 0.1, "EHVVA not opening after the warm-up: {lift0} mm");
        let (sa, sq, s16) = (run::<f32>(), run::<Q32>(), run::<Q16>());
        // Lift rising, cam phase moving, actuator pressure pulled down from ambient (the rod
        // does not move yet in 8 ms), LPV lift up, positioner moving.
        assert!(
            sa[0] > f64::from(lift0) && sa[5] != 0.0 && sa[7] < 99.0 && sa[11] > 0.1 && sa[13] != 0.0,
            "{sa:?}"
        );
        for k in 0..N_STATE {
            let (x, y, z) = (sa[k], sq[k], s16[k]);
            assert!((x - y).abs() <= 1e-3 * (1.0 + y.abs()), "state {k}: f32 {x} vs Q32 {y}");
            // Q16.16 resolves 1.5e-5 in each state's unit: within 1 % of the state's range
            // here (the plants' own tests bound it over their envelopes).
            assert!((z - y).abs() <= 0.01 * RANGE[k], "state {k}: Q16 {z} vs Q32 {y}");
        }
    }
}
