//! ECU firmware (STM32F405RG, embassy): one task per part of the ECU's one composition
//! (`model_core::ecu::schedule::Ecu`: supervisor, EHVVA, EVVT, vacuum). The composition (periods,
//! input assembly, safe states, watchdog decision) is in model-core and is what `hil-host run`
//! and the QEMU image run too; the tasks in `tasks.rs` are a timer and a call of the part's
//! `run` with this board.
//!
//! Priorities: the EHVVA task runs on an interrupt executor above the others, so that a
//! vacuum model step or an ADC conversion never delays a pilot edge; the rest share the
//! thread-mode executor.
#![no_std]
#![no_main]

mod board;
mod calibration;
mod shared;
mod tasks;

use core::panic::PanicInfo;

use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac;
use model_core::ecu::schedule::{outputs_off, Ecu, EhvvaPart, EvvtPart, SupervisorPart, VacuumPart};

use board::ecu::{EcuAdc, EcuBoard, EcuEhvvaIo, EcuEvvtIo, EcuVacuumIo, EcuWatchdog};
use board::EmbassyClock;

defmt::timestamp!("{=u64:us}", embassy_time::Instant::now().as_micros());

static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART5() {
    // SAFETY: UART5 is not used as a UART; its vector only runs the high-priority executor.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

#[embassy_executor::task]
async fn ehvva_task(mut io: EcuEhvvaIo, part: EhvvaPart) -> ! {
    tasks::ehvva(&mut io, part).await
}

#[embassy_executor::task]
async fn evvt_task(mut io: EcuEvvtIo, part: EvvtPart) -> ! {
    tasks::evvt(&mut io, EmbassyClock, part).await
}

#[embassy_executor::task]
async fn vacuum_task(mut io: EcuVacuumIo, part: VacuumPart) -> ! {
    tasks::vacuum(&mut io, EmbassyClock, part).await
}

#[embassy_executor::task]
async fn supervisor_task(mut adc: EcuAdc, mut wdg: EcuWatchdog, part: SupervisorPart) -> ! {
    wdg.0.unleash();
    tasks::supervisor(&mut adc, &mut wdg, EmbassyClock, part).await
}

/// A calibration that does not validate: outputs stay off, the reason is logged, no task runs.
fn halt(what: &str) -> ! {
    defmt::error!("calibration rejected: {=str}; outputs stay off", what);
    loop {
        cortex_m::asm::wfi();
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::ecu::config());
    if pac::RCC.csr().read().wdgrstf() {
        defmt::warn!("restarted by the watchdog");
    }
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    let mut board = EcuBoard::new(p);
    outputs_off(&mut board.ehvva, &mut board.evvt, &mut board.vacuum);

    // The composition's parts, each moved into its task; their shared values start as
    // `EcuShared::BOOT` in `shared.rs` (every actuator safe until the first supervisor scan).
    let Ecu {
        supervisor,
        ehvva,
        evvt,
        vacuum,
        shared: _,
    } = Ecu::new(calibration::load()).unwrap_or_else(|what| halt(what));

    interrupt::UART5.set_priority(Priority::P6);
    let high = EXECUTOR_HIGH.start(interrupt::UART5);
    match ehvva_task(board.ehvva, ehvva) {
        Ok(t) => high.spawn(t),
        Err(_) => halt("EHVVA task spawn"),
    }
    match (
        evvt_task(board.evvt, evvt),
        vacuum_task(board.vacuum, vacuum),
        supervisor_task(board.adc, board.watchdog, supervisor),
    ) {
        (Ok(a), Ok(b), Ok(c)) => {
            spawner.spawn(a);
            spawner.spawn(b);
            spawner.spawn(c);
        }
        _ => halt("task spawn"),
    }
    defmt::info!("ECU running: EHVVA, EVVT, vacuum, supervisor");
}

/// Outputs safe first (register writes only), then the message; interrupts off so no task
/// drives an output again. The watchdog then restarts the ECU, which starts with all outputs
/// off.
#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    board::ecu::force_outputs_safe();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    loop {
        cortex_m::asm::nop();
    }
}
