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
