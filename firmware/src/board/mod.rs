//! Boards: the hardware behind the traits of `model_core::ecu::board`. `ecu` is the real
//! STM32F405RG board; an emulated board (QEMU issue) implements the same traits plus
//! [`EhvvaIo`] and [`AdcBank`], and the tasks in `crate::tasks` run unchanged on it.

pub mod ecu;

use model_core::ecu::board::{AnalogIn, Capture, Clock, SolenoidDriver, SwitchOut};

/// Everything the EHVVA task touches: the capture timer (also its clock), the pilot driver
/// and the two slow valves, plus the one async operation: sleep until an edge or `wake_at_us`.
pub trait EhvvaIo: Capture + Clock {
    type Pilot: SolenoidDriver;
    type Switch: SwitchOut;
    /// Returns when a crank edge was captured or the clock reached `wake_at_us`.
    async fn wait_edge_or(&mut self, wake_at_us: u32);
    fn pilot(&mut self) -> &mut Self::Pilot;
    fn lift_valve(&mut self) -> &mut Self::Switch;
    fn snubber_valve(&mut self) -> &mut Self::Switch;
}

/// The supervisor's analog inputs, one [`AnalogIn`] per `Channel` index (one short blocking
/// conversion per read, so the other tasks are never held up by a whole scan).
pub trait AnalogBank {
    type In<'a>: AnalogIn
    where
        Self: 'a;
    fn analog(&mut self, index: usize) -> Self::In<'_>;
}

/// The embassy time base as a [`Clock`] (any board with an embassy time driver).
pub struct EmbassyClock;
impl Clock for EmbassyClock {
    fn now_us(&self) -> u32 {
        // Wrapping to 32 bits is what the model-core clock contract expects.
        embassy_time::Instant::now().as_micros() as u32
    }
}
