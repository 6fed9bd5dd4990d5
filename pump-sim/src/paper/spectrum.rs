//! Eigenvalues of `XᵀX` and what they imply for Ridge-M: how far `k` iterates are from least
//! squares in each eigen-mode, and the worst mode over the search grid.

use ridge_core::{Error, Normal, Offset, Result, Structure, System};

/// Eigenvalues of a small symmetric matrix (cyclic Jacobi), ascending.
pub fn symmetric_eigenvalues(a: &[Vec<f64>]) -> Vec<f64> {
    let n = a.len();
    let mut a: Vec<Vec<f64>> = a.to_vec();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-32 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - s * y;
                    row[q] = s * x + c * y;
                }
                let (lo, hi) = a.split_at_mut(q);
                for (x, y) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                    let (u, v) = (*x, *y);
                    *x = c * u - s * v;
                    *y = s * u + c * v;
                }
            }
        }
    }
    let mut ev: Vec<f64> = (0..n).map(|i| a[i][i]).collect();
    ev.sort_by(f64::total_cmp);
    ev
}

/// `XᵀX` of a system (internal order) as a dense matrix.
pub fn gram_matrix(sys: &System<f64>) -> Vec<Vec<f64>> {
    let n = sys.params();
    (0..n)
        .map(|i| (0..n).map(|j| sys.augmented(i, j)).collect())
        .collect()
}

/// How far Ridge-M is from least squares after `k` iterates, per eigen-mode of `XᵀX`
/// with eigenvalue `lambda` (SPEC §3 closed form): `w_k − w_LS = −γ/(λ+γ) ρ^{k−1} w_LS`
/// in that mode, `ρ = β + (1−β) γ/(λ+γ)`. Returns `γ/(λ+γ) ρ^{k−1}`.
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
