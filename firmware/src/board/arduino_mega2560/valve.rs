//! Exhalation valve output on PA0 = Arduino Mega pin **D22** (a plain digital pin of the
//! double header, no timer or bus function in use): driven **high = valve closed**, low =
//! open ([`crate::ventilation`]'s safe state).
//!
//! The valve is normally open (its driver de-energised) and the driver input needs a
//! pull-down: from reset until [`ValvePin::new`] the pin is a floating input, and after a
//! panic the handler drives it low itself ([`force_open`]). `new` runs before the pump's PWM
//! is set up at boot.

use avr_device::atmega2560::PORTA;
use ridge_pump_firmware::ventilation::Valve;

/// Arduino D22 = PA0.
const PIN: u8 = 1 << 0;

/// The valve's output pin.
pub struct ValvePin {
    porta: PORTA,
}

impl ValvePin {
    /// D22 an output driven low: the valve open. Takes PORTA (D22 is its only pin the board
    /// uses).
    pub fn new(porta: PORTA) -> Self {
        drive(&porta, false);
        porta
            .ddra()
            .modify(|r, w| unsafe { w.bits(r.bits() | PIN) });
        ValvePin { porta }
    }

    /// Drives the valve: high closes it, low opens it.
    pub fn set(&mut self, valve: Valve) {
        drive(&self.porta, valve == Valve::Closed);
    }
}

fn drive(porta: &avr_device::atmega2560::porta::RegisterBlock, high: bool) {
    porta.porta().modify(|r, w| unsafe {
        w.bits(if high {
            r.bits() | PIN
        } else {
            r.bits() & !PIN
        })
    });
}

/// Valve open without the adapter, for the panic handler: D22 an output driven low.
///
/// # Safety
///
/// Writes PORTA behind the back of its owner: call it only where nothing else will run
/// afterwards (the panic handler, interrupts disabled).
pub unsafe fn force_open() {
    // SAFETY: the caller guarantees nothing else accesses PORTA any more.
    let porta = unsafe { &*PORTA::ptr() };
    drive(porta, false);
    porta
        .ddra()
        .modify(|r, w| unsafe { w.bits(r.bits() | PIN) });
}
