//! The statistics pass: a record into exact streaming statistics ([`read_record`],
//! [`RecordStats`]), with what is needed to explain a problem with it.

use std::path::{Path, PathBuf};

use ridge_core_host::{Error as CoreError, MeasuredGram, Normal, Scale};

use crate::csv::{CsvRecord, Sample};
use crate::error::IdError;

/// Products of two samples below this are too small for `f64` statistics: near the
/// subnormal range (2.2e-308) sums of squares lose their precision.
pub const TINY_PRODUCT: f64 = 1e-280;

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
    /// Standard deviation of the input over all samples (0 for a constant one).
    pub u_std: f64,
    /// Standard deviation of the output over all samples.
    pub y_std: f64,
}

/// The spread of one signal in one pass: sums of the deviations from its first sample (the
/// variance does not change, and the sums do not cancel when the signal has a large mean).
#[derive(Debug, Clone, Copy, Default)]
struct Spread {
    n: u64,
    first: f64,
    sum: f64,
    squares: f64,
}

impl Spread {
    fn push(&mut self, v: f64) {
        if self.n == 0 {
            self.first = v;
        }
        let d = v - self.first;
        self.n += 1;
        self.sum += d;
        self.squares += d * d;
    }

    /// The standard deviation (population: over `n`), 0 without samples.
    fn std(&self) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        let n = self.n as f64;
        let mean = self.sum / n;
        (self.squares / n - mean * mean).max(0.0).sqrt()
    }
}

impl RecordStats {
    /// Number of samples.
    pub fn rows(&self) -> u32 {
        self.gram.len()
    }

    /// The largest `|u|` and `|y|`.
    pub fn largest(&self) -> (f64, f64) {
        let big = |r: (f64, f64)| r.0.abs().max(r.1.abs());
        (big(self.u_range), big(self.y_range))
    }

    /// `true` when products of two samples fall below [`TINY_PRODUCT`]: the record's values
    /// are too small for `f64` statistics.
    pub fn tiny(&self) -> bool {
        let (u, y) = self.largest();
        (u * u).min(u * y).min(y * y) < TINY_PRODUCT
    }

    /// The scale that standardises this record: `u / σ_u`, `y / σ_y` (its standard
    /// deviations); `None` for a constant signal, or values too small for `f64` statistics
    /// ([`RecordStats::tiny`]: their sums are not exact enough to be rescaled).
    pub fn standard_scale(&self) -> Option<Scale> {
        let ok = |s: f64| s.is_finite() && s > 0.0;
        (ok(self.u_std) && ok(self.y_std) && !self.tiny()).then(|| Scale {
            u: 1.0 / self.u_std,
            y: 1.0 / self.y_std,
        })
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
        self.normal_scaled(Scale::UNIT)
    }

    /// The solve-time statistics of the samples times `scale` (e.g. divided by their
    /// standard deviations: [`RecordStats::standard_scale`]). Errors as [`RecordStats::normal`].
    pub fn normal_scaled(&self, scale: Scale) -> Result<Normal<f64>, IdError> {
        self.gram
            .normal::<f64>(scale)
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
        u_std: 0.0,
        y_std: 0.0,
    };
    let (mut su, mut sy) = (Spread::default(), Spread::default());
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
        su.push(s.u);
        sy.push(s.y);
    }
    (stats.u_std, stats.y_std) = (su.std(), sy.std());
    Ok(stats)
}
