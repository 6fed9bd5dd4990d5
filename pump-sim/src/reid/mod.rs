//! The closed-loop re-identification study (issue 32, item 3): the firmware identifies the
//! simulated blower and lung at power-up and designs its controller as on the device; the loop
//! then tracks square breaths while `ridge_core::reid` re-estimates the ARX part of its
//! Hammerstein model (the dynamics from the static map's flow `v` to the flow; the map stays) at
//! the same structure from the loop's own data (the direct method), checks it, and the
//! controller is re-designed and swapped at a breath boundary. The lung changes suddenly at
//! chosen breaths.
//!
//! - `truth.rs`: [`linearisation`], the truth, the noise-free plant's small-signal step response
//!   and static gain at a steady flow (central differences of `±δ` duty steps); [`through_map`]
//!   and [`secant_through_map`]: the same as the model sees it, after the power-up's map;
//!   [`closed_valve_step`]: a volume breath's inspiration, the exhalation valve closed.
//! - `study.rs`: [`run`], one closed-loop run ([`Study`]) with the per-breath figures
//!   ([`BreathFigures`]) and every re-estimate ([`Estimate`]), and the figures its tables use.
//! - `closed_loop.rs`: the loop's two sides, which the ventilation benchmark
//!   ([`crate::vent_bench`]) runs too: [`Running`], the firmware's controller through the static
//!   map ([`Running::tick`]: run mode's step; [`Running::swapped`]: the bumpless swap,
//!   [`Running::swapped_at`] with a given regulation speed, [`design_at`]), and
//!   [`Reestimation`], the window, the re-estimate (its record [`Estimate`]), its hold-out and
//!   verdict, and the swap rule ([`swap_allowed`]); [`Feed`] which ticks the window takes and
//!   at which structure (every tick today; each inspiration only, the breath-plant study).
//!
//! # Timing
//! As in [`crate::baseline::experiment`]: tick `k` reads the flow at the end of interval
//! `k − 1`, sets the duty of interval `k` (setpoint `value(program, start, k + preview)`), and
//! the window takes `(v_k, reading_k)` after the interval (`v_k` the map's flow at the duty
//! written), the firmware's order (statistics after the PWM write). [`Study::units`]
//! [`Refit`](ridge_core::reid::Refit) units per tick. Breath `b` (from 0) is ticks
//! `b·P … (b + 1)·P − 1`; a lung change, a re-estimate's start and its verdict happen at breath
//! boundaries, a controller swap at the boundary as the controller sees it (its preview ahead).

mod closed_loop;
mod study;
mod truth;

pub use closed_loop::{
    design, design_at, design_verdict, map_slm, swap_allowed, Estimate, Feed, Mode, Reestimation,
    Rules, Running, WindowStore,
};
pub(crate) use study::DitherGen;
pub use study::{
    acceptance, breath_ticks, breaths_in, inspiration_ticks, mean_sd, models_in, run,
    BreathFigures, Dither, LungChange, Study, StudyRun, MIN_INPUT_RESPONSE, PROGRAM,
};
pub use truth::{
    closed_valve_step, linearisation, model_step, rise63, secant_gain, secant_through_map,
    step_error_pct, through_map, Linearisation, DELTA, STEP_TICKS,
};
