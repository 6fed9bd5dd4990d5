//! The estimation steps shared by the experiments: the structure search with the paper's α,
//! RLS sample by sample over a log, and models from coefficient vectors.

use ridge_core::{
    ArxModel, Criterion, Error, Method, Normal, Offset, Real, Regressor, Result, Rls, Search,
    Structure, System,
};

use super::ALPHA;
use crate::Log;

/// RLS on a fixed structure, sample by sample over the whole log (physical units), from
/// `w = 0`, `P₀ = δI`; returns the final model.
pub fn rls(
    log: &Log,
    s: Structure,
    offset: Offset,
    lambda: f64,
    delta: f64,
) -> Result<ArxModel<f64>> {
    let mut r = Rls::new(s, offset, lambda, delta)?;
    for (&u, &y) in log.u.iter().zip(&log.y) {
        r.update(u, y)?;
    }
    Ok(r.model())
}

/// Turns coefficients in a [`System`]'s internal order into an [`ArxModel`].
pub fn model_from_internal<T: Real>(sys: &System<T>, w: &[T]) -> Result<ArxModel<T>> {
    let s = sys.structure();
    let mut theta = vec![T::ZERO; usize::from(s.p)];
    let mut phi = vec![T::ZERO; usize::from(s.q)];
    let mut c = T::ZERO;
    for (i, &v) in w.iter().enumerate().take(sys.params()) {
        match sys.regressor(i) {
            Some(Regressor::Output(k)) if k >= 1 => theta[usize::from(k) - 1] = v,
            Some(Regressor::Input(k)) => phi[usize::from(k - s.d)] = v,
            Some(Regressor::Constant) => c = v,
            _ => return Err(Error::InvalidStructure),
        }
    }
    ArxModel::new(&theta, &phi, s.d, sys.offset(), c)
}

/// A structure search on `normal` with the paper's α and grid.
pub fn search<T: Real>(
    normal: &Normal<T>,
    criterion: Criterion,
    offset: Offset,
    method: Method<T>,
    prune: bool,
) -> Result<ridge_core::Selection<T>> {
    Search {
        criterion,
        offset,
        method,
        prune,
        alpha: T::from_f64(ALPHA),
        ..Search::default()
    }
    .run(normal, None)
}
