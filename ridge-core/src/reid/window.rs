//! [`Window`]: the exact statistics of one ARX structure over a window of breaths, in
//! borrowed storage.

use crate::cholesky::{packed, packed_len};
use crate::error::{Error, Result};
use crate::normal::{Col, Layout};
use crate::structure::{Offset, Structure};
use crate::{L_MAX, PARAMS_MAX, P_MAX};

/// Entries of the largest window: the packed `(PARAMS_MAX + 1)²` matrix (105 `i64`).
pub const WINDOW_LEN_MAX: usize = packed_len(PARAMS_MAX + 1);

/// Entries a [`Window`] of `params` coefficients needs: the packed symmetric matrix of the
/// regressors and the target, `(params + 1)(params + 2) / 2` (55 for 9 coefficients:
/// 440 bytes of `i64`).
pub const fn window_len(params: usize) -> usize {
    packed_len(params + 1)
}

/// Largest diagonal entry before an update is refused ([`Error::Overflow`]): one more row adds
/// at most `2³⁰` to any entry of samples within `i16`, so every entry stays within `i64`
/// (off-diagonal entries are bounded by the diagonal ones, `|g_ij| ≤ √(g_ii g_jj)`).
const DIAGONAL_MAX: i64 = i64::MAX - (1 << 32);

/// The exact statistics `Σ λ^{b(t)} z_t z_tᵀ` of one structure's regressor row and target
/// `z_t = [y_{t-1}, (1), y_{t-2} … y_{t-p}, u_{t-d} … u_{t-d-q+1}, y_t]` (the internal order of
/// [`crate::System`]), with `b(t)` the number of breaths since sample `t`.
///
/// - Samples are integer counts in `i16` (SFM3300 words minus 32768, duty or map counts); the
///   caller may subtract an operating point first (with an intercept that changes nothing but
///   the size of the sums). Products are exact (`i32`), sums exact (`i64`).
/// - One [`push`](Self::push) per tick: one rank-1 update, `(n + 1)(n + 2) / 2` products and
///   `i64` additions for `n` coefficients (55 of each for `n = 9`).
/// - [`end_breath`](Self::end_breath) once per breath forgets: every entry `g ← g − (g >> k)`,
///   `λ = 1 − 2^{−k}` per breath (`k = 0`: nothing is forgotten). The window is then about
///   `2^k` breaths long (the weights sum to `1 / (1 − λ)` breaths). The shift truncates by less
///   than one count² per entry per breath.
/// - The first `m = max(p, d + q − 1)` samples only fill the lag history (measured initial
///   conditions, no zero padding), as after [`clear`](Self::clear).
///
/// Storage: `window_len(n)` entries borrowed from the caller (e.g. buffers of the power-up
/// search that are idle in run mode), plus the lag history, counts and structure (104 bytes on
/// a 64-bit host).
#[derive(Debug)]
pub struct Window<'a> {
    /// The structure, the lag history and the counts (all but the storage).
    state: WindowState,
    gram: &'a mut [i64],
}

/// A [`Window`] without its storage ([`Window::detach`]): the structure, the lag history and
/// the counts, so that a caller can keep a window beside the storage it lends (a struct cannot
/// hold both a buffer and a borrow of it) and [`Window::attach`] it again for each update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowState {
    layout: Layout,
    /// `y[k − 1] = y_{t−k}` before the sample `t` is taken.
    y: [i16; P_MAX],
    /// `u[k] = u_{t−k}` once `u_t` is taken.
    u: [i16; L_MAX],
    /// Samples taken into the lag history so far, up to the seed length.
    seeded: u8,
    seed: u8,
    /// Rows accumulated since the last clear (not weighted).
    rows: u32,
    /// Rows accumulated, forgotten as the entries are.
    weight: u32,
    shift: u8,
}

impl<'a> Window<'a> {
    /// A window for `structure` with `offset` in `storage` (at least
    /// [`window_len`]`(n)` entries; it is zeroed), forgetting `λ = 1 − 2^{−shift}` per breath
    /// (`shift` 0: nothing forgotten; at most 16).
    ///
    /// Errors: [`Error::InvalidStructure`] for a structure outside the maxima or storage too
    /// small, [`Error::InvalidParameter`] for `shift > 16`.
    pub fn new(
        structure: Structure,
        offset: Offset,
        shift: u8,
        storage: &'a mut [i64],
    ) -> Result<Self> {
        structure.check()?;
        if shift > 16 {
            return Err(Error::InvalidParameter);
        }
        let layout = Layout::new(structure, offset);
        if storage.len() < window_len(layout.len) {
            return Err(Error::InvalidStructure);
        }
        let mut w = Window {
            state: WindowState {
                layout,
                y: [0; P_MAX],
                u: [0; L_MAX],
                seeded: 0,
                // ≤ D_MAX + Q_MAX − 1 = 11.
                seed: structure.seed_len() as u8,
                rows: 0,
                weight: 0,
                shift,
            },
            gram: storage,
        };
        w.clear();
        Ok(w)
    }

    /// The window without its storage; the statistics stay in the storage, unchanged.
    pub fn detach(self) -> WindowState {
        self.state
    }

    /// The window `state` again, on `storage` (which must hold what the window had when it was
    /// detached: nothing is zeroed).
    ///
    /// Errors: [`Error::InvalidStructure`] when `storage` is shorter than the structure needs.
    pub fn attach(state: WindowState, storage: &'a mut [i64]) -> Result<Self> {
        if storage.len() < window_len(state.layout.len) {
            return Err(Error::InvalidStructure);
        }
        Ok(Window {
            state,
            gram: storage,
        })
    }

    /// Forgets everything, lag history included.
    pub fn clear(&mut self) {
        for g in self.gram.iter_mut() {
            *g = 0;
        }
        self.state.seeded = 0;
        self.state.rows = 0;
        self.state.weight = 0;
    }

    /// Restarts the lag history and keeps the statistics: the next `m = max(p, d + q − 1)`
    /// samples only fill the lag history again (as after [`clear`](Self::clear)), so that no row
    /// spans the gap. For a window fed with segments of the record only (e.g. each breath's
    /// inspiration, the exhalation valve closed): call it before each segment's first sample;
    /// every row then holds samples of one segment. Nothing else changes (entries, rows,
    /// weight, forgetting).
    pub fn restart_lags(&mut self) {
        self.state.seeded = 0;
    }

    /// Takes one sample: `u_t`, the input applied during the interval that ends with the
    /// reading `y_t` (counts). Once the lag history is full, adds the row `z_t zᵀ_t`.
    ///
    /// Errors: [`Error::Overflow`] when a diagonal entry is too large for another row (never
    /// with forgetting: the entries stay below `2^{30+k}` rows' worth); nothing is changed
    /// then but the lag history.
    pub fn push(&mut self, u: i16, y: i16) -> Result<()> {
        self.state.u.copy_within(0..L_MAX - 1, 1);
        self.state.u[0] = u;
        let result = if self.state.seeded >= self.state.seed {
            self.add_row(y)
        } else {
            self.state.seeded += 1;
            Ok(())
        };
        self.state.y.copy_within(0..P_MAX - 1, 1);
        self.state.y[0] = y;
        result
    }

    /// The value of column `c` in the current row (target: `y`).
    fn value(&self, c: Col, y: i16) -> i16 {
        match c {
            Col::Y(0) => y,
            Col::Y(k) => self.state.y.get(usize::from(k) - 1).copied().unwrap_or(0),
            Col::U(k) => self.state.u.get(usize::from(k)).copied().unwrap_or(0),
            Col::One => 1,
        }
    }

    fn add_row(&mut self, y: i16) -> Result<()> {
        let n = self.state.layout.len;
        let mut z = [0i16; PARAMS_MAX + 1];
        for (slot, c) in z.iter_mut().zip(self.state.layout.cols.iter()).take(n) {
            *slot = self.value(*c, y);
        }
        z[n] = y;
        // Diagonal (i, i) sits at i (i + 3) / 2 in packed order.
        let mut at = 0;
        for i in 0..=n {
            if self.gram.get(at).is_none_or(|&g| g > DIAGONAL_MAX) {
                return Err(Error::Overflow);
            }
            at += i + 2;
        }
        // Entries in packed order, (0, 0), (1, 0), (1, 1), …: one pass, no index arithmetic.
        let mut entries = self.gram.iter_mut();
        for i in 0..=n {
            let zi = i32::from(z[i]);
            for &zj in &z[..=i] {
                if let Some(g) = entries.next() {
                    // A 16 × 16 → 32-bit product (|z_i z_j| ≤ 2³⁰), then one i64 addition: on
                    // the ATmega2560 a 64-bit product per entry made the update 30 k cycles.
                    *g += i64::from(zi * i32::from(zj));
                }
            }
        }
        self.state.rows = self.state.rows.saturating_add(1);
        self.state.weight = self.state.weight.saturating_add(1);
        Ok(())
    }

    /// The breath boundary: forgets `2^{−k}` of everything accumulated so far (see the type's
    /// docs). `(n + 1)(n + 2) / 2` shifts and subtractions.
    pub fn end_breath(&mut self) {
        if self.state.shift == 0 {
            return;
        }
        let k = u32::from(self.state.shift);
        for g in self.gram.iter_mut() {
            *g -= *g >> k;
        }
        self.state.weight -= self.state.weight >> k;
    }

    /// Number of coefficients `n`.
    pub fn params(&self) -> usize {
        self.state.layout.len
    }

    /// The structure.
    pub fn structure(&self) -> Structure {
        self.state.layout.structure
    }

    /// The offset choice.
    pub fn offset(&self) -> Offset {
        self.state.layout.offset
    }

    /// The forgetting shift `k` (`λ = 1 − 2^{−k}` per breath).
    pub fn shift(&self) -> u8 {
        self.state.shift
    }

    /// Rows accumulated since the last clear.
    pub fn rows(&self) -> u32 {
        self.state.rows
    }

    /// Rows accumulated, weighted as the entries are (the window's effective length).
    pub fn weight(&self) -> u32 {
        self.state.weight
    }

    /// Entry `(i, j)` of the statistics in internal order (index `n`: the target), counts²;
    /// 0 outside.
    pub fn entry(&self, i: usize, j: usize) -> i64 {
        let n = self.state.layout.len;
        if i > n || j > n {
            return 0;
        }
        let (a, b) = if i >= j { (i, j) } else { (j, i) };
        self.gram.get(packed(a, b)).copied().unwrap_or(0)
    }

    pub(crate) fn layout(&self) -> &Layout {
        &self.state.layout
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_that_could_overflow_is_refused_and_changes_nothing() {
        let s = Structure::new(1, 1, 0).unwrap();
        let mut store = [0i64; WINDOW_LEN_MAX];
        let mut w = Window::new(s, Offset::None, 0, &mut store).unwrap();
        w.push(3, 4).unwrap(); // seeds y_{t−1}
        w.push(5, 6).unwrap();
        // Rows [y_{t−1}, u_t, y_t] = [4, 5, 6].
        assert_eq!((w.entry(0, 0), w.entry(1, 0), w.entry(2, 2)), (16, 20, 36));
        w.gram[packed(1, 1)] = DIAGONAL_MAX + 1;
        let before: [i64; 6] = core::array::from_fn(|k| w.gram[k]);
        assert_eq!(w.push(7, 8), Err(Error::Overflow));
        assert_eq!(before, core::array::from_fn(|k| w.gram[k]));
        assert_eq!(w.rows(), 1);
        // At the limit itself the row is still taken, and the largest row fits in i64.
        w.gram[packed(1, 1)] = DIAGONAL_MAX;
        assert_eq!(w.push(i16::MIN, i16::MIN), Ok(()));
        assert_eq!(w.entry(1, 1), DIAGONAL_MAX + (1 << 30));
    }
}
