//! The power controller's control registers (PWR, RM0383 §5.4) and the backup domain's 20
//! backup registers (RTC_BKPxR, §17.6.20): what the image uses to keep its reset-loop count
//! across resets.
//!
//! Modelled:
//! - `PWR_CR` (§5.4.1, reset value 0x0000_C000) and `PWR_CSR` (§5.4.2, 0), stored. DBP
//!   (PWR_CR bit 8) lifts the backup domain's write protection (§5.1.2 "Backup domain
//!   access": after reset the domain is protected against unwanted writes). Writes to PWR
//!   take effect only with its interface clock on (RCC_APB1ENR.PWREN, §6.3.11): a write with
//!   the clock off is dropped and counted in [`Backup::dropped`]; the bus passes the enable.
//! - `RTC_BKPxR`: read at any time (no RTC clock needed: the registers sit on the APB
//!   interface); written only while DBP is set, otherwise the write is dropped and counted.
//!   They keep their content across every system reset and power reset (§6.1.2); a
//!   backup-domain reset (§6.1.3: VDD and VBAT both lost, or RCC_BDCR.BDRST) clears them to 0.
//!   The bench's power cycle is such a loss (the Black Pill's VBAT pin fed from its 3.3 V, no
//!   battery): [`Backup::domain_reset`].
//! - Simplification: the other RTC registers (time, date, alarms, wake-up) are not modelled:
//!   an access to them is reported as unmodelled by the bus.

use super::Unmodelled;

/// PWR base address.
pub const PWR: u32 = 0x4000_7000;
/// RTC base address.
pub const RTC: u32 = 0x4000_2800;
/// Offset of RTC_BKP0R in the RTC block.
pub const BKP0R: u32 = 0x50;
/// Backup registers.
pub const BKP_COUNT: usize = 20;
/// PWR_CR.DBP.
pub const CR_DBP: u32 = 1 << 8;

/// PWR and the backup registers.
#[derive(Clone, Debug)]
pub struct Backup {
    cr: u32,
    csr: u32,
    /// The backup registers.
    pub bkp: [u32; BKP_COUNT],
    /// Writes dropped: to PWR with its clock off, or to a backup register with DBP clear.
    pub dropped: u64,
}

impl Default for Backup {
    fn default() -> Self {
        Self::new()
    }
}

impl Backup {
    /// A powered-up backup domain (registers 0).
    pub fn new() -> Self {
        Backup {
            cr: 0x0000_C000,
            csr: 0,
            bkp: [0; BKP_COUNT],
            dropped: 0,
        }
    }

    /// A system or power reset: PWR to its reset values, the backup registers kept.
    pub fn reset(&mut self) {
        self.cr = 0x0000_C000;
        self.csr = 0;
    }

    /// A backup-domain reset: the backup registers cleared too.
    pub fn domain_reset(&mut self) {
        *self = Backup {
            dropped: self.dropped,
            ..Backup::new()
        };
    }

    /// PWR register read.
    pub fn read_pwr(&self, off: u32) -> Result<u32, Unmodelled> {
        match off {
            0x00 => Ok(self.cr),
            0x04 => Ok(self.csr),
            _ => Err(Unmodelled),
        }
    }

    /// PWR register write; `clock` is RCC_APB1ENR.PWREN.
    pub fn write_pwr(&mut self, off: u32, v: u32, clock: bool) -> Result<(), Unmodelled> {
        if !matches!(off, 0x00 | 0x04) {
            return Err(Unmodelled);
        }
        if !clock {
            self.dropped += 1;
            return Ok(());
        }
        match off {
            // CSR: only EWUP (bit 8) and BRE (bit 9) are writable; the flags read-only.
            0x04 => self.csr = (self.csr & !0x300) | (v & 0x300),
            _ => self.cr = v,
        }
        Ok(())
    }

    /// RTC register read (the backup registers only).
    pub fn read_rtc(&self, off: u32) -> Result<u32, Unmodelled> {
        Self::bkp_index(off).map(|i| self.bkp[i]).ok_or(Unmodelled)
    }

    /// RTC register write (the backup registers only).
    pub fn write_rtc(&mut self, off: u32, v: u32) -> Result<(), Unmodelled> {
        let i = Self::bkp_index(off).ok_or(Unmodelled)?;
        if self.cr & CR_DBP != 0 {
            self.bkp[i] = v;
        } else {
            self.dropped += 1;
        }
        Ok(())
    }

    fn bkp_index(off: u32) -> Option<usize> {
        let i = off.checked_sub(BKP0R)? / 4;
        (off % 4 == 0 && (i as usize) < BKP_COUNT).then_some(i as usize)
    }
}
