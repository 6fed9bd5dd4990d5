//! Streaming passes over a CSV record: statistics for estimation ([`read_record`]) and
//! scores of a model ([`evaluate_file`]), each in constant memory.
//!
//! Scores are from measured initial conditions: the one-step-ahead and free-run predictors
//! are seeded with the first `m = max(p, d + q − 1)` measured samples and scored on
//! samples `m..N` ([`ridge_core_host::Evaluation`]), as MATLAB `compare` and SysIdentPy do, so
//! a model is not charged for a start-up transient it cannot know. (The estimation's initial
//! conditions are `--initial`'s: measured by default, or the paper's zero history, eq. 6.)
//!
//! Files: `stats.rs` (the statistics pass), `score.rs` (the scoring pass), `trace.rs` (what a
//! scoring pass keeps for the plot).

mod score;
mod stats;
mod trace;

pub(crate) use score::too_short_to_score;
pub use score::{evaluate, evaluate_file, Figures};
pub use stats::{read_record, read_record_with, read_samples, RecordStats, TINY_PRODUCT};
pub use trace::{Envelope, Trace, PLOT_POINTS};
