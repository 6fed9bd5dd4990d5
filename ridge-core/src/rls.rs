//! Recursive least squares for a fixed structure, sample by sample (`P₀ = δI`, forgetting
//! factor λ): one of the paper's baselines.

use crate::cholesky::{packed, packed_len};
use crate::error::{Error, Result};
use crate::model::ArxModel;
use crate::normal::Col;
use crate::normal::Layout;
use crate::real::Real;
use crate::structure::{Offset, Structure};
use crate::{L_MAX, PARAMS_MAX, P_MAX};

/// Recursive least squares with exponential forgetting:
///
/// ```text
/// k = P φ / (λ + φᵀ P φ);  w ← w + k (y − φᵀ w);  P ← (P − k φᵀ P) / λ
/// ```
///
/// from `w = 0`, `P₀ = δ I`, with zero history before the first sample (the same
/// regressors as eq. 6). `P` is kept symmetric in packed storage (91 scalars).
#[derive(Debug, Clone)]
pub struct Rls<T: Real> {
    layout: Layout,
    lambda: T,
    w: [T; PARAMS_MAX],
    p: [T; packed_len(PARAMS_MAX)],
    y_past: [T; P_MAX],
    u_past: [T; L_MAX],
    samples: u32,
}

impl<T: Real> Rls<T> {
    /// RLS for `structure` with forgetting factor `lambda ∈ (0, 1]` (1 = ordinary
    /// least squares) and initial covariance `delta > 0` (`P₀ = δI`, e.g. 1e3).
    pub fn new(structure: Structure, offset: Offset, lambda: T, delta: T) -> Result<Self> {
        structure.check()?;
        let lambda_ok = lambda.is_finite() && lambda > T::ZERO && lambda <= T::ONE;
        let delta_ok = delta.is_finite() && delta > T::ZERO;
        if !(lambda_ok && delta_ok) {
            return Err(Error::InvalidParameter);
        }
        let layout = Layout::new(structure, offset);
        let mut p = [T::ZERO; packed_len(PARAMS_MAX)];
        for i in 0..layout.len {
            p[packed(i, i)] = delta;
        }
        Ok(Rls {
            layout,
            lambda,
            w: [T::ZERO; PARAMS_MAX],
            p,
            y_past: [T::ZERO; P_MAX],
            u_past: [T::ZERO; L_MAX],
            samples: 0,
        })
    }

    fn p_at(&self, i: usize, j: usize) -> T {
        let (a, b) = if i >= j { (i, j) } else { (j, i) };
        self.p[packed(a, b)]
    }

    /// Takes `(u_t, y_t)` and updates the estimate. Returns the a-priori prediction
    /// error `y_t − φᵀw` (output units).
    ///
    /// Errors: [`Error::NonFinite`] for a non-finite sample or when the update would
    /// make the estimate non-finite; the state is then unchanged.
    pub fn update(&mut self, u: T, y: T) -> Result<T> {
        if !(u.is_finite() && y.is_finite()) {
            return Err(Error::NonFinite);
        }
        let mut u_past = self.u_past;
        u_past.copy_within(0..L_MAX - 1, 1);
        u_past[0] = u;
        let n = self.layout.len;
        let mut phi = [T::ZERO; PARAMS_MAX];
        for (slot, col) in phi.iter_mut().zip(self.layout.cols.iter()).take(n) {
            *slot = match *col {
                Col::Y(i) => self.y_past[usize::from(i) - 1],
                Col::U(k) => u_past[usize::from(k)],
                Col::One => T::ONE,
            };
        }
        let mut pphi = [T::ZERO; PARAMS_MAX];
        let mut denom = self.lambda;
        let mut yhat = T::ZERO;
        for i in 0..n {
            let mut s = T::ZERO;
            for j in 0..n {
                s += self.p_at(i, j) * phi[j];
            }
            pphi[i] = s;
            denom += phi[i] * s;
            yhat += phi[i] * self.w[i];
        }
        let err = y - yhat;
        let mut w = self.w;
        let mut p = self.p;
        for i in 0..n {
            w[i] += pphi[i] / denom * err;
            for j in 0..=i {
                p[packed(i, j)] = (p[packed(i, j)] - pphi[i] * pphi[j] / denom) / self.lambda;
            }
        }
        if !(err.is_finite() && w.iter().chain(p.iter()).all(|v| v.is_finite())) {
            return Err(Error::NonFinite);
        }
        self.w = w;
        self.p = p;
        self.u_past = u_past;
        self.y_past.copy_within(0..P_MAX - 1, 1);
        self.y_past[0] = y;
        self.samples = self.samples.saturating_add(1);
        Ok(err)
    }

    /// Samples taken.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// The current model.
    pub fn model(&self) -> ArxModel<T> {
        ArxModel::from_layout(&self.layout, &self.w)
    }
}
