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
//! The parsing is the `csv` crate's ([`Reference`]); [`CsvRecord`] reads the common rows —
//! one line, no double quote, ASCII — itself, which the `csv` crate would split on the
//! commas alone, and hands the rest of the input to [`Reference`] at the first row that is
//! not such a line (a quote, a non-ASCII byte, a line whose end is not within 64 KiB): the
//! results, errors included, are the `csv` crate's, which a test checks on arbitrary bytes.
//! This module adds the column lookup, the checks and the messages. Rows are read one at a
//! time into reused buffers, so a record of any length streams in constant memory. Errors
//! name the file, the 1-based line and the problem, e.g.
//! `LOG.csv line 17: column y: "abc" is not a number`; a cell or a header is quoted with at
//! most [`QUOTE_CHARS`] characters.

// Measured (`scripts/bench-speed` with a random-step log: `ridge-id identify --input LOG
// --json`, release build, 10^6 rows, 23 MB, two passes, user CPU of the whole run on a
// shared 2-core machine): 0.24 s
// with every row through the `csv` crate (ridge-id at opt-level 3); 0.18 s with the line
// reader splitting cells and `number`; 0.10 s with `quick_row` (one pass over a common row's
// bytes, its numbers read on the way) together with grid-sized statistics
// (`MeasuredGram::for_grid`) and the residual analysis's ring buffer.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use csv::{ByteRecord, ReaderBuilder, StringRecord, Terminator};

use crate::error::IdError;

/// Longest line accepted, in bytes (1 MiB): a row of `t,u,y` is a few dozen bytes.
pub const MAX_LINE: u64 = 1 << 20;

/// Most characters of a cell or a header quoted in an error message.
pub const QUOTE_CHARS: usize = 80;

/// Bytes of each read, [`CsvRecord`]'s and the `csv` crate's (64 KiB): [`CsvRecord`] reads a
/// line itself when it finds its end within this many bytes.
const BUFFER: usize = 1 << 16;

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
/// `InvalidData` wrapping this, recognised in [`Reference::read_error`]).
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

/// Where the `u` and `y` columns are, from the header.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Header {
    /// Line of the header.
    line: u64,
    /// Cells a row must have.
    columns: usize,
    u_col: usize,
    y_col: usize,
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

/// The plain-line reader: a buffer over the input, the lines consumed so far.
///
/// It reads as the `csv` crate's reader does — [`BUFFER`] bytes asked for, and only once
/// the bytes read before are used up (the part of a line they end with is kept) — so that
/// after a switch the input sees the same reads, and fails or ends on the same one, as
/// under [`Reference`] alone. Hence twice [`BUFFER`]: the kept part, shorter than
/// [`BUFFER`], and one read.
#[derive(Debug)]
struct Lines<R> {
    inner: R,
    buf: Box<[u8]>,
    /// Unread bytes: `buf[start..end]`, always starting at the beginning of a line.
    start: usize,
    end: usize,
    /// The input has ended.
    eof: bool,
    /// The last byte read from the input.
    last: Option<u8>,
    /// Bytes the first read returned.
    first_read: usize,
    /// Line number of the next line (line ends consumed + 1).
    line: u64,
    /// Bytes consumed (whole lines).
    consumed: u64,
    /// Line of the last row read (0 before any).
    row_line: u64,
    header: Option<Header>,
    /// Scratch for the header's names.
    names: Vec<String>,
}

/// What [`Lines::step`] found.
enum Step {
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
    fn new(inner: R) -> Self {
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
    #[inline(never)]
    fn step(&mut self, path: &Path) -> Result<Step, IdError> {
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
    fn quick(&mut self) -> Option<Sample> {
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
    fn end_line(&self) -> u64 {
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
#[inline]
fn plain_number(cell: &[u8]) -> Option<f64> {
    let start = cell.iter().position(|&b| !blank(b))?;
    let end = cell.iter().rposition(|&b| !blank(b))? + 1;
    decimal(&cell[start..end])
}

/// `s` read as a number when it is `-?d+(.d*)?` with at most 19 digits whose value is
/// at most 2⁵³ — `w / 10^k` with both exact in `f64`, so one correctly rounded division
/// gives the correctly rounded value, exactly what `str::parse::<f64>` gives — else `None`.
#[inline]
pub(crate) fn decimal(s: &[u8]) -> Option<f64> {
    match decimal_prefix(s) {
        (Some(v), used) if used == s.len() => Some(v),
        _ => None,
    }
}

/// The longest prefix of `s` of the form `-?d+(.d*)?` and the bytes it takes, with its
/// value when [`decimal`] reads it (at most 19 digits, at most 2⁵³ without the point).
#[inline(always)]
fn decimal_prefix(s: &[u8]) -> (Option<f64>, usize) {
    const POW10: [f64; 20] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19,
    ];
    let negative = s.first() == Some(&b'-');
    let mut i = usize::from(negative);
    let mut w: u64 = 0;
    // Wrapping: more than 19 digits are refused below, whatever `w` became.
    let mut digits = |i: &mut usize| {
        let start = *i;
        while let Some(&b) = s.get(*i) {
            let d = b.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            w = w.wrapping_mul(10).wrapping_add(u64::from(d));
            *i += 1;
        }
        *i - start
    };
    let whole = digits(&mut i);
    if whole == 0 {
        return (None, 0);
    }
    let mut fraction = 0;
    if s.get(i) == Some(&b'.') {
        i += 1;
        fraction = digits(&mut i);
    }
    if whole + fraction > 19 || w > 1 << 53 {
        return (None, i);
    }
    let v = w as f64 / POW10[fraction];
    (Some(if negative { -v } else { v }), i)
}

/// The number at the start of `bytes` when it is `-?d+(.d*)?([eE][+-]?d+)?` with a finite
/// value — [`decimal_prefix`]'s when it has one, else `str::parse`'s (what [`number`] gives
/// the same text) — and the bytes it takes; `None` for another form or a value out of range.
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

/// The sample of a row of `count` cells whose `u` and `y` cells are `u` and `y` (`None`
/// when the row is too short), else the error naming line `at`.
fn sample(
    path: &Path,
    at: u64,
    h: &Header,
    count: usize,
    u: Option<&str>,
    y: Option<&str>,
) -> Result<Sample, IdError> {
    let (Some(u), Some(y), true) = (u, y, count == h.columns) else {
        return Err(IdError::line(
            path,
            at,
            format!(
                "expected {} columns as in the header (line {}), found {count}",
                h.columns, h.line
            ),
        ));
    };
    Ok(Sample {
        line: at,
        u: number(unquote(u), "u", path, at)?,
        y: number(unquote(y), "y", path, at)?,
    })
}

/// The columns `u` and `y` among the header's `names` (unquoted), else the error naming
/// line `line` of `path`.
fn header_columns(names: &[&str], path: &Path, line: u64) -> Result<(usize, usize), IdError> {
    let find = |want: &str| -> Result<usize, IdError> {
        column(names, want, path, line)?.ok_or_else(|| {
            let other_separator = matches!(names, [one] if one.contains([';', '\t']));
            let hint = if other_separator {
                " (columns must be separated by commas)"
            } else {
                ""
            };
            IdError::line(
                path,
                line,
                format!(
                    "header has no column named {want} (found: {}){hint}",
                    found(names)
                ),
            )
        })
    };
    Ok((find("u")?, find("y")?))
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

/// The error of an input without a header, at line `line`.
fn empty_file(path: &Path, line: u64) -> IdError {
    IdError::line(
        path,
        line,
        "empty file: expected a header row naming the columns u and y",
    )
}

/// The `csv` crate's reading of the format (see the [module docs](self)): what
/// [`CsvRecord`] hands the input to at the first row that is not a plain line, and the
/// reference its own reading is tested against. An iterator of samples like
/// [`CsvRecord`], every row through the `csv` crate.
#[derive(Debug)]
pub struct Reference<R: Read = File> {
    reader: csv::Reader<Source<R>>,
    /// The row last read (reused: no allocation per row once it has grown).
    row: StringRecord,
    path: PathBuf,
    /// Lines before the reader's first line.
    base: u64,
    line: u64,
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
    pub fn from_reader(reader: R, name: impl AsRef<Path>) -> Result<Self, IdError> {
        Self::with_base(reader, name, 0, None)
    }

    /// A reader of input whose first line is line `base + 1` of the file; the header is
    /// `header` when already read, else read now.
    fn with_base(
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

    fn next_sample(&mut self) -> Result<Option<Sample>, IdError> {
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
    if let Some(v) = decimal(s.as_bytes()) {
        return Ok(v);
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

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config {
            cases: 20_000,
            failure_persistence: None,
            ..Default::default()
        })]

        /// The plain decimal reading is `str::parse` wherever it answers: on decimals of
        /// every length and precision, with leading zeros, and on strings that only look
        /// like them.
        #[test]
        fn decimal_is_str_parse(
            sign in proptest::prop_oneof![proptest::strategy::Just(""), proptest::strategy::Just("-"), proptest::strategy::Just("+")],
            int in "[0-9]{0,21}",
            dot in proptest::bool::ANY,
            frac in "[0-9]{0,21}",
            tail in proptest::prop_oneof![4 => proptest::strategy::Just(String::new()), 1 => "[eE.x -]{1,2}"],
        ) {
            let text = format!("{sign}{int}{}{frac}{tail}", if dot { "." } else { "" });
            if let Some(v) = decimal(text.as_bytes()) {
                let parsed: f64 = text.parse().unwrap();
                proptest::prop_assert_eq!(v.to_bits(), parsed.to_bits(), "{}", text);
            }
        }

        #[test]
        fn decimal_is_str_parse_on_printed_values(v in proptest::num::f64::NORMAL, digits in 0usize..18) {
            let text = format!("{v:.digits$}");
            if let Some(w) = decimal(text.as_bytes()) {
                proptest::prop_assert_eq!(w.to_bits(), text.parse::<f64>().unwrap().to_bits(), "{}", text);
            }
        }
    }

    #[test]
    fn decimal_answers_the_common_forms_only() {
        let yes = [
            "0",
            "-0",
            "5.",
            "0.0001",
            "-12.3456",
            "9007199254740992",
            "0.1234567890123456",
        ];
        for t in yes {
            assert_eq!(
                decimal(t.as_bytes()).map(f64::to_bits),
                Some(t.parse::<f64>().unwrap().to_bits()),
                "{t}"
            );
        }
        assert_eq!(decimal(b"-0").map(f64::is_sign_negative), Some(true));
        for t in [
            "",
            "-",
            ".5",
            "+1",
            "1e3",
            "1.2.3",
            "9007199254740993",
            "1234567890123456789",
            "12345678901234567890",
            " 1",
            "inf",
            "NaN",
        ] {
            assert_eq!(decimal(t.as_bytes()), None, "{t}");
        }
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
