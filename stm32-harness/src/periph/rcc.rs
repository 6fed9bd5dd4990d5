//! RCC, reset and clock control (RM0383 §6): the clock tree the image sets up (HSE 25 MHz and
//! the main PLL to 100 MHz), the peripheral enable and reset registers, and the reset flags.
//!
//! Modelled:
//! - `RCC_CR` (§6.3.1): each ready flag (HSIRDY, HSERDY, PLLRDY, PLLI2SRDY) follows its enable
//!   (HSION, HSEON, PLLON, PLLI2SON). Simplification: at once; a real HSE needs its start-up
//!   time (≈ 2 ms, crystal dependent) and the PLL its lock time (≤ 100 µs), which the image
//!   only waits for.
//! - `RCC_PLLCFGR` (§6.3.2), `RCC_CFGR` (§6.3.3): SWS follows SW when the selected source is
//!   ready; SYSCLK, HCLK, PCLK1/2 and the timer clocks (§6.2, "TIMPRE = 0: the timer clock is
//!   PCLKx when the APBx prescaler is 1, else 2 × PCLKx") are computed from them.
//! - enable and reset registers (§6.3.5–§6.3.16) are stored. Simplification: a peripheral
//!   whose clock is off still answers (the real one ignores writes and reads 0).
//! - `RCC_CSR` (§6.3.18): LSION/LSIRDY, RMVF (writing 1 clears the reset flags), reset flags
//!   set by [`Rcc::reset`] (power-on: reset value 0x0E00_0000, POR + PIN + BOR; a power
//!   reset, power-on or brown-out, clears the flags before setting its own).
//! - other registers (CIR, BDCR, SSCGR, PLLI2SCFGR, DCKCFGR) are stored with their reset
//!   values.

use super::Unmodelled;

/// HSE crystal of the Black Pill, Hz.
pub const HSE_HZ: u32 = 25_000_000;
/// HSI RC oscillator, Hz (§6.2.2).
pub const HSI_HZ: u32 = 16_000_000;

// RCC_CR bits (§6.3.1).
const CR_HSION: u32 = 1 << 0;
const CR_HSIRDY: u32 = 1 << 1;
const CR_HSEON: u32 = 1 << 16;
const CR_HSERDY: u32 = 1 << 17;
const CR_PLLON: u32 = 1 << 24;
const CR_PLLRDY: u32 = 1 << 25;
const CR_PLLI2SON: u32 = 1 << 26;
const CR_PLLI2SRDY: u32 = 1 << 27;
const CR_READY: u32 = CR_HSIRDY | CR_HSERDY | CR_PLLRDY | CR_PLLI2SRDY;

// RCC_CSR bits (§6.3.18).
const CSR_LSION: u32 = 1 << 0;
const CSR_LSIRDY: u32 = 1 << 1;
const CSR_RMVF: u32 = 1 << 24;
/// Reset flags, bits 31..25 (LPWR, WWDG, IWDG, SFT, POR, PIN, BOR).
const CSR_FLAGS: u32 = 0xFE00_0000;

/// What caused a reset, as RCC_CSR records it (§6.3.18).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetCause {
    /// Power-on: PORRSTF, PINRSTF and BORRSTF (the register's documented reset value).
    PowerOn,
    /// Independent watchdog: IWDGRSTF.
    Watchdog,
    /// Software (`SCB_AIRCR.SYSRESETREQ`): SFTRSTF.
    Software,
    /// The NRST pin (a reset button): PINRSTF.
    Pin,
    /// Brown-out (the supply below the BOR level set in the option bytes): a power reset,
    /// BORRSTF with PINRSTF.
    BrownOut,
}

impl ResetCause {
    /// The RCC_CSR flags this reset sets. An internal reset (watchdog, software) drives the
    /// NRST pin low through the reset pulse generator (§6.1.2, Figure 11), so PINRSTF comes
    /// with it, as on the chip.
    pub fn flags(self) -> u32 {
        const BOR: u32 = 1 << 25;
        const PIN: u32 = 1 << 26;
        const POR: u32 = 1 << 27;
        const SFT: u32 = 1 << 28;
        const IWDG: u32 = 1 << 29;
        match self {
            ResetCause::PowerOn => POR | PIN | BOR,
            ResetCause::Watchdog => IWDG | PIN,
            ResetCause::Software => SFT | PIN,
            ResetCause::Pin => PIN,
            ResetCause::BrownOut => BOR | PIN,
        }
    }

    /// Whether this is a power reset (§6.1.2), which clears the reset flags before setting
    /// its own.
    pub fn is_power_reset(self) -> bool {
        matches!(self, ResetCause::PowerOn | ResetCause::BrownOut)
    }
}

/// The clock frequencies the RCC registers select, Hz.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Clocks {
    /// SYSCLK.
    pub sysclk: u32,
    /// HCLK (AHB, the core).
    pub hclk: u32,
    /// PCLK1 (APB1: TIM3, TIM5, I2C1, IWDG's bus).
    pub pclk1: u32,
    /// PCLK2 (APB2: USART1).
    pub pclk2: u32,
    /// Timer clock of the APB1 timers.
    pub tim1clk: u32,
}

/// The RCC registers.
#[derive(Clone, Debug)]
pub struct Rcc {
    regs: [u32; 0x90 / 4],
}

/// Offsets (§6.3.22, register map).
pub const CR: u32 = 0x00;
/// PLL configuration.
pub const PLLCFGR: u32 = 0x04;
/// Clock configuration.
pub const CFGR: u32 = 0x08;
/// Control/status (reset flags).
pub const CSR: u32 = 0x74;

/// Reset values (§6.3.1–§6.3.21); offsets without a register are `None`.
fn reset_value(off: u32) -> Option<u32> {
    Some(match off {
        0x00 => 0x0000_0083, // CR: HSION, HSIRDY, HSITRIM = 16
        0x04 => 0x2400_3010, // PLLCFGR
        0x08 => 0,           // CFGR
        0x0C => 0,           // CIR
        0x10 | 0x14 | 0x20 | 0x24 => 0,
        0x30 | 0x34 | 0x40 | 0x44 => 0,
        0x50 => 0x0061_909F, // AHB1LPENR
        0x54 => 0x0000_0080, // AHB2LPENR
        0x60 => 0x10E2_C80F, // APB1LPENR
        0x64 => 0x0077_7F33, // APB2LPENR
        0x70 => 0,           // BDCR
        0x74 => 0x0E00_0000, // CSR
        0x80 => 0,           // SSCGR
        0x84 => 0x2400_3000, // PLLI2SCFGR
        0x8C => 0,           // DCKCFGR
        _ => return None,
    })
}

impl Default for Rcc {
    fn default() -> Self {
        Self::new()
    }
}

impl Rcc {
    /// Power-on state.
    pub fn new() -> Self {
        let mut regs = [0; 0x90 / 4];
        for (i, r) in regs.iter_mut().enumerate() {
            *r = reset_value(i as u32 * 4).unwrap_or(0);
        }
        Rcc { regs }
    }

    fn reg(&self, off: u32) -> u32 {
        self.regs[(off / 4) as usize]
    }

    fn set(&mut self, off: u32, v: u32) {
        self.regs[(off / 4) as usize] = v;
    }

    /// A system reset by `cause`: every register back to its reset value except the reset
    /// flags, which accumulate until RMVF (§6.3.18: "reset by system reset, except reset flags
    /// by power reset only").
    pub fn reset(&mut self, cause: ResetCause) {
        let flags = if cause.is_power_reset() {
            0
        } else {
            self.reg(CSR) & CSR_FLAGS
        };
        *self = Self::new();
        let csr = (self.reg(CSR) & !CSR_FLAGS) | flags | cause.flags();
        self.set(CSR, csr);
    }

    /// RCC_APB1ENR.PWREN (§6.3.11): the PWR interface's clock.
    pub fn pwr_clock(&self) -> bool {
        self.reg(0x40) & (1 << 28) != 0
    }

    /// The reset flags now (RCC_CSR bits 31..24 as a byte, as the image prints them).
    pub fn reset_flags(&self) -> u8 {
        (self.reg(CSR) >> 24) as u8
    }

    /// Register read.
    pub fn read(&mut self, off: u32) -> Result<u32, Unmodelled> {
        reset_value(off).ok_or(Unmodelled)?;
        Ok(self.reg(off))
    }

    /// Register write.
    pub fn write(&mut self, off: u32, v: u32) -> Result<(), Unmodelled> {
        reset_value(off).ok_or(Unmodelled)?;
        match off {
            CR => {
                // HSION cannot be cleared while HSI is the system clock (§6.3.1); the ready
                // flags follow their enables.
                let mut cr = v & !CR_READY;
                if self.sws() == 0 {
                    cr |= CR_HSION;
                }
                let on = [
                    (CR_HSION, CR_HSIRDY),
                    (CR_HSEON, CR_HSERDY),
                    (CR_PLLON, CR_PLLRDY),
                    (CR_PLLI2SON, CR_PLLI2SRDY),
                ];
                for (en, rdy) in on {
                    if cr & en != 0 {
                        cr |= rdy;
                    }
                }
                // Read-only calibration bits 15..8 kept.
                cr = (cr & !0xFF00) | (self.reg(CR) & 0xFF00);
                self.set(CR, cr);
                self.update_sws();
            }
            CFGR => {
                // SWS (bits 3:2) is read-only.
                self.set(CFGR, (v & !0xC) | (self.reg(CFGR) & 0xC));
                self.update_sws();
            }
            CSR => {
                let mut csr =
                    (v & !(CSR_FLAGS | CSR_RMVF | CSR_LSIRDY)) | (self.reg(CSR) & CSR_FLAGS);
                if v & CSR_RMVF != 0 {
                    csr &= !CSR_FLAGS;
                }
                if csr & CSR_LSION != 0 {
                    csr |= CSR_LSIRDY;
                }
                self.set(CSR, csr);
            }
            _ => self.set(off, v),
        }
        Ok(())
    }

    fn sws(&self) -> u32 {
        (self.reg(CFGR) >> 2) & 3
    }

    /// SWS follows SW once the selected oscillator is ready (§6.3.3).
    fn update_sws(&mut self) {
        let sw = self.reg(CFGR) & 3;
        let cr = self.reg(CR);
        let ready = match sw {
            0 => cr & CR_HSIRDY != 0,
            1 => cr & CR_HSERDY != 0,
            2 => cr & CR_PLLRDY != 0,
            _ => false,
        };
        if ready {
            let cfgr = (self.reg(CFGR) & !0xC) | (sw << 2);
            self.set(CFGR, cfgr);
        }
    }

    /// The PLL output (§6.3.2: f = f_in / PLLM × PLLN / PLLP), Hz.
    fn pll_hz(&self) -> u32 {
        let p = self.reg(PLLCFGR);
        let m = u64::from(p & 0x3F).max(2);
        let n = u64::from((p >> 6) & 0x1FF);
        let pdiv = 2 * (u64::from((p >> 16) & 3) + 1);
        let src = if p & (1 << 22) != 0 { HSE_HZ } else { HSI_HZ };
        (u64::from(src) * n / m / pdiv) as u32
    }

    /// The clocks the registers select now.
    pub fn clocks(&self) -> Clocks {
        let sysclk = match self.sws() {
            1 => HSE_HZ,
            2 => self.pll_hz(),
            _ => HSI_HZ,
        };
        let cfgr = self.reg(CFGR);
        // HPRE (§6.3.3): 0xxx: /1, 1000: /2 ... 1111: /512 (no /32).
        let hpre = (cfgr >> 4) & 0xF;
        let ahb_div = match hpre {
            0..=7 => 1,
            8..=11 => 2 << (hpre - 8),
            _ => 64 << (hpre - 12),
        };
        let hclk = sysclk / ahb_div;
        // PPRE1/2: 0xx: /1, 100: /2, 101: /4, 110: /8, 111: /16.
        let apb_div = |bits: u32| if bits < 4 { 1 } else { 2 << (bits - 4) };
        let d1 = apb_div((cfgr >> 10) & 7);
        let d2 = apb_div((cfgr >> 13) & 7);
        let pclk1 = hclk / d1;
        let pclk2 = hclk / d2;
        Clocks {
            sysclk,
            hclk,
            pclk1,
            pclk2,
            tim1clk: if d1 == 1 { pclk1 } else { 2 * pclk1 },
        }
    }
}
