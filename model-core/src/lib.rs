//! Actuator plant models, their building blocks and controllers for the engine's actuator
//! controllers: no_std, no heap, no unsafe. The firmware wires peripherals to these types; the
//! host tools run the very same code against simulated and measured data.
//!
//! Layout: one module per actuator's physics (`ehvva`, `evvt`, `vacuum`, `positioner`), one per
//! building block (`delay`, `lut`, `pwm_comp`, `peak_hold`, `prbs`), one per controller under
//! `control`. Models are generic over [`Real`] (f32, f64, Q32.32).
#![no_std]
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
extern crate std;

pub mod control;
pub mod delay;
pub mod ecu;
pub mod ehvva;
pub mod evvt;
pub mod lut;
pub mod peak_hold;
pub mod plant_bench;
pub mod positioner;
pub mod prbs;
pub mod pwm_comp;
pub mod real;
pub mod vacuum;

pub use real::{Real, Q16, Q32};
