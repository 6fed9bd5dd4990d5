//! I2C1 as a master at register level (RM0383 §18), with one slave device on the bus (the
//! SFM3300, `crate::sensor`), byte by byte at the bus clock the registers set.
//!
//! Modelled (§18.3.3 "I2C master mode", Figures 163 and 164 for the flag sequences):
//! - `I2C_CR1` (§18.6.1): PE, START, STOP, ACK, SWRST. START is cleared when the start
//!   condition has been sent, STOP when the stop condition has; in master receiver mode a
//!   STOP set during a byte is sent after that byte ("after the current byte transfer"), as is
//!   the ACK or NACK that CR1.ACK selects when the byte's 9th clock comes. PE = 0 releases the
//!   bus and clears the flags; SWRST resets every register.
//! - `I2C_CR2` (§18.6.2): FREQ (the PCLK1 frequency the firmware claims, stored), interrupt
//!   enables stored. `I2C_CCR` (§18.6.8), `I2C_TRISE` (§18.6.9): the SCL period is
//!   2 × CCR × T_PCLK1 in standard mode (T_high = T_low = CCR × T_PCLK1), 3 × CCR (DUTY = 0)
//!   or 25 × CCR (DUTY = 1) × T_PCLK1 in fast mode. Simplification: TRISE (the rise time)
//!   adds nothing.
//! - `I2C_SR1` (§18.6.6): SB (set one SCL period after START; cleared by reading SR1 then
//!   writing DR), ADDR (address acknowledged; cleared by reading SR1 then SR2), BTF, TXE,
//!   RXNE, AF (address or data byte not acknowledged), BERR, ARLO, OVR (rc_w0: writing 0
//!   clears, 1 leaves), and `I2C_SR2` (§18.6.7) MSL, BUSY, TRA.
//! - transmitter: after ADDR is cleared DR is empty (TXE); a byte written to DR moves into the
//!   shift register at once if it is idle (TXE set again), takes 9 SCL periods (8 data bits
//!   and the slave's ACK), and when it ends with DR still empty BTF is set and SCL is
//!   stretched. A NACKed byte sets AF.
//! - receiver: reception starts when ADDR is cleared; each byte takes 9 SCL periods and lands
//!   in DR (RXNE); when DR is still full the byte waits in the shift register (BTF, SCL
//!   stretched) until DR is read; the master continues only after an ACK.
//! - the bus: a START when the bus is held busy (SDA low by a slave) is not sent: SB never
//!   comes and BUSY stays set (the firmware's bus recovery has to free it).
//! - Simplifications: no interrupts or DMA (the image polls), no slave mode, no 10-bit
//!   addressing, no PEC or SMBus, no clock stretching by the slave, and the analog/digital
//!   filters (FLTR) are stored only. BERR and ARLO are raised only by an injected fault
//!   ([`I2c::inject`]).

use super::{cycles_to_ps, Time, Unmodelled};

/// Register offsets (§18.6.11, register map).
pub const CR1: u32 = 0x00;
/// Control 2.
pub const CR2: u32 = 0x04;
/// Own address 1.
pub const OAR1: u32 = 0x08;
/// Own address 2.
pub const OAR2: u32 = 0x0C;
/// Data.
pub const DR: u32 = 0x10;
/// Status 1.
pub const SR1: u32 = 0x14;
/// Status 2.
pub const SR2: u32 = 0x18;
/// Clock control.
pub const CCR: u32 = 0x1C;
/// Rise time.
pub const TRISE: u32 = 0x20;
/// Filters.
pub const FLTR: u32 = 0x24;

// I2C_CR1 (§18.6.1).
const CR1_PE: u32 = 1 << 0;
const CR1_START: u32 = 1 << 8;
const CR1_STOP: u32 = 1 << 9;
const CR1_ACK: u32 = 1 << 10;
const CR1_SWRST: u32 = 1 << 15;

// I2C_SR1 (§18.6.6).
/// Start bit sent.
pub const SR1_SB: u32 = 1 << 0;
/// Address sent and acknowledged.
pub const SR1_ADDR: u32 = 1 << 1;
/// Byte transfer finished.
pub const SR1_BTF: u32 = 1 << 2;
/// Data register not empty (receiver).
pub const SR1_RXNE: u32 = 1 << 6;
/// Data register empty (transmitter).
pub const SR1_TXE: u32 = 1 << 7;
/// Bus error.
pub const SR1_BERR: u32 = 1 << 8;
/// Arbitration lost.
pub const SR1_ARLO: u32 = 1 << 9;
/// Acknowledge failure.
pub const SR1_AF: u32 = 1 << 10;
/// Overrun/underrun.
pub const SR1_OVR: u32 = 1 << 11;
const SR1_RC_W0: u32 = 0xDF00;

// I2C_SR2 (§18.6.7).
/// Master mode.
pub const SR2_MSL: u32 = 1 << 0;
/// Bus busy.
pub const SR2_BUSY: u32 = 1 << 1;
/// Transmitter.
pub const SR2_TRA: u32 = 1 << 2;

/// A slave on the bus, seen byte by byte.
pub trait Device {
    /// A START (or repeated START) condition at `now`.
    fn start(&mut self, now: Time);
    /// The address byte ended at `now`: 7-bit address and direction; `true` to acknowledge.
    fn address(&mut self, addr: u8, read: bool, now: Time) -> bool;
    /// A data byte written by the master ended at `now`; `true` to acknowledge.
    fn write(&mut self, byte: u8, now: Time) -> bool;
    /// The master starts clocking a byte in at `now`: the byte the slave puts on SDA.
    fn read(&mut self, now: Time) -> u8;
    /// The master's acknowledge of the byte just read (`false`: NACK, the last byte).
    fn read_ack(&mut self, ack: bool, now: Time);
    /// A STOP condition at `now`.
    fn stop(&mut self, now: Time);
    /// Whether the slave holds SDA low at `now` (a stuck bus).
    fn holds_sda(&self, now: Time) -> bool;
    /// The interface was asked for a START at `now` while SDA was held: it is not sent.
    fn start_blocked(&mut self, _now: Time) {}
    /// The MCU's GPIO drive of SCL / SDA changed at `now` (`true`: driven low), while the
    /// pins are not the interface's (bus recovery).
    fn pins(&mut self, _now: Time, _scl_low: bool, _sda_low: bool) {}
    /// The levels on the wire at `now`: (SCL, SDA), `true` = high.
    fn levels(&self, now: Time) -> (bool, bool) {
        (true, !self.holds_sda(now))
    }
}

/// Faults injected on the bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusFault {
    /// A misplaced START/STOP during the next byte: BERR.
    BusError,
    /// Another master wins the next byte: ARLO, the interface drops to slave mode.
    ArbitrationLost,
}

/// What the shift register is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Bus idle or held (no master operation pending).
    Idle,
    /// START requested, sent at the time.
    Start(Time),
    /// Address byte on the bus until the time.
    Address(u8, Time),
    /// Master transmitter, waiting for ADDR to be cleared / DR to be written.
    TxWait,
    /// Data byte on the bus until the time.
    Tx(u8, Time),
    /// Master receiver, waiting for ADDR to be cleared.
    RxAddr,
    /// Data byte coming in until the time.
    Rx(u8, Time),
    /// A received byte waits in the shift register (DR full): SCL stretched.
    RxHeld(u8),
    /// Receiver done (NACK sent), waiting for STOP or a repeated START.
    RxDone,
    /// STOP condition sent at the time.
    Stop(Time),
}

/// The I2C interface with its slave.
pub struct I2c {
    cr1: u32,
    cr2: u32,
    oar1: u32,
    oar2: u32,
    ccr: u32,
    trise: u32,
    fltr: u32,
    sr1: u32,
    sr2: u32,
    dr_rx: u8,
    dr_tx: Option<u8>,
    sr1_read: bool,
    phase: Phase,
    /// A STOP requested while a byte was in progress (sent after it).
    stop_pending: bool,
    fault: Option<BusFault>,
    pclk_hz: u32,
    /// The slave.
    pub device: Box<dyn Device>,
}

impl std::fmt::Debug for I2c {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("I2c")
            .field("cr1", &self.cr1)
            .field("sr1", &self.sr1)
            .field("sr2", &self.sr2)
            .field("phase", &self.phase)
            .finish()
    }
}

impl I2c {
    /// At reset, with `device` on the bus.
    pub fn new(device: Box<dyn Device>) -> Self {
        I2c {
            cr1: 0,
            cr2: 0,
            oar1: 0,
            oar2: 0,
            ccr: 0,
            trise: 2,
            fltr: 0,
            sr1: 0,
            sr2: 0,
            dr_rx: 0,
            dr_tx: None,
            sr1_read: false,
            phase: Phase::Idle,
            stop_pending: false,
            fault: None,
            pclk_hz: 16_000_000,
            device,
        }
    }

    /// System reset (or SWRST): registers to their reset values; the slave stays as it is
    /// (it has its own power).
    pub fn reset(&mut self) {
        let device = std::mem::replace(&mut self.device, Box::new(NoDevice));
        let pclk = self.pclk_hz;
        *self = I2c::new(device);
        self.pclk_hz = pclk;
    }

    /// Sets PCLK1, Hz.
    pub fn set_clock(&mut self, hz: u32) {
        self.pclk_hz = hz;
    }

    /// Injects a bus fault on the next byte.
    pub fn inject(&mut self, fault: BusFault) {
        self.fault = Some(fault);
    }

    /// One SCL period, ps (see the module docs).
    pub fn scl_period(&self) -> Time {
        let ccr = u64::from(self.ccr & 0xFFF).max(1);
        let clocks = if self.ccr & (1 << 15) == 0 {
            2 * ccr
        } else if self.ccr & (1 << 14) == 0 {
            3 * ccr
        } else {
            25 * ccr
        };
        cycles_to_ps(clocks, self.pclk_hz)
    }

    fn byte_time(&self) -> Time {
        9 * self.scl_period()
    }

    /// When the shift register next finishes something by itself.
    pub fn next_event(&self) -> Option<Time> {
        match self.phase {
            Phase::Start(t) | Phase::Address(_, t) | Phase::Tx(_, t) | Phase::Rx(_, t) => Some(t),
            Phase::Stop(t) => Some(t),
            _ => None,
        }
    }

    /// Processes the bus up to `now`.
    pub fn advance(&mut self, now: Time) {
        while let Some(t) = self.next_event().filter(|&t| t <= now) {
            self.event(t);
        }
    }

    fn event(&mut self, t: Time) {
        match self.phase {
            Phase::Start(_) => {
                self.cr1 &= !CR1_START;
                self.sr1 |= SR1_SB;
                self.sr2 |= SR2_MSL | SR2_BUSY;
                self.device.start(t);
                self.phase = Phase::Idle;
            }
            Phase::Address(a, _) => {
                if self.take_fault() {
                    return;
                }
                let read = a & 1 != 0;
                if self.device.address(a >> 1, read, t) {
                    self.sr1 |= SR1_ADDR;
                    if read {
                        self.sr2 &= !SR2_TRA;
                        self.phase = Phase::RxAddr;
                    } else {
                        self.sr2 |= SR2_TRA;
                        self.phase = Phase::TxWait;
                    }
                } else {
                    self.sr1 |= SR1_AF;
                    self.phase = Phase::Idle;
                    self.after_byte(t);
                }
            }
            Phase::Tx(b, _) => {
                if self.take_fault() {
                    return;
                }
                if self.device.write(b, t) {
                    match self.dr_tx.take() {
                        Some(next) => {
                            self.phase = Phase::Tx(next, t + self.byte_time());
                            self.sr1 |= SR1_TXE;
                        }
                        None => {
                            self.sr1 |= SR1_BTF;
                            self.phase = Phase::TxWait;
                        }
                    }
                } else {
                    self.sr1 |= SR1_AF;
                    self.phase = Phase::TxWait;
                }
                self.after_byte(t);
            }
            Phase::Rx(b, _) => {
                if self.take_fault() {
                    return;
                }
                let ack = self.cr1 & CR1_ACK != 0;
                self.device.read_ack(ack, t);
                if self.sr1 & SR1_RXNE == 0 {
                    self.dr_rx = b;
                    self.sr1 |= SR1_RXNE;
                    self.phase = if ack && !self.stop_pending() {
                        Phase::Rx(self.device.read(t), t + self.byte_time())
                    } else {
                        Phase::RxDone
                    };
                } else {
                    self.sr1 |= SR1_BTF;
                    self.phase = Phase::RxHeld(b);
                }
                if matches!(self.phase, Phase::RxDone) {
                    self.after_byte(t);
                }
            }
            Phase::Stop(_) => {
                self.cr1 &= !CR1_STOP;
                self.sr2 &= !(SR2_MSL | SR2_BUSY | SR2_TRA);
                self.sr1 &= !(SR1_TXE | SR1_BTF);
                self.stop_pending = false;
                self.device.stop(t);
                self.phase = Phase::Idle;
            }
            _ => {}
        }
    }

    fn stop_pending(&self) -> bool {
        self.stop_pending || self.cr1 & CR1_STOP != 0
    }

    /// After a byte: a pending STOP is sent now (one SCL period).
    fn after_byte(&mut self, t: Time) {
        if self.stop_pending() {
            self.phase = Phase::Stop(t + self.scl_period());
        }
    }

    fn take_fault(&mut self) -> bool {
        match self.fault.take() {
            None => false,
            Some(BusFault::BusError) => {
                self.sr1 |= SR1_BERR;
                false
            }
            Some(BusFault::ArbitrationLost) => {
                self.sr1 |= SR1_ARLO;
                self.sr2 &= !(SR2_MSL | SR2_TRA);
                self.phase = Phase::Idle;
                true
            }
        }
    }

    /// Register read at `now`.
    pub fn read(&mut self, off: u32, now: Time) -> Result<u32, Unmodelled> {
        self.advance(now);
        Ok(match off {
            CR1 => self.cr1,
            CR2 => self.cr2,
            OAR1 => self.oar1,
            OAR2 => self.oar2,
            DR => {
                let v = u32::from(self.dr_rx);
                if self.sr1 & SR1_RXNE != 0 {
                    self.sr1 &= !SR1_RXNE;
                    if let Phase::RxHeld(b) = self.phase {
                        // The held byte moves into DR; reception goes on (BTF cleared by the
                        // DR read after the SR1 read).
                        self.dr_rx = b;
                        self.sr1 |= SR1_RXNE;
                        self.sr1 &= !SR1_BTF;
                        let ack = self.cr1 & CR1_ACK != 0;
                        self.phase = if ack && !self.stop_pending() {
                            Phase::Rx(self.device.read(now), now + self.byte_time())
                        } else {
                            Phase::RxDone
                        };
                        if self.phase == Phase::RxDone {
                            self.after_byte(now);
                        }
                    }
                }
                self.sr1_read = false;
                v
            }
            SR1 => {
                self.sr1_read = true;
                let busy = self.sr2 & SR2_BUSY != 0 || self.device.holds_sda(now);
                self.sr2 = (self.sr2 & !SR2_BUSY) | if busy { SR2_BUSY } else { 0 };
                self.sr1
            }
            SR2 => {
                if self.sr1_read && self.sr1 & SR1_ADDR != 0 {
                    self.sr1 &= !SR1_ADDR;
                    match self.phase {
                        Phase::TxWait => self.sr1 |= SR1_TXE,
                        Phase::RxAddr => {
                            self.phase = Phase::Rx(self.device.read(now), now + self.byte_time())
                        }
                        _ => {}
                    }
                    // Consumed by the ADDR sequence; an SR2 read otherwise leaves a pending
                    // SB sequence (SR1 read, then DR write) as it is.
                    self.sr1_read = false;
                }
                let busy = self.sr2 & SR2_BUSY != 0 || self.device.holds_sda(now);
                (self.sr2 & !SR2_BUSY) | if busy { SR2_BUSY } else { 0 }
            }
            CCR => self.ccr,
            TRISE => self.trise,
            FLTR => self.fltr,
            _ => return Err(Unmodelled),
        })
    }

    /// Register write at `now`.
    pub fn write(&mut self, off: u32, v: u32, now: Time) -> Result<(), Unmodelled> {
        self.advance(now);
        match off {
            CR1 => self.write_cr1(v, now),
            CR2 => self.cr2 = v & 0x1F3F,
            OAR1 => self.oar1 = v,
            OAR2 => self.oar2 = v & 0xFF,
            DR => self.write_dr(v as u8, now),
            SR1 => self.sr1 &= v | !SR1_RC_W0,
            SR2 => {}
            CCR => self.ccr = v & 0xCFFF,
            TRISE => self.trise = v & 0x3F,
            FLTR => self.fltr = v & 0x1F,
            _ => return Err(Unmodelled),
        }
        Ok(())
    }

    fn write_cr1(&mut self, v: u32, now: Time) {
        if v & CR1_SWRST != 0 {
            self.reset();
            self.cr1 = CR1_SWRST;
            return;
        }
        let was = self.cr1;
        self.cr1 = v & 0xBFFF;
        if v & CR1_PE == 0 {
            // PE = 0: the interface is off, the lines released (§18.6.1).
            if was & CR1_PE != 0 && self.sr2 & SR2_MSL != 0 {
                self.device.stop(now);
            }
            self.cr1 &= !(CR1_START | CR1_STOP);
            self.sr1 = 0;
            self.sr2 = 0;
            self.phase = Phase::Idle;
            self.stop_pending = false;
            return;
        }
        if v & CR1_START != 0 && was & CR1_START == 0 {
            match self.phase {
                Phase::Idle | Phase::TxWait | Phase::RxDone => {
                    if self.device.holds_sda(now) && self.sr2 & SR2_MSL == 0 {
                        // Bus busy: the start condition cannot be sent.
                        self.sr2 |= SR2_BUSY;
                        self.device.start_blocked(now);
                    } else {
                        self.sr1 &= !(SR1_BTF | SR1_TXE);
                        self.phase = Phase::Start(now + self.scl_period());
                    }
                }
                _ => {}
            }
        }
        if v & CR1_STOP != 0 && was & CR1_STOP == 0 {
            match self.phase {
                Phase::Idle | Phase::TxWait | Phase::RxDone | Phase::RxHeld(_) => {
                    if self.sr2 & SR2_MSL != 0 {
                        self.phase = Phase::Stop(now + self.scl_period());
                    } else {
                        self.cr1 &= !CR1_STOP;
                    }
                }
                // During a byte: sent after it.
                _ => self.stop_pending = true,
            }
        }
    }

    fn write_dr(&mut self, b: u8, now: Time) {
        if self.sr1 & SR1_SB != 0 && self.sr1_read {
            self.sr1 &= !SR1_SB;
            self.sr1_read = false;
            self.phase = Phase::Address(b, now + self.byte_time());
            return;
        }
        if self.sr1_read {
            self.sr1 &= !SR1_BTF;
        }
        self.sr1_read = false;
        match self.phase {
            Phase::TxWait if self.sr1 & SR1_ADDR == 0 => {
                self.sr1 &= !SR1_BTF;
                self.phase = Phase::Tx(b, now + self.byte_time());
                self.sr1 |= SR1_TXE;
            }
            Phase::Tx(..) => {
                if self.dr_tx.is_some() {
                    self.sr1 |= SR1_OVR;
                }
                self.dr_tx = Some(b);
                self.sr1 &= !SR1_TXE;
            }
            _ => {}
        }
    }
}

/// No slave (a placeholder while the real one is moved).
struct NoDevice;

impl Device for NoDevice {
    fn start(&mut self, _: Time) {}
    fn address(&mut self, _: u8, _: bool, _: Time) -> bool {
        false
    }
    fn write(&mut self, _: u8, _: Time) -> bool {
        false
    }
    fn read(&mut self, _: Time) -> u8 {
        0xFF
    }
    fn read_ack(&mut self, _: bool, _: Time) {}
    fn stop(&mut self, _: Time) {}
    fn holds_sda(&self, _: Time) -> bool {
        false
    }
}
