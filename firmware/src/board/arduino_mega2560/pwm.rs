//! Pump PWM on Timer/Counter4, channel A: OC4A = PH3 = Arduino Mega pin **D6**, implementing
//! [`embedded_hal::pwm::SetDutyCycle`].
//!
//! Fast PWM, mode 14 (TOP = ICR4 = 799), no prescaler: 16 MHz / 800 = **20 kHz**, above hearing
//! and within what common BLDC/ESC PWM inputs accept. Non-inverting output.
//!
//! `max_duty_cycle()` is 800 = TOP + 1, so that every duty `d` in `0..=800` is exactly `d / 800`:
//! `d ≥ 1` is written as `OCR4A = d − 1` (in fast PWM the pin is high for `OCR4A + 1` counts, and
//! `OCR4A = TOP` is constantly high), while `d = 0` disconnects OC4A from the pin, which then
//! drives its PORT value, low. (With `OCR4A = 0` fast PWM would still give a one-count pulse
//! each period.) Every duty-0 write also clears PH3 in PORTH: on silicon the output compare unit
//! never touches PORTH, but simavr copies the OC4A level into it, so without this the pin would
//! stay high there when the PWM is cut during its high phase.

use avr_device::atmega2560::{PORTH, TC4};
use core::convert::Infallible;
use embedded_hal::pwm::{ErrorType, SetDutyCycle};

/// Timer TOP (ICR4): 16 MHz / (799 + 1) = 20 kHz.
pub const TOP: u16 = 799;

/// Arduino D6 = PH3.
const PIN: u8 = 1 << 3;

// TCCR4A: COM4A = 0b10 (clear on compare match, set at BOTTOM) and WGM41:40 = 0b10.
const TCCR4A_OFF: u8 = 0b0000_0010;
const TCCR4A_ON: u8 = 0b1000_0010;
// TCCR4B: WGM43:42 = 0b11 (mode 14), CS4 = 0b001 (clk/1).
const TCCR4B_RUN: u8 = 0b0001_1001;

/// Pump off without the adapter, for the panic handler: OCR4A = 0, OC4A disconnected from
/// the pin (normal port operation), D6 an output driven low.
///
/// # Safety
///
/// Writes TC4 and PORTH registers behind the back of their owners: call it only where nothing
/// else will run afterwards (the panic handler, interrupts disabled).
pub unsafe fn force_off() {
    // SAFETY: the caller guarantees nothing else accesses these registers any more.
    let (tc4, porth) = unsafe { (&*TC4::ptr(), &*PORTH::ptr()) };
    tc4.ocr4a().write(|w| unsafe { w.bits(0) });
    tc4.tccr4a().write(|w| unsafe { w.bits(0) });
    drive_low(porth);
}

/// D6 (PH3) an output driven low: what the pin shows while OC4A is disconnected.
fn drive_low(porth: &avr_device::atmega2560::porth::RegisterBlock) {
    porth
        .porth()
        .modify(|r, w| unsafe { w.bits(r.bits() & !PIN) });
    porth
        .ddrh()
        .modify(|r, w| unsafe { w.bits(r.bits() | PIN) });
}

/// PWM channel OC4A (D6).
pub struct Pwm4A {
    tc4: TC4,
    porth: PORTH,
    connected: bool,
}

impl Pwm4A {
    /// Starts Timer4 at 20 kHz with the output disconnected and D6 driven low (duty 0). Takes
    /// PORTH (D6 is its only pin the board uses).
    pub fn new(tc4: TC4, porth: PORTH) -> Self {
        drive_low(&*porth);
        tc4.tccr4b().write(|w| unsafe { w.bits(0) }); // stop while configuring
        tc4.tccr4a().write(|w| unsafe { w.bits(TCCR4A_OFF) });
        tc4.icr4().write(|w| unsafe { w.bits(TOP) });
        tc4.ocr4a().write(|w| unsafe { w.bits(0) });
        tc4.tcnt4().write(|w| unsafe { w.bits(0) });
        tc4.tccr4b().write(|w| unsafe { w.bits(TCCR4B_RUN) });
        Pwm4A {
            tc4,
            porth,
            connected: false,
        }
    }
}

impl ErrorType for Pwm4A {
    type Error = Infallible;
}

impl SetDutyCycle for Pwm4A {
    fn max_duty_cycle(&self) -> u16 {
        TOP + 1
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        let duty = duty.min(TOP + 1);
        if duty == 0 {
            if self.connected {
                self.tc4.tccr4a().write(|w| unsafe { w.bits(TCCR4A_OFF) });
                self.connected = false;
            }
            self.tc4.ocr4a().write(|w| unsafe { w.bits(0) });
            drive_low(&*self.porth);
        } else {
            // OCR4A is double-buffered in fast PWM: the new value takes effect at TOP.
            self.tc4.ocr4a().write(|w| unsafe { w.bits(duty - 1) });
            if !self.connected {
                self.tc4.tccr4a().write(|w| unsafe { w.bits(TCCR4A_ON) });
                self.connected = true;
            }
        }
        Ok(())
    }
}
