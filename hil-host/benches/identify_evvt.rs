//! `identify evvt` on one closed-loop PRBS log of the design table (1100 rpm, 11.5 V, 204 s at
//! 100 Hz, cam-event sampling, 0.3 deg noise, 1 deg quantization): the PRBS correlation, the
//! Hankel SVD and realization, the poles, the indirect approach and the continuous-time fit.
//! Generation and parsing are outside the timing.
//! `cargo bench -p hil-host --bench identify_evvt`
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use hil_host::generate::evvt::{identification_log, IdentificationExperiment};
use hil_host::identify::evvt::{identify_log, EvvtIdentifyOptions};
use hil_host::log::parse_log;

fn bench(c: &mut Criterion) {
    let x = IdentificationExperiment {
        engine_rpm: 1100.0,
        u_batt_v: 11.5,
        seed: 3,
        ..Default::default()
    };
    let text = identification_log(&x).expect("log generates");
    let log = parse_log("prbs.csv", &text, None).expect("log reads back");
    let opts = EvvtIdentifyOptions::default();
    let mut g = c.benchmark_group("identify_evvt");
    g.sample_size(20).measurement_time(Duration::from_secs(10));
    g.bench_function("one PRBS log (20 400 rows), paper's method", |b| {
        b.iter(|| identify_log(&log, &opts).expect("identifies"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
