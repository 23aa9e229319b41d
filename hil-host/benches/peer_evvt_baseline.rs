//! Issue #12.8's peer comparison: the EVVT baseline fit of `diagnose` (coarse (α, β) grid, then
//! the trust-region solver on the closed-loop simulation error of the whole estimation log)
//! against the same fit by scipy's `least_squares` (`tools/py/peer_evvt_baseline.py`, run on
//! the same log; docs/performance.md has both figures and the commands).
//! `cargo bench -p hil-host --bench peer_evvt_baseline`
//!
//! The log is `hil-host generate evvt none --seed 33` (22 500 estimation samples at 100 Hz).
//! The timed part is `Family::fit` with no effect on a fresh family: the grid, the solver, and
//! the prediction of the validation log (one simulation, which the Python peer does not do).
use criterion::{criterion_group, criterion_main, Criterion};
use hil_host::diagnose::family_for;
use hil_host::generate;
use hil_host::log::Plant;

fn bench(c: &mut Criterion) {
    let case = generate::generate(Plant::Evvt, "none", 33).expect("generated case");
    let (est, val) = case.logs().expect("generated logs read back");
    c.bench_function("evvt baseline fit, 22 500 samples (seed 33)", |b| {
        b.iter(|| {
            let family = family_for(Plant::Evvt).expect("evvt family");
            let fit = family.fit(&[], None, &est, &val).expect("baseline fit");
            assert!((fit.params[0].1 - 0.48783).abs() < 1e-4, "{:?}", fit.params);
            fit
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
