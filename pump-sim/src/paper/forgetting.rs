//! RLS with forgetting factors (no paper counterpart; the paper does not state its λ): final
//! estimates on one structure, scored on the four records.

use ridge_core::{Offset, Result, Structure};
use ridge_pump_firmware::excitation::Record;

use super::{rls, Dataset, Rmse, RLS_DELTA};

/// Final RLS estimates with forgetting, scored on the four records.
#[derive(Clone, Debug, PartialEq)]
pub struct Forgetting {
    /// Structure.
    pub structure: Structure,
    /// `(λ, mean RMSE over the four records)`.
    pub rows: Vec<(f64, Rmse)>,
}

/// RLS forgetting factors of the extra table.
pub const FORGETTING: [f64; 4] = [1.0, 0.999, 0.99, 0.98];

/// RLS with each forgetting factor of [`FORGETTING`] on `r`, final estimate, averaged
/// over the four records.
pub fn rls_forgetting(data: &Dataset, r: Record, s: Structure) -> Result<Forgetting> {
    let log = data.log(r)?;
    let rows = FORGETTING
        .iter()
        .map(|&l| {
            let m = rls(log, s, Offset::None, l, RLS_DELTA)?;
            let v = data
                .logs
                .iter()
                .map(|x| Rmse::of(&m, x))
                .collect::<Result<Vec<_>>>()?;
            Ok((l, Rmse::mean(&v)))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Forgetting { structure: s, rows })
}
