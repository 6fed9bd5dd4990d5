//! The Cortex-M4 system control block and the FPU's system registers (PM0214 §4.4, §4.6),
//! and the system timer SysTick (§4.5), as far as the startup code (cortex-m-rt) and the
//! image use them.
//!
//! Modelled:
//! - `CPUID` (§4.4.1, Cortex-M4 r0p1: 0x410F_C241), `ICSR` (§4.4.2: VECTACTIVE, VECTPENDING,
//!   ISRPENDING from the machine), `VTOR` (§4.4.3), `AIRCR` (§4.4.4: PRIGROUP stored;
//!   SYSRESETREQ with the key 0x05FA requests a system reset), `SCR` (§4.4.5), `CCR` (§4.4.6,
//!   reset STKALIGN set), `SHPR1..3` (§4.4.7), `SHCSR` (§4.4.9), the fault status registers
//!   (§4.4.10–§4.4.15), stored; `ACTLR` (§4.3.1).
//! - `CPACR` (§4.6.1) stored. Simplification: Unicorn executes FP instructions whatever CP10
//!   and CP11 say (the startup code enables them before any FP instruction).
//! - `FPCCR` (§4.6.2: reset ASPEN | LSPEN, automatic state preservation with lazy stacking),
//!   `FPCAR` (§4.6.3), `FPDSCR` (§4.6.4): FPCCR.ASPEN decides whether exception entry saves
//!   the FP context (the machine's exception entry, see [`crate::machine`]).
//! - SysTick `STK_CTRL`, `STK_LOAD`, `STK_VAL`, `STK_CALIB` (§4.5): counts down on the
//!   processor clock (CLKSOURCE = 1) or HCLK/8, COUNTFLAG and TICKINT (exception 15).
//!   Simplification: the image does not use it; it is modelled so that a use is seen.

use super::{ps_to_cycles, Time, Unmodelled};

/// SysTick exception number.
pub const EXC_SYSTICK: u32 = 15;

/// The system control block, FPU system registers and SysTick.
#[derive(Clone, Debug)]
pub struct Scb {
    /// `VTOR`.
    pub vtor: u32,
    aircr: u32,
    scr: u32,
    ccr: u32,
    shpr: [u32; 3],
    shcsr: u32,
    faults: [u32; 6],
    actlr: u32,
    cpacr: u32,
    /// `FPCCR`.
    pub fpccr: u32,
    fpcar: u32,
    fpdscr: u32,
    /// A system reset was requested (AIRCR.SYSRESETREQ).
    pub reset_requested: bool,
    stk_ctrl: u32,
    stk_load: u32,
    /// SysTick: counter value at `stk_base` (when it runs).
    stk_val: u32,
    stk_base: Time,
}

impl Default for Scb {
    fn default() -> Self {
        Self::new()
    }
}

/// `FPCCR.ASPEN`: automatic FP state preservation on exception entry.
pub const FPCCR_ASPEN: u32 = 1 << 31;
/// `FPCCR.LSPEN`: lazy state preservation.
pub const FPCCR_LSPEN: u32 = 1 << 30;

impl Scb {
    /// Reset values.
    pub fn new() -> Self {
        Scb {
            vtor: 0,
            aircr: 0xFA05_0000,
            scr: 0,
            ccr: 0x200,
            shpr: [0; 3],
            shcsr: 0,
            faults: [0; 6],
            actlr: 0,
            cpacr: 0,
            fpccr: FPCCR_ASPEN | FPCCR_LSPEN,
            fpcar: 0,
            fpdscr: 0,
            reset_requested: false,
            stk_ctrl: 0,
            stk_load: 0,
            stk_val: 0,
            stk_base: 0,
        }
    }

    /// `CCR.STKALIGN`: 8-byte stack alignment on exception entry.
    pub fn stkalign(&self) -> bool {
        self.ccr & 0x200 != 0
    }

    /// AIRCR.PRIGROUP.
    pub fn prigroup(&self) -> u32 {
        (self.aircr >> 8) & 7
    }

    /// Priority byte of system exception `exc` (4..15).
    pub fn system_priority(&self, exc: u32) -> u8 {
        if !(4..16).contains(&exc) {
            return 0;
        }
        let i = exc - 4;
        (self.shpr[(i / 4) as usize] >> (8 * (i % 4))) as u8
    }

    fn systick_count(&self, now: Time, hclk: u32) -> u32 {
        if self.stk_ctrl & 1 == 0 {
            return self.stk_val;
        }
        let hz = if self.stk_ctrl & 4 != 0 {
            hclk
        } else {
            hclk / 8
        };
        let ticks = ps_to_cycles(now.saturating_sub(self.stk_base), hz);
        let period = u64::from(self.stk_load) + 1;
        let v = u64::from(self.stk_val);
        if ticks <= v {
            (v - ticks) as u32
        } else {
            (self.stk_load as u64 - ((ticks - v - 1) % period)) as u32
        }
    }

    /// Whether SysTick is counting with its interrupt enabled.
    pub fn systick_irq_enabled(&self) -> bool {
        self.stk_ctrl & 3 == 3
    }

    /// Register read at `addr` (0xE000_E000..0xE000_EFFF, outside the NVIC's range).
    pub fn read(&mut self, addr: u32, now: Time, hclk: u32, icsr: u32) -> Result<u32, Unmodelled> {
        Ok(match addr {
            0xE000_E004 => 2, // ICTR: 96 interrupt lines
            0xE000_E008 => self.actlr,
            0xE000_E010 => {
                let c = self.stk_ctrl;
                // COUNTFLAG (bit 16) reads 1 if the counter reached 0 since the last read;
                // approximated by the counter having wrapped since it was started.
                let wrapped = self.stk_ctrl & 1 != 0
                    && ps_to_cycles(now.saturating_sub(self.stk_base), hclk)
                        > u64::from(self.stk_val);
                c | if wrapped { 1 << 16 } else { 0 }
            }
            0xE000_E014 => self.stk_load,
            0xE000_E018 => self.systick_count(now, hclk),
            0xE000_E01C => 0x4000_0000, // CALIB: NOREF, no TENMS
            0xE000_ED00 => 0x410F_C241,
            0xE000_ED04 => icsr,
            0xE000_ED08 => self.vtor,
            0xE000_ED0C => self.aircr,
            0xE000_ED10 => self.scr,
            0xE000_ED14 => self.ccr,
            0xE000_ED18 => self.shpr[0],
            0xE000_ED1C => self.shpr[1],
            0xE000_ED20 => self.shpr[2],
            0xE000_ED24 => self.shcsr,
            0xE000_ED28..=0xE000_ED3C => self.faults[((addr - 0xE000_ED28) / 4) as usize],
            0xE000_ED88 => self.cpacr,
            0xE000_EF34 => self.fpccr,
            0xE000_EF38 => self.fpcar,
            0xE000_EF3C => self.fpdscr,
            _ => return Err(Unmodelled),
        })
    }

    /// Register write at `addr`.
    pub fn write(&mut self, addr: u32, v: u32, now: Time, hclk: u32) -> Result<(), Unmodelled> {
        match addr {
            0xE000_E008 => self.actlr = v,
            0xE000_E010 => {
                self.stk_val = self.systick_count(now, hclk);
                self.stk_base = now;
                self.stk_ctrl = v & 7;
            }
            0xE000_E014 => self.stk_load = v & 0x00FF_FFFF,
            0xE000_E018 => {
                self.stk_val = 0;
                self.stk_base = now;
            }
            0xE000_ED04 => {} // ICSR set/clear-pend bits: no use in the image
            0xE000_ED08 => self.vtor = v & 0xFFFF_FF80,
            0xE000_ED0C => {
                if v >> 16 == 0x05FA {
                    self.aircr = 0xFA05_0000 | (v & 0x700);
                    if v & 4 != 0 {
                        self.reset_requested = true;
                    }
                }
            }
            0xE000_ED10 => self.scr = v & 0x16,
            0xE000_ED14 => self.ccr = v & 0x31B,
            0xE000_ED18 => self.shpr[0] = v & 0xF0F0_F0F0,
            0xE000_ED1C => self.shpr[1] = v & 0xF000_0000,
            0xE000_ED20 => self.shpr[2] = v & 0xF0F0_0000,
            0xE000_ED24 => self.shcsr = v,
            // Fault status registers: write 1 to clear.
            0xE000_ED28..=0xE000_ED30 => self.faults[((addr - 0xE000_ED28) / 4) as usize] &= !v,
            0xE000_ED34..=0xE000_ED3C => self.faults[((addr - 0xE000_ED28) / 4) as usize] = v,
            0xE000_ED88 => self.cpacr = v & 0x00F0_0000,
            0xE000_EF34 => self.fpccr = v & 0xC000_01FB,
            0xE000_EF38 => self.fpcar = v & !7,
            0xE000_EF3C => self.fpdscr = v & 0x07C0_0000,
            _ => return Err(Unmodelled),
        }
        Ok(())
    }
}
