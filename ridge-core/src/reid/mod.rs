//! Closed-loop re-identification at a fixed structure: the power-up model's `(p, q, d)` and
//! intercept, re-estimated from the data the running loop produces.
//!
//! - [`Window`]: exact integer statistics `Σ z zᵀ` of the regressor row and the target,
//!   one rank-1 update per tick, forgotten once per breath by a shift (`λ = 1 − 2^−k`); the
//!   storage is borrowed, so a caller can lend it from buffers that are idle in run mode.
//! - [`Refit`]: Ridge-M on a snapshot of those statistics, resumable: each call does at most
//!   a given number of bounded units of work (a factor row, one iterate) and reports
//!   [`RefitStep::Working`], [`RefitStep::Done`] or [`RefitStep::Refused`]; the result does
//!   not depend on how the work was sliced.
//! - [`Acceptance`] / [`Holdout`]: the checks the power-up model passes where they apply
//!   (stable, static gain in range, the window excited) and a prediction check on data the fit
//!   did not see (the breaths after its snapshot), against the running model.

mod accept;
mod refit;
mod window;

pub use accept::{Acceptance, Holdout, HoldoutVerdict, Rejection};
pub use refit::{unit_flops, Refit, RefitStep};
pub use window::{window_len, Window, WindowState, WINDOW_LEN_MAX};
