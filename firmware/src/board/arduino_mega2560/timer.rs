//! The 100 Hz tick: Timer/Counter3 in CTC mode (mode 4, TOP = OCR3A), clk/64:
//! 16 MHz / 64 / (2499 + 1) = 100 Hz exactly. The compare-match interrupt only counts; the main
//! loop polls the count (busy-waiting: no SLEEP, which simulators such as avr-tester stop on),
//! does the work (I2C included) and sees from the count whether it came back late.

use avr_device::atmega2560::TC3;
use core::sync::atomic::{AtomicU16, Ordering};

/// OCR3A: 250 kHz timer clock × 10 ms − 1.
pub const OCR3A: u16 = 2_499;

// TCCR3B: WGM32 (CTC with OCR3A as TOP), CS3 = 0b011 (clk/64).
const TCCR3B_RUN: u8 = 0b0000_1011;
// TIMSK3: OCIE3A.
const OCIE3A: u8 = 1 << 1;

/// Ticks since start, modulo 2¹⁶ (wraps after 655 s, longer than any search). Written only by
/// the interrupt (load + store: no atomic read-modify-write on AVR, and none is needed with a
/// single writer; 16-bit loads in the main loop run with interrupts off).
static TICKS: AtomicU16 = AtomicU16::new(0);

/// Waits for ticks; owns Timer3.
pub struct Ticker {
    _tc3: TC3,
    last: u16,
}

impl Ticker {
    /// Starts Timer3 and enables its compare interrupt (global interrupts are enabled by the
    /// caller).
    pub fn new(tc3: TC3) -> Self {
        tc3.tccr3b().write(|w| unsafe { w.bits(0) });
        tc3.tccr3a().write(|w| unsafe { w.bits(0) });
        tc3.ocr3a().write(|w| unsafe { w.bits(OCR3A) });
        tc3.tcnt3().write(|w| unsafe { w.bits(0) });
        tc3.tifr3().write(|w| unsafe { w.bits(0xFF) }); // clear pending flags
        tc3.timsk3().write(|w| unsafe { w.bits(OCIE3A) });
        tc3.tccr3b().write(|w| unsafe { w.bits(TCCR3B_RUN) });
        Ticker {
            _tc3: tc3,
            last: TICKS.load(Ordering::Acquire),
        }
    }

    /// Non-blocking: the ticks since the last call that returned `Some`, or `None`.
    pub fn poll(&mut self) -> Option<u16> {
        let now = TICKS.load(Ordering::Acquire);
        if now == self.last {
            return None;
        }
        let elapsed = now.wrapping_sub(self.last);
        self.last = now;
        Some(elapsed)
    }
}

#[avr_device::interrupt(atmega2560)]
fn TIMER3_COMPA() {
    TICKS.store(
        TICKS.load(Ordering::Relaxed).wrapping_add(1),
        Ordering::Release,
    );
}
