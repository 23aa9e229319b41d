//! Issue #12.8's peer comparison, the Rust side of the vacuum baseline fit (docs/performance.md
//! has both figures and the commands; the Python side is `tools/py/peer_vacuum_baseline.py` on
//! the same log).
//!
//! `cargo bench -p hil-host --bench peer_vacuum_baseline`
//!
//! The log is `hil-host generate vacuum none --seed 33` (9 180 estimation samples at 80 Hz, an
//! HPT-like actuator). The timed part is `Family::fit` with no effect on a fresh family: the
//! pressure stage from the three presets (valve map and time constant on the chamber-pressure
//! simulation error), the position map from the (pressure, position) band, the rod stage
//! (position map, mass, both dampings on the position simulation error, 13 rod substeps a
//! sample), the pressure stage's 95 % intervals and the prediction of the validation log (one
//! simulation, which the Python peer does not do). Jacobian columns on 2 threads (the solver's
//! default), except the band's arctan fit (1 thread); the second function is the same fit on one
//! thread throughout, as the Python peer runs.
use criterion::{criterion_group, criterion_main, Criterion};
use hil_host::diagnose::vacuum::{Inputs, RodMap, VacuumFamily, VacuumModel, ValveMap};
use hil_host::diagnose::{family_for, Family};
use hil_host::generate;
use hil_host::log::Plant;

fn bench(c: &mut Criterion) {
    let case = generate::generate(Plant::Vacuum, "none", 33).expect("generated case");
    let (est, val) = case.logs().expect("generated logs read back");
    let once = family_for(Plant::Vacuum)
        .expect("vacuum family")
        .fit(&[], None, &est, &val)
        .expect("baseline fit");
    // The optimum, for the comparison with the peer's.
    eprintln!(
        "vacuum baseline, {} estimation samples: position cost (half sum of squares) {:.6}, {}",
        est.len(),
        once.est_cost,
        once.convergence
    );
    for (n, v) in &once.params {
        eprintln!("  {n} = {v:.9e}");
    }
    // Each run refits from scratch and must land on the same optimum.
    let refit = |family: &dyn Family| {
        let fit = family.fit(&[], None, &est, &val).expect("baseline fit");
        assert!(
            (fit.est_cost - once.est_cost).abs() <= 1e-9 * once.est_cost,
            "{}",
            fit.est_cost
        );
        fit
    };
    c.bench_function("vacuum baseline fit, 9 180 samples (seed 33)", |b| {
        b.iter(|| refit(family_for(Plant::Vacuum).expect("vacuum family").as_ref()))
    });
    c.bench_function("vacuum baseline fit, 9 180 samples (seed 33), 1 thread", |b| {
        b.iter(|| {
            let mut family = VacuumFamily::default();
            family.lsq.threads = 1;
            refit(&family)
        })
    });
}

/// One simulation of the estimation log (valve and rod, 13 rod sub-steps a sample) at the fitted
/// model: the unit of the fits' cost, against the peer's `per_rod_sim_ms`.
fn bench_simulation(c: &mut Criterion) {
    let case = generate::generate(Plant::Vacuum, "none", 33).expect("generated case");
    let (est, val) = case.logs().expect("generated logs read back");
    let fit = family_for(Plant::Vacuum)
        .expect("vacuum family")
        .fit(&[], None, &est, &val)
        .expect("baseline fit");
    let mut m = VacuumModel::baseline_guess(ValveMap::PiecewiseLinear, RodMap::Arctan);
    for (n, v) in &fit.params {
        m.set(n, *v).expect("a baseline parameter");
    }
    let io = Inputs::from_log(&est).expect("vacuum inputs");
    let n = io.len();
    let h_max_s = VacuumFamily::default().h_max_s;
    let (mut x, mut p) = (vec![0.0; n], vec![0.0; n]);
    c.bench_function("vacuum one simulation of the 9 180 samples (valve and rod)", |b| {
        b.iter(|| {
            m.simulate(&io, 0..n, h_max_s, true, &mut x, &mut p)
                .expect("simulation")
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench, bench_simulation
}
criterion_main!(benches);
