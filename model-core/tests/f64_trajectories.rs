//! The f64 models' results, bit for bit: every plant runs a few thousand f64 steps on varied
//! inputs and the bits of its outputs are hashed (FNV-1a). The host's diagnosis fits react to
//! rounding-level changes of the f64 models, so a speed-up of the f32 or fixed-point step must
//! leave f64 exactly as it was (issue #14): a change that moves these hashes changes f64
//! arithmetic. If that is intended, rerun the diagnosis tests and update the constants from this
//! test's failure message.

use model_core::ehvva::{EhvvaFull, EhvvaInputs, EhvvaLpv, EhvvaParams, EhvvaPlant, EhvvaReduced, PAPER_TESTS};
use model_core::evvt::{EvvtParams, EvvtPlant};
use model_core::positioner::{Positioner, PositionerParams};
use model_core::vacuum::{
    VacuumInputs, VacuumParams, VacuumStaticModel, VacuumSystem, VacuumTank, VacuumTankParams, VacuumValveActuator,
};

/// FNV-1a over the bits of every value pushed.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn push(&mut self, x: f64) {
        for b in x.to_bits().to_le_bytes() {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// A small deterministic generator of inputs in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn vacuum_hash() -> u64 {
    let mut h = Fnv::new();
    let mut g = Lcg(7);
    let with_backlash = VacuumParams::hpt().with_effects(model_core::vacuum::VacuumEffects {
        backlash: true,
        ..VacuumParams::hpt().effects
    });
    let sets = [
        VacuumParams::lpt(),
        VacuumParams::hpt(),
        VacuumParams::hpc(),
        VacuumParams::hpt().baseline(),
        with_backlash,
    ];
    for (k, p) in sets.iter().enumerate() {
        let mut a = VacuumValveActuator::<f64>::new(p).unwrap();
        if k == 2 {
            a = a.with_rod_step_s(0.001).unwrap();
        }
        let mut inputs = VacuumInputs {
            duty_pct: 50.0,
            u_batt_v: 12.5,
            p_amb_kpa: 100.0,
            p_tank_kpa: 30.0,
        };
        for i in 0..3000 {
            if i % 40 == 0 {
                inputs.duty_pct = -5.0 + 110.0 * g.next();
                inputs.u_batt_v = 10.0 + 4.0 * g.next();
                inputs.p_amb_kpa = 95.0 + 7.0 * g.next();
                inputs.p_tank_kpa = 15.0 + 30.0 * g.next();
            }
            // Mostly 1 ms, sometimes the ECU task's 12.5 ms or an odd step.
            let dt = match i % 97 {
                0 => 0.0125,
                1 => 0.00037,
                _ => 0.001,
            };
            let o = a.step(&inputs, dt);
            for v in [
                o.p_act_kpa,
                o.x_pct,
                o.x_membrane_pct,
                o.p_static_kpa,
                o.flow_to_tank_mg_s,
            ] {
                h.push(v);
            }
            h.push(a.friction_kpa());
            if i % 50 == 0 {
                a.advance(&inputs, 0.002);
                h.push(a.advance_pressure(&inputs, 0.0005));
            }
        }
    }
    let mut s = VacuumSystem::<f64>::paper(30.0).unwrap();
    for i in 0..2000 {
        let d = [(i % 100) as f64, 100.0 - (i % 77) as f64, 30.0 + (i % 61) as f64];
        let o = s.step(d, 11.0 + (i % 5) as f64 * 0.5, 100.0, i % 300 < 200, 0.0125);
        h.push(o.p_tank_kpa);
        h.push(o.pump_flow_mg_s);
        for a in o.actuators {
            h.push(a.x_pct);
            h.push(a.flow_to_tank_mg_s);
        }
    }
    let mut t = VacuumTank::<f64>::new(&VacuumTankParams::paper(), 50.0).unwrap();
    for i in 0..500 {
        h.push(t.step(i % 7 != 0, 100.0 * g.next(), 100.0, 0.025));
        h.push(t.base_leak_mg_s(100.0, t.p_tank_kpa()));
    }
    for p in [VacuumParams::lpt(), VacuumParams::hpt(), VacuumParams::hpc()] {
        let m = VacuumStaticModel::<f64>::new(&p).unwrap();
        for i in 0..=200 {
            let x = -10.0 + 0.6 * i as f64;
            let pk = 10.0 + 0.5 * i as f64;
            h.push(m.pressure_for_position_kpa(x, 98.0));
            h.push(m.position_for_pressure_pct(pk, 101.0));
            h.push(m.duty_for_pressure_pct(pk, 100.0));
            h.push(m.pressure_for_duty_kpa(x, 100.0, 25.0));
        }
    }
    h.0
}

fn evvt_hash() -> u64 {
    let mut h = Fnv::new();
    let mut g = Lcg(11);
    for p in [EvvtParams::default(), EvvtParams::baseline()] {
        let mut plant = EvvtPlant::<f64>::new(&p).unwrap();
        let (mut cmd, mut rpm, mut ub) = (0.0, 1500.0, 12.0);
        for i in 0..4000 {
            if i % 25 == 0 {
                cmd = -3000.0 + 6000.0 * g.next();
                ub = 10.0 + 5.0 * g.next();
            }
            rpm = (rpm + 200.0 * (g.next() - 0.5)).clamp(600.0, 6500.0);
            let dt = if i % 53 == 0 { 0.005 } else { 0.01 };
            h.push(plant.step(cmd, rpm, ub, dt));
            h.push(plant.phase_deg());
            h.push(plant.phase_rate_deg_per_s());
            h.push(plant.measured_phase_deg());
        }
    }
    h.0
}

fn ehvva_hash() -> u64 {
    let mut h = Fnv::new();
    let params = EhvvaParams::paper_default();
    // Every paper test (oil at -20 to 100 °C), the temperature moved off the breakpoints
    // halfway through each run.
    for (k, t) in PAPER_TESTS.iter().enumerate() {
        let mut inputs = EhvvaInputs::<f64>::from_test(t);
        let mut red = EhvvaReduced::<f64>::new(&params, &inputs, 0.01).unwrap();
        let mut lpv = EhvvaLpv::<f64>::new(&params, &inputs, 0.01).unwrap();
        for i in 0..3000 {
            if i == 1500 {
                inputs.temp_c += 3.7;
            }
            // Pilot on for 8 ms of every 20 ms, shifted per test.
            let on = (i + 100 * k) % 2000 < 800;
            h.push(red.step(on, &inputs));
            h.push(red.velocity_m_s());
            h.push(red.p_mo_mpa());
            h.push(red.p_high_mpa());
            h.push(red.p_low_mpa());
            h.push(lpv.step(on, &inputs));
            h.push(lpv.velocity_m_s());
            for v in lpv.state() {
                h.push(v);
            }
            if let Some(v) = red.take_seat_velocity() {
                h.push(v);
            }
        }
        if k < 2 {
            let mut full = EhvvaFull::<f64>::new(&params, &inputs, 0.01).unwrap();
            for i in 0..3000 {
                let on = i % 2000 < 800;
                h.push(full.step(on, &inputs));
                h.push(full.velocity_m_s());
                h.push(full.p_main_mpa());
                h.push(full.pilot_mm());
            }
        }
    }
    h.0
}

fn positioner_hash() -> u64 {
    let mut h = Fnv::new();
    let mut g = Lcg(5);
    for p in [PositionerParams::emps(), PositionerParams::emps_asymmetric()] {
        let mut pos = Positioner::<f64>::new(&p).unwrap();
        let mut force = 0.0;
        for i in 0..4000 {
            if i % 30 == 0 {
                force = -80.0 + 160.0 * g.next();
            }
            let dt = if i % 41 == 0 { 0.0005 } else { 0.001 };
            h.push(pos.step(force, dt));
            h.push(pos.vel_m_s());
        }
    }
    h.0
}

#[test]
fn f64_plant_trajectories_are_unchanged() {
    let got = [
        ("vacuum", vacuum_hash()),
        ("evvt", evvt_hash()),
        ("ehvva", ehvva_hash()),
        ("positioner", positioner_hash()),
    ];
    let want: [u64; 4] = [
        0x62d7_085f_8092_7eb1,
        0xc3ba_fcf2_892e_6cd1,
        0x45d4_b815_8692_c402,
        0x0283_a1a2_6ee0_46bb,
    ];
    let mut bad = Vec::new();
    for ((name, g), w) in got.iter().zip(want) {
        if *g != w {
            bad.push(format!("{name}: {g:#018x} (expected {w:#018x})"));
        }
    }
    assert!(bad.is_empty(), "f64 trajectories changed:\n{}", bad.join("\n"));
}
