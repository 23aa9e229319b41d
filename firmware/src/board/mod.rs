//! Boards: the hardware behind the traits of `model_core::ecu::board` and
//! `model_core::ecu::schedule` (the parts' boards). `ecu` is the real STM32F405RG board; the
//! tasks in `crate::tasks` are written against the traits only.

pub mod ecu;

use model_core::ecu::board::Clock;
use model_core::ecu::schedule::EhvvaBoard;

/// The EHVVA part's board plus its clock (the capture timer) and the one async operation:
/// sleep until an edge or `wake_at_us`.
pub trait EhvvaIo: EhvvaBoard + Clock {
    /// Returns when a crank edge was captured or the clock reached `wake_at_us`.
    async fn wait_edge_or(&mut self, wake_at_us: u32);
}

/// The embassy time base as a [`Clock`] (any board with an embassy time driver).
pub struct EmbassyClock;
impl Clock for EmbassyClock {
    fn now_us(&self) -> u32 {
        // Wrapping to 32 bits is what the model-core clock contract expects.
        embassy_time::Instant::now().as_micros() as u32
    }
}
