//! The fuzz harness the three fuzz targets share (fuzz_reader, fuzz_scenario, fuzz_frame):
//! proptest on stable Rust, each input timed against a hang limit, a one-line tally on stderr.

use std::cell::Cell;
use std::time::{Duration, Instant};

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

/// An input that takes longer than this is a hang (inputs are at most a few kB).
pub const HANG_LIMIT: Duration = Duration::from_secs(2);

/// Runs `check` on `cases` inputs drawn from `strategy`, timing each; fails on the first
/// panic, hang or broken invariant (proptest then shrinks it to a minimal input). `check`
/// returns whether the input was accepted, for the tally.
pub fn fuzz<S: Strategy>(
    name: &str,
    strategy: S,
    cases: u32,
    check: impl Fn(&S::Value) -> Result<bool, TestCaseError>,
) {
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 2000,
        ..Config::default()
    });
    let (inputs, accepted, slowest) = (Cell::new(0u64), Cell::new(0u64), Cell::new(Duration::ZERO));
    let started = Instant::now();
    let result = runner.run(&strategy, |v| {
        let t0 = Instant::now();
        let ok = check(&v)?;
        let took = t0.elapsed();
        if took > HANG_LIMIT {
            return Err(TestCaseError::fail(format!("hang: {took:?} on one input")));
        }
        inputs.set(inputs.get() + 1);
        accepted.set(accepted.get() + u64::from(ok));
        slowest.set(slowest.get().max(took));
        Ok(())
    });
    eprintln!(
        "fuzz {name}: {} inputs ({} accepted), {} panics, 0 hangs (slowest {:.3} ms, limit {} s), {:.1} s wall",
        inputs.get(),
        accepted.get(),
        u8::from(result.is_err()),
        slowest.get().as_secs_f64() * 1e3,
        HANG_LIMIT.as_secs(),
        started.elapsed().as_secs_f64()
    );
    if let Err(e) = result {
        panic!("fuzz {name}: {e}");
    }
}

/// The number of inputs: `FUZZ_CASES` (the documented long run) or the CI default.
pub fn cases(ci: u32) -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(ci)
}
