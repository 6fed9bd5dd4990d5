//! Streaming reader of `u`/`y` records in CSV, with line-numbered errors.
//!
//! Format:
//! - the first line that is neither blank nor a `#` comment is the header: comma-separated
//!   column names; the columns named `u` (input) and `y` (output) are required, any
//!   others (`t`, …) are ignored. Names are trimmed and may be double-quoted; a UTF-8 byte
//!   order mark is skipped.
//! - every further non-blank, non-comment line is one sample and must have as many
//!   comma-separated cells as the header; the `u` and `y` cells must be finite decimal
//!   numbers (`1.5`, `-2e-3`, …; `NaN` and `inf` are rejected).
//! - line ends may be `\n` or `\r\n`.
//!
//! One line is held in memory at a time, so a record of any length streams in constant
//! memory. Errors name the file, the 1-based line and the problem, e.g.
//! `LOG.csv line 17: column y: "abc" is not a number`.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use crate::error::IdError;

/// One `(u_t, y_t)` sample and the line it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// 1-based line number in the file.
    pub line: u64,
    /// Input `u_t`.
    pub u: f64,
    /// Output `y_t`.
    pub y: f64,
}

/// A CSV record read one line at a time; an iterator of samples (see the
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
pub struct CsvRecord<R: BufRead = BufReader<File>> {
    reader: R,
    path: PathBuf,
    line: u64,
    header_line: u64,
    columns: usize,
    u_col: usize,
    y_col: usize,
    buf: Vec<u8>,
    done: bool,
}

impl CsvRecord<BufReader<File>> {
    /// Opens `path` and reads its header.
    ///
    /// Errors: the file cannot be opened or read, it is empty, or its header has no
    /// `u` or no `y` column (or one of them twice).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, IdError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|source| IdError::Io {
            path: path.to_path_buf(),
            line: None,
            source,
        })?;
        Self::from_reader(BufReader::with_capacity(1 << 16, file), path)
    }
}

/// What one physical line holds.
enum Content<'a> {
    Skip,
    Text(&'a str),
}

impl<R: BufRead> CsvRecord<R> {
    /// Reads the header from `reader`; `name` is the file name used in error messages.
    pub fn from_reader(reader: R, name: impl AsRef<Path>) -> Result<Self, IdError> {
        let mut rec = CsvRecord {
            reader,
            path: name.as_ref().to_path_buf(),
            line: 0,
            header_line: 0,
            columns: 0,
            u_col: 0,
            y_col: 0,
            buf: Vec::with_capacity(256),
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

    /// Number of the last line read (0 before any).
    pub fn line(&self) -> u64 {
        self.line
    }

    /// Reads the next physical line into `buf`; `false` at the end of the file.
    fn read_line(&mut self) -> Result<bool, IdError> {
        self.buf.clear();
        let n = self
            .reader
            .read_until(b'\n', &mut self.buf)
            .map_err(|source| IdError::Io {
                path: self.path.clone(),
                line: Some(self.line + 1),
                source,
            })?;
        if n == 0 {
            return Ok(false);
        }
        self.line += 1;
        Ok(true)
    }

    /// The current line as text without its line end, or `Skip` for blank and `#` lines.
    fn content(&self) -> Result<Content<'_>, IdError> {
        let mut bytes = self.buf.as_slice();
        if self.line == 1 {
            bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        }
        let text = std::str::from_utf8(bytes)
            .map_err(|_| IdError::line(&self.path, self.line, "not valid UTF-8 text"))?;
        let text = text.trim_end_matches(['\n', '\r']);
        let trimmed = text.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            Ok(Content::Skip)
        } else {
            Ok(Content::Text(text))
        }
    }

    fn read_header(&mut self) -> Result<(), IdError> {
        loop {
            if !self.read_line()? {
                return Err(IdError::line(
                    &self.path,
                    self.line + 1,
                    "empty file: expected a header row naming the columns u and y",
                ));
            }
            let text = match self.content()? {
                Content::Skip => continue,
                Content::Text(t) => t,
            };
            let names: Vec<String> = text.split(',').map(|c| unquote(c).to_string()).collect();
            let find = |want: &str| -> Result<usize, IdError> {
                let mut hits = names.iter().enumerate().filter(|(_, n)| n.as_str() == want);
                match (hits.next(), hits.next()) {
                    (Some((i, _)), None) => Ok(i),
                    (Some(_), Some(_)) => Err(IdError::line(
                        &self.path,
                        self.line,
                        format!("header has two columns named {want}"),
                    )),
                    (None, _) => {
                        let hint =
                            if names.len() == 1 && (text.contains(';') || text.contains('\t')) {
                                " (columns must be separated by commas)"
                            } else {
                                ""
                            };
                        Err(IdError::line(
                            &self.path,
                            self.line,
                            format!(
                                "header has no column named {want} (found: {}){hint}",
                                names.join(", ")
                            ),
                        ))
                    }
                }
            };
            let (u, y) = (find("u")?, find("y")?);
            self.u_col = u;
            self.y_col = y;
            self.columns = names.len();
            self.header_line = self.line;
            return Ok(());
        }
    }

    fn parse_row(&self, text: &str) -> Result<Sample, IdError> {
        let mut u = None;
        let mut y = None;
        let mut count = 0usize;
        for (i, cell) in text.split(',').enumerate() {
            count += 1;
            if i == self.u_col {
                u = Some(self.number(cell, "u")?);
            } else if i == self.y_col {
                y = Some(self.number(cell, "y")?);
            }
        }
        match (u, y) {
            (Some(u), Some(y)) if count == self.columns => Ok(Sample {
                line: self.line,
                u,
                y,
            }),
            _ => Err(IdError::line(
                &self.path,
                self.line,
                format!(
                    "expected {} columns as in the header (line {}), found {count}",
                    self.columns, self.header_line
                ),
            )),
        }
    }

    fn number(&self, cell: &str, column: &str) -> Result<f64, IdError> {
        let s = unquote(cell);
        if s.is_empty() {
            return Err(IdError::line(
                &self.path,
                self.line,
                format!("column {column}: empty cell"),
            ));
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(IdError::line(
                &self.path,
                self.line,
                format!("column {column}: {s:?} is not a finite number"),
            )),
            Err(_) => Err(IdError::line(
                &self.path,
                self.line,
                format!("column {column}: {s:?} is not a number"),
            )),
        }
    }

    fn next_sample(&mut self) -> Result<Option<Sample>, IdError> {
        loop {
            if !self.read_line()? {
                return Ok(None);
            }
            match self.content()? {
                Content::Skip => continue,
                Content::Text(t) => return self.parse_row(t).map(Some),
            }
        }
    }
}

impl<R: BufRead> Iterator for CsvRecord<R> {
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

/// A cell without surrounding blanks and double quotes.
fn unquote(cell: &str) -> &str {
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
        CsvRecord::from_reader(text.as_bytes(), "LOG.csv")?.collect()
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
    fn errors_name_file_line_and_problem() {
        let msg = |t: &str| read(t).unwrap_err().to_string();
        assert_eq!(
            msg("t,u,y\n0,1,2\n1,1,abc\n"),
            "LOG.csv line 3: column y: \"abc\" is not a number"
        );
        assert_eq!(
            msg("t,u,y\n0,NaN,2\n"),
            "LOG.csv line 2: column u: \"NaN\" is not a finite number"
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
            msg(""),
            "LOG.csv line 1: empty file: expected a header row naming the columns u and y"
        );
        assert_eq!(
            msg("t,u,y\n0,1\n"),
            "LOG.csv line 2: expected 3 columns as in the header (line 1), found 2"
        );
        assert_eq!(
            msg("u,y,u\n"),
            "LOG.csv line 1: header has two columns named u"
        );
    }

    #[test]
    fn invalid_utf8_is_a_line_error() {
        let bytes: &[u8] = b"u,y\n1,2\n\xff,3\n";
        let r: Result<Vec<Sample>, _> = CsvRecord::from_reader(bytes, "LOG.csv").unwrap().collect();
        assert_eq!(
            r.unwrap_err().to_string(),
            "LOG.csv line 3: not valid UTF-8 text"
        );
    }

    #[test]
    fn bom_is_skipped() {
        let s = read("\u{feff}u,y\n1,2\n").unwrap();
        assert_eq!(s.len(), 1);
    }
}
