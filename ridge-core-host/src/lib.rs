#![no_std]
#![deny(missing_docs)]
#![allow(clippy::needless_range_loop)]
//! # ridge-core-host
//!
//! ridge-core's identification code (statistics, estimators, structure search, models) built
//! a second time with larger compile-time maxima, for identifying logged data on a PC
//! (`ridge-id`): `p ≤ P_MAX = 12`, `q ≤ Q_MAX = 12`, `d ≤ D_MAX = 12` (so `q + d ≤ 24`).
//!
//! The maxima size every fixed array of the core (lag histories, the lag Gram, factors,
//! coefficient vectors), so they are constants of the crate. ridge-core keeps 6/6/6 for the
//! devices, whose RAM and flash budgets are set by them; this crate compiles the very same
//! source files (`#[path]`, nothing copied) with the constants below. Only the identification
//! modules are included: the controller design stays ridge-core's (the firmware's orders).
//! Costs of the larger maxima: the statistics keep 13 output and 24 input lags (73 products a
//! sample instead of 37) and `Gram::normal` forms a 38 × 38 lag Gram instead of 20 × 20;
//! `MeasuredGram::for_grid` (what ridge-id uses) keeps only the lags of the grid searched,
//! 37 products a sample on the default 6/6/6 grid.
//!
//! The API is ridge-core's; see its documentation.

#[path = "../../ridge-core/src/bounds.rs"]
mod bounds;
#[path = "../../ridge-core/src/cholesky.rs"]
mod cholesky;
#[path = "../../ridge-core/src/eigen.rs"]
mod eigen;
#[path = "../../ridge-core/src/error.rs"]
pub mod error;
#[path = "../../ridge-core/src/estimate.rs"]
pub mod estimate;
#[path = "../../ridge-core/src/gram.rs"]
pub mod gram;
#[cfg(feature = "alasso")]
#[path = "../../ridge-core/src/lasso.rs"]
pub mod lasso;
#[path = "../../ridge-core/src/modal.rs"]
mod modal;
#[path = "../../ridge-core/src/model.rs"]
pub mod model;
#[path = "../../ridge-core/src/normal.rs"]
pub mod normal;
#[path = "../../ridge-core/src/real.rs"]
pub mod real;
#[path = "../../ridge-core/src/ridge_m.rs"]
pub mod ridge_m;
#[path = "../../ridge-core/src/rls.rs"]
pub mod rls;
#[path = "../../ridge-core/src/search.rs"]
pub mod search;
#[path = "../../ridge-core/src/structure.rs"]
pub mod structure;
#[doc(hidden)]
#[path = "../../ridge-core/src/wide.rs"]
pub mod wide;

pub use error::{Error, Result, UnknownName};
pub use estimate::{Estimator, Fit, Ols, Ridge, RidgeM};
pub use gram::{Accumulator, FloatGram, Gram, IntGram, MeasuredGram, Scale};
#[cfg(feature = "alasso")]
pub use lasso::{AdaptiveLasso, Lambda};
pub use model::{ArxModel, Evaluation, Metrics, Mode, Predictor, Score};
pub use normal::{Factor, Normal, Regressor, System};
pub use real::Real;
pub use rls::Rls;
pub use search::{Criterion, Method, MethodKind, Search, Selection};
pub use structure::{Grid, GridIter, Offset, OrderRange, Structure, GRID_MAX};

/// Largest autoregressive order `p` (host).
pub const P_MAX: usize = 12;
/// Largest number of input coefficients `q` (host).
pub const Q_MAX: usize = 12;
/// Largest input delay `d`, in samples (host).
pub const D_MAX: usize = 12;
/// Input lags kept by the statistics: `u_t … u_{t-(Q_MAX+D_MAX-1)}`.
pub const L_MAX: usize = Q_MAX + D_MAX;
/// Largest number of coefficients: `P_MAX + Q_MAX + 1` (intercept).
pub const PARAMS_MAX: usize = P_MAX + Q_MAX + 1;
