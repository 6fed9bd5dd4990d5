//! Reset loops: watchdog and brown-out resets counted across boots, so that a pump that keeps
//! resetting (a hang that trips the watchdog in the same place after every boot, a supply that
//! sags below the brown-out level whenever the blower starts) stops in a safe state, with the
//! reason reported, instead of restarting it forever.
//!
//! The count lives in one byte of non-volatile storage ([`COUNT_OFFSET`] from the board's
//! storage base, after the record slots): the low nibble counts watchdog resets, the high
//! nibble brown-out resets, stored inverted so that an erased byte (0xFF) reads as no resets.
//! A one-byte write is atomic for this purpose: power lost during it leaves either value or
//! the erased byte (no resets), never a larger count.
//!
//! | reset cause (ATmega2560 MCUSR) | effect on the count |
//! |---|---|
//! | watchdog (WDRF; also every panic, which ends in a watchdog reset) | +1 watchdog |
//! | brown-out (BORF) | +1 brown-out |
//! | power-on (PORF) or the reset pin (EXTRF) | cleared: the operator restarted the pump |
//! | none (a bootloader cleared MCUSR) | unchanged |
//!
//! [`LIMIT`] abnormal resets without [`CLEAN_TICKS`] of running in between (counted from each
//! boot) are a reset loop: the state machine starts in the fault state (duty 0, `FAULT resets
//! watchdog=<n> brownout=<n>`), latched until a power-on or reset-pin reset. After
//! [`CLEAN_TICKS`] without a reset the count is cleared.
//!
//! The count takes the reset cause in the ATmega2560's MCUSR bits; the STM32F411's reset flags
//! (RCC_CSR) are translated into them first ([`cause_from_rcc_csr`]). There the count lives
//! in a backup register (`board/blackpill_f411.rs`), not in this module's byte offset.

/// MCUSR bits (ATmega2560 datasheet, section 12.5.1 "MCUSR – MCU Status Register").
const PORF: u8 = 1 << 0;
/// External reset flag.
const EXTRF: u8 = 1 << 1;
/// Brown-out reset flag.
const BORF: u8 = 1 << 2;
/// Watchdog reset flag.
const WDRF: u8 = 1 << 3;

/// Abnormal resets (watchdog + brown-out) that make a reset loop.
pub const LIMIT: u8 = 3;

/// Ticks of running after a boot (10 ms each: 60 s) after which the count is cleared.
pub const CLEAN_TICKS: u16 = 6_000;

/// Where the count byte lives, from the board's storage base: right after the two record
/// slots.
pub const COUNT_OFFSET: u16 = crate::slots::STORE_LEN as u16;

/// Resets counted since the last power-on, reset-pin reset or clean minute, each saturating
/// at 15.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Resets {
    /// Watchdog resets (panics included).
    pub watchdog: u8,
    /// Brown-out resets.
    pub brownout: u8,
}

impl Resets {
    /// The count as stored (see the [module docs](self)).
    pub const fn from_byte(stored: u8) -> Self {
        let b = !stored;
        Resets {
            watchdog: b & 0x0F,
            brownout: b >> 4,
        }
    }

    /// The byte to store.
    pub const fn to_byte(self) -> u8 {
        !((self.watchdog & 0x0F) | (self.brownout << 4))
    }

    /// The count after a boot whose reset cause (MCUSR) is `cause`.
    pub const fn after_boot(self, cause: u8) -> Self {
        if cause & (PORF | EXTRF) != 0 {
            return Resets {
                watchdog: 0,
                brownout: 0,
            };
        }
        Resets {
            watchdog: bump(self.watchdog, cause & WDRF != 0),
            brownout: bump(self.brownout, cause & BORF != 0),
        }
    }

    /// Whether these resets make a reset loop (see [`LIMIT`]).
    pub const fn is_loop(self) -> bool {
        self.watchdog + self.brownout >= LIMIT
    }
}

// RCC_CSR reset flags as the byte RCC_CSR >> 24 (RM0383 §6.3.18 "RCC clock control & status
// register": bit 25 BORRSTF, 26 PINRSTF, 27 PORRSTF, 28 SFTRSTF, 29 IWDGRSTF, 30 WWDGRSTF,
// 31 LPWRRSTF).
const CSR_BOR: u8 = 1 << 1;
const CSR_PIN: u8 = 1 << 2;
const CSR_POR: u8 = 1 << 3;
const CSR_SFT: u8 = 1 << 4;
const CSR_IWDG: u8 = 1 << 5;
const CSR_WWDG: u8 = 1 << 6;
const CSR_LPWR: u8 = 1 << 7;

/// The STM32F411's reset flags (RCC_CSR bits 31..24 as a byte, as its `BOOT` line prints
/// them) as the MCUSR bits [`Resets::after_boot`] takes:
///
/// | RCC_CSR flags | MCUSR |
/// |---|---|
/// | PORRSTF (power-on or power-down reset; BORRSTF comes with it) | PORF: cleared |
/// | IWDGRSTF or WWDGRSTF (every panic ends in an IWDG reset) | WDRF: +1 watchdog |
/// | BORRSTF without PORRSTF (a brown-out with BOR enabled in the option bytes) | BORF: +1 brown-out |
/// | PINRSTF alone, or SFTRSTF (the reset button; a debugger or flasher resets by software: the image never does) | EXTRF: cleared |
/// | LPWRRSTF alone (the image never enters Stop or Standby), none | none: unchanged |
///
/// An internal reset (watchdog, software) drives NRST low through the reset pulse generator
/// (RM0383 §6.1.2, Figure 11), so PINRSTF comes with it: only PINRSTF with no other flag is
/// the reset pin.
pub const fn cause_from_rcc_csr(flags: u8) -> u8 {
    if flags & CSR_POR != 0 {
        return PORF;
    }
    let mut cause = 0;
    if flags & (CSR_IWDG | CSR_WWDG) != 0 {
        cause |= WDRF;
    }
    if flags & CSR_BOR != 0 {
        cause |= BORF;
    }
    let others = CSR_BOR | CSR_IWDG | CSR_WWDG | CSR_LPWR;
    if flags & CSR_SFT != 0 || (flags & CSR_PIN != 0 && flags & others == 0) {
        cause |= EXTRF;
    }
    cause
}

/// `n + 1` if `hit`, saturating at 15 (a nibble).
const fn bump(n: u8, hit: bool) -> u8 {
    if hit && n < 15 {
        n + 1
    } else {
        n
    }
}
