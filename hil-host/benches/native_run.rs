//! Native HIL speed: simulated seconds per wall second of `hil-host run`, the ECU's EcuCore in
//! lockstep every 50 µs with the plants (EHVVA at 10 µs, EVVT and vacuum at 0.5 ms).
//! `cargo bench -p hil-host --bench native_run`
//!
//! One iteration runs the first simulated second of the default scenario (20 000 lockstep
//! steps, logs kept, nothing written); simulated s per wall s = 1 / the time per iteration.
//! The throughput is reported in lockstep steps.
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hil_host::run::{run_with, NativeLink, RunOptions, Scenario};

fn native_run(c: &mut Criterion) {
    let sc = Scenario::default_scenario();
    let mut g = c.benchmark_group("native_run");
    g.sample_size(20);
    g.throughput(Throughput::Elements(20_000));
    g.bench_function("default_scenario_first_1s", |b| {
        b.iter(|| {
            let mut link = NativeLink::new().unwrap();
            let o = run_with(
                &sc,
                &mut link,
                &RunOptions {
                    until_s: Some(1.0),
                    keep_frames: false,
                },
            )
            .unwrap();
            std::hint::black_box(o.summary.ehvva_events)
        })
    });
    g.finish();
}

criterion_group!(benches, native_run);
criterion_main!(benches);
