//! The paper's experiments (section 3, Tables 1–5) on simulated pump records.
//!
//! Every record is simulated by [`crate::record`] on the reference blower
//! ([`PumpParams::default`]: true transport delay 3 samples, dead zone, convex fan curve)
//! and fed to the statistics exactly as the firmware will: an [`IntGram`] of
//! `(raw_u, raw_y − 32768)` with [`SCALE`], solved in `f64` (and in `f32`
//! for the precision check). Models are therefore in duty fraction (0..1) and slm.
//!
//! Models are scored with [`Evaluation`]: one-step-ahead and free-run RMSE, both seeded with
//! the first `m = max(p, d + q − 1)` measured samples and scored on samples `m..N`
//! (SPEC §6). The paper's own RMSE figures (26–40) were obtained on a real pump with an
//! unknown evaluation protocol; see `docs/results.md` for the reading.
//!
//! The functions return plain structs (for the tests); [`render_markdown`] turns a
//! [`Report`] into the tables printed by the `paper-tables` binary.

use std::fmt::Write as _;

use ridge_core::{
    AdaptiveLasso, ArxModel, Criterion, Error, Estimator, Evaluation, IntGram, Method, Normal, Ols,
    Real, Regressor, Ridge, RidgeM, Rls, Search, Structure, System,
};
pub use ridge_core::{Offset, Result};
use ridge_pump_firmware::units::SCALE;

use crate::{record, Log, PumpParams, Sfm3300Params};
use ridge_pump_firmware::excitation::Record;

/// Default noise seed of `paper-tables`.
pub const DEFAULT_SEED: u64 = 20_250_601;

/// The paper's four records, in the order of its tables.
pub const RECORDS: [Record; 4] = [
    Record::AMultistep,
    Record::BMultistep,
    Record::ARamp,
    Record::BRamp,
];

/// Ridge and Ridge-M regularisation of Tables 1 and 5 (paper: 1000).
pub const GAMMA: f64 = 1000.0;
/// AIC penalty weight per parameter (paper: 12).
pub const ALPHA: f64 = 12.0;
/// RLS forgetting factor of the comparison (1: ordinary least squares).
pub const RLS_LAMBDA: f64 = 1.0;
/// RLS initial covariance `P₀ = δI`.
pub const RLS_DELTA: f64 = 1e3;
/// The γ values of Table 4: 1e-1 … 1e9, one per decade.
pub const GAMMAS: [f64; 11] = [1e-1, 1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
/// The iterations printed in Tables 2–3 (as in the paper).
pub const ITERATIONS: [u32; 7] = [1, 30, 60, 90, 120, 150, 180];

/// Ridge-M with the paper's hyper-parameters (γ = 1000, β = 0.01, ε = 1e-6, 200 iterates).
pub fn ridge_m<T: Real>() -> RidgeM<T> {
    RidgeM::default()
}

/// The four simulated records and their exact integer statistics.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Sensor-noise seed of every record.
    pub seed: u64,
    /// Logs in [`RECORDS`] order.
    pub logs: Vec<Log>,
    /// Integer statistics of each log, in [`RECORDS`] order.
    pub grams: Vec<IntGram>,
}

/// Exact statistics of a log, fed as the firmware feeds them:
/// `push(raw_u, raw_y − 32768)`.
pub fn int_gram(log: &Log) -> Result<IntGram> {
    let mut g = IntGram::new();
    for (&u, &y) in log.raw_u.iter().zip(&log.raw_y) {
        g.push(i32::from(u), i32::from(y) - 32_768)?;
    }
    Ok(g)
}

/// Index of a record in [`RECORDS`].
pub fn record_index(r: Record) -> Option<usize> {
    RECORDS.iter().position(|&x| x == r)
}

impl Dataset {
    /// Simulates the four records on the reference pump with sensor-noise seed `seed`.
    pub fn simulate(seed: u64) -> Result<Self> {
        let params = PumpParams::default();
        let logs: Vec<Log> = RECORDS.iter().map(|&r| record(r, &params, seed)).collect();
        let grams = logs.iter().map(int_gram).collect::<Result<Vec<_>>>()?;
        Ok(Dataset { seed, logs, grams })
    }

    /// The log of record `r` (one of [`RECORDS`]).
    pub fn log(&self, r: Record) -> Result<&Log> {
        record_index(r)
            .and_then(|i| self.logs.get(i))
            .ok_or(Error::InvalidParameter)
    }

    /// The solve-time statistics of record `r` in scalar `T`.
    pub fn normal<T: Real>(&self, r: Record) -> Result<Normal<T>> {
        record_index(r)
            .and_then(|i| self.grams.get(i))
            .ok_or(Error::InvalidParameter)?
            .normal(SCALE)
    }
}

/// One-step and free-run RMSE of a model on one record (slm), seeded with measured samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rmse {
    /// Free-run simulation RMSE (the model feeds back its own outputs).
    pub free_run: f64,
    /// One-step-ahead RMSE (measured past outputs).
    pub one_step: f64,
    /// Samples scored (`N − m`).
    pub scored: u32,
}

/// Scores `model` on `log` with [`Evaluation`] (seeded with the first `m` measured samples).
pub fn evaluate(model: &ArxModel<f64>, log: &Log) -> Result<Rmse> {
    let mut ev = Evaluation::new(*model);
    for (&u, &y) in log.u.iter().zip(&log.y) {
        ev.push(u, y);
    }
    match (ev.free_run(), ev.one_step()) {
        (Some(f), Some(o)) => Ok(Rmse {
            free_run: f.rmse,
            one_step: o.rmse,
            scored: f.n,
        }),
        _ => Err(Error::TooShort {
            needed: model.structure().seed_len() as u32 + 1,
            have: log.len() as u32,
        }),
    }
}

/// Mean of a set of RMSE figures.
pub fn mean_rmse(v: &[Rmse]) -> Rmse {
    let n = v.len().max(1) as f64;
    Rmse {
        free_run: v.iter().map(|r| r.free_run).sum::<f64>() / n,
        one_step: v.iter().map(|r| r.one_step).sum::<f64>() / n,
        scored: v.iter().map(|r| r.scored).sum(),
    }
}

/// RLS on a fixed structure, sample by sample over the whole log (physical units), from
/// `w = 0`, `P₀ = δI`; returns the final model.
pub fn rls(
    log: &Log,
    s: Structure,
    offset: Offset,
    lambda: f64,
    delta: f64,
) -> Result<ArxModel<f64>> {
    let mut r = Rls::new(s, offset, lambda, delta)?;
    for (&u, &y) in log.u.iter().zip(&log.y) {
        r.update(u, y)?;
    }
    Ok(r.model())
}

/// Turns coefficients in a [`System`]'s internal order into an [`ArxModel`].
pub fn model_from_internal<T: Real>(sys: &System<T>, w: &[T]) -> Result<ArxModel<T>> {
    let s = sys.structure();
    let mut theta = vec![T::ZERO; usize::from(s.p)];
    let mut phi = vec![T::ZERO; usize::from(s.q)];
    let mut c = T::ZERO;
    for (i, &v) in w.iter().enumerate().take(sys.params()) {
        match sys.regressor(i) {
            Some(Regressor::Output(k)) if k >= 1 => theta[usize::from(k) - 1] = v,
            Some(Regressor::Input(k)) => phi[usize::from(k - s.d)] = v,
            Some(Regressor::Constant) => c = v,
            _ => return Err(Error::InvalidStructure),
        }
    }
    ArxModel::new(&theta, &phi, s.d, sys.offset(), c)
}

/// A structure search on `normal` with the paper's α and grid.
pub fn search<T: Real>(
    normal: &Normal<T>,
    criterion: Criterion,
    offset: Offset,
    method: Method<T>,
    prune: bool,
) -> Result<ridge_core::Selection<T>> {
    Search {
        criterion,
        offset,
        method,
        prune,
        alpha: T::from_f64(ALPHA),
        ..Search::default()
    }
    .run(normal, None)
}

/// The estimators compared in Tables 1 and 5 (plus least squares as a reference).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Algorithm {
    /// Recursive least squares, λ = 1, δ = 1e3, sample by sample.
    Rls,
    /// Plain Ridge, γ = 1000.
    Ridge,
    /// Adaptive LASSO, BIC-chosen λ ([`AdaptiveLasso::default`]).
    Alasso,
    /// Ridge-M with the paper's hyper-parameters.
    RidgeM,
    /// Ordinary least squares (reference; not in the paper's tables).
    Ols,
}

impl Algorithm {
    /// All, in table order.
    pub const ALL: [Algorithm; 5] = [
        Algorithm::Rls,
        Algorithm::Ridge,
        Algorithm::Alasso,
        Algorithm::RidgeM,
        Algorithm::Ols,
    ];

    /// Column title.
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::Rls => "RLS",
            Algorithm::Ridge => "Ridge",
            Algorithm::Alasso => "ALASSO",
            Algorithm::RidgeM => "Ridge-M",
            Algorithm::Ols => "OLS (ref.)",
        }
    }
}

/// Display name of a criterion.
pub fn criterion_name(c: Criterion) -> &'static str {
    match c {
        Criterion::Paper => "paper eq. (14), N ln(RSS/N) + α(p+q+d)",
        Criterion::Aic => "delay-free AIC, N ln(RSS/N) + α(p+q)",
        Criterion::Bic => "BIC",
        Criterion::Validation => "validation loss",
    }
}

/// Tables 1 and 5: a structure chosen by Ridge-M + search on one record, then every
/// estimator on that structure, validated on the four records.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// Identification record.
    pub identification: Record,
    /// Criterion of the structure search.
    pub criterion: Criterion,
    /// Constant term.
    pub offset: Offset,
    /// The structure chosen by Ridge-M + search.
    pub structure: Structure,
    /// Candidates the pruned search ran Ridge-M on.
    pub evaluated: u16,
    /// Candidates in the grid (252).
    pub candidates: u16,
    /// Ridge-M iterates used on the chosen structure.
    pub ridge_m_iterations: u32,
    /// The model of each algorithm, in [`Algorithm::ALL`] order.
    pub models: Vec<(Algorithm, ArxModel<f64>)>,
    /// `rmse[a][r]`: algorithm `a` ([`Algorithm::ALL`]) on record `r` ([`RECORDS`]).
    pub rmse: Vec<Vec<Rmse>>,
}

impl Comparison {
    /// Mean over the four records for algorithm index `a`.
    pub fn average(&self, a: usize) -> Rmse {
        mean_rmse(&self.rmse[a])
    }

    /// The model of one algorithm.
    pub fn model(&self, a: Algorithm) -> Option<&ArxModel<f64>> {
        self.models.iter().find(|(x, _)| *x == a).map(|(_, m)| m)
    }
}

/// Runs one Table-1/5 comparison.
pub fn comparison(
    data: &Dataset,
    identification: Record,
    criterion: Criterion,
    offset: Offset,
) -> Result<Comparison> {
    let normal = data.normal::<f64>(identification)?;
    let sel = search(&normal, criterion, offset, Method::RidgeM(ridge_m()), true)?;
    let s = sel.structure();
    let sys = normal.system(s, offset)?;
    let ls = sys.factor(0.0)?;
    let log = data.log(identification)?;
    let mut models = Vec::new();
    for a in Algorithm::ALL {
        let m = match a {
            Algorithm::Rls => rls(log, s, offset, RLS_LAMBDA, RLS_DELTA)?,
            Algorithm::Ridge => Ridge { gamma: GAMMA }.fit_with(&sys, &ls)?.model(),
            Algorithm::Alasso => AdaptiveLasso::default().fit_with(&sys, &ls)?.model(),
            Algorithm::RidgeM => ridge_m().fit_with(&sys, &ls)?.model(),
            Algorithm::Ols => Ols.fit_with(&sys, &ls)?.model(),
        };
        models.push((a, m));
    }
    let rmse = models
        .iter()
        .map(|(_, m)| data.logs.iter().map(|l| evaluate(m, l)).collect())
        .collect::<Result<Vec<Vec<Rmse>>>>()?;
    Ok(Comparison {
        identification,
        criterion,
        offset,
        structure: s,
        evaluated: sel.evaluated,
        candidates: sel.candidates,
        ridge_m_iterations: sel.fit.iterations,
        models,
        rmse,
    })
}

/// One estimator's pick at one γ of Table 4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepPick {
    /// Structure chosen by the search.
    pub structure: Structure,
    /// The chosen model scored on the validation record.
    pub rmse: Rmse,
    /// Candidates evaluated by the pruned search.
    pub evaluated: u16,
    /// Iterates used on the chosen structure (1 for plain Ridge).
    pub iterations: u32,
}

/// One row of Table 4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepRow {
    /// Regularisation γ.
    pub gamma: f64,
    /// Without momentum (plain Ridge, the first Ridge-M iterate).
    pub plain: SweepPick,
    /// With momentum (Ridge-M, β = 0.01, 200 iterates, ε = 1e-6).
    pub momentum: SweepPick,
    /// Theory: largest per-mode distance of 200 Ridge-M iterates from least squares over
    /// the grid, [`ridge_m_residual_factor`] at the smallest eigenvalue of any candidate's
    /// `XᵀX`. Near 0: Ridge-M is least squares on every candidate; near 1: far from it.
    pub residual_factor: f64,
}

/// Table 4: the search run with plain Ridge and with Ridge-M for every γ of [`GAMMAS`].
#[derive(Clone, Debug)]
pub struct Sweep {
    /// Identification record.
    pub identification: Record,
    /// Validation record.
    pub validation: Record,
    /// Criterion.
    pub criterion: Criterion,
    /// Least-squares search on the same record (the γ → 0 limit of both).
    pub ols: SweepPick,
    /// Smallest eigenvalue of `XᵀX` over the grid, and its candidate.
    pub lambda_min: (f64, Structure),
    /// One row per γ.
    pub rows: Vec<SweepRow>,
}

fn pick(
    normal: &Normal<f64>,
    criterion: Criterion,
    method: Method<f64>,
    val: &Log,
) -> Result<SweepPick> {
    let sel = search(normal, criterion, Offset::None, method, true)?;
    Ok(SweepPick {
        structure: sel.structure(),
        rmse: evaluate(&sel.fit.model(), val)?,
        evaluated: sel.evaluated,
        iterations: sel.fit.iterations,
    })
}

/// Runs Table 4 for one criterion.
pub fn gamma_sweep(
    data: &Dataset,
    identification: Record,
    validation: Record,
    criterion: Criterion,
) -> Result<Sweep> {
    let normal = data.normal::<f64>(identification)?;
    let val = data.log(validation)?;
    let ols = pick(&normal, criterion, Method::Ols, val)?;
    let lambda_min = smallest_eigenvalue_over_grid(&normal, Offset::None)?;
    let rm = ridge_m::<f64>();
    let rows = GAMMAS
        .iter()
        .map(|&gamma| {
            Ok(SweepRow {
                gamma,
                plain: pick(&normal, criterion, Method::Ridge(Ridge { gamma }), val)?,
                momentum: pick(
                    &normal,
                    criterion,
                    Method::RidgeM(RidgeM { gamma, ..ridge_m() }),
                    val,
                )?,
                residual_factor: ridge_m_residual_factor(lambda_min.0, gamma, rm.beta, rm.max_iter),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Sweep {
        identification,
        validation,
        criterion,
        ols,
        lambda_min,
        rows,
    })
}

/// Tables 2–3: Ridge-M coefficients against the iteration count.
#[derive(Clone, Debug)]
pub struct Convergence {
    /// Regularisation γ.
    pub gamma: f64,
    /// Structure.
    pub structure: Structure,
    /// `(k, w_k)` at the requested iterations, as models (θ, φ).
    pub rows: Vec<(u32, ArxModel<f64>)>,
    /// The least-squares solution, the fixed point of the iteration.
    pub ols: ArxModel<f64>,
}

/// Runs Ridge-M with tolerance 0 up to `max(at)` iterations on `structure` of record `r`,
/// keeping the iterates listed in `at`.
pub fn convergence(
    data: &Dataset,
    r: Record,
    structure: Structure,
    gamma: f64,
    at: &[u32],
) -> Result<Convergence> {
    let normal = data.normal::<f64>(r)?;
    let sys = normal.system(structure, Offset::None)?;
    let max_iter = at.iter().copied().max().unwrap_or(1).max(1);
    let rm = RidgeM {
        gamma,
        tol: 0.0,
        max_iter,
        ..ridge_m()
    };
    let mut kept: Vec<(u32, Vec<f64>)> = Vec::new();
    rm.iterate(&sys, |k, w| {
        if at.contains(&k) {
            kept.push((k, w.to_vec()));
        }
    })?;
    let rows = kept
        .iter()
        .map(|(k, w)| Ok((*k, model_from_internal(&sys, w)?)))
        .collect::<Result<Vec<_>>>()?;
    let ols = Ols.fit(&sys)?.model();
    Ok(Convergence {
        gamma,
        structure,
        rows,
        ols,
    })
}

/// Pruned vs exhaustive search on one record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pruning {
    /// Criterion.
    pub criterion: Criterion,
    /// Constant term.
    pub offset: Offset,
    /// Pick of the pruned search.
    pub pruned: Structure,
    /// Candidates the pruned search ran Ridge-M on.
    pub evaluated: u16,
    /// Pick of the exhaustive search.
    pub exhaustive: Structure,
    /// Candidates the exhaustive search ran Ridge-M on (all fittable ones).
    pub exhaustive_evaluated: u16,
    /// Grid size.
    pub candidates: u16,
    /// The two picks' criterion values agree exactly.
    pub same_score: bool,
}

/// Runs the Ridge-M search with and without pruning.
pub fn pruning(data: &Dataset, r: Record, criterion: Criterion, offset: Offset) -> Result<Pruning> {
    let normal = data.normal::<f64>(r)?;
    let a = search(&normal, criterion, offset, Method::RidgeM(ridge_m()), true)?;
    let b = search(&normal, criterion, offset, Method::RidgeM(ridge_m()), false)?;
    Ok(Pruning {
        criterion,
        offset,
        pruned: a.structure(),
        evaluated: a.evaluated,
        exhaustive: b.structure(),
        exhaustive_evaluated: b.evaluated,
        candidates: a.candidates,
        same_score: a.score == b.score,
    })
}

/// `f32` vs `f64` solve on the same exact statistics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Precision {
    /// Record.
    pub record: Record,
    /// Criterion.
    pub criterion: Criterion,
    /// Pick with `f64` solves.
    pub structure_f64: Structure,
    /// Pick with `f32` solves.
    pub structure_f32: Structure,
    /// Candidates evaluated, `f64` / `f32`.
    pub evaluated: (u16, u16),
    /// Largest |coefficient difference| of Ridge-M on the `f64` pick, `f32` vs `f64`.
    pub max_coef_diff: f64,
    /// Largest |coefficient| of the `f64` model (for scale).
    pub max_coef: f64,
    /// Free-run RMSE on the identification record, `f64` model / `f32` model (same
    /// structure, evaluated in `f64`).
    pub free_run: (f64, f64),
}

fn coefficients(m: &ArxModel<f64>) -> Vec<f64> {
    let mut v: Vec<f64> = m.theta().iter().chain(m.phi()).copied().collect();
    if m.offset() == Offset::Intercept {
        v.push(m.intercept());
    }
    v
}

fn widen(m: &ArxModel<f32>) -> Result<ArxModel<f64>> {
    let t: Vec<f64> = m.theta().iter().map(|&x| f64::from(x)).collect();
    let p: Vec<f64> = m.phi().iter().map(|&x| f64::from(x)).collect();
    ArxModel::new(
        &t,
        &p,
        m.structure().d,
        m.offset(),
        f64::from(m.intercept()),
    )
}

/// Runs the Ridge-M search and fit in `f32` and `f64` on the same integer statistics.
pub fn precision(data: &Dataset, r: Record, criterion: Criterion) -> Result<Precision> {
    let n64 = data.normal::<f64>(r)?;
    let n32 = data.normal::<f32>(r)?;
    let s64 = search(
        &n64,
        criterion,
        Offset::None,
        Method::RidgeM(ridge_m()),
        true,
    )?;
    let s32 = search(
        &n32,
        criterion,
        Offset::None,
        Method::RidgeM(ridge_m()),
        true,
    )?;
    let s = s64.structure();
    let m64 = s64.fit.model();
    let m32 = widen(&ridge_m::<f32>().fit(&n32.system(s, Offset::None)?)?.model())?;
    let (c64, c32) = (coefficients(&m64), coefficients(&m32));
    let max_coef_diff = c64
        .iter()
        .zip(&c32)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let max_coef = c64.iter().map(|a| a.abs()).fold(0.0, f64::max);
    let log = data.log(r)?;
    Ok(Precision {
        record: r,
        criterion,
        structure_f64: s,
        structure_f32: s32.structure(),
        evaluated: (s64.evaluated, s32.evaluated),
        max_coef_diff,
        max_coef,
        free_run: (evaluate(&m64, log)?.free_run, evaluate(&m32, log)?.free_run),
    })
}

/// Summary of one simulated record (for the scale of the RMSE figures).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordStats {
    /// Record.
    pub record: Record,
    /// Samples.
    pub samples: usize,
    /// Duty range, fraction 0..1.
    pub u_range: (f64, f64),
    /// Samples where the duty changes (`u_t ≠ u_{t−1}`): the only samples at which a
    /// delay `d` and a delay `d + 1` give different regressors.
    pub u_changes: usize,
    /// Flow mean, slm.
    pub y_mean: f64,
    /// Flow standard deviation, slm.
    pub y_std: f64,
    /// Flow range, slm.
    pub y_range: (f64, f64),
    /// RMS of the simulated sensor's noise standard deviation over the record
    /// (`Sfm3300Params::default().noise_std` at the measured flows), slm: the floor of any
    /// one-step RMSE.
    pub noise_rms: f64,
}

/// Summarises a log.
pub fn record_stats(r: Record, log: &Log) -> RecordStats {
    let n = log.len().max(1) as f64;
    let sensor = Sfm3300Params::default();
    let mean = log.y.iter().sum::<f64>() / n;
    let var = log.y.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / n;
    let range = |v: &[f64]| {
        v.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            })
    };
    RecordStats {
        record: r,
        samples: log.len(),
        u_range: range(&log.u),
        u_changes: log.raw_u.windows(2).filter(|w| w[0] != w[1]).count(),
        y_mean: mean,
        y_std: var.sqrt(),
        y_range: range(&log.y),
        noise_rms: (log
            .y
            .iter()
            .map(|&y| sensor.noise_std(y).powi(2))
            .sum::<f64>()
            / n)
            .sqrt(),
    }
}

/// Eigenvalues of a small symmetric matrix (cyclic Jacobi), ascending.
pub fn symmetric_eigenvalues(a: &[Vec<f64>]) -> Vec<f64> {
    let n = a.len();
    let mut a: Vec<Vec<f64>> = a.to_vec();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-32 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - s * y;
                    row[q] = s * x + c * y;
                }
                let (lo, hi) = a.split_at_mut(q);
                for (x, y) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                    let (u, v) = (*x, *y);
                    *x = c * u - s * v;
                    *y = s * u + c * v;
                }
            }
        }
    }
    let mut ev: Vec<f64> = (0..n).map(|i| a[i][i]).collect();
    ev.sort_by(f64::total_cmp);
    ev
}

/// `XᵀX` of a system (internal order) as a dense matrix.
pub fn gram_matrix(sys: &System<f64>) -> Vec<Vec<f64>> {
    let n = sys.params();
    (0..n)
        .map(|i| (0..n).map(|j| sys.augmented(i, j)).collect())
        .collect()
}

/// How far Ridge-M is from least squares after `k` iterates, per eigen-mode of `XᵀX`
/// with eigenvalue `lambda` (SPEC §3 closed form): `w_k − w_LS = −γ/(λ+γ) ρ^{k−1} w_LS`
/// in that mode, `ρ = β + (1−β) γ/(λ+γ)`. Returns `γ/(λ+γ) ρ^{k−1}`.
pub fn ridge_m_residual_factor(lambda: f64, gamma: f64, beta: f64, k: u32) -> f64 {
    let shrink = gamma / (lambda + gamma);
    let rho = beta + (1.0 - beta) * shrink;
    shrink * rho.powi(k.saturating_sub(1) as i32)
}

/// Smallest eigenvalue of `XᵀX` over every candidate of the paper's grid on `normal`, and
/// the candidate that has it.
pub fn smallest_eigenvalue_over_grid(
    normal: &Normal<f64>,
    offset: Offset,
) -> Result<(f64, Structure)> {
    let mut best: Option<(f64, Structure)> = None;
    for s in ridge_core::Grid::default().iter() {
        let sys = normal.system(s, offset)?;
        let l = symmetric_eigenvalues(&gram_matrix(&sys))[0];
        if best.is_none_or(|(b, _)| l < b) {
            best = Some((l, s));
        }
    }
    best.ok_or(Error::NoCandidate)
}

/// How often each delay is picked over many noise seeds.
#[derive(Clone, Debug, PartialEq)]
pub struct CensusRow {
    /// Record.
    pub record: Record,
    /// Criterion.
    pub criterion: Criterion,
    /// Constant term.
    pub offset: Offset,
    /// `true`: least squares in the search; `false`: Ridge-M (paper defaults).
    pub ols: bool,
    /// `d_counts[d]`: seeds whose pick has delay `d`.
    pub d_counts: [u32; 7],
    /// Seeds whose pick has `d = 0` or `q = 6` (the paper-criterion flaw pattern).
    pub flaw_pattern: u32,
    /// The most frequent pick and its count.
    pub mode: (Structure, u32),
    /// Seeds.
    pub seeds: u32,
}

/// The searches of the census: (criterion, offset, least squares?).
pub const CENSUS_SEARCHES: [(Criterion, Offset, bool); 6] = [
    (Criterion::Paper, Offset::None, false),
    (Criterion::Paper, Offset::None, true),
    (Criterion::Paper, Offset::Intercept, false),
    (Criterion::Paper, Offset::Intercept, true),
    (Criterion::Aic, Offset::None, false),
    (Criterion::Aic, Offset::Intercept, false),
];

/// Records of the census.
pub const CENSUS_RECORDS: [Record; 3] = [Record::AMultistep, Record::ARamp, Record::Prbs];

/// Re-simulates `r` with `seeds` sensor-noise seeds `first, first + 1, …` and tallies the
/// picks of every search of [`CENSUS_SEARCHES`].
pub fn census(r: Record, first: u64, seeds: u32) -> Result<Vec<CensusRow>> {
    let params = PumpParams::default();
    let mut picks: Vec<Vec<Structure>> = vec![Vec::new(); CENSUS_SEARCHES.len()];
    for i in 0..seeds {
        let log = record(r, &params, first.wrapping_add(u64::from(i)));
        let normal = int_gram(&log)?.normal::<f64>(SCALE)?;
        for (k, &(c, o, ols)) in CENSUS_SEARCHES.iter().enumerate() {
            let method = if ols {
                Method::Ols
            } else {
                Method::RidgeM(ridge_m())
            };
            picks[k].push(search(&normal, c, o, method, true)?.structure());
        }
    }
    Ok(CENSUS_SEARCHES
        .iter()
        .zip(picks)
        .map(|(&(criterion, offset, ols), p)| {
            let mut d_counts = [0u32; 7];
            for s in &p {
                d_counts[usize::from(s.d).min(6)] += 1;
            }
            let mut mode = (p[0], 0u32);
            for s in &p {
                let c = p.iter().filter(|x| *x == s).count() as u32;
                if c > mode.1 {
                    mode = (*s, c);
                }
            }
            CensusRow {
                record: r,
                criterion,
                offset,
                ols,
                d_counts,
                flaw_pattern: p
                    .iter()
                    .filter(|s| s.d == 0 || usize::from(s.q) == ridge_core::Q_MAX)
                    .count() as u32,
                mode,
                seeds,
            }
        })
        .collect())
}

/// Final RLS estimates with forgetting, scored on the four records.
#[derive(Clone, Debug, PartialEq)]
pub struct Forgetting {
    /// Structure.
    pub structure: Structure,
    /// `(λ, mean RMSE over the four records)`.
    pub rows: Vec<(f64, Rmse)>,
}

/// RLS forgetting factors of the extra table.
pub const FORGETTING: [f64; 4] = [1.0, 0.999, 0.99, 0.98];

/// RLS with each forgetting factor of [`FORGETTING`] on `r`, final estimate, averaged
/// over the four records.
pub fn rls_forgetting(data: &Dataset, r: Record, s: Structure) -> Result<Forgetting> {
    let log = data.log(r)?;
    let rows = FORGETTING
        .iter()
        .map(|&l| {
            let m = rls(log, s, Offset::None, l, RLS_DELTA)?;
            let v = data
                .logs
                .iter()
                .map(|x| evaluate(&m, x))
                .collect::<Result<Vec<_>>>()?;
            Ok((l, mean_rmse(&v)))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Forgetting { structure: s, rows })
}

/// Everything `paper-tables` prints.
#[derive(Clone, Debug)]
pub struct Report {
    /// Noise seed.
    pub seed: u64,
    /// The four records.
    pub records: Vec<RecordStats>,
    /// Table 1 (A-Multistep), paper criterion then delay-free AIC.
    pub table1: Vec<Comparison>,
    /// Table 5 (A-Ramp), paper criterion then delay-free AIC.
    pub table5: Vec<Comparison>,
    /// Table 1 with an intercept, delay-free AIC.
    pub intercept: Comparison,
    /// Table 4, paper criterion then delay-free AIC.
    pub table4: Vec<Sweep>,
    /// Tables 2–3 (γ = 100 and 1000) on the structure of Table 1 for each criterion.
    pub convergence: Vec<(Criterion, Vec<Convergence>)>,
    /// Pruned vs exhaustive search on A-Multistep.
    pub pruning: Vec<Pruning>,
    /// f32 vs f64 on A-Multistep.
    pub precision: Vec<Precision>,
    /// RLS with forgetting on the structure of Table 1 (delay-free AIC).
    pub forgetting: Forgetting,
    /// Picks over [`CENSUS_SEEDS`] noise seeds starting at `seed`.
    pub census: Vec<CensusRow>,
}

/// Noise seeds of the census.
pub const CENSUS_SEEDS: u32 = 40;

/// The two criteria compared throughout.
pub const CRITERIA: [Criterion; 2] = [Criterion::Paper, Criterion::Aic];

/// Runs every experiment.
pub fn run(seed: u64) -> Result<Report> {
    let data = Dataset::simulate(seed)?;
    let table1 = CRITERIA
        .iter()
        .map(|&c| comparison(&data, Record::AMultistep, c, Offset::None))
        .collect::<Result<Vec<_>>>()?;
    let table5 = CRITERIA
        .iter()
        .map(|&c| comparison(&data, Record::ARamp, c, Offset::None))
        .collect::<Result<Vec<_>>>()?;
    let intercept = comparison(&data, Record::AMultistep, Criterion::Aic, Offset::Intercept)?;
    let table4 = CRITERIA
        .iter()
        .map(|&c| gamma_sweep(&data, Record::AMultistep, Record::BRamp, c))
        .collect::<Result<Vec<_>>>()?;
    let convergence = table1
        .iter()
        .map(|t| {
            let tables = [100.0, 1000.0]
                .iter()
                .map(|&g| convergence(&data, Record::AMultistep, t.structure, g, &ITERATIONS))
                .collect::<Result<Vec<_>>>()?;
            Ok((t.criterion, tables))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut pruning_rows = Vec::new();
    for c in CRITERIA {
        for o in [Offset::None, Offset::Intercept] {
            pruning_rows.push(pruning(&data, Record::AMultistep, c, o)?);
        }
    }
    let precision = CRITERIA
        .iter()
        .map(|&c| precision(&data, Record::AMultistep, c))
        .collect::<Result<Vec<_>>>()?;
    let forgetting = rls_forgetting(&data, Record::AMultistep, table1[1].structure)?;
    let mut census_rows = Vec::new();
    for r in CENSUS_RECORDS {
        census_rows.extend(census(r, seed, CENSUS_SEEDS)?);
    }
    let records = RECORDS
        .iter()
        .zip(&data.logs)
        .map(|(&r, l)| record_stats(r, l))
        .collect();
    Ok(Report {
        seed,
        records,
        table1,
        table5,
        intercept,
        table4,
        convergence,
        pruning: pruning_rows,
        precision,
        forgetting,
        census: census_rows,
    })
}

// ---------------------------------------------------------------------------------------------
// Markdown
// ---------------------------------------------------------------------------------------------

fn st(s: Structure) -> String {
    format!("({}, {}, {})", s.p, s.q, s.d)
}

fn short_criterion(c: Criterion) -> &'static str {
    match c {
        Criterion::Paper => "paper criterion",
        Criterion::Aic => "delay-free AIC",
        Criterion::Bic => "BIC",
        Criterion::Validation => "validation loss",
    }
}

fn offset_name(o: Offset) -> &'static str {
    match o {
        Offset::None => "no offset",
        Offset::Intercept => "intercept",
    }
}

fn coef_list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.4}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn comparison_md(out: &mut String, title: &str, c: &Comparison) {
    let _ = writeln!(
        out,
        "### {title}: identified on {}, {}, {}\n",
        c.identification.name(),
        short_criterion(c.criterion),
        offset_name(c.offset)
    );
    let _ = writeln!(
        out,
        "Ridge-M + search ({}, α = {ALPHA}, γ = {GAMMA}, β = 0.01, 200 iterates, ε = 1e-6) picks \
         **ARX{}** (true plant delay: 3 samples); Ridge-M ran on {} of {} candidates and used {} \
         iterates on the pick.\n",
        criterion_name(c.criterion),
        st(c.structure),
        c.evaluated,
        c.candidates,
        c.ridge_m_iterations
    );
    for (label, free) in [
        ("Free-run RMSE (slm)", true),
        ("One-step RMSE (slm)", false),
    ] {
        let _ = writeln!(out, "{label}:\n");
        let _ = write!(out, "| Input function |");
        for a in Algorithm::ALL {
            let _ = write!(out, " {} |", a.name());
        }
        let _ = writeln!(out);
        let _ = write!(out, "|---|");
        for _ in Algorithm::ALL {
            let _ = write!(out, "---:|");
        }
        let _ = writeln!(out);
        let val = |r: &Rmse| if free { r.free_run } else { r.one_step };
        for (ri, r) in RECORDS.iter().enumerate() {
            let _ = write!(out, "| {} |", r.name());
            for ai in 0..Algorithm::ALL.len() {
                let _ = write!(out, " {:.4} |", val(&c.rmse[ai][ri]));
            }
            let _ = writeln!(out);
        }
        let _ = write!(out, "| **Average** |");
        for ai in 0..Algorithm::ALL.len() {
            let _ = write!(out, " **{:.4}** |", val(&c.average(ai)));
        }
        let _ = writeln!(out, "\n");
    }
    let _ = writeln!(
        out,
        "Coefficients (θ₁…θ_p | φ₀…φ_q₋₁{}):\n",
        if c.offset == Offset::Intercept {
            " | c"
        } else {
            ""
        }
    );
    for (a, m) in &c.models {
        let _ = write!(
            out,
            "- {}: θ = [{}], φ = [{}]",
            a.name(),
            coef_list(m.theta()),
            coef_list(m.phi())
        );
        if c.offset == Offset::Intercept {
            let _ = write!(out, ", c = {:.4}", m.intercept());
        }
        let _ = writeln!(out, ", static gain {:.1} slm/duty", m.static_gain());
    }
    let _ = writeln!(
        out,
        "\nAll models are scored by `ridge_core::Evaluation`: both predictors are seeded with the \
         first m = max(p, d+q−1) = {} measured samples and scored on samples m..N (SPEC §6), \
         not from the zero history used for estimation. RLS: λ = {RLS_LAMBDA}, δ = {RLS_DELTA}, \
         one update per sample over the whole record, final estimate. ALASSO: weights 1/|w_OLS|, \
         λ by BIC over a 30-point path. OLS is a reference column, not in the paper.\n",
        c.structure.seed_len()
    );
}

fn sweep_md(out: &mut String, s: &Sweep) {
    let _ = writeln!(
        out,
        "### Table 4 ({}): γ sweep, identified on {}, validated on {}\n",
        short_criterion(s.criterion),
        s.identification.name(),
        s.validation.name()
    );
    let _ = writeln!(
        out,
        "| γ | free-run RMSE | one-step RMSE | (p, q, d) | | free-run RMSE | one-step RMSE | (p, q, d) | iterates | theory: γ/(λ+γ)·ρ¹⁹⁹ |"
    );
    let _ = writeln!(out, "|---:|---:|---:|:---:|---|---:|---:|:---:|---:|---:|");
    let _ = writeln!(
        out,
        "| | **without momentum (Ridge)** | | | | **with momentum (Ridge-M)** | | | | |"
    );
    let o = &s.ols;
    let _ = writeln!(
        out,
        "| OLS (γ=0) | {:.4} | {:.4} | {} | | | | | | |",
        o.rmse.free_run,
        o.rmse.one_step,
        st(o.structure)
    );
    for r in &s.rows {
        let _ = writeln!(
            out,
            "| 1e{} | {:.4} | {:.4} | {} | | {:.4} | {:.4} | {} | {} | {:.2e} |",
            r.gamma.log10().round() as i32,
            r.plain.rmse.free_run,
            r.plain.rmse.one_step,
            st(r.plain.structure),
            r.momentum.rmse.free_run,
            r.momentum.rmse.one_step,
            st(r.momentum.structure),
            r.momentum.iterations,
            r.residual_factor
        );
    }
    let _ = writeln!(
        out,
        "\nRMSE in slm on {}, seeded with measured samples (SPEC §6). \"iterates\": Ridge-M \
         iterates on the pick (200 = stopped by max_iter, not by ε = 1e-6). Theory column: after \
         200 iterates Ridge-M differs from least squares by the factor γ/(λ+γ)·ρ¹⁹⁹, \
         ρ = β + (1−β)γ/(λ+γ), in the eigen-mode λ of XᵀX; shown for the smallest eigenvalue \
         of any candidate, λ_min = {:.4} at ARX{} (largest eigenvalues ~1e8). Where it is ≪ 1, \
         Ridge-M is least squares on every candidate and must pick what OLS picks.\n",
        s.validation.name(),
        s.lambda_min.0,
        st(s.lambda_min.1)
    );
}

fn convergence_md(out: &mut String, crit: Criterion, c: &Convergence, table: u8) {
    let s = c.structure;
    let _ = writeln!(
        out,
        "### Table {table} ({}): Ridge-M coefficients vs iteration, γ = {}, ARX{} on A-Multistep\n",
        short_criterion(crit),
        c.gamma,
        st(s)
    );
    let _ = write!(out, "| Iteration |");
    for i in 1..=s.p {
        let _ = write!(out, " θ{i} |");
    }
    for j in 0..s.q {
        let _ = write!(out, " φ{j} |");
    }
    let _ = writeln!(out);
    let _ = write!(out, "|---:|");
    for _ in 0..(s.p + s.q) {
        let _ = write!(out, "---:|");
    }
    let _ = writeln!(out);
    let rows = c
        .rows
        .iter()
        .map(|(k, m)| (k.to_string(), m))
        .chain(std::iter::once(("OLS".to_string(), &c.ols)));
    for (k, m) in rows {
        let _ = write!(out, "| {k} |");
        for v in m.theta().iter().chain(m.phi()) {
            let _ = write!(out, " {v:.4} |");
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "\nβ = 0.01, tolerance 0 (every iterate runs). Row \"OLS\" is the least-squares solution, \
         the fixed point of the iteration.\n"
    );
}

/// Renders a [`Report`] as markdown.
pub fn render_markdown(r: &Report) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "## Paper tables on the simulated pump (seed {})\n\n\
         Records: `pump_sim::record(Record::…, &PumpParams::default(), {})`, 3000 samples \
         at 100 Hz each (reference blower: dead zone 12–15 % duty, τ = 0.15 s, flow ∝ speed^1.3, \
         150 slm at full duty, transport delay 3 samples; SFM3300 noise 3 % of reading). \
         Statistics: `IntGram::push(raw_u, raw_y − 32768)`, `SCALE`, solved \
         in f64. Coefficients in slm and duty fraction (0..1). Grid p ∈ 1..6, q ∈ 1..6, \
         d ∈ 0..6 (252 candidates).\n",
        r.seed, r.seed
    );
    let _ = writeln!(out, "### Records\n");
    let _ = writeln!(
        out,
        "| Record | N | duty range | duty changes | flow mean (slm) | flow std (slm) | flow range (slm) | sensor noise RMS (slm) |"
    );
    let _ = writeln!(out, "|---|---:|:---:|---:|---:|---:|:---:|---:|");
    for x in &r.records {
        let _ = writeln!(
            out,
            "| {} | {} | {:.2}–{:.2} | {} | {:.2} | {:.2} | {:.2}–{:.2} | {:.2} |",
            x.record.name(),
            x.samples,
            x.u_range.0,
            x.u_range.1,
            x.u_changes,
            x.y_mean,
            x.y_std,
            x.y_range.0,
            x.y_range.1,
            x.noise_rms
        );
    }
    let _ = writeln!(
        out,
        "\n\"duty changes\": samples with u_t ≠ u_(t−1), the only samples at which delays d and \
         d+1 give different regressors. On a ramp the difference u_(t−d) − u_(t−d−1) is the \
         constant slope almost everywhere, which a neighbouring input lag absorbs: ramps carry \
         almost no information about d.\n"
    );
    let _ = writeln!(out, "### Structures picked by the Ridge-M search\n");
    let _ = writeln!(
        out,
        "| Identification record | paper criterion | delay-free AIC |"
    );
    let _ = writeln!(out, "|---|:---:|:---:|");
    for (name, t) in [("A-Multistep", &r.table1), ("A-Ramp", &r.table5)] {
        let _ = writeln!(
            out,
            "| {name} | {} | {} |",
            st(t[0].structure),
            st(t[1].structure)
        );
    }
    let _ = writeln!(
        out,
        "| A-Multistep, intercept | — | {} |\n\nTrue transport delay of the simulated plant: \
         d = 3. The paper reports (5, 6, 4) on its A-Multistep and (5, 1, 0) on its A-Ramp.\n",
        st(r.intercept.structure)
    );
    for c in &r.table1 {
        comparison_md(&mut out, "Table 1", c);
    }
    for c in &r.table5 {
        comparison_md(&mut out, "Table 5", c);
    }
    comparison_md(&mut out, "Table 1 with intercept", &r.intercept);
    for s in &r.table4 {
        sweep_md(&mut out, s);
    }
    for (crit, tables) in &r.convergence {
        for (c, n) in tables.iter().zip([2u8, 3]) {
            convergence_md(&mut out, *crit, c, n);
        }
    }
    let _ = writeln!(
        out,
        "### Pruned search vs exhaustive grid (A-Multistep, Ridge-M)\n"
    );
    let _ = writeln!(
        out,
        "| Criterion | Offset | pruned pick | Ridge-M runs (pruned) | exhaustive pick | Ridge-M runs (exhaustive) | same score |"
    );
    let _ = writeln!(out, "|---|---|:---:|---:|:---:|---:|:---:|");
    for p in &r.pruning {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} of {} | {} | {} | {} |",
            short_criterion(p.criterion),
            offset_name(p.offset),
            st(p.pruned),
            p.evaluated,
            p.candidates,
            st(p.exhaustive),
            p.exhaustive_evaluated,
            if p.same_score { "yes" } else { "no" }
        );
    }
    let _ = writeln!(out);
    let _ = writeln!(
        out,
        "### f32 vs f64 solves on the same integer statistics (A-Multistep, Ridge-M)\n"
    );
    let _ = writeln!(
        out,
        "| Criterion | f64 pick | f32 pick | Ridge-M runs f64 / f32 | max abs coef diff | max abs coef | free-run RMSE f64 / f32 |"
    );
    let _ = writeln!(out, "|---|:---:|:---:|---:|---:|---:|---:|");
    for p in &r.precision {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} / {} | {:.3e} | {:.4} | {:.4} / {:.4} |",
            short_criterion(p.criterion),
            st(p.structure_f64),
            st(p.structure_f32),
            p.evaluated.0,
            p.evaluated.1,
            p.max_coef_diff,
            p.max_coef,
            p.free_run.0,
            p.free_run.1
        );
    }
    let _ = writeln!(
        out,
        "\nCoefficient difference: Ridge-M fitted in f32 and in f64 on the f64 pick; the f32 model \
         is scored in f64 arithmetic.\n"
    );
    let f = &r.forgetting;
    let _ = writeln!(
        out,
        "### RLS forgetting factor (A-Multistep, ARX{}, final estimate, mean over the four records)\n",
        st(f.structure)
    );
    let _ = writeln!(out, "| λ | mean free-run RMSE | mean one-step RMSE |");
    let _ = writeln!(out, "|---:|---:|---:|");
    for (l, m) in &f.rows {
        let _ = writeln!(out, "| {l} | {:.4} | {:.4} |", m.free_run, m.one_step);
    }
    let _ = writeln!(out);
    if let Some(first) = r.census.first() {
        let _ = writeln!(
            out,
            "### Seed census: picks over {} sensor-noise seeds ({}..{})\n",
            first.seeds,
            r.seed,
            r.seed.wrapping_add(u64::from(first.seeds) - 1)
        );
    }
    let _ = writeln!(
        out,
        "| Record | Criterion | Offset | Estimator | d = 0 | 1 | 2 | 3 | 4 | 5 | 6 | d = 0 or q = 6 | most frequent pick |"
    );
    let _ = writeln!(
        out,
        "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|:---|"
    );
    for c in &r.census {
        let _ = write!(
            out,
            "| {} | {} | {} | {} |",
            c.record.name(),
            short_criterion(c.criterion),
            offset_name(c.offset),
            if c.ols { "OLS" } else { "Ridge-M" }
        );
        for n in c.d_counts {
            let _ = write!(out, " {n} |");
        }
        let _ = writeln!(
            out,
            " {} of {} | {} ×{} |",
            c.flaw_pattern,
            c.seeds,
            st(c.mode.0),
            c.mode.1
        );
    }
    let _ = writeln!(
        out,
        "\nTrue delay 3. \"d = 0 or q = 6\": the pattern the paper criterion must follow with least \
         squares, since (p, q+d, 0) nests (p, q, d) at the same penalty (SPEC §4).\n"
    );
    out
}
