//! Pruned vs exhaustive structure search (no paper counterpart): the pruned search must
//! pick what the whole grid picks, with fewer Ridge-M runs.

use ridge_core::{Criterion, Method, Offset, Result, Structure};
use ridge_pump_firmware::excitation::Record;

use super::{ridge_m, search, Dataset};

/// Pruned vs exhaustive search on one record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pruning {
    /// Criterion.
    pub criterion: Criterion,
    /// Constant term.
    pub offset: Offset,
    /// Pick of the pruned search.
    pub pruned: Structure,
    /// Candidates the pruned search ran Ridge-M on.
    pub evaluated: u16,
    /// Pick of the exhaustive search.
    pub exhaustive: Structure,
    /// Candidates the exhaustive search ran Ridge-M on (all fittable ones).
    pub exhaustive_evaluated: u16,
    /// Grid size.
    pub candidates: u16,
    /// The two picks' criterion values agree exactly.
    pub same_score: bool,
}

/// Runs the Ridge-M search with and without pruning.
pub fn pruning(data: &Dataset, r: Record, criterion: Criterion, offset: Offset) -> Result<Pruning> {
    let normal = data.normal::<f64>(r)?;
    let a = search(&normal, criterion, offset, Method::RidgeM(ridge_m()), true)?;
    let b = search(&normal, criterion, offset, Method::RidgeM(ridge_m()), false)?;
    Ok(Pruning {
        criterion,
        offset,
        pruned: a.structure(),
        evaluated: a.evaluated,
        exhaustive: b.structure(),
        exhaustive_evaluated: b.evaluated,
        candidates: a.candidates,
        same_score: a.score == b.score,
    })
}
