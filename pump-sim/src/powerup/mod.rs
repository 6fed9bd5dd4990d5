//! Issue 31's figures on the simulated rig (what `powerup-table` prints): the firmware's
//! power-up identification — when it is ready, how well its model predicts breaths over the
//! flow range and a fresh ramp signal — beside the power-up before it, the spectrum of the
//! estimation records, and the validation rule's verdicts.
//!
//! One file per concern:
//!
//! - [`before`]: the power-up before issue 31 (settle 2 s, the 30 s A-Multistep, the search
//!   on the duty), reproduced from the firmware's parts: its model, for comparison;
//! - [`fits`]: the breath program (square duties giving 10 ↔ 60 slm), the fresh B-Ramp
//!   signal, and the free-run fit of either model on them;
//! - [`spectrum`]: the power spectrum of a record against the blower's band;
//! - [`verdicts`]: the old and the new acceptance rule on healthy and changed plants;
//! - [`table`]: one plant and seed identified both ways, and the markdown.

pub mod before;
pub mod fits;
pub mod spectrum;
pub mod table;
pub mod verdicts;
