//! `ridge-id`: ARX identification of a logged `u`/`y` record (CSV), as a library.
//!
//! The crate is `ridge-id/` in the workspace. Its binary `ridge-id` (`src/main.rs`) only
//! calls [`cli::main`], which parses the command line (clap) and prints a [`Report`]:
//!
//! ```text
//! cargo run --release -p ridge-id -- identify --input LOG.csv [--validate VAL.csv] [--json]
//!     [--control [--speed TAU_S] [--ts SECONDS]]
//! ```
//!
//! Everything else is here, so that other programs (e.g. the paper tables, the whole-firmware
//! simulation's plots) can reuse the pieces:
//! - [`csv::CsvRecord`]: streaming CSV reader (the `csv` crate) with line-numbered errors.
//! - [`eval::read_record`]: one streaming pass into exact statistics
//!   ([`ridge_core_host::FloatGram`], `f64`).
//! - [`eval::evaluate_file`]: one streaming pass scoring a model one-step and free-run
//!   from measured initial conditions (seeded with the first `m = max(p, d + q − 1)`
//!   measured samples, scored on samples `m..N`), optionally collecting a bounded
//!   [`eval::Trace`] for [`plot::write_png`].
//! - [`Options`] (`src/options.rs`): what a run does; estimators, criteria and offsets are
//!   ridge-core's [`ridge_core_host::MethodKind`], [`ridge_core_host::Criterion`] and
//!   [`ridge_core_host::Offset`], named by their `name()` on the command line and in reports.
//! - [`run`]: the whole identification of [`Options`] → [`Report`] (`src/outcome.rs`; text or
//!   JSON by [`printer`]); every failure is an [`IdError`] (`src/error.rs`), one line naming
//!   the file, the line and the problem.
//! - [`control`] (`--control`): the firmware's controller design (ridge-core's pole placement
//!   with integral action, in `f64`) for the identified model, its checks, closed-loop poles
//!   and a simulated setpoint step ([`control::simulate_step`], [`plot::write_step_png`]). A
//!   refused controller is part of the [`Report`], not an error; the binary then exits with
//!   [`control::EXIT_REFUSED`] (3).
//!
//! Tests: `tests/cli.rs` runs the binary (JSON shape, bad input, a known ARX plant from
//! `pump-sim`, 10⁶ rows in flat memory); `tests/logged_data.rs` checks the library on the
//! two real records of `shared/data/` against an explicit regression built with nalgebra;
//! `tests/control.rs` checks `--control` against a known plant (closed-loop polynomial and
//! poles rebuilt from the JSON, the loop simulated on the true plant, refusals).
//!
//! - [`input::Input`]: a regular file (streamed for every pass) or input that can be read only
//!   once (`--input -`, a pipe, a FIFO: read once into memory, at most
//!   [`input::MEMORY_ROWS`] rows).
//! - [`phase`] (`--phase`, `--attempt`, `--operating-point`): one segment of a pump's log
//!   capture (rows of one `phase`, `#` comment lines with the pump's `EXCITE` and `ID` lines)
//!   as the estimation record, around the pump's operating point; [`device_check`]
//!   (`--device`): the firmware's identification settings (docs/real-logs.md, "Check the pump's
//!   identification on the PC"). Tested against the firmware itself in
//!   `host-tests/tests/device_log.rs`.
//! - [`warnings`]: what should not be trusted about a model (unstable, negative fit, too
//!   short or too little excited for the structure, Ridge-M stopped on a non-move), in every
//!   [`Report`]; `--strict` exits 1 on any.
//!
//! Memory is independent of the record length: the estimation record is read once for
//! the statistics, once more to score the model (and once more for RLS); the
//! validation record once for its statistics and once to score the model. The plot
//! keeps at most ~2000 points per signal (a min/max envelope for longer records).

pub mod capture;
pub mod cli;
pub mod control;
pub mod csv;
pub mod device_check;
pub mod error;
pub mod eval;
pub mod export;
pub mod initial;
pub mod input;
pub mod numfmt;
pub mod options;
pub mod outcome;
pub mod phase;
pub mod plot;
pub mod printer;
pub mod refine;
pub mod residuals;
pub mod warnings;

/// The former name of [`device_check`], kept while the workspace's other crates (host-tests,
/// simavr-harness) name `ridge_id::device::DEVICE_OPTIONS`; remove once they use
/// `device_check`.
#[doc(hidden)]
pub use device_check as device;

pub use control::{ControlOptions, ControlReport};
pub use error::IdError;
pub use eval::{evaluate_file, read_record, read_record_with, Figures, RecordStats, Trace};
pub use initial::Initial;
pub use options::Hyper;
pub use options::Options;
pub use outcome::{Report, SearchInfo};

use ridge_core_host::{
    ArxModel, Criterion, Error as CoreError, Grid, MethodKind, Normal, Rls, Search, Structure,
};

use input::{evaluate_input, Input};
use numfmt::typed;
use options::{Refine, Select};

/// Where `--plot OUT.png` puts the closed-loop step of `--control`: `OUT-control.png`, next
/// to it.
pub fn control_plot_path(plot: &std::path::Path) -> std::path::PathBuf {
    let stem = plot
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = plot
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    plot.with_file_name(format!("{stem}-control{ext}"))
}

/// Where `--plot OUT.png` puts the residual analysis: `OUT-residuals.png`, next to it.
pub fn residuals_plot_path(plot: &std::path::Path) -> std::path::PathBuf {
    let stem = plot
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = plot
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    plot.with_file_name(format!("{stem}-residuals{ext}"))
}

/// Points kept per signal for the plot.
pub const PLOT_POINTS: usize = 2000;

/// Regression rows a structure needs on a record: `m` seed samples, one per coefficient, plus
/// one (the core's [`ridge_core_host::Normal::system`] rule; with measured initial conditions
/// the record needs the `M` initial samples more).
pub fn rows_needed(s: Structure, offset: ridge_core_host::Offset) -> u32 {
    (s.seed_len() + s.params(offset) + 1) as u32
}

/// Checks that `rec` has enough rows for the smallest candidate of `grid`.
fn check_rows(
    rec: &RecordStats,
    grid: &Grid,
    offset: ridge_core_host::Offset,
) -> Result<(), IdError> {
    let Some((s, needed)) = grid
        .iter()
        .map(|s| (s, rows_needed(s, offset)))
        .min_by_key(|&(_, n)| n)
    else {
        return Ok(());
    };
    if rec.gram.rows() < needed {
        let needed = needed + rec.gram.initial();
        let which = if grid.len() == 1 {
            "structure"
        } else {
            "smallest candidate structure"
        };
        return Err(IdError::file(
            &rec.path,
            format!(
                "{}, but the {which} (p = {}, q = {}, d = {}) needs at least {needed} \
                 (m = {} seed samples, one per coefficient, plus one){}",
                rec.describe_rows(),
                s.p,
                s.q,
                s.d,
                s.seed_len(),
                rec.initial_note()
            ),
        ));
    }
    Ok(())
}

/// Products of two samples below this are too small for `f64` statistics: near the
/// subnormal range (2.2e-308) sums of squares lose their precision.
pub const TINY_PRODUCT: f64 = 1e-280;

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
    let big = |r: (f64, f64)| r.0.abs().max(r.1.abs());
    let (u, y) = (big(rec.u_range), big(rec.y_range));
    let tiny = (u * u).min(u * y).min(y * y) < TINY_PRODUCT;
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

/// Identifies an ARX model as `opts` says and scores it (see the [module docs](self)).
///
/// With [`Options::control`], also checks the model and designs its controller
/// ([`control::control`]); a refusal is reported in [`Report::control`], not as an error.
///
/// Errors: bad options ([`IdError::Usage`]); unreadable or malformed records, records
/// too short for the grid or without excitation (file and line named); a plot that
/// cannot be written.
pub fn run(opts: &Options) -> Result<Report, IdError> {
    opts.check()?;
    if let Some(p) = &opts.plot {
        plot::check_output(p)?;
    }
    let grid = opts.effective_grid();
    let initial = opts.hyper.initial.samples(&grid);
    // --phase: the estimation record is one segment of a pump's capture, its statistics
    // taken around the operating point (src/phase/).
    let segment = opts
        .segment
        .as_ref()
        .map(|s| phase::read(&opts.input, s))
        .transpose()?;
    let (est_in, val_in) = match &segment {
        Some(seg) => {
            let val = opts.validate.as_deref().map(Input::open).transpose()?;
            (seg.input(), val)
        }
        None => Input::open_pair(&opts.input, opts.validate.as_deref())?,
    };
    let shift = segment.as_ref().and_then(|s| s.operating_point);
    // Statistics of the lags the grid's candidates use only (exactly theirs).
    let gram = || ridge_core_host::MeasuredGram::for_grid(initial, &grid);
    let est = phase::read_shifted(&est_in, gram(), shift)?;
    let val = val_in
        .as_ref()
        .map(|v| phase::read_shifted(v, gram(), shift))
        .transpose()?;
    check_rows(&est, &grid, opts.offset)?;
    let est_normal = est.normal()?;
    let val_normal = match (&val, opts.criterion) {
        (Some(v), Criterion::Validation) => {
            check_rows(v, &grid, opts.offset)?;
            Some(v.normal()?)
        }
        (Some(v), _) => {
            // Not needed for the search, but a record without excitation cannot
            // validate anything: say so rather than print a meaningless fit.
            v.normal()?;
            None
        }
        (None, _) => None,
    };
    let search = Search {
        grid,
        offset: opts.offset,
        criterion: opts.criterion,
        alpha: opts.hyper.alpha,
        method: opts.core_method(),
        prune: true,
    };
    let sel = search
        .run(&est_normal, val_normal.as_ref())
        .map_err(|e| match e {
            CoreError::NoCandidate => match (&val, &val_normal) {
                (Some(v), Some(vn)) if no_fit_on(vn, &grid, opts) => {
                    no_candidate(v, vn, &grid, opts)
                }
                _ => no_candidate(&est, &est_normal, &grid, opts),
            },
            other => IdError::Usage(format!("structure search: {other}")),
        })?;
    let structure = sel.structure();
    let (model, iterations, rss, score) = match opts.method {
        MethodKind::Rls => {
            let (model, samples) = run_rls(opts, &est_in, structure)?;
            let rss_of = |n: &Normal<f64>, path: &std::path::Path| {
                n.rss(&model)
                    .map_err(|e| IdError::file(path, format!("cannot score the RLS model: {e}")))
            };
            let rss = rss_of(&est_normal, est_in.name())?;
            // Scored like the search scores its candidates: on the validation statistics
            // for `validation`, else on the estimation statistics.
            let (score_rss, score_samples) = match (&val_normal, &val) {
                (Some(vn), Some(v)) => (rss_of(vn, &v.path)?, vn.samples()),
                _ => (rss, est_normal.samples()),
            };
            let score = opts.criterion.value(
                opts.hyper.alpha,
                score_rss,
                score_samples,
                structure,
                opts.offset,
            );
            (model, samples, rss, score)
        }
        _ => (sel.fit.model(), sel.fit.iterations, sel.fit.rss, sel.score),
    };
    // The model of the statistics (of the deviations with --phase), for the warnings; the
    // model reported and scored is the absolute one.
    let fitted = model;
    let model = match shift {
        Some(op) => phase::absolute_model(&model, op)
            .map_err(|e| IdError::file(est_in.name(), format!("absolute model: {e}")))?,
        None => model,
    };

    // --select free-run and --refine oe (src/refine.rs): they change the model, whose RSS and
    // score are then computed from the statistics like the RLS model's.
    let val_data = match (&val_in, opts.select, opts.refine) {
        (Some(v), Select::FreeRun, _) | (Some(v), _, Refine::Oe) => Some(refine::load(v)?),
        _ => None,
    };
    let mut tuned = model;
    if let (Select::FreeRun, Some(vd)) = (opts.select, &val_data) {
        let mut models = Vec::new();
        search
            .for_each(&est_normal, val_normal.as_ref(), |_, fit, _| {
                models.push(fit.model())
            })
            .map_err(|e| IdError::Usage(format!("--select free-run: {e}")))?;
        if let Some((best, _)) = refine::best_free_run(&models, vd) {
            tuned = best;
        }
    }
    let refinement = match opts.refine {
        Refine::Oe => {
            let (m, r) = refine::refine(tuned, &est_in, val_data.as_deref())?;
            tuned = m;
            Some(r)
        }
        Refine::None => None,
    };
    let (model, iterations, rss, score) = if tuned == model {
        (model, iterations, rss, score)
    } else {
        let s = tuned.structure();
        let rss_of = |n: &Normal<f64>, path: &std::path::Path| {
            n.rss(&tuned)
                .map_err(|e| IdError::file(path, format!("cannot score the model: {e}")))
        };
        let new_rss = rss_of(&est_normal, est_in.name())?;
        let (score_rss, score_samples) = match (&val_normal, &val) {
            (Some(vn), Some(v)) => (rss_of(vn, &v.path)?, vn.samples()),
            _ => (new_rss, est_normal.samples()),
        };
        let score =
            opts.criterion
                .value(opts.hyper.alpha, score_rss, score_samples, s, opts.offset);
        (tuned, iterations, new_rss, score)
    };
    let structure = model.structure();

    let mut est_trace = opts
        .plot
        .as_ref()
        .map(|_| Trace::new(u64::from(est.rows()), PLOT_POINTS));
    let estimation = evaluate_input(&est_in, model, est_trace.as_mut())?;
    let mut val_trace = match (&opts.plot, &val) {
        (Some(_), Some(v)) => Some(Trace::new(u64::from(v.rows()), PLOT_POINTS)),
        _ => None,
    };
    let validation = match &val_in {
        Some(v) => Some(evaluate_input(v, model, val_trace.as_mut())?),
        None => None,
    };

    let span = control::LogSpan {
        u: est.u_range.1 - est.u_range.0,
        y: est.y_range.1 - est.y_range.0,
    };
    // The firmware's controller design, for the device's orders (p, q, d ≤ 6).
    let device = opts
        .control
        .as_ref()
        .map(|_| control::device_model(&model))
        .transpose()?;
    let control = opts
        .control
        .as_ref()
        .zip(device.as_ref())
        .map(|(c, m)| control::control(m, c, span));
    // The simulated loop's limits are checked even without --plot: bad ones are a usage
    // error whatever is printed.
    let limits = opts
        .control
        .as_ref()
        .map(|c| c.limits(est.u_range))
        .transpose()?;
    let mut control_plot = None;
    if let (Some(path), Some(report), Some(limits), Some(device)) =
        (&opts.plot, &control, limits, &device)
    {
        if let Some(designed) = report.designed() {
            if let Some(step) =
                control::simulate_step(device, &designed.design, limits, report.options.ts)
            {
                let s = structure;
                let d = &designed.design;
                let title = format!(
                    "closed-loop setpoint steps (simulated on the model): {}   ({},{},{})   \
                     pole placement, tau {} s, margin {:.2}",
                    path_name(est_in.name()),
                    s.p,
                    s.q,
                    s.d,
                    (d.tau * 1e4).round() / 1e4,
                    d.modulus_margin
                );
                let out = control_plot_path(path);
                plot::write_step_png(&out, &title, &step)?;
                control_plot = Some(out);
            }
        }
    }

    let mut residuals_plot = None;
    if let (Some(path), Some(et)) = (&opts.plot, &est_trace) {
        let s = structure;
        let title = |what: &str, p: &std::path::Path, f: &Figures| {
            format!(
                "{what}: {}   {} ({},{},{})   free-run fit {:.1} %, RMSE {:.4}",
                path_name(p),
                opts.method.name(),
                s.p,
                s.q,
                s.d,
                f.fit_free_run,
                f.rmse_free_run
            )
        };
        let mut panels = vec![plot::Panel {
            title: title("estimation", est_in.name(), &estimation),
            trace: et,
        }];
        if let (Some(vt), Some(vi), Some(vf)) = (&val_trace, &val_in, &validation) {
            panels.push(plot::Panel {
                title: title("validation", vi.name(), vf),
                trace: vt,
            });
        }
        plot::write_png(path, &panels)?;
        let mut rows = Vec::new();
        for (what, f) in [
            ("estimation", Some(&estimation)),
            ("validation", validation.as_ref()),
        ] {
            if let Some(r) = f.and_then(|f| f.residuals.as_ref()) {
                rows.push((what.to_string(), r));
            }
        }
        if !rows.is_empty() {
            let out = residuals_plot_path(path);
            plot::write_residuals_png(&out, &rows)?;
            residuals_plot = Some(out);
        }
    }

    let warnings = warnings::warnings(&warnings::Run {
        opts,
        normal: &est_normal,
        model: if shift.is_some() { &fitted } else { &model },
        iterations,
        estimation: (est_in.name(), &estimation),
        validation: val_in.as_ref().map(|v| v.name()).zip(validation.as_ref()),
    });

    Ok(Report {
        input: est_in.name().to_path_buf(),
        input_rows: est.rows(),
        validate: val_in.as_ref().map(|v| v.name().to_path_buf()),
        validate_rows: val.as_ref().map(|v| v.rows()),
        method: opts.method,
        criterion: opts.criterion,
        model,
        score,
        iterations,
        rss,
        hyper: opts.hyper,
        search: SearchInfo {
            candidates: sel.candidates,
            evaluated: sel.evaluated,
            skipped: sel.skipped,
            fixed: opts.structure.is_some(),
        },
        estimation,
        validation,
        plot: opts.plot.clone(),
        initial_samples: initial,
        select: opts.select,
        refinement,
        residuals_plot,
        control,
        control_plot,
        warnings,
        segment: segment.map(|s| s.info(&opts.segment)),
    })
}

/// The file name of `p`, for plot titles.
fn path_name(p: &std::path::Path) -> String {
    p.file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default()
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
