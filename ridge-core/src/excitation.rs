//! Excitation signals for the power-up identification run.
//!
//! The firmware drives the pump with one of these generators at the sample rate
//! ([`SAMPLE_RATE_HZ`], 100 Hz) and logs the SFM3300 flow alongside. Every generator yields one
//! **duty** value per sample, in units of 1/[`DUTY_FULL_SCALE`] of full scale (`0..=10_000` is
//! 0..100 % PWM duty), and has a length in samples that is known before it starts
//! (`len_samples`).
//!
//! Everything here is integer arithmetic: no floats, no allocation, no panicking paths
//! (no `unwrap`, no slice indexing, overflow-checked or saturating arithmetic), so it runs
//! unchanged on AVR and Cortex-M.
//!
//! Generators:
//! - [`Multistep`]: a table of levels, each held for a number of samples.
//! - [`Ramp`]: linear ramps up and down between two levels with a slope in duty units per sample.
//! - [`Prbs`]: a maximum-length LFSR pseudo-random binary sequence between two levels.
//!
//! Presets, each about 30 s long with every duty within 20..90 % (the pump's dead zone lies
//! below ~15 %), mirror the four records of the paper plus a PRBS: see [`Record`].
//!
//! Each generator is also an [`Iterator`] over `u16` duty values; `next_duty` is the same call
//! under the name the firmware uses.

use core::iter::FusedIterator;

/// Full-scale duty: a duty value of `DUTY_FULL_SCALE` is 100 % PWM duty, `0` is 0 %.
/// Duty values are therefore in units of 0.01 %.
pub const DUTY_FULL_SCALE: u16 = 10_000;

/// Sample rate at which the generators are meant to be stepped, in Hz (Ts = 10 ms).
pub const SAMPLE_RATE_HZ: u16 = 100;

/// Lowest duty any preset emits, in duty units (20 %). Below ~15 % the pump does not turn.
pub const PRESET_DUTY_MIN: u16 = 2_000;

/// Highest duty any preset emits, in duty units (90 %).
pub const PRESET_DUTY_MAX: u16 = 9_000;

/// Converts a duty (units of 1/[`DUTY_FULL_SCALE`]) to a timer compare value for a PWM timer
/// counting `0..=top`, rounding to nearest. Duties above full scale saturate at `top`.
///
/// Example: `duty_to_compare(5_000, 1023) == 512` (50 % of a 10-bit timer).
pub const fn duty_to_compare(duty: u16, top: u16) -> u16 {
    let d = if duty > DUTY_FULL_SCALE {
        DUTY_FULL_SCALE
    } else {
        duty
    };
    let half = (DUTY_FULL_SCALE / 2) as u32;
    // d * top + half < 2^32 (10_000 * 65_535 + 5_000), so the saturating ops never saturate.
    // Literal divisor (== DUTY_FULL_SCALE, asserted below) so that it is visibly non-zero.
    let c = (d as u32).saturating_mul(top as u32).saturating_add(half) / 10_000u32;
    // c <= top because d <= DUTY_FULL_SCALE, so the cast is lossless.
    c as u16
}

/// Compile-time check that the literal divisor in [`duty_to_compare`] is the full scale.
const _: () = assert!(DUTY_FULL_SCALE as u32 == 10_000u32);

/// Clamps an iterator-style remaining count to a `size_hint`: exact when it fits in `usize`
/// (AVR has a 16-bit `usize`), otherwise an honest open-ended hint.
fn hint(remaining: u32) -> (usize, Option<usize>) {
    match usize::try_from(remaining) {
        Ok(n) => (n, Some(n)),
        Err(_) => (usize::MAX, None),
    }
}

// ---------------------------------------------------------------------------------------------
// Multistep
// ---------------------------------------------------------------------------------------------

/// One level of a [`Multistep`] table: `duty` (units of 1/[`DUTY_FULL_SCALE`]) held for `hold`
/// samples (at 100 Hz, `hold = 100` is one second). A step with `hold == 0` is skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Step {
    /// Duty level, units of 1/[`DUTY_FULL_SCALE`] (0..=10 000).
    pub duty: u16,
    /// Number of samples the level is held for.
    pub hold: u16,
}

impl Step {
    /// A step of `duty` (units of 1/[`DUTY_FULL_SCALE`]) held for `hold` samples.
    pub const fn new(duty: u16, hold: u16) -> Self {
        Self { duty, hold }
    }
}

/// Step table of the "A-Multistep" preset: 15 levels of 2 s (200 samples) each, 3000 samples
/// (30 s) in all, levels between 20 % and 90 % in a non-monotone order so that both up and down
/// steps of several sizes occur.
pub const A_MULTISTEP_STEPS: &[Step] = &[
    Step::new(2_000, 200),
    Step::new(4_000, 200),
    Step::new(3_000, 200),
    Step::new(6_000, 200),
    Step::new(9_000, 200),
    Step::new(5_000, 200),
    Step::new(7_000, 200),
    Step::new(2_500, 200),
    Step::new(8_000, 200),
    Step::new(4_500, 200),
    Step::new(8_500, 200),
    Step::new(3_500, 200),
    Step::new(6_500, 200),
    Step::new(5_500, 200),
    Step::new(2_000, 200),
];

/// Step table of the "B-Multistep" preset: 12 levels with other values than A and unequal holds
/// of 1.5..3.5 s, 3000 samples (30 s) in all, levels between 20 % and 90 %.
pub const B_MULTISTEP_STEPS: &[Step] = &[
    Step::new(2_500, 250),
    Step::new(5_000, 150),
    Step::new(3_500, 300),
    Step::new(8_000, 200),
    Step::new(6_000, 250),
    Step::new(9_000, 150),
    Step::new(4_000, 300),
    Step::new(7_000, 200),
    Step::new(2_000, 250),
    Step::new(7_500, 300),
    Step::new(3_000, 350),
    Step::new(5_500, 300),
];

/// Multistep excitation: walks a `'static` table of [`Step`]s, emitting each step's duty
/// (units of 1/[`DUTY_FULL_SCALE`]) for `hold` samples, then ends (`None`).
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
    /// Returns `None` if a duty exceeds [`DUTY_FULL_SCALE`] or the total length does not fit
    /// in a `u32` number of samples. An empty table (or all holds zero) is valid and yields
    /// nothing.
    pub const fn new(steps: &'static [Step]) -> Option<Self> {
        let mut total: u32 = 0;
        let mut rest = steps;
        while let Some((first, tail)) = rest.split_first() {
            if first.duty > DUTY_FULL_SCALE {
                return None;
            }
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

    /// The "A-Multistep" preset ([`A_MULTISTEP_STEPS`], 3000 samples).
    pub const fn a_multistep() -> Self {
        A_MULTISTEP
    }

    /// The "B-Multistep" preset ([`B_MULTISTEP_STEPS`], 3000 samples).
    pub const fn b_multistep() -> Self {
        B_MULTISTEP
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

    /// Next duty (units of 1/[`DUTY_FULL_SCALE`]), or `None` once all steps are done.
    pub fn next_duty(&mut self) -> Option<u16> {
        while let Some((first, tail)) = self.rest.split_first() {
            if self.done_in_step < first.hold {
                self.done_in_step = self.done_in_step.saturating_add(1);
                self.emitted = self.emitted.saturating_add(1);
                return Some(first.duty);
            }
            self.rest = tail;
            self.done_in_step = 0;
        }
        None
    }
}

/// The A-Multistep generator, validated at compile time.
const A_MULTISTEP: Multistep = match Multistep::new(A_MULTISTEP_STEPS) {
    Some(m) => m,
    // Evaluated at compile time: an invalid preset table is a build error, not a runtime panic.
    None => panic!("invalid A-Multistep table"), // ok: const-evaluated, a bad preset fails the build
};

/// The B-Multistep generator, validated at compile time.
const B_MULTISTEP: Multistep = match Multistep::new(B_MULTISTEP_STEPS) {
    Some(m) => m,
    None => panic!("invalid B-Multistep table"), // ok: const-evaluated, a bad preset fails the build
};

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

// ---------------------------------------------------------------------------------------------
// Ramp
// ---------------------------------------------------------------------------------------------

/// Shape of a [`Ramp`] excitation. All duties in units of 1/[`DUTY_FULL_SCALE`], all
/// durations in samples (100 per second).
///
/// The signal is: `lead_in` samples at `low`, then `cycles` times
/// `[ramp up | dwell_high at high | ramp down | dwell_low at low]`.
/// A ramp takes `ceil((high - low) / slope)` samples: the ramp up emits
/// `low, low + slope, low + 2 slope, …` (all below `high`), the ramp down
/// `high, high - slope, …` (all above `low`). When `slope` divides `high - low`, every
/// sample-to-sample change inside and between ramps is exactly `slope`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RampShape {
    /// Lower level, duty units.
    pub low: u16,
    /// Upper level, duty units (`low <= high <= DUTY_FULL_SCALE`).
    pub high: u16,
    /// Slope magnitude in duty units per sample (≥ 1 unless `low == high`).
    /// 1 unit/sample = 0.01 %/sample = 1 %/s at 100 Hz.
    pub slope: u16,
    /// Samples at `low` before the first ramp (lets the pump spin up).
    pub lead_in: u16,
    /// Samples held at `high` between the ramp up and the ramp down.
    pub dwell_high: u16,
    /// Samples held at `low` after each ramp down.
    pub dwell_low: u16,
    /// Number of up/down cycles.
    pub cycles: u16,
}

/// Shape of the "A-Ramp" preset: 20 % ↔ 90 % at 14 units/sample (14 %/s, 5 s per ramp),
/// 2 s lead-in, 2 s dwells, 2 cycles: 200 + 2 × (500 + 200 + 500 + 200) = 3000 samples.
pub const A_RAMP_SHAPE: RampShape = RampShape {
    low: 2_000,
    high: 9_000,
    slope: 14,
    lead_in: 200,
    dwell_high: 200,
    dwell_low: 200,
    cycles: 2,
};

/// Shape of the "B-Ramp" preset: 25 % ↔ 85 % at 30 units/sample (30 %/s, 2 s per ramp),
/// 2 s lead-in, 1.5 s dwells, 4 cycles: 200 + 4 × (200 + 150 + 200 + 150) = 3000 samples.
pub const B_RAMP_SHAPE: RampShape = RampShape {
    low: 2_500,
    high: 8_500,
    slope: 30,
    lead_in: 200,
    dwell_high: 150,
    dwell_low: 150,
    cycles: 4,
};

/// Ramp excitation: linear ramps between two levels, see [`RampShape`] for the exact shape.
/// Duties in units of 1/[`DUTY_FULL_SCALE`].
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
    /// Returns `None` if `low > high`, `high > DUTY_FULL_SCALE`, `slope == 0` while
    /// `low != high`, or the total length overflows a `u32` number of samples.
    pub const fn new(shape: RampShape) -> Option<Self> {
        if shape.low > shape.high || shape.high > DUTY_FULL_SCALE {
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
        // ramp_len <= 10_000, dwells <= 65_535: no overflow in u32.
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

    /// The "A-Ramp" preset ([`A_RAMP_SHAPE`], 3000 samples).
    pub const fn a_ramp() -> Self {
        A_RAMP
    }

    /// The "B-Ramp" preset ([`B_RAMP_SHAPE`], 3000 samples).
    pub const fn b_ramp() -> Self {
        B_RAMP
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

    /// Duty (units of 1/[`DUTY_FULL_SCALE`]) of sample `n` (0-based), or `None` past the end.
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

    /// Next duty (units of 1/[`DUTY_FULL_SCALE`]), or `None` at the end.
    pub fn next_duty(&mut self) -> Option<u16> {
        let d = self.duty_at(self.pos);
        if d.is_some() {
            self.pos = self.pos.saturating_add(1);
        }
        d
    }
}

/// The A-Ramp generator, validated at compile time.
const A_RAMP: Ramp = match Ramp::new(A_RAMP_SHAPE) {
    Some(r) => r,
    // Compile-time check of the preset, not a runtime panic.
    None => panic!("invalid A-Ramp shape"), // ok: const-evaluated, a bad preset fails the build
};

/// The B-Ramp generator, validated at compile time.
const B_RAMP: Ramp = match Ramp::new(B_RAMP_SHAPE) {
    Some(r) => r,
    None => panic!("invalid B-Ramp shape"), // ok: const-evaluated, a bad preset fails the build
};

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

// ---------------------------------------------------------------------------------------------
// PRBS
// ---------------------------------------------------------------------------------------------

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

/// PRBS excitation: an [`Lfsr`] bit sequence mapped to two duty levels (bit 1 → `high`,
/// bit 0 → `low`, units of 1/[`DUTY_FULL_SCALE`]), each bit held for `hold` samples, for a
/// whole number of LFSR periods: `len_samples = periods × (2^order − 1) × hold`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Prbs {
    /// Register at the start (for [`Prbs::reset`]).
    initial: Lfsr,
    /// Running register.
    lfsr: Lfsr,
    /// Duty for a 0 bit.
    low: u16,
    /// Duty for a 1 bit.
    high: u16,
    /// Samples per bit.
    hold: u16,
    /// Samples left of the current bit.
    hold_left: u16,
    /// Duty of the current bit.
    level: u16,
    /// Total length in samples.
    total: u32,
    /// Samples emitted so far.
    emitted: u32,
}

/// LFSR order of the PRBS preset (period 511 bits).
pub const PRBS_PRESET_ORDER: u8 = 9;
/// Samples per bit of the PRBS preset (60 ms per bit; longest run 9 bits = 0.54 s).
pub const PRBS_PRESET_HOLD: u16 = 6;
/// Low level of the PRBS preset, duty units (30 %).
pub const PRBS_PRESET_LOW: u16 = 3_000;
/// High level of the PRBS preset, duty units (80 %).
pub const PRBS_PRESET_HIGH: u16 = 8_000;

impl Prbs {
    /// Builds a PRBS generator of LFSR `order` (2..=16, seed 1), levels `low`/`high` (duty
    /// units, both ≤ [`DUTY_FULL_SCALE`]), `hold` samples per bit and `periods` full LFSR
    /// periods. `None` for an unsupported order, a level above full scale, `hold == 0`, or a
    /// length that overflows a `u32` number of samples.
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
        if low > DUTY_FULL_SCALE || high > DUTY_FULL_SCALE || hold == 0 {
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

    /// The PRBS preset: order 9 (511 bits), 30 % / 80 %, 6 samples per bit, one period:
    /// 3066 samples (30.66 s).
    pub const fn preset() -> Self {
        PRBS_PRESET
    }

    /// The underlying register in its initial state.
    pub const fn initial_lfsr(&self) -> Lfsr {
        self.initial
    }

    /// Samples per bit.
    pub const fn hold(&self) -> u16 {
        self.hold
    }

    /// Duty (units of 1/[`DUTY_FULL_SCALE`]) emitted for a 0 bit.
    pub const fn low(&self) -> u16 {
        self.low
    }

    /// Duty (units of 1/[`DUTY_FULL_SCALE`]) emitted for a 1 bit.
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

    /// Next duty (units of 1/[`DUTY_FULL_SCALE`]), or `None` at the end.
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

/// The PRBS preset generator, validated at compile time.
const PRBS_PRESET: Prbs = match Prbs::new(
    PRBS_PRESET_ORDER,
    PRBS_PRESET_LOW,
    PRBS_PRESET_HIGH,
    PRBS_PRESET_HOLD,
    1,
) {
    Some(p) => p,
    // Compile-time check of the preset, not a runtime panic.
    None => panic!("invalid PRBS preset"), // ok: const-evaluated, a bad preset fails the build
};

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

// ---------------------------------------------------------------------------------------------
// Presets
// ---------------------------------------------------------------------------------------------

/// Any of the generators, so that firmware can hold "the current excitation" in one value.
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
    /// Next duty (units of 1/[`DUTY_FULL_SCALE`]), or `None` at the end.
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

/// The preset excitation records: the paper's four (A/B-Multistep, A/B-Ramp) plus a PRBS.
/// Each is about 30 s at 100 Hz with all duties within
/// [`PRESET_DUTY_MIN`]..=[`PRESET_DUTY_MAX`] (20..90 %).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Record {
    /// "A-Multistep": [`A_MULTISTEP_STEPS`], 3000 samples.
    AMultistep,
    /// "B-Multistep": [`B_MULTISTEP_STEPS`], 3000 samples.
    BMultistep,
    /// "A-Ramp": [`A_RAMP_SHAPE`], 3000 samples.
    ARamp,
    /// "B-Ramp": [`B_RAMP_SHAPE`], 3000 samples.
    BRamp,
    /// "PRBS": [`Prbs::preset`], 3066 samples.
    Prbs,
}

impl Record {
    /// All presets, in declaration order.
    pub const ALL: [Record; 5] = [
        Record::AMultistep,
        Record::BMultistep,
        Record::ARamp,
        Record::BRamp,
        Record::Prbs,
    ];

    /// A fresh generator for this record.
    pub const fn generator(self) -> Excitation {
        match self {
            Record::AMultistep => Excitation::Multistep(Multistep::a_multistep()),
            Record::BMultistep => Excitation::Multistep(Multistep::b_multistep()),
            Record::ARamp => Excitation::Ramp(Ramp::a_ramp()),
            Record::BRamp => Excitation::Ramp(Ramp::b_ramp()),
            Record::Prbs => Excitation::Prbs(Prbs::preset()),
        }
    }

    /// Length of the record in samples.
    pub const fn len_samples(self) -> u32 {
        self.generator().len_samples()
    }

    /// The record's name as the paper writes it: "A-Multistep", "B-Multistep", "A-Ramp",
    /// "B-Ramp", or "PRBS".
    pub const fn name(self) -> &'static str {
        match self {
            Record::AMultistep => "A-Multistep",
            Record::BMultistep => "B-Multistep",
            Record::ARamp => "A-Ramp",
            Record::BRamp => "B-Ramp",
            Record::Prbs => "PRBS",
        }
    }

    /// The record named `name` (as [`Record::name`] gives it, ASCII case-insensitive).
    pub fn from_name(name: &str) -> Option<Record> {
        Self::ALL
            .into_iter()
            .find(|r| r.name().eq_ignore_ascii_case(name))
    }
}

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

    const BUF: usize = 4096;

    #[test]
    fn preset_lengths_are_about_30_s() {
        let expect = [3000u32, 3000, 3000, 3000, 3066];
        for (r, &n) in Record::ALL.iter().zip(expect.iter()) {
            assert_eq!(r.len_samples(), n, "{}", r.name());
            let mut g = r.generator();
            assert_eq!(g.size_hint(), (n as usize, Some(n as usize)));
            let mut count = 0u32;
            while g.next_duty().is_some() {
                count += 1;
                assert_eq!(g.remaining(), n - count);
            }
            assert_eq!(count, n, "{}", r.name());
            // Fused: stays exhausted.
            assert_eq!(g.next_duty(), None);
            assert_eq!(g.next(), None);
            // 30 s ± 1 s at 100 Hz.
            assert!((2900..=3100).contains(&n));
        }
    }

    #[test]
    fn preset_levels_within_20_to_90_percent() {
        for r in Record::ALL {
            let mut lo = u16::MAX;
            let mut hi = 0;
            for d in r.generator() {
                lo = lo.min(d);
                hi = hi.max(d);
            }
            assert!(lo >= PRESET_DUTY_MIN, "{} min {}", r.name(), lo);
            assert!(hi <= PRESET_DUTY_MAX, "{} max {}", r.name(), hi);
            // Every preset actually spans a good part of the range.
            assert!(hi - lo >= 4_000, "{} span {}", r.name(), hi - lo);
        }
    }

    #[test]
    fn reset_replays_the_same_sequence() {
        for r in Record::ALL {
            let mut a = [0u16; BUF];
            let mut b = [0u16; BUF];
            let mut g = r.generator();
            let na = drain(&mut g, &mut a);
            g.reset();
            let nb = drain(&mut g, &mut b);
            assert_eq!(na, nb);
            assert_eq!(a, b, "{}", r.name());
        }
    }

    #[test]
    fn names_round_trip() {
        for r in Record::ALL {
            assert_eq!(Record::from_name(r.name()), Some(r));
        }
        assert_eq!(Record::from_name("a-ramp"), Some(Record::ARamp));
        assert_eq!(Record::from_name("C-Ramp"), None);
    }

    #[test]
    fn multistep_holds_each_level() {
        for (steps, g) in [
            (A_MULTISTEP_STEPS, Multistep::a_multistep()),
            (B_MULTISTEP_STEPS, Multistep::b_multistep()),
        ] {
            let mut buf = [0u16; BUF];
            let n = drain(g, &mut buf);
            let mut pos = 0usize;
            for s in steps {
                let h = usize::from(s.hold);
                assert!(buf[pos..pos + h].iter().all(|&d| d == s.duty));
                pos += h;
            }
            assert_eq!(pos, n);
        }
        // A and B really differ, in levels and in holds.
        assert_ne!(A_MULTISTEP_STEPS, B_MULTISTEP_STEPS);
        assert!(B_MULTISTEP_STEPS.iter().any(|s| s.hold != 200));
    }

    #[test]
    fn multistep_edge_cases() {
        static STEPS: [Step; 4] = [
            Step::new(100, 0),
            Step::new(200, 2),
            Step::new(300, 0),
            Step::new(400, 1),
        ];
        let mut g = Multistep::new(&STEPS).unwrap();
        assert_eq!(g.len_samples(), 3);
        let mut buf = [0u16; 8];
        assert_eq!(drain(&mut g, &mut buf), 3);
        assert_eq!(&buf[..3], &[200, 200, 400]);
        assert!(Multistep::new(&[]).is_some_and(|m| m.len_samples() == 0));
        static BAD: [Step; 1] = [Step::new(10_001, 1)];
        assert!(Multistep::new(&BAD).is_none());
    }

    #[test]
    fn ramp_slope_is_exact() {
        for (g, slope) in [(Ramp::a_ramp(), 14i32), (Ramp::b_ramp(), 30)] {
            let shape = g.shape();
            assert_eq!((shape.high - shape.low) % shape.slope, 0);
            let mut buf = [0u16; BUF];
            let n = drain(g.clone(), &mut buf);
            let v = &buf[..n];
            let mut ups = 0;
            let mut downs = 0;
            for w in v.windows(2) {
                let dv = i32::from(w[1]) - i32::from(w[0]);
                assert!(dv == 0 || dv.abs() == slope, "step {dv}");
                if dv > 0 {
                    ups += 1;
                } else if dv < 0 {
                    downs += 1;
                }
            }
            let per_ramp = (shape.high - shape.low) / shape.slope;
            assert_eq!(g.ramp_len(), u32::from(per_ramp));
            // Each cycle: `per_ramp` increments up and `per_ramp` decrements down.
            assert_eq!(ups, per_ramp * shape.cycles);
            assert_eq!(downs, per_ramp * shape.cycles);
            assert_eq!(v[0], shape.low);
            assert_eq!(*v.iter().max().unwrap(), shape.high);
            assert_eq!(*v.iter().min().unwrap(), shape.low);
            // duty_at agrees with iteration.
            for (i, &d) in v.iter().enumerate() {
                assert_eq!(g.duty_at(i as u32), Some(d));
            }
            assert_eq!(g.duty_at(n as u32), None);
        }
        // A and B have different slopes.
        assert_ne!(A_RAMP_SHAPE.slope, B_RAMP_SHAPE.slope);
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
        assert!(Ramp::new(RampShape {
            high: 10_001,
            ..shape
        })
        .is_none());
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
    fn prbs_preset_period_balance_and_hold() {
        let g = Prbs::preset();
        assert_eq!(g.initial_lfsr().order(), PRBS_PRESET_ORDER);
        assert_eq!(g.initial_lfsr().period(), 511);
        let hold = usize::from(g.hold());
        let mut buf = [0u16; BUF];
        let n = drain(g.clone(), &mut buf);
        assert_eq!(n, 511 * hold);
        let v = &buf[..n];
        // Constant within each bit.
        for bit in v.chunks(hold) {
            assert!(bit.iter().all(|&d| d == bit[0]));
            assert!(bit[0] == g.low() || bit[0] == g.high());
        }
        let highs = v.chunks(hold).filter(|b| b[0] == g.high()).count();
        let lows = v.chunks(hold).filter(|b| b[0] == g.low()).count();
        assert_eq!(highs, 256);
        assert_eq!(lows, 255);
        // Longest run of equal bits in an m-sequence of order n is n (ones) and n-1 (zeros).
        let mut longest = 0;
        let mut run = 0;
        let mut prev = None;
        for b in v.chunks(hold) {
            if Some(b[0]) == prev {
                run += 1;
            } else {
                run = 1;
                prev = Some(b[0]);
            }
            longest = longest.max(run);
        }
        assert_eq!(longest, usize::from(PRBS_PRESET_ORDER));
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
        assert!(Prbs::new(5, 1_000, 10_001, 1, 1).is_none());
        assert!(Prbs::new(16, 0, 1, u16::MAX, u16::MAX).is_none());
    }

    #[test]
    fn duty_to_compare_rounds_and_saturates() {
        assert_eq!(duty_to_compare(0, 1023), 0);
        assert_eq!(duty_to_compare(5_000, 1023), 512);
        assert_eq!(duty_to_compare(10_000, 1023), 1023);
        assert_eq!(duty_to_compare(65_535, 1023), 1023);
        assert_eq!(duty_to_compare(2_000, u16::MAX), 13_107);
    }
}
