//! The embassy-time driver on SysTick.
//!
//! What QEMU's SysTick counts: with CLKSOURCE = 1 it decrements at the board's `cpuclk`,
//! 168 MHz on the netduinoplus2, of QEMU's *virtual* clock (a `ptimer`). Without `-icount` that
//! clock follows the host's clock while the machine runs, not the instructions executed: a
//! busy guest gets fewer instructions per emulated millisecond, not longer milliseconds. On a
//! heavily loaded host (load 8-10 on 2 cores) emulated time was measured 17-20 % behind host
//! time (10.0 emulated s in 12.2-12.6 host s: QEMU's timer thread serves the periods late).
//! Only the link timeouts and log time stamps use this clock; lockstep time comes from the
//! frames.
//!
//! SysTick is 24 bit: it reloads every [`PERIOD_MS`] ms and its interrupt counts the periods;
//! `now` adds the count down within the period (1 µs resolution). Alarms are checked in that
//! interrupt, so a timer fires on the first period boundary at or after its deadline (10 ms
//! resolution: plenty for the 100 ms link timeout).
use core::cell::{Cell, RefCell};
use core::task::Waker;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;
use critical_section::{CriticalSection, Mutex};
use embassy_time_driver::{Driver, TICK_HZ};
use embassy_time_queue_utils::Queue;

use super::CORE_CLOCK_HZ;

/// SysTick period (the alarm resolution).
pub const PERIOD_MS: u32 = 10;
/// Core clocks per SysTick period.
const CLOCKS_PER_PERIOD: u32 = CORE_CLOCK_HZ / 1000 * PERIOD_MS;
/// Core clocks per embassy-time tick (1 µs at the default 1 MHz tick rate).
const CLOCKS_PER_TICK: u64 = CORE_CLOCK_HZ as u64 / TICK_HZ;
const _: () = assert!((CORE_CLOCK_HZ as u64).is_multiple_of(TICK_HZ) && CLOCKS_PER_PERIOD <= 1 << 24);

struct SysTickDriver {
    /// Completed SysTick periods since start.
    periods: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
    /// The earliest deadline in the queue (u64::MAX when none).
    next_alarm_tick: Mutex<Cell<u64>>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    periods: Mutex::new(Cell::new(0)),
    queue: Mutex::new(RefCell::new(Queue::new())),
    next_alarm_tick: Mutex::new(Cell::new(u64::MAX)),
});

impl SysTickDriver {
    fn now_in(&self, cs: CriticalSection) -> u64 {
        // The interrupt cannot run inside the critical section, so a wrap shows as the pending
        // flag (or as the count jumping up between the two reads); then the second reading
        // belongs to the next period.
        let periods = self.periods.borrow(cs).get();
        let first = SYST::get_current();
        let wrapped = SCB::is_pendst_pending();
        let second = SYST::get_current();
        let (periods, current) = if wrapped || second > first {
            (periods + 1, second)
        } else {
            (periods, first)
        };
        let clocks = periods * CLOCKS_PER_PERIOD as u64 + u64::from(CLOCKS_PER_PERIOD - 1 - current);
        clocks / CLOCKS_PER_TICK
    }

    fn on_period(&self, cs: CriticalSection) {
        let periods = self.periods.borrow(cs);
        periods.set(periods.get() + 1);
        let now = self.now_in(cs);
        if now >= self.next_alarm_tick.borrow(cs).get() {
            let next = self.queue.borrow(cs).borrow_mut().next_expiration(now);
            self.next_alarm_tick.borrow(cs).set(next);
        }
    }
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.now_in(cs))
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let mut queue = self.queue.borrow(cs).borrow_mut();
            if queue.schedule_wake(at, waker) {
                // Deadlines already passed are woken here, the rest on a period boundary.
                let next = queue.next_expiration(self.now_in(cs));
                self.next_alarm_tick.borrow(cs).set(next);
            }
        })
    }
}

/// Starts SysTick from the core clock with its interrupt every period.
pub fn start(syst: &mut SYST) {
    syst.disable_counter();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CLOCKS_PER_PERIOD - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

#[exception]
fn SysTick() {
    critical_section::with(|cs| DRIVER.on_period(cs));
}
