//! The ECU core on QEMU's netduinoplus2 (emulated STM32F405RG) for processor-in-the-loop runs:
//! the host sends a sensor frame over USART1 each lockstep step, the firmware runs
//! [`EcuCore::step`] and answers the actuator frame (`lockstep`). Started with the semihosting
//! argument `bench`, it first runs the instruction-count bench (`bench`) and then serves the
//! link with markers around every task.
//!
//! Board specifics (SysTick time driver, USART1, executor) are in `board`; defmt goes out over
//! semihosting (`-semihosting-config enable=on,target=native`, decode with `defmt-print`).
#![no_std]
#![no_main]

mod bench;
mod board;
mod calibration;
mod lockstep;

use core::panic::PanicInfo;

use cortex_m_rt::entry;
use defmt_semihosting as _;
use model_core::ecu::frame::{encode, Frame, MAX_FRAME_BYTES};
use model_core::ecu::lockstep::EcuCore;

use board::Link;
use lockstep::Server;

defmt::timestamp!("{=u64:us}", embassy_time::Instant::now().as_micros());

/// How the host started us (semihosting command line).
#[derive(Clone, Copy, PartialEq, Eq, defmt::Format)]
enum Mode {
    Lockstep,
    Bench,
}

fn mode_from_command_line() -> Mode {
    match semihosting::experimental::env::args::<128>() {
        Ok(args) => {
            if (&args).into_iter().any(|a| a == Ok("bench")) {
                Mode::Bench
            } else {
                Mode::Lockstep
            }
        }
        Err(_) => Mode::Lockstep,
    }
}

#[embassy_executor::task]
async fn lockstep_task(mut link: Link, mut server: Server, mode: Mode) -> ! {
    match mode {
        Mode::Lockstep => lockstep::serve(&mut link, &mut server, |core, s| core.step(s)).await,
        Mode::Bench => {
            if let Err(what) = bench::run_plants(&mut link) {
                defmt::error!("plant bench: {=str}", what);
            }
            lockstep::serve(&mut link, &mut server, bench::counted_step).await
        }
    }
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        halt("core peripherals taken twice")
    };
    let board = board::init(core);
    let mode = mode_from_command_line();
    let ecu = match EcuCore::new(calibration::load()) {
        Ok(ecu) => ecu,
        Err(what) => halt(what),
    };
    defmt::info!("netduinoplus2: ECU core up, mode {}", mode);
    match lockstep_task(board.link, Server::new(ecu), mode) {
        Ok(t) => board.spawner.spawn(t),
        Err(_) => halt("task spawn"),
    }
    board::idle()
}

/// Start-up failed (a calibration that does not validate): the outputs are reported safe
/// once and nothing runs.
fn halt(what: &str) -> ! {
    send_safe_outputs();
    defmt::error!("halted: {=str}; outputs safe", what);
    board::idle()
}

/// The safe state on the link, by register writes only (usable in the panic handler).
fn send_safe_outputs() {
    let mut out = [0u8; MAX_FRAME_BYTES];
    if let Ok(n) = encode(&Frame::Actuator(EcuCore::safe_outputs(0, 0)), &mut out) {
        board::usart1::write_blocking(&out[..n]);
    }
}

/// Outputs safe first, then the message; interrupts stay off so no task drives them again.
#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    send_safe_outputs();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    loop {
        cortex_m::asm::wfi();
    }
}
