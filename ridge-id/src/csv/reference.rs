//! [`Reference`]: the `csv` crate's reading of the format, every row through it; what
//! [`CsvRecord`](super::CsvRecord) hands the input to, and the reference its own reading is
//! tested against.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use csv::{ByteRecord, ReaderBuilder, StringRecord, Terminator};

use super::cells::{empty_file, header_columns, sample, unquote, Header, Sample, BUFFER, MAX_LINE};
use crate::error::IdError;

/// The error [`Source`] returns for a line longer than [`MAX_LINE`] (an `io::Error` of kind
/// `InvalidData` wrapping this, recognised in [`Reference::read_error`]).
#[derive(Debug)]
struct LineTooLong;

impl std::fmt::Display for LineTooLong {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line longer than {MAX_LINE} bytes")
    }
}

impl std::error::Error for LineTooLong {}

/// The `csv` crate's reading of the format (see the [module docs](super)): what
/// [`CsvRecord`] hands the input to at the first row that is not a plain line, and the
/// reference its own reading is tested against. An iterator of samples like
/// [`CsvRecord`], every row through the `csv` crate.
///
/// [`CsvRecord`]: super::CsvRecord
#[derive(Debug)]
pub struct Reference<R: Read = File> {
    reader: csv::Reader<Source<R>>,
    /// The row last read (reused: no allocation per row once it has grown).
    row: StringRecord,
    path: PathBuf,
    /// Lines before the reader's first line.
    base: u64,
    pub(super) line: u64,
    header: Header,
    done: bool,
}

/// The input as the `csv` reader pulls it, with what tells whether the last row of the
/// input ended with a line end: how many bytes were read, whether the input has ended,
/// and its last byte; and the bytes since the last line end, to stop at a line longer
/// than [`MAX_LINE`].
#[derive(Debug)]
struct Source<R> {
    inner: R,
    bytes: u64,
    ended: bool,
    last: Option<u8>,
    /// Bytes read since the last `\n`.
    run: u64,
}

impl<R: Read> Read for Source<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let got = buf.get(..n).unwrap_or_default();
        match got.last() {
            Some(&b) => {
                self.bytes += n as u64;
                self.last = Some(b);
            }
            None => self.ended |= !buf.is_empty(),
        }
        // The first and the last line end of the chunk: a chunk of ordinary rows has both
        // within a few dozen bytes of its ends, so this costs next to nothing. Lines between
        // them are shorter than the chunk, checked only when the chunk is longer than a line
        // may be.
        let too_long = match got.iter().position(|&b| b == b'\n') {
            None => {
                self.run += n as u64;
                false
            }
            Some(first) => {
                let over = self.run + first as u64 > MAX_LINE
                    || (n as u64 > MAX_LINE
                        && got
                            .split(|&b| b == b'\n')
                            .any(|l| l.len() as u64 > MAX_LINE));
                let last = got.iter().rposition(|&b| b == b'\n').unwrap_or(first);
                self.run = (n - 1 - last) as u64;
                over
            }
        };
        if too_long || self.run > MAX_LINE {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                LineTooLong,
            ));
        }
        Ok(n)
    }
}

impl<R: Read> Reference<R> {
    /// Reads the header from `reader` (as [`CsvRecord::from_reader`]).
    ///
    /// [`CsvRecord::from_reader`]: super::CsvRecord::from_reader
    pub fn from_reader(reader: R, name: impl AsRef<Path>) -> Result<Self, IdError> {
        Self::with_base(reader, name, 0, None)
    }

    /// A reader of input whose first line is line `base + 1` of the file; the header is
    /// `header` when already read, else read now.
    pub(super) fn with_base(
        reader: R,
        name: impl AsRef<Path>,
        base: u64,
        header: Option<Header>,
    ) -> Result<Self, IdError> {
        let source = Source {
            inner: reader,
            bytes: 0,
            ended: false,
            last: None,
            run: 0,
        };
        let reader = ReaderBuilder::new()
            // The header is checked here, for its messages and line number.
            .has_headers(false)
            // Row lengths are checked here too: blank-looking lines are skipped first.
            .flexible(true)
            .comment(Some(b'#'))
            // Rows end at `\n` only, so that every row ends where its line count says; a
            // `\r` before it stays in the last cell, which is trimmed.
            .terminator(Terminator::Any(b'\n'))
            .buffer_capacity(BUFFER)
            .from_reader(source);
        let mut rec = Reference {
            reader,
            row: StringRecord::new(),
            path: name.as_ref().to_path_buf(),
            base,
            line: 0,
            header: Header {
                line: 0,
                columns: 0,
                u_col: 0,
                y_col: 0,
            },
            done: false,
        };
        match header {
            Some(h) => rec.header = h,
            None => rec.read_header()?,
        }
        Ok(rec)
    }

    /// The file name used in messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Line number of the header.
    pub fn header_line(&self) -> u64 {
        self.header.line
    }

    /// Line number of the last row read (0 before any).
    pub fn line(&self) -> u64 {
        self.line
    }

    /// Reads the next row that is not blank or a comment into `self.row`; `false` at the
    /// end of the file. The `csv` reader skips empty lines and lines starting with `#`;
    /// lines of blanks only and comments after leading blanks are skipped here.
    fn read_row(&mut self) -> Result<bool, IdError> {
        let mut bytes = std::mem::take(&mut self.row).into_byte_record();
        loop {
            match self.reader.read_byte_record(&mut bytes) {
                Ok(true) => {}
                Ok(false) => return Ok(false),
                Err(e) => return Err(self.read_error(e)),
            }
            self.line = self.row_line(&bytes);
            let first = bytes.get(0).unwrap_or_default().trim_ascii_start();
            let blank = bytes.len() == 1 && first.is_empty();
            if !(blank || first.starts_with(b"#")) {
                break;
            }
        }
        self.row = StringRecord::from_byte_record(bytes)
            .map_err(|_| IdError::line(&self.path, self.line, "not valid UTF-8 text"))?;
        Ok(true)
    }

    /// The line on which the row `bytes`, just read, starts. The reader counts the line
    /// ends it has consumed, blank and comment lines included: the row's last line is the
    /// one before the reader's line, unless the row ended with the input and not with a
    /// line end; a quoted cell may hold line ends of its own.
    fn row_line(&self, bytes: &ByteRecord) -> u64 {
        let after = self.reader.position();
        let source = self.reader.get_ref();
        let at_end = source.ended && after.byte() == source.bytes;
        let line_end = !at_end || source.last == Some(b'\n');
        // (`contains` is a fast search: most rows have no line end and are not counted.)
        let text = bytes.as_slice();
        let inside = match text.contains(&b'\n') {
            true => text.iter().filter(|&&b| b == b'\n').count() as u64,
            false => 0,
        };
        self.base
            + after
                .line()
                .saturating_sub(u64::from(line_end) + inside)
                .max(1)
    }

    /// The line after the last one: where a header was expected in a file without one.
    fn end_line(&self) -> u64 {
        let source = self.reader.get_ref();
        let unterminated = source.last.is_some_and(|b| b != b'\n');
        self.base + self.reader.position().line() + u64::from(unterminated)
    }

    /// An error of the `csv` reader (reading failed), with the line being read.
    fn read_error(&self, e: csv::Error) -> IdError {
        let line = self.base + self.reader.position().line();
        // Invalid UTF-8 (checked in `read_row`), unequal lengths (the reader is flexible),
        // seeking and (de)serialising do not occur here; say what the reader said all the
        // same.
        let text = e.to_string();
        match e.into_kind() {
            csv::ErrorKind::Io(source)
                if source
                    .get_ref()
                    .is_some_and(|inner| inner.is::<LineTooLong>()) =>
            {
                IdError::line(
                    &self.path,
                    line,
                    format!(
                        "line longer than {MAX_LINE} bytes (1 MiB) without a line end: \
                         not a CSV log of u and y (a binary file, or rows without line ends?)"
                    ),
                )
            }
            csv::ErrorKind::Io(source) => IdError::Io {
                path: self.path.clone(),
                line: Some(line),
                source,
            },
            _ => IdError::line(&self.path, line, text),
        }
    }

    fn read_header(&mut self) -> Result<(), IdError> {
        if !self.read_row()? {
            return Err(empty_file(&self.path, self.end_line()));
        }
        let names: Vec<&str> = self.row.iter().map(unquote).collect();
        let (u_col, y_col) = header_columns(&names, &self.path, self.line)?;
        self.header = Header {
            line: self.line,
            columns: names.len(),
            u_col,
            y_col,
        };
        Ok(())
    }

    pub(super) fn next_sample(&mut self) -> Result<Option<Sample>, IdError> {
        if !self.read_row()? {
            return Ok(None);
        }
        let h = &self.header;
        let row = &self.row;
        sample(
            &self.path,
            self.line,
            h,
            row.len(),
            row.get(h.u_col),
            row.get(h.y_col),
        )
        .map(Some)
    }
}

impl<R: Read> Iterator for Reference<R> {
    type Item = Result<Sample, IdError>;

    /// The next sample; after the first error, `None`.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let r = self.next_sample().transpose();
        self.done = !matches!(r, Some(Ok(_)));
        r
    }
}
