//! One step of each plant, in f32 (the target's type) and Q32.32 fixed point (the EHVVA
//! ninth-order model is the host reference, benchmarked too for comparison).
//! `cargo bench -p model-core --bench plants`
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use model_core::ehvva::{EhvvaFull, EhvvaInputs, EhvvaLpv, EhvvaParams, EhvvaPlant, EhvvaReduced};
use model_core::evvt::{EvvtParams, EvvtPlant};
use model_core::positioner::{Positioner, PositionerParams};
use model_core::vacuum::{VacuumInputs, VacuumParams, VacuumValveActuator};
use model_core::{Real, Q32};

fn bench_type<R: Real>(c: &mut Criterion) {
    let name = R::NAME;
    let f = R::from_f64;

    let mut evvt = EvvtPlant::<R>::new(&EvvtParams::default()).expect("valid");
    c.bench_function(&format!("evvt_step/{name}"), |b| {
        // Engine speed and battery change every step, so the ZOH is recomputed (worst case).
        let mut k = 0u32;
        b.iter(|| {
            k = k.wrapping_add(1);
            let n = f(800.0 + (k % 600) as f64);
            evvt.step(black_box(f(40.0)), black_box(n), black_box(f(12.0)), f(0.01))
        })
    });

    let mut vac = VacuumValveActuator::<R>::new(&VacuumParams::hpt()).expect("valid");
    let inputs = VacuumInputs {
        duty_pct: f(55.0),
        u_batt_v: f(12.5),
        p_amb_kpa: f(100.0),
        p_tank_kpa: f(30.0),
    };
    c.bench_function(&format!("vacuum_hpt_step/{name}"), |b| {
        b.iter(|| vac.step(black_box(&inputs), f(0.001)))
    });

    // EHVVA: one 10 µs step (the models sub-step internally) with the pilot on, mid-opening
    // after 2 ms of pilot so the orifice and snubber terms are live.
    let ehvva_params = EhvvaParams::paper_default();
    let ehvva_in = EhvvaInputs {
        p_supply_mpa: f(7.0),
        p_back_mpa: f(1.0),
        temp_c: f(22.0),
        lift_high: true,
        snubber_on: true,
    };
    let mut reduced = EhvvaReduced::<R>::new(&ehvva_params, &ehvva_in, 0.01).expect("valid");
    let mut lpv = EhvvaLpv::<R>::new(&ehvva_params, &ehvva_in, 0.01).expect("valid");
    let mut full = EhvvaFull::<R>::new(&ehvva_params, &ehvva_in, 0.01).expect("valid");
    for _ in 0..400 {
        reduced.step(true, &ehvva_in);
        lpv.step(true, &ehvva_in);
        full.step(true, &ehvva_in);
    }
    c.bench_function(&format!("ehvva_reduced_step/{name}"), |b| {
        b.iter(|| reduced.step(black_box(true), black_box(&ehvva_in)))
    });
    c.bench_function(&format!("ehvva_lpv_step/{name}"), |b| {
        b.iter(|| lpv.step(black_box(true), black_box(&ehvva_in)))
    });
    c.bench_function(&format!("ehvva_full_step/{name}"), |b| {
        b.iter(|| full.step(black_box(true), black_box(&ehvva_in)))
    });

    let mut pos = Positioner::<R>::new(&PositionerParams::emps()).expect("valid");
    c.bench_function(&format!("positioner_step/{name}"), |b| {
        b.iter(|| pos.step(black_box(f(30.0)), f(0.001)))
    });
}

fn benches(c: &mut Criterion) {
    bench_type::<f32>(c);
    bench_type::<Q32>(c);
}

criterion_group!(plants, benches);
criterion_main!(plants);
