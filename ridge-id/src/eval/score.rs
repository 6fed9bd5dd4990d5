//! The scoring pass: a model's one-step and free-run figures and residual analysis on a
//! record, from measured initial conditions ([`evaluate`], [`Figures`]).

use std::path::Path;

use ridge_core_host::{ArxModel, Evaluation};

use super::trace::Trace;
use crate::csv::{CsvRecord, Sample};
use crate::error::IdError;
use crate::residuals::{ResidualStats, Residuals};

/// Scores of one model on one record, from measured initial conditions (samples `m..N`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// Samples scored: `N − m`.
    pub n: u32,
    /// One-step-ahead RMSE (eq. 16), output units.
    pub rmse_one_step: f64,
    /// Free-run RMSE, output units.
    pub rmse_free_run: f64,
    /// One-step fit %, `100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)`.
    pub fit_one_step: f64,
    /// Free-run fit % (what MATLAB `compare` shows).
    pub fit_free_run: f64,
    /// Residual analysis of the one-step residuals on the scored samples (MATLAB `resid`);
    /// `None` when they are all zero or the input is constant there.
    pub residuals: Option<Residuals>,
}

/// Scores `model` on a stream of samples; `trace` (if any) receives every measured and
/// predicted value for a plot. `Ok(None)` when the stream has no sample past the seed.
pub fn evaluate<I>(
    samples: I,
    model: ArxModel<f64>,
    mut trace: Option<&mut Trace>,
) -> Result<Option<Figures>, IdError>
where
    I: IntoIterator<Item = Result<Sample, IdError>>,
{
    let mut ev = Evaluation::new(model);
    let mut resid = ResidualStats::new();
    for (i, s) in samples.into_iter().enumerate() {
        let s = s?;
        let pred = ev.push(s.u, s.y);
        if let Some((one_step, _)) = pred {
            resid.push(s.u, s.y - one_step);
        }
        if let Some(t) = trace.as_deref_mut() {
            t.push(i as u64, s.y, pred);
        }
    }
    if let Some(t) = trace {
        t.finish();
    }
    Ok(match (ev.one_step(), ev.free_run()) {
        (Some(a), Some(b)) => Some(Figures {
            n: a.n,
            rmse_one_step: a.rmse,
            rmse_free_run: b.rmse,
            fit_one_step: a.fit,
            fit_free_run: b.fit,
            residuals: resid.finish(),
        }),
        _ => None,
    })
}

/// Scores `model` on the CSV record at `path` in one streaming pass (see [`evaluate`]).
///
/// Errors: CSV errors with file and line; a record with no sample past the `m` seed
/// samples.
pub fn evaluate_file(
    path: impl AsRef<Path>,
    model: ArxModel<f64>,
    trace: Option<&mut Trace>,
) -> Result<Figures, IdError> {
    let path = path.as_ref();
    evaluate(CsvRecord::open(path)?, model, trace)?.ok_or_else(|| too_short_to_score(path, &model))
}

/// The error of a record with no sample past the model's seed.
pub(crate) fn too_short_to_score(path: &Path, model: &ArxModel<f64>) -> IdError {
    let m = model.structure().seed_len();
    IdError::file(
        path,
        format!(
            "too short to score the model: its first {m} samples only seed the predictors, at least {} data rows needed",
            m + 1
        ),
    )
}
