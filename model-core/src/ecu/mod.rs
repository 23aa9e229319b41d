//! The ECU firmware's hardware-free logic: one synchronous state machine per task
//! (`fn step(&mut self, inputs, now) -> outputs`), written against the small traits of
//! [`board`], so that the embassy tasks on the ECU board and on an emulated board are a few
//! lines of glue and everything here is tested on the host.
//!
//! - [`ehvva_task`]: crank/cam decoding, valve events in the crank-angle domain advanced by
//!   the LPV model's delay td(Ph, T), pilot peak-and-hold, lift and snubber switch valves.
//! - [`evvt_task`]: cam phase from the edges, scheduled cam phase control, motor speed command.
//! - [`vacuum_task`]: 80 Hz duty from the inverse actuator model with supply-voltage
//!   compensation, pump on the needed pressure, tank leak residual, stuck actuators.
//! - [`supervisor`]: ADC range checks, fault debouncing, the safe state of each actuator.
//!
//! Everything runs in f32 (the target's FPU type).

pub mod board;
pub mod ehvva_task;
pub mod evvt_task;
pub mod supervisor;
pub mod vacuum_task;
