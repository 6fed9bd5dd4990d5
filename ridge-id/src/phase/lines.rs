//! The capture's line reader: lines of at most [`MAX_LINE`] bytes of UTF-8, numbered from 1
//! (a capture holds comment lines the CSV readers skip, which `--phase` reads).

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use crate::csv::MAX_LINE;
use crate::error::IdError;

/// Lines of a reader, at most [`MAX_LINE`] bytes each, UTF-8, numbered from 1; a `\r`
/// before the `\n` and a byte order mark at the start are removed.
pub(super) struct Lines<R> {
    reader: BufReader<R>,
    name: PathBuf,
    line: u64,
    buf: Vec<u8>,
}

impl<R: Read> Lines<R> {
    pub(super) fn new(reader: R, name: &Path) -> Self {
        Lines {
            reader: BufReader::with_capacity(1 << 16, reader),
            name: name.to_path_buf(),
            line: 0,
            buf: Vec::new(),
        }
    }

    pub(super) fn next_line(&mut self) -> Result<Option<(u64, &str)>, IdError> {
        self.buf.clear();
        self.line += 1;
        let n = (&mut self.reader)
            .take(MAX_LINE + 2)
            .read_until(b'\n', &mut self.buf)
            .map_err(|source| IdError::Io {
                path: self.name.clone(),
                line: Some(self.line),
                source,
            })?;
        if n == 0 {
            return Ok(None);
        }
        if self.buf.last() == Some(&b'\n') {
            self.buf.pop();
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        if self.buf.len() as u64 > MAX_LINE {
            return Err(IdError::line(
                &self.name,
                self.line,
                format!("line longer than {MAX_LINE} bytes (1 MiB): not a log capture"),
            ));
        }
        let mut text = std::str::from_utf8(&self.buf)
            .map_err(|_| IdError::line(&self.name, self.line, "not valid UTF-8 text"))?;
        if self.line == 1 {
            text = text.strip_prefix('\u{feff}').unwrap_or(text);
        }
        Ok(Some((self.line, text)))
    }
}
