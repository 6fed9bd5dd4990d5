//! [`Refit`]: Ridge-M on a [`Window`]'s statistics, in slices of bounded work.

use crate::cholesky::{self, backward, forward, packed};
use crate::error::{Error, Result};
use crate::estimate::RidgeM;
use crate::gram::Scale;
use crate::model::ArxModel;
use crate::normal::{pivot_tol, Col, Layout};
use crate::real::Real;
use crate::wide::Wide;
use crate::PARAMS_MAX;

use super::window::{Window, WINDOW_LEN_MAX};

/// The most floating-point operations one unit of [`Refit::step`] costs for `n` coefficients
/// (additions, multiplications, divisions and square roots counted alike): the larger of a
/// Ridge-M iterate, `2 n (n − 1) + 2 n + 8 n` (two triangular solves and the update of `w`,
/// the step and the momentum), and the last factor row, `n (n + 1) + n + 1`. 234 for `n = 9`.
pub const fn unit_flops(n: usize) -> usize {
    let iterate = 2 * n * n.saturating_sub(1) + 2 * n + 8 * n;
    let row = n * (n + 1) + n + 1;
    if iterate > row {
        iterate
    } else {
        row
    }
}

/// What one call of [`Refit::step`] ended with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RefitStep<T: Real> {
    /// More work to do: call again.
    Working,
    /// The estimate and the Ridge-M iterates it took (returned again by further calls).
    Done(ArxModel<T>, u32),
    /// No estimate from these statistics (returned again by further calls): the regularised
    /// normal equations are not positive definite ([`Error::NotPositiveDefinite`]) or the
    /// iterates not finite ([`Error::NonFinite`]).
    Refused(Error),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// The snapshot's statistics not taken yet ([`Refit::take_rows`]).
    Snapshot,
    /// Factoring row `row` of the augmented matrix next.
    Factor,
    /// The Ridge solution from the factor's last row.
    Solution,
    /// Ridge-M iterate `iter + 1` next.
    Iterate,
    Done,
    Failed(Error),
}

/// A re-estimate of one structure by Ridge-M ([`RidgeM`], eq. 9–12) on a snapshot of a
/// [`Window`], resumable: [`start`](Self::start) copies the statistics (in physical units,
/// `γ` added), then each [`step`](Self::step) does at most `units` units of work, each at most
/// [`unit_flops`]`(n)` floating-point operations:
///
/// - one row of the Cholesky factor of `[XᵀX + γD, Xᵀy; yᵀX, yᵀy]` (`n + 1` rows),
/// - the Ridge solution (one back substitution),
/// - one Ridge-M iterate (two triangular solves), at most `max_iter`.
///
/// The arithmetic is the same whatever the slicing (the state between units is all there is),
/// so the result is bit-identical to one call with an unlimited budget (tested), and it is
/// [`RidgeM::iterate`]'s iteration on the same statistics (the same formulas in the same order;
/// the crate's other paths eliminate `y_{t−1}` first, so they agree to rounding, tested).
/// The window keeps accumulating while the fit runs: it works on its snapshot.
///
/// Memory: 105 + 4 × 13 scalars and the settings, whatever the structure (720 bytes in `f32` on
/// a 64-bit host).
#[derive(Debug, Clone)]
pub struct Refit<T: Real> {
    layout: Layout,
    method: RidgeM<T>,
    /// The augmented matrix, then its factor, packed.
    a: [T; WINDOW_LEN_MAX],
    w_ridge: [T; PARAMS_MAX],
    w: [T; PARAMS_MAX],
    w_prev: [T; PARAMS_MAX],
    v: [T; PARAMS_MAX],
    row: u8,
    iter: u32,
    stage: Stage,
    /// RMS of the target about its mean over the window (about 0 without an intercept).
    response: T,
    /// RMS of the input column `u_{t−d}` about its mean (about 0 without an intercept).
    input_response: T,
    weight: u32,
}

impl<T: Real> Refit<T> {
    /// Takes a snapshot of `window` (counts, turned into physical units by `scale`) for
    /// `method`. One unit of work of its own: `(n + 1)(n + 2) / 2` conversions and two
    /// products each, the window's response (one exact 128-bit product) and a square root.
    /// The same as [`begin`](Self::begin), [`take_rows`](Self::take_rows) and
    /// [`take_responses`](Self::take_responses) on the same window, bit for bit.
    ///
    /// Errors: [`Error::InvalidParameter`] for `method` ([`RidgeM::check`]),
    /// [`Error::TooShort`] when the window holds fewer weighted rows than `2 (n + 1)`.
    pub fn start(window: &Window<'_>, method: RidgeM<T>, scale: &Scale) -> Result<Self> {
        let layout = checked(window, &method)?;
        // Built here and moved once: through `begin` it took 20 k cycles and 1.2 KB of stack
        // more on the ATmega2560 (the 700-byte value moved twice).
        let mut a = [T::ZERO; WINDOW_LEN_MAX];
        convert(&mut a, &layout, &method, window, scale);
        let (response, input_response) = responses(&layout, window, scale);
        Ok(Refit {
            layout,
            method,
            a,
            w_ridge: [T::ZERO; PARAMS_MAX],
            w: [T::ZERO; PARAMS_MAX],
            w_prev: [T::ZERO; PARAMS_MAX],
            v: [T::ZERO; PARAMS_MAX],
            row: 0,
            iter: 0,
            stage: Stage::Factor,
            response,
            input_response,
            weight: window.weight(),
        })
    }

    /// A fit of `window`'s structure whose snapshot is taken in two parts, for a caller that
    /// spreads the work over ticks: [`take_rows`](Self::take_rows) (the statistics), then
    /// [`take_responses`](Self::take_responses) (the output's and input's RMS), both of the
    /// same window, unchanged in between and since this call (the caller holds the window's
    /// updates back meanwhile). [`step`](Self::step) does no work before the rows are taken;
    /// the responses are needed only once it says [`RefitStep::Done`]. The checks of
    /// [`start`](Self::start) and its errors; nothing is converted yet. The parts compute
    /// what [`start`](Self::start) does, bit for bit (the same functions).
    pub fn begin(window: &Window<'_>, method: RidgeM<T>) -> Result<Self> {
        let layout = checked(window, &method)?;
        Ok(Refit {
            layout,
            method,
            a: [T::ZERO; WINDOW_LEN_MAX],
            w_ridge: [T::ZERO; PARAMS_MAX],
            w: [T::ZERO; PARAMS_MAX],
            w_prev: [T::ZERO; PARAMS_MAX],
            v: [T::ZERO; PARAMS_MAX],
            row: 0,
            iter: 0,
            stage: Stage::Snapshot,
            response: T::ZERO,
            input_response: T::ZERO,
            weight: window.weight(),
        })
    }

    /// The first part of the snapshot: `window`'s statistics (counts, turned into physical
    /// units by `scale`, `γ` added), `(n + 1)(n + 2) / 2` conversions and two products each.
    /// The fit's units may run from then on. Does nothing once taken.
    ///
    /// Errors: [`Error::InvalidStructure`] when `window` is not of this fit's structure, or
    /// has not the weight it had at [`begin`](Self::begin).
    pub fn take_rows(&mut self, window: &Window<'_>, scale: &Scale) -> Result<()> {
        self.same_window(window)?;
        if self.stage != Stage::Snapshot {
            return Ok(());
        }
        convert(&mut self.a, &self.layout, &self.method, window, scale);
        self.stage = Stage::Factor;
        Ok(())
    }

    /// The second part of the snapshot: the output's and the newest input's RMS about their
    /// means over `window` ([`response`](Self::response),
    /// [`input_response`](Self::input_response); zero before): one exact 128-bit product and
    /// a square root each.
    ///
    /// Errors: as [`take_rows`](Self::take_rows).
    pub fn take_responses(&mut self, window: &Window<'_>, scale: &Scale) -> Result<()> {
        self.same_window(window)?;
        (self.response, self.input_response) = responses(&self.layout, window, scale);
        Ok(())
    }

    /// `window` is the one this fit began with, as far as it can tell: the structure, the
    /// offset and the weight.
    fn same_window(&self, window: &Window<'_>) -> Result<()> {
        let l = window.layout();
        if l.structure != self.layout.structure
            || l.offset != self.layout.offset
            || window.weight() != self.weight
        {
            return Err(Error::InvalidStructure);
        }
        Ok(())
    }

    /// The RMS deviation of the output from its mean over the window's rows (weighted as the
    /// statistics are), output units; about zero without an intercept.
    pub fn response(&self) -> T {
        self.response
    }

    /// The RMS deviation of the input `u_{t−d}` from its mean over the window's rows (weighted),
    /// input units; about zero without an intercept. In closed loop the output's spread is
    /// also the sensor's noise fed back, the input's follows what excites the loop.
    pub fn input_response(&self) -> T {
        self.input_response
    }

    /// The window's weighted rows at the snapshot.
    pub fn weight(&self) -> u32 {
        self.weight
    }

    /// Does at most `units` units of work (0: none) and says where the fit stands.
    pub fn step(&mut self, units: u32) -> RefitStep<T> {
        let mut left = units;
        while left > 0 {
            match self.stage {
                Stage::Snapshot | Stage::Done | Stage::Failed(_) => break,
                Stage::Factor => self.factor_row(),
                Stage::Solution => self.solution(),
                Stage::Iterate => self.iterate(),
            }
            left -= 1;
        }
        self.outcome()
    }

    /// Where the fit stands, with no work: what the last [`step`](Self::step) returned.
    pub fn outcome(&self) -> RefitStep<T> {
        match self.stage {
            Stage::Done => RefitStep::Done(ArxModel::from_layout(&self.layout, &self.w), self.iter),
            Stage::Failed(e) => RefitStep::Refused(e),
            _ => RefitStep::Working,
        }
    }

    /// Runs to the end: [`step`](Self::step) with an unlimited budget.
    pub fn finish(&mut self) -> RefitStep<T> {
        self.step(u32::MAX)
    }

    /// Row `row` of the factor: Cholesky–Banachiewicz, the arithmetic of the crate's
    /// factorisation (`first = 0`; the target row's pivot clamped at zero, a regressor's
    /// refused at or below the relative tolerance of every normal-equation factor).
    fn factor_row(&mut self) {
        let n = self.layout.len;
        let i = usize::from(self.row);
        match factor_row(&mut self.a, i, n, pivot_tol()) {
            Err(e) => self.stage = Stage::Failed(e),
            Ok(()) if i >= n => self.stage = Stage::Solution,
            Ok(()) => self.row += 1,
        }
    }

    /// `w_ridge = (XᵀX + γD)⁻¹ Xᵀy` from the factor's last row (as [`crate::Factor::solution`]).
    fn solution(&mut self) {
        let n = self.layout.len;
        let mut w = [T::ZERO; PARAMS_MAX];
        for (i, wi) in w.iter_mut().enumerate().take(n) {
            *wi = self.a[packed(n, i)];
        }
        backward(&self.a, n, &mut w);
        self.w_ridge = w;
        self.stage = Stage::Iterate;
    }

    /// One Ridge-M iterate, as [`RidgeM::iterate`] writes it:
    /// `w = w_ridge + γ A⁻¹ D v`, `v ← β v + (1 − β) w`, stop when `‖Δw‖ < ε`.
    fn iterate(&mut self) {
        let n = self.layout.len;
        let m = self.method;
        let mut x = self.v;
        if let Some(i) = self.layout.intercept() {
            x[i] = T::ZERO;
        }
        forward(&self.a, n, &mut x);
        backward(&self.a, n, &mut x);
        let mut step = T::ZERO;
        for i in 0..n {
            self.w[i] = self.w_ridge[i] + m.gamma * x[i];
            let dw = self.w[i] - self.w_prev[i];
            step += dw * dw;
            self.v[i] = m.beta * self.v[i] + (T::ONE - m.beta) * self.w[i];
        }
        self.iter += 1;
        if !self.w[..n].iter().all(|w| w.is_finite()) {
            self.stage = Stage::Failed(Error::NonFinite);
        } else if step.sqrt() < m.tol || self.iter >= m.max_iter {
            self.stage = Stage::Done;
        } else {
            self.w_prev = self.w;
        }
    }
}

/// The checks of [`Refit::start`] and [`Refit::begin`]: `method`, and the window's weight for
/// its structure; the window's layout.
fn checked<T: Real>(window: &Window<'_>, method: &RidgeM<T>) -> Result<Layout> {
    method.check()?;
    let layout = *window.layout();
    let needed = 2 * (layout.len as u32 + 1);
    if window.weight() < needed {
        return Err(Error::TooShort {
            needed,
            have: window.weight(),
        });
    }
    Ok(layout)
}

/// The packed augmented matrix `a` from `window`'s statistics in physical units (`scale`),
/// `γ` on the regressors' diagonal but the intercept's.
fn convert<T: Real>(
    a: &mut [T; WINDOW_LEN_MAX],
    layout: &Layout,
    method: &RidgeM<T>,
    window: &Window<'_>,
    scale: &Scale,
) {
    let n = layout.len;
    let su = T::from_f64(scale.u);
    let sy = T::from_f64(scale.y);
    let unit = |i: usize| match layout.cols.get(i) {
        _ if i == n => sy,
        Some(Col::Y(_)) => sy,
        Some(Col::U(_)) => su,
        _ => T::ONE,
    };
    let intercept = layout.intercept();
    for i in 0..=n {
        let si = unit(i);
        for j in 0..=i {
            let mut x = T::from_i64(window.entry(i, j)) * (si * unit(j));
            if i == j && i < n && intercept != Some(i) {
                x += method.gamma;
            }
            if let Some(slot) = a.get_mut(packed(i, j)) {
                *slot = x;
            }
        }
    }
}

/// The output's and the newest input's RMS about their means over `window`, in physical units
/// (`scale`; the input's zero without an input column).
fn responses<T: Real>(layout: &Layout, window: &Window<'_>, scale: &Scale) -> (T, T) {
    let n = layout.len;
    let intercept = layout.intercept();
    let response = column_rms::<T>(window, n, intercept) * T::from_f64(scale.y);
    let first_input = layout
        .cols
        .iter()
        .take(n)
        .position(|c| matches!(c, Col::U(_)));
    let input_response = match first_input {
        Some(k) => column_rms::<T>(window, k, intercept) * T::from_f64(scale.u),
        None => T::ZERO,
    };
    (response, input_response)
}

/// The RMS of column `k` of `window` about its mean, in counts: with the intercept column `c`,
/// `√(N Σx² − (Σx)²) / N` from the exact statistics (`N Σx² − (Σx)²` in the crate's byte-wise
/// 128-bit arithmetic: no `i128` on the ATmega2560); without one, `√(Σx² / weight)`.
fn column_rms<T: Real>(window: &Window<'_>, k: usize, intercept: Option<usize>) -> T {
    match intercept {
        Some(c) => {
            let count = window.entry(c, c);
            let sum = window.entry(k, c);
            let sq = window.entry(k, k);
            let mut spread = Wide::product(&count, &sq);
            spread.sub_product(&sum, &sum);
            if count > 0 && !spread.is_negative() && !spread.is_zero() {
                let var = spread.to_real::<T>() / (T::from_i64(count) * T::from_i64(count));
                var.sqrt()
            } else {
                T::ZERO
            }
        }
        None => (T::from_i64(window.entry(k, k)) / T::from_u32(window.weight().max(1))).sqrt(),
    }
}

/// Row `i` of the Cholesky factor of the packed `(n + 1) × (n + 1)` matrix `a` in place, rows
/// `0..i` already factored; the same operations in the same order as the crate's
/// `factor_in_place(a, n + 1, 0, n, tol)` does for that row.
fn factor_row<T: Real>(a: &mut [T], i: usize, n: usize, tol: T) -> Result<()> {
    if i > n || a.len() < packed(i, i) + 1 {
        return Err(Error::InvalidStructure);
    }
    cholesky::factor_row(a, i, 0, n, tol)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cholesky::{factor_in_place, packed_len};

    #[test]
    fn rows_one_at_a_time_are_the_crates_factorisation_bit_for_bit() {
        // A = M Mᵀ + diag, 6 × 6, with an augmented last row.
        let n = 5;
        let mut a = [0.0f32; packed_len(6)];
        for i in 0..=n {
            for j in 0..=i {
                let m = |r: usize, k: usize| ((r * 7 + k * 3) % 11) as f32 * 0.37 - 1.1;
                let mut s: f32 = (0..6).map(|k| m(i, k) * m(j, k)).sum();
                if i == j {
                    s += 0.5;
                }
                a[packed(i, j)] = s;
            }
        }
        let mut whole = a;
        factor_in_place(&mut whole, n + 1, 0, n, pivot_tol()).unwrap();
        let mut rows = a;
        for i in 0..=n {
            factor_row(&mut rows, i, n, pivot_tol::<f32>()).unwrap();
        }
        assert_eq!(whole.map(f32::to_bits), rows.map(f32::to_bits));
        // A singular regressor block is refused like the crate's.
        let mut sing = [1.0f32, 1.0, 1.0, 0.0, 0.0, 1.0];
        assert_eq!(factor_row(&mut sing, 0, 2, pivot_tol()), Ok(()));
        assert_eq!(
            factor_row(&mut sing, 1, 2, pivot_tol()),
            Err(Error::NotPositiveDefinite)
        );
    }
}
