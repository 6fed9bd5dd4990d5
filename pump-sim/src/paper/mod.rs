//! The paper's experiments (section 3, Tables 1–5) on simulated pump records.
//!
//! Every record is simulated by [`crate::record`] on the reference blower
//! ([`crate::PumpParams::default`]: true transport delay 3 samples, dead zone, convex fan
//! curve) and fed to the statistics exactly as the firmware will: a [`ridge_core::IntGram`] of
//! `(raw_u, raw_y − 32768)` with [`ridge_pump_firmware::units::SCALE`], solved in `f64` (and
//! in `f32` for the precision check). Models are therefore in duty fraction (0..1) and slm.
//!
//! Models are scored with [`ridge_core::Evaluation`]: one-step-ahead and free-run RMSE, both
//! seeded with the first `m = max(p, d + q − 1)` measured samples and scored on samples `m..N`,
//! so that no model is charged for a start-up transient it cannot know (estimation, like the
//! paper's Algorithm 1, assumes zero history). The paper's own RMSE figures (26–40) were
//! obtained on a real pump with an evaluation protocol it does not state; see
//! `docs/results.md` for the reading.
//!
//! The experiments return plain structs (for the tests); [`Tables::compute`] runs them all
//! and [`Tables::to_markdown`] renders what the `paper-tables` binary prints.
//!
//! One file per concern:
//!
//! - [`dataset`]: the simulated records, their exact statistics and a summary of each;
//! - [`estimate`]: the structure search with the paper's α, RLS over a log, and models from
//!   coefficient vectors;
//! - [`score`]: one-step and free-run RMSE of a model on a log;
//! - [`comparison`](mod@comparison): Tables 1 and 5 (every estimator on the searched
//!   structure);
//! - [`convergence`](mod@convergence): Tables 2–3 (Ridge-M iterates against the iteration
//!   count);
//! - [`sweep`]: Table 4 (the γ sweep with and without momentum);
//! - [`spectrum`]: eigenvalues of `XᵀX` and what they imply for Ridge-M after `k` iterates;
//! - checks with no paper counterpart: [`pruning`](mod@pruning) (pruned vs exhaustive
//!   search), [`precision`](mod@precision) (`f32` vs `f64`), [`forgetting`] (RLS forgetting
//!   factors), [`census`](mod@census) (picks over many noise seeds);
//! - [`markdown`]: the rendering printed by `paper-tables`.

pub mod census;
pub mod comparison;
pub mod convergence;
pub mod dataset;
pub mod estimate;
pub mod forgetting;
pub mod markdown;
pub mod precision;
pub mod pruning;
pub mod score;
pub mod spectrum;
pub mod sweep;

use ridge_core::{Criterion, Offset, Real, Result, RidgeM};
use ridge_pump_firmware::excitation::Record;

pub use census::{census, CensusRow, CENSUS_RECORDS, CENSUS_SEARCHES, CENSUS_SEEDS};
pub use comparison::{comparison, Comparison, Estimate, COMPARED};
pub use convergence::{convergence, Convergence, ITERATIONS};
pub use dataset::{int_gram, record_index, Dataset, RecordSummary};
pub use estimate::{model_from_internal, rls, search};
pub use forgetting::{rls_forgetting, Forgetting, FORGETTING};
pub use precision::{precision, Precision};
pub use pruning::{pruning, Pruning};
pub use score::Rmse;
pub use spectrum::{
    gram_matrix, ridge_m_residual_factor, smallest_eigenvalue_over_grid, symmetric_eigenvalues,
};
pub use sweep::{gamma_sweep, Sweep, SweepPick, SweepRow, GAMMAS};

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
/// The two criteria compared throughout (in this order in every table).
pub const CRITERIA: [Criterion; 2] = [Criterion::Paper, Criterion::Aic];

/// Ridge-M with the paper's hyper-parameters (γ = 1000, β = 0.01, ε = 1e-6, 200 iterates).
pub fn ridge_m<T: Real>() -> RidgeM<T> {
    RidgeM::default()
}

/// Every table `paper-tables` prints, as numbers: the paper's Tables 1–5 on the simulated
/// records plus the checks with no paper counterpart.
#[derive(Clone, Debug)]
pub struct Tables {
    /// Noise seed.
    pub seed: u64,
    /// The four records.
    pub records: Vec<RecordSummary>,
    /// Table 1 (A-Multistep), one per criterion of [`CRITERIA`].
    pub table1: Vec<Comparison>,
    /// Table 5 (A-Ramp), one per criterion of [`CRITERIA`].
    pub table5: Vec<Comparison>,
    /// Table 1 with an intercept, delay-free AIC.
    pub intercept: Comparison,
    /// Table 4, one per criterion of [`CRITERIA`].
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

impl Tables {
    /// Simulates the records with sensor-noise seed `seed` and runs every experiment.
    pub fn compute(seed: u64) -> Result<Tables> {
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
            .map(|(&r, l)| RecordSummary::of(r, l))
            .collect();
        Ok(Tables {
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
}
