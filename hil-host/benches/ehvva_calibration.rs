//! Issue 6: the EHVVA calibration problem (Li 2018 Sec. 5.2, eqs. (16)-(20)) on the shared
//! trust-region solver: one test condition (τp and Cd with td from the lift onset, then td VO,
//! td VC, τp and Cd together), and the whole Table 1-like matrix (20 conditions, both passes).
//! `cargo bench -p hil-host --bench ehvva_calibration`
//!
//! The bench log: valve events from model-core's reduced model (paper calibration, 20 kHz,
//! lift noise 3 µm on 2 µm), at each of 4 supply pressures × 5 temperatures a low-lift event
//! at 1 MPa and one at 3 MPa back pressure and, from 6 MPa, a high-lift event, dwell 8 ms. Generation and parsing are outside the
//! timing.
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use hil_host::diagnose::ehvva::Events;
use hil_host::generate::ehvva::{log_text, run_bench, Sensors, Test};
use hil_host::generate::Rng;
use hil_host::identify::ehvva::{conditions, default_options, fit_condition, identify};
use hil_host::log::parse_log;
use model_core::ehvva::{EhvvaInputs, EhvvaParams, EhvvaReduced};

const DT_MS: f64 = 0.05;

fn matrix_events() -> Events {
    let mut tests = Vec::new();
    for ph in [5.0, 6.0, 7.0, 8.0] {
        for t in [-20.0, 0.0, 22.0, 60.0, 100.0] {
            let at = |p_back_mpa: f64, lift_high: bool, snubber_on: bool| Test {
                inputs: EhvvaInputs {
                    p_supply_mpa: ph,
                    p_back_mpa,
                    temp_c: t,
                    lift_high,
                    snubber_on,
                },
                dwell_ms: 8.0,
            };
            tests.push(at(1.0, false, false));
            tests.push(at(3.0, false, false));
            if ph >= 6.0 {
                tests.push(at(1.0, true, true));
            }
        }
    }
    let p = EhvvaParams::paper_default();
    let sensors = Sensors {
        lift_sigma_mm: 0.003,
        lift_lsb_mm: 0.002,
        p_sigma_mpa: 0.01,
        p_lsb_mpa: 0.005,
        temp_sigma_c: 0.3,
        temp_lsb_c: 0.1,
    };
    let cols = run_bench(&tests, DT_MS, &sensors, &mut Rng::new(1), |i| {
        EhvvaReduced::<f64, 1024>::new(&p, i, DT_MS).map_err(|e| format!("{e:?}"))
    })
    .expect("bench runs");
    let log = parse_log("bench.csv", &log_text("benchmark", DT_MS, &cols), None).expect("log reads back");
    Events::from_log(&log).expect("events")
}

fn bench(c: &mut Criterion) {
    let set = matrix_events();
    let groups = conditions(std::slice::from_ref(&set));
    // One condition: 7 MPa, 22 °C (two low-lift events and a high-lift one).
    let one = groups
        .iter()
        .find(|g| (g.events[0].inputs.p_supply_mpa - 7.0).abs() < 0.3 && (g.events[0].inputs.temp_c - 22.0).abs() < 3.0)
        .expect("7 MPa, 22 °C tested")
        .clone();
    let opts = default_options();
    let mut g = c.benchmark_group("ehvva_calibration");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    g.bench_function("one condition (onset stage, then td VO, td VC, tau_p, Cd)", |b| {
        b.iter(|| fit_condition(&one, &opts).expect("fit"))
    });
    g.bench_function("Table 1-like matrix, 20 conditions", |b| {
        b.iter(|| identify(std::slice::from_ref(&set), &opts, &mut |_, _| {}).expect("identify"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
