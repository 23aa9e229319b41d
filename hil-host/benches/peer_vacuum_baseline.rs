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
use hil_host::diagnose::vacuum::VacuumFamily;
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
    c.bench_function("vacuum baseline fit, 9 180 samples (seed 33)", |b| {
        b.iter(|| {
            let family = family_for(Plant::Vacuum).expect("vacuum family");
            let fit = family.fit(&[], None, &est, &val).expect("baseline fit");
            assert!(
                (fit.est_cost - once.est_cost).abs() <= 1e-9 * once.est_cost,
                "{}",
                fit.est_cost
            );
            fit
        })
    });
    c.bench_function("vacuum baseline fit, 9 180 samples (seed 33), 1 thread", |b| {
        b.iter(|| {
            let mut family = VacuumFamily::default();
            family.lsq.threads = 1;
            let fit = family.fit(&[], None, &est, &val).expect("baseline fit");
            assert!(
                (fit.est_cost - once.est_cost).abs() <= 1e-9 * once.est_cost,
                "{}",
                fit.est_cost
            );
            fit
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
