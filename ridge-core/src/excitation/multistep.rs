//! [`Multistep`]: a table of levels, each held for a number of samples.

use core::iter::FusedIterator;

use super::hint;

/// One level of a [`Multistep`] table: `level` held for `hold` samples. A step with
/// `hold == 0` is skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Step {
    /// The level, in the caller's units.
    pub level: u16,
    /// Number of samples the level is held for.
    pub hold: u16,
}

impl Step {
    /// A step of `level` held for `hold` samples.
    pub const fn new(level: u16, hold: u16) -> Self {
        Self { level, hold }
    }
}

/// Multistep excitation: walks a `'static` table of [`Step`]s, emitting each step's level
/// for `hold` samples, then ends (`None`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Multistep {
    /// The whole table (kept for [`Multistep::reset`]).
    steps: &'static [Step],
    /// Steps not finished yet; the first one is the current step.
    rest: &'static [Step],
    /// Samples already emitted of the current step.
    done_in_step: u16,
    /// Total length in samples.
    total: u32,
    /// Samples emitted so far.
    emitted: u32,
}

impl Multistep {
    /// Builds a generator over `steps`.
    ///
    /// Returns `None` if the total length does not fit in a `u32` number of samples. An empty
    /// table (or all holds zero) is valid and yields nothing. Levels are not checked: they are
    /// in whatever unit the caller drives (the pump's presets check theirs at compile time).
    pub const fn new(steps: &'static [Step]) -> Option<Self> {
        let mut total: u32 = 0;
        let mut rest = steps;
        while let Some((first, tail)) = rest.split_first() {
            total = match total.checked_add(first.hold as u32) {
                Some(t) => t,
                None => return None,
            };
            rest = tail;
        }
        Some(Self {
            steps,
            rest: steps,
            done_in_step: 0,
            total,
            emitted: 0,
        })
    }

    /// The step table this generator walks.
    pub const fn steps(&self) -> &'static [Step] {
        self.steps
    }

    /// Total length in samples.
    pub const fn len_samples(&self) -> u32 {
        self.total
    }

    /// Samples still to come.
    pub const fn remaining(&self) -> u32 {
        self.total.saturating_sub(self.emitted)
    }

    /// Restarts from the first sample.
    pub fn reset(&mut self) {
        self.rest = self.steps;
        self.done_in_step = 0;
        self.emitted = 0;
    }

    /// Next level, or `None` once all steps are done.
    pub fn next_duty(&mut self) -> Option<u16> {
        while let Some((first, tail)) = self.rest.split_first() {
            if self.done_in_step < first.hold {
                self.done_in_step = self.done_in_step.saturating_add(1);
                self.emitted = self.emitted.saturating_add(1);
                return Some(first.level);
            }
            self.rest = tail;
            self.done_in_step = 0;
        }
        None
    }
}

impl Iterator for Multistep {
    type Item = u16;
    fn next(&mut self) -> Option<u16> {
        self.next_duty()
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        hint(self.remaining())
    }
}

impl FusedIterator for Multistep {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_holds_are_skipped_and_any_level_is_emitted() {
        static STEPS: [Step; 5] = [
            Step::new(100, 0),
            Step::new(200, 2),
            Step::new(300, 0),
            Step::new(u16::MAX, 1),
            Step::new(0, 1),
        ];
        let mut g = Multistep::new(&STEPS).unwrap();
        assert_eq!(g.len_samples(), 4);
        let mut buf = [0u16; 8];
        let mut n = 0;
        for (slot, d) in buf.iter_mut().zip(&mut g) {
            *slot = d;
            n += 1;
        }
        assert_eq!(&buf[..n], &[200, 200, u16::MAX, 0]);
        assert_eq!((g.next_duty(), g.remaining()), (None, 0));
        g.reset();
        assert_eq!((g.next_duty(), g.remaining()), (Some(200), 3));
        assert!(Multistep::new(&[]).is_some_and(|m| m.len_samples() == 0));
    }
}
