//! A serial line into the simulated MCU's USART0: what a PC's USB-serial bridge sends to the
//! Arduino Mega's RX0 pin, byte by byte at the line's own rate.
//!
//! **Timing.** The line runs at [`BAUD`] (115 200) with 8N1 frames, [`FRAME_BITS`] = 10 bits a
//! byte, back to back: at 16 MHz byte `k` of a transmission that starts at cycle `C` has its
//! start bit at `C + round(k · 10 · 16e6 / 115 200)` = `C + 1 388.9 k` and the last byte's stop
//! bit ends at `C + 1 388.9 n`. A transmission waits for the one before it to end (one wire).
//! Each byte is handed to simavr's UART input IRQ (`UART_IRQ_INPUT`) at its start bit (at the
//! first instruction boundary at or after it: a few cycles late at most).
//!
//! **What simavr then does** (`avr_uart.c`): the byte goes into the UART's 64-entry input FIFO;
//! a receive "pump" raises `RXCn` (and the receive interrupt) one frame time after the FIFO was
//! last empty, then once per frame time while bytes remain. The frame time is the UART's
//! `cycles_per_byte`, which also paces what the firmware transmits ([`UartTiming`]):
//! - simavr's own ([`UartTiming::Simavr`], the bench's default): recomputed only when `UBRRnL`
//!   is written, as `(UBRR + 1) · 8 · 11` or `· 16 · 11` depending on `U2Xn` *at that moment*
//!   (it counts a parity bit in every frame). The firmware writes `UBRR0 = 16` before it sets
//!   `U2X0`, so simavr runs USART0 at 2 992 cycles a byte, 5 348 bytes/s, 2.2 times slower
//!   than the chip in both directions; received bytes reach the firmware 2 992 cycles apart
//!   whatever the line does;
//! - the chip's ([`UartTiming::Chip`], `Machine::uart_chip_timing`):
//!   [`chip_frame_cycles`] from the registers after every write to them, 1 360 cycles (10 bits
//!   at 117 647 baud) for the firmware's settings. The first byte of a burst then reaches the
//!   firmware 1 360 cycles after its start bit (the chip: ~1 300, in the stop bit) and the
//!   following ones at the line's pace (the line's 1 389 cycles a byte are slower than the
//!   receiver's frame), so the firmware sees the line as the chip would.
//!
//! A firmware that reads `UDRn` in its receive interrupt never lets simavr's FIFO fill (nor the
//! chip's 2-byte one). Should it fill, simavr signals `UART_IRQ_OUT_XOFF` (watched by
//! [`UartInput`]); the line keeps sending (the Mega's serial bridge has no flow control), so the
//! byte is lost with `DORn` set, as on the chip, and recorded as [`Delivery::FifoFull`]. A byte
//! sent while the firmware has the receiver off is lost too ([`Delivery::ReceiverOff`]).
//!
//! **Scheduling** ([`SerialLine`]): a transmission starts at a given cycle, or a delay after
//! the first UART line from the firmware that matches a predicate (e.g. "`LOG on` once the
//! board printed its first line", as `ridge-id capture --send` does).

use std::cell::Cell;
use std::collections::VecDeque;
use std::rc::Rc;

use simavr_ffi as ffi;

use crate::transcript::Line;

/// The line's rate, baud (the firmware's and `ridge-id capture`'s default).
pub const BAUD: u32 = 115_200;

/// Bits a byte on the line: start, 8 data, stop (8N1).
pub const FRAME_BITS: u32 = 10;

/// Cycles the chip takes for one frame of a USART in asynchronous mode (ATmega2560 datasheet,
/// "USART": baud rate `f / (16 (UBRR + 1))`, with `U2Xn` `f / (8 (UBRR + 1))`; a frame is a start
/// bit, 5–9 data bits (`UCSZn2:0`), a parity bit if `UPMn1:0` ≠ 0 and 1 or 2 stop bits
/// (`USBSn`)), from `UBRRn` and the `UCSRnA/B/C` register values. 1 360 at the firmware's
/// `UBRR0 = 16`, U2X, 8N1.
pub fn chip_frame_cycles(ubrr: u16, ucsra: u8, ucsrb: u8, ucsrc: u8) -> u64 {
    let per_bit = (u64::from(ubrr) + 1) * if ucsra & 0x02 != 0 { 8 } else { 16 };
    let data = match ((ucsrc >> 1) & 3) | (ucsrb & 0x04) {
        0 => 5,
        1 => 6,
        2 => 7,
        7 => 9,
        _ => 8,
    };
    let parity = u64::from((ucsrc >> 4) & 3 != 0);
    let stop = if ucsrc & 0x08 != 0 { 2 } else { 1 };
    per_bit * (1 + data + parity + stop)
}

/// How simavr times the frames of USART0 (see the [module docs](self)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UartTiming {
    /// simavr's own frame time: 2 992 cycles a byte with the firmware's settings.
    #[default]
    Simavr,
    /// The chip's: [`chip_frame_cycles`], 1 360 cycles a byte with the firmware's settings.
    Chip,
}

/// Index of a transmission on its [`SerialLine`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SendId(pub usize);

/// A trigger: `(predicate on the line's text, delay in cycles after the line's end)`.
type Trigger = (Box<dyn FnMut(&str) -> bool>, u64);

/// One transmission: the bytes and, once it started, when each went out.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Transmission {
    /// The bytes, in order (a command line includes its `\n`).
    pub bytes: Vec<u8>,
    /// Cycle of the first byte's start bit, once the transmission is scheduled.
    pub start: Option<u64>,
    /// Cycle of the last byte's stop-bit end (the line fully received), once scheduled.
    pub end: Option<u64>,
    /// Cycle at which each byte sent so far was handed to simavr (its start bit).
    pub handed: Vec<u64>,
    /// Bytes lost at the receiver: `(index in bytes, why)`.
    pub lost: Vec<(usize, Delivery)>,
}

impl Transmission {
    /// Whether every byte has been handed to the receiver.
    pub fn done(&self) -> bool {
        self.handed.len() == self.bytes.len()
    }

    /// The bytes as text (lossy), for messages.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.bytes).into_owned()
    }
}

/// The serial line into one UART, with its schedule (see the [module docs](self)).
pub struct SerialLine {
    /// Core clock, Hz.
    frequency: u32,
    /// Line rate, baud.
    baud: u32,
    /// Every transmission asked for, by [`SendId`].
    sent: Vec<Transmission>,
    /// Transmissions waiting for a matching UART line.
    triggers: Vec<(SendId, Trigger)>,
    /// Transmissions scheduled and not finished, in start order: `(id, next byte)`.
    queue: VecDeque<(SendId, usize)>,
    /// The cycle at which the last scheduled transmission's stop bit ends.
    busy_until: u64,
}

impl std::fmt::Debug for SerialLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialLine")
            .field("baud", &self.baud)
            .field("sent", &self.sent.len())
            .field("waiting", &self.triggers.len())
            .field("queued", &self.queue.len())
            .finish()
    }
}

impl SerialLine {
    /// An idle line at `baud` into a core clocked at `frequency` Hz.
    pub fn new(frequency: u32, baud: u32) -> Self {
        Self {
            frequency,
            baud,
            sent: Vec::new(),
            triggers: Vec::new(),
            queue: VecDeque::new(),
            busy_until: 0,
        }
    }

    /// Cycles from a transmission's start to the start bit of its byte `k` (`k` = its length:
    /// to the end of its last stop bit), rounded to the nearest cycle.
    pub fn offset(&self, k: usize) -> u64 {
        let num = k as u64 * u64::from(FRAME_BITS) * u64::from(self.frequency);
        (num + u64::from(self.baud) / 2) / u64::from(self.baud)
    }

    /// Cycles one byte takes on the line (1 389 at 16 MHz and 115 200 baud), rounded.
    pub fn byte_cycles(&self) -> u64 {
        self.offset(1)
    }

    fn push(&mut self, bytes: Vec<u8>) -> SendId {
        let id = SendId(self.sent.len());
        self.sent.push(Transmission {
            bytes,
            ..Transmission::default()
        });
        id
    }

    fn schedule(&mut self, id: SendId, at: u64) {
        let start = at.max(self.busy_until);
        let end = start + self.offset(self.sent[id.0].bytes.len());
        let t = &mut self.sent[id.0];
        t.start = Some(start);
        t.end = Some(end);
        self.busy_until = end;
        self.queue.push_back((id, 0));
    }

    /// Sends `bytes` from cycle `at` on (or as soon as the line is free).
    pub fn send_at(&mut self, at: u64, bytes: impl Into<Vec<u8>>) -> SendId {
        let id = self.push(bytes.into());
        self.schedule(id, at);
        id
    }

    /// Sends `bytes` `delay` cycles after the end of the first UART line from the firmware
    /// (seen by [`SerialLine::on_line`] from now on) whose text `matches` accepts.
    pub fn send_after(
        &mut self,
        matches: impl FnMut(&str) -> bool + 'static,
        delay: u64,
        bytes: impl Into<Vec<u8>>,
    ) -> SendId {
        let id = self.push(bytes.into());
        self.triggers.push((id, (Box::new(matches), delay)));
        id
    }

    /// A complete UART line from the firmware, seen at cycle `now` (at or after the line's
    /// end): schedules the transmissions waiting for it, none before `now`.
    pub fn on_line(&mut self, line: &Line, now: u64) {
        let mut fired = Vec::new();
        self.triggers.retain_mut(|(id, (matches, delay))| {
            if matches(&line.text) {
                fired.push((*id, (line.cycle + *delay).max(now)));
                false
            } else {
                true
            }
        });
        for (id, at) in fired {
            self.schedule(id, at);
        }
    }

    /// Cycle of the next byte's start bit, if one is scheduled.
    pub fn next_due(&self) -> Option<u64> {
        let &(id, k) = self.queue.front()?;
        Some(self.sent[id.0].start? + self.offset(k))
    }

    /// Hands every byte whose start bit is due at `now` to `port`.
    pub fn deliver(&mut self, now: u64, port: &UartInput) {
        while self.next_due().is_some_and(|d| d <= now) {
            let (id, k) = self.queue.pop_front().expect("next_due saw it");
            let t = &mut self.sent[id.0];
            let outcome = port.send(t.bytes[k]);
            t.handed.push(now);
            if outcome != Delivery::Queued {
                t.lost.push((k, outcome));
            }
            if k + 1 < t.bytes.len() {
                self.queue.push_front((id, k + 1));
            }
        }
    }

    /// The transmission `id`.
    pub fn get(&self, id: SendId) -> &Transmission {
        &self.sent[id.0]
    }

    /// Every transmission asked for, in the order asked.
    pub fn all(&self) -> &[Transmission] {
        &self.sent
    }

    /// Whether nothing is scheduled or waiting for a line.
    pub fn idle(&self) -> bool {
        self.queue.is_empty() && self.triggers.is_empty()
    }
}

/// What became of a byte handed to a UART's receiver ([`UartInput::send`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delivery {
    /// In simavr's input FIFO: the receiver raises RXC for it one frame time after the FIFO
    /// was last empty (or after the byte before it).
    Queued,
    /// The firmware had the receiver off (`RXENn` = 0): the byte is lost, as on the chip.
    ReceiverOff,
    /// simavr's 64-entry input FIFO was full (it had signalled `UART_IRQ_OUT_XOFF`): the byte is
    /// lost and `DORn` set. (The chip has a 2-byte FIFO; a firmware that reads `UDRn` in its
    /// receive interrupt never lets simavr's fill.)
    FifoFull,
}

/// The receive side of one UART, seen from the wire: hands bytes to simavr's UART input IRQ
/// (`UART_IRQ_INPUT`) as the line delivers them (see the [module docs](self) for the line's
/// timing). Clones share the FIFO-full flag. Does nothing once its machine is dropped
/// ([`Machine::uart_input`](crate::machine::Machine::uart_input) makes it).
#[derive(Clone)]
pub struct UartInput {
    avr: *mut ffi::avr_t,
    alive: Rc<Cell<bool>>,
    input: *mut ffi::avr_irq_t,
    /// simavr's input FIFO is full (last `UART_IRQ_OUT_XOFF` value).
    full: Rc<Cell<bool>>,
    /// Data-space address of `UCSRnB` (receiver enable `RXENn`, bit 4).
    ucsrb: u16,
}

impl std::fmt::Debug for UartInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UartInput")
            .field("ucsrb", &self.ucsrb)
            .field("fifo_full", &self.full.get())
            .finish()
    }
}

/// `RXENn` in `UCSRnB` (ATmega2560 datasheet, USART register description).
const RXEN: u8 = 1 << 4;

impl UartInput {
    /// The receive side of the core `avr`'s UART: its input IRQ `input`, the FIFO-full flag
    /// `full` that its `UART_IRQ_OUT_XOFF` hook sets, its `UCSRnB` address `ucsrb`; `alive`
    /// turns false when the core is freed.
    ///
    /// # Safety
    /// `avr` and `input` are a live core and one of its UART's input IRQs, valid while
    /// `alive` is true.
    pub(crate) unsafe fn new(
        avr: *mut ffi::avr_t,
        alive: Rc<Cell<bool>>,
        input: *mut ffi::avr_irq_t,
        full: Rc<Cell<bool>>,
        ucsrb: u16,
    ) -> Self {
        UartInput {
            avr,
            alive,
            input,
            full,
            ucsrb,
        }
    }

    /// Whether the firmware has the receiver on (`RXENn` in `UCSRnB`).
    pub fn receiver_enabled(&self) -> bool {
        if !self.alive.get() {
            return false;
        }
        // SAFETY: live core; `ucsrb` is an I/O register below RAMEND.
        unsafe { *(*self.avr).data.add(self.ucsrb.into()) & RXEN != 0 }
    }

    /// Whether simavr's input FIFO is full (it signalled XOFF and not XON since).
    pub fn fifo_full(&self) -> bool {
        self.full.get()
    }

    /// Hands `byte` to the receiver now (its start bit is on the line now; simavr raises RXC
    /// one frame time later, see the [module docs](self)).
    pub fn send(&self, byte: u8) -> Delivery {
        if !self.receiver_enabled() {
            return Delivery::ReceiverOff;
        }
        if self.full.get() {
            // simavr drops it and sets DORn: raise it anyway so that the firmware sees the
            // overrun flag as it would on the chip.
            // SAFETY: live core (checked above); the input IRQ of the same core.
            unsafe { ffi::avr_raise_irq(self.input, u32::from(byte)) };
            return Delivery::FifoFull;
        }
        // SAFETY: as above.
        unsafe { ffi::avr_raise_irq(self.input, u32::from(byte)) };
        Delivery::Queued
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chip_frames() {
        // The firmware's USART0: UBRR0 = 16, U2X0, 8N1 (UCSR0C = 0b110).
        assert_eq!(chip_frame_cycles(16, 0x02, 0x98, 0x06), 1360);
        // Without U2X, 8E2: 12 bits of 16 · 17 cycles.
        assert_eq!(
            chip_frame_cycles(16, 0x00, 0x98, 0x06 | 0x20 | 0x08),
            12 * 272
        );
        // 9 data bits (UCSZ = 7), no parity, 1 stop: 11 bits of 8 cycles.
        assert_eq!(chip_frame_cycles(0, 0x02, 0x04, 0x06), 8 * 11);
    }

    #[test]
    fn bytes_are_spaced_one_frame_apart_and_transmissions_queue() {
        let mut line = SerialLine::new(16_000_000, BAUD);
        assert_eq!(line.byte_cycles(), 1389);
        // 9 bytes: 9 · 10 · 16e6 / 115 200 = 12 500 cycles exactly.
        assert_eq!(line.offset(9), 12_500);
        let a = line.send_at(1000, b"STATUS\n".to_vec());
        let b = line.send_at(1000, b"STOP\n".to_vec());
        assert_eq!(line.get(a).start, Some(1000));
        let a_end = line.get(a).end.unwrap();
        assert_eq!(a_end, 1000 + line.offset(7));
        assert_eq!(line.get(b).start, Some(a_end));
        assert_eq!(line.next_due(), Some(1000));
        let c = line.send_after(|t| t.starts_with("OK"), 50, b"X\n".to_vec());
        assert!(line.get(c).start.is_none());
        line.on_line(
            &Line {
                cycle: 5,
                text: "BOOT".into(),
            },
            10,
        );
        assert!(line.get(c).start.is_none());
        line.on_line(
            &Line {
                cycle: 100_000,
                text: "OK stop".into(),
            },
            100_010,
        );
        assert_eq!(line.get(c).start, Some(100_050));
    }
}
