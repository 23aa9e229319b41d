//! Issue #12.8's peer comparison, the Rust side (docs/performance.md has both figures and the
//! commands; the Python side is `tools/py/peer_*.py` on the same logs):
//! - the EVVT baseline fit of `diagnose` (coarse (α, β) grid, then the trust-region solver on
//!   the closed-loop simulation error of the whole estimation log), scipy's peer
//!   `peer_evvt_baseline.py`;
//! - the positioner's Coulomb-friction fit on the EMPS benchmark (IDIM-LS: filters,
//!   derivatives, decimation, linear least squares, the validation log predicted), scipy's
//!   peer `peer_positioner_idim.py` (skipped with a message without ../shared); and its
//!   least-squares solve alone on the same regression, scipy's `least_squares` timed alone.
//!
//! `cargo bench -p hil-host --bench peer_evvt_baseline`
//!
//! The log is `hil-host generate evvt none --seed 33` (22 500 estimation samples at 100 Hz).
//! The timed part is `Family::fit` with no effect on a fresh family: the grid, the solver, and
//! the prediction of the validation log (one simulation, which the Python peer does not do).
use criterion::{criterion_group, criterion_main, Criterion};
use hil_host::diagnose::family_for;
use hil_host::generate;
use hil_host::log::{read_log, Plant};
use std::path::PathBuf;

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

fn bench_positioner(c: &mut Criterion) {
    let shared = std::env::var_os("SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let dir = shared.join("data/emps");
    let (Ok(est), Ok(val)) = (
        read_log(&dir.join("emps-estimation.csv"), None),
        read_log(&dir.join("emps-validation.csv"), None),
    ) else {
        eprintln!("skipped: the EMPS logs are not in {} (set SHARED_DIR)", dir.display());
        return;
    };
    c.bench_function("positioner coulomb-friction fit, EMPS 2 x 24 841 samples", |b| {
        b.iter(|| {
            let family = family_for(Plant::Positioner).expect("positioner family");
            let fit = family.fit(&["coulomb-friction"], None, &est, &val).expect("fit");
            assert!((fit.params[0].1 - 95.067).abs() < 0.01, "{:?}", fit.params);
            fit
        })
    });
    // The least-squares solve alone, on the same decimated regression (scipy's
    // `least_squares` on `A θ - y` is timed alone the same way by the peer script).
    let family = hil_host::diagnose::positioner::PositionerFamily::default();
    let (cols, y) = family
        .idim_regression(&est, Some("coulomb-friction"))
        .expect("EMPS regression");
    c.bench_function("positioner coulomb-friction least squares alone, EMPS", |b| {
        b.iter(|| {
            let theta = hil_host::lsq::linear_lsq(&cols, &y).expect("solve");
            assert!((theta[0] - 95.067).abs() < 0.01, "{theta:?}");
            theta
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench, bench_positioner
}
criterion_main!(benches);
