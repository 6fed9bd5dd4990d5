//! TWI (I2C) master on the ATmega2560, polled, implementing [`embedded_hal::i2c::I2c`]
//! (7-bit addresses).
//!
//! Arduino Mega 2560: SDA = D20 = PD1, SCL = D21 = PD0 (the board has 10 kΩ pull-ups to 5 V on
//! both; the internal pull-ups are enabled as well).
//!
//! - Every wait for the hardware is bounded ([`POLL_LIMIT`] register reads, ≈ 2.5 ms at
//!   16 MHz): on expiry the transaction fails with [`Error::Timeout`] (kind `Other`), the TWI is
//!   switched off, the bus is recovered (up to 9 SCL pulses while a slave holds SDA low, then a
//!   STOP) and the TWI is switched on again. Nothing here can hang. A slave holding SDA low
//!   makes the TWI wait for a STOP before its START, so it times out this way; what follows
//!   (recovery in simavr, the fault when SDA stays low) is in docs/boards.md, Faults.
//! - A NACK after the address or a data byte is `ErrorKind::NoAcknowledge(Address|Data)`; a STOP
//!   is sent. Arbitration loss and the TWI's bus-error state are reported as such.
//! - [`transaction`](embedded_hal::i2c::I2c::transaction) follows the embedded-hal contract: one
//!   START, a repeated START only where the direction changes, adjacent operations of the same
//!   direction merged, the last byte read NACKed, one STOP at the end.

use avr_device::atmega2560::{PORTD, TWI};
use embedded_hal::i2c::{self, ErrorKind, NoAcknowledgeSource, Operation, SevenBitAddress};

use super::F_CPU;

/// Register reads while waiting for TWINT (or for a STOP to finish) before giving up: one poll
/// takes 10 cycles, so 4000 polls are 2.5 ms (measured in simavr: 40 065 cycles from the START
/// request to the first recovery pulse), 28 byte times at 100 kHz.
pub const POLL_LIMIT: u16 = 4_000;

// TWCR bits.
const TWINT: u8 = 1 << 7;
const TWEA: u8 = 1 << 6;
const TWSTA: u8 = 1 << 5;
const TWSTO: u8 = 1 << 4;
const TWEN: u8 = 1 << 2;

// TWSR status codes (prescaler bits masked off), ATmega2560 datasheet tables 24-2 and 24-3.
const START: u8 = 0x08;
const REP_START: u8 = 0x10;
const MT_SLA_ACK: u8 = 0x18;
const MT_SLA_NACK: u8 = 0x20;
const MT_DATA_ACK: u8 = 0x28;
const MT_DATA_NACK: u8 = 0x30;
const ARB_LOST: u8 = 0x38;
const MR_SLA_ACK: u8 = 0x40;
const MR_SLA_NACK: u8 = 0x48;
const MR_DATA_ACK: u8 = 0x50;
const MR_DATA_NACK: u8 = 0x58;
const BUS_ERROR: u8 = 0x00;

// PORTD pins of the bus.
const SCL: u8 = 1 << 0;
const SDA: u8 = 1 << 1;

/// Errors of the TWI master.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The address or a data byte was not acknowledged.
    NoAcknowledge(NoAcknowledgeSource),
    /// Another master won the bus.
    ArbitrationLoss,
    /// Illegal START/STOP seen on the bus, or an unexpected TWI state.
    Bus,
    /// The TWI did not finish a step within [`POLL_LIMIT`] polls (bus stuck, SCL held low).
    Timeout,
}

impl i2c::Error for Error {
    fn kind(&self) -> ErrorKind {
        match *self {
            Error::NoAcknowledge(source) => ErrorKind::NoAcknowledge(source),
            Error::ArbitrationLoss => ErrorKind::ArbitrationLoss,
            Error::Bus => ErrorKind::Bus,
            Error::Timeout => ErrorKind::Other,
        }
    }
}

/// The TWI master. Owns the TWI block and port D (PD0/PD1 for bus recovery).
pub struct Twi {
    twi: TWI,
    portd: PORTD,
}

impl Twi {
    /// Sets up the TWI as a master at `scl_hz` (e.g. 100 kHz or 400 kHz from [`F_CPU`]),
    /// prescaler 1: `TWBR = (F_CPU / scl − 16) / 2` (72 for 100 kHz, 12 for 400 kHz).
    pub fn new(twi: TWI, portd: PORTD, scl_hz: u32) -> Self {
        let twbr = (F_CPU / scl_hz).saturating_sub(16) / 2;
        let twbr = u8::try_from(twbr).unwrap_or(u8::MAX);
        // Prescaler 1 (TWPS = 0).
        twi.twsr().write(|w| unsafe { w.bits(0) });
        twi.twbr().write(|w| unsafe { w.bits(twbr) });
        let mut this = Twi { twi, portd };
        this.release_pins();
        this.enable();
        this
    }

    /// Inputs with the internal pull-ups on (the TWI overrides the pins while enabled).
    fn release_pins(&mut self) {
        self.portd
            .ddrd()
            .modify(|r, w| unsafe { w.bits(r.bits() & !(SCL | SDA)) });
        self.portd
            .portd()
            .modify(|r, w| unsafe { w.bits(r.bits() | SCL | SDA) });
    }

    fn enable(&mut self) {
        self.set_twcr(TWEN);
    }

    fn set_twcr(&mut self, bits: u8) {
        self.twi.twcr().write(|w| unsafe { w.bits(bits) });
    }

    fn status(&self) -> u8 {
        self.twi.twsr().read().bits() & 0xF8
    }

    /// Waits (bounded) for TWINT, then returns the status.
    fn wait(&mut self) -> Result<u8, Error> {
        for _ in 0..POLL_LIMIT {
            if self.twi.twcr().read().bits() & TWINT != 0 {
                return Ok(self.status());
            }
        }
        Err(Error::Timeout)
    }

    /// Sends START (or a repeated START).
    fn start(&mut self) -> Result<(), Error> {
        self.set_twcr(TWINT | TWSTA | TWEN);
        match self.wait()? {
            START | REP_START => Ok(()),
            ARB_LOST => Err(Error::ArbitrationLoss),
            _ => Err(Error::Bus),
        }
    }

    /// Sends SLA+R or SLA+W.
    fn address(&mut self, address: SevenBitAddress, read: bool) -> Result<(), Error> {
        self.twi
            .twdr()
            .write(|w| unsafe { w.bits((address << 1) | u8::from(read)) });
        self.set_twcr(TWINT | TWEN);
        match self.wait()? {
            MT_SLA_ACK | MR_SLA_ACK => Ok(()),
            MT_SLA_NACK | MR_SLA_NACK => Err(Error::NoAcknowledge(NoAcknowledgeSource::Address)),
            ARB_LOST => Err(Error::ArbitrationLoss),
            _ => Err(Error::Bus),
        }
    }

    fn write_byte(&mut self, byte: u8) -> Result<(), Error> {
        self.twi.twdr().write(|w| unsafe { w.bits(byte) });
        self.set_twcr(TWINT | TWEN);
        match self.wait()? {
            MT_DATA_ACK => Ok(()),
            MT_DATA_NACK => Err(Error::NoAcknowledge(NoAcknowledgeSource::Data)),
            ARB_LOST => Err(Error::ArbitrationLoss),
            _ => Err(Error::Bus),
        }
    }

    /// Receives a byte and answers ACK (more to come) or NACK (last byte).
    fn read_byte(&mut self, ack: bool) -> Result<u8, Error> {
        self.set_twcr(TWINT | TWEN | if ack { TWEA } else { 0 });
        match self.wait()? {
            MR_DATA_ACK | MR_DATA_NACK => Ok(self.twi.twdr().read().bits()),
            ARB_LOST => Err(Error::ArbitrationLoss),
            _ => Err(Error::Bus),
        }
    }

    /// Sends STOP and waits (bounded) until the TWI has put it on the bus.
    fn stop(&mut self) -> Result<(), Error> {
        self.set_twcr(TWINT | TWSTO | TWEN);
        for _ in 0..POLL_LIMIT {
            if self.twi.twcr().read().bits() & TWSTO == 0 {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }

    /// Leaves the bus in a clean state after a failed transaction.
    fn abort(&mut self, error: Error) {
        match error {
            // The master still owns the bus: release it with a STOP.
            Error::NoAcknowledge(_) => {
                if self.stop().is_err() {
                    self.recover();
                }
            }
            // The TWI already let go of the bus (it is in not-addressed slave mode).
            Error::ArbitrationLoss => {}
            Error::Bus => {
                if self.status() == BUS_ERROR {
                    // Datasheet: TWSTO with TWINT releases the lines without sending a STOP.
                    self.set_twcr(TWINT | TWSTO | TWEN);
                } else {
                    self.recover();
                }
            }
            Error::Timeout => self.recover(),
        }
    }

    /// Bus recovery: TWI off, clock SCL by hand (open drain via DDR; measured 5.6 µs low,
    /// 6.9 µs high, 80 kHz) until a slave that was stuck mid-byte releases SDA (at most 9
    /// pulses), send a STOP (SDA low, then high, while SCL is high), TWI on again.
    pub fn recover(&mut self) {
        const HALF: u32 = F_CPU / 200_000; // 5 µs
        self.set_twcr(0);
        // Outputs drive low when DDR = 1, so clear PORT first; DDR = 0 lets the pull-ups win.
        self.portd
            .portd()
            .modify(|r, w| unsafe { w.bits(r.bits() & !(SCL | SDA)) });
        let ddr = self.portd.ddrd();
        let sda_high = |portd: &PORTD| portd.pind().read().bits() & SDA != 0;
        for _ in 0..9 {
            if sda_high(&self.portd) {
                break;
            }
            ddr.modify(|r, w| unsafe { w.bits(r.bits() | SCL) });
            avr_device::asm::delay_cycles(HALF);
            ddr.modify(|r, w| unsafe { w.bits(r.bits() & !SCL) });
            avr_device::asm::delay_cycles(HALF);
        }
        // STOP: SDA low while SCL is high, then SDA high.
        ddr.modify(|r, w| unsafe { w.bits(r.bits() | SDA) });
        avr_device::asm::delay_cycles(HALF);
        ddr.modify(|r, w| unsafe { w.bits(r.bits() & !SDA) });
        avr_device::asm::delay_cycles(HALF);
        self.release_pins();
        self.enable();
    }

    fn run(&mut self, address: SevenBitAddress, ops: &mut [Operation<'_>]) -> Result<(), Error> {
        let mut previous_read = None;
        let count = ops.len();
        for i in 0..count {
            let read = matches!(ops[i], Operation::Read(_));
            if previous_read != Some(read) {
                self.start()?;
                self.address(address, read)?;
            }
            let next_is_read = matches!(ops.get(i + 1), Some(Operation::Read(_)));
            match &mut ops[i] {
                Operation::Write(bytes) => {
                    for &byte in bytes.iter() {
                        self.write_byte(byte)?;
                    }
                }
                Operation::Read(buffer) => {
                    let len = buffer.len();
                    for (j, slot) in buffer.iter_mut().enumerate() {
                        // ACK all but the very last byte of a run of reads.
                        *slot = self.read_byte(j + 1 < len || next_is_read)?;
                    }
                }
            }
            previous_read = Some(read);
        }
        self.stop()
    }
}

impl i2c::ErrorType for Twi {
    type Error = Error;
}

impl i2c::I2c<SevenBitAddress> for Twi {
    fn transaction(
        &mut self,
        address: SevenBitAddress,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        if operations.is_empty() {
            return Ok(());
        }
        self.run(address, operations)
            .inspect_err(|&e| self.abort(e))
    }
}
