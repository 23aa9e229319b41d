use super::*;
use crate::vacuum::{VacuumEffects, VacuumSystem};

const DT_US: u32 = 12_500;

/// The actuators without friction/backlash but with the supply-voltage effect (the
/// feedforward has no friction compensation; the position controller is another module).
fn frictionless() -> [VacuumParams; 3] {
    let e = VacuumEffects {
        supply_voltage: true,
        ..VacuumEffects::NONE
    };
    [
        VacuumParams::lpt().with_effects(e),
        VacuumParams::hpt().with_effects(e),
        VacuumParams::hpc().with_effects(e),
    ]
}

struct Sim {
    task: VacuumTask,
    plant: VacuumSystem<f32>,
    tank_params: VacuumTankParams,
    t_us: u32,
    pump_on_steps: u32,
    pump_broken: bool,
    x_override: [Option<f32>; 3],
    safe: SafeState,
}

impl Sim {
    fn new(params: [VacuumParams; 3], p_tank0: f64) -> Self {
        Self::with_config(
            VacuumTaskConfig {
                actuators: params,
                ..Default::default()
            },
            p_tank0,
        )
    }

    fn with_config(cfg: VacuumTaskConfig, p_tank0: f64) -> Self {
        let params = cfg.actuators;
        let tank = VacuumTankParams::paper();
        Self {
            task: VacuumTask::new(cfg).unwrap(),
            plant: VacuumSystem::new(&params[0], &params[1], &params[2], &tank, p_tank0).unwrap(),
            tank_params: tank,
            t_us: 0,
            pump_on_steps: 0,
            pump_broken: false,
            x_override: [None; 3],
            safe: SafeState::default(),
        }
    }

    /// Runs for `s` seconds; returns the last outputs.
    fn run(&mut self, x_set: [f32; 3], u_batt: f32, s: f32) -> VacuumTaskOutputs {
        let steps = (s * 1e6 / DT_US as f32) as u32;
        let mut out = None;
        let mut x_meas = [self.plant.lpt.x_pct(), self.plant.hpt.x_pct(), self.plant.hpc.x_pct()];
        for _ in 0..steps {
            for k in 0..3 {
                if let Some(x) = self.x_override[k] {
                    x_meas[k] = x;
                }
            }
            let inp = VacuumTaskInputs {
                x_set_pct: x_set,
                x_meas_pct: x_meas,
                p_tank_kpa: self.plant.tank.p_tank_kpa(),
                p_amb_kpa: 100.0,
                u_batt_v: u_batt,
                safe: self.safe,
            };
            let o = self.task.step(&inp, self.t_us);
            self.pump_on_steps += u32::from(o.pump_on);
            let duties = o.duty.map(|d| d * 100.0);
            let r = self.plant.step(
                duties,
                u_batt,
                100.0,
                o.pump_on && !self.pump_broken,
                DT_US as f32 * 1e-6,
            );
            x_meas = r.actuators.map(|a| a.x_pct);
            self.t_us += DT_US;
            out = Some(o);
        }
        out.unwrap()
    }
}

#[test]
fn inverse_model_with_compensation_puts_the_actuators_at_the_setpoints() {
    // At 11 V and 14.5 V (U_ref = 12 V) the compensated duty holds the positions. (The
    // HPC valve needs 87 % corrected duty for 30 %: at 11 V that is 95 % of the PWM; below
    // about 10.5 V it saturates at 100 % and falls short, a physical limit.)
    for u in [11.0f32, 14.5] {
        let mut sim = Sim::new(frictionless(), 25.0);
        let x_set = [40.0, 30.0, 30.0];
        sim.run(x_set, u, 3.0);
        let x = [sim.plant.lpt.x_pct(), sim.plant.hpt.x_pct(), sim.plant.hpc.x_pct()];
        for k in 0..3 {
            assert!(
                (x[k] - x_set[k]).abs() < 1.0,
                "{u} V actuator {k}: {} vs {}",
                x[k],
                x_set[k]
            );
        }
    }
    // Without compensation (duty fixed at its 12 V value) the HPT at 14.5 V misses by far.
    let task = VacuumTask::new(VacuumTaskConfig {
        actuators: frictionless(),
        ..Default::default()
    })
    .unwrap();
    let (_, duty_12v, _) = task.feedforward(1, 30.0, 100.0, 12.0);
    let (_, duty_14v, _) = task.feedforward(1, 30.0, 100.0, 14.5);
    assert!((duty_14v / duty_12v - 12.0 / 14.5).abs() < 1e-4);
    let mut plant = VacuumSystem::<f32>::new(
        &frictionless()[0],
        &frictionless()[1],
        &frictionless()[2],
        &VacuumTankParams::paper(),
        25.0,
    )
    .unwrap();
    for _ in 0..240 {
        plant.step([0.0, duty_12v, 0.0], 14.5, 100.0, true, 0.0125);
    }
    assert!(
        (plant.hpt.x_pct() - 30.0).abs() > 10.0,
        "uncompensated HPT at {}",
        plant.hpt.x_pct()
    );
}

#[test]
fn pump_runs_on_the_needed_pressure_and_less_than_a_fixed_35_kpa_rule() {
    // Setpoints that need about 73-74 kPa in the chambers (the HPC at rest needs none):
    // the target is the lower of the two less the 10 kPa margin.
    let x_set = [30.0, 30.0, 0.0];
    let mut sim = Sim::new(frictionless(), 100.0);
    let need = [0, 1].map(|k| sim.task.feedforward(k, x_set[k], 100.0, 13.5).0.unwrap());
    assert!(need.iter().all(|p| (70.0..76.0).contains(p)), "{need:?}");
    let expected = need[0].min(need[1]) - sim.task.cfg.tank_margin_kpa;
    let out = sim.run(x_set, 13.5, 60.0);
    assert!(
        (out.p_tank_target_kpa - expected).abs() < 0.5,
        "target {} (expected {expected})",
        out.p_tank_target_kpa
    );
    // The pump holds the tank within its hysteresis below the target.
    let p = sim.plant.tank.p_tank_kpa();
    assert!(p < expected + 1.0 && p > expected - 10.0, "tank {p}");
    assert!((sim.plant.lpt.x_pct() - 30.0).abs() < 1.0 && (sim.plant.hpt.x_pct() - 30.0).abs() < 1.0);
    let on_needed = sim.pump_on_steps;
    // The fixed rule (always below 35 kPa, 5 kPa hysteresis) on the same plant and setpoints.
    let mut plant = VacuumSystem::<f32>::new(
        &frictionless()[0],
        &frictionless()[1],
        &frictionless()[2],
        &sim.tank_params,
        100.0,
    )
    .unwrap();
    let duties = [0, 1, 2].map(|k| sim.task.feedforward(k, x_set[k], 100.0, 13.5).1);
    let (mut pump, mut on_fixed) = (false, 0u32);
    for _ in 0..(60_000_000 / DT_US) {
        let p = plant.tank.p_tank_kpa();
        pump = p > 35.0 || (pump && p > 30.0);
        on_fixed += u32::from(pump);
        plant.step(duties, 13.5, 100.0, pump, DT_US as f32 * 1e-6);
    }
    assert!(
        (on_needed as f32) < 0.6 * on_fixed as f32,
        "pump on {} steps on the need vs {} on the fixed rule",
        on_needed,
        on_fixed
    );
    // A setpoint that needs deep vacuum lowers the target.
    let out = sim.run([90.0, 30.0, 0.0], 13.5, 0.1);
    assert!(out.p_tank_target_kpa < 40.0, "{}", out.p_tank_target_kpa);
}

#[test]
fn healthy_system_raises_no_leak_and_no_stuck_flag() {
    let mut sim = Sim::new(VacuumTaskConfig::default().actuators, 60.0);
    for x_set in [
        [20.0, 40.0, 60.0],
        [80.0, 10.0, 30.0],
        [0.0, 60.0, 90.0],
        [50.0, 50.0, 50.0],
    ] {
        let out = sim.run(x_set, 13.5, 10.0);
        assert!(!out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
        assert!(
            out.residual_kpa_per_s.abs() < 0.2,
            "residual {}",
            out.residual_kpa_per_s
        );
        assert_eq!(out.stuck, [false; 3]);
    }
}

#[test]
fn broken_hose_is_flagged_and_the_wastegate_goes_to_its_spring() {
    let mut sim = Sim::new(frictionless(), 60.0);
    let x_set = [40.0, 30.0, 20.0];
    assert!(!sim.run(x_set, 13.5, 10.0).abnormal_leak);
    // A hose cracks: 0.5 mm² from ambient into the tank (25 times the base leak).
    let cracked = VacuumTankParams {
        base_leak_area_mm2: 0.5,
        ..sim.tank_params
    };
    let p_now = sim.plant.tank.p_tank_kpa() as f64;
    sim.plant.tank = VacuumTank::new(&cracked, p_now).unwrap();
    let out = sim.run(x_set, 13.5, 6.5);
    assert!(out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
    assert!(out.residual_kpa_per_s > 0.5);
    assert_eq!(out.duty, [0.0; 3]);
    assert!(!out.pump_on);
    // Spring position: all actuators back at 0 %.
    sim.run(x_set, 13.5, 2.0);
    assert!(
        sim.plant.lpt.x_pct() < 0.5 && sim.plant.hpt.x_pct() < 0.5,
        "{} {}",
        sim.plant.lpt.x_pct(),
        sim.plant.hpt.x_pct()
    );
}

#[test]
fn failed_pump_is_flagged_as_a_leak() {
    let mut sim = Sim::new(frictionless(), 100.0);
    sim.pump_broken = true;
    let out = sim.run([40.0, 30.0, 20.0], 13.5, 6.5);
    assert!(out.abnormal_leak, "residual {} kPa/s", out.residual_kpa_per_s);
    assert!(!out.pump_on && out.duty == [0.0; 3]);
}

#[test]
fn stuck_actuator_is_flagged_after_the_time_limit() {
    let mut sim = Sim::new(frictionless(), 40.0);
    sim.run([40.0, 30.0, 20.0], 13.5, 2.0);
    sim.x_override[1] = Some(30.0);
    // Setpoint moves; the HPT reading stays at 30 %.
    let out = sim.run([40.0, 80.0, 20.0], 13.5, 0.8);
    assert_eq!(out.stuck, [false; 3], "not before 1 s");
    let out = sim.run([40.0, 80.0, 20.0], 13.5, 1.0);
    assert_eq!(out.stuck, [false, true, false]);
    assert_eq!(out.duty, [0.0; 3]);
}

#[test]
fn supervisor_safe_state_is_applied() {
    let mut sim = Sim::new(frictionless(), 90.0);
    sim.safe = SafeState {
        vacuum_spring_open: true,
        pump_off: true,
        ..Default::default()
    };
    let out = sim.run([40.0, 30.0, 20.0], 13.5, 1.0);
    assert_eq!(out.duty, [0.0; 3]);
    assert!(!out.pump_on);
    // Pump off only (battery low): duties still follow the setpoints.
    sim.safe = SafeState {
        pump_off: true,
        ..Default::default()
    };
    let out = sim.run([40.0, 30.0, 20.0], 13.5, 0.1);
    assert!(out.duty[0] > 0.0 && !out.pump_on);
}

fn x_now(sim: &Sim) -> [f32; 3] {
    [sim.plant.lpt.x_pct(), sim.plant.hpt.x_pct(), sim.plant.hpc.x_pct()]
}

/// Holds `x_set` for `s` seconds one 80 Hz period at a time; per valve the time after the
/// hold's start from which |x − setpoint| stays within `band_pct` (None: not settled by
/// the end), and the largest overshoot beyond the setpoint in the step's direction.
fn hold(sim: &mut Sim, x_set: [f32; 3], band_pct: f32, s: f32) -> ([Option<f32>; 3], [f32; 3]) {
    let x0 = x_now(sim);
    let steps = (s * 1e6 / DT_US as f32) as u32;
    let mut last_out = [Some(0.0f32); 3];
    let mut overshoot = [0.0f32; 3];
    for n in 1..=steps {
        sim.run(x_set, 13.5, DT_US as f32 * 1e-6);
        let x = x_now(sim);
        for k in 0..3 {
            if (x[k] - x_set[k]).abs() > band_pct {
                last_out[k] = Some(n as f32 * DT_US as f32 * 1e-6);
            }
            let dir = if x_set[k] >= x0[k] { 1.0 } else { -1.0 };
            overshoot[k] = overshoot[k].max(dir * (x[k] - x_set[k]));
        }
    }
    let end = x_now(sim);
    let settled = [0, 1, 2].map(|k| {
        if (end[k] - x_set[k]).abs() <= band_pct {
            last_out[k]
        } else {
            None
        }
    });
    (settled, overshoot)
}

/// The run's wastegate profile 20 → 60 → 40 % (with moves of the bypasses), 4 s holds.
const PROFILE: [[f32; 3]; 3] = [[20.0, 20.0, 30.0], [60.0, 45.0, 50.0], [40.0, 30.0, 40.0]];

#[test]
fn with_rod_friction_the_closed_loop_settles_within_1_pct_where_feedforward_alone_does_not() {
    // The paper's actuators with their Dahl/Coulomb friction (Figs. 9-10; Fc 1.5/4/5 kPa).
    let mut closed = Sim::new(VacuumTaskConfig::default().actuators, 40.0);
    let ff_cfg = VacuumTaskConfig {
        kp_loop_gain: 0.0,
        ki_kpa_per_pct_s: 0.0,
        friction_compensation: 0.0,
        ..Default::default()
    };
    let mut open = Sim::with_config(ff_cfg, 40.0);
    let mut ff_misses = 0;
    for x_set in PROFILE {
        let (settled, overshoot) = hold(&mut closed, x_set, 1.0, 4.0);
        let (ff_settled, _) = hold(&mut open, x_set, 1.0, 4.0);
        extern crate std;
        std::println!("{x_set:?}: closed loop into ±1 % after {settled:?} s (overshoot {overshoot:?} %), x {:?}; feedforward only {ff_settled:?}, x {:?}", x_now(&closed), x_now(&open));
        for k in 0..3 {
            // Bound: into ±1 % within 1 s of the step and held to the end of the 4 s hold;
            // overshoot below 2 % on the wastegate, 3 % on the bypasses (their friction,
            // 4-5 kPa, is 10-30 % of stroke on the HPT's steep part; the feedforward of
            // friction and clearance and the slope-scaled gain keep it small: measured
            // 0.6 / 0.66 / 0.19 s, 1.7 / 1.6 / 0.6 %; with a fixed 0.3 kPa/% gain the HPT's
            // steeper map overshot 9 %).
            assert!(
                settled[k].is_some_and(|t| t <= 1.0),
                "{x_set:?} valve {k}: {settled:?}, x {:?}",
                x_now(&closed)
            );
            assert!(
                overshoot[k] < [2.0, 3.0, 3.0][k],
                "{x_set:?} valve {k}: overshoot {} %",
                overshoot[k]
            );
        }
        // Feedforward alone leaves the friction offset: (Fc on the rod)·slope, 1.5 kPa ≈ 3 %
        // on the wastegate.
        ff_misses += settled_count_missing(&ff_settled);
    }
    assert!(
        ff_misses >= 3,
        "feedforward alone settled into ±1 % in all but {ff_misses} holds"
    );
    let integrals = [0, 1, 2].map(|k| closed.task.integral_kpa(k));
    assert!(
        integrals.iter().any(|i| i.abs() > 0.5),
        "no friction offset learnt: {integrals:?}"
    );
    assert_eq!(open.task.integral_kpa(0), 0.0);
}

fn settled_count_missing(s: &[Option<f32>; 3]) -> u32 {
    s.iter().map(|t| u32::from(t.is_none())).sum()
}

#[test]
fn no_windup_after_a_safe_state_or_a_stuck_reading() {
    let actuators = VacuumTaskConfig::default().actuators;
    let limit = [0, 1, 2].map(|k| 2.0 * actuators[k].fc_kpa as f32 + 5.0);
    let mut sim = Sim::new(actuators, 40.0);
    hold(&mut sim, [40.0, 30.0, 40.0], 1.0, 4.0);
    // Spring-open safe state for 2 s (e.g. a battery-low phase) while the setpoints ask
    // for more: the valves vent, the rods fall to the spring and the integrators stay
    // cleared, so nothing is stored for the recovery.
    sim.safe = SafeState {
        vacuum_spring_open: true,
        ..Default::default()
    };
    let x_set = [60.0, 45.0, 50.0];
    let out = sim.run(x_set, 13.5, 2.0);
    assert_eq!(out.duty, [0.0; 3]);
    assert_eq!(out.mode, [VacuumPositionMode::Off; 3]);
    assert_eq!([0, 1, 2].map(|k| sim.task.integral_kpa(k)), [0.0; 3]);
    assert!(x_now(&sim)[0] < 1.0, "wastegate {} % in the safe state", x_now(&sim)[0]);
    sim.safe = SafeState::default();
    let (settled, overshoot) = hold(&mut sim, x_set, 1.0, 4.0);
    extern crate std;
    std::println!("after the safe state: into ±1 % after {settled:?} s, overshoot {overshoot:?} %");
    for k in 0..3 {
        assert!(
            settled[k].is_some_and(|t| t <= 2.5) && overshoot[k] < 3.0,
            "valve {k}: {settled:?} {overshoot:?}"
        );
    }

    // The wastegate's reading freezes for 0.8 s (a binding rod or sensor, not yet the 1 s
    // stuck flag) while its setpoint steps up: the integrator sees a constant error but is
    // held by its limit (2·Fc + 5 kPa) and its zone; once the reading moves again the loop
    // is back within ±1 % without a long excursion.
    let x_frozen = x_now(&sim)[0];
    sim.x_override[0] = Some(x_frozen);
    let mut worst_integral = 0.0f32;
    for _ in 0..64 {
        let out = sim.run([70.0, 45.0, 50.0], 13.5, DT_US as f32 * 1e-6);
        assert_eq!(out.stuck, [false; 3]);
        worst_integral = worst_integral.max(sim.task.integral_kpa(0).abs());
    }
    assert!(
        worst_integral <= limit[0] + 1e-4,
        "integral {worst_integral} kPa beyond the limit {}",
        limit[0]
    );
    sim.x_override[0] = None;
    let (settled, overshoot) = hold(&mut sim, [70.0, 45.0, 50.0], 1.0, 4.0);
    std::println!("after the frozen reading: integral at most {worst_integral:.2} kPa, into ±1 % after {settled:?} s, overshoot {overshoot:?} %");
    assert!(settled[0].is_some_and(|t| t <= 3.0), "{settled:?}, x {:?}", x_now(&sim));

    // Flagged stuck: every valve disabled, integrators cleared.
    sim.x_override[0] = Some(x_now(&sim)[0]);
    let out = sim.run([20.0, 45.0, 50.0], 13.5, 1.2);
    assert!(out.stuck[0]);
    assert_eq!((out.duty, out.mode), ([0.0; 3], [VacuumPositionMode::Off; 3]));
    assert_eq!([0, 1, 2].map(|k| sim.task.integral_kpa(k)), [0.0; 3]);
}

#[test]
fn implausible_position_reading_falls_back_to_feedforward_then_the_spring() {
    for bad_reading in [f32::NAN, 150.0, -20.0] {
        let mut sim = Sim::new(VacuumTaskConfig::default().actuators, 40.0);
        let x_set = [50.0, 30.0, 40.0];
        hold(&mut sim, x_set, 1.0, 4.0);
        // The wastegate's reading goes bad: that valve alone runs on its feedforward
        // (inverse model + eq. (15)), integrator cleared; the others stay in control.
        sim.x_override[0] = Some(bad_reading);
        let out = sim.run(x_set, 12.5, 0.5);
        let (_, ff_duty, _) = sim.task.feedforward(0, 50.0, 100.0, 12.5);
        assert_eq!(
            out.mode[0],
            VacuumPositionMode::OpenLoop(VacuumPositionFault::PositionSensor),
            "{bad_reading}"
        );
        assert_eq!(out.mode[1..], [VacuumPositionMode::Control; 2]);
        assert!(
            (out.duty[0] * 100.0 - ff_duty).abs() < 1e-5,
            "{bad_reading}: duty {} vs feedforward {ff_duty}",
            out.duty[0] * 100.0
        );
        assert_eq!(sim.task.integral_kpa(0), 0.0);
        // Open loop the wastegate stays within its friction band of the setpoint.
        let x = x_now(&sim)[0];
        assert!((x - 50.0).abs() < 5.0, "{bad_reading}: wastegate at {x} % open loop");
        // The supervisor's debounced position-sensor fault asks for the spring position.
        sim.safe = crate::ecu::supervisor::Fault::VacuumPositionSensor.reaction();
        let out = sim.run(x_set, 12.5, 1.0);
        assert_eq!((out.duty, out.mode), ([0.0; 3], [VacuumPositionMode::Off; 3]));
        assert!(x_now(&sim)[0] < 1.0);
    }
}

#[test]
fn supply_below_the_compensator_range_freezes_the_integrators() {
    let mut sim = Sim::new(VacuumTaskConfig::default().actuators, 40.0);
    let x_set = [50.0, 30.0, 40.0];
    hold(&mut sim, x_set, 1.0, 4.0);
    let before = [0, 1, 2].map(|k| sim.task.integral_kpa(k));
    // 5 V: below comp_u_min_v = 6 V; the valves cannot hold the rods, the errors are large.
    let out = sim.run(x_set, 5.0, 1.0);
    assert!(out.supply_low);
    assert_eq!(
        out.mode,
        [VacuumPositionMode::OpenLoop(VacuumPositionFault::SupplyLow); 3]
    );
    assert_eq!(
        [0, 1, 2].map(|k| sim.task.integral_kpa(k)),
        before,
        "integrators moved below the range"
    );
    let x = x_now(&sim);
    assert!(
        (0..3).any(|k| (x[k] - x_set[k]).abs() > 1.0),
        "the sag did not move anything: {x:?}"
    );
    // Back in range the learnt offsets are still there and the loop settles again.
    let (settled, _) = hold(&mut sim, x_set, 1.0, 4.0);
    assert!(settled.iter().all(|t| t.is_some_and(|t| t <= 3.0)), "{settled:?}");
}
