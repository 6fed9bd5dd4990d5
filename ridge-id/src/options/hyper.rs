//! [`Hyper`]: the numeric settings of a run (estimator, criterion, RLS), with the paper's
//! values as defaults.

use crate::initial::Initial;

/// Hyper-parameters of a run (all of them, whether the method uses them or not).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hyper {
    /// Ridge / Ridge-M regularisation γ (default 1000).
    pub gamma: f64,
    /// Ridge-M momentum β (default 0.01).
    pub beta: f64,
    /// Penalty weight α of the `paper` and `aic` criteria (default 12).
    pub alpha: f64,
    /// Ridge-M maximum iterates (default 200).
    pub max_iter: u32,
    /// Ridge-M stopping tolerance ε (default 1e-6).
    pub tol: f64,
    /// RLS forgetting factor λ ∈ (0, 1] (default 1).
    pub lambda: f64,
    /// RLS initial covariance δ > 0, `P₀ = δI` (default 1e3).
    pub delta: f64,
    /// Initial conditions of the regression (default [`Initial::Measured`]).
    pub initial: Initial,
}

impl Default for Hyper {
    /// The paper's values (the `ridge-id` defaults).
    fn default() -> Self {
        Hyper {
            gamma: 1000.0,
            beta: 0.01,
            alpha: 12.0,
            max_iter: 200,
            tol: 1e-6,
            lambda: 1.0,
            delta: 1e3,
            initial: Initial::Measured,
        }
    }
}
