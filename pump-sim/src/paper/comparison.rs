//! Tables 1 and 5: the structure chosen by Ridge-M + search on one record, then every
//! estimator of the paper on that structure, scored on the four records.

use ridge_core::{
    AdaptiveLasso, ArxModel, Criterion, Estimator, Method, Offset, Ols, Result, Ridge, Structure,
};
use ridge_pump_firmware::excitation::Record;

use super::{ridge_m, rls, search, Dataset, Rmse, GAMMA, RLS_DELTA, RLS_LAMBDA};

/// The estimators compared in Tables 1 and 5 (plus least squares as a reference).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Algorithm {
    /// Recursive least squares, λ = 1, δ = 1e3, sample by sample.
    Rls,
    /// Plain Ridge, γ = 1000.
    Ridge,
    /// Adaptive LASSO, BIC-chosen λ ([`AdaptiveLasso::default`]).
    Alasso,
    /// Ridge-M with the paper's hyper-parameters.
    RidgeM,
    /// Ordinary least squares (reference; not in the paper's tables).
    Ols,
}

impl Algorithm {
    /// All, in table order.
    pub const ALL: [Algorithm; 5] = [
        Algorithm::Rls,
        Algorithm::Ridge,
        Algorithm::Alasso,
        Algorithm::RidgeM,
        Algorithm::Ols,
    ];

    /// Column title.
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::Rls => "RLS",
            Algorithm::Ridge => "Ridge",
            Algorithm::Alasso => "ALASSO",
            Algorithm::RidgeM => "Ridge-M",
            Algorithm::Ols => "OLS (ref.)",
        }
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
    /// The model of each algorithm, in [`Algorithm::ALL`] order.
    pub models: Vec<(Algorithm, ArxModel<f64>)>,
    /// `rmse[a][r]`: algorithm `a` ([`Algorithm::ALL`]) on record `r` ([`RECORDS`](super::RECORDS)).
    pub rmse: Vec<Vec<Rmse>>,
}

impl Comparison {
    /// Mean over the four records for algorithm index `a`.
    pub fn average(&self, a: usize) -> Rmse {
        Rmse::mean(&self.rmse[a])
    }

    /// The model of one algorithm.
    pub fn model(&self, a: Algorithm) -> Option<&ArxModel<f64>> {
        self.models.iter().find(|(x, _)| *x == a).map(|(_, m)| m)
    }
}

/// Runs one Table-1/5 comparison.
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
    let mut models = Vec::new();
    for a in Algorithm::ALL {
        let m = match a {
            Algorithm::Rls => rls(log, s, offset, RLS_LAMBDA, RLS_DELTA)?,
            Algorithm::Ridge => Ridge { gamma: GAMMA }.fit_with(&sys, &ls)?.model(),
            Algorithm::Alasso => AdaptiveLasso::default().fit_with(&sys, &ls)?.model(),
            Algorithm::RidgeM => ridge_m().fit_with(&sys, &ls)?.model(),
            Algorithm::Ols => Ols.fit_with(&sys, &ls)?.model(),
        };
        models.push((a, m));
    }
    let rmse = models
        .iter()
        .map(|(_, m)| data.logs.iter().map(|l| Rmse::of(m, l)).collect())
        .collect::<Result<Vec<Vec<Rmse>>>>()?;
    Ok(Comparison {
        identification,
        criterion,
        offset,
        structure: s,
        evaluated: sel.evaluated,
        candidates: sel.candidates,
        ridge_m_iterations: sel.fit.iterations,
        models,
        rmse,
    })
}
