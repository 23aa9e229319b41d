//! Issue #12.8's peer comparison, the Rust side of the EHVVA four-knob baseline fit
//! (docs/performance.md has both figures and the commands; the Python side is
//! `tools/py/peer_ehvva_baseline.py` on the same log).
//!
//! `cargo bench -p hil-host --bench peer_ehvva_baseline`
//!
//! The log is `hil-host generate ehvva none --seed 33` (estimation part: 10 480 samples at
//! 20 kHz). The timed part is `Family::fit` with no effect on a fresh family with the paper's
//! calibration only (`unit_baseline: false`): the events cut from the log, the start (td shifted
//! by the mean lift-onset difference of one simulation at the paper's values), the trust-region
//! solver on the four knobs (td, Cd, τp, mass) against the lift simulation error of every event
//! (reduced model eq. (12), 10 sub-steps a sample), its 95 % intervals, and the prediction of the
//! validation log (one simulation, which the Python peer does not do). Each simulation on 2
//! threads by events (the solver's default); the second function on 1 thread, as the Python
//! peer runs.
use criterion::{criterion_group, criterion_main, Criterion};
use hil_host::diagnose::ehvva::{apply_knobs, simulate_all_on, EhvvaFamily, Events, BASELINE_KNOBS};
use hil_host::diagnose::Family;
use hil_host::generate;
use hil_host::log::Plant;
use model_core::ehvva::EhvvaParams;

fn family(threads: usize) -> EhvvaFamily {
    let mut f = EhvvaFamily::default();
    f.unit_baseline = false;
    f.lsq.threads = threads;
    f
}

fn bench(c: &mut Criterion) {
    let case = generate::generate(Plant::Ehvva, "none", 33).expect("generated case");
    let (est, val) = case.logs().expect("generated logs read back");
    let once = family(2).fit(&[], None, &est, &val).expect("baseline fit");
    // The optimum, for the comparison with the peer's.
    eprintln!(
        "ehvva four-knob baseline, {} estimation samples: cost (half sum of squares) {:.9e}, {}",
        est.len(),
        once.est_cost,
        once.convergence
    );
    for (n, v) in &once.params {
        eprintln!("  {n} = {v:.9e}");
    }
    // One simulation of every estimation event at the optimum (the unit of the fit's cost,
    // against the peer's `per_sim_ms`), on 1 thread.
    let set = Events::from_log(&est).expect("events");
    let x: Vec<f64> = once.params.iter().map(|(_, v)| *v).collect();
    let p = apply_knobs(&EhvvaParams::baseline(), &BASELINE_KNOBS, &x);
    let mut sim = vec![0.0; set.samples];
    c.bench_function("ehvva one simulation of the 20 estimation events, 1 thread", |b| {
        b.iter(|| simulate_all_on(&p, &set, &mut sim, 1).expect("simulation"))
    });
    for threads in [2, 1] {
        let name = format!("ehvva four-knob baseline fit, 10 480 samples (seed 33), {threads} thread(s)");
        c.bench_function(&name, |b| {
            b.iter(|| {
                let fit = family(threads).fit(&[], None, &est, &val).expect("baseline fit");
                assert!(
                    (fit.est_cost - once.est_cost).abs() <= 1e-9 * once.est_cost,
                    "{}",
                    fit.est_cost
                );
                fit
            })
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
