//! Solve-time statistics: the lag Gram in physical units, per-structure normal
//! equations ([`System`]) and their Cholesky factors ([`Factor`]).
//!
//! # Numerics
//! Flow and duty records have large means and, at 100 Hz, neighbouring lags are almost
//! collinear, so `XᵀX` and `yᵀy` are dominated by what `y_{t-1}` already explains. Every
//! structure contains `y_{t-1}` (`p ≥ 1`), and [`crate::Gram::normal`] eliminates it
//! *exactly*: with integer statistics the Schur complements
//! `S_ab − S_a1 S_1b / S_11` are formed from 128-bit products before any rounding. The
//! floating-point Cholesky then only sees the part of the data that `y_{t-1}` does
//! not explain, which is what lets `f32` resolve residual sums of squares of
//! 10⁻⁵ of `yᵀy` (see the crate docs for measured precision).
//!
//! The residual sum of squares of any coefficient vector `w` is computed as
//! `RSS(w) = RSS_OLS + ‖L₀ᵀ w − l‖²` from the factor `[L₀ 0; lᵀ ρ]` of the augmented
//! matrix `[XᵀX Xᵀy; yᵀX yᵀy]` (`RSS_OLS = ρ²`): a sum of two non-negative terms, free of
//! the cancellation of `yᵀy − 2wᵀXᵀy + wᵀXᵀXw`, and never below the least-squares bound
//! that the pruned search relies on.

use crate::cholesky::{backward, factor_in_place, forward, packed, packed_len};
use crate::error::{Error, Result};
use crate::real::Real;
use crate::structure::{Offset, Structure};
use crate::{L_MAX, PARAMS_MAX, P_MAX};

/// One column of the full lag Gram: an output lag, an input lag or the constant 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Col {
    /// `y_{t-k}`, `k ∈ 0..=P_MAX` (`k = 0` is the regression target).
    Y(u8),
    /// `u_{t-k}`, `k ∈ 0..L_MAX`.
    U(u8),
    /// The constant 1 of the intercept.
    One,
}

/// The 19 columns of the lag Gram other than the pivot `y_{t-1}`:
/// `y_{t-2} … y_{t-P}`, `u_t … u_{t-L+1}`, `1`, `y_t` (target, last).
pub(crate) const OTHERS: [Col; P_MAX - 1 + L_MAX + 2] = others();

const fn others() -> [Col; P_MAX - 1 + L_MAX + 2] {
    let mut out = [Col::One; P_MAX - 1 + L_MAX + 2];
    let mut i = 0;
    while i < P_MAX - 1 {
        out[i] = Col::Y(i as u8 + 2);
        i += 1;
    }
    let mut j = 0;
    while j < L_MAX {
        out[P_MAX - 1 + j] = Col::U(j as u8);
        j += 1;
    }
    out[P_MAX - 1 + L_MAX] = Col::One;
    out[P_MAX + L_MAX] = Col::Y(0);
    out
}

/// The column at position `idx` of [`OTHERS`], computed rather than read from the
/// constant table (the AVR build is checked against the host with this form).
pub(crate) fn other(idx: usize) -> Col {
    if idx < P_MAX - 1 {
        Col::Y(idx as u8 + 2)
    } else if idx < P_MAX - 1 + L_MAX {
        Col::U((idx - (P_MAX - 1)) as u8)
    } else if idx == P_MAX - 1 + L_MAX {
        Col::One
    } else {
        Col::Y(0)
    }
}

/// Number of columns besides the pivot `y_{t-1}`.
pub(crate) const N_OTHER: usize = OTHERS.len();

/// Position of a column in [`OTHERS`].
pub(crate) fn others_index(c: Col) -> usize {
    match c {
        Col::Y(0) => P_MAX + L_MAX,
        Col::Y(k) => usize::from(k) - 2,
        Col::U(k) => P_MAX - 1 + usize::from(k),
        Col::One => P_MAX - 1 + L_MAX,
    }
}

const N_OTHERS: usize = OTHERS.len();

/// The full lag Gram of one record in physical units, with `y_{t-1}` eliminated
/// exactly (see the [module docs](self)). Made by [`crate::Gram::normal`]; 210 scalars
/// (840 bytes in `f32`).
#[derive(Debug, Clone, PartialEq)]
#[repr(C)]
pub struct Normal<T: Real> {
    pub(crate) n: u32,
    /// `Σ y_{t-1}²`.
    pub(crate) s11: T,
    /// `Σ c_t y_{t-1}` for each column of [`OTHERS`].
    pub(crate) r: [T; N_OTHERS],
    /// Exact Schur complements `S_ab − S_a1 S_1b / S_11`, packed.
    pub(crate) schur: [T; packed_len(N_OTHERS)],
    /// Rounding level of `yᵀy` from the accumulation (zero for integer statistics).
    pub(crate) y_rounding: T,
}

impl<T: Real> Normal<T> {
    /// Empty statistics (no samples), e.g. storage for [`crate::Gram::normal_into`].
    pub fn empty() -> Self {
        Normal {
            n: 0,
            s11: T::ZERO,
            r: [T::ZERO; N_OTHERS],
            schur: [T::ZERO; packed_len(N_OTHERS)],
            y_rounding: T::ZERO,
        }
    }

    /// Resets to [`Normal::empty`] in place, element by element (no 840-byte temporary).
    pub(crate) fn clear(&mut self) {
        self.n = 0;
        self.s11 = T::ZERO;
        self.y_rounding = T::ZERO;
        for v in self.r.iter_mut().chain(self.schur.iter_mut()) {
            *v = T::ZERO;
        }
    }

    pub(crate) fn set_schur(&mut self, a: usize, b: usize, v: T) {
        let (a, b) = if a >= b { (a, b) } else { (b, a) };
        if let Some(x) = self.schur.get_mut(packed(a, b)) {
            *x = v;
        }
    }

    pub(crate) fn schur_at(&self, a: usize, b: usize) -> T {
        let (a, b) = if a >= b { (a, b) } else { (b, a) };
        self.schur.get(packed(a, b)).copied().unwrap_or(T::ZERO)
    }

    pub(crate) fn check_finite(&self) -> Result<()> {
        let all = core::iter::once(&self.s11)
            .chain(self.r.iter())
            .chain(self.schur.iter());
        for v in all {
            if !v.is_finite() {
                return Err(Error::Overflow);
            }
        }
        Ok(())
    }

    /// Entry `(a, b)` (positions in [`OTHERS`]) of the matrix that Cholesky continues on
    /// after the exact pivot `y_{t-1}`, without the `γD` of the diagonal: the Schur
    /// complement plus `c r_a r_b`, `c = γ / (s11 (s11 + γ))` (see [`System::factor_into`],
    /// whose formula this is; `c = 0` for least squares).
    pub(crate) fn trailing(&self, a: usize, b: usize, c: T) -> T {
        let ra = self.r.get(a).copied().unwrap_or(T::ZERO);
        let rb = self.r.get(b).copied().unwrap_or(T::ZERO);
        self.schur_at(a, b) + c * ra * rb
    }

    /// `c = γ / (s11 (s11 + γ))` of [`Normal::trailing`] and the pivot `s11 + γ`, or
    /// [`Error::NotPositiveDefinite`] when that pivot is not positive and finite.
    pub(crate) fn pivot(&self, gamma: T) -> Result<(T, T)> {
        let a11 = self.s11 + gamma;
        if a11 <= T::ZERO || !a11.is_finite() {
            return Err(Error::NotPositiveDefinite);
        }
        Ok((a11, gamma / (self.s11 * a11)))
    }

    /// The rounding floor of the least-squares RSS of a system of `n` coefficients:
    /// Cholesky's backward error on the target row (`4 n ε` of what `y_{t-1}` leaves
    /// unexplained of the target) plus the rounding of the statistics themselves.
    pub(crate) fn rss_floor(&self, n: usize) -> T {
        let target = others_index(Col::Y(0));
        let floor = T::from_u32(4 * n as u32) * T::EPSILON * self.schur_at(target, target)
            + self.y_rounding;
        if floor > T::ZERO {
            floor
        } else {
            T::ZERO
        }
    }

    /// Number of samples `N` of the record (rows of the regression matrix).
    pub fn samples(&self) -> u32 {
        self.n
    }

    /// The normal equations of one structure: `XᵀX`, `Xᵀy`, `yᵀy` and `N` of the
    /// zero-padded regression matrix of eq. (6), in physical units.
    ///
    /// Errors: [`Error::InvalidStructure`] outside the maxima, [`Error::TooShort`] when
    /// the record has fewer than `m + n + 1` samples (`m` seed samples, `n` parameters).
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    pub fn system(&self, structure: Structure, offset: Offset) -> Result<System<'_, T>> {
        structure.check()?;
        let layout = Layout::new(structure, offset);
        let n = layout.len;
        let needed = (structure.seed_len() + n + 1) as u32;
        if self.n < needed {
            return Err(Error::TooShort {
                needed,
                have: self.n,
            });
        }
        // Rest = params 1..n, then the target: n entries, as positions in OTHERS.
        let mut rest = [0u8; PARAMS_MAX];
        for (slot, c) in rest.iter_mut().zip(layout.cols[1..n].iter()) {
            *slot = others_index(*c) as u8;
        }
        rest[n - 1] = others_index(Col::Y(0)) as u8;
        Ok(System {
            normal: self,
            layout,
            rest,
        })
    }

    /// Residual sum of squares `‖y − Xw‖²` of `model` on this record (one-step-ahead
    /// errors of eq. 6 with zero history), in output units squared: how a second `Gram`
    /// of a validation record scores an identified model without the data.
    ///
    /// Errors: as [`Normal::system`] and [`System::factor`].
    pub fn rss(&self, model: &crate::ArxModel<T>) -> Result<T> {
        let sys = self.system(model.structure(), model.offset())?;
        let ls = sys.factor(T::ZERO)?;
        let w = model.in_layout(&sys.layout);
        Ok(ls.rss(&w[..sys.params()]))
    }
}

/// Where each coefficient of a structure sits in the parameter vector.
///
/// Internal order: `[y_{t-1}, (1), y_{t-2} … y_{t-p}, u_{t-d} … u_{t-d-q+1}]`: the columns
/// every candidate of one `p` shares come first and the input lags last, so that the
/// factor of `(p, q, d)` is the leading block of the factor of `(p, q', d)` for `q' > q`
/// (what the search's bounds use, [`crate::bounds`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Layout {
    pub(crate) structure: Structure,
    pub(crate) offset: Offset,
    pub(crate) len: usize,
    pub(crate) cols: [Col; PARAMS_MAX],
}

impl Layout {
    pub(crate) fn new(structure: Structure, offset: Offset) -> Self {
        let mut cols = [Col::One; PARAMS_MAX];
        let mut n = 0;
        let mut put = |c: Col| {
            if let Some(slot) = cols.get_mut(n) {
                *slot = c;
                n += 1;
            }
        };
        put(Col::Y(1));
        if offset == Offset::Intercept {
            put(Col::One);
        }
        for i in 2..=structure.p {
            put(Col::Y(i));
        }
        for j in 0..structure.q {
            put(Col::U(structure.d + j));
        }
        Layout {
            structure,
            offset,
            len: n,
            cols,
        }
    }

    /// Index of the intercept, if any.
    pub(crate) fn intercept(&self) -> Option<usize> {
        match self.offset {
            Offset::Intercept => Some(1),
            Offset::None => None,
        }
    }
}

/// What one column of the regression matrix `X` of eq. (6) holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regressor {
    /// The output `y_{t-k}` (`k = 0` is the regression target `y_t`).
    Output(u8),
    /// The input `u_{t-k}`.
    Input(u8),
    /// The constant 1 of the intercept.
    Constant,
}

/// The normal equations of one structure on one record (see [`Normal::system`]): a
/// view into the record's [`Normal`] (no copy: 30 bytes plus a reference, which keeps
/// the search's stack small on an 8-bit MCU).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct System<'a, T: Real> {
    normal: &'a Normal<T>,
    pub(crate) layout: Layout,
    /// Positions in [`OTHERS`] of params `1..n` and the target (index `n − 1`).
    rest: [u8; PARAMS_MAX],
}

impl<T: Real> System<'_, T> {
    /// `Σ c_t y_{t-1}` of rest entry `a`.
    fn r(&self, a: usize) -> T {
        self.normal
            .r
            .get(usize::from(self.rest[a]))
            .copied()
            .unwrap_or(T::ZERO)
    }

    /// Exact Schur complement of rest entries `a`, `b`.
    fn schur(&self, a: usize, b: usize) -> T {
        self.normal
            .schur_at(usize::from(self.rest[a]), usize::from(self.rest[b]))
    }

    /// Samples `N` of the record.
    pub fn samples(&self) -> u32 {
        self.normal.n
    }

    /// Number of coefficients `n = p + q (+ 1)`.
    pub fn params(&self) -> usize {
        self.layout.len
    }

    /// The structure.
    pub fn structure(&self) -> Structure {
        self.layout.structure
    }

    /// The offset choice.
    pub fn offset(&self) -> Offset {
        self.layout.offset
    }

    /// The regressor of parameter `i` in internal order (`i = n`: the target
    /// `Output(0)`); `None` past the end. The internal order is
    /// `[y_{t-1}, (1), y_{t-2} … y_{t-p}, u_{t-d} … u_{t-d-q+1}]`.
    pub fn regressor(&self, i: usize) -> Option<Regressor> {
        if i == self.layout.len {
            return Some(Regressor::Output(0));
        }
        self.layout
            .cols
            .get(i)
            .filter(|_| i < self.layout.len)
            .map(|c| match *c {
                Col::Y(k) => Regressor::Output(k),
                Col::U(k) => Regressor::Input(k),
                Col::One => Regressor::Constant,
            })
    }

    /// Entry `(i, j)` of the augmented matrix `[XᵀX Xᵀy; yᵀX yᵀy]` in internal
    /// parameter order (index `n` is the target), reconstructed from the pivot and the
    /// Schur complement. For estimators that need the plain Gram (coordinate descent,
    /// reference tests); the factorisations do not use it.
    pub fn augmented(&self, i: usize, j: usize) -> T {
        let n = self.layout.len;
        if i > n || j > n {
            return T::ZERO;
        }
        match (i, j) {
            (0, 0) => self.normal.s11,
            (0, k) | (k, 0) => self.r(k - 1),
            (a, b) => {
                let (a, b) = (a - 1, b - 1);
                self.schur(a, b) + self.r(a) * self.r(b) / self.normal.s11
            }
        }
    }

    /// Factors `[XᵀX + γD, Xᵀy; yᵀX, yᵀy]`, where `D` is the identity except for a zero
    /// at the intercept (the intercept is not regularised). `gamma = 0` gives the
    /// least-squares factor.
    ///
    /// Errors: [`Error::InvalidParameter`] for `gamma < 0` or non-finite,
    /// [`Error::NotPositiveDefinite`] when the regressors are (numerically) linearly
    /// dependent on this record.
    pub fn factor(&self, gamma: T) -> Result<Factor<T>> {
        let mut f = Factor::empty();
        self.factor_into(gamma, &mut f)?;
        Ok(f)
    }

    /// [`System::factor`] into existing storage (no 420-byte temporary on the stack).
    /// On error `out` holds no usable factor.
    pub fn factor_into(&self, gamma: T, out: &mut Factor<T>) -> Result<()> {
        if !gamma.is_finite() || gamma < T::ZERO {
            return Err(Error::InvalidParameter);
        }
        let n = self.layout.len;
        // Eliminating the regularised pivot y_{t-1} leaves, for the other columns,
        // Schur + γD + r rᵀ (1/s11 − 1/(s11 + γ)) = Schur + γD + r rᵀ γ / (s11 (s11 + γ)):
        // the trailing block is formed from the exact Schur complements, column 0 of L
        // directly, and Cholesky continues from row 1.
        let (a11, c) = self.normal.pivot(gamma)?;
        let l00 = a11.sqrt();
        let intercept = self.layout.intercept();
        out.n = n;
        out.l[0] = l00;
        for i in 1..=n {
            let ri = usize::from(self.rest[i - 1]);
            out.l[packed(i, 0)] = self.r(i - 1) / l00;
            for j in 1..=i {
                let mut v = self.normal.trailing(ri, usize::from(self.rest[j - 1]), c);
                // The target (row n) is never regularised, nor is the intercept.
                if i == j && i < n && intercept != Some(i) {
                    v += gamma;
                }
                out.l[packed(i, j)] = v;
            }
        }
        factor_in_place(&mut out.l, n + 1, 1, n, pivot_tol())?;
        out.rss_floor = self.normal.rss_floor(n);
        Ok(())
    }
}

/// The relative pivot tolerance of every factorisation of normal equations: a pivot of a
/// regressor row at or below `4 · PARAMS_MAX · ε` of its diagonal entry is a linear
/// dependence ([`Error::NotPositiveDefinite`]).
pub(crate) fn pivot_tol<T: Real>() -> T {
    T::from_u32(4 * PARAMS_MAX as u32) * T::EPSILON
}

/// Cholesky factor `[L 0; lᵀ ρ]` of an augmented normal-equation matrix
/// (see [`System::factor`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Factor<T: Real> {
    n: usize,
    l: [T; packed_len(PARAMS_MAX + 1)],
    rss_floor: T,
}

impl<T: Real> Factor<T> {
    /// Storage for a factor, to be filled by [`System::factor_into`].
    pub fn empty() -> Self {
        Factor {
            n: 0,
            l: [T::ZERO; packed_len(PARAMS_MAX + 1)],
            rss_floor: T::ZERO,
        }
    }

    /// The factor's storage as scratch space ([`crate::bounds`]); the factor is not usable
    /// afterwards.
    pub(crate) fn storage(&mut self) -> &mut [T; packed_len(PARAMS_MAX + 1)] {
        self.n = 0;
        &mut self.l
    }

    /// Number of coefficients.
    pub fn params(&self) -> usize {
        self.n
    }

    /// Entry `(i, j)` of `[L 0; lᵀ ρ]` (row `n`: the augmented row); zero above the diagonal
    /// and outside.
    pub(crate) fn at(&self, i: usize, j: usize) -> T {
        if j > i || i > self.n {
            return T::ZERO;
        }
        self.l.get(packed(i, j)).copied().unwrap_or(T::ZERO)
    }

    /// `ρ²`: the residual sum of squares of the least-squares solution of the factored
    /// system (for `γ = 0`: `min_w ‖y − Xw‖²`, a lower bound of every estimator's RSS),
    /// floored at the rounding level of the computation (`4 n ε` of what `y_{t-1}` leaves
    /// unexplained, plus the rounding of float statistics) so that rounding noise on
    /// noise-free data cannot rank models.
    pub fn rss_min(&self) -> T {
        let rho = self.l[packed(self.n, self.n)];
        let r2 = rho * rho;
        if r2 > self.rss_floor {
            r2
        } else {
            self.rss_floor
        }
    }

    /// Solves `(XᵀX + γD) x = b` in place (`b` of length ≥ `n`, extra entries untouched).
    pub fn solve(&self, b: &mut [T]) {
        if b.len() >= self.n {
            forward(&self.l, self.n, b);
            backward(&self.l, self.n, b);
        }
    }

    /// The regularised least-squares solution `(XᵀX + γD)⁻¹ Xᵀy` (from the factor's
    /// last row, without forming `Xᵀy`).
    pub fn solution(&self) -> [T; PARAMS_MAX] {
        let mut w = [T::ZERO; PARAMS_MAX];
        for (i, wi) in w.iter_mut().enumerate().take(self.n) {
            *wi = self.l[packed(self.n, i)];
        }
        backward(&self.l, self.n, &mut w);
        w
    }

    /// `(XᵀX + γD)⁻¹ (Xᵀy + g x)` in place of `x` (length ≥ `n`), from the factor's last row:
    /// the solution of the factored system with `g x` added to its right-hand side.
    pub(crate) fn solve_shifted(&self, g: T, x: &mut [T]) {
        if x.len() >= self.n {
            forward(&self.l, self.n, x);
            for (i, xi) in x.iter_mut().enumerate().take(self.n) {
                *xi = self.l[packed(self.n, i)] + g * *xi;
            }
            backward(&self.l, self.n, x);
        }
    }

    /// `‖Lᵀ w − l‖²`: how much `w` adds to the residual sum of squares over the
    /// solution of this factor. For a `γ = 0` factor, `RSS(w) = rss_min() + excess(w)`.
    pub fn excess(&self, w: &[T]) -> T {
        let mut e = T::ZERO;
        for i in 0..self.n {
            let mut s = -self.l[packed(self.n, i)];
            for k in i..self.n {
                s += self.l[packed(k, i)] * w.get(k).copied().unwrap_or(T::ZERO);
            }
            e += s * s;
        }
        e
    }

    /// Residual sum of squares `‖y − Xw‖²` of `w` on the factored record (valid for a
    /// `γ = 0` factor), never below [`Factor::rss_min`].
    pub fn rss(&self, w: &[T]) -> T {
        self.rss_min() + self.excess(w)
    }
}
