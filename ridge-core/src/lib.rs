#![no_std]
#![deny(missing_docs)]
// Small dense linear algebra reads best with the indices of its formulas.
#![allow(clippy::needless_range_loop)]
//! # ridge-core
//!
//! `no_std`, allocation-free identification of ARX models
//!
//! ```text
//! y_t = Σ_{i=1..p} θ_i y_{t-i} + Σ_{j=0..q-1} φ_j u_{t-j-d} (+ c)
//! ```
//!
//! by Ridge regression with momentum (Ridge-M) and a bounded search over `(p, q, d)`,
//! small enough to run at power-up on an ATmega2560 and the same on a PC.
//!
//! The pipeline:
//! 1. [`Gram`]: exact streaming statistics, one `(u, y)` sample at a time, in constant
//!    memory (integer counts in `i64` — exact for any record length — or `f64`).
//! 2. [`Gram::normal`]: the statistics in physical units ([`Scale`]) with `y_{t-1}`
//!    eliminated exactly, in the solve-time scalar `T` (`f32` or `f64`).
//! 3. [`Normal::system`]: the normal equations of one [`Structure`] ([`Offset`] optional).
//! 4. Estimators: [`RidgeM`], [`Ridge`], [`Ols`], `AdaptiveLasso` (cargo feature
//!    `alasso`, on by default) on a [`System`];
//!    [`Rls`] sample by sample.
//! 5. [`Search`]: the structure search with the paper's criterion, delay-free AIC (the
//!    default), BIC or validation loss, exactly pruned.
//! 6. [`ArxModel`], [`Predictor`], [`Evaluation`]: one-step and free-run prediction with
//!    RMSE and fit %, seeded with measured samples.
//! 7. [`reid`]: re-identification of one structure from a running loop's data: windowed
//!    exact statistics forgotten once a breath, Ridge-M in bounded slices, its checks.
//!
//! Compile-time maxima: `p ≤ P_MAX = 6`, `q ≤ Q_MAX = 6`, `d ≤ D_MAX = 6`. Nothing in
//! the crate allocates or panics on bad data: every failure is an [`Error`].
//!
//! ## Precision
//! See `README.md` ("Precision") for the measured agreement of the `f32` and `f64`
//! paths; the host tests check it.

mod bounds;
mod cholesky;
pub mod control;
mod eigen;
pub mod error;
pub mod estimate;
pub mod excitation;
pub mod gram;
pub mod input_map;
#[cfg(feature = "alasso")]
pub mod lasso;
mod modal;
pub mod model;
pub mod normal;
pub mod real;
pub mod reid;
pub mod ridge_m;
pub mod rls;
pub mod search;
pub mod structure;
#[doc(hidden)]
pub mod wide;

pub use error::{Error, Result, UnknownName};
pub use estimate::{Estimator, Fit, Ols, Ridge, RidgeM};
pub use gram::{Accumulator, FloatGram, Gram, IntGram, MeasuredGram, Scale};
pub use input_map::{InputMap, MapError, MapScan, MapTable, MAP_KNOTS};
#[cfg(feature = "alasso")]
pub use lasso::{AdaptiveLasso, Lambda};
pub use model::{ArxModel, Evaluation, Metrics, Mode, Predictor, Score};
pub use normal::{Factor, Normal, Regressor, System};
pub use real::Real;
pub use rls::Rls;
pub use search::{Criterion, Method, MethodKind, Search, Selection};
pub use structure::{Grid, GridIter, Offset, OrderRange, Structure, GRID_MAX};

/// Largest autoregressive order `p`.
pub const P_MAX: usize = 6;
/// Largest number of input coefficients `q`.
pub const Q_MAX: usize = 6;
/// Largest input delay `d`, in samples.
pub const D_MAX: usize = 6;
/// Input lags kept by the statistics: `u_t … u_{t-(Q_MAX+D_MAX-1)}`.
pub const L_MAX: usize = Q_MAX + D_MAX;
/// Largest number of coefficients: `P_MAX + Q_MAX + 1` (intercept).
pub const PARAMS_MAX: usize = P_MAX + Q_MAX + 1;
