//! USART0 (Arduino Mega pins D0 = RX = PE0, D1 = TX = PE1, wired to the board's USB serial
//! bridge) at 115200 baud 8N1: transmit through [`ufmt::uWrite`], receive into a queue.
//!
//! Baud rate: with U2X (double speed) `UBRR = 16` gives 16 MHz / (8 · 17) = 117 647 baud, +2.1 %
//! from 115 200 (without U2X the nearest is −3.5 %, too far for reliable 8N1 reception).
//!
//! Bytes go through a 256-byte queue that the data-register-empty interrupt (`USART0_UDRE`)
//! drains, so a report line costs the main loop a few µs instead of 87 µs per character. The
//! longest burst (the `ID` line after the search with the `SEARCH` and `STACK` lines, ~220
//! bytes) fits. When the queue is full the writer waits for room (≤ 22 ms for a whole queue);
//! with interrupts disabled it sends directly instead.
//!
//! Received bytes go into a 64-byte queue filled by the receive-complete interrupt
//! (`USART0_RX`) and read by the main loop ([`receive`]) whenever it waits for a tick and
//! holds no complete command line: at 11.5 bytes per millisecond the queue covers 5.5 ms
//! without a read. A byte that finds the queue full is dropped and the newest byte in the
//! queue replaced by [`LOST`]; a byte received with a hardware overrun or framing error
//! (ATmega2560 datasheet §22.7.4: DOR0, FE0) is queued as [`LOST`]. The marker sits where the
//! bytes went missing, so the damaged command line is refused (`ERR overrun`), not
//! executed, and the lines around it are not.

use avr_device::atmega2560::USART0;
use core::convert::Infallible;
use ridge_pump_firmware::command::LOST;
use ridge_pump_firmware::ring::Ring;

/// The baud rate set by [`Usart0::new`].
pub const BAUD: u32 = 115_200;

// UCSR0A bits (datasheet §22.10.2).
const UDRE0: u8 = 1 << 5;
const FE0: u8 = 1 << 4;
const DOR0: u8 = 1 << 3;
const U2X0: u8 = 1 << 1;
// UCSR0B bits (datasheet §22.10.3).
const RXCIE0: u8 = 1 << 7;
const UDRIE0: u8 = 1 << 5;
const RXEN0: u8 = 1 << 4;
const TXEN0: u8 = 1 << 3;
// UCSR0C: asynchronous, no parity, 1 stop bit, 8 data bits (UCSZ01:00 = 11).
const UCSR0C_8N1: u8 = 0b0000_0110;

/// Transmit queue, drained by `USART0_UDRE`.
static TX: Ring<256> = Ring::new();

/// Receive queue, filled by `USART0_RX`.
static RX: Ring<64> = Ring::new();

/// The next received byte, if any (main loop only).
pub fn receive() -> Option<u8> {
    RX.pop()
}

/// Free bytes in the transmit queue.
pub fn tx_room() -> usize {
    TX.room()
}

/// USART0 transmitter.
pub struct Usart0 {
    usart: USART0,
}

impl Usart0 {
    /// Sets up 115200 8N1 with U2X and enables the transmitter and the receiver with its
    /// interrupt.
    pub fn new(usart: USART0) -> Self {
        let ubrr = (super::F_CPU + 4 * BAUD) / (8 * BAUD) - 1; // 16
        usart.ubrr0().write(|w| unsafe { w.bits(ubrr as u16) });
        usart.ucsr0a().write(|w| unsafe { w.bits(U2X0) });
        usart.ucsr0c().write(|w| unsafe { w.bits(UCSR0C_8N1) });
        usart
            .ucsr0b()
            .write(|w| unsafe { w.bits(TXEN0 | RXEN0 | RXCIE0) });
        Usart0 { usart }
    }

    fn write_byte(&mut self, byte: u8) {
        while !TX.push(byte) {
            if !avr_device::interrupt::is_enabled() {
                // Nobody drains the queue: send its oldest byte here.
                if let Some(old) = TX.pop() {
                    // SAFETY: interrupts are off, so the ISR (the only other consumer) cannot run.
                    unsafe { send_polled(old) };
                }
            }
        }
        avr_device::interrupt::free(|_| {
            self.usart
                .ucsr0b()
                .modify(|r, w| unsafe { w.bits(r.bits() | UDRIE0) });
        });
    }
}

impl ufmt::uWrite for Usart0 {
    type Error = Infallible;

    fn write_str(&mut self, s: &str) -> Result<(), Infallible> {
        for &byte in s.as_bytes() {
            self.write_byte(byte);
        }
        Ok(())
    }
}

/// Sends one byte by polling UDRE0 (bounded: ~200 µs, longer than one character), e.g. from the
/// panic handler. Does nothing if the transmitter is not enabled.
///
/// # Safety
///
/// Accesses USART0 behind its owner's back: only with interrupts disabled, from code that the
/// owner will not resume (panic handler) or while the owner waits.
pub unsafe fn send_polled(byte: u8) {
    // SAFETY: see the function's contract.
    let usart = unsafe { &*USART0::ptr() };
    if usart.ucsr0b().read().bits() & TXEN0 == 0 {
        return;
    }
    for _ in 0..1_000u16 {
        if usart.ucsr0a().read().bits() & UDRE0 != 0 {
            usart.udr0().write(|w| unsafe { w.bits(byte) });
            return;
        }
    }
}

/// A `ufmt::uWrite` that sends by polling ([`send_polled`]), for the panic handler.
pub struct Polled;

impl ufmt::uWrite for Polled {
    type Error = Infallible;

    fn write_str(&mut self, s: &str) -> Result<(), Infallible> {
        for &byte in s.as_bytes() {
            // SAFETY: only used by the panic handler, with interrupts disabled.
            unsafe { send_polled(byte) };
        }
        Ok(())
    }
}

#[avr_device::interrupt(atmega2560)]
fn USART0_UDRE() {
    // SAFETY: the ISR only touches UDR0 and the UDRIE0 bit; the owner sets UDRIE0 only inside a
    // critical section, so the read-modify-write below cannot interleave with it.
    let usart = unsafe { &*USART0::ptr() };
    match TX.pop() {
        Some(byte) => {
            usart.udr0().write(|w| unsafe { w.bits(byte) });
        }
        None => {
            usart
                .ucsr0b()
                .modify(|r, w| unsafe { w.bits(r.bits() & !UDRIE0) });
        }
    }
}

#[avr_device::interrupt(atmega2560)]
fn USART0_RX() {
    // SAFETY: the ISR only reads UCSR0A and UDR0 (reading UDR0 clears the interrupt); the
    // owner never reads them.
    let usart = unsafe { &*USART0::ptr() };
    // The status bits belong to the byte in UDR0: read them first (datasheet §22.7.4).
    let status = usart.ucsr0a().read().bits();
    let byte = usart.udr0().read().bits();
    let byte = if status & (FE0 | DOR0) != 0 {
        LOST
    } else {
        byte
    };
    if !RX.push(byte) {
        RX.replace_newest(LOST);
    }
}
