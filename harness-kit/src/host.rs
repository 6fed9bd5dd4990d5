//! The firmware's structure search rerun on the host from the samples it saw, and the
//! comparison of two printed models: the check that the board computed what ridge-core
//! computes.

use ridge_core::{IntGram, Real, Search};
use ridge_pump_firmware::lines::{IdLine, PrintedModel};
use ridge_pump_firmware::selfid::{absolute_model, DEFAULT_CONFIG};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::MODEL_SCALE;

use crate::samples::Samples;

/// The firmware's search configuration (`selfid::DEFAULT_CONFIG.search`: ridge-core's
/// default search on the device's grid, p ≤ 5, with an intercept, on deviations from the
/// operating point), in `T`.
pub fn firmware_search<T: Real>() -> Search<T> {
    Search {
        grid: DEFAULT_CONFIG.search.grid,
        offset: DEFAULT_CONFIG.search.offset,
        ..Search::default()
    }
}

/// Reruns the firmware's search on the host from `samples` with exact integer statistics and
/// `f64` normal equations (ridge-core `IntGram` + `Search<f64>` on the deviations
/// `(v − v0, y − y0)`, `v` the map's flow at the duty), and converts the result to the absolute
/// model with an intercept as the firmware does (`selfid::absolute_model`:
/// `c = c_dev + y0 (1 − Σθ) − v0 Σφ`).
pub fn host_search(samples: &Samples) -> Result<IdLine, String> {
    host_search_in::<f64>(samples)
}

/// [`host_search`] with the normal equations and the search in `T` (`f32` is what the
/// firmware runs).
pub fn host_search_in<T: Real>(samples: &Samples) -> Result<IdLine, String> {
    let map = samples.map.ok_or("no MAP line before the record")?;
    let mut g = IntGram::new();
    let (v0, y0) = (map.at(samples.u0), i32::from(samples.y0));
    for (&u, &raw) in samples.u.iter().zip(&samples.raw) {
        let dv = i32::from(map.at(u)) - i32::from(v0);
        g.push(dv, i32::from(raw_to_counts(raw)) - y0)
            .map_err(|e| format!("{e:?}"))?;
    }
    let normal = g.normal::<T>(MODEL_SCALE).map_err(|e| format!("{e:?}"))?;
    let sel = firmware_search::<T>()
        .run(&normal, None)
        .map_err(|e| format!("{e:?}"))?;
    let m = absolute_model(&sel.fit.model(), v0, samples.y0).map_err(|e| format!("{e:?}"))?;
    let s = m.structure();
    Ok(IdLine {
        model: PrintedModel {
            p: s.p,
            q: s.q,
            d: s.d,
            offset: m.offset(),
            theta: m.theta().iter().map(|v| v.to_f64()).collect(),
            phi: m.phi().iter().map(|v| v.to_f64()).collect(),
            c: m.intercept().to_f64(),
        },
        score: sel.score.to_f64(),
        evaluated: sel.evaluated,
        candidates: sel.candidates,
        skipped: sel.skipped,
        iterations: sel.fit.iterations,
    })
}

/// Largest coefficient difference between two models of the same structure, relative to
/// `max(1, |b|)` per coefficient (θ, φ, c); `None` if the structures differ.
pub fn coefficient_error(a: &PrintedModel, b: &PrintedModel) -> Option<f64> {
    if (a.p, a.q, a.d) != (b.p, b.q, b.d) || a.theta.len() != b.theta.len() {
        return None;
    }
    let pairs = a
        .theta
        .iter()
        .zip(&b.theta)
        .chain(a.phi.iter().zip(&b.phi))
        .chain(std::iter::once((&a.c, &b.c)));
    Some(
        pairs
            .map(|(x, y)| (x - y).abs() / y.abs().max(1.0))
            .fold(0.0, f64::max),
    )
}
