//! Tables 1 and 5: the structure chosen by Ridge-M + search on one record, then every
//! estimator of the paper on that structure, scored on the four records.

use ridge_core::{
    AdaptiveLasso, ArxModel, Criterion, Estimator, Method, MethodKind, Offset, Ols, Result, Ridge,
    Structure,
};
use ridge_pump_firmware::excitation::Record;

use super::{ridge_m, rls, search, Dataset, Rmse, GAMMA, RLS_DELTA, RLS_LAMBDA};

/// The estimators compared in Tables 1 and 5, in column order, plus least squares as a
/// reference column (not in the paper's tables):
///
/// - [`MethodKind::Rls`]: recursive least squares, λ = [`RLS_LAMBDA`], `P₀ = δI` with
///   δ = [`RLS_DELTA`], one update per sample over the whole record, final estimate;
/// - [`MethodKind::Ridge`]: plain Ridge, γ = [`GAMMA`];
/// - [`MethodKind::AdaptiveLasso`]: adaptive LASSO, λ chosen by BIC
///   ([`AdaptiveLasso::default`]);
/// - [`MethodKind::RidgeM`]: Ridge-M with the paper's hyper-parameters ([`ridge_m`]);
/// - [`MethodKind::Ols`]: ordinary least squares (reference).
pub const COMPARED: [MethodKind; 5] = [
    MethodKind::Rls,
    MethodKind::Ridge,
    MethodKind::AdaptiveLasso,
    MethodKind::RidgeM,
    MethodKind::Ols,
];

/// One estimator of a [`Comparison`]: its model on the chosen structure and its scores.
#[derive(Clone, Debug)]
pub struct Estimate {
    /// The estimator.
    pub method: MethodKind,
    /// Its model (coefficients in slm and duty fraction).
    pub model: ArxModel<f64>,
    /// Its RMSE on each record, in [`RECORDS`](super::RECORDS) order.
    pub rmse: Vec<Rmse>,
}

impl Estimate {
    /// Mean RMSE over the records.
    pub fn average(&self) -> Rmse {
        Rmse::mean(&self.rmse)
    }
}

/// Tables 1 and 5: a structure chosen by Ridge-M + search on one record, then every
/// estimator on that structure, validated on the four records.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// Identification record.
    pub identification: Record,
    /// Criterion of the structure search.
    pub criterion: Criterion,
    /// Constant term.
    pub offset: Offset,
    /// The structure chosen by Ridge-M + search.
    pub structure: Structure,
    /// Candidates the pruned search ran Ridge-M on.
    pub evaluated: u16,
    /// Candidates in the grid (252).
    pub candidates: u16,
    /// Ridge-M iterates used on the chosen structure.
    pub ridge_m_iterations: u32,
    /// One entry per estimator, in [`COMPARED`] order.
    pub estimates: Vec<Estimate>,
}

impl Comparison {
    /// The entry of estimator `method` (`None` if it is not one of [`COMPARED`]).
    pub fn estimate(&self, method: MethodKind) -> Option<&Estimate> {
        self.estimates.iter().find(|e| e.method == method)
    }
}

/// Runs one Table-1/5 comparison: the Ridge-M search (criterion `criterion`,
/// α = [`ALPHA`](super::ALPHA)) on `identification`, then every estimator of [`COMPARED`] on
/// the chosen structure.
pub fn comparison(
    data: &Dataset,
    identification: Record,
    criterion: Criterion,
    offset: Offset,
) -> Result<Comparison> {
    let normal = data.normal::<f64>(identification)?;
    let sel = search(&normal, criterion, offset, Method::RidgeM(ridge_m()), true)?;
    let s = sel.structure();
    let sys = normal.system(s, offset)?;
    let ls = sys.factor(0.0)?;
    let log = data.log(identification)?;
    let mut estimates = Vec::new();
    for method in COMPARED {
        let model = match method {
            MethodKind::Rls => rls(log, s, offset, RLS_LAMBDA, RLS_DELTA)?,
            MethodKind::Ridge => Ridge { gamma: GAMMA }.fit_with(&sys, &ls)?.model(),
            MethodKind::AdaptiveLasso => AdaptiveLasso::default().fit_with(&sys, &ls)?.model(),
            MethodKind::RidgeM => ridge_m().fit_with(&sys, &ls)?.model(),
            MethodKind::Ols => Ols.fit_with(&sys, &ls)?.model(),
        };
        let rmse = data
            .logs
            .iter()
            .map(|l| Rmse::of(&model, l))
            .collect::<Result<Vec<_>>>()?;
        estimates.push(Estimate {
            method,
            model,
            rmse,
        });
    }
    Ok(Comparison {
        identification,
        criterion,
        offset,
        structure: s,
        evaluated: sel.evaluated,
        candidates: sel.candidates,
        ridge_m_iterations: sel.fit.iterations,
        estimates,
    })
}
