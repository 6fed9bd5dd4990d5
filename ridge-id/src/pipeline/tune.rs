//! The pipeline's choice among the search's fits and refinement of the chosen model
//! (`--select free-run`, `--refine oe`; [`tune`] → [`Tuned`]), rescored when they change it.

use ridge_core_host::ArxModel;

use super::identify::{rescore, Identified};
use super::read::Records;
use crate::error::IdError;
use crate::options::{Options, Refine, Select};
use crate::refine::{self, Refinement};

/// The model after `--select` and `--refine`, with its figures.
#[derive(Debug)]
pub(super) struct Tuned {
    /// The model reported.
    pub model: ArxModel<f64>,
    /// Its RSS on the estimation statistics.
    pub rss: f64,
    /// Its criterion value.
    pub score: f64,
    /// What `--refine oe` did, if asked.
    pub refinement: Option<Refinement>,
}

/// Applies `--select free-run` (the search's fit with the lowest validation free-run RMSE)
/// and `--refine oe` (src/refine.rs) to the identified model; a changed model is rescored
/// from the statistics ([`rescore`]).
///
/// Errors: a record that cannot be read again, a search that fails on its second run, a
/// model that cannot be scored.
pub(super) fn tune(opts: &Options, rec: &Records, id: &Identified) -> Result<Tuned, IdError> {
    let val_data = match (&rec.val_in, opts.select, opts.refine) {
        (Some(v), Select::FreeRun, _) | (Some(v), _, Refine::Oe) => Some(refine::load(v)?),
        _ => None,
    };
    let mut tuned = id.model;
    if let (Select::FreeRun, Some(vd)) = (opts.select, &val_data) {
        let mut models = Vec::new();
        id.search
            .for_each(&rec.est_normal, rec.val_normal.as_ref(), |_, fit, _| {
                models.push(fit.model())
            })
            .map_err(|e| IdError::Usage(format!("--select free-run: {e}")))?;
        if let Some((best, _)) = refine::best_free_run(&models, vd) {
            tuned = best;
        }
    }
    let refinement = match opts.refine {
        Refine::Oe => {
            let (m, r) = refine::refine(tuned, &rec.est_in, val_data.as_deref())?;
            tuned = m;
            Some(r)
        }
        Refine::None => None,
    };
    let (rss, score) = if tuned == id.model {
        (id.rss, id.score)
    } else {
        rescore(opts, rec, &tuned, "the model")?
    };
    Ok(Tuned {
        model: tuned,
        rss,
        score,
        refinement,
    })
}
