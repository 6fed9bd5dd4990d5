//! The simulated Sensirion SFM3300 on the simulated TWI bus, as an `avr_tester` [`TwiSlave`]:
//! the part itself (commands, frames, NACKs, faults) is `harness_kit::sfm3300`'s
//! [`SensorState`], shared with the STM32F411 harness; this file maps simavr's TWI packets onto
//! it. simavr's master sends START with the 8-bit address (SLA+R/W) once the address byte is
//! clocked out, and STOP carries the address too.
//!
//! The slave only sees bus packets; time comes from the bench through a clock cell the machine
//! sets to the core cycle of each packet ([`Machine::attach_twi`]), the flow it measures from
//! the harness, which sets `flow_slm` at every 0.5 ms plant step.
//!
//! [`Machine::attach_twi`]: crate::machine::Machine::attach_twi

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use avr_tester::{TwiPacket, TwiSlave};

pub use harness_kit::sfm3300::{Event, Fault, SensorState, SERIAL};
use pump_sim::sfm3300::I2C_ADDRESS;

/// 7-bit address (the simulator's, not the firmware driver's: the slave checks the driver).
pub const ADDRESS: u8 = I2C_ADDRESS;

/// Measurement update period in CPU cycles at 16 MHz (0.5 ms).
pub const UPDATE_CYCLES_16MHZ: u64 = 8_000;

/// The TWI slave: a handle on the shared [`SensorState`] and the clock it reads the time from.
#[derive(Debug, Clone)]
pub struct Sfm3300Slave {
    /// Shared state.
    pub state: Rc<RefCell<SensorState>>,
    /// Core cycle of the packet being handled (set by the machine).
    pub clock: Rc<Cell<u64>>,
}

impl TwiSlave for Sfm3300Slave {
    fn recv(&mut self, p: TwiPacket) -> Option<TwiPacket> {
        let mut s = self.state.borrow_mut();
        let now = self.clock.get();
        if p.addr >> 1 != ADDRESS {
            if p.is_start() {
                // Another slave's transfer: this one is no longer addressed.
                s.address(p.addr >> 1, p.addr & 1 == 1, now);
            }
            return None;
        }
        if p.is_stop() {
            s.stop();
            return Some(p.respond_ack());
        }
        if p.is_start() {
            let ack = s.address(ADDRESS, p.addr & 1 == 1, now);
            return Some(TwiPacket {
                data: u8::from(ack),
                ..p.respond_ack()
            });
        }
        if !s.addressed() {
            return None;
        }
        if p.is_write() {
            let ack = s.write(p.data, now);
            return Some(TwiPacket {
                data: u8::from(ack),
                ..p.respond_ack()
            });
        }
        if p.is_read() {
            let b = s.read();
            return Some(p.respond_data(b));
        }
        None
    }
}
