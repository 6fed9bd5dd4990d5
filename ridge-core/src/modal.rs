//! Ridge-M (eq. 9–12) in the eigenbasis of the normal equations: the iterates of
//! [`RidgeM`], their stopping rule and the last iterate at a cost of `O(n)` per iterate
//! instead of two triangular solves, after one eigen-decomposition ([`crate::eigen`]).
//!
//! # One mode at a time
//! Without an intercept, let `XᵀX = U Λ Uᵀ`, so `A = XᵀX + γI = U (Λ + γ) Uᵀ`, and write
//! `ω = Uᵀ w`, `ν = Uᵀ v`, `z = Uᵀ Xᵀy`. Each mode `i` (`μ_i = λ_i + γ`) iterates on its own:
//!
//! ```text
//! ω_{k+1} = (z + γ ν_k) / μ,   ν_{k+1} = ρ ν_k + s,   ρ = β + (1 − β) γ / μ,   s = (1 − β) z / μ
//! ```
//!
//! From `v_0 = w_0 = 0` the first iterate is the Ridge solution `ω_1 = z / μ`, and the steps
//! after it are geometric: `Δω_2 = (ρ − β) ω_1 =: a`, `Δω_{k+1} = ρ Δω_k`. Hence
//!
//! ```text
//! ω_K = ω_1 + a G_{K−1},   G_j = 1 + ρ + … + ρ^{j−1}
//! ‖w_k − w_{k−1}‖² = Σ_i a_i² ρ_i^{2(k−2)}   (k ≥ 2)
//! ```
//!
//! The momentum is `ν_k = s G_k`.
//!
//! # The intercept
//! The intercept `c` is not regularised. Eliminating it, `w_S = B⁻¹ (b̃ + γ v_S)` with
//! `B = A_SS − a aᵀ / a_cc = G̃ + γI` (`G̃`: the Gram of the centred regressors,
//! `a = A_Sc`) and `b̃ = b_S − a b_c / a_cc`, and `w_c = (b_c − aᵀ w_S) / a_cc`. So the
//! other coefficients follow the intercept-free iteration on `(G̃, b̃)`, and the intercept
//! moves by `Δw_c = −(a / a_cc)ᵀ Δw_S = −gᵀ Δω` with `g = Uᵀ a / a_cc`: the step is
//! `‖Δw‖² = Σ Δω_i² + (Σ g_i Δω_i)²`, still `O(n)` per iterate.
//!
//! # From the least-squares factor
//! Everything comes from the factor `[L 0; lᵀ ρ]` of the candidate's augmented normal
//! equations at `γ = 0` (`L Lᵀ = XᵀX`, `L l = Xᵀy`), which the search holds anyway. Without
//! an intercept `M = L`. With one (position 1 of the internal order), the rotation of `L`'s
//! first two columns that turns the intercept's row `(l₁₀, l₁₁)` into `(0, r)` leaves the
//! other rows as a factor of `G̃`: `M Mᵀ = G̃`, where `M` is those rows without the column
//! along the intercept's row, whose entries are `a / r` (`r² = a_cc`). The augmented row
//! rotated alike is `l̃` with `M l̃ = b̃`. One-sided Jacobi gives `M W = U Σ` (`Σ² = Λ`) and
//! `Wᵀ l̃`, so `z = Σ Wᵀ l̃`, and nothing below divides by `σ`: with
//! `â_i = a_i / σ_i = (ρ_i − β) (Wᵀ l̃)_i / μ_i`,
//!
//! ```text
//! ‖Δw_k‖² = Σ_i (σ_i â_i)² ρ_i^{2(k−2)} + (Σ_i h_i ρ_i^{k−2})²,   h_i = â_i (M W)_iᵀ a / a_cc
//! ```
//!
//! # The stopping rule
//! `Σ_i (σ_i â_i)² ρ_i^{2(k−2)}` never grows with `k` (`0 < ρ_i ≤ 1`), and it is the whole
//! step without an intercept, a lower bound of it with one. The first `k` where it falls below
//! `ε²` is found by bisection (powers of `ρ_i` by squaring, `O(n log² K)` in all); before it no
//! step is below `ε`, and without an intercept the rule stops exactly there. With one, the
//! steps from there on are evaluated one by one, `O(n)` each. Rounding can move the count only
//! where a step is within rounding of `ε` (measured on the pump's records in `f32`: never).
//!
//! # The last iterate
//! The last iterate is formed as the iteration forms every iterate,
//! `w_K = A⁻¹ (Xᵀy + γ D v_{K−1})` with the Cholesky factor of `A`, from the momentum
//! `v_{K−1,S} = U ν_{K−1} = Σ_i (M W)_i (1 − β) (Wᵀ l̃)_i G_{K−1,i} / μ_i` (`ν = s G`, `G_j` a sum
//! of positive terms computed by doubling: nothing cancels however slowly a mode converges).
//! Summing the modes' corrections `Σ_i u_i a_i G_{K−1,i}` directly instead puts the rounding
//! of the eigenvectors, times the large amplitudes of the slow modes, into every coefficient;
//! `A⁻¹` damps the part of it along the fast modes. Measured in `f32` on the pump's records
//! (`host-tests/tests/ridge_m_modes.rs`): the intercept within 6e-6 of the `f64` iteration
//! this way, 1.8e-3 summed directly. The first iterate is the Cholesky Ridge solution
//! ([`crate::Factor::solution`]), so plain Ridge is still exactly the first iterate.
//!
//! Rounding only makes this differ from the iteration as written ([`RidgeM::iterate`]): the
//! tests compare both with an `f64` iteration written from eq. 9–12.

use crate::cholesky::packed;
use crate::eigen::{self, Columns, COLS_MAX, HEAD_COLS, ROWS, STORAGE};
use crate::error::{Error, Result};
use crate::normal::{Factor, System};
use crate::real::Real;
use crate::ridge_m::RidgeM;
use crate::PARAMS_MAX;

/// Ridge-M on `system` given its least-squares factor `ls` (`system.factor(0)`). `f` and `ls`
/// are the work space: `f` holds the factor of `XᵀX + γD` on return and `ls` the least-squares
/// factor again (it is factored anew: it holds columns of the decomposition and the per-mode
/// arrays in between); on an error either may hold neither. Returns the last iterate
/// (internal order) and the number of iterates. Calls `progress()` between factorisations,
/// for every pair of columns the decomposition compares, once per mode and once per iterate:
/// no stretch between two calls is longer than one factorisation.
///
/// Never inlined, nor are its parts: their locals are on the stack one after another.
#[inline(never)]
pub(crate) fn ridge_m<T: Real>(
    rm: &RidgeM<T>,
    system: &System<T>,
    ls: &mut Factor<T>,
    f: &mut Factor<T>,
    progress: &mut impl FnMut(),
) -> Result<([T; PARAMS_MAX], u32)> {
    rm.check()?;
    let n = system.params();
    if ls.params() != n {
        return Err(Error::InvalidStructure);
    }
    progress();
    system.factor_into(rm.gamma, f)?;
    let mut w = f.solution();
    progress();
    // Iterate 1, the Ridge solution: a step of ‖w_1 − w_0‖ = ‖w_1‖.
    let mut step2 = T::ZERO;
    for v in w.iter().take(n) {
        step2 += *v * *v;
    }
    if rm.max_iter == 1 || step2.sqrt() < rm.tol {
        return Ok((w, 1));
    }
    let intercept = system.layout.intercept().is_some();
    let m = if intercept { n - 1 } else { n };
    // `w` holds a / a_cc (in M's row order) for the stopping rule, then D v_{K−1}.
    coupling(ls, intercept, m, &mut w)?;
    let used = {
        let second = ls.storage();
        fill(f.storage(), second, n, intercept)?;
        let (tail, work) = eigen::split(second).ok_or(Error::InvalidStructure)?;
        let mut cols = Columns::new(f.storage(), tail, m)?;
        progress();
        let (norms, _) = work
            .split_first_chunk_mut::<COLS_MAX>()
            .ok_or(Error::InvalidStructure)?;
        cols.orthogonalise(norms, progress)?;
        let used = stop(rm, &cols, work, &w, intercept, progress)?;
        momentum(rm, &cols, intercept, used, &mut w, progress);
        used
    };
    // w_K = A⁻¹ (Xᵀy + γ D v_{K−1}), A factored again; then the least-squares factor.
    system.factor_into(rm.gamma, f)?;
    progress();
    f.solve_shifted(rm.gamma, &mut w);
    progress();
    system.factor_into(T::ZERO, ls)?;
    progress();
    if w.iter().take(n).all(|v| v.is_finite()) {
        Ok((w, used))
    } else {
        Err(Error::NonFinite)
    }
}

/// `ρ_j` and `μ_j = σ_j² + γ` of mode `j` from the rotated columns.
fn mode<T: Real>(rm: &RidgeM<T>, cols: &Columns<'_, T>, j: usize) -> (T, T) {
    let mu = cols.norm2(j) + rm.gamma;
    (rm.beta + (T::ONE - rm.beta) * rm.gamma / mu, mu)
}

/// The rotation that eliminates the intercept (see the module docs): `(cos, sin, r)` of the
/// intercept's row `(l₁₀, l₁₁) = r (sin, cos)` of the factor `at`.
fn rotation<T: Real>(at: impl Fn(usize, usize) -> T) -> Result<(T, T, T)> {
    let (l10, l11) = (at(1, 0), at(1, 1));
    let r = (l10 * l10 + l11 * l11).sqrt();
    if !(r > T::ZERO && r.is_finite()) {
        return Err(Error::NotPositiveDefinite);
    }
    Ok((l11 / r, l10 / r, r))
}

/// Row of the factor that holds row `i` of `M` (or the carried row, `i = m`).
fn source_row(i: usize, intercept: bool) -> usize {
    if intercept && i >= 1 {
        i + 1
    } else {
        i
    }
}

/// `a / a_cc` in `M`'s row order into `out` (zero without an intercept): the rotated column
/// along the intercept's row over `r`.
fn coupling<T: Real>(
    ls: &Factor<T>,
    intercept: bool,
    m: usize,
    out: &mut [T; PARAMS_MAX],
) -> Result<()> {
    for v in out.iter_mut() {
        *v = T::ZERO;
    }
    if intercept {
        let (cs, sn, r) = rotation(|i, j| ls.at(i, j))?;
        for (i, v) in out.iter_mut().enumerate().take(m) {
            let row = source_row(i, true);
            *v = (sn * ls.at(row, 0) + cs * ls.at(row, 1)) / r;
        }
    }
    Ok(())
}

// `fill` writes the tail columns over the front of the factor it reads: the sources of every
// later column (rows ≥ its index, in packed order) lie past what the columns before it wrote.
const _: () = {
    let mut j = HEAD_COLS;
    while j + 1 < COLS_MAX {
        assert!(packed(j + 1, j + 1) >= (j + 1 - HEAD_COLS) * ROWS);
        j += 1;
    }
};

/// Writes `M` and the carried row `l̃` (see the module docs), built from the least-squares
/// factor of `n` coefficients held in `second` (packed), into the column slots
/// ([`eigen::slot`]): the first columns into `first`, the others over the front of `second`,
/// one whole column at a time in increasing order.
#[inline(never)]
fn fill<T: Real>(
    first: &mut [T; STORAGE],
    second: &mut [T; STORAGE],
    n: usize,
    intercept: bool,
) -> Result<()> {
    let m = if intercept { n - 1 } else { n };
    let at = |s: &[T; STORAGE], i: usize, j: usize| {
        if j > i || i > n {
            T::ZERO
        } else {
            s.get(packed(i, j)).copied().unwrap_or(T::ZERO)
        }
    };
    // Rows 0, 2, 3, …, n of the factor with an intercept (its row 1 left out); columns: the
    // rotated first one, then 2, 3, ….
    let (cs, sn, _) = if intercept {
        rotation(|i, j| at(second, i, j))?
    } else {
        (T::ONE, T::ZERO, T::ONE)
    };
    let mut col = [T::ZERO; ROWS];
    for j in 0..m {
        for (i, v) in col.iter_mut().enumerate().take(m + 1) {
            let row = source_row(i, intercept);
            *v = match (intercept, j) {
                (false, _) => at(second, row, j),
                (true, 0) => cs * at(second, row, 0) - sn * at(second, row, 1),
                (true, _) => at(second, row, j + 1),
            };
        }
        let (in_first, off) = eigen::slot(j);
        let dst = if in_first {
            first.get_mut(off..off + ROWS)
        } else {
            second.get_mut(off..off + ROWS)
        };
        if let Some(dst) = dst {
            dst.copy_from_slice(&col);
        }
    }
    Ok(())
}

/// The stopping rule (see the module docs): the first `k` with `‖w_k − w_{k−1}‖ < ε`, or
/// `max_iter` (iterate 1 was checked by the caller), with `work` for the per-mode arrays and
/// `xr = a / a_cc` ([`coupling`]). Calls `progress()` once per iterate and once per
/// evaluation of the bound.
#[inline(never)]
fn stop<T: Real>(
    rm: &RidgeM<T>,
    cols: &Columns<'_, T>,
    work: &mut [T; eigen::WORK],
    xr: &[T; PARAMS_MAX],
    intercept: bool,
    progress: &mut impl FnMut(),
) -> Result<u32> {
    let m = cols.n().min(COLS_MAX);
    // Per mode: ρ, its share (σ â)² of ‖Δw_2‖², and h of the intercept's step at k = 2.
    let (rho, rest) = work
        .split_first_chunk_mut::<COLS_MAX>()
        .ok_or(Error::InvalidStructure)?;
    let (sq, rest) = rest
        .split_first_chunk_mut::<COLS_MAX>()
        .ok_or(Error::InvalidStructure)?;
    let (cross, _) = rest
        .split_first_chunk_mut::<COLS_MAX>()
        .ok_or(Error::InvalidStructure)?;
    for j in 0..m {
        let (rh, mu) = mode(rm, cols, j);
        let ahat = (rh - rm.beta) * cols.get(cols.n(), j) / mu;
        let mut h = T::ZERO;
        if intercept {
            for (i, x) in xr.iter().enumerate().take(m) {
                h += cols.get(i, j) * *x;
            }
            h *= ahat;
        }
        let s = cols.norm2(j) * ahat * ahat;
        if !(rh.is_finite() && s.is_finite() && h.is_finite()) {
            return Err(Error::NonFinite);
        }
        rho[j] = rh;
        sq[j] = s;
        cross[j] = h;
    }
    // Σ_j (σ_j â_j)² ρ_j^{2(k−2)}: the step without the intercept's share, non-increasing.
    let lower = |k: u32| {
        let mut s = T::ZERO;
        for j in 0..m {
            s += sq[j] * powi(rho[j] * rho[j], k - 2);
        }
        s
    };
    let below = |s: T| s.sqrt() < rm.tol;
    let max = rm.max_iter;
    let mut used = max;
    progress();
    if below(lower(max)) {
        // The first k ∈ [2, max] with the lower bound below ε: lower(lo) ≥ ε² > lower(hi).
        let (mut lo, mut hi) = (1, max);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            progress();
            if below(lower(mid)) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        used = hi;
        if intercept {
            // From there, every step with the intercept's share.
            for j in 0..m {
                let z = powi(rho[j], hi - 2);
                sq[j] *= z * z;
                cross[j] *= z;
            }
            used = max;
            for k in hi..=max {
                let (mut s, mut h) = (T::ZERO, T::ZERO);
                for j in 0..m {
                    if k > hi {
                        sq[j] *= rho[j] * rho[j];
                        cross[j] *= rho[j];
                    }
                    s += sq[j];
                    h += cross[j];
                }
                if below(s + h * h) {
                    used = k;
                    break;
                }
            }
        }
    }
    for _ in 2..=used {
        progress();
    }
    Ok(used)
}

/// `D v_{K−1}` into `out` (internal order, zero at the intercept) for `K = used` (see the
/// module docs). Calls `progress()` once per mode.
#[inline(never)]
fn momentum<T: Real>(
    rm: &RidgeM<T>,
    cols: &Columns<'_, T>,
    intercept: bool,
    used: u32,
    out: &mut [T; PARAMS_MAX],
    progress: &mut impl FnMut(),
) {
    let m = cols.n();
    for v in out.iter_mut() {
        *v = T::ZERO;
    }
    for j in 0..m {
        progress();
        let (rho, mu) = mode(rm, cols, j);
        let k = (T::ONE - rm.beta) * cols.get(m, j) * geometric(rho, used - 1) / mu;
        for i in 0..m {
            if let Some(v) = out.get_mut(source_row(i, intercept)) {
                *v += cols.get(i, j) * k;
            }
        }
    }
}

/// `x^e` by squaring.
fn powi<T: Real>(mut x: T, mut e: u32) -> T {
    let mut p = T::ONE;
    while e != 0 {
        if e & 1 != 0 {
            p *= x;
        }
        x *= x;
        e >>= 1;
    }
    p
}

/// `G_j = 1 + ρ + … + ρ^{j−1}` (0 for `j = 0`) by doubling, `G_{2i} = G_i (1 + ρ^i)` and
/// `G_{i+1} = 1 + ρ G_i`, from the top bit of `j` down: `2 log₂ j` steps of positive terms.
fn geometric<T: Real>(rho: T, j: u32) -> T {
    let (mut g, mut p) = (T::ZERO, T::ONE);
    let mut bit = 1u32 << 31;
    while bit > j {
        bit >>= 1;
    }
    while bit != 0 {
        g += g * p;
        p *= p;
        if j & bit != 0 {
            g = T::ONE + rho * g;
            p *= rho;
        }
        bit >>= 1;
    }
    g
}

#[cfg(test)]
mod tests {
    use super::{geometric, powi};

    #[test]
    fn geometric_sums_match_the_series() {
        for rho in [0.0f64, 0.01, 0.5, 0.9, 0.999, 1.0] {
            let mut want = 0.0;
            for j in 0..300u32 {
                let got = geometric(rho, j);
                assert!(
                    (got - want).abs() <= 1e-13 * want.max(1.0),
                    "ρ {rho} j {j}: {got} vs {want}"
                );
                want = 1.0 + rho * want;
            }
        }
        assert_eq!(geometric(0.5f32, u32::MAX), 2.0);
    }

    #[test]
    fn powers_by_squaring() {
        for x in [0.0f64, 0.3, 0.999, 1.0, 1.5] {
            let mut want = 1.0;
            for e in 0..200u32 {
                assert!((powi(x, e) - want).abs() <= 1e-13 * want, "{x}^{e}");
                want *= x;
            }
        }
    }
}
