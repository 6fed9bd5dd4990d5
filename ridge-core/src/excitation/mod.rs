//! Excitation signals for identification experiments.
//!
//! Every generator yields one **level** per sample, a `u16` in whatever unit the caller drives
//! its actuator with (the pump firmware uses duty in 1/10 000 of full scale), and has a length
//! in samples that is known before it starts (`len_samples`). The generators know nothing of
//! the actuator: its range, its sample rate and the presets of a particular plant live with
//! the plant (for the pump: `ridge_pump_firmware::excitation`).
//!
//! Everything here is integer arithmetic: no floats, no allocation, no panicking paths
//! (no `unwrap`, no slice indexing, overflow-checked or saturating arithmetic), so it runs
//! unchanged on AVR and Cortex-M.
//!
//! - [`Multistep`]: a table of levels, each held for a number of samples.
//! - [`Ramp`]: linear ramps up and down between two levels with a slope in level units per
//!   sample.
//! - [`Prbs`]: a maximum-length LFSR pseudo-random binary sequence between two levels.
//! - [`RandomSteps`]: a seeded pseudo-random multistep over a range of levels and holds.
//! - [`Excitation`]: any of them, in one value.
//!
//! Each generator is also an [`Iterator`] over `u16` levels; `next_duty` is the same call
//! under the name the firmware uses.

use core::iter::FusedIterator;

mod multistep;
mod prbs;
mod ramp;
mod random_steps;

pub use multistep::{Multistep, Step};
pub use prbs::{lfsr_mask, Lfsr, Prbs, LFSR_ORDER_MAX, LFSR_ORDER_MIN};
pub use ramp::{Ramp, RampShape};
pub use random_steps::{RandomShape, RandomSteps};

/// Clamps an iterator-style remaining count to a `size_hint`: exact when it fits in `usize`
/// (AVR has a 16-bit `usize`), otherwise an honest open-ended hint.
fn hint(remaining: u32) -> (usize, Option<usize>) {
    match usize::try_from(remaining) {
        Ok(n) => (n, Some(n)),
        Err(_) => (usize::MAX, None),
    }
}

/// Any of the generators, so that a caller can hold "the current excitation" in one value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Excitation {
    /// A [`Multistep`] generator.
    Multistep(Multistep),
    /// A [`Ramp`] generator.
    Ramp(Ramp),
    /// A [`Prbs`] generator.
    Prbs(Prbs),
}

impl Excitation {
    /// Next level, or `None` at the end.
    pub fn next_duty(&mut self) -> Option<u16> {
        match self {
            Self::Multistep(g) => g.next_duty(),
            Self::Ramp(g) => g.next_duty(),
            Self::Prbs(g) => g.next_duty(),
        }
    }

    /// Total length in samples.
    pub const fn len_samples(&self) -> u32 {
        match self {
            Self::Multistep(g) => g.len_samples(),
            Self::Ramp(g) => g.len_samples(),
            Self::Prbs(g) => g.len_samples(),
        }
    }

    /// Samples still to come.
    pub const fn remaining(&self) -> u32 {
        match self {
            Self::Multistep(g) => g.remaining(),
            Self::Ramp(g) => g.remaining(),
            Self::Prbs(g) => g.remaining(),
        }
    }

    /// Restarts from the first sample.
    pub fn reset(&mut self) {
        match self {
            Self::Multistep(g) => g.reset(),
            Self::Ramp(g) => g.reset(),
            Self::Prbs(g) => g.reset(),
        }
    }
}

impl Iterator for Excitation {
    type Item = u16;
    fn next(&mut self) -> Option<u16> {
        self.next_duty()
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        hint(self.remaining())
    }
}

impl FusedIterator for Excitation {}
