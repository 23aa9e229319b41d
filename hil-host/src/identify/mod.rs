//! `identify`: parameter tables for model-core from measured logs (issue 6).

pub mod ehvva;
pub mod evvt;
