//! Exhalation valve output on **PB0** (a plain GPIO of the Black Pill's header, no timer, bus
//! or boot function in use), push-pull 3.3 V: driven **high = valve closed**, low = open
//! ([`ridge_pump_firmware::ventilation`]'s safe state).
//!
//! The valve is normally open (its driver de-energised) and the driver input needs a
//! pull-down: from reset until [`ValvePin::new`] PB0 is a floating input (RM0383 §8.4.1, the
//! reset value of GPIOB_MODER), and after a panic the handler drives it low itself
//! ([`force_open`]). `new` runs before the pump's PWM is set up at boot.

use stm32f4xx_hal::gpio::{Output, PinState, PushPull, PB0};
use stm32f4xx_hal::pac;

use ridge_pump_firmware::ventilation::Valve;

/// The valve's output pin.
pub struct ValvePin {
    pin: PB0<Output<PushPull>>,
}

impl ValvePin {
    /// PB0 a push-pull output driven low (ODR written before MODER): the valve open.
    pub fn new(pin: PB0) -> Self {
        ValvePin {
            pin: pin.into_push_pull_output_in_state(PinState::Low),
        }
    }

    /// Drives the valve: high closes it, low opens it.
    pub fn set(&mut self, valve: Valve) {
        self.pin.set_state(if valve == Valve::Closed {
            PinState::High
        } else {
            PinState::Low
        });
    }
}

/// Valve open without the adapter, for the panic handler: PB0's ODR bit reset through BSRR
/// (one write; MODER is left as it is: an output after boot, before it the reset's floating
/// input that the driver's pull-down holds open).
pub fn force_open() {
    // SAFETY: a single write of GPIOB_BSRR's BR0 (RM0383 §8.4.7), which touches no other pin;
    // the panic handler runs with interrupts disabled and never returns to the pin's owner.
    let gpiob = unsafe { &*pac::GPIOB::ptr() };
    gpiob.bsrr().write(|w| w.br0().set_bit());
}
