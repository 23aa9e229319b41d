//! Issue 12.8: the diagnosis of an EHVVA bench pair of ~400 000 rows (the Table 1-like test
//! matrix repeated at 20 kHz), every candidate and the selection, as `hil-host diagnose
//! est.csv --validation val.csv` runs it: the estimation record reduced to the part its fits
//! use (`Family::estimation_part`), then `diagnose()`.
//! `cargo bench -p hil-host --bench diagnose_ehvva_400k`
//!
//! Generation and parsing are outside the timing; peak memory is measured on the command
//! (docs/performance.md gives the `/usr/bin/time -v` line), not here.
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use hil_host::diagnose::{diagnose, family_for, Rules};
use hil_host::generate::generate_repeated;
use hil_host::log::Plant;

/// 18 repeats of the 20-event matrix and of the 24-event validation programme: ~208 000 +
/// ~208 000 rows.
const REPEATS: usize = 18;
const SEED: u64 = 21;

fn benches(c: &mut Criterion) {
    let rules = Rules::default();
    let mut group = c.benchmark_group("diagnose_ehvva_400k");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(60));
    for effect in ["none", "pressure-delay", "snubber"] {
        let case = generate_repeated(Plant::Ehvva, effect, SEED, REPEATS).unwrap_or_else(|e| panic!("{effect}: {e}"));
        let (est, val) = case.logs().unwrap_or_else(|e| panic!("{effect}: {e}"));
        let rows = est.len() + val.len();
        let est = family_for(Plant::Ehvva)
            .and_then(|f| f.estimation_part(est))
            .unwrap_or_else(|e| panic!("{effect}: {e}"));
        let family = family_for(Plant::Ehvva).expect("EHVVA has a family");
        let d = diagnose(family.as_ref(), &est, &val, false, &rules, &mut |_| {})
            .unwrap_or_else(|e| panic!("{effect}: {e}"));
        eprintln!(
            "ehvva hidden {effect} (seed {SEED}, {rows} rows; fitted on {}): named {}, gain {:.1} %, verdict {}",
            est.file, d.cause, d.gain_pct, d.verdict
        );
        group.bench_function(effect, |b| {
            b.iter_batched(
                || family_for(Plant::Ehvva).expect("EHVVA has a family"),
                |family| diagnose(family.as_ref(), &est, &val, false, &rules, &mut |_| {}).map(|d| d.gain_pct),
                BatchSize::PerIteration,
            )
        });
    }
    group.finish();
}

criterion_group!(diagnose_ehvva_400k, benches);
criterion_main!(diagnose_ehvva_400k);
