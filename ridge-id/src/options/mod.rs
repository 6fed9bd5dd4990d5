//! What an identification run does: [`Options`] and the settings beside it ([`Hyper`], the
//! choices [`Select`] and [`Refine`], the parsers of order ranges and structures). The names of
//! estimators, criteria and offsets are ridge-core's ([`MethodKind`], [`Criterion`],
//! [`Offset`]: `name()` and `FromStr`).

use std::path::PathBuf;

mod choices;
mod hyper;
mod parse;

pub use choices::{Refine, Select};
pub use hyper::{GammaScale, Hyper, STANDARDISED_GAMMA};
pub use parse::{parse_range, parse_structure};

use ridge_core_host::{
    AdaptiveLasso, Criterion, Grid, Method as CoreMethod, MethodKind, Offset, Ridge, RidgeM,
    Structure,
};

use crate::control::ControlOptions;
use crate::error::IdError;
use crate::initial::Initial;
use crate::phase::SegmentOptions;

/// Largest `--max-iter` accepted. Each Ridge-M iterate costs ~0.16 µs (p = q = 6, two
/// triangular solves), so the worst case — all 252 candidates of the default grid
/// evaluated, `--tol 0` — is ~4 s (measured: 4.1 s with `--gamma 1e8`, which defeats the
/// pruning); the paper's 200 iterates settle every record tried.
pub const MAX_ITER_LIMIT: u32 = 100_000;

/// Everything an identification run needs; [`Options::new`] gives the defaults of the
/// `ridge-id` command line.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Estimation record (CSV with `u` and `y` columns).
    pub input: PathBuf,
    /// Optional validation record, scored like the estimation record; required by
    /// [`Criterion::Validation`].
    pub validate: Option<PathBuf>,
    /// Estimator (default `ridge-m`). [`MethodKind::Rls`] runs recursive least squares,
    /// sample by sample over the estimation record, on the structure a Ridge-M search picks
    /// (or [`Options::structure`]); [`MethodKind::AdaptiveLasso`] is
    /// [`AdaptiveLasso::default`] (weights from least squares, λ by BIC).
    pub method: MethodKind,
    /// Structure criterion (default: delay-free AIC, the core's default, which unlike the
    /// paper's criterion can find a true delay; see [`Criterion`]).
    pub criterion: Criterion,
    /// Hyper-parameters (defaults: [`Hyper::default`], the paper's but for `γ`, which is
    /// scale-free; [`Hyper::paper`] is the paper's).
    pub hyper: Hyper,
    /// Search grid (default p 1..=6, q 1..=6, d 0..=6); ignored when `structure` is set.
    pub grid: Grid,
    /// A fixed structure (a single-point grid).
    pub structure: Option<Structure>,
    /// Constant term (default [`Offset::Intercept`]: estimated, never shrunk, so that a log
    /// with an offset — a sensor's zero, a pump's dead zone, an output level — is modelled;
    /// [`Offset::None`] is the paper's model).
    pub offset: Offset,
    /// Write a PNG of measured, one-step and free-run output here (with `control`, also the
    /// simulated closed-loop step to [`crate::plot::control_plot_path`] of it).
    pub plot: Option<PathBuf>,
    /// Design a controller for the identified model (`--control`; see [`crate::control`]).
    pub control: Option<ControlOptions>,
    /// How the structure is chosen (default [`Select::Auto`], see
    /// [`Options::select_choice`]).
    pub select: Select,
    /// Output-error refinement of the chosen model (default [`Refine::Auto`], see
    /// [`Options::refine_choice`]).
    pub refine: Refine,
    /// The estimation record is one segment of a pump's log capture (`--phase`, see
    /// [`crate::phase`]); `None`: the whole of [`Options::input`].
    pub segment: Option<SegmentOptions>,
}

impl Options {
    /// The defaults of `ridge-id identify --input INPUT`.
    pub fn new(input: impl Into<PathBuf>) -> Self {
        Options {
            input: input.into(),
            validate: None,
            method: MethodKind::RidgeM,
            criterion: Criterion::Aic,
            hyper: Hyper::default(),
            grid: Grid::default(),
            structure: None,
            offset: Offset::Intercept,
            plot: None,
            control: None,
            select: Select::Auto,
            refine: Refine::Auto,
            segment: None,
        }
    }

    /// The paper's Ridge-M settings on `input`: [`Hyper::paper`] (`γ = 1000` in the data's
    /// units), the paper's criterion, zero history before the record (eq. 6), no offset, the
    /// structure by the criterion and no refinement.
    pub fn paper(input: impl Into<PathBuf>) -> Self {
        let mut o = Options::new(input);
        o.hyper = Hyper {
            initial: Initial::Zero,
            ..Hyper::paper()
        };
        o.criterion = Criterion::Paper;
        o.offset = Offset::None;
        o.select = Select::Criterion;
        o.refine = Refine::None;
        o
    }

    /// [`Options::select`] resolved, and why when it was [`Select::Auto`]: the lowest
    /// validation free-run RMSE ([`Select::FreeRun`]) when a validation record is given, for
    /// a search (no fixed structure) of the estimator's own fits (not `rls`), on a whole record
    /// (not `--phase`, which reads one segment only); else the criterion.
    pub fn select_choice(&self) -> (Select, Option<&'static str>) {
        match self.select {
            Select::Auto if self.validate.is_none() => (Select::Criterion, None),
            Select::Auto
                if self.structure.is_none()
                    && self.method != MethodKind::Rls
                    && self.segment.is_none() =>
            {
                (Select::FreeRun, Some("a validation record is given"))
            }
            Select::Auto => (Select::Criterion, None),
            s => (s, None),
        }
    }

    /// [`Options::refine`] resolved, and why when it was [`Refine::Auto`]: the output-error
    /// refinement ([`Refine::Oe`], kept only if it lowers the validation free-run RMSE) when
    /// a validation record is given, not with `rls` or `--phase`; else none.
    pub fn refine_choice(&self) -> (Refine, Option<&'static str>) {
        match self.refine {
            Refine::Auto
                if self.validate.is_some()
                    && self.method != MethodKind::Rls
                    && self.segment.is_none() =>
            {
                (Refine::Oe, Some("a validation record is given"))
            }
            Refine::Auto => (Refine::None, None),
            r => (r, None),
        }
    }

    /// `true` when the estimator runs on the standardised record
    /// ([`GammaScale::Standardised`]): Ridge-M and Ridge (and the Ridge-M search of `rls`),
    /// whose `γ` depends on the units. Least squares and the adaptive LASSO do not depend on
    /// them and run on the data as they are.
    pub fn standardises(&self) -> bool {
        self.hyper.gamma_scale == GammaScale::Standardised
            && matches!(
                self.method,
                MethodKind::RidgeM | MethodKind::Ridge | MethodKind::Rls
            )
    }

    /// The grid actually searched: the fixed structure, or [`Options::grid`].
    pub fn effective_grid(&self) -> Grid {
        self.structure.map(Grid::single).unwrap_or(self.grid)
    }

    /// The Ridge-M estimator of these options.
    pub fn ridge_m(&self) -> RidgeM<f64> {
        RidgeM {
            gamma: self.hyper.gamma,
            beta: self.hyper.beta,
            tol: self.hyper.tol,
            max_iter: self.hyper.max_iter,
        }
    }

    /// The core estimator run on each candidate: the method itself, or Ridge-M for
    /// `rls` (which is not a Gram method: it only borrows the search's structure).
    pub fn core_method(&self) -> CoreMethod<f64> {
        match self.method {
            MethodKind::RidgeM | MethodKind::Rls => CoreMethod::RidgeM(self.ridge_m()),
            MethodKind::Ridge => CoreMethod::Ridge(Ridge {
                gamma: self.hyper.gamma,
            }),
            MethodKind::Ols => CoreMethod::Ols,
            MethodKind::AdaptiveLasso => CoreMethod::AdaptiveLasso(AdaptiveLasso::default()),
        }
    }

    /// Checks values and combinations, with a message naming the option.
    pub fn check(&self) -> Result<(), IdError> {
        let bad = |m: String| Err(IdError::Usage(m));
        if !(self.hyper.gamma.is_finite() && self.hyper.gamma > 0.0) {
            return bad(format!(
                "--gamma {}: must be a number above 0",
                self.hyper.gamma
            ));
        }
        if !(self.hyper.beta.is_finite() && (0.0..1.0).contains(&self.hyper.beta)) {
            return bad(format!("--beta {}: must be in [0, 1)", self.hyper.beta));
        }
        if !(self.hyper.alpha.is_finite() && self.hyper.alpha >= 0.0) {
            return bad(format!(
                "--alpha {}: must be a number ≥ 0",
                self.hyper.alpha
            ));
        }
        if !(1..=MAX_ITER_LIMIT).contains(&self.hyper.max_iter) {
            return bad(format!(
                "--max-iter {}: must be a whole number in 1..={MAX_ITER_LIMIT} (the bound keeps \
                 a run within seconds: every searched structure may iterate that often)",
                self.hyper.max_iter
            ));
        }
        if !(self.hyper.tol.is_finite() && self.hyper.tol >= 0.0) {
            return bad(format!("--tol {}: must be a number ≥ 0", self.hyper.tol));
        }
        if !(self.hyper.lambda.is_finite() && self.hyper.lambda > 0.0 && self.hyper.lambda <= 1.0) {
            return bad(format!("--lambda {}: must be in (0, 1]", self.hyper.lambda));
        }
        if !(self.hyper.delta.is_finite() && self.hyper.delta > 0.0) {
            return bad(format!(
                "--delta {}: must be a number above 0",
                self.hyper.delta
            ));
        }
        if self.criterion == Criterion::Validation && self.validate.is_none() {
            return bad(
                "--criterion validation needs a validation record: add --validate VAL.csv".into(),
            );
        }
        if self.select == Select::FreeRun && self.validate.is_none() {
            return bad(
                "--select free-run needs a validation record: add --validate VAL.csv".into(),
            );
        }
        if self.select == Select::FreeRun && self.method == MethodKind::Rls {
            return bad(
                "--select free-run chooses among the search's fits: not with --method rls".into(),
            );
        }
        if let Err(e) = self.effective_grid().check() {
            return bad(format!("search ranges: {e}"));
        }
        if let Some(c) = &self.control {
            c.check()?;
        }
        if let Some(seg) = &self.segment {
            if seg.phase.trim().is_empty() {
                return bad("--phase: give the phase name, e.g. --phase excite".into());
            }
            // These read the whole --input file again by its path.
            for (on, what) in [
                (self.method == MethodKind::Rls, "--method rls"),
                (self.select == Select::FreeRun, "--select free-run"),
                (self.refine == Refine::Oe, "--refine oe"),
                (self.input.as_os_str() == "-", "--input - (standard input)"),
            ] {
                if on {
                    return bad(format!(
                        "--phase: not with {what}, which would read the whole capture"
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn core_method_is_the_method_and_ridge_m_for_rls() {
        let mut o = Options::new("x.csv");
        for m in MethodKind::ALL {
            o.method = m;
            let want = if m == MethodKind::Rls {
                MethodKind::RidgeM
            } else {
                m
            };
            assert_eq!(o.core_method().kind(), want);
        }
        o.method = MethodKind::RidgeM;
        o.hyper.gamma = 7.0;
        o.hyper.max_iter = 3;
        match o.core_method() {
            CoreMethod::RidgeM(r) => assert_eq!((r.gamma, r.max_iter), (7.0, 3)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn checks() {
        let mut o = Options::new("x.csv");
        assert!(o.check().is_ok());
        o.criterion = Criterion::Validation;
        assert!(o.check().unwrap_err().to_string().contains("--validate"));
        let mut o = Options::new("x.csv");
        o.hyper.beta = 1.0;
        assert!(o.check().unwrap_err().to_string().starts_with("--beta"));
    }
}
