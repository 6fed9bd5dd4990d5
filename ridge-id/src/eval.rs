//! Streaming passes over a CSV record: statistics for estimation ([`read_record`]) and
//! scores of a model ([`evaluate_file`]), each in constant memory.
//!
//! Scores are from measured initial conditions: the one-step-ahead and free-run predictors
//! are seeded with the first `m = max(p, d + q − 1)` measured samples and scored on
//! samples `m..N` ([`ridge_core_host::Evaluation`]), as MATLAB `compare` and SysIdentPy do, so a
//! model is not charged for a start-up transient it cannot know. (Estimation keeps the
//! paper's zero history before the record, eq. 6 of the paper (Ridge-M ventilation pump).)

use std::path::{Path, PathBuf};

use ridge_core_host::{ArxModel, Error as CoreError, Evaluation, MeasuredGram, Normal, Scale};

use crate::csv::{CsvRecord, Sample};
use crate::error::IdError;
use crate::residuals::{ResidualStats, Residuals};

/// The statistics of one record after a streaming pass, plus what is needed to explain
/// a problem with it.
#[derive(Debug, Clone)]
pub struct RecordStats {
    /// The file.
    pub path: PathBuf,
    /// Exact streaming statistics of all samples (f64 sums), the first
    /// [`MeasuredGram::initial`] of them only filling the lag history.
    pub gram: MeasuredGram<f64>,
    /// Line of the first and last sample (0 when there is none).
    pub lines: (u64, u64),
    /// Smallest and largest input.
    pub u_range: (f64, f64),
    /// Smallest and largest output.
    pub y_range: (f64, f64),
}

impl RecordStats {
    /// Number of samples.
    pub fn rows(&self) -> u32 {
        self.gram.len()
    }

    /// `""`, or with measured initial conditions `" (the first M only fill the lag history)"`.
    pub fn initial_note(&self) -> String {
        match self.gram.initial() {
            0 => String::new(),
            m => format!(" (the first {m} only fill the lag history: --initial measured)"),
        }
    }

    /// `"1024 data rows (lines 2–1025)"`.
    pub fn describe_rows(&self) -> String {
        match self.rows() {
            0 => "no data rows".to_string(),
            1 => format!("1 data row (line {})", self.lines.0),
            n => format!("{n} data rows (lines {}–{})", self.lines.0, self.lines.1),
        }
    }

    /// The solve-time statistics in physical units (`f64`, [`Scale::UNIT`]).
    ///
    /// Errors name the file: fewer than 2 rows, or a constant input or output (the
    /// record does not excite the plant).
    pub fn normal(&self) -> Result<Normal<f64>, IdError> {
        self.gram
            .normal::<f64>(Scale::UNIT)
            .map_err(|e| match e {
                CoreError::NotExcited => {
                    let what = if self.u_range.0 == self.u_range.1 {
                        format!(
                            "column u is constant ({:?}) over all {}: the input does not excite the plant",
                            self.u_range.0,
                            self.describe_rows()
                        )
                    } else if self.y_range.0 == self.y_range.1 {
                        format!(
                            "column y is constant ({:?}) over all {}: the output shows no response",
                            self.y_range.0,
                            self.describe_rows()
                        )
                    } else {
                        format!(
                            "input or output varies too little to identify anything ({}; u in [{:?}, {:?}], y in [{:?}, {:?}])",
                            self.describe_rows(),
                            self.u_range.0,
                            self.u_range.1,
                            self.y_range.0,
                            self.y_range.1
                        )
                    };
                    IdError::file(&self.path, what)
                }
                CoreError::TooShort { needed, .. } => IdError::file(
                    &self.path,
                    format!(
                        "{}, at least {} needed{}",
                        self.describe_rows(),
                        needed + self.gram.initial(),
                        self.initial_note()
                    ),
                ),
                other => IdError::file(&self.path, format!("{other}")),
            })
    }
}

/// Reads a whole CSV record into streaming statistics with zero history (one pass, constant
/// memory).
///
/// Errors: everything [`CsvRecord`] reports, with file and line.
pub fn read_record(path: impl AsRef<Path>) -> Result<RecordStats, IdError> {
    read_record_with(path, 0)
}

/// [`read_record`] whose first `initial` samples only fill the lag history (measured
/// initial conditions, [`MeasuredGram`]).
pub fn read_record_with(path: impl AsRef<Path>, initial: u32) -> Result<RecordStats, IdError> {
    let path = path.as_ref();
    read_samples(path, CsvRecord::open(path)?, MeasuredGram::new(initial))
}

/// [`read_record_with`] of a stream of samples (e.g. an [`crate::input::Input`]'s) named
/// `path` in messages, into the empty statistics `gram` (e.g. [`MeasuredGram::for_grid`]:
/// only the lags a search uses).
pub fn read_samples<I>(
    path: &Path,
    samples: I,
    gram: MeasuredGram<f64>,
) -> Result<RecordStats, IdError>
where
    I: IntoIterator<Item = Result<Sample, IdError>>,
{
    let mut stats = RecordStats {
        path: path.to_path_buf(),
        gram,
        lines: (0, 0),
        u_range: (f64::INFINITY, f64::NEG_INFINITY),
        y_range: (f64::INFINITY, f64::NEG_INFINITY),
    };
    for s in samples {
        let s = s?;
        stats.gram.push(s.u, s.y).map_err(|e| {
            IdError::line(
                path,
                s.line,
                format!(
                    "cannot add this sample to the statistics ({e}): u = {:?}, y = {:?}: \
                     too large for f64 sums over this many rows",
                    s.u, s.y
                ),
            )
        })?;
        if stats.lines.0 == 0 {
            stats.lines.0 = s.line;
        }
        stats.lines.1 = s.line;
        stats.u_range = (stats.u_range.0.min(s.u), stats.u_range.1.max(s.u));
        stats.y_range = (stats.y_range.0.min(s.y), stats.y_range.1.max(s.y));
    }
    Ok(stats)
}

/// Scores of one model on one record, from measured initial conditions (samples `m..N`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// Samples scored: `N − m`.
    pub n: u32,
    /// One-step-ahead RMSE (eq. 16), output units.
    pub rmse_one_step: f64,
    /// Free-run RMSE, output units.
    pub rmse_free_run: f64,
    /// One-step fit %, `100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)`.
    pub fit_one_step: f64,
    /// Free-run fit % (what MATLAB `compare` shows).
    pub fit_free_run: f64,
    /// Residual analysis of the one-step residuals on the scored samples (MATLAB `resid`);
    /// `None` when they are all zero or the input is constant there.
    pub residuals: Option<Residuals>,
}

/// Scores `model` on a stream of samples; `trace` (if any) receives every measured and
/// predicted value for a plot. `Ok(None)` when the stream has no sample past the seed.
pub fn evaluate<I>(
    samples: I,
    model: ArxModel<f64>,
    mut trace: Option<&mut Trace>,
) -> Result<Option<Figures>, IdError>
where
    I: IntoIterator<Item = Result<Sample, IdError>>,
{
    let mut ev = Evaluation::new(model);
    let mut resid = ResidualStats::new();
    for (i, s) in samples.into_iter().enumerate() {
        let s = s?;
        let pred = ev.push(s.u, s.y);
        if let Some((one_step, _)) = pred {
            resid.push(s.u, s.y - one_step);
        }
        if let Some(t) = trace.as_deref_mut() {
            t.push(i as u64, s.y, pred);
        }
    }
    if let Some(t) = trace {
        t.finish();
    }
    Ok(match (ev.one_step(), ev.free_run()) {
        (Some(a), Some(b)) => Some(Figures {
            n: a.n,
            rmse_one_step: a.rmse,
            rmse_free_run: b.rmse,
            fit_one_step: a.fit,
            fit_free_run: b.fit,
            residuals: resid.finish(),
        }),
        _ => None,
    })
}

/// Scores `model` on the CSV record at `path` in one streaming pass (see [`evaluate`]).
///
/// Errors: CSV errors with file and line; a record with no sample past the `m` seed
/// samples.
pub fn evaluate_file(
    path: impl AsRef<Path>,
    model: ArxModel<f64>,
    trace: Option<&mut Trace>,
) -> Result<Figures, IdError> {
    let path = path.as_ref();
    evaluate(CsvRecord::open(path)?, model, trace)?.ok_or_else(|| too_short_to_score(path, &model))
}

/// The error of a record with no sample past the model's seed.
pub(crate) fn too_short_to_score(path: &Path, model: &ArxModel<f64>) -> IdError {
    let m = model.structure().seed_len();
    IdError::file(
        path,
        format!(
            "too short to score the model: its first {m} samples only seed the predictors, at least {} data rows needed",
            m + 1
        ),
    )
}

/// Points a [`Trace`] of a run keeps per signal for the plot.
pub const PLOT_POINTS: usize = 2000;

/// A bounded picture of one signal for plotting: every sample while the record has at
/// most `max_points` samples, otherwise the minimum and maximum of each of
/// `max_points / 2` equal buckets (a min/max envelope, so spikes stay visible).
#[derive(Debug, Clone, Default)]
pub struct Envelope {
    /// One entry per bucket in index order: `(first sample index, min, max)`; without
    /// decimation every bucket is one sample and `min == max`.
    pub buckets: Vec<(f64, f64, f64)>,
    current: Option<Bucket>,
}

/// The open bucket of an [`Envelope`].
#[derive(Debug, Clone, Copy)]
struct Bucket {
    id: u64,
    first: u64,
    lo: f64,
    hi: f64,
}

impl Envelope {
    fn push(&mut self, bucket: u64, i: u64, v: f64) {
        if !v.is_finite() {
            return;
        }
        let b = i / bucket.max(1);
        match &mut self.current {
            Some(c) if c.id == b => {
                c.lo = c.lo.min(v);
                c.hi = c.hi.max(v);
            }
            _ => {
                self.flush();
                self.current = Some(Bucket {
                    id: b,
                    first: i,
                    lo: v,
                    hi: v,
                });
            }
        }
    }

    fn flush(&mut self) {
        if let Some(c) = self.current.take() {
            self.buckets.push((c.first as f64, c.lo, c.hi));
        }
    }

    /// Smallest and largest value, if any.
    pub fn range(&self) -> Option<(f64, f64)> {
        self.buckets
            .iter()
            .fold(None, |acc, &(_, lo, hi)| match acc {
                None => Some((lo, hi)),
                Some((a, b)) => Some((a.min(lo), b.max(hi))),
            })
    }

    /// The lower outline `(index, min)`: the signal itself when not decimated.
    pub fn lower(&self) -> Vec<(f64, f64)> {
        self.buckets.iter().map(|&(x, lo, _)| (x, lo)).collect()
    }

    /// The upper outline `(index, max)`.
    pub fn upper(&self) -> Vec<(f64, f64)> {
        self.buckets.iter().map(|&(x, _, hi)| (x, hi)).collect()
    }
}

/// Measured, one-step and free-run output of one record, decimated for a plot
/// (memory bounded by `max_points` per signal whatever the record length).
#[derive(Debug, Clone)]
pub struct Trace {
    /// Samples per bucket.
    bucket: u64,
    /// Samples pushed.
    pub samples: u64,
    /// Measured output.
    pub measured: Envelope,
    /// One-step-ahead prediction (from sample `m` on).
    pub one_step: Envelope,
    /// Free-run simulation (from sample `m` on).
    pub free_run: Envelope,
}

impl Trace {
    /// A trace for a record of `total` samples keeping about `max_points` points per
    /// signal (at least 4).
    pub fn new(total: u64, max_points: usize) -> Self {
        let max_points = max_points.max(4) as u64;
        let bucket = if total <= max_points {
            1
        } else {
            total.div_ceil(max_points / 2)
        };
        Trace {
            bucket,
            samples: 0,
            measured: Envelope::default(),
            one_step: Envelope::default(),
            free_run: Envelope::default(),
        }
    }

    /// Adds sample `i`: the measurement and, once seeded, `(one-step, free-run)`.
    pub fn push(&mut self, i: u64, y: f64, pred: Option<(f64, f64)>) {
        self.samples = self.samples.max(i + 1);
        self.measured.push(self.bucket, i, y);
        if let Some((a, b)) = pred {
            self.one_step.push(self.bucket, i, a);
            self.free_run.push(self.bucket, i, b);
        }
    }

    /// Flushes the last bucket (call once after the last sample).
    pub fn finish(&mut self) {
        self.measured.flush();
        self.one_step.flush();
        self.free_run.flush();
    }

    /// `true` when the signals were decimated to a min/max envelope.
    pub fn decimated(&self) -> bool {
        self.bucket > 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_is_bounded_and_keeps_extremes() {
        let n = 1_000_000u64;
        let mut t = Trace::new(n, 2000);
        for i in 0..n {
            let y = if i == 123_457 {
                500.0
            } else {
                (i % 100) as f64
            };
            t.push(i, y, Some((y, y)));
        }
        t.finish();
        assert!(t.decimated());
        let b = &t.measured.buckets;
        assert!(b.len() <= 1001, "{}", b.len());
        // The one-sample spike survives decimation, and so do the extremes.
        assert_eq!(t.measured.range(), Some((0.0, 500.0)));
        assert_eq!(
            t.measured.upper().iter().filter(|p| p.1 == 500.0).count(),
            1
        );
        assert!(t.measured.lower().iter().all(|p| p.1 == 0.0));
        let mut t = Trace::new(10, 2000);
        for i in 0..10 {
            t.push(i, i as f64, None);
        }
        t.finish();
        assert_eq!(t.measured.lower(), t.measured.upper());
        assert_eq!(t.measured.buckets.len(), 10);
        assert!(t.one_step.buckets.is_empty());
    }
}
