//! GPIO ports A and B (RM0383 §8): the mode, type, speed, pull and alternate-function
//! registers the HAL configures for the pins the image uses (PA6 TIM3_CH1, PA9/PA10 USART1,
//! PB6/PB7 I2C1), and the output data register.
//!
//! Modelled: `GPIOx_MODER` (§8.4.1), `OTYPER` (§8.4.2), `OSPEEDR` (§8.4.3), `PUPDR` (§8.4.4),
//! `IDR` (§8.4.5), `ODR` (§8.4.6), `BSRR` (§8.4.7, write-only: BSy sets, BRy resets, BS wins),
//! `LCKR` (§8.4.8, stored, the lock sequence not modelled), `AFRL`/`AFRH` (§8.4.9, §8.4.10).
//! Reset values of port A and B differ (the debug pins, §8.4.1).
//!
//! Simplification: `IDR` reads an output pin's `ODR` bit and an input or alternate-function
//! pin as its pull (high with a pull-up or an open-drain I2C line, else low); the bus
//! ([`crate::chip`]) replaces PB6/PB7 with the I2C lines' levels ([`crate::bus`]).

use super::Unmodelled;

/// Register offsets (§8.4.11, register map).
pub const MODER: u32 = 0x00;
/// Output data register.
pub const ODR: u32 = 0x14;
/// Bit set/reset register.
pub const BSRR: u32 = 0x18;

/// One GPIO port.
#[derive(Clone, Debug)]
pub struct Gpio {
    port: char,
    regs: [u32; 10],
}

impl Gpio {
    /// Port `port` (`'A'` or `'B'`) at reset.
    pub fn new(port: char) -> Self {
        let mut g = Gpio {
            port,
            regs: [0; 10],
        };
        g.reset();
        g
    }

    /// Reset values (§8.4.1–§8.4.4).
    pub fn reset(&mut self) {
        self.regs = [0; 10];
        let (moder, ospeedr, pupdr) = match self.port {
            'A' => (0x0C00_0000, 0x0C00_0000, 0x6400_0000),
            'B' => (0x0000_0280, 0x0000_00C0, 0x0000_0100),
            _ => (0, 0, 0),
        };
        self.regs[0] = moder;
        self.regs[2] = ospeedr;
        self.regs[3] = pupdr;
    }

    /// Mode of pin `n`: 0 input, 1 output, 2 alternate function, 3 analog.
    pub fn mode(&self, n: u32) -> u32 {
        (self.regs[0] >> (2 * n)) & 3
    }

    /// Alternate function number of pin `n`.
    pub fn alternate(&self, n: u32) -> u32 {
        let r = if n < 8 { self.regs[8] } else { self.regs[9] };
        (r >> (4 * (n % 8))) & 0xF
    }

    /// Whether pin `n` drives its line low: a general-purpose output with its `ODR` bit 0
    /// (in open-drain or push-pull type alike).
    pub fn drives_low(&self, n: u32) -> bool {
        self.mode(n) == 1 && self.regs[5] >> n & 1 == 0
    }

    /// `ODR`.
    pub fn read_odr(&self) -> u32 {
        self.regs[5]
    }

    /// Register read.
    pub fn read(&mut self, off: u32) -> Result<u32, Unmodelled> {
        match off {
            0x10 => Ok(self.idr()),
            BSRR => Ok(0),
            0x00..=0x24 if off % 4 == 0 => Ok(self.regs[(off / 4) as usize]),
            _ => Err(Unmodelled),
        }
    }

    fn idr(&self) -> u32 {
        let mut v = 0;
        for n in 0..16 {
            let high = match self.mode(n) {
                1 => self.regs[5] >> n & 1 != 0,
                // Open-drain alternate function (I2C): the external pull-up.
                2 if self.regs[1] >> n & 1 != 0 => true,
                _ => (self.regs[3] >> (2 * n)) & 3 == 1,
            };
            if high {
                v |= 1 << n;
            }
        }
        v
    }

    /// Register write.
    pub fn write(&mut self, off: u32, v: u32) -> Result<(), Unmodelled> {
        match off {
            0x10 => {} // IDR is read-only
            BSRR => {
                let set = v & 0xFFFF;
                let reset = v >> 16;
                self.regs[5] = (self.regs[5] & !reset) | set;
            }
            ODR | 0x04 => self.regs[(off / 4) as usize] = v & 0xFFFF,
            0x00..=0x24 if off % 4 == 0 => self.regs[(off / 4) as usize] = v,
            _ => return Err(Unmodelled),
        }
        Ok(())
    }
}
