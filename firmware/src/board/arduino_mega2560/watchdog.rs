//! Watchdog (WDT, 128 kHz oscillator) in system-reset mode, and the reset cause.
//!
//! The timeout is 0.5 s (WDP = 0b0101, 64 K cycles). The loop pets it every 10 ms tick, and the
//! search through its `pet` closure. A hung loop, or the panic handler (which stops the pump and
//! then spins with interrupts off), ends in a watchdog reset.
//!
//! After a watchdog reset the WDT stays enabled with its shortest timeout (16 ms) for as long as
//! WDRF is set, so [`take_reset_cause`] runs first thing in `main`: it reads MCUSR, clears it and
//! turns the watchdog off until [`Watchdog::start`].

use avr_device::atmega2560::{CPU, WDT};

// WDTCSR bits.
const WDCE: u8 = 1 << 4;
const WDE: u8 = 1 << 3;
/// WDE with WDP3:0 = 0b0101: reset after 64 K cycles of 128 kHz ≈ 0.5 s.
const WDTCSR_500MS: u8 = WDE | 0b0000_0101;

/// Writes WDTCSR with the timed sequence (the new value within 4 cycles of WDCE|WDE).
fn write_wdtcsr(value: u8) {
    avr_device::interrupt::free(|_| {
        // SAFETY: WDTCSR is at data address 0x60 (not in I/O space: `sts`, 2 cycles each);
        // interrupts are off so the two stores are back to back.
        unsafe {
            core::arch::asm!(
                "wdr",
                "sts 0x60, {ce}",
                "sts 0x60, {value}",
                ce = in(reg) WDCE | WDE,
                value = in(reg) value,
                options(nostack),
            )
        };
    });
}

/// Reads and clears MCUSR (PORF 0, EXTRF 1, BORF 2, WDRF 3, JTRF 4) and disables the
/// watchdog. Under the Arduino bootloader MCUSR may already have been cleared (then 0).
pub fn take_reset_cause(cpu: &CPU) -> u8 {
    let cause = cpu.mcusr().read().bits();
    cpu.mcusr().write(|w| unsafe { w.bits(0) });
    write_wdtcsr(0);
    cause
}

/// The running watchdog.
pub struct Watchdog {
    _wdt: WDT,
}

impl Watchdog {
    /// Starts the watchdog with a 0.5 s timeout (system reset).
    pub fn start(wdt: WDT) -> Self {
        write_wdtcsr(WDTCSR_500MS);
        Watchdog { _wdt: wdt }
    }

    /// Restarts the timeout.
    pub fn pet(&mut self) {
        avr_device::asm::wdr();
    }
}
