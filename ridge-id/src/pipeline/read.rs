//! The pipeline's first step: the records of a run read into their statistics ([`read`] →
//! [`Records`]), the estimation record a `--phase` segment when asked, each checked long
//! enough and excited.

use ridge_core_host::{Criterion, Grid, MeasuredGram, Normal, Offset, Scale, Structure};

use crate::error::IdError;
use crate::eval::RecordStats;
use crate::input::Input;
use crate::options::Options;
use crate::phase::{self, Segment};

/// The records of a run and their statistics.
#[derive(Debug)]
pub(super) struct Records {
    /// The grid searched.
    pub grid: Grid,
    /// Samples that only fill the lag history (measured initial conditions).
    pub initial: u32,
    /// The `--phase` segment the estimation record is, if any.
    pub segment: Option<Segment>,
    /// The estimation record.
    pub est_in: Input,
    /// The validation record, if any.
    pub val_in: Option<Input>,
    /// The operating point subtracted before the statistics, `(u0, y0)` (`--phase`).
    pub shift: Option<(f64, f64)>,
    /// The estimation record's statistics.
    pub est: RecordStats,
    /// The validation record's statistics.
    pub val: Option<RecordStats>,
    /// The estimation record's normal equations.
    pub est_normal: Normal<f64>,
    /// The validation record's normal equations, for `--criterion validation` only.
    pub val_normal: Option<Normal<f64>>,
    /// The scale the estimator runs on (the estimation record standardised, see
    /// [`Options::standardises`]), with the normal equations of both records on it; `None`:
    /// the data as they are.
    pub standard: Option<Standard>,
}

/// The records standardised for the estimator: both divided by the estimation record's
/// standard deviations.
#[derive(Debug)]
pub(super) struct Standard {
    /// `u / σ_u`, `y / σ_y`.
    pub scale: Scale,
    /// The estimation record's normal equations on that scale.
    pub est_normal: Normal<f64>,
    /// The validation record's, for `--criterion validation` only.
    pub val_normal: Option<Normal<f64>>,
}

impl Records {
    /// The normal equations the estimator runs on: `(estimation, validation)`.
    pub fn search_normals(&self) -> (&Normal<f64>, Option<&Normal<f64>>) {
        match &self.standard {
            Some(s) => (&s.est_normal, s.val_normal.as_ref()),
            None => (&self.est_normal, self.val_normal.as_ref()),
        }
    }
}

/// Regression rows a structure needs on a record: `m` seed samples, one per coefficient, plus
/// one (the core's [`ridge_core_host::Normal::system`] rule; with measured initial conditions
/// the record needs the `M` initial samples more).
pub fn rows_needed(s: Structure, offset: Offset) -> u32 {
    (s.seed_len() + s.params(offset) + 1) as u32
}

/// Checks that `rec` has enough rows for the smallest candidate of `grid`.
fn check_rows(rec: &RecordStats, grid: &Grid, offset: Offset) -> Result<(), IdError> {
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

/// Reads the records of `opts` into their statistics (the lags of the grid's candidates
/// only), the estimation record the `--phase` segment around its operating point when asked.
///
/// Errors: unreadable or malformed records, a segment that cannot be used, records too short
/// for the grid or without excitation (a validation record too, though only
/// `--criterion validation` needs its statistics: it could not validate anything).
pub(super) fn read(opts: &Options) -> Result<Records, IdError> {
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
            // The model's input is the map's flow when the segment's was: the validation
            // record's duty goes through the same map.
            let val = match &seg.map {
                Some(m) => val.map(|v| v.through(*m)),
                None => val,
            };
            (seg.input(), val)
        }
        None => Input::open_pair(&opts.input, opts.validate.as_deref())?,
    };
    let shift = segment.as_ref().and_then(|s| s.operating_point);
    // Statistics of the lags the grid's candidates use only (exactly theirs).
    let gram = || MeasuredGram::for_grid(initial, &grid);
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
    let standard = match est.standard_scale().filter(|_| opts.standardises()) {
        Some(scale) => Some(Standard {
            scale,
            est_normal: est.normal_scaled(scale)?,
            val_normal: match (&val, &val_normal) {
                (Some(v), Some(_)) => Some(v.normal_scaled(scale)?),
                _ => None,
            },
        }),
        None => None,
    };
    Ok(Records {
        grid,
        initial,
        segment,
        est_in,
        val_in,
        shift,
        est,
        val,
        est_normal,
        val_normal,
        standard,
    })
}
