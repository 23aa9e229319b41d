//! Controllers: setpoint, observe the plant, open-loop part plus closed-loop part, output;
//! with enable conditions and safe default outputs. One file per controller.
pub mod evvt_phase;
pub mod vacuum_position;
