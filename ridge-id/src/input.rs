//! Where a record comes from: a regular file, streamed anew for every pass, or input that
//! can be read only once (standard input as `--input -`, a pipe, a FIFO, a character
//! device), read once into memory within a stated bound.
//!
//! An identification run reads its estimation record two or three times (statistics,
//! scores, RLS) and its validation record twice. A regular file is simply opened again
//! for each pass, in constant memory whatever its length. Input that cannot be read
//! twice — a FIFO opened a second time waits for a writer that has gone, a pipe reads as
//! empty — is parsed once into [`Sample`]s (24 bytes a row) and the passes run over them:
//! at most [`MEMORY_ROWS`] rows (2²² = 4 194 304 rows, 96 MiB), beyond which the run stops
//! with an error naming the line, rather than grow without bound.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ridge_core_host::{ArxModel, MeasuredGram};

use crate::csv::{CsvRecord, Sample};
use crate::error::IdError;
use crate::eval::{evaluate, read_samples, too_short_to_score, Figures, RecordStats, Trace};

/// Rows read into memory at most from input that can be read only once (2²² rows:
/// 96 MiB of samples).
pub const MEMORY_ROWS: usize = 1 << 22;

/// The name standard input (`--input -`) goes by in messages and reports.
pub const STDIN_NAME: &str = "<stdin>";

/// A record ready to be read as many times as a run needs.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    /// A regular file, streamed from disk for every pass.
    File(PathBuf),
    /// Input that can be read only once, parsed into memory (at most [`MEMORY_ROWS`] rows).
    Memory {
        /// The name used in messages ([`STDIN_NAME`] for standard input).
        name: PathBuf,
        /// Every sample, in order, with its line (shared: the same input may be both the
        /// estimation and the validation record).
        samples: Arc<Vec<Sample>>,
    },
    /// Another input whose `u` (a duty fraction) is read through a pump's static map: the
    /// map's flow there, slm (the input of the pump's model, `--phase` on a capture with a
    /// `# MAP` line).
    Through {
        /// The input as logged.
        input: Box<Input>,
        /// The map.
        map: crate::phase::DeviceMap,
    },
}

impl Input {
    /// Prepares `path` for reading: `-` is standard input, a regular file is streamed, and
    /// anything else that can be opened (a FIFO, `/dev/stdin` on a pipe, a character
    /// device) is read once now ([`Input::read_once`] with [`MEMORY_ROWS`]).
    ///
    /// Errors: the path cannot be opened or is a directory; for input read now, every
    /// CSV error (file and line named) and a record longer than [`MEMORY_ROWS`] rows.
    pub fn open(path: &Path) -> Result<Input, IdError> {
        if path == Path::new("-") {
            return Input::read_once(std::io::stdin().lock(), STDIN_NAME, MEMORY_ROWS);
        }
        let io = |source| IdError::Io {
            path: path.to_path_buf(),
            line: None,
            source,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if meta.is_file() {
            return Ok(Input::File(path.to_path_buf()));
        }
        if meta.is_dir() {
            return Err(IdError::file(path, "is a directory, not a CSV file"));
        }
        let file = File::open(path).map_err(io)?;
        Input::read_once(file, path, MEMORY_ROWS)
    }

    /// Parses `reader` (named `name` in messages) into memory, at most `max_rows` rows.
    ///
    /// Errors: every CSV error, with file and line; a row past `max_rows`, with its line.
    pub fn read_once(
        reader: impl std::io::Read,
        name: impl AsRef<Path>,
        max_rows: usize,
    ) -> Result<Input, IdError> {
        let name = name.as_ref().to_path_buf();
        let mut samples: Vec<Sample> = Vec::new();
        for s in CsvRecord::from_reader(reader, &name)? {
            let s = s?;
            if samples.len() >= max_rows {
                return Err(IdError::line(
                    &name,
                    s.line,
                    format!(
                        "more than {max_rows} data rows: standard input, pipes and FIFOs are \
                         read once into memory, at most {max_rows} rows; save the log to a \
                         file, which is streamed whatever its length"
                    ),
                ));
            }
            if samples.len() == samples.capacity() {
                // Doubling, but never past the bound.
                let more = samples.len().max(4096).min(max_rows - samples.len());
                samples.reserve_exact(more);
            }
            samples.push(s);
        }
        Ok(Input::Memory {
            name,
            samples: Arc::new(samples),
        })
    }

    /// The estimation record `input` and the validation record `validate`, each prepared by
    /// [`Input::open`]; the same path given twice and read into memory is read once and
    /// shared (a FIFO or standard input cannot be read twice).
    pub fn open_pair(
        input: &Path,
        validate: Option<&Path>,
    ) -> Result<(Input, Option<Input>), IdError> {
        let est = Input::open(input)?;
        let val = match validate {
            Some(v) if v == input && est.in_memory() => Some(est.clone()),
            Some(v) => Some(Input::open(v)?),
            None => None,
        };
        Ok((est, val))
    }

    /// The name of the record in messages and reports.
    pub fn name(&self) -> &Path {
        match self {
            Input::File(p) => p,
            Input::Memory { name, .. } => name,
            Input::Through { input, .. } => input.name(),
        }
    }

    /// `true` when the record was read into memory (it cannot be opened again).
    pub fn in_memory(&self) -> bool {
        match self {
            Input::Memory { .. } => true,
            Input::Through { input, .. } => input.in_memory(),
            Input::File(_) => false,
        }
    }

    /// This input with `u` read through `map` (see [`Input::Through`]).
    pub fn through(self, map: crate::phase::DeviceMap) -> Input {
        Input::Through {
            input: Box::new(self),
            map,
        }
    }

    /// One pass over the samples: a regular file is opened (and its header read) anew.
    ///
    /// Errors: as [`CsvRecord::open`].
    pub fn samples(&self) -> Result<Samples<'_>, IdError> {
        Ok(match self {
            Input::File(p) => Samples::File(Box::new(CsvRecord::open(p)?)),
            Input::Memory { samples, .. } => Samples::Memory(samples.iter()),
            Input::Through { input, map } => Samples::Through(Box::new(input.samples()?), *map),
        })
    }
}

/// [`crate::read_record_with`] of an [`Input`]: its statistics in one pass into the empty
/// `gram` (its first [`MeasuredGram::initial`] samples filling the lag history only).
pub fn read_input(input: &Input, gram: MeasuredGram<f64>) -> Result<RecordStats, IdError> {
    read_samples(input.name(), input.samples()?, gram)
}

/// [`crate::evaluate_file`] of an [`Input`]: the scores of `model` in one pass.
pub fn evaluate_input(
    input: &Input,
    model: ArxModel<f64>,
    trace: Option<&mut Trace>,
) -> Result<Figures, IdError> {
    evaluate(input.samples()?, model, trace)?
        .ok_or_else(|| too_short_to_score(input.name(), &model))
}

/// One pass over the samples of an [`Input`]: an iterator of `Result<Sample, IdError>`
/// (in memory, never an error).
#[derive(Debug)]
pub enum Samples<'a> {
    /// Streaming from a file (boxed: the reader's state is ~230 bytes).
    File(Box<CsvRecord<File>>),
    /// From memory.
    Memory(std::slice::Iter<'a, Sample>),
    /// Another pass with `u` through a map ([`Input::Through`]).
    Through(Box<Samples<'a>>, crate::phase::DeviceMap),
}

impl Iterator for Samples<'_> {
    type Item = Result<Sample, IdError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Samples::File(r) => r.next(),
            Samples::Memory(it) => it.next().copied().map(Ok),
            Samples::Through(inner, map) => inner.next().map(|s| {
                s.map(|s| Sample {
                    u: map.flow(s.u),
                    ..s
                })
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_once_keeps_lines_and_stops_past_the_bound() {
        let text = "t,u,y\n0,1,2\n\n# c\n1,3,4\n2,5,6\n";
        let i = Input::read_once(text.as_bytes(), "P", 3).unwrap();
        let got: Vec<(u64, f64, f64)> = i
            .samples()
            .unwrap()
            .map(|s| s.map(|s| (s.line, s.u, s.y)))
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(got, [(2, 1.0, 2.0), (5, 3.0, 4.0), (6, 5.0, 6.0)]);
        // A second pass gives the same samples.
        assert_eq!(i.samples().unwrap().count(), 3);
        assert!(i.in_memory());
        assert_eq!(i.name(), Path::new("P"));
        let e = Input::read_once(text.as_bytes(), "P", 2).unwrap_err();
        assert_eq!(e.line_number(), Some(6), "{e}");
        assert!(e.to_string().contains("more than 2 data rows"), "{e}");
        // CSV errors come out at once, named as usual.
        let e = Input::read_once("u,y\n1,x\n".as_bytes(), "P", 10).unwrap_err();
        assert_eq!(e.to_string(), "P line 2: column y: \"x\" is not a number");
    }

    #[test]
    fn regular_files_stream_and_directories_are_refused() {
        let dir = std::env::temp_dir();
        let e = Input::open(&dir).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        let f = dir.join(format!("ridge-id-input-{}.csv", std::process::id()));
        std::fs::write(&f, "u,y\n1,2\n").unwrap();
        let i = Input::open(&f).unwrap();
        assert_eq!(i, Input::File(f.clone()));
        assert_eq!(i.samples().unwrap().count(), 1);
        std::fs::remove_file(&f).unwrap();
    }
}
