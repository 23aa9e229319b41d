//! ECU firmware (STM32F405RG, embassy): one task per actuator plus a supervisor. All control
//! logic is in `model_core::ecu` (host-tested); the tasks in `tasks.rs` only move values
//! between the board traits and those state machines.
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
use model_core::ecu::ehvva_task::EhvvaTask;
use model_core::ecu::evvt_task::EvvtTask;
use model_core::ecu::supervisor::Supervisor;
use model_core::ecu::vacuum_task::VacuumTask;
use model_core::ehvva::EhvvaTables;

use board::ecu::{EcuAdc, EcuBoard, EcuEhvvaIo, EcuEvvtIo, EcuVacuumIo};
use board::EmbassyClock;

defmt::timestamp!("{=u64:us}", embassy_time::Instant::now().as_micros());

static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART5() {
    // SAFETY: UART5 is not used as a UART; its vector only runs the high-priority executor.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

#[embassy_executor::task]
async fn ehvva_task(mut io: EcuEhvvaIo, task: EhvvaTask<EhvvaTables<f32>>) -> ! {
    tasks::ehvva(&mut io, task).await
}

#[embassy_executor::task]
async fn evvt_task(mut io: EcuEvvtIo, task: EvvtTask) -> ! {
    let fault_n = io.driver_fault_n;
    tasks::evvt(&mut io.motor, move || fault_n.is_low(), EmbassyClock, task).await
}

#[embassy_executor::task]
async fn vacuum_task(mut io: EcuVacuumIo, task: VacuumTask) -> ! {
    tasks::vacuum(&mut io.valves, &mut io.pump, EmbassyClock, task).await
}

#[embassy_executor::task]
async fn supervisor_task(
    mut adc: EcuAdc,
    mut wdg: embassy_stm32::wdg::IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
    sup: Supervisor,
) -> ! {
    wdg.unleash();
    tasks::supervisor(&mut adc, move || wdg.pet(), EmbassyClock, sup).await
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
    let board = EcuBoard::new(p);

    // The unit's calibration image, or the paper defaults (calibration.rs).
    let cfg = calibration::load();
    let tables = EhvvaTables::<f32>::with_valve_motion(&cfg.ehvva_model, &cfg.ehvva_motion)
        .unwrap_or_else(|_| halt("EHVVA delay tables"));
    let ehvva = EhvvaTask::new(cfg.ehvva, tables).unwrap_or_else(|e| halt(e));
    let evvt = EvvtTask::new(cfg.evvt).unwrap_or_else(|_| halt("EVVT controller"));
    let vacuum = VacuumTask::new(cfg.vacuum).unwrap_or_else(|_| halt("vacuum models"));
    let sup = Supervisor::new(cfg.supervisor);

    interrupt::UART5.set_priority(Priority::P6);
    let high = EXECUTOR_HIGH.start(interrupt::UART5);
    match ehvva_task(board.ehvva, ehvva) {
        Ok(t) => high.spawn(t),
        Err(_) => halt("EHVVA task spawn"),
    }
    match (
        evvt_task(board.evvt, evvt),
        vacuum_task(board.vacuum, vacuum),
        supervisor_task(board.adc, board.watchdog, sup),
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
