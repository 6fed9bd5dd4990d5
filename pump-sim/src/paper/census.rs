//! Seed census (no paper counterpart): how often each delay is picked when a record is
//! re-simulated with many sensor-noise seeds.

use ridge_core::{Criterion, Error, Method, MethodKind, Offset, Result, Structure};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::SCALE;

use super::{int_gram, ridge_m, search};
use crate::{record, PumpParams};

/// How often each delay is picked over many noise seeds.
#[derive(Clone, Debug, PartialEq)]
pub struct CensusRow {
    /// Record.
    pub record: Record,
    /// Criterion.
    pub criterion: Criterion,
    /// Constant term.
    pub offset: Offset,
    /// Estimator run on every candidate of the search: [`MethodKind::RidgeM`] (the paper's
    /// hyper-parameters) or [`MethodKind::Ols`].
    pub method: MethodKind,
    /// `d_counts[d]`: seeds whose pick has delay `d`.
    pub d_counts: [u32; 7],
    /// Seeds whose pick has `d = 0` or `q = 6` (the paper-criterion flaw pattern).
    pub flaw_pattern: u32,
    /// The most frequent pick and its count.
    pub mode: (Structure, u32),
    /// Seeds.
    pub seeds: u32,
}

/// The searches of the census: (criterion, offset, estimator on every candidate).
pub const CENSUS_SEARCHES: [(Criterion, Offset, MethodKind); 6] = [
    (Criterion::Paper, Offset::None, MethodKind::RidgeM),
    (Criterion::Paper, Offset::None, MethodKind::Ols),
    (Criterion::Paper, Offset::Intercept, MethodKind::RidgeM),
    (Criterion::Paper, Offset::Intercept, MethodKind::Ols),
    (Criterion::Aic, Offset::None, MethodKind::RidgeM),
    (Criterion::Aic, Offset::Intercept, MethodKind::RidgeM),
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
        for (k, &(c, o, kind)) in CENSUS_SEARCHES.iter().enumerate() {
            let method = match kind {
                MethodKind::Ols => Method::Ols,
                MethodKind::RidgeM => Method::RidgeM(ridge_m()),
                _ => return Err(Error::InvalidParameter),
            };
            picks[k].push(search(&normal, c, o, method, true)?.structure());
        }
    }
    Ok(CENSUS_SEARCHES
        .iter()
        .zip(picks)
        .map(|(&(criterion, offset, method), p)| {
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
                method,
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
/// Noise seeds of the census.
pub const CENSUS_SEEDS: u32 = 40;
