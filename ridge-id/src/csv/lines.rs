//! The plain-line reader of [`CsvRecord`](super::CsvRecord): rows that are one line, with no
//! double quote and no non-ASCII byte, read without the `csv` crate, and the point where it
//! hands the rest of the input to the `csv` crate ([`Step::Switch`]).

use std::io::Read;
use std::path::Path;

use super::cells::{
    decimal, decimal_prefix, header_columns, sample, unquote, Header, Sample, BUFFER,
};
use crate::error::IdError;

/// The plain-line reader: a buffer over the input, the lines consumed so far.
///
/// It reads as the `csv` crate's reader does — [`BUFFER`] bytes asked for, and only once
/// the bytes read before are used up (the part of a line they end with is kept) — so that
/// after a switch the input sees the same reads, and fails or ends on the same one, as
/// under [`Reference`](super::Reference) alone. Hence twice [`BUFFER`]: the kept part, shorter than
/// [`BUFFER`], and one read.
#[derive(Debug)]
pub(super) struct Lines<R> {
    pub(super) inner: R,
    pub(super) buf: Box<[u8]>,
    /// Unread bytes: `buf[start..end]`, always starting at the beginning of a line.
    pub(super) start: usize,
    pub(super) end: usize,
    /// The input has ended.
    pub(super) eof: bool,
    /// The last byte read from the input.
    pub(super) last: Option<u8>,
    /// Bytes the first read returned.
    pub(super) first_read: usize,
    /// Line number of the next line (line ends consumed + 1).
    pub(super) line: u64,
    /// Bytes consumed (whole lines).
    pub(super) consumed: u64,
    /// Line of the last row read (0 before any).
    pub(super) row_line: u64,
    pub(super) header: Option<Header>,
    /// Scratch for the header's names.
    pub(super) names: Vec<String>,
}

/// What [`Lines::step`] found.
pub(super) enum Step {
    /// A sample.
    Row(Sample),
    /// The header was read.
    Header,
    /// The end of the input.
    End,
    /// The next row is not a plain line: the `csv` crate reads from here.
    Switch,
}

impl<R: Read> Lines<R> {
    pub(super) fn new(inner: R) -> Self {
        Lines {
            inner,
            buf: vec![0; 2 * BUFFER].into_boxed_slice(),
            start: 0,
            end: 0,
            eof: false,
            last: None,
            first_read: 0,
            line: 1,
            consumed: 0,
            row_line: 0,
            header: None,
            names: Vec::new(),
        }
    }

    /// The next line, scanned ([`scan`], cells `want` located), reading more input as
    /// needed; `None` at the end of the input, for a line whose end is not within [`BUFFER`]
    /// bytes and for a non-ASCII first byte of the input. Errors: the input cannot be read
    /// (on the line being read, as the `csv` crate says).
    fn next_line(&mut self, path: &Path, want: [usize; 2]) -> Result<Option<Scan>, IdError> {
        loop {
            // A byte order mark, or the start of one, at the start: the `csv` crate decides
            // from its first read alone whether to skip it (and when the first read is just
            // the mark, sees an empty file), so it reads from the start.
            if self.consumed == 0 && self.buf[..self.end].first().is_some_and(|b| !b.is_ascii()) {
                return Ok(None);
            }
            let unread = &self.buf[self.start..self.end];
            let line = scan(unread, want);
            if line.ended || (self.eof && line.len > 0) {
                return Ok(Some(line));
            }
            if self.eof || unread.len() >= BUFFER {
                return Ok(None);
            }
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
            let n = self
                .inner
                .read(&mut self.buf[self.end..self.end + BUFFER])
                .map_err(|source| IdError::Io {
                    path: path.to_path_buf(),
                    line: Some(self.line),
                    source,
                })?;
            if self.consumed == 0 && self.end == 0 && self.first_read == 0 {
                self.first_read = n;
            }
            match self.buf[self.end..self.end + n].last() {
                Some(&b) => self.last = Some(b),
                None => self.eof = true,
            }
            self.end += n;
        }
    }

    /// Consumes the line of `len` bytes (plus its line end, if any).
    fn consume(&mut self, len: usize, ended: bool) {
        let used = len + usize::from(ended);
        self.start += used;
        self.consumed += used as u64;
        self.line += u64::from(ended);
        // A row that the end of the input ended is followed by one more read (the `csv`
        // crate's): the input may have more, or fail.
        self.eof &= ended;
    }

    /// Reads the next header or data row, skipping what the `csv` crate skips (empty lines,
    /// lines starting with `#`) and what [`Reference`] skips (blank lines, comments after
    /// blanks).
    ///
    /// [`Reference`]: super::Reference
    #[inline(never)]
    pub(super) fn step(&mut self, path: &Path) -> Result<Step, IdError> {
        let want = self.header.map_or([0, 0], |h| [h.u_col, h.y_col]);
        loop {
            let Some(sc) = self.next_line(path, want)? else {
                return Ok(if self.eof && self.start == self.end {
                    Step::End
                } else {
                    Step::Switch
                });
            };
            let (len, ended) = (sc.len, sc.ended);
            let line = &self.buf[self.start..self.start + len];
            let at = self.line;
            // The csv crate's own skips: an empty line, a comment from the first byte on
            // (whatever it holds) — except a comment that ends the input without a line
            // end, which it reads as a row (skipped below, its line counted as read).
            if line.first().is_none_or(|&b| b == b'#') {
                if !ended {
                    self.row_line = at;
                }
                self.consume(len, ended);
                continue;
            }
            if sc.special {
                return Ok(Step::Switch);
            }
            self.row_line = at;
            let first = line[..sc.first_end].trim_ascii_start();
            if (sc.cells == 1 && first.is_empty()) || first.starts_with(b"#") {
                self.consume(len, ended);
                continue;
            }
            let result = match self.header {
                None => self.read_header(len, path).map(|()| Step::Header),
                Some(h) => row(line, &sc, &h, path, at).map(Step::Row),
            };
            self.consume(len, ended);
            return result;
        }
    }

    /// The next row when it is a common one already in the buffer ([`quick_row`]), else
    /// `None` ([`Lines::step`] reads it).
    #[inline(always)]
    pub(super) fn quick(&mut self) -> Option<Sample> {
        let (u, y, used) = quick_row(&self.buf[self.start..self.end], self.header.as_ref()?)?;
        let at = self.line;
        self.row_line = at;
        self.consume(used - 1, true);
        Some(Sample { line: at, u, y })
    }

    /// The header in the next `len` bytes (a plain line).
    fn read_header(&mut self, len: usize, path: &Path) -> Result<(), IdError> {
        let line = &self.buf[self.start..self.start + len];
        self.names.clear();
        self.names.extend(
            line.split(|&b| b == b',')
                .map(|cell| ascii(cell).to_string()),
        );
        let names: Vec<&str> = self.names.iter().map(|n| unquote(n)).collect();
        let (u_col, y_col) = header_columns(&names, path, self.line)?;
        self.header = Some(Header {
            line: self.line,
            columns: names.len(),
            u_col,
            y_col,
        });
        Ok(())
    }

    /// The line where a header was expected at the end of the input (the `csv` crate's count).
    pub(super) fn end_line(&self) -> u64 {
        self.line + u64::from(self.last.is_some_and(|b| b != b'\n'))
    }
}

/// `cell`, known to be ASCII, as text.
fn ascii(cell: &[u8]) -> &str {
    std::str::from_utf8(cell).unwrap_or_default()
}

/// One line of the input as [`scan`] finds it.
#[derive(Debug, Clone, Copy)]
struct Scan {
    /// Bytes before the line end (or the end of the input).
    len: usize,
    /// The line ends with `\n`.
    ended: bool,
    /// Cells (commas + 1).
    cells: usize,
    /// End of the first cell.
    first_end: usize,
    /// The cells asked for, as byte ranges (`(0, 0)` when the line has fewer cells).
    wanted: [(usize, usize); 2],
    /// A double quote or a non-ASCII byte: not a plain line.
    special: bool,
}

/// The line at the start of `bytes` in one pass: its length, its cells (the byte ranges of
/// cells `want`), and whether it is plain.
#[inline(always)]
fn scan(bytes: &[u8], want: [usize; 2]) -> Scan {
    let mut sc = Scan {
        len: bytes.len(),
        ended: false,
        cells: 0,
        first_end: bytes.len(),
        wanted: [(0, 0); 2],
        special: false,
    };
    let mut cell_start = 0;
    let close = |sc: &mut Scan, end: usize, cell_start: usize| {
        if sc.cells == 0 {
            sc.first_end = end;
        }
        for (w, range) in want.iter().zip(sc.wanted.iter_mut()) {
            if *w == sc.cells {
                *range = (cell_start, end);
            }
        }
        sc.cells += 1;
    };
    for (i, &b) in bytes.iter().enumerate() {
        match b {
            b',' => {
                close(&mut sc, i, cell_start);
                cell_start = i + 1;
            }
            b'\n' => {
                sc.len = i;
                sc.ended = true;
                break;
            }
            b'"' | 0x80..=0xff => sc.special = true,
            _ => {}
        }
    }
    let end = sc.len;
    close(&mut sc, end, cell_start);
    sc
}

/// The sample of the plain line `line` (line number `at`), scanned as `sc`.
fn row(line: &[u8], sc: &Scan, h: &Header, path: &Path, at: u64) -> Result<Sample, IdError> {
    let cell = |k: usize| {
        let (a, b) = sc.wanted[k];
        (sc.cells > [h.u_col, h.y_col][k]).then(|| &line[a..b])
    };
    let (u, y) = (cell(0), cell(1));
    if sc.cells == h.columns {
        if let (Some(u), Some(y)) = (u.and_then(plain_number), y.and_then(plain_number)) {
            return Ok(Sample { line: at, u, y });
        }
    }
    sample(path, at, h, sc.cells, u.map(ascii), y.map(ascii))
}

/// `char::is_whitespace` on ASCII (what [`unquote`] trims): tab, line feed, vertical tab,
/// form feed, carriage return, space.
#[inline(always)]
fn blank(b: u8) -> bool {
    matches!(b, b'\t' | b'\n' | 0x0b | 0x0c | b'\r' | b' ')
}

/// The number in an ASCII cell without quotes when it is a plain decimal ([`decimal`],
/// after the blanks [`unquote`] trims), else `None`: then [`number`] reads it.
///
/// [`number`]: super::cells::number
#[inline]
fn plain_number(cell: &[u8]) -> Option<f64> {
    let start = cell.iter().position(|&b| !blank(b))?;
    let end = cell.iter().rposition(|&b| !blank(b))? + 1;
    decimal(&cell[start..end])
}

/// The number at the start of `bytes` when it is `-?d+(.d*)?([eE][+-]?d+)?` with a finite
/// value — [`decimal_prefix`]'s when it has one, else `str::parse`'s (what [`number`] gives
/// the same text) — and the bytes it takes; `None` for another form or a value out of range.
///
/// [`number`]: super::cells::number
#[inline(always)]
fn number_prefix(bytes: &[u8]) -> (Option<f64>, usize) {
    let (v, mut used) = decimal_prefix(bytes);
    if used == 0 {
        return (None, 0);
    }
    let mut exponent = false;
    if let Some(b'e' | b'E') = bytes.get(used) {
        let mut j = used + 1;
        if let Some(b'+' | b'-') = bytes.get(j) {
            j += 1;
        }
        let digits = bytes[j.min(bytes.len())..]
            .iter()
            .take_while(|b| b.is_ascii_digit())
            .count();
        if digits == 0 {
            return (None, used);
        }
        used = j + digits;
        exponent = true;
    }
    match v {
        Some(v) if !exponent => (Some(v), used),
        _ => (parsed(&bytes[..used]), used),
    }
}

/// `str::parse` of ASCII `text` when finite (out of line: the common cells do not need it).
#[inline(never)]
fn parsed(text: &[u8]) -> Option<f64> {
    let text = std::str::from_utf8(text).ok()?;
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The sample of the line at the start of `bytes` and the bytes it takes with its line end,
/// when it is the common row that [`Lines::step`] would read to this very sample: ended by
/// `\n`, not starting with `#` or a blank, no double quote or non-ASCII byte, as many
/// cells as the header, the `u` and `y` cells numbers without a sign `+`, a leading point,
/// `inf` or `NaN` ([`number_prefix`]) between blanks; else `None`
/// (then [`Lines::step`] reads it). One pass over the bytes.
#[inline(always)]
fn quick_row(bytes: &[u8], h: &Header) -> Option<(f64, f64, usize)> {
    if bytes.first().is_none_or(|&b| b == b'#' || blank(b)) {
        return None;
    }
    let mut values = [0.0; 2];
    let mut i = 0;
    let mut cell = 0;
    loop {
        let want = if cell == h.u_col {
            Some(0)
        } else if cell == h.y_col {
            Some(1)
        } else {
            None
        };
        match want {
            Some(k) => {
                while bytes.get(i).is_some_and(|&b| blank(b) && b != b'\n') {
                    i += 1;
                }
                let (v, used) = number_prefix(&bytes[i..]);
                values[k] = v?;
                i += used;
                while bytes.get(i).is_some_and(|&b| blank(b) && b != b'\n') {
                    i += 1;
                }
            }
            None => loop {
                match bytes.get(i) {
                    Some(b',' | b'\n') => break,
                    Some(&b) if b == b'"' || !b.is_ascii() => return None,
                    Some(_) => i += 1,
                    None => return None,
                }
            },
        }
        cell += 1;
        match bytes.get(i) {
            Some(b',') => i += 1,
            Some(b'\n') => break,
            _ => return None,
        }
    }
    (cell == h.columns).then_some((values[0], values[1], i + 1))
}
