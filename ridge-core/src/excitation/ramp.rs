//! [`Ramp`]: linear ramps up and down between two levels.

use core::iter::FusedIterator;

use super::hint;

/// Shape of a [`Ramp`] excitation. Levels in the caller's units,
/// durations in samples.
///
/// The signal is: `lead_in` samples at `low`, then `cycles` times
/// `[ramp up | dwell_high at high | ramp down | dwell_low at low]`.
/// A ramp takes `ceil((high - low) / slope)` samples: the ramp up emits
/// `low, low + slope, low + 2 slope, …` (all below `high`), the ramp down
/// `high, high - slope, …` (all above `low`). When `slope` divides `high - low`, every
/// sample-to-sample change inside and between ramps is exactly `slope`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RampShape {
    /// Lower level.
    pub low: u16,
    /// Upper level (`low <= high`).
    pub high: u16,
    /// Slope magnitude in level units per sample (≥ 1 unless `low == high`).
    pub slope: u16,
    /// Samples at `low` before the first ramp (lets the plant settle).
    pub lead_in: u16,
    /// Samples held at `high` between the ramp up and the ramp down.
    pub dwell_high: u16,
    /// Samples held at `low` after each ramp down.
    pub dwell_low: u16,
    /// Number of up/down cycles.
    pub cycles: u16,
}

/// Ramp excitation: linear ramps between two levels, see [`RampShape`] for the exact shape.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ramp {
    /// Shape parameters.
    shape: RampShape,
    /// Samples per ramp (up or down).
    ramp_len: u32,
    /// Samples per cycle.
    cycle_len: u32,
    /// Total length in samples.
    total: u32,
    /// Index of the next sample.
    pos: u32,
}

impl Ramp {
    /// Builds a ramp generator.
    ///
    /// Returns `None` if `low > high`, `slope == 0` while
    /// `low != high`, or the total length overflows a `u32` number of samples.
    pub const fn new(shape: RampShape) -> Option<Self> {
        if shape.low > shape.high {
            return None;
        }
        let span = shape.high.saturating_sub(shape.low) as u32;
        let ramp_len = if span == 0 {
            0
        } else if shape.slope == 0 {
            return None;
        } else {
            span.div_ceil(shape.slope as u32)
        };
        // ramp_len <= 65_535, dwells <= 65_535: no overflow in u32.
        let cycle_len = ramp_len
            .saturating_mul(2)
            .saturating_add(shape.dwell_high as u32)
            .saturating_add(shape.dwell_low as u32);
        let body = match cycle_len.checked_mul(shape.cycles as u32) {
            Some(b) => b,
            None => return None,
        };
        let total = match body.checked_add(shape.lead_in as u32) {
            Some(t) => t,
            None => return None,
        };
        Some(Self {
            shape,
            ramp_len,
            cycle_len,
            total,
            pos: 0,
        })
    }

    /// The shape this generator follows.
    pub const fn shape(&self) -> RampShape {
        self.shape
    }

    /// Samples taken by one ramp (up or down): `ceil((high - low) / slope)`.
    pub const fn ramp_len(&self) -> u32 {
        self.ramp_len
    }

    /// Total length in samples.
    pub const fn len_samples(&self) -> u32 {
        self.total
    }

    /// Samples still to come.
    pub const fn remaining(&self) -> u32 {
        self.total.saturating_sub(self.pos)
    }

    /// Restarts from the first sample.
    pub fn reset(&mut self) {
        self.pos = 0;
    }

    /// Level of sample `n` (0-based), or `None` past the end.
    /// Pure: does not move the generator.
    pub const fn duty_at(&self, n: u32) -> Option<u16> {
        if n >= self.total {
            return None;
        }
        let s = &self.shape;
        let lead = s.lead_in as u32;
        if n < lead {
            return Some(s.low);
        }
        let mut m = match n.saturating_sub(lead).checked_rem(self.cycle_len) {
            Some(m) => m,
            None => return Some(s.low),
        };
        let low = s.low as u32;
        let high = s.high as u32;
        let slope = s.slope as u32;
        if m < self.ramp_len {
            // m < ramp_len <= 10_000 and slope <= 65_535: the product fits in u32.
            let v = low.saturating_add(m.saturating_mul(slope));
            return Some(if v > high { s.high } else { v as u16 });
        }
        m = m.saturating_sub(self.ramp_len);
        if m < s.dwell_high as u32 {
            return Some(s.high);
        }
        m = m.saturating_sub(s.dwell_high as u32);
        if m < self.ramp_len {
            let dv = m.saturating_mul(slope);
            return Some(if dv > high.saturating_sub(low) {
                s.low
            } else {
                high.saturating_sub(dv) as u16
            });
        }
        Some(s.low)
    }

    /// Next level, or `None` at the end.
    pub fn next_duty(&mut self) -> Option<u16> {
        let d = self.duty_at(self.pos);
        if d.is_some() {
            self.pos = self.pos.saturating_add(1);
        }
        d
    }
}

impl Iterator for Ramp {
    type Item = u16;
    fn next(&mut self) -> Option<u16> {
        self.next_duty()
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        hint(self.remaining())
    }
}

impl FusedIterator for Ramp {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drains a generator into a fixed buffer (no alloc in this crate), returning the count.
    fn drain<I: Iterator<Item = u16>>(it: I, buf: &mut [u16]) -> usize {
        let mut n = 0;
        for (slot, d) in buf.iter_mut().zip(it) {
            *slot = d;
            n += 1;
        }
        n
    }

    #[test]
    fn ramp_uneven_slope_and_invalid_shapes() {
        let shape = RampShape {
            low: 1_000,
            high: 1_010,
            slope: 3,
            lead_in: 1,
            dwell_high: 1,
            dwell_low: 0,
            cycles: 1,
        };
        let g = Ramp::new(shape).unwrap();
        assert_eq!(g.ramp_len(), 4);
        let mut buf = [0u16; 16];
        let n = drain(g, &mut buf);
        assert_eq!(
            &buf[..n],
            &[1000, 1000, 1003, 1006, 1009, 1010, 1010, 1007, 1004, 1001]
        );
        assert!(Ramp::new(RampShape { slope: 0, ..shape }).is_none());
        assert!(Ramp::new(RampShape {
            low: 2_000,
            high: 1_000,
            ..shape
        })
        .is_none());
        // Levels are not bounded (any unit): the whole u16 range is a valid shape.
        let wide = Ramp::new(RampShape {
            low: 0,
            high: u16::MAX,
            slope: u16::MAX,
            ..shape
        })
        .unwrap();
        assert_eq!(wide.ramp_len(), 1);
        assert_eq!(wide.duty_at(1), Some(0));
        assert_eq!(wide.duty_at(2), Some(u16::MAX));
        // Flat ramp: slope irrelevant.
        let flat = Ramp::new(RampShape {
            low: 500,
            high: 500,
            slope: 0,
            lead_in: 2,
            dwell_high: 1,
            dwell_low: 1,
            cycles: 3,
        })
        .unwrap();
        assert_eq!(flat.len_samples(), 8);
        assert!(flat.clone().all(|d| d == 500));
        // Overflowing length is rejected, not wrapped.
        assert!(Ramp::new(RampShape {
            low: 0,
            high: 10_000,
            slope: 1,
            lead_in: 0,
            dwell_high: u16::MAX,
            dwell_low: u16::MAX,
            cycles: u16::MAX,
        })
        .is_none());
    }
}
