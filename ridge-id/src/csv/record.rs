//! [`CsvRecord`]: the reader of a record, its plain lines read by [`super::lines`] and the rest
//! of the input, from the first row that is not a plain line, handed to the `csv` crate
//! ([`Reference`]).

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use super::cells::{empty_file, Sample};
use super::lines::{Lines, Step};
use super::reference::Reference;
use crate::error::IdError;

/// A CSV record read one row at a time; an iterator of samples (see the
/// [module docs](super) for the format).
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
    engine: Engine<R>,
    path: PathBuf,
    done: bool,
}

/// Who reads the rest of the input: [`Lines`] as long as the rows are plain lines, then
/// [`Reference`] (the `csv` crate) to the end.
#[derive(Debug)]
enum Engine<R: Read> {
    Lines(Lines<R>),
    Csv(Box<Reference<Rest<R>>>),
    /// Only while switching.
    Switching,
}

/// The input [`Reference`] reads after a switch: what [`Lines`] had read and not used — the
/// bytes (the first read's worth first, when at the start), then the empty read that ended
/// the input, if it had seen one — and then the input itself: the reads the `csv` crate
/// would have made, up to the sizes of the pieces (which change nothing but a byte order
/// mark's skip, decided by the first).
#[derive(Debug)]
struct Rest<R> {
    first: Option<usize>,
    pending: Vec<u8>,
    at: usize,
    zero: bool,
    inner: R,
}

impl<R: Read> Read for Rest<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = &self.pending[self.at..];
        if left.is_empty() {
            if std::mem::take(&mut self.zero) {
                return Ok(0);
            }
            return self.inner.read(buf);
        }
        let n = left
            .len()
            .min(buf.len())
            .min(self.first.take().unwrap_or(usize::MAX));
        buf[..n].copy_from_slice(&left[..n]);
        self.at += n;
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
        let mut rec = CsvRecord {
            engine: Engine::Lines(Lines::new(reader)),
            path: name.as_ref().to_path_buf(),
            done: false,
        };
        loop {
            let step = match &mut rec.engine {
                Engine::Lines(lines) => lines.step(&rec.path)?,
                Engine::Csv(_) | Engine::Switching => return Ok(rec),
            };
            match step {
                Step::Header => return Ok(rec),
                Step::Switch => rec.switch()?,
                Step::End => {
                    let line = match &rec.engine {
                        Engine::Lines(lines) => lines.end_line(),
                        _ => 0,
                    };
                    return Err(empty_file(&rec.path, line));
                }
                Step::Row(_) => unreachable!("a row before the header"),
            }
        }
    }

    /// Hands the rest of the input, from the start of the line being read, to the `csv`
    /// crate ([`Reference`]), which reads the header if it has not been read.
    fn switch(&mut self) -> Result<(), IdError> {
        let Engine::Lines(lines) = std::mem::replace(&mut self.engine, Engine::Switching) else {
            return Ok(());
        };
        let mut pending = Vec::with_capacity(lines.end - lines.start + 1);
        // After the first byte the `csv` crate no longer skips a byte order mark: an empty
        // line (which it skips) tells it so, and is not counted.
        let primed = lines.consumed > 0;
        if primed {
            pending.push(b'\n');
        }
        pending.extend_from_slice(&lines.buf[lines.start..lines.end]);
        let base = lines.line - 1 - u64::from(primed);
        let reader = Rest {
            // At the start, the `csv` crate's first read decides whether it skips a byte
            // order mark (only if it holds all 3 bytes): the same first read.
            first: (!primed).then_some(lines.first_read),
            pending,
            at: 0,
            zero: lines.eof,
            inner: lines.inner,
        };
        let mut csv = Reference::with_base(reader, &self.path, base, lines.header)?;
        if lines.header.is_some() {
            csv.line = lines.row_line;
        }
        self.engine = Engine::Csv(Box::new(csv));
        Ok(())
    }

    /// The file name used in messages.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Line number of the header.
    pub fn header_line(&self) -> u64 {
        match &self.engine {
            Engine::Lines(l) => l.header.map_or(0, |h| h.line),
            Engine::Csv(c) => c.header_line(),
            Engine::Switching => 0,
        }
    }

    /// Line number of the last row read (0 before any).
    pub fn line(&self) -> u64 {
        match &self.engine {
            Engine::Lines(l) => l.row_line,
            Engine::Csv(c) => c.line(),
            Engine::Switching => 0,
        }
    }

    fn next_sample(&mut self) -> Result<Option<Sample>, IdError> {
        loop {
            let step = match &mut self.engine {
                Engine::Lines(lines) => lines.step(&self.path)?,
                Engine::Csv(c) => return c.next_sample(),
                Engine::Switching => return Ok(None),
            };
            match step {
                Step::Row(s) => return Ok(Some(s)),
                Step::End => return Ok(None),
                Step::Switch => self.switch()?,
                Step::Header => unreachable!("the header is read once, first"),
            }
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
        if let Engine::Lines(lines) = &mut self.engine {
            if let Some(s) = lines.quick() {
                return Some(Ok(s));
            }
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

#[cfg(test)]
mod tests {
    use super::super::cells::{MAX_LINE, QUOTE_CHARS};
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
