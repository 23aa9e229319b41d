//! What is particular to QEMU's `netduinoplus2` (an STM32F405 with a Cortex-M4F): the clock
//! QEMU runs SysTick from, the time driver built on it, USART1 as the lockstep link, and how
//! the executor sleeps. The application sees [`Link`] (bytes in and out), embassy-time and a
//! spawner.
//!
//! What QEMU models and what not (QEMU 10.0, `hw/arm/stm32f405_soc.c`): no RCC (reads 0,
//! writes ignored: the clock is fixed at 168 MHz by the board), no DMA, no GPIO; TIM2-5 count
//! but raise no compare interrupts; USART1-6 move bytes synchronously (TXE always set, RXNE
//! set per received byte, no idle line); SysTick is the ARMv7-M one.
//!
//! Why an interrupt executor and WFI rather than embassy's thread-mode executor: QEMU runs
//! WFE as a plain yield, so the thread-mode executor's `poll; wfe` loop spins a host core at
//! 100 % while it waits for the link, and that core is then missing for the byte-by-byte
//! character device I/O. WFI halts the emulated CPU until an interrupt is pending.

pub mod systick_time;
pub mod usart1;

use embassy_executor::{InterruptExecutor, SendSpawner};
use stm32_metapac::{interrupt, Interrupt};

pub use usart1::Link;

/// The core clock QEMU's netduinoplus2 feeds the CPU and SysTick (CLKSOURCE = 1) with. SysTick's
/// external reference (CLKSOURCE = 0) runs at a fixed 1/8 of it.
pub const CORE_CLOCK_HZ: u32 = 168_000_000;

/// NVIC priorities (upper 4 bits on the STM32F4; lower number preempts): the link's receive
/// interrupt and SysTick preempt the tasks, so bytes and time keep coming during a long step.
const PRIO_LINK_RX: u8 = 0x40;
const PRIO_SYSTICK: u8 = 0x40;
const PRIO_TASKS: u8 = 0xF0;

/// The tasks run in this vector's handler. UART5 is unused on this board (its USART stays
/// disabled, so nothing but the executor's pender ever raises it).
const EXECUTOR_IRQ: Interrupt = Interrupt::UART5;
static EXECUTOR: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART5() {
    // SAFETY: the vector is reserved for the executor (see EXECUTOR_IRQ).
    unsafe { EXECUTOR.on_interrupt() }
}

/// Everything the application gets from the board, set up once.
pub struct Board {
    pub link: Link,
    pub spawner: SendSpawner,
}

/// Starts the time driver, the link and the executor. Call once.
pub fn init(mut core: cortex_m::Peripherals) -> Board {
    // SAFETY: priorities are set before the interrupts are unmasked; no priority-based
    // critical sections are in use (critical-section masks all interrupts).
    unsafe {
        core.NVIC.set_priority(Interrupt::USART1, PRIO_LINK_RX);
        core.NVIC.set_priority(EXECUTOR_IRQ, PRIO_TASKS);
        core.SCB
            .set_priority(cortex_m::peripheral::scb::SystemHandler::SysTick, PRIO_SYSTICK);
    }
    systick_time::start(&mut core.SYST);
    let link = usart1::Link::init();
    let spawner = EXECUTOR.start(EXECUTOR_IRQ);
    Board { link, spawner }
}

/// Thread mode has nothing to do: sleep until the next interrupt, forever.
pub fn idle() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}
