//! The I2C bus at the pin level: SCL = PD0 and SDA = PD1 of the ATmega2560 (Arduino Mega pins
//! 21 and 20), beside simavr's TWI model, which moves bytes as messages and never drives the
//! pins. What it adds:
//!
//! - **Pull-ups**: both lines read high whenever nothing drives them low (the Mega's 10 kΩ to
//!   5 V), also while the firmware has its internal pull-ups off.
//! - **A slave holding SDA low** ([`SdaHold`], armed with [`BusState::arm`] or
//!   `bench::Action::HoldSda`): a slave that lost a clock in a frame still drives a 0 bit when
//!   the master ends the frame, so the master's STOP never reaches the bus. The hold starts at
//!   the firmware's next STOP request (a TWCR write with TWSTO) after arming. From then on PD1
//!   reads low at the port (PIND), whatever the firmware drives, and a START the firmware asks
//!   the TWI for never completes: TWINT stays clear and TWSR keeps 0xF8 ("no relevant state
//!   information", TWINT = 0). ATmega2560 datasheet, TWCR bit 5 TWSTA: "if the bus is not free,
//!   the TWI waits until a STOP condition is detected" — and no STOP (SDA rising while SCL is
//!   high) can happen while SDA is held. Nothing reaches the slave model meanwhile.
//! - **Release**: a slave stuck in a byte drives one bit per SCL clock and lets go of SDA after
//!   the rest of its byte and the acknowledge slot, i.e. after at most 9 clocks.
//!   [`SdaHold::ReleaseAfter`]`(k)` lets go at the k-th falling SCL edge after the hold began
//!   (the edge at which a slave puts out its next bit); [`SdaHold::Forever`] never does. Only
//!   the firmware's GPIO clocking (bus recovery, TWI off) makes SCL edges: simavr's TWI does
//!   not clock the pins, so a pending START never sees the release.
//! - **What the lines did** ([`BusEvent`], cycle-stamped): every level change of SCL and SDA,
//!   START (SDA falls while SCL is high) and STOP (SDA rises while SCL is high) conditions, the
//!   hold, the release, and every START request the held bus blocked. This is the harness's own
//!   view of the pins, independent of what the firmware reports.
//!
//! The lines themselves ([`BusState`]: hold, release, events) are `harness_kit::i2c_lines`,
//! shared with the STM32F411's harness; this file wires them to PD0/PD1 and TWCR.

use std::cell::RefCell;
use std::rc::Rc;

pub use harness_kit::i2c_lines::{BusEvent, SdaHold};

use crate::machine::{IoWrite, Machine};

/// The bus lines' state, shared between the pin callbacks and the harness (the lines of
/// `harness_kit::i2c_lines`, which the STM32F411's harness shares).
pub type BusState = harness_kit::i2c_lines::Lines;

/// TWCR, the TWI control register (data-space address, ATmega2560).
pub const TWCR: u16 = 0xBC;
/// Port of both lines.
pub const PORT: char = 'D';
/// SCL bit in port D (PD0).
pub const SCL: u8 = 0;
/// SDA bit in port D (PD1).
pub const SDA: u8 = 1;

// TWCR bits.
const TWINT: u8 = 1 << 7;
const TWSTA: u8 = 1 << 5;
const TWSTO: u8 = 1 << 4;
const TWEN: u8 = 1 << 2;

/// A TWCR write `v` (register `old` before it) seen by the lines at `cycle`: blocks a START
/// while SDA is held, starts an armed hold at a STOP request. Returns what the TWI gets and
/// whether the hold began.
fn twcr_write(lines: &mut BusState, cycle: u64, old: u8, v: u8) -> (IoWrite, bool) {
    let enabled = v & TWEN != 0;
    if lines.holding() && enabled && v & TWSTA != 0 {
        lines.blocked_start(cycle);
        // Writing one clears TWINT; the START it waits for never comes to set it again.
        let twint = if v & TWINT != 0 { 0 } else { old & TWINT };
        return (IoWrite::Store((v & !TWINT) | twint), false);
    }
    if enabled && v & TWSTO != 0 && lines.begin_hold(cycle) {
        return (IoWrite::Pass, true);
    }
    (IoWrite::Pass, false)
}

/// Wires the bus model to `machine`: pull-ups on PD0/PD1, the pin watchers and the TWCR
/// interception. Returns the shared state.
pub fn attach(machine: &mut Machine) -> Result<Rc<RefCell<BusState>>, String> {
    let state = Rc::new(RefCell::new(BusState::default()));
    let pins = machine.external_pins(PORT)?;
    let scl = 1 << SCL;
    let sda = 1 << SDA;
    {
        let st = state.clone();
        let pins = pins.clone();
        machine.on_pin_change(PORT, SCL, move |cycle, high| {
            let release = st.borrow_mut().scl(cycle, high);
            if release {
                // Not borrowed here: the SDA watcher runs inside `set`.
                pins.set(sda, sda);
            }
        })?;
    }
    {
        let st = state.clone();
        machine.on_pin_change(PORT, SDA, move |cycle, high| {
            // The pin as simavr sees it: the MCU's output, or the external level.
            st.borrow_mut().sda(cycle, high);
        })?;
    }
    {
        let st = state.clone();
        let pins = pins.clone();
        machine.intercept_write(TWCR, move |cycle, old, v| {
            let (write, hold) = twcr_write(&mut st.borrow_mut(), cycle, old, v);
            if hold {
                pins.set(sda, 0);
            }
            write
        })?;
    }
    pins.set(scl | sda, scl | sda);
    Ok(state)
}
