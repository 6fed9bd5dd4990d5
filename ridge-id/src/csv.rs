//! Streaming reader of `u`/`y` records in CSV, with line-numbered errors.
//!
//! Format:
//! - the first line that is neither blank nor a comment (first non-blank character `#`) is
//!   the header: comma-separated column names; the columns named `u` (input) and `y`
//!   (output) are required, any others (`t`, …) are ignored, in any order. Names are
//!   trimmed and may be double-quoted; a UTF-8 byte order mark at the start of the file is
//!   skipped.
//! - every further non-blank, non-comment line is one sample and must have as many
//!   comma-separated cells as the header; the `u` and `y` cells must be finite decimal
//!   numbers (`1.5`, `-2e-3`, ` 4 `, `"3"`; `NaN` and `inf` are rejected). Cells may be
//!   double-quoted as RFC 4180 says (a quoted comma does not separate cells).
//! - line ends may be `\n` or `\r\n`; the text must be UTF-8.
//!
//! - a line may be at most [`MAX_LINE`] bytes (1 MiB) long: a longer one is an error naming
//!   its line, so that a file without line ends (a binary file, a log written without
//!   `\n`) cannot make the reader grow its buffer without bound.
//!
//! The parsing is the `csv` crate's; this module adds the column lookup, the checks and
//! the messages. Rows are read one at a time into one reused buffer, so a record of
//! any length streams in constant memory. Errors name the file, the 1-based line and the
//! problem, e.g. `LOG.csv line 17: column y: "abc" is not a number`; a cell or a header
//! is quoted with at most [`QUOTE_CHARS`] characters.

// Measured (`ridge-id identify --input big.csv --json`, release build, 10^6 rows, 48 MB;
// medians of 7 runs on a shared 2-core machine): 0.36 s wall and 3.1 MB peak RSS with the
// `csv` crate, 0.32 s and 3.1 MB with the hand-written line splitter it replaced. The
// difference is csv-core's byte-by-byte state machine under the workspace's
// `opt-level = "s"`: built with `opt-level = 3` for csv-core alone, it is 0.32 s too.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use csv::{ByteRecord, ReaderBuilder, StringRecord, Terminator};

use crate::error::IdError;

/// Longest line accepted, in bytes (1 MiB): a row of `t,u,y` is a few dozen bytes.
pub const MAX_LINE: u64 = 1 << 20;

/// Most characters of a cell or a header quoted in an error message.
pub const QUOTE_CHARS: usize = 80;

/// `text` as a quoted string for a message: `"abc"` (Rust string syntax, so control
/// characters are escaped), cut to its first [`QUOTE_CHARS`] characters and marked
/// `"abc…" (1234 characters)` when longer.
pub fn quote(text: &str) -> String {
    let total = text.chars().count();
    if total <= QUOTE_CHARS {
        return format!("{text:?}");
    }
    let head: String = text.chars().take(QUOTE_CHARS).collect();
    let mut q = format!("{head:?}");
    q.insert(q.len() - 1, '…');
    format!("{q} ({total} characters)")
}

/// The error [`Source`] returns for a line longer than [`MAX_LINE`] (an `io::Error` of kind
/// `InvalidData` wrapping this, recognised in [`CsvRecord::read_error`]).
#[derive(Debug)]
struct LineTooLong;

impl std::fmt::Display for LineTooLong {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line longer than {MAX_LINE} bytes")
    }
}

impl std::error::Error for LineTooLong {}

/// One `(u_t, y_t)` sample and the line it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// 1-based line number in the file.
    pub line: u64,
    /// Input `u_t` (the unit of the record's `u` column).
    pub u: f64,
    /// Output `y_t` (the unit of the record's `y` column).
    pub y: f64,
}

/// A CSV record read one row at a time; an iterator of samples (see the
/// [module docs](self) for the format).
///
/// ```no_run
/// use ridge_id::csv::CsvRecord;
/// let mut n = 0;
/// for sample in CsvRecord::open("LOG.csv")? {
///     let s = sample?; // line-numbered error on a bad row
///     n += 1;
///     let _ = (s.u, s.y);
/// }
/// # Ok::<(), ridge_id::IdError>(())
/// ```
#[derive(Debug)]
pub struct CsvRecord<R: Read = File> {
    reader: csv::Reader<Source<R>>,
    /// The row last read (reused: no allocation per row once it has grown).
    row: StringRecord,
    path: PathBuf,
    line: u64,
    header_line: u64,
    columns: usize,
    u_col: usize,
    y_col: usize,
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

impl CsvRecord<File> {
    /// Opens `path` and reads its header.
    ///
    /// Errors: the file cannot be opened or read, it has no header, or its header has no
    /// `u` or no `y` column (or one of them twice).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, IdError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|source| IdError::Io {
            path: path.to_path_buf(),
            line: None,
            source,
        })?;
        Self::from_reader(file, path)
    }
}

impl<R: Read> CsvRecord<R> {
    /// Reads the header from `reader` (buffered here: pass a plain `File`); `name` is the
    /// file name used in error messages.
    pub fn from_reader(reader: R, name: impl AsRef<Path>) -> Result<Self, IdError> {
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
            .buffer_capacity(1 << 16)
            .from_reader(source);
        let mut rec = CsvRecord {
            reader,
            row: StringRecord::new(),
            path: name.as_ref().to_path_buf(),
            line: 0,
            header_line: 0,
            columns: 0,
            u_col: 0,
            y_col: 0,
            done: false,
        };
        rec.read_header()?;
        Ok(rec)
    }

    /// The file name used in messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Line number of the header.
    pub fn header_line(&self) -> u64 {
        self.header_line
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
        after
            .line()
            .saturating_sub(u64::from(line_end) + inside)
            .max(1)
    }

    /// The line after the last one: where a header was expected in a file without one.
    fn end_line(&self) -> u64 {
        let source = self.reader.get_ref();
        let unterminated = source.last.is_some_and(|b| b != b'\n');
        self.reader.position().line() + u64::from(unterminated)
    }

    /// An error of the `csv` reader (reading failed), with the line being read.
    fn read_error(&self, e: csv::Error) -> IdError {
        let line = self.reader.position().line();
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
            return Err(IdError::line(
                &self.path,
                self.end_line(),
                "empty file: expected a header row naming the columns u and y",
            ));
        }
        let names: Vec<&str> = self.row.iter().map(unquote).collect();
        let find = |want: &str| -> Result<usize, IdError> {
            column(&names, want, &self.path, self.line)?.ok_or_else(|| {
                let other_separator =
                    matches!(names.as_slice(), [one] if one.contains([';', '\t']));
                let hint = if other_separator {
                    " (columns must be separated by commas)"
                } else {
                    ""
                };
                IdError::line(
                    &self.path,
                    self.line,
                    format!(
                        "header has no column named {want} (found: {}){hint}",
                        found(&names)
                    ),
                )
            })
        };
        let (u, y) = (find("u")?, find("y")?);
        self.columns = names.len();
        self.u_col = u;
        self.y_col = y;
        self.header_line = self.line;
        Ok(())
    }

    /// The sample of the row in `self.row`.
    fn parse_row(&self) -> Result<Sample, IdError> {
        let count = self.row.len();
        let (Some(u), Some(y), true) = (
            self.row.get(self.u_col),
            self.row.get(self.y_col),
            count == self.columns,
        ) else {
            return Err(IdError::line(
                &self.path,
                self.line,
                format!(
                    "expected {} columns as in the header (line {}), found {count}",
                    self.columns, self.header_line
                ),
            ));
        };
        Ok(Sample {
            line: self.line,
            u: self.number(u, "u")?,
            y: self.number(y, "y")?,
        })
    }

    fn number(&self, cell: &str, column: &str) -> Result<f64, IdError> {
        number(unquote(cell), column, &self.path, self.line)
    }

    fn next_sample(&mut self) -> Result<Option<Sample>, IdError> {
        if self.read_row()? {
            self.parse_row().map(Some)
        } else {
            Ok(None)
        }
    }
}

impl<R: Read> Iterator for CsvRecord<R> {
    type Item = Result<Sample, IdError>;

    /// The next sample; after the first error, `None`.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.next_sample() {
            Ok(Some(s)) => Some(Ok(s)),
            Ok(None) => {
                self.done = true;
                None
            }
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}

/// The index of the header column `want` among `names` (`None`: there is none); two columns
/// of that name are an error on line `line` of `path`.
pub(crate) fn column(
    names: &[&str],
    want: &str,
    path: &Path,
    line: u64,
) -> Result<Option<usize>, IdError> {
    let mut hits = names.iter().enumerate().filter(|(_, n)| **n == want);
    match (hits.next(), hits.next()) {
        (Some(_), Some(_)) => Err(IdError::line(
            path,
            line,
            format!("header has two columns named {want}"),
        )),
        (hit, _) => Ok(hit.map(|(i, _)| i)),
    }
}

/// The finite number in the (unquoted) cell `s` of column `column`, else an error on line
/// `line` of `path` naming the cell.
pub(crate) fn number(s: &str, column: &str, path: &Path, line: u64) -> Result<f64, IdError> {
    if s.is_empty() {
        return Err(IdError::line(
            path,
            line,
            format!("column {column}: empty cell"),
        ));
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(IdError::line(
            path,
            line,
            format!("column {column}: {} is not a finite number", quote(s)),
        )),
        Err(_) => Err(IdError::line(
            path,
            line,
            format!("column {column}: {} is not a number", quote(s)),
        )),
    }
}

/// The column names of a header for a message: `t, u`, cut to about [`QUOTE_CHARS`]
/// characters (`a, b, … (1234 columns)` when longer).
pub(crate) fn found(names: &[&str]) -> String {
    let all = names.join(", ");
    if all.chars().count() <= QUOTE_CHARS {
        return all;
    }
    let head: String = all.chars().take(QUOTE_CHARS).collect();
    format!("{head}… ({} columns)", names.len())
}

/// A cell without surrounding blanks and double quotes. The `csv` reader has removed the
/// quotes of a cell that starts with one; this also takes them off ` "u" ` (blanks outside
/// the quotes, which the reader keeps as text).
pub(crate) fn unquote(cell: &str) -> &str {
    let t = cell.trim();
    t.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .map(str::trim)
        .unwrap_or(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<Vec<Sample>, IdError> {
        read_bytes(text.as_bytes())
    }

    fn read_bytes(bytes: &[u8]) -> Result<Vec<Sample>, IdError> {
        CsvRecord::from_reader(bytes, "LOG.csv")?.collect()
    }

    fn msg(text: &str) -> String {
        read(text).unwrap_err().to_string()
    }

    #[test]
    fn reads_columns_by_name_and_skips_others() {
        let s = read("t,y,u\n0,1.5,2\r\n1,-2e-3,\"3\"\n\n# note\n2, 4 ,5\n").unwrap();
        assert_eq!(s.len(), 3);
        assert_eq!((s[0].u, s[0].y, s[0].line), (2.0, 1.5, 2));
        assert_eq!((s[1].u, s[1].y), (3.0, -2e-3));
        assert_eq!((s[2].u, s[2].y, s[2].line), (5.0, 4.0, 6));
    }

    #[test]
    fn blank_lines_and_comments_anywhere_keep_physical_line_numbers() {
        let text = "# made by hand\n\n  # indented comment\n \t \n t , \"u\" , y \r\n\r\n\
                    0,1,2\n   \n# between rows, with \"quotes\n1,3,4\n# last\n";
        let mut r = CsvRecord::from_reader(text.as_bytes(), "LOG.csv").unwrap();
        assert_eq!(r.header_line(), 5);
        let s: Vec<Sample> = r.by_ref().collect::<Result<_, _>>().unwrap();
        let got: Vec<(u64, f64, f64)> = s.iter().map(|s| (s.line, s.u, s.y)).collect();
        assert_eq!(got, [(7, 1.0, 2.0), (10, 3.0, 4.0)]);
        assert_eq!(r.line(), 10);
        // A row after the comments is still numbered by its physical line.
        assert_eq!(
            msg("# a\n# b\nu,y\n\n1,2\n# c\n1,x\n"),
            "LOG.csv line 7: column y: \"x\" is not a number"
        );
    }

    #[test]
    fn line_numbers_without_a_final_line_end_with_crlf_and_multi_line_cells() {
        assert_eq!(
            msg("u,y\n1,2\n\n1,x"),
            "LOG.csv line 4: column y: \"x\" is not a number"
        );
        assert_eq!(
            msg("u,y\r\n\r\n1,2\r\n1,x\r\n"),
            "LOG.csv line 4: column y: \"x\" is not a number"
        );
        assert_eq!(
            msg("# no line end"),
            "LOG.csv line 2: empty file: expected a header row naming the columns u and y"
        );
        let s = read("u,y\n1,2").unwrap();
        assert_eq!((s[0].u, s[0].y, s[0].line), (1.0, 2.0, 2));
        // A quoted cell holding a line end: the row is numbered by its first line.
        let s = read("t,u,y\n\"a\nb\",1,2\n3,4,5\n").unwrap();
        let lines: Vec<u64> = s.iter().map(|s| s.line).collect();
        assert_eq!(lines, [2, 4]);
        assert_eq!(
            msg("t,u,y\n0,1,2\n\"a\nb\",1,x\n"),
            "LOG.csv line 3: column y: \"x\" is not a number"
        );
    }

    #[test]
    fn quoted_cells_follow_rfc_4180() {
        // A quoted comma is inside the cell, not a separator: one cell "1,5".
        assert_eq!(
            msg("u,y\n1,\"1,5\"\n"),
            "LOG.csv line 2: column y: \"1,5\" is not a number"
        );
        let s = read("\"u\",\"y\"\n\"-1.5\",\" 2 \"\n").unwrap();
        assert_eq!((s[0].u, s[0].y), (-1.5, 2.0));
    }

    #[test]
    fn errors_name_file_line_and_problem() {
        assert_eq!(
            msg("t,u,y\n0,1,2\n1,1,abc\n"),
            "LOG.csv line 3: column y: \"abc\" is not a number"
        );
        assert_eq!(
            msg("t,u,y\n0,NaN,2\n"),
            "LOG.csv line 2: column u: \"NaN\" is not a finite number"
        );
        assert_eq!(
            msg("t,u,y\n0,1,-inf\n"),
            "LOG.csv line 2: column y: \"-inf\" is not a finite number"
        );
        assert_eq!(
            msg("t,u,y\n0,1,1e400\n"),
            "LOG.csv line 2: column y: \"1e400\" is not a finite number"
        );
        assert_eq!(msg("t,u,y\n0,,2\n"), "LOG.csv line 2: column u: empty cell");
        assert_eq!(
            msg("t,u\n0,1\n"),
            "LOG.csv line 1: header has no column named y (found: t, u)"
        );
        assert_eq!(
            msg("t;u;y\n"),
            "LOG.csv line 1: header has no column named u (found: t;u;y) \
             (columns must be separated by commas)"
        );
        assert_eq!(
            msg("u\ty\n1\t2\n"),
            "LOG.csv line 1: header has no column named u (found: u\ty) \
             (columns must be separated by commas)"
        );
        assert_eq!(
            msg(""),
            "LOG.csv line 1: empty file: expected a header row naming the columns u and y"
        );
        assert_eq!(
            msg("# only\n\n# comments\n"),
            "LOG.csv line 4: empty file: expected a header row naming the columns u and y"
        );
        assert_eq!(
            msg("t,u,y\n0,1\n"),
            "LOG.csv line 2: expected 3 columns as in the header (line 1), found 2"
        );
        assert_eq!(
            msg("t,u,y\n0,1,2\n1,1,1,\n"),
            "LOG.csv line 3: expected 3 columns as in the header (line 1), found 4"
        );
        assert_eq!(
            msg("u,y,u\n"),
            "LOG.csv line 1: header has two columns named u"
        );
    }

    #[test]
    fn invalid_utf8_is_a_line_error() {
        for (bytes, line) in [
            (&b"u,y\n1,2\n\xff,3\n"[..], 3),
            (&b"u,y\n1,2\n2,3\n1,\xff\n"[..], 4),
            (&b"t,u,y\n0,1,2\n\xfe,1,2\n"[..], 3),
        ] {
            assert_eq!(
                read_bytes(bytes).unwrap_err().to_string(),
                format!("LOG.csv line {line}: not valid UTF-8 text")
            );
        }
    }

    #[test]
    fn bom_is_skipped() {
        let s = read("\u{feff}u,y\n1,2\n").unwrap();
        assert_eq!((s[0].u, s[0].y, s[0].line), (1.0, 2.0, 2));
        let s = read("\u{feff}# comment\nu,y\n1,2\n").unwrap();
        assert_eq!((s[0].u, s[0].y, s[0].line), (1.0, 2.0, 3));
    }

    #[test]
    fn io_errors_name_the_line_being_read() {
        /// Yields `ok`, then fails.
        struct Failing(&'static [u8]);
        impl Read for Failing {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                if self.0.is_empty() {
                    return Err(std::io::Error::other("disk on fire"));
                }
                let n = self.0.len().min(buf.len());
                buf[..n].copy_from_slice(&self.0[..n]);
                self.0 = &self.0[n..];
                Ok(n)
            }
        }
        let r: Result<Vec<Sample>, _> = CsvRecord::from_reader(Failing(b"u,y\n1,2\n"), "LOG.csv")
            .unwrap()
            .collect();
        assert_eq!(
            r.unwrap_err().to_string(),
            "LOG.csv line 3: cannot read: disk on fire"
        );
    }

    #[test]
    fn long_lines_stop_at_the_cap_with_their_line_number() {
        /// `head`, then `fill` forever (no line end).
        #[derive(Debug)]
        struct Endless(&'static [u8], u8, usize);
        impl Read for Endless {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                for b in buf.iter_mut() {
                    *b = self.0.get(self.2).copied().unwrap_or(self.1);
                    self.2 += 1;
                }
                Ok(buf.len())
            }
        }
        let cap = MAX_LINE as usize;
        // An endless header line, and an endless data row after two good rows.
        let e = CsvRecord::from_reader(Endless(b"", b'x', 0), "LOG.csv").unwrap_err();
        assert_eq!(e.line_number(), Some(1), "{e}");
        assert!(e.to_string().contains("longer than 1048576 bytes"), "{e}");
        let r = CsvRecord::from_reader(Endless(b"u,y\n1,2\n# c\n3,4\n5,", b'7', 0), "LOG.csv");
        let e = r.unwrap().collect::<Result<Vec<_>, _>>().unwrap_err();
        assert_eq!(e.line_number(), Some(5), "{e}");
        // The cap itself is fine, one byte more is not (the line end not counted).
        let row = |len: usize| format!("u,y\n1,{}\n", "0".repeat(len - 2));
        let s = read(&row(cap)).unwrap();
        assert_eq!(s.len(), 1);
        let e = read(&row(cap + 1)).unwrap_err();
        assert_eq!(e.line_number(), Some(2), "{e}");
    }

    #[test]
    fn messages_quote_at_most_80_characters() {
        let long = "a".repeat(500_000);
        let m = msg(&format!("u,y\n1,{long}\n"));
        assert!(m.len() < 200, "{} bytes", m.len());
        assert_eq!(
            m,
            format!(
                "LOG.csv line 2: column y: \"{}…\" (500000 characters) is not a number",
                "a".repeat(QUOTE_CHARS)
            )
        );
        let m = msg(&format!("{long},v\n"));
        assert!(m.len() < 250, "{} bytes: {m}", m.len());
        assert!(m.ends_with("… (2 columns))"), "{m}");
        // 80 characters are quoted whole.
        let cell = "é".repeat(QUOTE_CHARS);
        assert_eq!(
            msg(&format!("u,y\n1,{cell}\n")),
            format!("LOG.csv line 2: column y: \"{cell}\" is not a number")
        );
    }

    #[test]
    fn rows_stream_one_at_a_time() {
        /// An endless record: the header, then the row `1,2` forever.
        struct Endless(usize);
        impl Read for Endless {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                let text = b"u,y\n1,2\n";
                for b in buf.iter_mut() {
                    *b = text[if self.0 < 4 {
                        self.0
                    } else {
                        4 + (self.0 - 4) % 4
                    }];
                    self.0 += 1;
                }
                Ok(buf.len())
            }
        }
        // Samples come out of an input that never ends: nothing reads it to the end.
        let r = CsvRecord::from_reader(Endless(0), "LOG.csv").unwrap();
        let s: Vec<Sample> = r.take(100_000).collect::<Result<_, _>>().unwrap();
        assert_eq!(s.len(), 100_000);
        assert_eq!(
            (s[99_999].u, s[99_999].y, s[99_999].line),
            (1.0, 2.0, 100_001)
        );
    }
}
