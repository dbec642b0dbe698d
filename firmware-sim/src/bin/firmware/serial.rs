//! USART1 (PA9 TX, PA10 RX, AF7) at [`BAUD`]: bytes in and out through lock-free queues, moved
//! by the USART's interrupt.
//!
//! Receive: every byte goes from the data register to the [`RxQueue`] at once (the USART holds
//! one byte; the interrupt runs above the loop's timer so that a step never makes it lose one).
//! Transmit: the main loop queues a frame's bytes and pends the interrupt, which sends one byte
//! per "transmit register empty" and masks that event when the queue is empty. The main loop
//! sees the port as `embedded-io`'s `Read`, `ReadReady` and `Write` ([`SerialPort`]); the link's
//! framing ([`firmware_sim::link`]) is its own.

use core::cell::RefCell;

use cortex_m::interrupt::Mutex;
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4::stm32f405 as pac;
use stm32f4::stm32f405::interrupt;

/// The link's rate: 84 MHz / 2 Mbaud = 42 exactly (RM0090 30.3.4, oversampling by 16). A frame
/// of about 80 bytes each way per 1 ms step needs 0.8 Mbaud; USB-serial bridges (FT232H,
/// CP2102N) do 2 Mbaud or more.
pub const BAUD: u32 = 2_000_000;
/// APB2's clock (USART1's), Hz.
const APB2_HZ: u32 = 84_000_000;

/// Received bytes not yet read by the main loop (several frames).
pub const RX_CAPACITY: usize = 1024;
/// Bytes waiting to be sent (several estimate frames).
pub const TX_CAPACITY: usize = 1024;

/// Bytes from the USART to the main loop.
pub type RxQueue = Queue<u8, RX_CAPACITY>;
/// Bytes from the main loop to the USART.
pub type TxQueue = Queue<u8, TX_CAPACITY>;

/// What the interrupt owns.
struct Port {
    usart: pac::USART1,
    rx: Producer<'static, u8>,
    tx: Consumer<'static, u8>,
    /// Bytes lost: the receive queue was full, or the USART overran.
    lost: u32,
}

/// The interrupt's state, handed over once by [`start`].
static PORT: Mutex<RefCell<Option<Port>>> = Mutex::new(RefCell::new(None));

/// The main loop's end of the port.
pub struct SerialPort {
    rx: Consumer<'static, u8>,
    tx: Producer<'static, u8>,
}

impl embedded_io::ErrorType for SerialPort {
    type Error = core::convert::Infallible;
}

impl embedded_io::ReadReady for SerialPort {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.rx.ready())
    }
}

impl embedded_io::Read for SerialPort {
    /// Waits for at least one byte (call [`embedded_io::ReadReady::read_ready`] first not to).
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        let mut n = 0;
        while n == 0 {
            for slot in buf.iter_mut() {
                let Some(byte) = self.rx.dequeue() else { break };
                *slot = byte;
                n += 1;
            }
        }
        Ok(n)
    }
}

impl embedded_io::Write for SerialPort {
    /// Queues what fits (waiting for room for at least one byte) and starts sending.
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let mut n = 0;
        for &byte in buf {
            if self.tx.enqueue(byte).is_err() {
                if n > 0 {
                    break;
                }
                while self.tx.enqueue(byte).is_err() {
                    kick();
                }
            }
            n += 1;
        }
        kick();
        Ok(n)
    }

    /// Waits until every queued byte is in the USART.
    fn flush(&mut self) -> Result<(), Self::Error> {
        while !self.tx.is_empty() {
            kick();
        }
        Ok(())
    }
}

/// Configures PA9/PA10 and USART1, hands the USART and the queues' interrupt ends to the
/// interrupt, and enables it; returns the main loop's end.
pub fn start(usart: pac::USART1, gpioa: &pac::GPIOA, rx: &'static mut RxQueue, tx: &'static mut TxQueue) -> SerialPort {
    gpioa.moder().modify(|_, w| w.moder9().alternate().moder10().alternate());
    gpioa.afrh().modify(|_, w| w.afrh9().af7().afrh10().af7());
    usart.brr().write(|w| unsafe { w.bits((APB2_HZ / BAUD) as u16) });
    usart.cr1().write(|w| w.ue().set_bit().te().set_bit().re().set_bit().rxneie().set_bit());
    let (rx_producer, rx_consumer) = rx.split();
    let (tx_producer, tx_consumer) = tx.split();
    cortex_m::interrupt::free(|cs| {
        PORT.borrow(cs).replace(Some(Port { usart, rx: rx_producer, tx: tx_consumer, lost: 0 }));
    });
    SerialPort { rx: rx_consumer, tx: tx_producer }
}

/// Starts sending what the main loop queued.
pub fn kick() {
    cortex_m::peripheral::NVIC::pend(pac::Interrupt::USART1);
}

/// Bytes lost on reception so far.
pub fn lost() -> u32 {
    cortex_m::interrupt::free(|cs| PORT.borrow(cs).borrow().as_ref().map_or(0, |port| port.lost))
}

#[interrupt]
fn USART1() {
    cortex_m::interrupt::free(|cs| {
        let mut port = PORT.borrow(cs).borrow_mut();
        let Some(port) = port.as_mut() else { return };
        loop {
            let status = port.usart.sr().read();
            if status.rxne().bit_is_set() || status.ore().bit_is_set() {
                // Reading SR then DR clears both flags (RM0090 30.6.1).
                let byte = port.usart.dr().read().dr().bits() as u8;
                if status.ore().bit_is_set() || port.rx.enqueue(byte).is_err() {
                    port.lost = port.lost.wrapping_add(1);
                }
                continue;
            }
            if status.txe().bit_is_set() {
                if let Some(byte) = port.tx.dequeue() {
                    port.usart.dr().write(|w| w.dr().set(u16::from(byte)));
                    port.usart.cr1().modify(|_, w| w.txeie().set_bit());
                    continue;
                }
                port.usart.cr1().modify(|_, w| w.txeie().clear_bit());
            }
            break;
        }
    });
}
