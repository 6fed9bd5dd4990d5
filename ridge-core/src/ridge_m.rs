//! The settings of Ridge regression with momentum ([`RidgeM`], eq. 9–12): its four
//! hyper-parameters and the paper's values. The estimator itself (its fit and its iterates) is
//! in [`crate::estimate`]; the iterates in the normal equations' eigenbasis in `crate::modal`.
//! The settings have their own file so that both use them without importing each other.

use crate::real::Real;

/// Ridge regression with momentum (Ridge-M, eq. 9–12, Algorithm 1):
///
/// ```text
/// A = XᵀX + γD;  w_{k+1} = A⁻¹ (Xᵀy + γ D v_k);  v_{k+1} = β v_k + (1 − β) w_{k+1}
/// ```
///
/// from `v_0 = 0`, `w_0 = 0`, stopping when `‖w_{k+1} − w_k‖₂ < ε` or after `max_iter`
/// iterates. The fixed point is the least-squares solution: the iteration count is what
/// regularises, so [`Fit::iterations`](crate::estimate::Fit::iterations) is part of every result.
///
/// Two computations of the same iterates: [`RidgeM::iterate`] runs the iteration as written
/// (`A` factored once, two triangular solves per iterate, every iterate visited), while
/// [`Estimator::fit`](crate::estimate::Estimator::fit), [`RidgeM::fit_in`] and the search work in the eigenbasis of the normal
/// equations (one eigen-decomposition, then `O(n)` per iterate, `crate::modal`); they agree to
/// rounding (tested against an `f64` iteration of eq. 9–12). Both start from the Cholesky
/// Ridge solution, so the first iterate is [`Ridge`](crate::estimate::Ridge) exactly.
///
/// # Example
/// ```
/// use ridge_core::{Estimator, FloatGram, Offset, RidgeM, Scale, Structure};
/// let mut g = FloatGram::new();
/// let (mut y1, mut y2) = (0.0, 0.0);
/// for t in 0..2000 {
///     let u = if (t / 37) % 3 == 0 { 1.0 } else { -0.5 } + ((t * 7919) % 13) as f64 * 0.05;
///     let y = 1.2 * y1 - 0.4 * y2 + 0.5 * u;
///     g.push(u, y)?;
///     y2 = y1;
///     y1 = y;
/// }
/// let normal = g.normal::<f64>(Scale::UNIT)?;
/// let sys = normal.system(Structure::new(2, 1, 0)?, Offset::None)?;
/// let fit = RidgeM { max_iter: 5000, ..RidgeM::default() }.fit(&sys)?;
/// let m = fit.model();
/// assert!((m.theta()[0] - 1.2).abs() < 1e-3 && (m.phi()[0] - 0.5).abs() < 1e-3);
/// # Ok::<(), ridge_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RidgeM<T> {
    /// Regularisation `γ > 0` (paper: 1000).
    pub gamma: T,
    /// Momentum weight `β ∈ [0, 1)` (paper: 0.01).
    pub beta: T,
    /// Stopping tolerance `ε ≥ 0` on `‖w_{k+1} − w_k‖₂`, in coefficient units (1e-6).
    pub tol: T,
    /// Maximum iterates, `≥ 1` (200: the paper's Tables 2–3 settle after 150–180).
    pub max_iter: u32,
}

/// The paper's regularisation `γ`.
pub const PAPER_GAMMA: f64 = 1000.0;
/// The paper's momentum weight `β`.
pub const PAPER_BETA: f64 = 0.01;
/// Stopping tolerance `ε` (the paper gives none; 1e-6 in coefficient units).
pub const PAPER_TOL: f64 = 1e-6;
/// Iterate limit (the paper's Tables 2–3 settle after ~150–180 iterates).
pub const PAPER_MAX_ITER: u32 = 200;

impl<T: Real> Default for RidgeM<T> {
    /// γ = 1000, β = 0.01, ε = 1e-6, 200 iterates (the paper's values; its Tables 2–3 settle after ~150–180 iterates).
    fn default() -> Self {
        RidgeM {
            gamma: T::from_f64(PAPER_GAMMA),
            beta: T::from_f64(PAPER_BETA),
            tol: T::from_f64(PAPER_TOL),
            max_iter: PAPER_MAX_ITER,
        }
    }
}

impl RidgeM<f32> {
    /// [`RidgeM::default`] as a constant, in `f32` (for `static` settings on a device, which
    /// cost data rather than code).
    pub const PAPER: RidgeM<f32> = RidgeM {
        gamma: PAPER_GAMMA as f32,
        beta: PAPER_BETA as f32,
        tol: PAPER_TOL as f32,
        max_iter: PAPER_MAX_ITER,
    };
}
