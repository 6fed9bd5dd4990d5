//! A small Cholesky factorisation on packed lower-triangular storage.
//!
//! Sizes here are at most 14 × 14, so a row-oriented (Cholesky–Banachiewicz) loop on
//! a packed array is smaller and faster on an 8-bit MCU than a general matrix library.
//! Measured on the ATmega2560 (16 MHz, simavr; `scripts/avr-bench`, figures and method in
//! `docs/hand-written.md`), factor + solve of an `f32` system against nalgebra 0.35's
//! `Cholesky` on an `SMatrix`: 206 k vs 280 k cycles and 442 B vs 1.3 KB of stack for
//! 12 × 12, 251 k vs 330 k cycles and 442 B vs 1.5 KB for 13 × 13; 2.5 vs 2.7 KB of code
//! (nalgebra: per matrix size, as its size is a type parameter; here `n` is a run-time value).
//!
//! Element `(i, j)`, `j ≤ i`, lives at `i (i + 1) / 2 + j`.

use crate::error::{Error, Result};
use crate::real::Real;

/// Index of element `(i, j)` (`j ≤ i`) in packed lower-triangular storage.
#[inline]
pub(crate) const fn packed(i: usize, j: usize) -> usize {
    i * (i + 1) / 2 + j
}

/// Number of packed elements of an `n × n` symmetric matrix.
pub(crate) const fn packed_len(n: usize) -> usize {
    n * (n + 1) / 2
}

/// Factors the leading `n × n` block of the packed symmetric matrix `a` in place into
/// `L` with `L Lᵀ = A`. Rows and columns before `first` must already hold their factor
/// and the trailing block the matrix *after* their elimination (its Schur complement);
/// `first = 0` factors the whole matrix.
///
/// Rows `0..strict` must have pivots above `tol · a_ii` (relative to the original
/// diagonal), or [`Error::NotPositiveDefinite`] is returned; rows from `strict` on (the
/// augmented right-hand side of a least-squares problem) have their pivot clamped at
/// zero instead, as a zero residual is legitimate there.
pub(crate) fn factor_in_place<T: Real>(
    a: &mut [T],
    n: usize,
    first: usize,
    strict: usize,
    tol: T,
) -> Result<()> {
    if a.len() < packed_len(n) {
        return Err(Error::InvalidStructure);
    }
    for i in first..n {
        factor_row(a, i, first, strict, tol)?;
    }
    Ok(())
}

/// Row `i` of [`factor_in_place`]: factors it in place, rows `first..i` already factored (the
/// same pivot rule: rows before `strict` strict, later ones clamped at zero). The caller
/// checks that `a` holds row `i` (`packed_len(i + 1)` elements).
#[inline(always)]
pub(crate) fn factor_row<T: Real>(
    a: &mut [T],
    i: usize,
    first: usize,
    strict: usize,
    tol: T,
) -> Result<()> {
    for j in first..=i {
        let mut s = a[packed(i, j)];
        for k in first..j {
            s -= a[packed(i, k)] * a[packed(j, k)];
        }
        if i == j {
            let diag = a[packed(i, i)];
            if !s.is_finite() {
                return Err(Error::NotPositiveDefinite);
            }
            let d = if i < strict {
                if s <= tol * diag || s <= T::ZERO {
                    return Err(Error::NotPositiveDefinite);
                }
                s.sqrt()
            } else if s > T::ZERO {
                s.sqrt()
            } else {
                T::ZERO
            };
            a[packed(i, i)] = d;
        } else {
            let v = s / a[packed(j, j)];
            if !v.is_finite() {
                return Err(Error::NotPositiveDefinite);
            }
            a[packed(i, j)] = v;
        }
    }
    Ok(())
}

/// Solves `L x = b` in place (forward substitution) with the leading `n × n` block of
/// the packed factor `l`.
pub(crate) fn forward<T: Real>(l: &[T], n: usize, x: &mut [T]) {
    for i in 0..n {
        let mut s = x[i];
        for k in 0..i {
            s -= l[packed(i, k)] * x[k];
        }
        x[i] = s / l[packed(i, i)];
    }
}

/// Solves `Lᵀ x = b` in place (back substitution) with the leading `n × n` block.
pub(crate) fn backward<T: Real>(l: &[T], n: usize, x: &mut [T]) {
    for i in (0..n).rev() {
        let mut s = x[i];
        for k in i + 1..n {
            s -= l[packed(k, i)] * x[k];
        }
        x[i] = s / l[packed(i, i)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_and_solves_a_known_spd_matrix() {
        // A = M Mᵀ with M lower triangular [[2,0,0],[1,3,0],[-1,2,1]]: the factor is M.
        let m = [[2.0, 0.0, 0.0], [1.0, 3.0, 0.0], [-1.0, 2.0, 1.0]];
        let mut a = [0.0f64; 6];
        for i in 0..3 {
            for j in 0..=i {
                a[packed(i, j)] = (0..3).map(|k| m[i][k] * m[j][k]).sum();
            }
        }
        factor_in_place(&mut a, 3, 0, 3, 1e-12).unwrap();
        for i in 0..3 {
            for j in 0..=i {
                assert!((a[packed(i, j)] - m[i][j]).abs() < 1e-12);
            }
        }
        // Solve A x = A·[1,2,3]ᵀ.
        let x_true = [1.0, 2.0, 3.0];
        let mut b = [0.0; 3];
        for i in 0..3 {
            for j in 0..3 {
                let mi: f64 = (0..3).map(|k| m[i][k] * m[j][k]).sum();
                b[i] += mi * x_true[j];
            }
        }
        forward(&a, 3, &mut b);
        backward(&a, 3, &mut b);
        for i in 0..3 {
            assert!((b[i] - x_true[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn singular_matrix_is_an_error_not_a_panic() {
        // Rank one: [[1,1],[1,1]].
        let mut a = [1.0f32, 1.0, 1.0];
        assert_eq!(
            factor_in_place(&mut a, 2, 0, 2, 1e-6),
            Err(Error::NotPositiveDefinite)
        );
        let mut nan = [f32::NAN, 0.0, 1.0];
        assert_eq!(
            factor_in_place(&mut nan, 2, 0, 2, 1e-6),
            Err(Error::NotPositiveDefinite)
        );
        // A zero last pivot is allowed on the augmented row.
        let mut aug = [1.0f64, 1.0, 1.0];
        factor_in_place(&mut aug, 2, 0, 1, 1e-12).unwrap();
        assert_eq!(aug[2], 0.0);
    }
}
