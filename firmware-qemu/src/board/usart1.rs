//! USART1 as the lockstep link: every received byte is taken by the RXNE interrupt into a ring
//! buffer (QEMU models no DMA and never signals an idle line, so bytes are read as they come);
//! sending writes the data register byte by byte (QEMU's USART sends synchronously, TXE is
//! always set, so this never waits there; on silicon it waits one character per byte).
use core::cell::RefCell;
use core::future::poll_fn;
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Poll;

use critical_section::Mutex;
use embassy_sync::waitqueue::AtomicWaker;
use heapless::Deque;
use stm32_metapac::{self as pac, interrupt};

/// Bytes buffered between the interrupt and the task: more than two of the largest frames.
const RX_CAPACITY: usize = 512;

static RX: Mutex<RefCell<Deque<u8, RX_CAPACITY>>> = Mutex::new(RefCell::new(Deque::new()));
static RX_WAKER: AtomicWaker = AtomicWaker::new();
/// Bytes lost because the ring buffer was full (the frame they belonged to fails its CRC).
static RX_DROPPED: AtomicU32 = AtomicU32::new(0);

/// The link's receive side (the ring buffer) and send side (the data register).
pub struct Link {
    _private: (),
}

impl Link {
    /// Enables USART1 (8N1; the baud rate is not modelled by QEMU, 115 200 Bd is set for
    /// silicon at PCLK2 = 84 MHz) with the receive interrupt.
    pub(super) fn init() -> Link {
        pac::RCC.apb2enr().modify(|w| w.set_usart1en(true));
        let usart = pac::USART1;
        // 84 MHz / (16 * 115 200) = 45.57: mantissa 45, fraction 9/16.
        usart.brr().write(|w| w.0 = (45 << 4) | 9);
        usart.cr1().write(|w| {
            w.set_ue(true);
            w.set_te(true);
            w.set_re(true);
            // Only RXNE: QEMU raises the interrupt for TXE and TC too when enabled, and TXE is
            // always set there.
            w.set_rxneie(true);
        });
        // SAFETY: the handler below only touches the ring buffer, under a critical section.
        unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
        Link { _private: () }
    }

    /// The next received byte (waits for it).
    pub async fn read_byte(&mut self) -> u8 {
        poll_fn(|cx| {
            RX_WAKER.register(cx.waker());
            match critical_section::with(|cs| RX.borrow(cs).borrow_mut().pop_front()) {
                Some(b) => Poll::Ready(b),
                None => Poll::Pending,
            }
        })
        .await
    }

    /// Sends the bytes (returns when the last one is in the data register).
    pub fn write(&mut self, bytes: &[u8]) {
        write_blocking(bytes);
    }
}

/// Received bytes lost to a full buffer since start.
pub fn rx_dropped() -> u32 {
    RX_DROPPED.load(Ordering::Relaxed)
}

/// Register writes only, no state: usable from the panic handler.
pub fn write_blocking(bytes: &[u8]) {
    let usart = pac::USART1;
    for &b in bytes {
        while !usart.sr().read().txe() {}
        usart.dr().write(|w| w.set_dr(u16::from(b)));
    }
}

#[interrupt]
fn USART1() {
    let usart = pac::USART1;
    // Reading SR then DR clears RXNE (and an overrun flag with it).
    let sr = usart.sr().read();
    if sr.rxne() || sr.ore() {
        let byte = usart.dr().read().dr() as u8;
        let stored = critical_section::with(|cs| RX.borrow(cs).borrow_mut().push_back(byte).is_ok());
        if !stored {
            RX_DROPPED.fetch_add(1, Ordering::Relaxed);
        }
        RX_WAKER.wake();
    }
}
