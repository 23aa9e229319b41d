//! Host tools around model-core: measured-data logs, closed-loop runs against simulated plants,
//! identification and diagnosis.
pub mod calibrate;
pub mod diagnose;
pub mod generate;
pub mod html;
pub mod identify;
pub mod log;
pub mod lsq;
pub mod mf4;
pub mod numbers;
pub mod output;
pub mod paper_check;
pub mod pil;
pub mod plot;
pub mod residuals;
pub mod run;
pub mod signal;
