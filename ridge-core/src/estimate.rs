//! Batch estimators on the normal equations of one structure: [`Ols`], [`Ridge`] and
//! Ridge with momentum ([`RidgeM`], eq. 9–12). The adaptive LASSO lives in
//! [`crate::lasso`], recursive least squares in [`crate::rls`].

use crate::error::{Error, Result};
use crate::model::ArxModel;
use crate::normal::{Factor, Layout, System};
use crate::real::Real;
use crate::PARAMS_MAX;

pub use crate::ridge_m::{RidgeM, PAPER_BETA, PAPER_GAMMA, PAPER_MAX_ITER, PAPER_TOL};

/// Coefficients fitted to one structure, with their residual sum of squares.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit<T: Real> {
    pub(crate) layout: Layout,
    /// Coefficients in internal order (see [`Fit::model`] for the ARX form).
    pub(crate) w: [T; PARAMS_MAX],
    /// `‖y − Xw‖²` on the estimation record, in output units squared.
    pub rss: T,
    /// Iterations used (Ridge-M, adaptive LASSO sweeps); 1 for closed forms.
    pub iterations: u32,
}

impl<T: Real> Fit<T> {
    pub(crate) fn new(layout: Layout, w: [T; PARAMS_MAX], ls: &Factor<T>, iterations: u32) -> Self {
        let rss = ls.rss(&w[..layout.len]);
        Fit {
            layout,
            w,
            rss,
            iterations,
        }
    }

    /// The fitted ARX model (θ, φ and offset in physical units).
    ///
    /// Never inlined: the ATmega2560's search frame is smaller without its copy (−24 B).
    #[inline(never)]
    pub fn model(&self) -> ArxModel<T> {
        ArxModel::from_layout(&self.layout, &self.w)
    }
}

/// An estimator of the coefficients of a fixed structure from its normal equations.
pub trait Estimator<T: Real> {
    /// Fits `system`, given its least-squares factor `ls = system.factor(0)`
    /// (used to compute the residual sum of squares without cancellation).
    fn fit_with(&self, system: &System<T>, ls: &Factor<T>) -> Result<Fit<T>>;

    /// Fits `system` (factors it first).
    fn fit(&self, system: &System<T>) -> Result<Fit<T>> {
        let ls = system.factor(T::ZERO)?;
        self.fit_with(system, &ls)
    }
}

/// Ordinary least squares (`γ → 0`): `w = (XᵀX)⁻¹ Xᵀy`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Ols;

impl<T: Real> Estimator<T> for Ols {
    fn fit_with(&self, system: &System<T>, ls: &Factor<T>) -> Result<Fit<T>> {
        Ok(Fit::new(system.layout, ls.solution(), ls, 1))
    }
}

/// Plain Ridge regression: `w = (XᵀX + γD)⁻¹ Xᵀy` (the first Ridge-M iterate).
///
/// `D` is the identity except at the intercept, which is not shrunk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ridge<T> {
    /// Regularisation `γ > 0`, in units of `XᵀX` (output² or input · output).
    pub gamma: T,
}

impl<T: Real> Default for Ridge<T> {
    /// `γ = 1000`, the paper's value.
    fn default() -> Self {
        Ridge {
            gamma: T::from_f64(1000.0),
        }
    }
}

impl<T: Real> Ridge<T> {
    /// [`Estimator::fit_with`] with caller-provided storage for the factor of `XᵀX + γD`
    /// (overwritten), see [`RidgeM::fit_in`].
    pub fn fit_in(&self, system: &System<T>, ls: &Factor<T>, f: &mut Factor<T>) -> Result<Fit<T>> {
        if !(self.gamma.is_finite() && self.gamma > T::ZERO) {
            return Err(Error::InvalidParameter);
        }
        system.factor_into(self.gamma, f)?;
        Ok(Fit::new(system.layout, f.solution(), ls, 1))
    }
}

impl<T: Real> Estimator<T> for Ridge<T> {
    fn fit_with(&self, system: &System<T>, ls: &Factor<T>) -> Result<Fit<T>> {
        self.fit_in(system, ls, &mut Factor::empty())
    }
}

impl<T: Real> RidgeM<T> {
    /// Checks the hyper-parameters.
    pub fn check(&self) -> Result<()> {
        let ok = self.gamma.is_finite()
            && self.gamma > T::ZERO
            && self.beta.is_finite()
            && self.beta >= T::ZERO
            && self.beta < T::ONE
            && self.tol.is_finite()
            && self.tol >= T::ZERO
            && self.max_iter >= 1;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidParameter)
        }
    }

    /// Runs the iteration as written and calls `visit(k, w_k)` after every iterate
    /// `k = 1, 2, …` (for convergence tables); returns the last iterate (internal order) and
    /// the number of iterates. Needs only `XᵀX + γD` to be positive definite (not `XᵀX`).
    pub fn iterate(
        &self,
        system: &System<T>,
        mut visit: impl FnMut(u32, &[T]),
    ) -> Result<([T; PARAMS_MAX], u32)> {
        self.check()?;
        let n = system.params();
        let f = system.factor(self.gamma)?;
        let w_ridge = f.solution();
        let intercept = system.layout.intercept();
        let mut v = [T::ZERO; PARAMS_MAX];
        let mut w_prev = [T::ZERO; PARAMS_MAX];
        let mut w = w_prev;
        let mut used = self.max_iter;
        for k in 1..=self.max_iter {
            // w = A⁻¹ Xᵀy + γ A⁻¹ D v: the first term is the Ridge solution.
            let mut x = v;
            if let Some(i) = intercept {
                x[i] = T::ZERO;
            }
            f.solve(&mut x[..n]);
            let mut step = T::ZERO;
            for i in 0..n {
                w[i] = w_ridge[i] + self.gamma * x[i];
                let dw = w[i] - w_prev[i];
                step += dw * dw;
                v[i] = self.beta * v[i] + (T::ONE - self.beta) * w[i];
            }
            visit(k, &w[..n]);
            if step.sqrt() < self.tol {
                used = k;
                break;
            }
            w_prev = w;
        }
        Ok((w, used))
    }

    /// The fit of [`Estimator::fit_with`] in caller-provided storage (what the search
    /// lends, which matters in 8 KB of SRAM): the iterates of [`RidgeM::iterate`] computed
    /// in the eigenbasis of the normal equations, `O(n)` per iterate after one
    /// eigen-decomposition of the least-squares factor `ls` (`system.factor(0)`). `ls` and
    /// `f` are its work space: `ls` is factored again before the fit's RSS is computed from it
    /// (it holds the least-squares factor on success, maybe nothing usable after an error),
    /// `f` is overwritten. Calls `progress()` between factorisations, for every pair of
    /// columns the decomposition compares, once per mode and once per iterate, so that no
    /// stretch between two calls is longer than one `(n + 1)`-row factorisation.
    ///
    /// Errors: as [`RidgeM::check`] and [`System::factor`]; [`Error::InvalidStructure`] when
    /// `ls` is not a factor of `system`'s size; [`Error::NonFinite`] when the decomposition
    /// or the result is not finite.
    pub fn fit_in(
        &self,
        system: &System<T>,
        ls: &mut Factor<T>,
        f: &mut Factor<T>,
        mut progress: impl FnMut(),
    ) -> Result<Fit<T>> {
        let (w, used) = crate::modal::ridge_m(self, system, ls, f, &mut progress)?;
        Ok(Fit::new(system.layout, w, ls, used))
    }
}

impl<T: Real> Estimator<T> for RidgeM<T> {
    fn fit_with(&self, system: &System<T>, ls: &Factor<T>) -> Result<Fit<T>> {
        self.fit_in(system, &mut ls.clone(), &mut Factor::empty(), || {})
    }
}
