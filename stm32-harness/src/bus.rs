//! The I2C bus at the pin level: SCL = PB6 and SDA = PB7, beside the I2C1 model
//! ([`crate::periph::i2c`]), which moves bytes and conditions as events and never drives the
//! pins. What it adds, as `simavr-harness`'s bus does for the ATmega2560:
//!
//! - **Pull-ups**: a line reads high whenever nothing drives it low (the Black Pill's and the
//!   sensor board's pull-ups). The MCU drives a line low only while its pin is a
//!   general-purpose output with its ODR bit 0 (open drain, RM0383 §8.3.10); in the I2C
//!   alternate function the interface's bit-level drive is not modelled (simplification: the
//!   pins then read as the slave leaves them).
//! - **A slave holding SDA low** ([`SdaHold`], armed with [`Lines::arm`] or
//!   `bench::Action::HoldSda`): a slave that lost a clock in a frame still drives a 0 bit when
//!   the master ends the frame. The hold starts at the end of the next STOP condition the
//!   I2C1 model sends after arming. From then on PB7 reads low (IDR), I2C1 shows BUSY, and a
//!   START the firmware asks I2C1 for is not sent (RM0383 §18.3.3: the interface waits for a
//!   free bus), recorded as [`BusEvent::BlockedStart`]; nothing reaches the slave meanwhile.
//! - **Release**: a slave stuck in a byte drives one bit per SCL clock and lets go of SDA
//!   after the rest of its byte and the acknowledge slot, i.e. after at most 9 clocks.
//!   [`SdaHold::ReleaseAfter`]`(k)` lets go at the k-th falling SCL edge after the hold began;
//!   [`SdaHold::Forever`] never does. Only the firmware's GPIO clocking makes SCL edges.
//! - **What the lines did** ([`BusEvent`], time-stamped): every level change of SCL and SDA,
//!   START (SDA falls while SCL is high) and STOP (SDA rises while SCL is high) conditions on
//!   the pins, the hold, the release, and every START request the held bus blocked. A STOP on
//!   the pins also ends whatever frame the slave was in (its `stop`). This is the harness's
//!   own view of the pins, independent of what the firmware reports.
//!
//! The lines themselves ([`Lines`]) are `harness_kit::i2c_lines`, shared with the ATmega2560's
//! harness; this file puts them behind I2C1 ([`BusSlave`]).

use std::cell::RefCell;
use std::rc::Rc;

pub use harness_kit::i2c_lines::{BusEvent, Lines, SdaHold};

use crate::periph::i2c::Device;
use crate::periph::Time;

/// The slave on I2C1 behind the pin-level lines: what I2C1 sends reaches `inner` unless the
/// bus is held; the pins' levels come from [`Lines`].
pub struct BusSlave {
    /// The slave (the SFM3300).
    pub inner: Box<dyn Device>,
    /// The lines, shared with the bench.
    pub lines: Rc<RefCell<Lines>>,
}

impl Device for BusSlave {
    fn start(&mut self, now: Time) {
        self.inner.start(now);
    }
    fn address(&mut self, addr: u8, read: bool, now: Time) -> bool {
        self.inner.address(addr, read, now)
    }
    fn write(&mut self, byte: u8, now: Time) -> bool {
        self.inner.write(byte, now)
    }
    fn read(&mut self, now: Time) -> u8 {
        self.inner.read(now)
    }
    fn read_ack(&mut self, ack: bool, now: Time) {
        self.inner.read_ack(ack, now);
    }
    fn stop(&mut self, now: Time) {
        self.inner.stop(now);
        // I2C1 sent a STOP condition: an armed hold begins.
        self.lines.borrow_mut().begin_hold(now);
    }
    fn holds_sda(&self, _now: Time) -> bool {
        self.lines.borrow().holding()
    }
    fn start_blocked(&mut self, now: Time) {
        self.lines.borrow_mut().blocked_start(now);
    }
    fn pins(&mut self, now: Time, scl_low: bool, sda_low: bool) {
        // SCL first: a write of both pins changes SCL before SDA would matter only for a
        // simultaneous edge, which the firmware never makes.
        let stop = {
            let mut lines = self.lines.borrow_mut();
            lines.scl(now, !scl_low);
            lines.sda(now, !sda_low)
        };
        if stop {
            self.inner.stop(now);
        }
    }
    fn levels(&self, _now: Time) -> (bool, bool) {
        self.lines.borrow().levels()
    }
}
