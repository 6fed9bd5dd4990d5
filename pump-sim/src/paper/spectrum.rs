//! Eigenvalues of `XᵀX` and what they imply for Ridge-M: how far `k` iterates are from least
//! squares in each eigen-mode, and the worst mode over the search grid.

use nalgebra::{DMatrix, SymmetricEigen};
use ridge_core::{Error, Normal, Offset, Result, Structure, System};

/// Eigenvalues of a symmetric matrix, ascending (nalgebra's [`SymmetricEigen`]; only the lower
/// triangle is read). Same units as the matrix entries.
pub fn symmetric_eigenvalues(a: &DMatrix<f64>) -> Vec<f64> {
    let mut ev: Vec<f64> = SymmetricEigen::new(a.clone())
        .eigenvalues
        .iter()
        .copied()
        .collect();
    ev.sort_by(f64::total_cmp);
    ev
}

/// `XᵀX` of a system as a dense `params × params` matrix, rows and columns in the system's
/// internal regressor order ([`System::regressor`]); entries in the units of the statistics
/// the system was built from (here slm and duty fraction).
pub fn gram_matrix(sys: &System<f64>) -> DMatrix<f64> {
    let n = sys.params();
    DMatrix::from_fn(n, n, |i, j| sys.augmented(i, j))
}

/// How far Ridge-M is from least squares after `k` iterates, per eigen-mode of `XᵀX` with
/// eigenvalue `lambda` (units of `XᵀX`); `gamma` (same units) and `beta` as in the paper.
///
/// Closed form of the paper's iteration, eqs. (10) and (12), from `v_0 = 0`: in the mode,
/// with `s = γ/(λ+γ)`, `w_{k+1} − w_LS = s (v_k − w_LS)` and
/// `v_{k+1} − w_LS = ρ (v_k − w_LS)`, `ρ = β + (1−β) s`, so
/// `w_k − w_LS = −s ρ^{k−1} w_LS`. Returns the dimensionless factor `s ρ^{k−1}`: near 0,
/// Ridge-M has reached least squares in that mode; near 1, it is still near zero.
pub fn ridge_m_residual_factor(lambda: f64, gamma: f64, beta: f64, k: u32) -> f64 {
    let shrink = gamma / (lambda + gamma);
    let rho = beta + (1.0 - beta) * shrink;
    shrink * rho.powi(k.saturating_sub(1) as i32)
}

/// Smallest eigenvalue of `XᵀX` over every candidate of the paper's grid on `normal`, and
/// the candidate that has it.
pub fn smallest_eigenvalue_over_grid(
    normal: &Normal<f64>,
    offset: Offset,
) -> Result<(f64, Structure)> {
    let mut best: Option<(f64, Structure)> = None;
    for s in ridge_core::Grid::default().iter() {
        let sys = normal.system(s, offset)?;
        let l = symmetric_eigenvalues(&gram_matrix(&sys))[0];
        if best.is_none_or(|(b, _)| l < b) {
            best = Some((l, s));
        }
    }
    best.ok_or(Error::NoCandidate)
}
