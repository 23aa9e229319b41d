//! Test support: the models' Q16.16 lift against their f64 lift over Table 1's envelope
//! (`q16_lift_tracks_f64_over_the_envelope` in reduced.rs, `q16_lpv_lift_tracks_f64_over_the_envelope`
//! in lpv.rs).

use proptest::prelude::*;

use super::{EhvvaInputs, EhvvaParams, EhvvaPlant};
use crate::real::{Real, Q16};

/// An operating point of Table 1's envelope and how many 10 µs steps the pilot is on.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Case {
    pub p_supply_mpa: f64,
    pub p_back_mpa: f64,
    pub temp_c: f64,
    pub lift_high: bool,
    pub snubber_on: bool,
    pub on_steps: usize,
}

/// Table 1's envelope: supply 5.5-8 MPa, back pressure 1-4 MPa, -20..100 °C, both lifts and
/// switch states, an 8-20 ms event.
pub(crate) fn cases() -> impl Strategy<Value = Case> {
    (
        5.5f64..8.0,
        1.0f64..4.0,
        -20.0f64..100.0,
        any::<bool>(),
        any::<bool>(),
        800usize..2000,
    )
        .prop_map(
            |(p_supply_mpa, p_back_mpa, temp_c, lift_high, snubber_on, on_steps)| Case {
                p_supply_mpa,
                p_back_mpa,
                temp_c,
                lift_high,
                snubber_on,
                on_steps,
            },
        )
}

/// The largest deviation of a model's Q16.16 lift from its f64 lift over one event and the
/// closing after it, as a fraction of the stroke. Both run at the target's 10 µs step and on
/// the inputs as Q16.16 holds them, so that the comparison is of the arithmetic, not of the
/// rounding of a constant.
pub(crate) fn q16_lift_deviation<F: EhvvaPlant<f64>, Q: EhvvaPlant<Q16>>(
    c: Case,
    make_f64: impl Fn(&EhvvaParams, &EhvvaInputs<f64>, f64) -> F,
    make_q16: impl Fn(&EhvvaParams, &EhvvaInputs<Q16>, f64) -> Q,
) -> f64 {
    let p = EhvvaParams::paper_default();
    let q = Q16::from_f64;
    let qi = EhvvaInputs::<Q16> {
        p_supply_mpa: q(c.p_supply_mpa),
        p_back_mpa: q(c.p_back_mpa),
        temp_c: q(c.temp_c),
        lift_high: c.lift_high,
        snubber_on: c.snubber_on,
    };
    let fi = EhvvaInputs::<f64> {
        p_supply_mpa: qi.p_supply_mpa.to_f64(),
        p_back_mpa: qi.p_back_mpa.to_f64(),
        temp_c: qi.temp_c.to_f64(),
        lift_high: c.lift_high,
        snubber_on: c.snubber_on,
    };
    let dt_ms = q(0.01).to_f64();
    let (mut float, mut fixed) = (make_f64(&p, &fi, dt_ms), make_q16(&p, &qi, dt_ms));
    let mut worst: f64 = 0.0;
    for k in 0..c.on_steps + 2600 {
        let u = (100..100 + c.on_steps).contains(&k);
        let y = float.step(u, &fi);
        worst = worst.max((fixed.step(u, &qi).to_f64() - y).abs());
    }
    worst / p.stroke_mm(c.lift_high)
}

/// The corners' grid the tests' comments quote: supply 5.5/6.75/8 MPa, back pressure
/// 1/2.5/4 MPa, -20/40/100 °C, both lifts and switch states, 8 and 20 ms events.
#[cfg(feature = "std")]
pub(crate) fn grid() -> impl Iterator<Item = Case> {
    (0..3 * 3 * 3 * 8).map(|i| Case {
        p_supply_mpa: [5.5, 6.75, 8.0][i % 3],
        p_back_mpa: [1.0, 2.5, 4.0][i / 3 % 3],
        temp_c: [-20.0, 40.0, 100.0][i / 9 % 3],
        lift_high: i / 27 % 2 == 1,
        snubber_on: i / 54 % 2 == 1,
        on_steps: [800, 2000][i / 108 % 2],
    })
}

/// Prints the largest Q16.16-vs-f64 lift deviation of both models over [`grid`] (the numbers
/// the property tests' comments quote): `cargo test --release -p model-core --features std
/// --lib q16_deviation_on_the_corners_grid -- --ignored --nocapture`.
#[cfg(feature = "std")]
#[test]
#[ignore]
fn q16_deviation_on_the_corners_grid() {
    use crate::ehvva::{EhvvaLpv, EhvvaReduced};
    let worst = |dev: &dyn Fn(Case) -> f64| grid().map(dev).fold(0.0f64, f64::max);
    let reduced = worst(&|c| {
        q16_lift_deviation(
            c,
            |p, i, dt| EhvvaReduced::<f64>::new(p, i, dt).unwrap(),
            |p, i, dt| EhvvaReduced::<Q16>::new(p, i, dt).unwrap(),
        )
    });
    let lpv = worst(&|c| {
        q16_lift_deviation(
            c,
            |p, i, dt| EhvvaLpv::<f64>::new(p, i, dt).unwrap(),
            |p, i, dt| EhvvaLpv::<Q16>::new(p, i, dt).unwrap(),
        )
    });
    std::println!(
        "largest lift deviation, % of the stroke: reduced {:.4}, LPV {:.4}",
        100.0 * reduced,
        100.0 * lpv
    );
    assert!(reduced <= 0.001 && lpv <= 0.001);
}
