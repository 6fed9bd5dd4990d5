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

use std::path::Path;

use nalgebra::{DMatrix, SymmetricEigen};
use ridge_core_host::{ArxModel, Estimator, MethodKind, Normal, Offset, Ols, Regressor};

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

/// Relative distance `‖w − w_ls‖ / ‖w_ls‖` from the least-squares fit above which a Ridge-M
/// run that stopped on its tolerance did not converge.
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
}

impl WarningKind {
    /// Short name: `unstable`, `negative-fit`, `too-short`, `little-excitation`, `non-move`.
    pub const fn name(self) -> &'static str {
        match self {
            WarningKind::Unstable => "unstable",
            WarningKind::NegativeFit => "negative-fit",
            WarningKind::TooShort => "too-short",
            WarningKind::LittleExcitation => "little-excitation",
            WarningKind::NonMove => "non-move",
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
    /// Statistics of the estimation record (physical units).
    pub normal: &'a Normal<f64>,
    /// The identified model.
    pub model: &'a ArxModel<f64>,
    /// Iterations reported for the model (Ridge-M iterates for `ridge-m`).
    pub iterations: u32,
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
    if run.opts.method == MethodKind::RidgeM {
        out.extend(non_move(run.opts, run.normal, run.model, run.iterations));
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

/// `(θ, φ, c)` of a model as one vector.
fn coefficients(m: &ArxModel<f64>) -> Vec<f64> {
    let mut w: Vec<f64> = m.theta().iter().chain(m.phi()).copied().collect();
    if m.offset() == Offset::Intercept {
        w.push(m.intercept());
    }
    w
}

/// [`WarningKind::NonMove`]: Ridge-M (`opts`) stopped after `iterations` on a step below
/// its tolerance, but `model` is still more than [`NON_MOVE_GAP`] from its fixed point, the
/// least-squares fit of the same structure on `normal`.
pub fn non_move(
    opts: &Options,
    normal: &Normal<f64>,
    model: &ArxModel<f64>,
    iterations: u32,
) -> Option<Warning> {
    let h = &opts.hyper;
    if iterations >= h.max_iter {
        return None;
    }
    let sys = normal.system(model.structure(), model.offset()).ok()?;
    let ls = Ols.fit(&sys).ok()?.model();
    let (w, w_ls) = (coefficients(model), coefficients(&ls));
    let norm = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>().sqrt();
    let gap = norm(&mut w.iter().zip(&w_ls).map(|(a, b)| a - b)) / norm(&mut w_ls.iter().copied());
    // (A NaN gap, from a zero least-squares fit, is no warning.)
    if gap.is_nan() || gap <= NON_MOVE_GAP {
        return None;
    }
    let k = sys.params();
    let diag = (0..k)
        .filter(|&i| sys.regressor(i) != Some(Regressor::Constant))
        .map(|i| sys.augmented(i, i))
        .sum::<f64>()
        / (k as f64);
    let mut why = Vec::new();
    if h.gamma > diag {
        why.push(format!(
            "gamma {} is {:.1e} times the mean diagonal of XᵀX ({diag:.2e}): rescale the \
             data or lower --gamma",
            typed(h.gamma),
            h.gamma / diag
        ));
    }
    if h.beta >= 0.9 {
        why.push(format!(
            "beta {} keeps each step small: lower --beta",
            h.beta
        ));
    }
    if why.is_empty() {
        why.push("lower --tol".into());
    }
    Some(Warning::new(
        WarningKind::NonMove,
        format!(
            "ridge-m stopped after {iterations} iteration(s) on a step below --tol {}, but \
             still {:.0} % (relative distance) from its fixed point, the least-squares fit: it \
             barely moved, it did not converge; {}",
            typed(h.tol),
            100.0 * gap.min(1e6),
            why.join("; ")
        ),
    ))
}
