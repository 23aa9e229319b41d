//! Electro-hydraulic camless valve actuator (EHVVA), Li, Huang, Zhu, Lou 2018.
//! (parameter table: see below, being filled in)

pub mod event;
pub mod full;
pub mod lpv;
pub mod params;
mod piston;
pub mod reduced;
pub mod tables;

pub use full::EhvvaFull;
pub use event::{run_event, run_event_with, EhvvaPlant, EventMetrics, ValveEvent};
#[cfg(feature = "std")]
pub use event::{mean_relative_error_pct, run_event_trace, EventTrace};
pub use params::{
    EhvvaError, EhvvaInputs, EhvvaParams, EhvvaTableData, EhvvaValveParams, PaperTest, PAPER_TESTS,
};
pub use lpv::{EhvvaLpv, LpvAffine, N_THETA};
pub use reduced::EhvvaReduced;
pub use tables::{t_delay_ms, EhvvaTables};
