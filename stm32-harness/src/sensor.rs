//! The Sensirion SFM3300 flow sensor as a slave on the emulated I2C1 bus
//! ([`crate::periph::i2c::Device`]): the part itself (commands, frames, NACKs, faults) is
//! `harness_kit::sfm3300`'s [`SensorState`], shared with the ATmega2560 harness; this file maps
//! the I2C1 model's conditions and bytes onto it, with time in picoseconds. A slave holding SDA
//! low is the bus's ([`crate::bus`]).

use std::cell::RefCell;
use std::rc::Rc;

pub use harness_kit::sfm3300::{Event, Fault, SensorState, SERIAL};

use crate::periph::i2c::Device;
use crate::periph::Time;

/// Measurement update period, ps (0.5 ms).
pub const UPDATE_PS: Time = 500_000_000;

/// The bus's handle on the shared [`SensorState`].
#[derive(Debug, Clone)]
pub struct Sfm3300Slave {
    /// Shared state.
    pub state: Rc<RefCell<SensorState>>,
}

impl Device for Sfm3300Slave {
    fn start(&mut self, _now: Time) {
        self.state.borrow_mut().start();
    }

    fn address(&mut self, addr: u8, read: bool, now: Time) -> bool {
        self.state.borrow_mut().address(addr, read, now)
    }

    fn write(&mut self, byte: u8, now: Time) -> bool {
        self.state.borrow_mut().write(byte, now)
    }

    fn read(&mut self, _now: Time) -> u8 {
        self.state.borrow_mut().read()
    }

    fn read_ack(&mut self, _ack: bool, _now: Time) {}

    fn stop(&mut self, _now: Time) {
        self.state.borrow_mut().stop();
    }

    fn holds_sda(&self, _now: Time) -> bool {
        false
    }
}
