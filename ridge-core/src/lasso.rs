//! Adaptive LASSO on the normal equations: one of the paper's baselines.
//!
//! Minimises `½‖y − Xw‖² + λ Σ_j ω_j |w_j|` with weights `ω_j = 1/|ŵ_j|^g` from the
//! least-squares estimate `ŵ` (Zou 2006), by cyclic coordinate descent on `XᵀX` and
//! `Xᵀy` only: the record itself is never needed. The intercept is not penalised.

use crate::cholesky::{backward, factor_in_place, forward, packed, packed_len};
use crate::error::{Error, Result};
use crate::estimate::{Estimator, Fit};
use crate::normal::{Factor, System};
use crate::real::Real;
use crate::PARAMS_MAX;

/// Sweeps between two attempts at the exact active-set solution.
const POLISH_EVERY: u32 = 10;

/// How `λ` is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lambda<T> {
    /// A fixed `λ ≥ 0`, in units of `XᵀX` entries (output² per coefficient unit).
    Fixed(T),
    /// The `λ` of a log-spaced path of 30 values from `λ_max` (all penalised
    /// coefficients zero) down to `λ_max · 1e-6` minimising BIC
    /// `N ln(RSS/N) + ln(N) · (non-zero coefficients)`.
    Bic,
}

/// Adaptive LASSO by coordinate descent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptiveLasso<T> {
    /// Penalty choice (default: BIC over a path).
    pub lambda: Lambda<T>,
    /// Weight exponent `g > 0` in `ω_j = 1/|ŵ_j|^g` (default 1).
    pub g: T,
    /// Maximum coordinate sweeps per `λ` (default 20 000).
    pub max_sweeps: u32,
    /// Stop when no coordinate moves the fit by more than `tol · ‖y‖`
    /// (`|Δw_j| · sqrt((XᵀX)_jj)`, default 1e-9).
    pub tol: T,
}

impl<T: Real> Default for AdaptiveLasso<T> {
    fn default() -> Self {
        AdaptiveLasso {
            lambda: Lambda::Bic,
            g: T::ONE,
            max_sweeps: 20_000,
            tol: T::from_f64(1e-9),
        }
    }
}

struct Problem<T> {
    n: usize,
    g: [[T; PARAMS_MAX]; PARAMS_MAX],
    b: [T; PARAMS_MAX],
    yty: T,
    weight: [T; PARAMS_MAX],
}

fn soft(x: f64, t: f64) -> f64 {
    if x > t {
        x - t
    } else if x < -t {
        x + t
    } else {
        0.0
    }
}

impl<T: Real> AdaptiveLasso<T> {
    fn problem(&self, system: &System<T>, ls: &Factor<T>) -> Result<Problem<T>> {
        if !(self.g.is_finite() && self.g > T::ZERO && self.tol.is_finite() && self.tol >= T::ZERO)
        {
            return Err(Error::InvalidParameter);
        }
        let n = system.params();
        let init = ls.solution();
        let intercept = system.layout.intercept();
        let mut p = Problem {
            n,
            g: [[T::ZERO; PARAMS_MAX]; PARAMS_MAX],
            b: [T::ZERO; PARAMS_MAX],
            yty: system.augmented(n, n),
            weight: [T::ZERO; PARAMS_MAX],
        };
        for i in 0..n {
            for j in 0..n {
                p.g[i][j] = system.augmented(i, j);
            }
            p.b[i] = system.augmented(i, n);
            p.weight[i] = if intercept == Some(i) {
                T::ZERO
            } else {
                // |ŵ|^-g via exp(-g ln|ŵ|); a zero estimate gets an infinite weight.
                let a = init[i].abs().to_f64();
                let wgt = if a > 0.0 {
                    libm::exp(-self.g.to_f64() * libm::log(a))
                } else {
                    f64::MAX
                };
                T::from_f64(wgt)
            };
        }
        Ok(p)
    }

    /// Coordinate descent at one `λ` from the warm start `w`; returns sweeps used.
    fn descend(&self, p: &Problem<T>, lambda: f64, w: &mut [f64; PARAMS_MAX]) -> u32 {
        let n = p.n;
        let scale = libm::sqrt(p.yty.to_f64().abs()).max(f64::MIN_POSITIVE);
        for sweep in 1..=self.max_sweeps.max(1) {
            let mut moved = 0.0f64;
            for j in 0..n {
                let gjj = p.g[j][j].to_f64();
                if gjj <= 0.0 {
                    continue;
                }
                let mut r = p.b[j].to_f64();
                for k in 0..n {
                    if k != j {
                        r -= p.g[j][k].to_f64() * w[k];
                    }
                }
                let new = soft(r, lambda * p.weight[j].to_f64()) / gjj;
                let dm = (new - w[j]).abs() * libm::sqrt(gjj);
                if dm > moved {
                    moved = dm;
                }
                w[j] = new;
            }
            if moved <= self.tol.to_f64() * scale {
                return sweep;
            }
            // Coordinate descent crawls on ill-conditioned Grams (100 Hz lags): once it
            // has found the support, the solution is one linear solve away.
            if sweep % POLISH_EVERY == 0 && Self::polish(p, lambda, w) {
                return sweep;
            }
        }
        self.max_sweeps.max(1)
    }

    /// Active-set step: with the support `A` and signs `s` of the current `w`, the LASSO
    /// optimum solves `G_AA w_A = b_A − λ ω_A s_A`. Accepts (and writes) that solution
    /// only if it keeps the signs and satisfies the optimality conditions
    /// `|b_j − G_j w| ≤ λ ω_j` off the support; otherwise leaves `w` alone.
    fn polish(p: &Problem<T>, lambda: f64, w: &mut [f64; PARAMS_MAX]) -> bool {
        let n = p.n;
        let mut idx = [0usize; PARAMS_MAX];
        let mut m = 0;
        for j in 0..n {
            if w[j] != 0.0 {
                idx[m] = j;
                m += 1;
            }
        }
        if m == 0 {
            return false;
        }
        let mut a = [0.0f64; packed_len(PARAMS_MAX)];
        let mut x = [0.0f64; PARAMS_MAX];
        for r in 0..m {
            let j = idx[r];
            for c in 0..=r {
                a[packed(r, c)] = p.g[j][idx[c]].to_f64();
            }
            let sign = if w[j] > 0.0 { 1.0 } else { -1.0 };
            x[r] = p.b[j].to_f64() - lambda * p.weight[j].to_f64() * sign;
        }
        if factor_in_place(&mut a, m, 0, m, 1e-14).is_err() {
            return false;
        }
        forward(&a, m, &mut x);
        backward(&a, m, &mut x);
        let mut full = [0.0f64; PARAMS_MAX];
        for r in 0..m {
            let j = idx[r];
            let penalised = p.weight[j].to_f64() > 0.0;
            if penalised && (x[r] == 0.0 || (x[r] > 0.0) != (w[j] > 0.0)) {
                return false;
            }
            full[j] = x[r];
        }
        for j in 0..n {
            if full[j] != 0.0 {
                continue;
            }
            let mut grad = p.b[j].to_f64();
            for k in 0..n {
                grad -= p.g[j][k].to_f64() * full[k];
            }
            let limit = lambda * p.weight[j].to_f64();
            if grad.abs() > limit * (1.0 + 1e-9) + 1e-12 * p.g[j][j].to_f64().abs() {
                return false;
            }
        }
        *w = full;
        true
    }

    /// `λ_max`: the smallest `λ` at which every penalised coefficient is zero (with the
    /// unpenalised intercept fitted).
    fn lambda_max(p: &Problem<T>, intercept: Option<usize>) -> f64 {
        let mut w0 = [0.0f64; PARAMS_MAX];
        if let Some(i) = intercept {
            let gii = p.g[i][i].to_f64();
            if gii > 0.0 {
                w0[i] = p.b[i].to_f64() / gii;
            }
        }
        let mut m = 0.0f64;
        for j in 0..p.n {
            if Some(j) == intercept {
                continue;
            }
            let mut r = p.b[j].to_f64();
            for k in 0..p.n {
                r -= p.g[j][k].to_f64() * w0[k];
            }
            let wt = p.weight[j].to_f64();
            if wt > 0.0 && wt < f64::MAX {
                let v = r.abs() / wt;
                if v > m {
                    m = v;
                }
            }
        }
        m
    }
}

impl<T: Real> Estimator<T> for AdaptiveLasso<T> {
    fn fit_with(&self, system: &System<T>, ls: &Factor<T>) -> Result<Fit<T>> {
        let p = self.problem(system, ls)?;
        let to_t = |w: &[f64; PARAMS_MAX]| {
            let mut out = [T::ZERO; PARAMS_MAX];
            for (o, v) in out.iter_mut().zip(w.iter()) {
                *o = T::from_f64(*v);
            }
            out
        };
        let mut w = [0.0f64; PARAMS_MAX];
        match self.lambda {
            Lambda::Fixed(l) => {
                if !(l.is_finite() && l >= T::ZERO) {
                    return Err(Error::InvalidParameter);
                }
                let sweeps = self.descend(&p, l.to_f64(), &mut w);
                Ok(Fit::new(system.layout, to_t(&w), ls, sweeps))
            }
            Lambda::Bic => {
                let lmax = Self::lambda_max(&p, system.layout.intercept());
                let nn = f64::from(system.samples());
                let mut best: Option<(f64, [f64; PARAMS_MAX], u32)> = None;
                const STEPS: i32 = 30;
                for s in 0..STEPS {
                    let lambda = lmax * libm::pow(10.0, -6.0 * f64::from(s) / f64::from(STEPS - 1));
                    let sweeps = self.descend(&p, lambda, &mut w);
                    let rss = ls.rss(&to_t(&w)[..p.n]).to_f64();
                    let k = w[..p.n].iter().filter(|v| **v != 0.0).count() as f64;
                    let bic = nn * libm::log(rss / nn) + libm::log(nn) * k;
                    if bic.is_finite() && best.as_ref().is_none_or(|b| bic < b.0) {
                        best = Some((bic, w, sweeps));
                    }
                }
                let (_, w, sweeps) = best.ok_or(Error::NonFinite)?;
                Ok(Fit::new(system.layout, to_t(&w), ls, sweeps))
            }
        }
    }
}
