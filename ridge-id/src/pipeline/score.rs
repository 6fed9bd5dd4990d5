//! The pipeline's scoring step: the model's one-step and free-run figures and residual
//! analysis on each record, with the traces of the fit plot ([`score`] → [`Scored`]).

use ridge_core_host::ArxModel;

use super::read::Records;
use crate::error::IdError;
use crate::eval::{Figures, Trace, PLOT_POINTS};
use crate::input::evaluate_input;
use crate::options::Options;

/// The model's figures on the records, and their traces for `--plot`.
#[derive(Debug)]
pub(super) struct Scored {
    /// Figures on the estimation record.
    pub estimation: Figures,
    /// Figures on the validation record, if any.
    pub validation: Option<Figures>,
    /// The estimation record's trace (`--plot`).
    pub est_trace: Option<Trace>,
    /// The validation record's trace (`--plot` with a validation record).
    pub val_trace: Option<Trace>,
}

/// Scores `model` on each record of `rec` in one pass each (absolute samples), collecting
/// the plot's traces when `opts` writes a plot.
///
/// Errors: a record that cannot be read again, or too short to score the model.
pub(super) fn score(
    opts: &Options,
    rec: &Records,
    model: ArxModel<f64>,
) -> Result<Scored, IdError> {
    let mut est_trace = opts
        .plot
        .as_ref()
        .map(|_| Trace::new(u64::from(rec.est.rows()), PLOT_POINTS));
    let estimation = evaluate_input(&rec.est_in, model, est_trace.as_mut())?;
    let mut val_trace = match (&opts.plot, &rec.val) {
        (Some(_), Some(v)) => Some(Trace::new(u64::from(v.rows()), PLOT_POINTS)),
        _ => None,
    };
    let validation = match &rec.val_in {
        Some(v) => Some(evaluate_input(v, model, val_trace.as_mut())?),
        None => None,
    };
    Ok(Scored {
        estimation,
        validation,
        est_trace,
        val_trace,
    })
}
