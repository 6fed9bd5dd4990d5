//! The eigen-decomposition of `B = M Mᵀ` from a square factor `M`, by one-sided (Hestenes)
//! Jacobi on the columns of `M`: what Ridge-M's closed form ([`crate::modal`]) needs.
//!
//! Plane rotations `W` applied to the columns of `M` until every pair is orthogonal give
//! `M W = U Σ`, so `B = U Σ² Uᵀ`: the eigenvalues are the squared column norms and the
//! eigenvectors the normalised columns, without forming `B`. Working on the factor keeps
//! the accuracy of the Cholesky factor the crate computes from exact statistics: one-sided
//! Jacobi finds the eigenvalues of `M Mᵀ` to high relative accuracy (Demmel & Veselić,
//! "Jacobi's method is more accurate than QR", SIAM J. Matrix Anal. Appl. 13, 1992), where a
//! decomposition of `B` formed in floating point would lose its small eigenvalues to
//! rounding of its large entries. One more row, carried along by the same rotations, turns
//! `lᵀ` into `lᵀ W`.
//!
//! Storage: the matrix is dense and column-major, one slot of [`ROWS`] scalars per column
//! (`M`'s rows and the carried row). Up to 12 columns of 13 scalars do not fit one factor's
//! storage (105), and the ATmega2560 has no stack for them: the first [`HEAD_COLS`] columns
//! live in one factor's storage (the search's scratch factor), the others ([`TAIL`] scalars)
//! and the per-mode work space ([`WORK`]) at the front of a second one (the least-squares
//! factor, which its owner factors again afterwards), see [`split`].

use crate::cholesky::packed_len;
use crate::error::{Error, Result};
use crate::real::Real;
use crate::{PARAMS_MAX, P_MAX, Q_MAX};

/// Most columns: the coefficients of the largest structure without its intercept.
pub(crate) const COLS_MAX: usize = P_MAX + Q_MAX;
/// Scalars per column slot: `M`'s rows and the carried row.
pub(crate) const ROWS: usize = COLS_MAX + 1;
/// Scalars of one factor's storage.
pub(crate) const STORAGE: usize = packed_len(PARAMS_MAX + 1);
/// Columns in the first storage.
pub(crate) const HEAD_COLS: usize = STORAGE / ROWS;
/// Scalars of the columns in the second storage.
pub(crate) const TAIL: usize = (COLS_MAX - HEAD_COLS) * ROWS;
/// Scalars of per-mode work space after them: three arrays of [`COLS_MAX`].
pub(crate) const WORK: usize = 3 * COLS_MAX;
const _: () = assert!(HEAD_COLS <= COLS_MAX && HEAD_COLS >= 1);
const _: () = assert!(TAIL + WORK <= STORAGE);

/// Where column `j` lives: in the first storage (`true`) or the second, and its offset there.
pub(crate) const fn slot(j: usize) -> (bool, usize) {
    if j < HEAD_COLS {
        (true, j * ROWS)
    } else {
        (false, (j - HEAD_COLS) * ROWS)
    }
}

/// The second storage cut into the tail columns and the work space.
pub(crate) fn split<T>(second: &mut [T; STORAGE]) -> Option<(&mut [T; TAIL], &mut [T; WORK])> {
    let (tail, rest) = second.split_first_chunk_mut::<TAIL>()?;
    let (work, _) = rest.split_first_chunk_mut::<WORK>()?;
    Some((tail, work))
}

/// Full sweeps over all column pairs before the rotation gives up (the rotations converge
/// quadratically: 4–7 sweeps measured on the pump's normal equations, `f32` and `f64`).
const MAX_SWEEPS: u32 = 30;

/// A dense `(n + 1) × n` matrix, column-major: `M` (rows `0..n`) and a carried row `n`.
pub(crate) struct Columns<'a, T: Real> {
    head: &'a mut [T; STORAGE],
    tail: &'a mut [T; TAIL],
    n: usize,
}

impl<'a, T: Real> Columns<'a, T> {
    /// The matrix of `n` columns whose slots ([`slot`]) hold what `head` and `tail` hold.
    /// [`Error::InvalidStructure`] unless `1 ≤ n ≤ COLS_MAX`.
    pub(crate) fn new(
        head: &'a mut [T; STORAGE],
        tail: &'a mut [T; TAIL],
        n: usize,
    ) -> Result<Self> {
        if n == 0 || n > COLS_MAX {
            return Err(Error::InvalidStructure);
        }
        Ok(Columns { head, tail, n })
    }

    /// Number of columns `n` (and of `M`'s rows).
    pub(crate) fn n(&self) -> usize {
        self.n
    }

    /// Column `j` as an array (in the head or in the tail).
    fn col(&self, j: usize) -> Option<&[T; ROWS]> {
        let s = if j < HEAD_COLS {
            self.head.get(j * ROWS..(j + 1) * ROWS)
        } else {
            let k = j - HEAD_COLS;
            self.tail.get(k * ROWS..(k + 1) * ROWS)
        };
        s.and_then(|s| s.try_into().ok())
    }

    #[cfg(test)]
    fn col_mut(&mut self, j: usize) -> Option<&mut [T; ROWS]> {
        let s = if j < HEAD_COLS {
            self.head.get_mut(j * ROWS..(j + 1) * ROWS)
        } else {
            let k = j - HEAD_COLS;
            self.tail.get_mut(k * ROWS..(k + 1) * ROWS)
        };
        s.and_then(|s| s.try_into().ok())
    }

    /// Columns `p < q` at once, both mutable.
    fn pair_mut(&mut self, p: usize, q: usize) -> Option<(&mut [T; ROWS], &mut [T; ROWS])> {
        if p >= q {
            return None;
        }
        let (x, y) = if q < HEAD_COLS {
            let (lo, hi) = self.head.split_at_mut(q * ROWS);
            (lo.get_mut(p * ROWS..(p + 1) * ROWS)?, hi.get_mut(..ROWS)?)
        } else if p < HEAD_COLS {
            let k = q - HEAD_COLS;
            (
                self.head.get_mut(p * ROWS..(p + 1) * ROWS)?,
                self.tail.get_mut(k * ROWS..(k + 1) * ROWS)?,
            )
        } else {
            let (kp, kq) = (p - HEAD_COLS, q - HEAD_COLS);
            let (lo, hi) = self.tail.split_at_mut(kq * ROWS);
            (lo.get_mut(kp * ROWS..(kp + 1) * ROWS)?, hi.get_mut(..ROWS)?)
        };
        Some((x.try_into().ok()?, y.try_into().ok()?))
    }

    /// Entry `(i, j)` (`i = n`: the carried row); zero outside.
    pub(crate) fn get(&self, i: usize, j: usize) -> T {
        self.col(j)
            .and_then(|c| c.get(i))
            .copied()
            .unwrap_or(T::ZERO)
    }

    /// Sets entry `(i, j)` (ignored outside).
    #[cfg(test)]
    fn set(&mut self, i: usize, j: usize, v: T) {
        if let Some(x) = self.col_mut(j).and_then(|c| c.get_mut(i)) {
            *x = v;
        }
    }

    /// `Σ_{i<n} M_ij²`: the squared norm of column `j` of `M` (the carried row left out).
    pub(crate) fn norm2(&self, j: usize) -> T {
        let mut s = T::ZERO;
        if let Some(c) = self.col(j) {
            for v in c.iter().take(self.n) {
                s += *v * *v;
            }
        }
        s
    }

    /// Rotates the columns until every pair of `M`'s columns is orthogonal to within
    /// `n ε` of the product of their norms (cyclic sweeps by rows; the carried row rotates
    /// along), with `norms` as work space. Calls `progress()` for every pair. Returns
    /// the number of rotations, or [`Error::NonFinite`] when a column norm is not finite or
    /// the sweeps do not converge (which only non-finite data can cause).
    #[inline(never)]
    pub(crate) fn orthogonalise(
        &mut self,
        norms: &mut [T; COLS_MAX],
        progress: &mut impl FnMut(),
    ) -> Result<u32> {
        let n = self.n;
        let tol = T::from_u32(n as u32) * T::EPSILON;
        let tol2 = tol * tol;
        // Beyond this |ζ| = |β − α| / 2|γ|, √(1 + ζ²) is |ζ| in both types (and ζ² finite).
        let large = T::from_f64(1e15);
        let mut rotations = 0u32;
        for _ in 0..MAX_SWEEPS {
            // Fresh norms every sweep; within one, the rotation's exact update below.
            for (j, v) in norms.iter_mut().enumerate().take(n) {
                *v = self.norm2(j);
                if !v.is_finite() {
                    return Err(Error::NonFinite);
                }
            }
            let mut rotated = false;
            for p in 0..n {
                for q in p + 1..n {
                    progress();
                    let (Some(&a), Some(&b)) = (norms.get(p), norms.get(q)) else {
                        continue;
                    };
                    let Some((x, y)) = self.pair_mut(p, q) else {
                        continue;
                    };
                    let mut g = T::ZERO;
                    for (u, v) in x.iter().zip(y.iter()).take(n) {
                        g += *u * *v;
                    }
                    // Orthogonal enough: γ² ≤ tol² α β, written so that nothing overflows
                    // (a zero column gives NaN here: nothing to rotate).
                    let apart = (g / b) * g > tol2 * a;
                    if !apart {
                        continue;
                    }
                    // The rotation [c s; −s c] with t = s / c the smaller root of
                    // t² + 2ζt − 1 = 0 zeroes γ; then α' = α − tγ, β' = β + tγ.
                    let zeta = (b - a) / (g + g);
                    let za = zeta.abs();
                    let root = if za > large {
                        za
                    } else {
                        (T::ONE + zeta * zeta).sqrt()
                    };
                    let mut t = T::ONE / (za + root);
                    if zeta < T::ZERO {
                        t = -t;
                    }
                    let c = T::ONE / (T::ONE + t * t).sqrt();
                    let s = c * t;
                    for (u, v) in x.iter_mut().zip(y.iter_mut()).take(n + 1) {
                        let (xu, yv) = (*u, *v);
                        *u = c * xu - s * yv;
                        *v = s * xu + c * yv;
                    }
                    if let Some(np) = norms.get_mut(p) {
                        *np = a - t * g;
                    }
                    if let Some(nq) = norms.get_mut(q) {
                        *nq = b + t * g;
                    }
                    rotated = true;
                    rotations += 1;
                }
            }
            if !rotated {
                return Ok(rotations);
            }
        }
        Err(Error::NonFinite)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lower-triangular `M` with known `M Mᵀ`: the squared column norms after the rotation
    /// are its eigenvalues, the columns are orthogonal, `M W (M W)ᵀ = M Mᵀ` still holds, and
    /// the carried row is rotated like the others (`‖l‖` and `(M W) (Wᵀ l) = M l` kept).
    #[test]
    fn rotated_columns_give_the_eigenvalues_of_m_mt() {
        // M Mᵀ = Q diag(9, 4, 1) Qᵀ for a known orthogonal Q: take M = Q diag(3, 2, 1) (any
        // factor works; Jacobi only sees the columns).
        let (c, s) = (0.6f64, 0.8f64);
        let q = [
            [c, -s, 0.0],
            [s * 0.6, c * 0.6, -0.8],
            [s * 0.8, c * 0.8, 0.6],
        ];
        let sig = [3.0, 2.0, 1.0];
        let l = [0.5, -1.0, 2.0];
        let (mut head, mut tail) = ([0.0f64; STORAGE], [0.0f64; TAIL]);
        let mut m = Columns::new(&mut head, &mut tail, 3).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                m.set(i, j, q[i][j] * sig[j]);
            }
        }
        // Mix the columns first so that there is something to do.
        let mut mixed = [[0.0; 3]; 3];
        let r = q;
        for i in 0..3 {
            for j in 0..3 {
                mixed[i][j] = (0..3).map(|k| m.get(i, k) * r[k][j]).sum();
            }
        }
        let ml: [f64; 3] = core::array::from_fn(|i| (0..3).map(|j| mixed[i][j] * l[j]).sum());
        for i in 0..3 {
            for j in 0..3 {
                m.set(i, j, mixed[i][j]);
            }
        }
        for j in 0..3 {
            m.set(3, j, l[j]);
        }
        let rotations = m.orthogonalise(&mut [0.0; COLS_MAX], &mut || {}).unwrap();
        assert!(rotations >= 2);
        let mut eig: [f64; 3] = core::array::from_fn(|j| m.norm2(j));
        eig.sort_by(f64::total_cmp);
        for (e, want) in eig.iter().zip([1.0, 4.0, 9.0]) {
            assert!((e - want).abs() < 1e-12, "{eig:?}");
        }
        for p in 0..3 {
            for q2 in p + 1..3 {
                let d: f64 = (0..3).map(|i| m.get(i, p) * m.get(i, q2)).sum();
                assert!(d.abs() < 1e-12);
            }
        }
        let lw: [f64; 3] = core::array::from_fn(|j| m.get(3, j));
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        assert!((norm(&lw) - norm(&l)).abs() < 1e-12);
        for i in 0..3 {
            let got: f64 = (0..3).map(|j| m.get(i, j) * lw[j]).sum();
            assert!((got - ml[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn columns_past_the_first_storage_and_bad_sizes() {
        let (mut head, mut tail) = ([0.0f32; STORAGE], [0.0f32; TAIL]);
        assert!(Columns::new(&mut head, &mut tail, 0).is_err());
        assert!(Columns::new(&mut head, &mut tail, COLS_MAX + 1).is_err());
        let mut m = Columns::new(&mut head, &mut tail, COLS_MAX).unwrap();
        for j in 0..COLS_MAX {
            for i in 0..=COLS_MAX {
                m.set(i, j, (i * 100 + j) as f32);
            }
        }
        for j in 0..COLS_MAX {
            for i in 0..=COLS_MAX {
                assert_eq!(m.get(i, j), (i * 100 + j) as f32);
            }
        }
        assert_eq!(m.get(ROWS, 0), 0.0);
        assert_eq!(m.get(0, COLS_MAX), 0.0);
        // Column j sits where `slot` says.
        for j in 0..COLS_MAX {
            let (first, at) = slot(j);
            let v = if first { head[at + 2] } else { tail[at + 2] };
            assert_eq!(v, (200 + j) as f32);
        }
        let (mut head, mut tail) = ([0.0f32; STORAGE], [0.0f32; TAIL]);
        let mut m = Columns::new(&mut head, &mut tail, 2).unwrap();
        m.set(0, 0, f32::NAN);
        m.set(1, 1, 1.0);
        assert_eq!(
            m.orthogonalise(&mut [0.0; COLS_MAX], &mut || {}),
            Err(Error::NonFinite)
        );
    }
}
