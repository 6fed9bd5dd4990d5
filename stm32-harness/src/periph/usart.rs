//! USART1 (RM0383 §19) as the image's console uses it: 115 200 baud 8N1, transmit from an
//! interrupt on TXE, receive into an interrupt on RXNE.
//!
//! Modelled:
//! - `USART_BRR` (§19.6.3) and the byte time: with OVER8 = 0 the baud rate is
//!   f_PCLK / (16 × USARTDIV) and BRR holds 16 × USARTDIV (§19.3.4, equation 1), so a bit takes
//!   BRR clocks of PCLK2; with OVER8 = 1 it takes 8 × USARTDIV = 8 × `BRR[15:4]` + `BRR[2:0]`. A
//!   frame is 1 start bit, 8 or 9 data bits (`CR1.M`), and 1, 2 (or 0.5, 1.5) stop bits
//!   (`CR2.STOP`, §19.6.5).
//! - transmitter (§19.3.2): a write to DR with TXE set moves the byte into the shift register
//!   at once if it is idle (TXE stays set, TC clears), else TXE clears until the shift register
//!   takes it at the end of the current frame. TC is set at the end of a frame with nothing in
//!   DR; it is cleared by a read of SR followed by a write to DR, or by writing 0 (§19.6.1).
//!   Every byte sent is recorded with the time its frame ended.
//! - receiver (§19.3.3): a byte arriving at the end of its frame lands in DR with RXNE set; if
//!   RXNE was still set, ORE is set and the byte is lost (DR keeps the older byte). RXNE is
//!   cleared by a read of DR (or writing 0); ORE, NF, FE by a read of SR followed by a read of
//!   DR.
//! - the interrupt (§19.4, Table 91): TXE & TXEIE, TC & TCIE, (RXNE | ORE) & RXNEIE,
//!   IDLE & IDLEIE.
//! - `UE`, `TE`, `RE` gate the transmitter and receiver; CR2, CR3 and GTPR are stored.
//!   Simplification: no noise, framing or parity errors (the line is perfect), no IDLE or LIN
//!   break detection, no hardware flow control, DMA, or synchronous mode.

use std::collections::VecDeque;

use super::{cycles_to_ps, Time, Unmodelled};

/// Register offsets (§19.6.8, register map).
pub const SR: u32 = 0x00;
/// Data.
pub const DR: u32 = 0x04;
/// Baud rate.
pub const BRR: u32 = 0x08;
/// Control 1.
pub const CR1: u32 = 0x0C;
/// Control 2.
pub const CR2: u32 = 0x10;
/// Control 3.
pub const CR3: u32 = 0x14;
/// Guard time and prescaler.
pub const GTPR: u32 = 0x18;

// USART_SR (§19.6.1).
/// Parity error.
pub const SR_PE: u32 = 1 << 0;
/// Framing error.
pub const SR_FE: u32 = 1 << 1;
/// Noise.
pub const SR_NF: u32 = 1 << 2;
/// Overrun.
pub const SR_ORE: u32 = 1 << 3;
/// Idle line.
pub const SR_IDLE: u32 = 1 << 4;
/// Read data register not empty.
pub const SR_RXNE: u32 = 1 << 5;
/// Transmission complete.
pub const SR_TC: u32 = 1 << 6;
/// Transmit data register empty.
pub const SR_TXE: u32 = 1 << 7;

// USART_CR1 (§19.6.4).
const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_IDLEIE: u32 = 1 << 4;
const CR1_RXNEIE: u32 = 1 << 5;
const CR1_TCIE: u32 = 1 << 6;
const CR1_TXEIE: u32 = 1 << 7;
const CR1_M: u32 = 1 << 12;
const CR1_UE: u32 = 1 << 13;
const CR1_OVER8: u32 = 1 << 15;

/// A byte that left the transmitter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sent {
    /// When its frame started (DR moved into the shift register).
    pub start: Time,
    /// Instructions executed when the firmware wrote it to DR.
    pub instr: u64,
    /// When its frame ended (stop bit done).
    pub end: Time,
    /// The byte.
    pub byte: u8,
}

/// A byte that reached the receiver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    /// When its frame ended.
    pub at: Time,
    /// The byte.
    pub byte: u8,
    /// Whether it was lost (RXNE was still set: overrun).
    pub lost: bool,
}

/// One USART.
#[derive(Clone, Debug)]
pub struct Usart {
    sr: u32,
    dr_rx: u32,
    /// Byte waiting in the transmit data register (TXE clear), with the instruction count
    /// of its write.
    tdr: Option<(u8, u64)>,
    /// Byte in the shift register (with its write's instruction count), its frame's start
    /// and end.
    shifting: Option<((u8, u64), Time, Time)>,
    brr: u32,
    cr1: u32,
    cr2: u32,
    cr3: u32,
    gtpr: u32,
    /// SR was read since the last DR access (first half of the clearing sequences).
    sr_read: bool,
    /// PCLK of the USART's bus, Hz.
    pclk_hz: u32,
    /// Bytes arriving on RX: (end of frame, byte), in time order.
    rx_line: VecDeque<(Time, u8)>,
    /// Every byte transmitted, in order.
    pub sent: Vec<Sent>,
    /// Every byte received, in order.
    pub received: Vec<Received>,
}

impl Default for Usart {
    fn default() -> Self {
        Self::new()
    }
}

impl Usart {
    /// At reset (§19.6: SR = 0x00C0, the rest 0).
    pub fn new() -> Self {
        Usart {
            sr: SR_TXE | SR_TC,
            dr_rx: 0,
            tdr: None,
            shifting: None,
            brr: 0,
            cr1: 0,
            cr2: 0,
            cr3: 0,
            gtpr: 0,
            sr_read: false,
            pclk_hz: 16_000_000,
            rx_line: VecDeque::new(),
            sent: Vec::new(),
            received: Vec::new(),
        }
    }

    /// System reset: registers to reset values; the logs and the bytes on their way stay.
    pub fn reset(&mut self) {
        let sent = std::mem::take(&mut self.sent);
        let received = std::mem::take(&mut self.received);
        let rx_line = std::mem::take(&mut self.rx_line);
        *self = Usart::new();
        self.sent = sent;
        self.received = received;
        self.rx_line = rx_line;
    }

    /// Sets the bus clock (PCLK2 for USART1), Hz.
    pub fn set_clock(&mut self, hz: u32) {
        self.pclk_hz = hz;
    }

    /// Bit time in clocks of PCLK (see the module docs).
    fn bit_clocks(&self) -> u64 {
        if self.cr1 & CR1_OVER8 != 0 {
            u64::from((self.brr >> 4) * 8 + (self.brr & 7))
        } else {
            u64::from(self.brr & 0xFFFF)
        }
    }

    /// One frame, in bit times × 2 (stop bits can be halves): start + data + stop.
    fn frame_half_bits(&self) -> u64 {
        let data = if self.cr1 & CR1_M != 0 { 9 } else { 8 };
        let stop_halves = match (self.cr2 >> 12) & 3 {
            0 => 2,
            1 => 1,
            2 => 4,
            _ => 3,
        };
        2 * (1 + data) + stop_halves
    }

    /// Duration of one frame at the current settings, ps.
    pub fn frame_ps(&self) -> Time {
        cycles_to_ps(self.bit_clocks() * self.frame_half_bits(), self.pclk_hz) / 2
    }

    fn enabled(&self, bit: u32) -> bool {
        self.cr1 & CR1_UE != 0 && self.cr1 & bit != 0
    }

    /// Queues `byte` to arrive on RX, its frame ending at `at` (the line's time order is
    /// the caller's).
    pub fn receive_at(&mut self, at: Time, byte: u8) {
        self.rx_line.push_back((at, byte));
    }

    /// Processes what happened up to `now`: frames ending, bytes arriving.
    pub fn advance(&mut self, now: Time) {
        loop {
            let tx = self.shifting.map(|(_, _, end)| end).filter(|&e| e <= now);
            let rx = self
                .rx_line
                .front()
                .map(|&(at, _)| at)
                .filter(|&a| a <= now);
            match (tx, rx) {
                (Some(t), Some(r)) if r < t => self.rx_frame(),
                (Some(t), _) => self.tx_frame_end(t),
                (None, Some(_)) => self.rx_frame(),
                (None, None) => break,
            }
        }
    }

    fn tx_frame_end(&mut self, end: Time) {
        if let Some(((byte, instr), start, _)) = self.shifting.take() {
            self.sent.push(Sent {
                start,
                instr,
                end,
                byte,
            });
        }
        match self.tdr.take() {
            Some(next) => {
                self.shifting = Some((next, end, end + self.frame_ps()));
                self.sr |= SR_TXE;
            }
            None => self.sr |= SR_TC,
        }
    }

    fn rx_frame(&mut self) {
        let Some((at, byte)) = self.rx_line.pop_front() else {
            return;
        };
        if !self.enabled(CR1_RE) {
            self.received.push(Received {
                at,
                byte,
                lost: true,
            });
            return;
        }
        let lost = self.sr & SR_RXNE != 0;
        if lost {
            self.sr |= SR_ORE;
        } else {
            self.dr_rx = u32::from(byte);
            self.sr |= SR_RXNE;
        }
        self.received.push(Received { at, byte, lost });
    }

    /// When something next happens by itself: a frame ends or a byte arrives.
    pub fn next_event(&self) -> Option<Time> {
        let tx = self.shifting.map(|(_, _, end)| end);
        let rx = self.rx_line.front().map(|&(at, _)| at);
        match (tx, rx) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The interrupt line (§19.4).
    pub fn irq(&self) -> bool {
        let c = self.cr1;
        let s = self.sr;
        (c & CR1_TXEIE != 0 && s & SR_TXE != 0)
            || (c & CR1_TCIE != 0 && s & SR_TC != 0)
            || (c & CR1_RXNEIE != 0 && s & (SR_RXNE | SR_ORE) != 0)
            || (c & CR1_IDLEIE != 0 && s & SR_IDLE != 0)
    }

    /// Register read at `now`.
    pub fn read(&mut self, off: u32, now: Time) -> Result<u32, Unmodelled> {
        self.advance(now);
        Ok(match off {
            SR => {
                self.sr_read = true;
                self.sr
            }
            DR => {
                let v = self.dr_rx;
                self.sr &= !SR_RXNE;
                if self.sr_read {
                    self.sr &= !(SR_ORE | SR_NF | SR_FE | SR_PE | SR_IDLE);
                }
                self.sr_read = false;
                v
            }
            BRR => self.brr,
            CR1 => self.cr1,
            CR2 => self.cr2,
            CR3 => self.cr3,
            GTPR => self.gtpr,
            _ => return Err(Unmodelled),
        })
    }

    /// Register write at `now`, the `instr`-th instruction.
    pub fn write(&mut self, off: u32, v: u32, now: Time, instr: u64) -> Result<(), Unmodelled> {
        self.advance(now);
        match off {
            // RXNE and TC are rc_w0; the other flags are read-only (§19.6.1).
            SR => self.sr &= v | !(SR_RXNE | SR_TC),
            DR => {
                if self.sr_read {
                    self.sr &= !SR_TC;
                }
                self.sr_read = false;
                if !self.enabled(CR1_TE) {
                    return Ok(());
                }
                let byte = (v as u8, instr);
                self.sr &= !SR_TC;
                if self.shifting.is_none() {
                    self.shifting = Some((byte, now, now + self.frame_ps()));
                } else if self.tdr.is_none() {
                    self.tdr = Some(byte);
                    self.sr &= !SR_TXE;
                } else {
                    // Written with TXE clear: the waiting byte is overwritten (§19.3.2).
                    self.tdr = Some(byte);
                }
            }
            BRR => self.brr = v & 0xFFFF,
            CR1 => self.cr1 = v & 0xBFFF,
            CR2 => self.cr2 = v & 0x7F7F,
            CR3 => self.cr3 = v & 0x0FFF,
            GTPR => self.gtpr = v & 0xFFFF,
            _ => return Err(Unmodelled),
        }
        Ok(())
    }
}
