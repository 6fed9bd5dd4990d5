//! Tables 2–3: Ridge-M coefficients against the iteration count, and the least-squares
//! solution they converge to.

use ridge_core::{ArxModel, Estimator, Offset, Ols, Result, RidgeM, Structure};
use ridge_pump_firmware::excitation::Record;

use super::{model_from_internal, ridge_m, Dataset};

/// The iterations printed in Tables 2–3 (as in the paper).
pub const ITERATIONS: [u32; 7] = [1, 30, 60, 90, 120, 150, 180];
/// Tables 2–3: Ridge-M coefficients against the iteration count.
#[derive(Clone, Debug)]
pub struct Convergence {
    /// Regularisation γ.
    pub gamma: f64,
    /// Structure.
    pub structure: Structure,
    /// `(k, w_k)` at the requested iterations, as models (θ, φ).
    pub rows: Vec<(u32, ArxModel<f64>)>,
    /// The least-squares solution, the fixed point of the iteration.
    pub ols: ArxModel<f64>,
}

/// Runs Ridge-M with tolerance 0 up to `max(at)` iterations on `structure` of record `r`,
/// keeping the iterates listed in `at`.
pub fn convergence(
    data: &Dataset,
    r: Record,
    structure: Structure,
    gamma: f64,
    at: &[u32],
) -> Result<Convergence> {
    let normal = data.normal::<f64>(r)?;
    let sys = normal.system(structure, Offset::None)?;
    let max_iter = at.iter().copied().max().unwrap_or(1).max(1);
    let rm = RidgeM {
        gamma,
        tol: 0.0,
        max_iter,
        ..ridge_m()
    };
    let mut kept: Vec<(u32, Vec<f64>)> = Vec::new();
    rm.iterate(&sys, |k, w| {
        if at.contains(&k) {
            kept.push((k, w.to_vec()));
        }
    })?;
    let rows = kept
        .iter()
        .map(|(k, w)| Ok((*k, model_from_internal(&sys, w)?)))
        .collect::<Result<Vec<_>>>()?;
    let ols = Ols.fit(&sys)?.model();
    Ok(Convergence {
        gamma,
        structure,
        rows,
        ols,
    })
}
