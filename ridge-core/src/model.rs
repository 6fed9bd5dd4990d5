//! Identified ARX models, streaming predictors and scores (RMSE, eq. 16 of the paper; fit %
//! as MATLAB reports it).

use crate::error::{Error, Result};
use crate::normal::Col;
use crate::normal::Layout;
use crate::real::Real;
use crate::structure::{Offset, Structure};
use crate::{L_MAX, PARAMS_MAX, P_MAX, Q_MAX};

/// An ARX model `y_t = Σ_{i=1..p} θ_i y_{t-i} + Σ_{j=0..q-1} φ_j u_{t-j-d} + c`
/// in physical units (e.g. slm and duty fraction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArxModel<T: Real> {
    structure: Structure,
    offset: Offset,
    theta: [T; P_MAX],
    phi: [T; Q_MAX],
    c: T,
}

impl<T: Real> ArxModel<T> {
    /// A model from its coefficients: `theta = [θ_1 … θ_p]`, `phi = [φ_0 … φ_{q-1}]`,
    /// `c` the offset (ignored unless `offset` is [`Offset::Intercept`]).
    ///
    /// Errors: [`Error::InvalidStructure`] when the slice lengths do not give a valid
    /// structure, [`Error::NonFinite`] for NaN/±∞ coefficients.
    pub fn new(theta: &[T], phi: &[T], d: u8, offset: Offset, c: T) -> Result<Self> {
        let p = u8::try_from(theta.len()).map_err(|_| Error::InvalidStructure)?;
        let q = u8::try_from(phi.len()).map_err(|_| Error::InvalidStructure)?;
        let structure = Structure::new(p, q, d)?;
        if theta.iter().chain(phi.iter()).any(|v| !v.is_finite()) || !c.is_finite() {
            return Err(Error::NonFinite);
        }
        let mut m = ArxModel {
            structure,
            offset,
            theta: [T::ZERO; P_MAX],
            phi: [T::ZERO; Q_MAX],
            c: if offset == Offset::Intercept {
                c
            } else {
                T::ZERO
            },
        };
        m.theta[..theta.len()].copy_from_slice(theta);
        m.phi[..phi.len()].copy_from_slice(phi);
        Ok(m)
    }

    /// The first-order model with zero coefficients and no offset (`y_t = 0`): a placeholder
    /// for storage that must hold a model before one is identified.
    pub fn zero() -> Self {
        ArxModel {
            structure: Structure { p: 1, q: 1, d: 0 },
            offset: Offset::None,
            theta: [T::ZERO; P_MAX],
            phi: [T::ZERO; Q_MAX],
            c: T::ZERO,
        }
    }

    pub(crate) fn from_layout(layout: &Layout, w: &[T; PARAMS_MAX]) -> Self {
        let mut m = ArxModel {
            structure: layout.structure,
            offset: layout.offset,
            theta: [T::ZERO; P_MAX],
            phi: [T::ZERO; Q_MAX],
            c: T::ZERO,
        };
        for (col, &v) in layout.cols.iter().zip(w.iter()).take(layout.len) {
            match *col {
                Col::Y(i) => {
                    if let Some(t) = m.theta.get_mut(usize::from(i).wrapping_sub(1)) {
                        *t = v;
                    }
                }
                Col::U(k) => {
                    let j = usize::from(k - layout.structure.d);
                    if let Some(f) = m.phi.get_mut(j) {
                        *f = v;
                    }
                }
                Col::One => m.c = v,
            }
        }
        m
    }

    /// The coefficients in the internal order of `layout` (the inverse of
    /// [`ArxModel::from_layout`]).
    pub(crate) fn in_layout(&self, layout: &Layout) -> [T; PARAMS_MAX] {
        let mut w = [T::ZERO; PARAMS_MAX];
        for (slot, col) in w.iter_mut().zip(layout.cols.iter()).take(layout.len) {
            *slot = match *col {
                Col::Y(i) => self.theta.get(usize::from(i).wrapping_sub(1)).copied(),
                Col::U(k) => self
                    .phi
                    .get(usize::from(k.wrapping_sub(self.structure.d)))
                    .copied(),
                Col::One => Some(self.c),
            }
            .unwrap_or(T::ZERO);
        }
        w
    }

    /// The structure `(p, q, d)`.
    pub fn structure(&self) -> Structure {
        self.structure
    }

    /// Whether the model has an intercept.
    pub fn offset(&self) -> Offset {
        self.offset
    }

    /// `θ_1 … θ_p` (dimensionless).
    pub fn theta(&self) -> &[T] {
        &self.theta[..usize::from(self.structure.p)]
    }

    /// `φ_0 … φ_{q-1}` (output units per input unit).
    pub fn phi(&self) -> &[T] {
        &self.phi[..usize::from(self.structure.q)]
    }

    /// The intercept `c` in output units (0 without one).
    pub fn intercept(&self) -> T {
        self.c
    }

    /// Static gain `Σφ / (1 − Σθ)` (output units per input unit); ±∞ for an
    /// integrating model.
    pub fn static_gain(&self) -> T {
        let mut st = T::ZERO;
        for &t in self.theta() {
            st += t;
        }
        let mut sp = T::ZERO;
        for &f in self.phi() {
            sp += f;
        }
        sp / (T::ONE - st)
    }

    /// `ŷ_t` from `y_past[i] = y_{t-1-i}` and `u_past[k] = u_{t-k}` (`u_t` first).
    pub fn predict(&self, y_past: &[T], u_past: &[T]) -> T {
        let mut s = self.c;
        for (t, y) in self.theta().iter().zip(y_past.iter()) {
            s += *t * *y;
        }
        let d = usize::from(self.structure.d);
        for (f, u) in self.phi().iter().zip(u_past.iter().skip(d)) {
            s += *f * *u;
        }
        s
    }
}

/// How a [`Predictor`] forms its output history.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// One-step-ahead (eq. 7): past outputs are the measured ones.
    OneStep,
    /// Free-run simulation: past outputs are the model's own predictions (what MATLAB
    /// `compare` shows by default).
    FreeRun,
}

/// A streaming predictor: feed `(u_t, y_t)` samples, get `ŷ_t`.
///
/// The first `m = max(p, d + q − 1)` samples seed the history with measured values and
/// produce no prediction (as MATLAB `compare` and SysIdentPy seed them), so a model is never charged for a start-up
/// transient it cannot know. Memory: the last 6 outputs and 12 inputs, in rings (on the
/// ATmega2560 shifting arrays instead cost ~500 cycles a tick).
#[derive(Debug, Clone)]
pub struct Predictor<T: Real> {
    model: ArxModel<T>,
    mode: Mode,
    seed: usize,
    seen: usize,
    /// Past outputs, newest (`y_{t−1}` before a step) at `hy`, older ones after it (wrapping).
    y_past: [T; P_MAX],
    /// Past inputs, newest (`u_t` after it is taken) at `hu`.
    u_past: [T; L_MAX],
    hy: u8,
    hu: u8,
}

impl<T: Real> Predictor<T> {
    /// A predictor of `model` in `mode`.
    pub fn new(model: ArxModel<T>, mode: Mode) -> Self {
        Predictor {
            seed: model.structure.seed_len(),
            model,
            mode,
            seen: 0,
            y_past: [T::ZERO; P_MAX],
            u_past: [T::ZERO; L_MAX],
            hy: 0,
            hu: 0,
        }
    }

    /// Takes the input `u_t` and the measurement `y_t`; returns `ŷ_t`, or `None` while
    /// seeding. In [`Mode::OneStep`] the prediction uses only `y_{t-1}` and earlier.
    pub fn step(&mut self, u: T, y: T) -> Option<T> {
        let hu = ring_back(usize::from(self.hu), L_MAX);
        if let Some(x) = self.u_past.get_mut(hu) {
            *x = u;
        }
        let hy = usize::from(self.hy);
        let out = if self.seen >= self.seed {
            // ŷ_t = c + Σ θ_i y_{t−i} + Σ φ_j u_{t−j−d} (eq. 1).
            let m = &self.model;
            let d = usize::from(m.structure.d);
            Some(
                m.c + ring_dot(m.theta(), &self.y_past, hy)
                    + ring_dot(m.phi(), &self.u_past, hu + d),
            )
        } else {
            None
        };
        let next = match (self.mode, out) {
            (Mode::FreeRun, Some(yhat)) => yhat,
            _ => y,
        };
        let hy = ring_back(hy, P_MAX);
        if let Some(x) = self.y_past.get_mut(hy) {
            *x = next;
        }
        // Both below their capacities (6 and 12).
        self.hy = hy as u8;
        self.hu = hu as u8;
        self.seen = self.seen.saturating_add(1);
        out
    }

    /// Samples consumed for seeding (`m`).
    pub fn seed_len(&self) -> usize {
        self.seed
    }
}

/// The ring index one place before `i` (where the next newest entry goes) in a ring of `len`
/// entries (`i < len`).
pub(crate) fn ring_back(i: usize, len: usize) -> usize {
    if i == 0 {
        len - 1
    } else {
        i - 1
    }
}

/// The ring index one place after `i` (the next older entry) in a ring of `len` entries.
pub(crate) fn ring_next(i: usize, len: usize) -> usize {
    if i + 1 >= len {
        0
    } else {
        i + 1
    }
}

/// `Σ_k coefs[k] · ring[(start + k) mod len]`: a polynomial applied to a history kept in a
/// ring (newest at `start`, `start < 2 len`). Out of line: one copy of the loop serves the
/// predictor and the controller (on the ATmega2560 each inlined copy cost ~100 bytes).
#[inline(never)]
pub(crate) fn ring_dot<T: Real>(coefs: &[T], ring: &[T], start: usize) -> T {
    let len = ring.len();
    let mut i = if start >= len { start - len } else { start };
    let mut s = T::ZERO;
    for &c in coefs {
        if let Some(&x) = ring.get(i) {
            s += c * x;
        }
        i = ring_next(i, len);
    }
    s
}

/// RMSE (eq. 16) and fit % of predictions against measurements, accumulated in one pass.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Score<T: Real> {
    n: u32,
    sse: T,
    mean: T,
    m2: T,
}

/// Final figures of a [`Score`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Metrics<T> {
    /// Samples scored.
    pub n: u32,
    /// `sqrt(Σ(y − ŷ)² / n)`, output units.
    pub rmse: T,
    /// `100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)` in percent, as MATLAB's `compare` reports it.
    pub fit: T,
}

impl<T: Real> Score<T> {
    /// Empty score.
    pub fn new() -> Self {
        Score {
            n: 0,
            sse: T::ZERO,
            mean: T::ZERO,
            m2: T::ZERO,
        }
    }

    /// Adds one measurement `y` and its prediction `yhat`.
    pub fn add(&mut self, y: T, yhat: T) {
        let e = y - yhat;
        self.sse += e * e;
        self.n = self.n.saturating_add(1);
        // Welford: the spread of y without the cancellation of Σy² − (Σy)²/n.
        let delta = y - self.mean;
        self.mean += delta / T::from_u32(self.n);
        self.m2 += delta * (y - self.mean);
    }

    /// RMSE and fit; `None` before the first sample.
    pub fn metrics(&self) -> Option<Metrics<T>> {
        if self.n == 0 {
            return None;
        }
        let rmse = (self.sse / T::from_u32(self.n)).sqrt();
        let fit = T::from_f64(100.0) * (T::ONE - (self.sse / self.m2).sqrt());
        Some(Metrics {
            n: self.n,
            rmse,
            fit,
        })
    }
}

/// Scores a model on a record, one-step and free-run at once, in one streaming pass.
///
/// ```
/// use ridge_core::{ArxModel, Evaluation, Offset};
/// let m = ArxModel::new(&[0.5f64], &[1.0], 0, Offset::None, 0.0)?;
/// let mut ev = Evaluation::new(m);
/// let mut y = 0.0;
/// for t in 0..100 {
///     let u = if t % 10 < 5 { 1.0 } else { 0.0 };
///     y = 0.5 * y + u;
///     ev.push(u, y);
/// }
/// assert!(ev.free_run().unwrap().rmse < 1e-12);
/// # Ok::<(), ridge_core::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Evaluation<T: Real> {
    one: Predictor<T>,
    free: Predictor<T>,
    one_score: Score<T>,
    free_score: Score<T>,
}

impl<T: Real> Evaluation<T> {
    /// Starts scoring `model`.
    pub fn new(model: ArxModel<T>) -> Self {
        Evaluation {
            one: Predictor::new(model, Mode::OneStep),
            free: Predictor::new(model, Mode::FreeRun),
            one_score: Score::new(),
            free_score: Score::new(),
        }
    }

    /// Takes `(u_t, y_t)`; returns `(one-step ŷ_t, free-run ŷ_t)` once seeded.
    pub fn push(&mut self, u: T, y: T) -> Option<(T, T)> {
        let a = self.one.step(u, y);
        let b = self.free.step(u, y);
        match (a, b) {
            (Some(a), Some(b)) => {
                self.one_score.add(y, a);
                self.free_score.add(y, b);
                Some((a, b))
            }
            _ => None,
        }
    }

    /// One-step-ahead metrics on samples `m..N`.
    pub fn one_step(&self) -> Option<Metrics<T>> {
        self.one_score.metrics()
    }

    /// Free-run metrics on samples `m..N`.
    pub fn free_run(&self) -> Option<Metrics<T>> {
        self.free_score.metrics()
    }
}
