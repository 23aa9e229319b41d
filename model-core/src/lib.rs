//! Actuator plant models, their building blocks and controllers for the engine's actuator
//! controllers: no_std, no heap, no unsafe. The firmware wires peripherals to these types; the
//! host tools run the very same code against simulated and measured data.
#![no_std]
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
extern crate std;

pub mod lut;
pub mod real;

pub use real::{Real, Q32};
