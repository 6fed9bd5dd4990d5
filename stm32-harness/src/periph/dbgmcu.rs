//! DBGMCU, the MCU debug component (RM0383 §23.16): the ID code and the freeze registers.
//!
//! Modelled: `DBGMCU_IDCODE` (§23.16.1, DEV_ID 0x431 for the STM32F411xC/E, REV_ID 0x1000),
//! `DBGMCU_CR` (§23.16.2), `DBGMCU_APB1_FZ` (§23.16.3), `DBGMCU_APB2_FZ` (§23.16.4), stored.
//! Simplification: the freeze bits have no effect: no debugger halts the emulated core.

use super::Unmodelled;

/// Base address.
pub const BASE: u32 = 0xE004_2000;

/// The debug registers.
#[derive(Clone, Debug, Default)]
pub struct Dbgmcu {
    regs: [u32; 3],
}

impl Dbgmcu {
    /// Register read.
    pub fn read(&self, off: u32) -> Result<u32, Unmodelled> {
        match off {
            0 => Ok(0x1000_6431),
            4 | 8 | 12 => Ok(self.regs[(off / 4 - 1) as usize]),
            _ => Err(Unmodelled),
        }
    }

    /// Register write.
    pub fn write(&mut self, off: u32, v: u32) -> Result<(), Unmodelled> {
        match off {
            0 => Ok(()),
            4 | 8 | 12 => {
                self.regs[(off / 4 - 1) as usize] = v;
                Ok(())
            }
            _ => Err(Unmodelled),
        }
    }
}
