//! Warnings: a run that produced a model, but one that should not be trusted as it is.
//!
//! Each check is independent and returns at most one [`Warning`]; [`warnings`] runs them
//! all on a finished run. A report always carries its warnings (text: a `warnings` section;
//! JSON: `"warnings": [str, …]`, empty when all is well); `ridge-id --strict` exits with
//! status 1 when there is any.
//!
//! | kind | when |
//! |---|---|
//! | [`WarningKind::Unstable`] | a pole of the model, a root of `A(z) = 1 − θ₁ z⁻¹ − …`, has `|z| ≥ 1`: the free run diverges or never settles |
//! | [`WarningKind::NegativeFit`] | a free-run fit below 0 % (or not finite): the simulation is worse than the record's mean |
//! | [`WarningKind::TooShort`] | fewer than [`ROWS_PER_COEFFICIENT`] (10) estimation rows past the `m` seed samples per coefficient |
//! | [`WarningKind::LittleExcitation`] | the input is not persistently exciting of order `q`: the smallest eigenvalue of the covariance of its `q` lags is below [`EXCITATION_MIN`] (1e-5) of the largest |
//! | [`WarningKind::NonMove`] | Ridge-M stopped on a step below `--tol` while still more than [`NON_MOVE_GAP`] (1 %) away from its fixed point, the least-squares fit: it barely moved, it did not converge |
//! | [`WarningKind::MaxIter`] | Ridge-M stopped at `--max-iter` while still more than [`NON_MOVE_GAP`] (1 %) away from its fixed point: it did not converge |
//! | [`WarningKind::Shrunk`] | Ridge or the adaptive LASSO returned coefficients more than [`NON_MOVE_GAP`] (1 %) away from least squares on the same columns |
//!
//! The distances to least squares are measured on the standardised coefficients (`θ`,
//! `φ σ_u / σ_y`, `c / σ_y`, with the estimation record's standard deviations), so that they do
//! not depend on the units of `u` and `y`; least squares is fitted to the same structure on the
//! same statistics.

use std::path::Path;

use nalgebra::{DMatrix, SymmetricEigen};
use ridge_core_host::{ArxModel, Estimator, MethodKind, Normal, Offset, Ols, Regressor, System};

use crate::control::{denominator, roots};
use crate::eval::Figures;
use crate::numfmt::typed;
use crate::options::Options;

/// Rows per coefficient below which a record is too short for a structure (a rule of
/// thumb: with fewer, the coefficients' standard errors are of the order of the
/// coefficients of a typical noisy log).
pub const ROWS_PER_COEFFICIENT: usize = 10;

/// Smallest ratio of the smallest to the largest eigenvalue of the input's lag covariance
/// (order `q`) taken as excitation. A sine is exciting of order 2 only: with `q = 3` its
/// ratio is ~1e-7; a single step ~1e-4, a random binary signal ~0.9, the real records of
/// `shared/data` 5e-4 … 0.05.
pub const EXCITATION_MIN: f64 = 1e-5;

/// Relative distance `‖w − w_ls‖ / ‖w_ls‖` of the standardised coefficients from the
/// least-squares fit above which a Ridge-M run did not converge, and a shrinking estimator's
/// coefficients are shrunk.
pub const NON_MOVE_GAP: f64 = 0.01;

/// What a warning is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WarningKind {
    /// A model pole on or outside the unit circle.
    Unstable,
    /// A free-run fit below 0 % (or not finite).
    NegativeFit,
    /// Too few rows for the structure's coefficients.
    TooShort,
    /// An input not persistently exciting of the structure's input order.
    LittleExcitation,
    /// Ridge-M stopped on its tolerance far from its fixed point.
    NonMove,
    /// Ridge-M stopped at its iteration limit far from its fixed point.
    MaxIter,
    /// Ridge or the adaptive LASSO shrunk the coefficients away from least squares.
    Shrunk,
}

impl WarningKind {
    /// Short name: `unstable`, `negative-fit`, `too-short`, `little-excitation`, `non-move`,
    /// `max-iter`, `shrunk`.
    pub const fn name(self) -> &'static str {
        match self {
            WarningKind::Unstable => "unstable",
            WarningKind::NegativeFit => "negative-fit",
            WarningKind::TooShort => "too-short",
            WarningKind::LittleExcitation => "little-excitation",
            WarningKind::NonMove => "non-move",
            WarningKind::MaxIter => "max-iter",
            WarningKind::Shrunk => "shrunk",
        }
    }
}

/// One warning: its kind and a one-line message with the numbers behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct Warning {
    /// What it is about.
    pub kind: WarningKind,
    /// The message (one line, no trailing period), e.g. `unstable model: …`.
    pub message: String,
}

impl Warning {
    fn new(kind: WarningKind, message: String) -> Self {
        Warning { kind, message }
    }
}

/// What the checks look at: a finished run's pieces.
#[derive(Debug, Clone, Copy)]
pub struct Run<'a> {
    /// The run's options.
    pub opts: &'a Options,
    /// Statistics of the estimation record (physical units; the deviations from the operating
    /// point with `--phase`).
    pub normal: &'a Normal<f64>,
    /// The identified model.
    pub model: &'a ArxModel<f64>,
    /// The estimator's fit of the model's structure before any refinement, on the statistics
    /// of [`Run::normal`] in their units.
    pub fitted: &'a ArxModel<f64>,
    /// The estimator's iterations for it (Ridge-M iterates for `ridge-m`).
    pub iterations: u32,
    /// The estimation record's standard deviations `(σ_u, σ_y)`.
    pub std: (f64, f64),
    /// The estimation record's name and scores.
    pub estimation: (&'a Path, &'a Figures),
    /// The validation record's name and scores, if any.
    pub validation: Option<(&'a Path, &'a Figures)>,
}

/// Every warning of a finished run, in the order of the table in the [module docs](self).
pub fn warnings(run: &Run<'_>) -> Vec<Warning> {
    let mut out = Vec::new();
    out.extend(unstable(run.model));
    for (which, (path, f)) in std::iter::once(("estimation", run.estimation))
        .chain(run.validation.map(|v| ("validation", v)))
    {
        out.extend(negative_fit(which, path, f));
    }
    out.extend(too_short(run.normal.samples(), run.model));
    out.extend(little_excitation(run.normal, run.model));
    match run.opts.method {
        MethodKind::RidgeM => out.extend(non_move(run)),
        MethodKind::Ridge | MethodKind::AdaptiveLasso => out.extend(shrunk(run)),
        MethodKind::Ols | MethodKind::Rls => {}
    }
    out
}

/// [`WarningKind::Unstable`]: the largest `|z|` of the model's poles is 1 or more.
pub fn unstable(model: &ArxModel<f64>) -> Option<Warning> {
    let poles = roots(&denominator(model.theta()), 0.0);
    let largest = poles
        .as_ref()
        .and_then(|p| p.first())
        .map(|p| p.norm())
        .unwrap_or(f64::INFINITY);
    (largest.is_nan() || largest >= 1.0).then(|| {
        Warning::new(
            WarningKind::Unstable,
            format!(
                "unstable model: a pole at |z| = {largest:.4} (1 or more): its free run \
                 diverges or never settles; try a smaller structure, --offset intercept or \
                 more data"
            ),
        )
    })
}

/// [`WarningKind::NegativeFit`]: the free-run fit of `which` record (`path`) is below 0 %.
pub fn negative_fit(which: &str, path: &Path, f: &Figures) -> Option<Warning> {
    let fit = f.fit_free_run;
    (fit.is_nan() || fit < 0.0).then(|| {
        Warning::new(
            WarningKind::NegativeFit,
            format!(
                "negative fit: the free-run fit on the {which} record ({}) is {fit:.1} %: the \
                 model's simulation is worse than the record's mean",
                path.display()
            ),
        )
    })
}

/// [`WarningKind::TooShort`]: fewer than [`ROWS_PER_COEFFICIENT`] rows past the seed per
/// coefficient of `model`, on a record of `rows` rows.
pub fn too_short(rows: u32, model: &ArxModel<f64>) -> Option<Warning> {
    let s = model.structure();
    let k = s.params(model.offset());
    let m = s.seed_len();
    let usable = (rows as usize).saturating_sub(m);
    (usable < ROWS_PER_COEFFICIENT * k).then(|| {
        Warning::new(
            WarningKind::TooShort,
            format!(
                "record too short for the structure ({},{},{}): {rows} rows, {usable} past the \
                 {m} seed samples, for {k} coefficients (at least {} wanted, \
                 {ROWS_PER_COEFFICIENT} per coefficient)",
                s.p,
                s.q,
                s.d,
                m + ROWS_PER_COEFFICIENT * k
            ),
        )
    })
}

/// The ratio of the smallest to the largest eigenvalue of the covariance of the input lags
/// `u_{t−d} … u_{t−d−q+1}` of `model`'s structure on `normal`'s record (mean removed; the
/// zero history before the record included, as in the regression); `None` when `q = 1`
/// (always 1) or the record is too short for the structure.
pub fn input_excitation(normal: &Normal<f64>, model: &ArxModel<f64>) -> Option<f64> {
    let s = model.structure();
    if s.q < 2 {
        return None;
    }
    // With an intercept the augmented matrix holds the column sums as well.
    let sys = normal.system(s, Offset::Intercept).ok()?;
    let n = sys.params();
    let one = (0..n).find(|&i| sys.regressor(i) == Some(Regressor::Constant))?;
    let lags: Vec<usize> = (0..n)
        .filter(|&i| matches!(sys.regressor(i), Some(Regressor::Input(_))))
        .collect();
    let rows = f64::from(sys.samples());
    let q = lags.len();
    let cov = DMatrix::from_fn(q, q, |a, b| {
        let (i, j) = (lags[a], lags[b]);
        sys.augmented(i, j) / rows - sys.augmented(i, one) / rows * (sys.augmented(j, one) / rows)
    });
    if !cov.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = SymmetricEigen::new(cov).eigenvalues;
    let hi = eig.max();
    let lo = eig.min().max(0.0);
    (hi > 0.0).then_some(lo / hi)
}

/// [`WarningKind::LittleExcitation`]: [`input_excitation`] below [`EXCITATION_MIN`].
pub fn little_excitation(normal: &Normal<f64>, model: &ArxModel<f64>) -> Option<Warning> {
    let ratio = input_excitation(normal, model)?;
    let q = model.structure().q;
    (ratio < EXCITATION_MIN).then(|| {
        Warning::new(
            WarningKind::LittleExcitation,
            format!(
                "input too little excited for q = {q} input coefficients: the smallest \
                 eigenvalue of the covariance of u's {q} lags is {ratio:.1e} of the largest \
                 (below {EXCITATION_MIN:e}): u is not persistently exciting of order {q}, so \
                 the phi coefficients are poorly determined; use a richer input (steps of \
                 random length, a binary noise) or a smaller q"
            ),
        )
    })
}

/// `(θ, φ σ_u / σ_y, c / σ_y)` of a model as one vector: its coefficients on the record
/// standardised by `std = (σ_u, σ_y)`.
fn standardised(m: &ArxModel<f64>, (su, sy): (f64, f64)) -> Vec<f64> {
    let mut w: Vec<f64> = m.theta().to_vec();
    w.extend(m.phi().iter().map(|f| f * su / sy));
    if m.offset() == Offset::Intercept {
        w.push(m.intercept() / sy);
    }
    w
}

/// The relative distance `‖w − w_ls‖ / ‖w_ls‖` of `run`'s fit from least squares on the same
/// structure and statistics, on the standardised coefficients, with the least-squares
/// system; `None` when least squares cannot be fitted or the distance is not a number (a zero
/// least-squares fit).
fn distance_to_least_squares<'a>(run: &Run<'a>) -> Option<(f64, System<'a, f64>)> {
    let m = run.fitted;
    let sys = run.normal.system(m.structure(), m.offset()).ok()?;
    let ls = Ols.fit(&sys).ok()?.model();
    let (w, w_ls) = (standardised(m, run.std), standardised(&ls, run.std));
    let norm = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>().sqrt();
    let gap = norm(&mut w.iter().zip(&w_ls).map(|(a, b)| a - b)) / norm(&mut w_ls.iter().copied());
    (!gap.is_nan()).then_some((gap, sys))
}

/// [`WarningKind::NonMove`] or [`WarningKind::MaxIter`]: Ridge-M (`run.opts`) stopped after
/// `run.iterations`, on a step below its tolerance or at its limit, while its fit is still more
/// than [`NON_MOVE_GAP`] from its fixed point, the least-squares fit of the same structure.
pub fn non_move(run: &Run<'_>) -> Option<Warning> {
    let h = &run.opts.hyper;
    let (gap, sys) = distance_to_least_squares(run)?;
    if gap <= NON_MOVE_GAP {
        return None;
    }
    // The mean diagonal of the XᵀX the estimator ran on (standardised or the data's).
    let k = sys.params();
    let (su, sy) = run.std;
    let standard = run.opts.standardises();
    let diag = (0..k)
        .filter_map(|i| match sys.regressor(i) {
            Some(Regressor::Output(_)) if standard => Some(sys.augmented(i, i) / (sy * sy)),
            Some(Regressor::Input(_)) if standard => Some(sys.augmented(i, i) / (su * su)),
            Some(Regressor::Constant) => None,
            _ => Some(sys.augmented(i, i)),
        })
        .sum::<f64>()
        / (k as f64);
    let units = if standard {
        " of the standardised record"
    } else {
        ""
    };
    let mut why = Vec::new();
    let at_limit = run.iterations >= h.max_iter;
    if h.gamma > diag {
        why.push(format!(
            "gamma {} is {:.1e} times the mean diagonal of XᵀX{units} ({diag:.2e}): lower \
             --gamma{}",
            typed(h.gamma),
            h.gamma / diag,
            if standard { "" } else { " or rescale the data" }
        ));
    }
    if h.beta >= 0.9 {
        why.push(format!(
            "beta {} keeps each step small: lower --beta",
            h.beta
        ));
    }
    if why.is_empty() {
        why.push(if at_limit {
            "raise --max-iter or lower --gamma".into()
        } else {
            "lower --tol".into()
        });
    }
    let percent = 100.0 * gap.min(1e6);
    Some(if at_limit {
        Warning::new(
            WarningKind::MaxIter,
            format!(
                "ridge-m did not converge: it stopped at --max-iter {} still {percent:.0} % \
                 (relative distance, standardised coefficients) from its fixed point, the \
                 least-squares fit; {}",
                h.max_iter,
                why.join("; ")
            ),
        )
    } else {
        Warning::new(
            WarningKind::NonMove,
            format!(
                "ridge-m stopped after {} iteration(s) on a step below --tol {}, but still \
                 {percent:.0} % (relative distance, standardised coefficients) from its fixed \
                 point, the least-squares fit: it barely moved, it did not converge; {}",
                run.iterations,
                typed(h.tol),
                why.join("; ")
            ),
        )
    })
}

/// [`WarningKind::Shrunk`]: the coefficients of Ridge or the adaptive LASSO are more than
/// [`NON_MOVE_GAP`] from least squares on the same structure and statistics.
pub fn shrunk(run: &Run<'_>) -> Option<Warning> {
    let (gap, _) = distance_to_least_squares(run)?;
    (gap > NON_MOVE_GAP).then(|| {
        Warning::new(
            WarningKind::Shrunk,
            format!(
                "coefficients shrunk: {} returned them {:.0} % (relative distance, standardised \
                 coefficients) from least squares on the same columns; if that is not the \
                 regularisation wanted, use a smaller --gamma or --method ridge-m",
                run.opts.method.name(),
                100.0 * gap.min(1e6)
            ),
        )
    })
}
