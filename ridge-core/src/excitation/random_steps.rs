//! [`RandomSteps`]: a seeded pseudo-random multistep whose levels alternate between the lower
//! and the upper half of a range and whose holds are drawn from a range of lengths.
//!
//! Why this shape (the pump's power-up excitation, docs/identification.md): every step is large
//! (from one half of the range to the other: the plant's response stands out of the sensor
//! noise at every step), the levels cover the whole range (a model for the range, not for
//! one operating point), and the holds spread the signal's power over the band around the
//! plant's corner frequency `1 / (2π τ)` when they are drawn between ~2 and ~5 time constants
//! (shorter holds put power above the band, where the plant passes nothing; longer ones spend
//! seconds on the static gain). Unlike a PRBS, whose two levels identify a linear model of one
//! operating range, the multilevel signal also tells a static nonlinearity apart from
//! dynamics.
//!
//! The randomness is Marsaglia's 16-bit xorshift (triple 7, 9, 8; period 2¹⁶ − 1), integer
//! only and seeded: the same seed gives the same record on every target.

use core::iter::FusedIterator;

use super::hint;

/// The shape of a [`RandomSteps`] record, in the caller's level unit and samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RandomShape {
    /// Lowest level.
    pub low: u16,
    /// Highest level (`≥ low`).
    pub high: u16,
    /// Shortest hold, samples (`≥ 1`).
    pub hold_min: u16,
    /// Longest hold, samples (`≥ hold_min`).
    pub hold_max: u16,
    /// Length of the record, samples (the last hold is cut short to end there).
    pub len: u32,
    /// Seed of the generator (0 is replaced by 1).
    pub seed: u16,
}

/// A pseudo-random multistep (see the [module docs](crate::excitation)). The `k`-th level is uniform in
/// the lower half of `[low, high]` for even `k` and in the upper half for odd `k`; each is held
/// for a number of samples uniform in `[hold_min, hold_max]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RandomSteps {
    shape: RandomShape,
    /// Generator state (never zero).
    state: u16,
    /// Steps begun so far.
    steps: u32,
    /// Samples left of the current step.
    hold_left: u16,
    /// Level of the current step.
    level: u16,
    /// Samples emitted so far.
    emitted: u32,
}

impl RandomSteps {
    /// A generator of `shape`, or `None` when `high < low`, `hold_min` is 0 or
    /// `hold_max < hold_min`.
    pub const fn new(shape: RandomShape) -> Option<Self> {
        if shape.high < shape.low || shape.hold_min == 0 || shape.hold_max < shape.hold_min {
            return None;
        }
        Some(RandomSteps {
            shape,
            state: if shape.seed == 0 { 1 } else { shape.seed },
            steps: 0,
            hold_left: 0,
            level: shape.low,
            emitted: 0,
        })
    }

    /// The shape.
    pub const fn shape(&self) -> RandomShape {
        self.shape
    }

    /// Total length in samples.
    pub const fn len_samples(&self) -> u32 {
        self.shape.len
    }

    /// Samples still to come.
    pub const fn remaining(&self) -> u32 {
        self.shape.len.saturating_sub(self.emitted)
    }

    /// Restarts from the first sample (same seed, same record).
    pub fn reset(&mut self) {
        if let Some(fresh) = Self::new(self.shape) {
            *self = fresh;
        }
    }

    /// The next number of the xorshift, `1..=65535`.
    fn draw(&mut self) -> u16 {
        let mut x = self.state;
        x ^= x << 7;
        x ^= x >> 9;
        x ^= x << 8;
        self.state = x;
        x
    }

    /// Next level, or `None` at the end.
    pub fn next_duty(&mut self) -> Option<u16> {
        if self.emitted >= self.shape.len {
            return None;
        }
        if self.hold_left == 0 {
            let s = self.shape;
            let half = u32::from(s.high - s.low) / 2;
            let base = u32::from(s.low) + if self.steps % 2 == 1 { half } else { 0 };
            // Uniform in [base, base + half]: the draw's 16 bits scaled.
            let r = u32::from(self.draw());
            self.level = (base + half * r / 65_535) as u16;
            let span = u32::from(s.hold_max - s.hold_min) + 1;
            self.hold_left = s.hold_min + (u32::from(self.draw()) % span) as u16;
            self.steps = self.steps.saturating_add(1);
        }
        self.hold_left -= 1;
        self.emitted += 1;
        Some(self.level)
    }
}

impl Iterator for RandomSteps {
    type Item = u16;
    fn next(&mut self) -> Option<u16> {
        self.next_duty()
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        hint(self.remaining())
    }
}

impl FusedIterator for RandomSteps {}

#[cfg(test)]
mod tests {
    use super::*;

    const SHAPE: RandomShape = RandomShape {
        low: 2_000,
        high: 8_500,
        hold_min: 30,
        hold_max: 75,
        len: 5_000,
        seed: 7,
    };

    /// The runs of equal levels of `v` as (level, length), into `out`; returns how many.
    fn runs(v: &[u16], out: &mut [(u16, usize)]) -> usize {
        let mut n = 0;
        let mut rest = v;
        while let (Some(&first), Some(slot)) = (rest.first(), out.get_mut(n)) {
            let len = rest.iter().take_while(|&&x| x == first).count();
            *slot = (first, len);
            rest = &rest[len..];
            n += 1;
        }
        n
    }

    #[test]
    fn levels_alternate_between_the_halves_and_holds_stay_in_range() {
        let mut g = RandomSteps::new(SHAPE).unwrap();
        let mut v = [0u16; 5_000];
        for slot in v.iter_mut() {
            *slot = g.next_duty().unwrap();
        }
        assert_eq!(g.next_duty(), None);
        let mid = 2_000 + (8_500 - 2_000) / 2;
        let mut all = [(0u16, 0usize); 128];
        let n = runs(&v, &mut all);
        for (k, &(level, len)) in all.iter().take(n).enumerate() {
            // Two neighbouring steps may draw the same level only at the midpoint; none here.
            if k % 2 == 0 {
                assert!((2_000..=mid).contains(&level), "step {k}: {level}");
            } else {
                assert!((mid..=8_500).contains(&level), "step {k}: {level}");
            }
            // The last hold is cut at the record's end.
            if k + 1 < n {
                assert!((30..=75).contains(&len), "step {k}: hold {len}");
            }
        }
        // The levels spread over each half (not stuck near one value).
        let lows = all.iter().take(n).step_by(2).map(|r| r.0);
        let (min, max) = lows.fold((u16::MAX, 0), |(a, b), l| (a.min(l), b.max(l)));
        assert!(min < 2_500 && max > 4_700, "{min}..{max}");
        // The same seed gives the same record, another seed another one.
        g.reset();
        assert!(v.iter().all(|&x| g.next_duty() == Some(x)));
        let mut other = RandomSteps::new(RandomShape { seed: 8, ..SHAPE }).unwrap();
        assert!(v.iter().any(|&x| other.next_duty() != Some(x)));
    }

    #[test]
    fn bad_shapes_are_refused() {
        assert!(RandomSteps::new(RandomShape {
            high: 1_000,
            ..SHAPE
        })
        .is_none());
        assert!(RandomSteps::new(RandomShape {
            hold_min: 0,
            ..SHAPE
        })
        .is_none());
        assert!(RandomSteps::new(RandomShape {
            hold_max: 10,
            ..SHAPE
        })
        .is_none());
        let mut one = RandomSteps::new(RandomShape {
            low: 5,
            high: 5,
            hold_min: 1,
            hold_max: 1,
            len: 3,
            seed: 0,
        })
        .unwrap();
        assert_eq!(
            [one.next(), one.next(), one.next(), one.next()],
            [Some(5), Some(5), Some(5), None]
        );
    }
}
