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

use std::cell::RefCell;
use std::rc::Rc;

use crate::periph::i2c::Device;
use crate::periph::Time;

/// How long the slave holds SDA low.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdaHold {
    /// Lets go at the k-th falling SCL edge after the hold began (k ≥ 1; a real slave needs at
    /// most 9: the rest of its byte and the acknowledge slot). `0` is taken as 1.
    ReleaseAfter(u8),
    /// Never lets go (a dead slave).
    Forever,
}

/// A change on the bus lines, with its time (ps).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusEvent {
    /// The slave started holding SDA low.
    Hold(Time),
    /// The firmware asked I2C1 for a START while SDA was held: it is not sent.
    BlockedStart(Time),
    /// SCL changed level (`true` = high).
    Scl(Time, bool),
    /// SDA changed level (`true` = high) on the wire.
    Sda(Time, bool),
    /// START condition on the pins: SDA fell while SCL was high.
    Start(Time),
    /// STOP condition on the pins: SDA rose while SCL was high.
    Stop(Time),
    /// The slave let go of SDA.
    Release(Time),
}

impl BusEvent {
    /// Time of the event, ps.
    pub fn at(&self) -> Time {
        match *self {
            BusEvent::Hold(t)
            | BusEvent::BlockedStart(t)
            | BusEvent::Scl(t, _)
            | BusEvent::Sda(t, _)
            | BusEvent::Start(t)
            | BusEvent::Stop(t)
            | BusEvent::Release(t) => t,
        }
    }
}

/// The bus lines' state, shared between the bus and the bench.
#[derive(Debug)]
pub struct Lines {
    armed: Option<SdaHold>,
    /// The hold in force and the falling SCL edges since it began.
    holding: Option<(SdaHold, u8)>,
    /// The MCU drives SCL / SDA low.
    mcu_scl_low: bool,
    mcu_sda_low: bool,
    scl: bool,
    sda: bool,
    /// Everything seen so far, in order.
    pub events: Vec<BusEvent>,
}

impl Default for Lines {
    fn default() -> Self {
        Lines {
            armed: None,
            holding: None,
            mcu_scl_low: false,
            mcu_sda_low: false,
            scl: true,
            sda: true,
            events: Vec::new(),
        }
    }
}

impl Lines {
    /// Arms a hold: SDA goes low at the end of the next STOP condition I2C1 sends.
    pub fn arm(&mut self, hold: SdaHold) {
        self.armed = Some(hold);
    }

    /// Whether the slave holds SDA low now.
    pub fn holding(&self) -> bool {
        self.holding.is_some()
    }

    /// The levels on the wire: (SCL, SDA), `true` = high.
    pub fn levels(&self) -> (bool, bool) {
        (self.scl, self.sda)
    }

    /// Clock pulses (falling SCL edges) in `from..to`.
    pub fn scl_pulses(&self, from: Time, to: Time) -> usize {
        self.events
            .iter()
            .filter(|e| matches!(e, BusEvent::Scl(t, false) if (from..to).contains(t)))
            .count()
    }

    /// Times of the events `want` picks out, in order.
    pub fn times(&self, want: impl Fn(&BusEvent) -> bool) -> Vec<Time> {
        self.events
            .iter()
            .filter(|e| want(e))
            .map(BusEvent::at)
            .collect()
    }

    /// The MCU's drive changed; returns whether a STOP condition happened on the pins.
    fn drive(&mut self, now: Time, scl_low: bool, sda_low: bool) -> bool {
        self.mcu_scl_low = scl_low;
        self.mcu_sda_low = sda_low;
        // SCL first: a write of both pins changes SCL before SDA would matter only for a
        // simultaneous edge, which the firmware never makes.
        let scl = !scl_low;
        if scl != self.scl {
            self.scl = scl;
            self.events.push(BusEvent::Scl(now, scl));
            if !scl {
                if let Some((hold, edges)) = &mut self.holding {
                    *edges = edges.saturating_add(1);
                    if matches!(*hold, SdaHold::ReleaseAfter(k) if *edges >= k.max(1)) {
                        self.holding = None;
                        self.events.push(BusEvent::Release(now));
                    }
                }
            }
        }
        self.update_sda(now)
    }

    /// SDA from the MCU's drive and the hold; returns whether a STOP condition happened.
    fn update_sda(&mut self, now: Time) -> bool {
        let sda = !self.mcu_sda_low && self.holding.is_none();
        if sda == self.sda {
            return false;
        }
        self.sda = sda;
        self.events.push(BusEvent::Sda(now, sda));
        if self.scl {
            self.events.push(if sda {
                BusEvent::Stop(now)
            } else {
                BusEvent::Start(now)
            });
            return sda;
        }
        false
    }

    /// I2C1 sent a STOP condition: an armed hold begins.
    fn stop_sent(&mut self, now: Time) {
        if let Some(hold) = self.armed.take() {
            self.holding = Some((hold, 0));
            self.events.push(BusEvent::Hold(now));
            // The slave drove its bit while SCL was low: no START condition on the wire.
            self.sda = false;
        }
    }
}

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
        self.lines.borrow_mut().stop_sent(now);
    }
    fn holds_sda(&self, _now: Time) -> bool {
        self.lines.borrow().holding()
    }
    fn start_blocked(&mut self, now: Time) {
        self.lines
            .borrow_mut()
            .events
            .push(BusEvent::BlockedStart(now));
    }
    fn pins(&mut self, now: Time, scl_low: bool, sda_low: bool) {
        let stop = self.lines.borrow_mut().drive(now, scl_low, sda_low);
        if stop {
            self.inner.stop(now);
        }
    }
    fn levels(&self, _now: Time) -> (bool, bool) {
        self.lines.borrow().levels()
    }
}
