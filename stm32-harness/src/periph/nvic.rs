//! NVIC, the nested vectored interrupt controller of the Cortex-M4 (PM0214 §4.2, the STM32
//! Cortex-M4 programming manual; the interrupt numbers are RM0383 §10.2, Table 37).
//!
//! Modelled: `NVIC_ISER0..7` / `NVIC_ICER0..7` (§4.2.2, §4.2.3: set/clear-enable),
//! `NVIC_ISPR` / `NVIC_ICPR` (§4.2.4, §4.2.5: set/clear-pending), `NVIC_IABR` (§4.2.6,
//! active), `NVIC_IPR0..59` (§4.2.7, one priority byte per interrupt; the STM32F4 implements
//! the upper 4 bits), `NVIC_STIR` (§4.2.8). The peripherals' interrupt lines are levels: an
//! interrupt is pending while its line is high or its pending bit is set (§4.2.9, "level-
//! sensitive interrupts"); taking it clears the pending bit, and the line pends it again if
//! it is still high after the handler.
//!
//! Exception entry and return are the machine's (Unicorn has no interrupt controller); the
//! priority check here decides which pending interrupt may preempt what runs.

use super::Unmodelled;

/// USART1 global interrupt (RM0383 Table 37, position 37).
pub const IRQ_USART1: u32 = 37;
/// I2C1 event interrupt (position 31).
pub const IRQ_I2C1_EV: u32 = 31;
/// TIM5 global interrupt (position 50).
pub const IRQ_TIM5: u32 = 50;
/// Interrupts of the STM32F411 (positions 0..85).
pub const IRQS: u32 = 86;

/// The NVIC's registers.
#[derive(Clone, Debug)]
pub struct Nvic {
    enabled: [u32; 8],
    pending: [u32; 8],
    /// Set by the machine while the handler runs.
    active: [u32; 8],
    priority: [u8; 240],
}

impl Default for Nvic {
    fn default() -> Self {
        Self::new()
    }
}

impl Nvic {
    /// At reset: nothing enabled or pending, priorities 0.
    pub fn new() -> Self {
        Nvic {
            enabled: [0; 8],
            pending: [0; 8],
            active: [0; 8],
            priority: [0; 240],
        }
    }

    fn bit(irq: u32) -> (usize, u32) {
        ((irq / 32) as usize, 1 << (irq % 32))
    }

    /// Whether `irq` is enabled.
    pub fn is_enabled(&self, irq: u32) -> bool {
        let (w, b) = Self::bit(irq);
        self.enabled[w] & b != 0
    }

    /// Priority byte of `irq` (implemented bits 7:4).
    pub fn priority(&self, irq: u32) -> u8 {
        self.priority.get(irq as usize).copied().unwrap_or(0)
    }

    /// Marks `irq` active (handler entered: pending cleared) or not (handler returned).
    pub fn set_active(&mut self, irq: u32, active: bool) {
        let (w, b) = Self::bit(irq);
        if active {
            self.active[w] |= b;
            self.pending[w] &= !b;
        } else {
            self.active[w] &= !b;
        }
    }

    /// The enabled interrupt to take, given the peripheral lines that are high: pending
    /// (bit or line), enabled, not active, with the lowest priority value (then the lowest
    /// number, §4.2.9 / PM0214 §2.3.4 "Exception priorities").
    pub fn next(&self, lines: &[u32]) -> Option<u32> {
        let mut best: Option<(u8, u32)> = None;
        let mut consider = |irq: u32| {
            let (w, b) = Self::bit(irq);
            if self.enabled[w] & b != 0 && self.active[w] & b == 0 {
                let p = self.priority(irq);
                if best.is_none_or(|(bp, bi)| (p, irq) < (bp, bi)) {
                    best = Some((p, irq));
                }
            }
        };
        for &irq in lines {
            consider(irq);
        }
        for w in 0..8u32 {
            let mut bits = self.pending[w as usize];
            while bits != 0 {
                let k = bits.trailing_zeros();
                consider(w * 32 + k);
                bits &= bits - 1;
            }
        }
        best.map(|(_, irq)| irq)
    }

    /// Register read at offset `off` from 0xE000_E100.
    pub fn read(&self, off: u32, lines: &[u32]) -> Result<u32, Unmodelled> {
        let w = ((off & 0x7F) / 4) as usize;
        let line_bits = |w: usize| {
            lines
                .iter()
                .filter(|&&i| (i / 32) as usize == w)
                .fold(0, |a, &i| a | (1 << (i % 32)))
        };
        Ok(match off {
            0x000..=0x01C => self.enabled[w],
            0x080..=0x09C => self.enabled[w],
            0x100..=0x11C | 0x180..=0x19C => self.pending[w] | line_bits(w),
            0x200..=0x21C => self.active[w],
            0x300..=0x3EF => {
                let i = (off - 0x300) as usize;
                u32::from_le_bytes([
                    self.priority[i],
                    self.priority[i + 1],
                    self.priority[i + 2],
                    self.priority[i + 3],
                ])
            }
            _ => return Err(Unmodelled),
        })
    }

    /// Register write at offset `off` from 0xE000_E100, `size` bytes (priorities may be
    /// written by byte).
    pub fn write(&mut self, off: u32, v: u32, size: u32) -> Result<(), Unmodelled> {
        let w = ((off & 0x7F) / 4) as usize;
        match off {
            0x000..=0x01C => self.enabled[w] |= v,
            0x080..=0x09C => self.enabled[w] &= !v,
            0x100..=0x11C => self.pending[w] |= v,
            0x180..=0x19C => self.pending[w] &= !v,
            0x200..=0x21C => {}
            0x300..=0x3EF => {
                let i = (off - 0x300) as usize;
                for k in 0..size as usize {
                    if let Some(p) = self.priority.get_mut(i + k) {
                        *p = (v >> (8 * k)) as u8 & 0xF0;
                    }
                }
            }
            // STIR (0xE000_EF00) is written through the SCB's range.
            _ => return Err(Unmodelled),
        }
        Ok(())
    }

    /// `NVIC_STIR`: pends interrupt `v & 0x1FF`.
    pub fn trigger(&mut self, v: u32) {
        let irq = v & 0x1FF;
        if irq < 240 {
            let (w, b) = Self::bit(irq);
            self.pending[w] |= b;
        }
    }
}
