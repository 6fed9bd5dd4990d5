//! The identification run, [`run`]: a pipeline of steps, each a function returning a struct,
//! computation first and presentation last:
//!
//! 1. read (`read.rs`, `read` → `Records`): the records into their statistics;
//! 2. identify (`identify.rs`, `identify` → `Identified`): the structure search (or RLS on its
//!    structure), the model made absolute around `--phase`'s operating point;
//! 3. select/refine (`tune.rs`, `tune` → `Tuned`): `--select free-run`, `--refine oe`, a
//!    changed model rescored (`identify::rescore`, the one home of RSS and score);
//! 4. score (`score.rs`, `score` → `Scored`): figures and residual analysis on each record,
//!    and the plot's traces;
//! 5. control (`controller.rs`, `control` → `Controlled`): `--control`'s design and, with
//!    `--plot`, its simulated setpoint step;
//! 6. render (`render.rs`, `render` → `Plots`): the PNGs of `--plot`;
//!
//! then the warnings, and the [`Report`] that the printers render ([`crate::printer`]).

mod choices;
mod controller;
mod identify;
mod read;
mod render;
mod score;
mod tune;

pub use read::rows_needed;

use crate::error::IdError;
use crate::options::Options;
use crate::outcome::Report;
use crate::plot;
use crate::warnings;

/// Identifies an ARX model as `opts` says and scores it (see the [module docs](self)).
///
/// With [`Options::control`], also checks the model and designs its controller
/// ([`crate::control::control`]); a refusal is reported in [`Report::control`], not as an
/// error.
///
/// Errors: bad options ([`IdError::Usage`]); unreadable or malformed records, records
/// too short for the grid or without excitation (file and line named); a plot that
/// cannot be written.
pub fn run(opts: &Options) -> Result<Report, IdError> {
    opts.check()?;
    if let Some(p) = &opts.plot {
        plot::check_output(p)?;
    }
    let rec = read::read(opts)?;
    let id = identify::identify(opts, &rec)?;
    let tuned = tune::tune(opts, &rec, &id)?;
    let model = tuned.model;
    let scored = score::score(opts, &rec, model)?;
    let ctl = controller::control(opts, &rec, &model)?;
    let plots = render::render(opts, &rec, &model, &scored, &ctl)?;
    let warnings = warnings::warnings(&warnings::Run {
        opts,
        normal: &rec.est_normal,
        model: &model,
        // The estimator's fit (of the deviations with --phase): the one whose coefficients
        // the statistics judge.
        fitted: &tuned.fitted,
        iterations: tuned.iterations,
        std: (rec.est.u_std, rec.est.y_std),
        estimation: (rec.est_in.name(), &scored.estimation),
        validation: rec
            .val_in
            .as_ref()
            .map(|v| v.name())
            .zip(scored.validation.as_ref()),
    });
    Ok(Report {
        input: rec.est_in.name().to_path_buf(),
        input_rows: rec.est.rows(),
        validate: rec.val_in.as_ref().map(|v| v.name().to_path_buf()),
        validate_rows: rec.val.as_ref().map(|v| v.rows()),
        method: opts.method,
        criterion: opts.criterion,
        model,
        score: tuned.score,
        iterations: tuned.iterations,
        rss: tuned.rss,
        hyper: opts.hyper,
        search: id.info,
        estimation: scored.estimation,
        validation: scored.validation,
        plot: opts.plot.clone(),
        initial_samples: rec.initial,
        select: tuned.select.0,
        refinement: tuned.refinement,
        residuals_plot: plots.residuals,
        control: ctl.report,
        control_plot: plots.control,
        warnings,
        standardised: rec
            .standard
            .as_ref()
            .map(|_| (rec.est.u_std, rec.est.y_std)),
        choices: choices::choices(opts, &rec, &tuned),
        segment: rec.segment.map(|s| s.info(&opts.segment)),
    })
}
