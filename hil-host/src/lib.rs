//! Host tools around model-core: measured-data logs, closed-loop runs against simulated plants,
//! identification and diagnosis.
pub mod log;
pub mod lsq;
pub mod residuals;
pub mod signal;
