//! [`Prbs`]: a maximum-length LFSR pseudo-random binary sequence between two levels.

use core::iter::FusedIterator;

use super::hint;

/// Smallest LFSR order supported by [`Lfsr`].
pub const LFSR_ORDER_MIN: u8 = 2;
/// Largest LFSR order supported by [`Lfsr`].
pub const LFSR_ORDER_MAX: u8 = 16;

/// Feedback mask of a maximum-length Galois LFSR of `order` bits (right-shifting form:
/// `out = s & 1; s >>= 1; if out { s ^= mask }`), or `None` outside
/// [`LFSR_ORDER_MIN`]..=[`LFSR_ORDER_MAX`]. Bit `k-1` of the mask is the tap `x^k` of a
/// primitive polynomial, e.g. order 9: `0x110` = x⁹ + x⁵ + 1.
pub const fn lfsr_mask(order: u8) -> Option<u16> {
    match order {
        2 => Some(0x0003),
        3 => Some(0x0006),
        4 => Some(0x000C),
        5 => Some(0x0014),
        6 => Some(0x0030),
        7 => Some(0x0060),
        8 => Some(0x00B8),
        9 => Some(0x0110),
        10 => Some(0x0240),
        11 => Some(0x0500),
        12 => Some(0x0E08),
        13 => Some(0x1C80),
        14 => Some(0x3802),
        15 => Some(0x6000),
        16 => Some(0xD008),
        _ => None,
    }
}

/// Maximum-length linear feedback shift register of `order` bits: its output bit sequence
/// repeats every `2^order − 1` bits and contains `2^(order−1)` ones and `2^(order−1) − 1`
/// zeros per period.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lfsr {
    /// Register contents, never zero.
    state: u16,
    /// Galois feedback mask.
    mask: u16,
    /// Register length in bits.
    order: u8,
}

impl Lfsr {
    /// An LFSR of `order` bits (2..=16) started from `seed` (its low `order` bits; an all-zero
    /// seed, which would lock the register, is replaced by 1). `None` for an unsupported order.
    pub const fn new(order: u8, seed: u16) -> Option<Self> {
        let mask = match lfsr_mask(order) {
            Some(m) => m,
            None => return None,
        };
        let width_mask: u16 = match 1u16.checked_shl(order as u32) {
            Some(v) => v.wrapping_sub(1),
            None => u16::MAX,
        };
        let s = seed & width_mask;
        Some(Self {
            state: if s == 0 { 1 } else { s },
            mask,
            order,
        })
    }

    /// Register length in bits.
    pub const fn order(&self) -> u8 {
        self.order
    }

    /// Sequence period in bits: `2^order − 1`.
    pub const fn period(&self) -> u32 {
        // order <= 16, so the shift is in range and the result >= 3.
        1u32.wrapping_shl(self.order as u32).wrapping_sub(1)
    }

    /// Current register contents (never zero).
    pub const fn state(&self) -> u16 {
        self.state
    }

    /// Next output bit; advances the register by one.
    pub fn next_bit(&mut self) -> bool {
        let out = self.state & 1 != 0;
        self.state >>= 1;
        if out {
            self.state ^= self.mask;
        }
        out
    }
}

/// PRBS excitation: an [`Lfsr`] bit sequence mapped to two levels (bit 1 → `high`,
/// bit 0 → `low`), each bit held for `hold` samples, for a
/// whole number of LFSR periods: `len_samples = periods × (2^order − 1) × hold`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Prbs {
    /// Register at the start (for [`Prbs::reset`]).
    initial: Lfsr,
    /// Running register.
    lfsr: Lfsr,
    /// Level of a 0 bit.
    low: u16,
    /// Level of a 1 bit.
    high: u16,
    /// Samples per bit.
    hold: u16,
    /// Samples left of the current bit.
    hold_left: u16,
    /// Level of the current bit.
    level: u16,
    /// Total length in samples.
    total: u32,
    /// Samples emitted so far.
    emitted: u32,
}

impl Prbs {
    /// Builds a PRBS generator of LFSR `order` (2..=16, seed 1), levels `low`/`high`, `hold` samples per bit and `periods` full LFSR periods. `None` for an
    /// unsupported order, `hold == 0`, or a length that overflows a `u32` number of samples.
    pub const fn new(order: u8, low: u16, high: u16, hold: u16, periods: u16) -> Option<Self> {
        Self::with_seed(order, 1, low, high, hold, periods)
    }

    /// As [`Prbs::new`] with an explicit LFSR seed (see [`Lfsr::new`]); different seeds give
    /// cyclic shifts of the same sequence.
    pub const fn with_seed(
        order: u8,
        seed: u16,
        low: u16,
        high: u16,
        hold: u16,
        periods: u16,
    ) -> Option<Self> {
        if hold == 0 {
            return None;
        }
        let lfsr = match Lfsr::new(order, seed) {
            Some(l) => l,
            None => return None,
        };
        let total = match lfsr.period().checked_mul(hold as u32) {
            Some(b) => match b.checked_mul(periods as u32) {
                Some(t) => t,
                None => return None,
            },
            None => return None,
        };
        Some(Self {
            initial: lfsr,
            lfsr,
            low,
            high,
            hold,
            hold_left: 0,
            level: low,
            total,
            emitted: 0,
        })
    }

    /// The underlying register in its initial state.
    pub const fn initial_lfsr(&self) -> Lfsr {
        self.initial
    }

    /// Samples per bit.
    pub const fn hold(&self) -> u16 {
        self.hold
    }

    /// Level emitted for a 0 bit.
    pub const fn low(&self) -> u16 {
        self.low
    }

    /// Level emitted for a 1 bit.
    pub const fn high(&self) -> u16 {
        self.high
    }

    /// Total length in samples.
    pub const fn len_samples(&self) -> u32 {
        self.total
    }

    /// Samples still to come.
    pub const fn remaining(&self) -> u32 {
        self.total.saturating_sub(self.emitted)
    }

    /// Restarts from the first sample (same seed, same sequence).
    pub fn reset(&mut self) {
        self.lfsr = self.initial;
        self.hold_left = 0;
        self.level = self.low;
        self.emitted = 0;
    }

    /// Next level, or `None` at the end.
    pub fn next_duty(&mut self) -> Option<u16> {
        if self.emitted >= self.total {
            return None;
        }
        if self.hold_left == 0 {
            self.level = if self.lfsr.next_bit() {
                self.high
            } else {
                self.low
            };
            self.hold_left = self.hold;
        }
        self.hold_left = self.hold_left.saturating_sub(1);
        self.emitted = self.emitted.saturating_add(1);
        Some(self.level)
    }
}

impl Iterator for Prbs {
    type Item = u16;
    fn next(&mut self) -> Option<u16> {
        self.next_duty()
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        hint(self.remaining())
    }
}

impl FusedIterator for Prbs {}

#[cfg(test)]
mod tests {
    use super::*;

    fn drain<I: Iterator<Item = u16>>(it: I, buf: &mut [u16]) -> usize {
        let mut n = 0;
        for (slot, d) in buf.iter_mut().zip(it) {
            *slot = d;
            n += 1;
        }
        n
    }

    #[test]
    fn lfsr_is_maximum_length_for_all_orders() {
        for order in LFSR_ORDER_MIN..=LFSR_ORDER_MAX {
            let mut l = Lfsr::new(order, 1).unwrap();
            let start = l.state();
            let period = l.period();
            let mut ones = 0u32;
            let mut seen_period = 0u32;
            for i in 1..=period {
                if l.next_bit() {
                    ones += 1;
                }
                if l.state() == start {
                    seen_period = i;
                    break;
                }
            }
            assert_eq!(seen_period, (1u32 << order) - 1, "order {order}");
            // Balance: one more 1 than 0 per period.
            assert_eq!(ones, 1u32 << (order - 1), "order {order}");
        }
        assert!(Lfsr::new(1, 1).is_none());
        assert!(Lfsr::new(17, 1).is_none());
        assert_eq!(Lfsr::new(9, 0).unwrap().state(), 1);
        assert_eq!(Lfsr::new(4, 0xFFF0).unwrap().state(), 1);
    }

    #[test]
    fn prbs_two_periods_repeat() {
        let g = Prbs::new(5, 1_000, 9_000, 3, 2).unwrap();
        assert_eq!(g.len_samples(), 2 * 31 * 3);
        let mut buf = [0u16; 256];
        let n = drain(g, &mut buf);
        assert_eq!(n, 186);
        assert_eq!(&buf[..93], &buf[93..186]);
        assert!(Prbs::new(5, 1_000, 9_000, 0, 1).is_none());
        assert!(Prbs::new(20, 1_000, 9_000, 1, 1).is_none());
        // Levels are not bounded (any unit).
        assert!(Prbs::new(5, 1_000, u16::MAX, 1, 1).is_some());
        assert!(Prbs::new(16, 0, 1, u16::MAX, u16::MAX).is_none());
    }
}
