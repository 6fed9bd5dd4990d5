//! The pump's excitation records, built from ridge-core's generic generators
//! ([`ridge_core::excitation`]) in duty units (1/[`DUTY_FULL_SCALE`] of full scale) at
//! [`SAMPLE_RATE_HZ`](crate::units::SAMPLE_RATE_HZ):
//!
//! - [`FlowSteps`]: what the power-up identification drives the blower with (the estimation
//!   and the validation record, `crate::selfid`): random steps whose levels are uniform in the
//!   static map's flow, driven at the map's inverse.
//! - [`Record`]: the paper's four records (A/B-Multistep, A/B-Ramp) plus a PRBS, about 30 s
//!   each with every duty within [`PRESET_DUTY_MIN`]..=[`PRESET_DUTY_MAX`] (20..90 %; the
//!   blower's dead zone lies below ~15 %), for the simulator's experiments and the host tools.
//!   Every preset is validated at compile time (length, levels within full scale): a bad table
//!   fails the build.

use core::str::FromStr;

use ridge_core::excitation::{
    Excitation, Multistep, Prbs, Ramp, RampShape, RandomShape, RandomSteps, Step,
};
use ridge_core::InputMap;

use crate::units::DUTY_FULL_SCALE;

/// Random steps uniform in flow (see the [module docs](self)): each level of a
/// [`RandomSteps`] is a flow (SFM3300 counts) between the map's flow at the lowest duty (at
/// least a given flow) and at the highest; it is driven at the map's inverse within the duty
/// range, and reported with the map's flow at that duty (the Hammerstein model's input).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FlowSteps {
    steps: RandomSteps,
    map: InputMap,
    /// Duty range, 1/10 000.
    low: u16,
    high: u16,
    /// The current level (flow counts; `u16::MAX` before the first), its duty and the map's
    /// flow there.
    level: u16,
    duty: u16,
    flow: i16,
}

/// The shape of a [`FlowSteps`] record (duties 1/10 000, flows in counts, holds in samples).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FlowShape {
    /// Lowest duty.
    pub low: u16,
    /// Highest duty.
    pub high: u16,
    /// Lowest flow of a level, counts.
    pub min_flow: i16,
    /// Shortest hold, samples (≥ 1).
    pub hold_min: u16,
    /// Longest hold, samples (≥ `hold_min`).
    pub hold_max: u16,
    /// Length, samples.
    pub len: u32,
    /// Seed of the generator.
    pub seed: u16,
}

impl FlowSteps {
    /// The record of `shape` through `map`; `None` when the map's flows leave no range (the
    /// flow at the highest duty not above the lowest level) or the holds are invalid.
    pub fn new(map: &InputMap, shape: &FlowShape) -> Option<Self> {
        let low_flow = map.at(shape.low).max(shape.min_flow).max(0);
        let high_flow = map.at(shape.high);
        if high_flow <= low_flow || shape.high < shape.low {
            return None;
        }
        // Both within 0..=32 767 here.
        let steps = RandomSteps::new(RandomShape {
            low: low_flow as u16,
            high: high_flow as u16,
            hold_min: shape.hold_min,
            hold_max: shape.hold_max,
            len: shape.len,
            seed: shape.seed,
        })?;
        Some(FlowSteps {
            steps,
            map: *map,
            low: shape.low,
            high: shape.high,
            level: u16::MAX,
            duty: shape.low,
            flow: 0,
        })
    }

    /// Total length in samples.
    pub fn len_samples(&self) -> u32 {
        self.steps.len_samples()
    }

    /// The next sample's duty (1/10 000) and the map's flow at it (counts), or `None` at the
    /// end. The map is inverted once per level, not per sample.
    pub fn next_step(&mut self) -> Option<(u16, i16)> {
        let level = self.steps.next_duty()?;
        if level != self.level {
            self.level = level;
            // Levels are within 0..=32 767 (`new`).
            let duty = self.map.inverse(level as i16).max(self.low).min(self.high);
            self.duty = duty;
            self.flow = self.map.at(duty);
        }
        Some((self.duty, self.flow))
    }
}

/// Lowest duty any preset emits, in duty units (20 %). Below ~15 % the pump does not turn.
pub const PRESET_DUTY_MIN: u16 = 2_000;

/// Highest duty any preset emits, in duty units (90 %).
pub const PRESET_DUTY_MAX: u16 = 9_000;

const _: () = assert!(PRESET_DUTY_MAX <= DUTY_FULL_SCALE);

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

/// LFSR order of the PRBS preset (period 511 bits).
pub const PRBS_PRESET_ORDER: u8 = 9;
/// Samples per bit of the PRBS preset (60 ms per bit; longest run 9 bits = 0.54 s).
pub const PRBS_PRESET_HOLD: u16 = 6;
/// Low level of the PRBS preset, duty units (30 %).
pub const PRBS_PRESET_LOW: u16 = 3_000;
/// High level of the PRBS preset, duty units (80 %).
pub const PRBS_PRESET_HIGH: u16 = 8_000;

/// Whether every level of `steps` is a duty within full scale (for the compile-time checks).
const fn steps_within_full_scale(steps: &[Step]) -> bool {
    let mut rest = steps;
    while let Some((first, tail)) = rest.split_first() {
        if first.level > DUTY_FULL_SCALE {
            return false;
        }
        rest = tail;
    }
    true
}

/// The A-Multistep generator, validated at compile time.
const A_MULTISTEP: Multistep = match Multistep::new(A_MULTISTEP_STEPS) {
    Some(m) if steps_within_full_scale(A_MULTISTEP_STEPS) => m,
    // Evaluated at compile time: an invalid preset table is a build error, not a runtime panic.
    _ => panic!("invalid A-Multistep table"), // ok: const-evaluated, a bad preset fails the build
};

/// The B-Multistep generator, validated at compile time.
const B_MULTISTEP: Multistep = match Multistep::new(B_MULTISTEP_STEPS) {
    Some(m) if steps_within_full_scale(B_MULTISTEP_STEPS) => m,
    _ => panic!("invalid B-Multistep table"), // ok: const-evaluated, a bad preset fails the build
};

/// The A-Ramp generator, validated at compile time.
const A_RAMP: Ramp = match Ramp::new(A_RAMP_SHAPE) {
    Some(r) if A_RAMP_SHAPE.high <= DUTY_FULL_SCALE => r,
    _ => panic!("invalid A-Ramp shape"), // ok: const-evaluated, a bad preset fails the build
};

/// The B-Ramp generator, validated at compile time.
const B_RAMP: Ramp = match Ramp::new(B_RAMP_SHAPE) {
    Some(r) if B_RAMP_SHAPE.high <= DUTY_FULL_SCALE => r,
    _ => panic!("invalid B-Ramp shape"), // ok: const-evaluated, a bad preset fails the build
};

/// The PRBS preset generator (one period: 511 × 6 = 3066 samples), validated at compile time.
const PRBS_PRESET: Prbs = match Prbs::new(
    PRBS_PRESET_ORDER,
    PRBS_PRESET_LOW,
    PRBS_PRESET_HIGH,
    PRBS_PRESET_HOLD,
    1,
) {
    Some(p) if PRBS_PRESET_HIGH <= DUTY_FULL_SCALE && PRBS_PRESET_LOW <= DUTY_FULL_SCALE => p,
    _ => panic!("invalid PRBS preset"), // ok: const-evaluated, a bad preset fails the build
};

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
    /// "PRBS": order [`PRBS_PRESET_ORDER`], [`PRBS_PRESET_LOW`] / [`PRBS_PRESET_HIGH`],
    /// [`PRBS_PRESET_HOLD`] samples per bit, 3066 samples.
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

    /// A fresh generator for this record (duty units, one per 10 ms tick).
    pub const fn generator(self) -> Excitation {
        match self {
            Record::AMultistep => Excitation::Multistep(A_MULTISTEP),
            Record::BMultistep => Excitation::Multistep(B_MULTISTEP),
            Record::ARamp => Excitation::Ramp(A_RAMP),
            Record::BRamp => Excitation::Ramp(B_RAMP),
            Record::Prbs => Excitation::Prbs(PRBS_PRESET),
        }
    }

    /// Length of the record in samples.
    pub const fn len_samples(self) -> u32 {
        self.generator().len_samples()
    }

    /// The record's name as the paper writes it: "A-Multistep", "B-Multistep", "A-Ramp",
    /// "B-Ramp", or "PRBS". The one name table of this enum: [`FromStr`] reads the same names
    /// (ASCII case-insensitive).
    pub const fn name(self) -> &'static str {
        match self {
            Record::AMultistep => "A-Multistep",
            Record::BMultistep => "B-Multistep",
            Record::ARamp => "A-Ramp",
            Record::BRamp => "B-Ramp",
            Record::Prbs => "PRBS",
        }
    }
}

/// An unknown record name (see [`Record::name`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownRecord;

impl core::fmt::Display for UnknownRecord {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("unknown record (expected A-Multistep, B-Multistep, A-Ramp, B-Ramp or PRBS)")
    }
}

impl core::error::Error for UnknownRecord {}

impl FromStr for Record {
    type Err = UnknownRecord;
    fn from_str(s: &str) -> Result<Self, UnknownRecord> {
        Self::ALL
            .into_iter()
            .find(|r| r.name().eq_ignore_ascii_case(s))
            .ok_or(UnknownRecord)
    }
}
