//! Table 4: the structure search run with plain Ridge and with Ridge-M over a range of γ,
//! identified on one record and scored on another.

use ridge_core::{Criterion, Method, Normal, Offset, Result, Ridge, RidgeM, Structure};
use ridge_pump_firmware::excitation::Record;

use super::{
    ridge_m, ridge_m_residual_factor, search, smallest_eigenvalue_over_grid, Dataset, Rmse,
};
use crate::Log;

/// The γ values of Table 4: 1e-1 … 1e9, one per decade.
pub const GAMMAS: [f64; 11] = [1e-1, 1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
/// One estimator's pick at one γ of Table 4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepPick {
    /// Structure chosen by the search.
    pub structure: Structure,
    /// The chosen model scored on the validation record.
    pub rmse: Rmse,
    /// Candidates evaluated by the pruned search.
    pub evaluated: u16,
    /// Iterates used on the chosen structure (1 for plain Ridge).
    pub iterations: u32,
}

/// One row of Table 4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepRow {
    /// Regularisation γ.
    pub gamma: f64,
    /// Without momentum (plain Ridge, the first Ridge-M iterate).
    pub plain: SweepPick,
    /// With momentum (Ridge-M, β = 0.01, 200 iterates, ε = 1e-6).
    pub momentum: SweepPick,
    /// Theory: largest per-mode distance of 200 Ridge-M iterates from least squares over
    /// the grid, [`ridge_m_residual_factor`] at the smallest eigenvalue of any candidate's
    /// `XᵀX`. Near 0: Ridge-M is least squares on every candidate; near 1: far from it.
    pub residual_factor: f64,
}

/// Table 4: the search run with plain Ridge and with Ridge-M for every γ of [`GAMMAS`].
#[derive(Clone, Debug)]
pub struct Sweep {
    /// Identification record.
    pub identification: Record,
    /// Validation record.
    pub validation: Record,
    /// Criterion.
    pub criterion: Criterion,
    /// Least-squares search on the same record (the γ → 0 limit of both).
    pub ols: SweepPick,
    /// Smallest eigenvalue of `XᵀX` over the grid, and its candidate.
    pub lambda_min: (f64, Structure),
    /// One row per γ.
    pub rows: Vec<SweepRow>,
}

fn pick(
    normal: &Normal<f64>,
    criterion: Criterion,
    method: Method<f64>,
    val: &Log,
) -> Result<SweepPick> {
    let sel = search(normal, criterion, Offset::None, method, true)?;
    Ok(SweepPick {
        structure: sel.structure(),
        rmse: Rmse::of(&sel.fit.model(), val)?,
        evaluated: sel.evaluated,
        iterations: sel.fit.iterations,
    })
}

/// Runs Table 4 for one criterion.
pub fn gamma_sweep(
    data: &Dataset,
    identification: Record,
    validation: Record,
    criterion: Criterion,
) -> Result<Sweep> {
    let normal = data.normal::<f64>(identification)?;
    let val = data.log(validation)?;
    let ols = pick(&normal, criterion, Method::Ols, val)?;
    let lambda_min = smallest_eigenvalue_over_grid(&normal, Offset::None)?;
    let rm = ridge_m::<f64>();
    let rows = GAMMAS
        .iter()
        .map(|&gamma| {
            Ok(SweepRow {
                gamma,
                plain: pick(&normal, criterion, Method::Ridge(Ridge { gamma }), val)?,
                momentum: pick(
                    &normal,
                    criterion,
                    Method::RidgeM(RidgeM { gamma, ..ridge_m() }),
                    val,
                )?,
                residual_factor: ridge_m_residual_factor(lambda_min.0, gamma, rm.beta, rm.max_iter),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Sweep {
        identification,
        validation,
        criterion,
        ols,
        lambda_min,
        rows,
    })
}
