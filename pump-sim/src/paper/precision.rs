//! `f32` vs `f64` solves on the same exact integer statistics (no paper counterpart).

use ridge_core::{ArxModel, Criterion, Estimator, Method, Offset, Result, Structure};
use ridge_pump_firmware::excitation::Record;

use super::{ridge_m, search, Dataset, Rmse};

/// `f32` vs `f64` solve on the same exact statistics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Precision {
    /// Record.
    pub record: Record,
    /// Criterion.
    pub criterion: Criterion,
    /// Pick with `f64` solves.
    pub structure_f64: Structure,
    /// Pick with `f32` solves.
    pub structure_f32: Structure,
    /// Candidates evaluated, `f64` / `f32`.
    pub evaluated: (u16, u16),
    /// Largest |coefficient difference| of Ridge-M on the `f64` pick, `f32` vs `f64`.
    pub max_coef_diff: f64,
    /// Largest |coefficient| of the `f64` model (for scale).
    pub max_coef: f64,
    /// Free-run RMSE on the identification record, `f64` model / `f32` model (same
    /// structure, evaluated in `f64`).
    pub free_run: (f64, f64),
}

fn coefficients(m: &ArxModel<f64>) -> Vec<f64> {
    let mut v: Vec<f64> = m.theta().iter().chain(m.phi()).copied().collect();
    if m.offset() == Offset::Intercept {
        v.push(m.intercept());
    }
    v
}

fn widen(m: &ArxModel<f32>) -> Result<ArxModel<f64>> {
    let t: Vec<f64> = m.theta().iter().map(|&x| f64::from(x)).collect();
    let p: Vec<f64> = m.phi().iter().map(|&x| f64::from(x)).collect();
    ArxModel::new(
        &t,
        &p,
        m.structure().d,
        m.offset(),
        f64::from(m.intercept()),
    )
}

/// Runs the Ridge-M search and fit in `f32` and `f64` on the same integer statistics.
pub fn precision(data: &Dataset, r: Record, criterion: Criterion) -> Result<Precision> {
    let n64 = data.normal::<f64>(r)?;
    let n32 = data.normal::<f32>(r)?;
    let s64 = search(
        &n64,
        criterion,
        Offset::None,
        Method::RidgeM(ridge_m()),
        true,
    )?;
    let s32 = search(
        &n32,
        criterion,
        Offset::None,
        Method::RidgeM(ridge_m()),
        true,
    )?;
    let s = s64.structure();
    let m64 = s64.fit.model();
    let m32 = widen(&ridge_m::<f32>().fit(&n32.system(s, Offset::None)?)?.model())?;
    let (c64, c32) = (coefficients(&m64), coefficients(&m32));
    let max_coef_diff = c64
        .iter()
        .zip(&c32)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let max_coef = c64.iter().map(|a| a.abs()).fold(0.0, f64::max);
    let log = data.log(r)?;
    Ok(Precision {
        record: r,
        criterion,
        structure_f64: s,
        structure_f32: s32.structure(),
        evaluated: (s64.evaluated, s32.evaluated),
        max_coef_diff,
        max_coef,
        free_run: (Rmse::of(&m64, log)?.free_run, Rmse::of(&m32, log)?.free_run),
    })
}
