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

use std::cell::RefCell;
use std::rc::Rc;

use crate::machine::{IoWrite, Machine};

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

/// How long the slave holds SDA low.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdaHold {
    /// Lets go at the k-th falling SCL edge after the hold began (k ≥ 1; a real slave needs at
    /// most 9: the rest of its byte and the acknowledge slot). `0` is taken as 1.
    ReleaseAfter(u8),
    /// Never lets go (a dead slave).
    Forever,
}

/// A change on the bus lines, with its core cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusEvent {
    /// The slave started holding SDA low.
    Hold(u64),
    /// The firmware asked the TWI for a START while SDA was held: it never completes.
    BlockedStart(u64),
    /// SCL changed level (`true` = high).
    Scl(u64, bool),
    /// SDA changed level (`true` = high) on the wire.
    Sda(u64, bool),
    /// START condition: SDA fell while SCL was high.
    Start(u64),
    /// STOP condition: SDA rose while SCL was high.
    Stop(u64),
    /// The slave let go of SDA.
    Release(u64),
}

impl BusEvent {
    /// Core cycle of the event.
    pub fn cycle(&self) -> u64 {
        match *self {
            BusEvent::Hold(c)
            | BusEvent::BlockedStart(c)
            | BusEvent::Scl(c, _)
            | BusEvent::Sda(c, _)
            | BusEvent::Start(c)
            | BusEvent::Stop(c)
            | BusEvent::Release(c) => c,
        }
    }
}

/// The bus lines' state, shared between the pin callbacks and the harness.
#[derive(Debug)]
pub struct BusState {
    armed: Option<SdaHold>,
    /// The hold in force and the falling SCL edges since it began.
    holding: Option<(SdaHold, u8)>,
    scl: bool,
    sda: bool,
    /// Everything seen so far, in order.
    pub events: Vec<BusEvent>,
}

impl BusState {
    fn new() -> Self {
        BusState {
            armed: None,
            holding: None,
            scl: true,
            sda: true,
            events: Vec::new(),
        }
    }

    /// Arms a hold: SDA goes low at the firmware's next STOP request (see the module docs).
    pub fn arm(&mut self, hold: SdaHold) {
        self.armed = Some(hold);
    }

    /// Whether the slave holds SDA low now.
    pub fn holding(&self) -> bool {
        self.holding.is_some()
    }

    /// Clock pulses (falling SCL edges) in cycles `from..to`.
    pub fn scl_pulses(&self, from: u64, to: u64) -> usize {
        self.events
            .iter()
            .filter(|e| matches!(e, BusEvent::Scl(c, false) if (from..to).contains(c)))
            .count()
    }

    /// Cycles of the events `want` picks out, in order.
    pub fn cycles(&self, want: impl Fn(&BusEvent) -> bool) -> Vec<u64> {
        self.events
            .iter()
            .filter(|e| want(e))
            .map(BusEvent::cycle)
            .collect()
    }

    /// An SCL edge; returns whether the slave lets go of SDA now.
    fn scl_edge(&mut self, cycle: u64, high: bool) -> bool {
        if high == self.scl {
            return false;
        }
        self.scl = high;
        self.events.push(BusEvent::Scl(cycle, high));
        let Some((hold, edges)) = &mut self.holding else {
            return false;
        };
        if high {
            return false;
        }
        *edges = edges.saturating_add(1);
        if !matches!(*hold, SdaHold::ReleaseAfter(k) if *edges >= k.max(1)) {
            return false;
        }
        self.holding = None;
        self.events.push(BusEvent::Release(cycle));
        true
    }

    /// A change of the SDA pin as simavr sees it (the MCU's output, or the external level).
    fn sda_edge(&mut self, cycle: u64, high: bool) {
        let high = high && self.holding.is_none();
        if high == self.sda {
            return;
        }
        self.sda = high;
        self.events.push(BusEvent::Sda(cycle, high));
        if self.scl {
            self.events.push(if high {
                BusEvent::Stop(cycle)
            } else {
                BusEvent::Start(cycle)
            });
        }
    }

    /// A TWCR write `v` (register `old` before it): blocks a START while SDA is held, starts
    /// an armed hold at a STOP request. Returns what the TWI gets and whether the hold began.
    fn twcr_write(&mut self, cycle: u64, old: u8, v: u8) -> (IoWrite, bool) {
        let enabled = v & TWEN != 0;
        if self.holding.is_some() && enabled && v & TWSTA != 0 {
            self.events.push(BusEvent::BlockedStart(cycle));
            // Writing one clears TWINT; the START it waits for never comes to set it again.
            let twint = if v & TWINT != 0 { 0 } else { old & TWINT };
            return (IoWrite::Store((v & !TWINT) | twint), false);
        }
        if enabled && v & TWSTO != 0 {
            if let Some(hold) = self.armed.take() {
                self.holding = Some((hold, 0));
                self.events.push(BusEvent::Hold(cycle));
                // The slave drove its bit while SCL was low: no START condition on the wire.
                self.sda = false;
                return (IoWrite::Pass, true);
            }
        }
        (IoWrite::Pass, false)
    }
}

/// Wires the bus model to `machine`: pull-ups on PD0/PD1, the pin watchers and the TWCR
/// interception. Returns the shared state.
pub fn attach(machine: &mut Machine) -> Result<Rc<RefCell<BusState>>, String> {
    let state = Rc::new(RefCell::new(BusState::new()));
    let pins = machine.external_pins(PORT)?;
    let scl = 1 << SCL;
    let sda = 1 << SDA;
    {
        let st = state.clone();
        let pins = pins.clone();
        machine.on_pin_change(PORT, SCL, move |cycle, high| {
            let release = st.borrow_mut().scl_edge(cycle, high);
            if release {
                // Not borrowed here: the SDA watcher runs inside `set`.
                pins.set(sda, sda);
            }
        })?;
    }
    {
        let st = state.clone();
        machine.on_pin_change(PORT, SDA, move |cycle, high| {
            st.borrow_mut().sda_edge(cycle, high);
        })?;
    }
    {
        let st = state.clone();
        let pins = pins.clone();
        machine.intercept_write(TWCR, move |cycle, old, v| {
            let (write, hold) = st.borrow_mut().twcr_write(cycle, old, v);
            if hold {
                pins.set(sda, 0);
            }
            write
        })?;
    }
    pins.set(scl | sda, scl | sda);
    Ok(state)
}
