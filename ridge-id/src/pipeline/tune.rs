//! The pipeline's choice among the search's fits and refinement of the chosen model
//! (`--select free-run`, `--refine oe`, and their `auto` defaults; [`tune`] → [`Tuned`]),
//! rescored when they change it.

use ridge_core_host::ArxModel;

use super::identify::{in_data_units, rescore, Identified};
use super::read::Records;
use crate::error::IdError;
use crate::options::{Options, Refine, Select};
use crate::refine::{self, Refinement};
use crate::warnings::{input_excitation, EXCITATION_MIN};

/// The model after `--select` and `--refine`, with its figures.
#[derive(Debug)]
pub(super) struct Tuned {
    /// The model reported.
    pub model: ArxModel<f64>,
    /// The estimator's fit of the chosen structure (before any refinement), in the data's
    /// units: what the estimator's warnings judge (the deviation model with `--phase`).
    pub fitted: ArxModel<f64>,
    /// Its iterations.
    pub iterations: u32,
    /// The reported model's RSS on the estimation statistics.
    pub rss: f64,
    /// Its criterion value.
    pub score: f64,
    /// How the structure was chosen, and why when `auto` chose it.
    pub select: (Select, Option<&'static str>),
    /// The refinement asked for (resolved), and why when `auto` chose it.
    pub refine: (Refine, Option<&'static str>),
    /// What the refinement did, if one ran.
    pub refinement: Option<Refinement>,
}

/// Applies the structure choice ([`Options::select_choice`]: with [`Select::FreeRun`], the
/// search's fit with the lowest validation free-run RMSE) and the refinement
/// ([`Options::refine_choice`], src/refine.rs) to the identified model; a changed model is
/// rescored from the statistics ([`rescore`]).
///
/// Errors: a record that cannot be read again, a search that fails on its second run, a
/// model that cannot be scored.
pub(super) fn tune(opts: &Options, rec: &Records, id: &Identified) -> Result<Tuned, IdError> {
    let select = opts.select_choice();
    let refine = opts.refine_choice();
    let val_data = match (&rec.val_in, select.0, refine.0) {
        (Some(v), Select::FreeRun, _) | (Some(v), _, Refine::Oe) => Some(refine::load(v)?),
        _ => None,
    };
    let (mut fitted, mut iterations) = (id.fitted, id.iterations);
    if let (Select::FreeRun, Some(vd)) = (select.0, &val_data) {
        let (est_normal, val_normal) = rec.search_normals();
        let mut fits = Vec::new();
        id.search
            .for_each(est_normal, val_normal, |_, fit, score| {
                fits.push((fit.model(), fit.iterations, score))
            })
            .map_err(|e| IdError::Usage(format!("--select free-run: {e}")))?;
        if let Some(st) = &rec.standard {
            for (m, _, _) in &mut fits {
                *m = in_data_units(m, st.scale)?;
            }
        }
        // Only the candidates whose input lags the estimation record excites: the others'
        // φ are not determined by it (the little-excitation warning), whatever their
        // simulation on the validation record.
        let excited = |m: &ArxModel<f64>| {
            input_excitation(&rec.est_normal, m).is_none_or(|r| r >= EXCITATION_MIN)
        };
        let mut models: Vec<(ArxModel<f64>, f64)> = fits
            .iter()
            .filter(|f| excited(&f.0))
            .map(|f| (f.0, f.2))
            .collect();
        if models.is_empty() {
            models = fits.iter().map(|f| (f.0, f.2)).collect();
        }
        if let Some((best, _)) = refine::best_free_run(&models, vd) {
            iterations = fits
                .iter()
                .find(|f| f.0 == best)
                .map_or(iterations, |f| f.1);
            fitted = best;
        }
    }
    // (Free-run selection and refinement are not run with --phase: the fit is the model.)
    let mut tuned = if fitted == id.fitted {
        id.model
    } else {
        fitted
    };
    let refinement = match refine.0 {
        Refine::Oe => {
            let (m, r) = refine::refine(tuned, &rec.est_in, val_data.as_deref())?;
            tuned = m;
            Some(r)
        }
        Refine::None | Refine::Auto => None,
    };
    let (rss, score) = if tuned == id.model {
        (id.rss, id.score)
    } else {
        rescore(opts, rec, &tuned, "the model")?
    };
    Ok(Tuned {
        model: tuned,
        fitted,
        iterations,
        rss,
        score,
        select,
        refine,
        refinement,
    })
}
