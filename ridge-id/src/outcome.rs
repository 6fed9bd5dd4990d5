//! The outcome of an identification run: [`Report`], everything the run produced, as data.
//! Its renderings, readable text and one JSON object, are the printers' ([`crate::printer`]).

use std::path::PathBuf;

use ridge_core_host::{ArxModel, Criterion, MethodKind};

use crate::control::ControlReport;
use crate::eval::Figures;
use crate::options::{Hyper, Select};
use crate::phase::SegmentInfo;
use crate::refine::Refinement;
use crate::warnings::Warning;

/// How the structure was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SearchInfo {
    /// Candidates in the grid (1 with `--structure`).
    pub candidates: u16,
    /// Candidates the estimator ran on. The rest were pruned exactly: least squares
    /// minimises the RSS, so a candidate's least-squares criterion is a lower bound of its
    /// score, and candidates whose bound is worse than the best score found are skipped.
    pub evaluated: u16,
    /// Candidates that could not be fitted (too short, or not excited on this record).
    pub skipped: u16,
    /// `true` when the structure was given (`--structure`).
    pub fixed: bool,
}

/// A setting the run chose for the user (a default that depends on the data, or one that a
/// newcomer would not expect), and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Choice {
    /// The option it stands for, without dashes: `gamma`, `offset`, `select`, `refine`.
    pub setting: &'static str,
    /// What was chosen, e.g. `free-run`.
    pub value: String,
    /// Why, in one line.
    pub why: String,
}

/// Everything an identification run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Estimation record.
    pub input: PathBuf,
    /// Its number of samples `N`.
    pub input_rows: u32,
    /// Validation record, if any.
    pub validate: Option<PathBuf>,
    /// Its number of samples.
    pub validate_rows: Option<u32>,
    /// Estimator.
    pub method: MethodKind,
    /// Structure criterion.
    pub criterion: Criterion,
    /// The identified model (structure, θ, φ, offset).
    pub model: ArxModel<f64>,
    /// Criterion value of the model (on the validation statistics for `validation`).
    pub score: f64,
    /// Ridge-M iterates / adaptive-LASSO sweeps / 1 for closed forms / samples for RLS.
    pub iterations: u32,
    /// `‖y − Xw‖²` on the estimation record's regression rows (rows `M+1..N` from measured
    /// initial conditions, all rows with zero history: [`Hyper::initial`]).
    pub rss: f64,
    /// Hyper-parameters.
    pub hyper: Hyper,
    /// Search statistics.
    pub search: SearchInfo,
    /// Scores on the estimation record.
    pub estimation: Figures,
    /// Scores on the validation record.
    pub validation: Option<Figures>,
    /// The PNG written, if any.
    pub plot: Option<PathBuf>,
    /// The PNG of the residual analysis written (`--plot`), if any.
    pub residuals_plot: Option<PathBuf>,
    /// How the structure was chosen (resolved: never [`Select::Auto`]).
    pub select: Select,
    /// What `--refine oe` did, if asked.
    pub refinement: Option<Refinement>,
    /// Samples `M` that only filled the lag history (0 with
    /// [`Initial::Zero`](crate::initial::Initial::Zero)).
    pub initial_samples: u32,
    /// The controller design of `--control` (or why it was refused).
    pub control: Option<ControlReport>,
    /// The PNG of the simulated closed-loop step written (`--control --plot`), if any.
    pub control_plot: Option<PathBuf>,
    /// What should not be trusted about the model ([`crate::warnings`]); empty when all
    /// is well.
    pub warnings: Vec<Warning>,
    /// The segment of a pump's capture used as the estimation record (`--phase`), with the
    /// pump's own result for it.
    pub segment: Option<SegmentInfo>,
    /// The standard deviations `(σ_u, σ_y)` of the estimation record the estimator divided
    /// the records by ([`crate::options::GammaScale::Standardised`]); `None`: it ran on the
    /// data as they are.
    pub standardised: Option<(f64, f64)>,
    /// The settings the run chose for the user, and why ([`Choice`]).
    pub choices: Vec<Choice>,
}
