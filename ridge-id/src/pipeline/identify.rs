//! The pipeline's identification step: the structure search on the estimation statistics
//! (or RLS on the structure it picks), the model in absolute terms ([`identify`] →
//! [`Identified`]); the RSS and score of any model on the run's statistics ([`rescore`]);
//! and why no candidate could be fitted.

use ridge_core_host::{
    ArxModel, Error as CoreError, Grid, MethodKind, Normal, Rls, Scale, Search, Structure,
};

use super::read::Records;
use crate::error::IdError;
use crate::eval::{RecordStats, TINY_PRODUCT};
use crate::input::Input;
use crate::numfmt::typed;
use crate::options::Options;
use crate::outcome::SearchInfo;
use crate::phase;

/// The model the estimator found, and how.
#[derive(Debug)]
pub(super) struct Identified {
    /// The search run (for `--select free-run`, which looks at every candidate's fit).
    pub search: Search<f64>,
    /// Its statistics.
    pub info: SearchInfo,
    /// The model of the statistics (of the deviations from the operating point with
    /// `--phase`), in the data's units, for the warnings.
    pub fitted: ArxModel<f64>,
    /// The model reported and scored: the absolute one.
    pub model: ArxModel<f64>,
    /// Ridge-M iterates / adaptive-LASSO sweeps / 1 for closed forms / samples for RLS.
    pub iterations: u32,
    /// `‖y − Xw‖²` on the estimation statistics.
    pub rss: f64,
    /// Criterion value of the model.
    pub score: f64,
}

/// Runs the structure search of `opts` on `rec`'s statistics and, for `--method rls`, RLS on
/// the structure it picks (see [`crate::options::Options::method`]).
///
/// Errors: no candidate can be fitted (the reason named), a diverging RLS update, a model
/// that cannot be scored or made absolute.
pub(super) fn identify(opts: &Options, rec: &Records) -> Result<Identified, IdError> {
    let grid = rec.grid;
    let search = Search {
        grid,
        offset: opts.offset,
        criterion: opts.criterion,
        alpha: opts.hyper.alpha,
        method: opts.core_method(),
        prune: true,
    };
    let (est_normal, val_normal) = rec.search_normals();
    let sel = search.run(est_normal, val_normal).map_err(|e| match e {
        CoreError::NoCandidate => match (&rec.val, &rec.val_normal) {
            (Some(v), Some(vn)) if no_fit_on(vn, &grid, opts) => no_candidate(v, vn, &grid, opts),
            _ => no_candidate(&rec.est, &rec.est_normal, &grid, opts),
        },
        other => IdError::Usage(format!("structure search: {other}")),
    })?;
    let (fitted, iterations, rss, score) = match opts.method {
        MethodKind::Rls => {
            let (model, samples) = run_rls(opts, &rec.est_in, sel.structure())?;
            let (rss, score) = rescore(opts, rec, &model, "the RLS model")?;
            (model, samples, rss, score)
        }
        _ => match &rec.standard {
            Some(st) => {
                // Fitted on the standardised record: back to the data's units, scored there.
                let model = in_data_units(&sel.fit.model(), st.scale)?;
                let (rss, score) = rescore(opts, rec, &model, "the model")?;
                (model, sel.fit.iterations, rss, score)
            }
            None => (sel.fit.model(), sel.fit.iterations, sel.fit.rss, sel.score),
        },
    };
    let model = match rec.shift {
        Some(op) => phase::absolute_model(&fitted, op)
            .map_err(|e| IdError::file(rec.est_in.name(), format!("absolute model: {e}")))?,
        None => fitted,
    };
    Ok(Identified {
        search,
        info: SearchInfo {
            candidates: sel.candidates,
            evaluated: sel.evaluated,
            skipped: sel.skipped,
            fixed: opts.structure.is_some(),
        },
        fitted,
        model,
        iterations,
        rss,
        score,
    })
}

/// `model`, fitted on samples times `scale` (e.g. the standardised record), in the data's
/// units: the same θ and delay, `φ` times `scale.u / scale.y`, the intercept divided by
/// `scale.y`.
///
/// Errors: coefficients that leave `f64` ([`ridge_core_host::Error::NonFinite`]).
pub(super) fn in_data_units(model: &ArxModel<f64>, scale: Scale) -> Result<ArxModel<f64>, IdError> {
    let phi: Vec<f64> = model.phi().iter().map(|f| f * scale.u / scale.y).collect();
    ArxModel::new(
        model.theta(),
        &phi,
        model.structure().d,
        model.offset(),
        model.intercept() / scale.y,
    )
    .map_err(|e| IdError::Usage(format!("the model in the data's units: {e}")))
}

/// The RSS of `model` on the estimation statistics and its criterion value, scored as the
/// search scores its candidates: on the validation statistics for `validation`, else on the
/// estimation statistics. `what` names the model in an error (`the model`).
///
/// Errors: the statistics cannot score the model (a lag they do not hold, a non-finite
/// coefficient).
pub(super) fn rescore(
    opts: &Options,
    rec: &Records,
    model: &ArxModel<f64>,
    what: &str,
) -> Result<(f64, f64), IdError> {
    let rss_of = |n: &Normal<f64>, path: &std::path::Path| {
        n.rss(model)
            .map_err(|e| IdError::file(path, format!("cannot score {what}: {e}")))
    };
    let rss = rss_of(&rec.est_normal, rec.est_in.name())?;
    let (score_rss, score_samples) = match (&rec.val_normal, &rec.val) {
        (Some(vn), Some(v)) => (rss_of(vn, &v.path)?, vn.samples()),
        _ => (rss, rec.est_normal.samples()),
    };
    let score = opts.criterion.value(
        opts.hyper.alpha,
        score_rss,
        score_samples,
        model.structure(),
        opts.offset,
    );
    Ok((rss, score))
}

/// Runs RLS on the estimation record, one update per sample.
fn run_rls(
    opts: &Options,
    input: &Input,
    structure: Structure,
) -> Result<(ArxModel<f64>, u32), IdError> {
    let mut rls = Rls::new(structure, opts.offset, opts.hyper.lambda, opts.hyper.delta)
        .map_err(|e| IdError::Usage(format!("rls: {e}")))?;
    for s in input.samples()? {
        let s = s?;
        rls.update(s.u, s.y).map_err(|e| {
            let hint = if opts.hyper.lambda < 1.0 {
                format!(
                    "with --lambda {} the covariance grows by 1/lambda = {} a sample in \
                     the directions the data do not excite: use a lambda closer to 1 (e.g. \
                     0.98 to 1), or a smaller --delta (now {})",
                    typed(opts.hyper.lambda),
                    typed(1.0 / opts.hyper.lambda),
                    typed(opts.hyper.delta)
                )
            } else {
                format!(
                    "try a smaller --delta (now {}: P0 = delta I)",
                    typed(opts.hyper.delta)
                )
            };
            IdError::line(
                input.name(),
                s.line,
                format!("the RLS update diverged here ({e}); {hint}"),
            )
        })?;
    }
    Ok((rls.model(), rls.samples()))
}

/// Explains why no candidate of `grid` could be fitted on `normal`.
fn no_candidate(rec: &RecordStats, normal: &Normal<f64>, grid: &Grid, opts: &Options) -> IdError {
    let offset = opts.offset;
    let mut singular = 0usize;
    let mut short = 0usize;
    let mut infinite = 0usize;
    for s in grid.iter() {
        match normal.system(s, offset).and_then(|sys| sys.factor(0.0)) {
            Err(CoreError::TooShort { .. }) => short += 1,
            Err(CoreError::NotPositiveDefinite) => singular += 1,
            Ok(f) => {
                let v = opts.criterion.value(
                    opts.hyper.alpha,
                    f.rss_min(),
                    normal.samples(),
                    s,
                    offset,
                );
                infinite += usize::from(!v.is_finite());
            }
            _ => {}
        }
    }
    let (u, y) = rec.largest();
    let tiny = rec.tiny();
    let smallest_k = grid
        .iter()
        .map(|s| s.params(offset) + usize::from(s.d))
        .min()
        .unwrap_or(1) as f64;
    let detail = if tiny && singular > 0 {
        format!(
            "the values are too small for f64 statistics (largest |u| {u:e}, largest |y| {y:e}: \
             products of two samples fall below {TINY_PRODUCT:e}, near the f64 underflow); \
             multiply the columns by a power of ten"
        )
    } else if singular > 0 && short == 0 {
        "the normal equations are singular: the input does not excite these structures \
         (too few distinct input values or a too-regular input)"
            .to_string()
    } else if infinite > 0 && singular == 0 && short == 0 {
        if !(opts.hyper.alpha * smallest_k).is_finite() {
            format!(
                "the criterion is not finite for any candidate: --alpha {:e} times the number \
                 of coefficients overflows f64; use a smaller --alpha",
                opts.hyper.alpha
            )
        } else {
            "the criterion N ln(RSS/N) + penalty is not finite for any candidate (RSS 0 or \
             overflowing: rescale the data)"
                .to_string()
        }
    } else {
        format!(
            "{singular} candidates singular (insufficient excitation), {short} longer than the \
             record, {infinite} with a criterion that is not finite"
        )
    };
    let which = if grid.len() == 1 {
        "the structure could not be fitted".to_string()
    } else {
        format!(
            "none of the {} candidate structures could be fitted",
            grid.len()
        )
    };
    IdError::file(
        &rec.path,
        format!("{which} on {}: {detail}", rec.describe_rows()),
    )
}

/// `true` when no candidate of `grid` can be fitted on `normal` (least squares).
fn no_fit_on(normal: &Normal<f64>, grid: &Grid, opts: &Options) -> bool {
    grid.iter().all(|s| {
        normal
            .system(s, opts.offset)
            .and_then(|sys| sys.factor(0.0))
            .is_err()
    })
}
