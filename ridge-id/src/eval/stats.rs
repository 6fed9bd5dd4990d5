//! The statistics pass: a record into exact streaming statistics ([`read_record`],
//! [`RecordStats`]), with what is needed to explain a problem with it.

use std::path::{Path, PathBuf};

use ridge_core_host::{Error as CoreError, MeasuredGram, Normal, Scale};

use crate::csv::{CsvRecord, Sample};
use crate::error::IdError;

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
