//! `--phase`: one segment of a pump's log capture as the estimation record, and the operating
//! point the pump identified around (`--operating-point`).
//!
//! A capture (see `docs/real-logs.md`, "Check the pump's identification on the PC") is the
//! pump's live log: the header `t,u,y,r,phase`, one row per 10 ms tick, and every other line
//! the pump printed as a comment `# …`, in order:
//!
//! ```text
//! t,u,y,r,phase
//! # EXCITE A-Multistep n=3000 u0=30.00 y0=19.058 attempt=1/3
//! 2.51,0.3000,19.05833,,settle
//! 2.52,0.5000,19.06667,,excite
//! …
//! # ID p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000 c=-0.125000 score=-1234.5 eval=14/252 skip=0 iters=200
//! ```
//!
//! A *segment* is a maximal run of consecutive rows whose `phase` cell equals the asked
//! phase. The rows of an `excite` segment are exactly the samples of the pump's estimation
//! record; the `# EXCITE` comment before it gives the record's length `n` and its operating
//! point (`u0` in percent, `y0` in slm), and the first `# ID` comment after it the model the
//! pump identified on it ([`DeviceId`]).
//!
//! Which segment: the `--attempt N`-th of the file (counted from 1 in file order), or by
//! default the last *complete* one (followed by a row of another phase, or holding the `n`
//! rows its `# EXCITE` line announces; a segment cut off by the end of the capture is not).
//! The chosen segment is refused, never silently patched, when rows are missing: fewer or
//! more rows than its `# EXCITE` line's `n`, a step of the `t` column that is not one sample
//! period (a dropped log row, `# LOG dropped=…`, or a lost tick, `# MISSED … lost=…`), or a
//! malformed row inside it or at its end. A `# LOG dropped=` comment inside a segment whose
//! rows are all there (the count covers the whole second before it) is not an error; without
//! a `t` column such a comment refuses the segment.
//!
//! The file is read once, line by line, in memory bounded by two segments of at most
//! [`MEMORY_ROWS`] rows each; lines are at most [`MAX_LINE`] bytes of UTF-8 text. Cells are
//! separated by commas and may be blank-padded or double-quoted (a quoted comma is not
//! supported here: the pump writes none).

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ridge_core_host::{ArxModel, MeasuredGram, Offset};
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_SCALE, SAMPLE_RATE_HZ};
use serde::Serialize;

use crate::csv::{column, found, number, quote, unquote, Sample, MAX_LINE};
use crate::error::IdError;
use crate::eval::{read_samples, RecordStats};
use crate::input::{read_input, Input, MEMORY_ROWS};

/// Where the operating point `(u0, y0)` subtracted from the segment's samples comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum OperatingPoint {
    /// From the last `# EXCITE … u0=… y0=…` comment before the segment (the pump's own):
    /// `u0` percent → fraction, `y0` slm → the nearest 1/120 slm (the pump's `y0` is a whole
    /// SFM3300 count, printed to 3 decimals). The default of `--phase`.
    #[default]
    Log,
    /// Nothing is subtracted.
    None,
    /// These values, in the log's units (`u` as a fraction, `y` in slm).
    Given {
        /// Input operating point.
        u0: f64,
        /// Output operating point.
        y0: f64,
    },
}

impl std::str::FromStr for OperatingPoint {
    type Err = String;
    /// `log`, `none` or `U0,Y0` (two finite numbers, e.g. `0.3,19.058`).
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "log" => Ok(OperatingPoint::Log),
            "none" => Ok(OperatingPoint::None),
            other => {
                let num = |t: &str| {
                    t.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| format!("{} is not a finite number", quote(t.trim())))
                };
                let (u, y) = other
                    .split_once(',')
                    .ok_or_else(|| format!("{}: expected log, none or U0,Y0", quote(other)))?;
                Ok(OperatingPoint::Given {
                    u0: num(u)?,
                    y0: num(y)?,
                })
            }
        }
    }
}

/// What `--phase` selects.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentOptions {
    /// The `phase` cell of the wanted rows, e.g. `excite`.
    pub phase: String,
    /// The segment's number in the file, from 1 (`--attempt N`); `None`: the last complete one.
    pub attempt: Option<u32>,
    /// The operating point subtracted before the statistics (`--operating-point`).
    pub operating_point: OperatingPoint,
}

impl SegmentOptions {
    /// The pump's estimation record: phase `excite`, the last complete segment, the operating
    /// point of its `# EXCITE` line.
    pub fn excite() -> Self {
        SegmentOptions {
            phase: EXCITE_PHASE.to_string(),
            attempt: None,
            operating_point: OperatingPoint::Log,
        }
    }
}

/// The `phase` of the pump's estimation rows (`State::Excite.name()` of the firmware).
pub const EXCITE_PHASE: &str = "excite";

/// The pump's `# EXCITE` line: the record announced before an excitation segment.
#[derive(Debug, Clone, PartialEq)]
pub struct ExciteLine {
    /// Line number of the comment.
    pub line: u64,
    /// The excitation preset, e.g. `A-Multistep`.
    pub record: String,
    /// Samples announced (`n`).
    pub samples: u32,
    /// Base duty as a fraction 0..1 (the line's `u0`, percent, divided by 100).
    pub u0: f64,
    /// Settled flow, slm: the line's `y0` taken to the nearest SFM3300 count (1/120 slm).
    pub y0: f64,
    /// The attempt as printed, e.g. `1/3`.
    pub attempt: String,
}

/// The model the pump reported after a segment (its `# ID` line): the absolute model
/// (duty as a fraction, flow in slm) with its intercept.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceId {
    /// Line number of the comment.
    pub line: u64,
    /// Orders and delay.
    pub p: u8,
    /// Input order.
    pub q: u8,
    /// Input delay, samples.
    pub d: u8,
    /// Whether the model has an intercept (`off=1`).
    pub offset: bool,
    /// Output coefficients θ_1..θ_p (6 decimals as printed).
    pub theta: Vec<f64>,
    /// Input coefficients φ_0..φ_{q−1}, slm per unit duty.
    pub phi: Vec<f64>,
    /// Intercept, slm.
    pub c: f64,
    /// Ridge-M iterations the pump ran on the chosen structure.
    pub iterations: Option<u32>,
}

/// The chosen segment.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// The capture file.
    pub path: PathBuf,
    /// Its rows as samples (absolute values, as logged), with their lines.
    pub samples: Vec<Sample>,
    /// Which segment of the file it is (from 1) and how many of that phase the file has.
    pub index: u32,
    /// Segments of the phase in the file.
    pub count: u32,
    /// The `# EXCITE` comment that announced it, if any.
    pub excite: Option<ExciteLine>,
    /// The first `# ID` comment after it (before the next segment), if any.
    pub device: Option<DeviceId>,
    /// The operating point subtracted, `(u0, y0)` in the log's units (`None`: nothing).
    pub operating_point: Option<(f64, f64)>,
}

impl Segment {
    /// Line of the first and last row.
    pub fn lines(&self) -> (u64, u64) {
        match (self.samples.first(), self.samples.last()) {
            (Some(a), Some(b)) => (a.line, b.line),
            _ => (0, 0),
        }
    }
}

/// One segment while it is read.
#[derive(Debug, Default)]
struct Building {
    index: u32,
    samples: Vec<Sample>,
    excite: Option<ExciteLine>,
    /// The previous row's `t` and line.
    last_t: Option<(f64, u64)>,
    /// The sample period `t` must step by, s: the pump's with an `# EXCITE` line, else the
    /// segment's first step.
    period: Option<f64>,
    /// The first thing that makes the segment unusable.
    damage: Option<IdError>,
    /// A `# LOG dropped=` comment inside it (line).
    dropped_inside: Option<u64>,
    /// Rows its `# EXCITE` line announces (an `excite` segment only).
    announced: Option<u32>,
    /// Followed by a row of another phase.
    ended: bool,
    device: Option<DeviceId>,
}

impl Building {
    fn complete(&self) -> bool {
        self.ended
            || self
                .announced
                .is_some_and(|n| n as usize == self.samples.len())
    }
}

/// The header's columns.
struct Columns {
    count: usize,
    t: Option<usize>,
    u: usize,
    y: usize,
    phase: usize,
}

/// Reads the segment `opts` asks for from the capture at `path` (see the [module docs](self)).
///
/// Errors (file and line named): the file cannot be read, has no header or no `u`, `y` or
/// `phase` column, a line longer than [`MAX_LINE`] or not UTF-8, a malformed `# EXCITE`
/// line, no segment of the phase, `--attempt` past the last one, no complete one, rows
/// missing from the chosen one, a bad number in it, more than [`MEMORY_ROWS`] rows, and for
/// [`OperatingPoint::Log`] no `# EXCITE` line before it.
pub fn read(path: &Path, opts: &SegmentOptions) -> Result<Segment, IdError> {
    let file = File::open(path).map_err(|source| IdError::Io {
        path: path.to_path_buf(),
        line: None,
        source,
    })?;
    read_from(file, path, opts)
}

/// [`read`] from any reader, `name` naming it in messages.
pub fn read_from(
    reader: impl Read,
    name: &Path,
    opts: &SegmentOptions,
) -> Result<Segment, IdError> {
    let mut lines = Lines::new(reader, name);
    let mut cols: Option<Columns> = None;
    let mut current: Option<Building> = None;
    // The segment kept: the `--attempt`-th, or the last complete one so far.
    let mut kept: Option<Building> = None;
    let mut count = 0u32;
    let mut last_excite: Option<ExciteLine> = None;
    // A malformed row since the last good one, while a segment was being read.
    let mut bad_row: Option<IdError> = None;
    let mut phases: Vec<String> = Vec::new();
    let mut cut: Option<Building> = None;
    while let Some((line, text)) = lines.next_line()? {
        let trimmed = text.trim();
        if trimmed.is_empty() {
            continue;
        }
        if let Some(comment) = trimmed.strip_prefix('#') {
            let comment = comment.trim();
            if let Some(rest) = comment.strip_prefix("EXCITE ") {
                last_excite = Some(parse_excite(rest, name, line)?);
            } else if let Some(rest) = comment.strip_prefix("ID ") {
                // The pump's result for the segment just read (before any later segment).
                let target = match (&mut current, &mut kept) {
                    (Some(b), _) if b.device.is_none() => Some(b),
                    (None, Some(k)) if k.device.is_none() && k.index == count => Some(k),
                    _ => None,
                };
                if let Some(b) = target {
                    b.device = parse_id(rest, line);
                }
            } else if comment.starts_with("LOG dropped=") {
                if let Some(b) = &mut current {
                    b.dropped_inside.get_or_insert(line);
                }
            }
            continue;
        }
        let Some(c) = &cols else {
            cols = Some(parse_header(trimmed, name, line)?);
            continue;
        };
        let cells: Vec<&str> = trimmed.split(',').map(unquote).collect();
        if cells.len() != c.count {
            let e = IdError::line(
                name,
                line,
                format!(
                    "expected {} columns as in the header, found {}: a damaged row",
                    c.count,
                    cells.len()
                ),
            );
            if current.is_some() && bad_row.is_none() {
                bad_row = Some(e);
            }
            continue;
        }
        let phase = cells[c.phase];
        if phase != opts.phase {
            if phases.len() < 16 && !phases.iter().any(|p| p == phase) {
                phases.push(phase.to_string());
            }
            if let Some(mut b) = current.take() {
                b.ended = true;
                if let Some(e) = bad_row.take() {
                    b.damage.get_or_insert(e);
                }
                keep(&mut kept, b, opts.attempt);
            }
            bad_row = None;
            continue;
        }
        let b = current.get_or_insert_with(|| {
            count += 1;
            let excite = last_excite.take();
            Building {
                index: count,
                announced: excite
                    .as_ref()
                    .filter(|_| opts.phase == EXCITE_PHASE)
                    .map(|e| e.samples),
                period: excite.as_ref().map(|_| 1.0 / f64::from(SAMPLE_RATE_HZ)),
                excite,
                ..Building::default()
            }
        });
        if let Some(e) = bad_row.take() {
            b.damage.get_or_insert(e);
        }
        // Rows of segments that are not wanted are checked for their column count only.
        let wanted = opts.attempt.is_none_or(|n| n == b.index);
        if !wanted || b.damage.is_some() {
            continue;
        }
        let sample = Sample {
            line,
            u: number(cells[c.u], "u", name, line)?,
            y: number(cells[c.y], "y", name, line)?,
        };
        if let Some(ti) = c.t {
            let t = number(cells[ti], "t", name, line)?;
            if let Some((t_prev, l_prev)) = b.last_t {
                let step = t - t_prev;
                // The pump's period for its own records, else the segment's first step.
                let expected = *b.period.get_or_insert(step);
                if !(step > 0.0 && (step - expected).abs() <= 0.5 * expected) {
                    b.damage.get_or_insert(IdError::line(
                        name,
                        line,
                        format!(
                            "t steps from {t_prev} (line {l_prev}) to {t} here, not by one \
                             sample period ({expected} s): rows of this segment are missing \
                             (log rows dropped, see `# LOG dropped=`, or ticks lost, see \
                             `# MISSED`)"
                        ),
                    ));
                }
            }
            b.last_t = Some((t, line));
        }
        if b.samples.len() >= MEMORY_ROWS {
            return Err(IdError::line(
                name,
                line,
                format!(
                    "more than {MEMORY_ROWS} rows in one segment of phase {}",
                    opts.phase
                ),
            ));
        }
        b.samples.push(sample);
    }
    if let Some(mut b) = current.take() {
        if let Some(e) = bad_row.take() {
            b.damage.get_or_insert(e);
        }
        if b.complete() || opts.attempt == Some(b.index) {
            keep(&mut kept, b, opts.attempt);
        } else {
            cut = Some(b);
        }
    }
    if cols.is_none() {
        return Err(IdError::file(
            name,
            "no header row: expected a capture with the header t,u,y,r,phase",
        ));
    }
    let Some(b) = kept else {
        return Err(match (count, opts.attempt, cut) {
            (0, _, _) => IdError::file(
                name,
                format!(
                    "no rows with phase {} (phases found: {})",
                    opts.phase,
                    if phases.is_empty() {
                        "none".to_string()
                    } else {
                        phases.join(", ")
                    }
                ),
            ),
            (n, Some(a), _) => IdError::Usage(format!(
                "--attempt {a}: {} has {n} segment(s) of phase {}",
                name.display(),
                opts.phase
            )),
            (_, None, Some(c)) => IdError::file(
                name,
                format!(
                    "the only segment of phase {} (from line {}) is cut off by the end of the \
                     file ({} rows{}): no complete one",
                    opts.phase,
                    c.samples.first().map_or(0, |s| s.line),
                    c.samples.len(),
                    c.excite
                        .as_ref()
                        .map(|e| format!(" of the {} its EXCITE line announces", e.samples))
                        .unwrap_or_default()
                ),
            ),
            (_, None, None) => IdError::file(name, "no complete segment"),
        });
    };
    finish(b, count, name, opts)
}

/// Keeps `b` when it is the asked one, or (no `--attempt`) a complete one later than the
/// one kept.
fn keep(kept: &mut Option<Building>, b: Building, attempt: Option<u32>) {
    match attempt {
        Some(n) if n == b.index => *kept = Some(b),
        Some(_) => {}
        None if b.complete() => *kept = Some(b),
        None => {}
    }
}

/// The chosen segment checked and its operating point found.
fn finish(b: Building, count: u32, name: &Path, opts: &SegmentOptions) -> Result<Segment, IdError> {
    let which = format!("segment {} of {count} of phase {}", b.index, opts.phase);
    if let Some(e) = b.damage {
        return Err(match e {
            IdError::Line {
                path,
                line,
                message,
            } => IdError::Line {
                path,
                line,
                message: format!("{which}: {message}"),
            },
            other => other,
        });
    }
    let first = b.samples.first().map_or(0, |s| s.line);
    let last = b.samples.last().map_or(0, |s| s.line);
    if let (Some(n), Some(e)) = (b.announced, &b.excite) {
        if n as usize != b.samples.len() {
            return Err(IdError::file(
                name,
                format!(
                    "{which} (lines {first}–{last}) has {} rows, but its EXCITE line (line {}) \
                     announces n={n}: rows are missing or the record was cut short",
                    b.samples.len(),
                    e.line
                ),
            ));
        }
    }
    if let (None, Some(l)) = (b.last_t, b.dropped_inside) {
        return Err(IdError::line(
            name,
            l,
            format!(
                "{which}: log rows were dropped inside it (and there is no t column to tell \
                 which)"
            ),
        ));
    }
    let operating_point = match opts.operating_point {
        OperatingPoint::None => None,
        OperatingPoint::Given { u0, y0 } => Some((u0, y0)),
        OperatingPoint::Log => match &b.excite {
            Some(e) => Some((e.u0, e.y0)),
            None => {
                return Err(IdError::file(
                    name,
                    format!(
                        "{which} (from line {first}) has no `# EXCITE … u0=… y0=…` line \
                         before it: give the operating point with --operating-point U0,Y0, \
                         or --operating-point none"
                    ),
                ))
            }
        },
    };
    Ok(Segment {
        path: name.to_path_buf(),
        samples: b.samples,
        index: b.index,
        count,
        excite: b.excite,
        device: b.device,
        operating_point,
    })
}

/// The value after `key=` among the space-separated fields of `text`.
fn field<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.split_ascii_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
}

/// Parses the rest of an `EXCITE` comment: `A-Multistep n=3000 u0=30.00 y0=19.058
/// attempt=1/3`.
fn parse_excite(rest: &str, name: &Path, line: u64) -> Result<ExciteLine, IdError> {
    let bad = |what: &str| {
        IdError::line(
            name,
            line,
            format!(
                "EXCITE line: {what} (expected `# EXCITE <record> n=<samples> u0=<duty %> \
                 y0=<slm> attempt=<k>/<n>`)"
            ),
        )
    };
    let num = |key: &str| -> Result<f64, IdError> {
        field(rest, key)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad(&format!("no number {key}=")))
    };
    let samples = field(rest, "n")
        .and_then(|v| v.parse::<u32>().ok())
        .ok_or_else(|| bad("no whole number n="))?;
    let u0_percent = num("u0")?;
    let y0_slm = num("y0")?;
    // The pump prints u0 (1/10 000 duty) in percent with 2 decimals and y0 (whole counts of
    // 1/120 slm) in slm with 3: both are recovered exactly.
    let full = f64::from(DUTY_FULL_SCALE);
    let scale = f64::from(FLOW_SCALE);
    let u0 = (u0_percent * full / 100.0).round() / full;
    let y0 = (y0_slm * scale).round() / scale;
    Ok(ExciteLine {
        line,
        record: rest
            .split_ascii_whitespace()
            .next()
            .unwrap_or("")
            .to_string(),
        samples,
        u0,
        y0,
        attempt: field(rest, "attempt").unwrap_or("").to_string(),
    })
}

/// Parses the rest of an `ID` comment (`p=1 q=1 d=3 off=1 theta=… phi=… c=… … iters=200`);
/// `None` when it is not one (the pump's line is informative here, never required).
fn parse_id(rest: &str, line: u64) -> Option<DeviceId> {
    let order = |k: &str| field(rest, k)?.parse::<u8>().ok();
    let list = |k: &str| -> Option<Vec<f64>> {
        field(rest, k)?
            .split(',')
            .map(|v| v.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect()
    };
    let id = DeviceId {
        line,
        p: order("p")?,
        q: order("q")?,
        d: order("d")?,
        offset: field(rest, "off")? == "1",
        theta: list("theta")?,
        phi: list("phi")?,
        c: field(rest, "c")?
            .parse()
            .ok()
            .filter(|c: &f64| c.is_finite())?,
        iterations: field(rest, "iters").and_then(|v| v.parse().ok()),
    };
    (id.theta.len() == usize::from(id.p) && id.phi.len() == usize::from(id.q)).then_some(id)
}

/// The header's columns: `u`, `y` and `phase` required, `t` optional.
fn parse_header(text: &str, name: &Path, line: u64) -> Result<Columns, IdError> {
    let names: Vec<&str> = text.split(',').map(unquote).collect();
    let find = |want: &str| column(&names, want, name, line);
    let need = |want: &str| -> Result<usize, IdError> {
        find(want)?.ok_or_else(|| {
            IdError::line(
                name,
                line,
                format!(
                    "header has no column named {want} (found: {}); --phase reads the \
                     pump's log capture, header t,u,y,r,phase",
                    found(&names)
                ),
            )
        })
    };
    Ok(Columns {
        count: names.len(),
        t: find("t")?,
        u: need("u")?,
        y: need("y")?,
        phase: need("phase")?,
    })
}

/// Lines of a reader, at most [`MAX_LINE`] bytes each, UTF-8, numbered from 1; a `\r`
/// before the `\n` and a byte order mark at the start are removed.
struct Lines<R> {
    reader: BufReader<R>,
    name: PathBuf,
    line: u64,
    buf: Vec<u8>,
}

impl<R: Read> Lines<R> {
    fn new(reader: R, name: &Path) -> Self {
        Lines {
            reader: BufReader::with_capacity(1 << 16, reader),
            name: name.to_path_buf(),
            line: 0,
            buf: Vec::new(),
        }
    }

    fn next_line(&mut self) -> Result<Option<(u64, &str)>, IdError> {
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

/// What the report says about the segment (`--phase`).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentInfo {
    /// The phase asked for.
    pub phase: String,
    /// Which segment of that phase (from 1) and how many the file has.
    pub index: u32,
    /// Segments of the phase in the file.
    pub count: u32,
    /// Lines of its first and last row.
    pub lines: (u64, u64),
    /// The `# EXCITE` line before it, if any.
    pub excite: Option<ExciteLine>,
    /// The pump's `# ID` line after it, if any.
    pub device: Option<DeviceId>,
    /// The operating point subtracted, `(u0, y0)` in the log's units.
    pub operating_point: Option<(f64, f64)>,
}

impl Segment {
    /// The segment's rows as an in-memory record (absolute values).
    pub fn input(&self) -> Input {
        Input::Memory {
            name: self.path.clone(),
            samples: Arc::new(self.samples.clone()),
        }
    }

    /// The report's account of it, for the phase of `opts`.
    pub fn info(&self, opts: &Option<SegmentOptions>) -> SegmentInfo {
        SegmentInfo {
            phase: opts.as_ref().map(|o| o.phase.clone()).unwrap_or_default(),
            index: self.index,
            count: self.count,
            lines: self.lines(),
            excite: self.excite.clone(),
            device: self.device.clone(),
            operating_point: self.operating_point,
        }
    }
}

/// The statistics of `input` with the operating point `shift = (u0, y0)` subtracted from
/// every sample (none: [`read_input`]), into the empty `gram`; the reported ranges are those
/// of the absolute samples.
///
/// Errors: as [`read_input`].
pub fn read_shifted(
    input: &Input,
    gram: MeasuredGram<f64>,
    shift: Option<(f64, f64)>,
) -> Result<RecordStats, IdError> {
    let Some((u0, y0)) = shift else {
        return read_input(input, gram);
    };
    let mut stats = read_samples(
        input.name(),
        input.samples()?.map(|s| {
            s.map(|s| Sample {
                u: s.u - u0,
                y: s.y - y0,
                ..s
            })
        }),
        gram,
    )?;
    stats.u_range = (stats.u_range.0 + u0, stats.u_range.1 + u0);
    stats.y_range = (stats.y_range.0 + y0, stats.y_range.1 + y0);
    Ok(stats)
}

/// The absolute model of a model `dev` identified on the deviations from the operating point
/// `(u0, y0)`: the same θ, φ and delay, with the intercept
/// `c = c_dev + y0 (1 − Σθ) − u0 Σφ` (the firmware's `selfid::absolute_model`, in `f64`).
///
/// Errors: [`ridge_core_host::Error::NonFinite`] for non-finite coefficients.
pub fn absolute_model(
    dev: &ArxModel<f64>,
    (u0, y0): (f64, f64),
) -> Result<ArxModel<f64>, ridge_core_host::Error> {
    let sum_theta: f64 = dev.theta().iter().sum();
    let sum_phi: f64 = dev.phi().iter().sum();
    let c = dev.intercept() + y0 * (1.0 - sum_theta) - u0 * sum_phi;
    ArxModel::new(
        dev.theta(),
        dev.phi(),
        dev.structure().d,
        Offset::Intercept,
        c,
    )
}

/// `ridge-id`'s model against the pump's `# ID` line.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Agreement {
    /// Same `p`, `q`, `d` and offset flag.
    pub same_structure: bool,
    /// Largest |Δθ_i| (with the same structure; else `None`).
    pub theta: Option<f64>,
    /// Largest |Δφ_j|, slm per unit duty.
    pub phi: Option<f64>,
    /// |Δc|, slm.
    pub c: Option<f64>,
}

/// Largest absolute difference of two equally long lists (`None` when they are not).
fn max_diff(a: &[f64], b: &[f64]) -> Option<f64> {
    (a.len() == b.len()).then(|| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    })
}

impl DeviceId {
    /// How `model` agrees with this line.
    pub fn agreement(&self, model: &ArxModel<f64>) -> Agreement {
        let s = model.structure();
        let same = (s.p, s.q, s.d, model.offset() == Offset::Intercept)
            == (self.p, self.q, self.d, self.offset);
        let c = same.then(|| (model.intercept() - self.c).abs());
        Agreement {
            same_structure: same,
            theta: max_diff(model.theta(), &self.theta).filter(|_| same),
            phi: max_diff(model.phi(), &self.phi).filter(|_| same),
            c,
        }
    }
}

impl SegmentInfo {
    /// The report's lines about the segment and, when the pump's `ID` line is there, how
    /// `model` agrees with it (indented by two spaces, each ending with a line end).
    pub fn to_text(&self, model: &ArxModel<f64>) -> String {
        let mut o = String::new();
        let excite = self
            .excite
            .as_ref()
            .map(|e| {
                format!(
                    ", announced by EXCITE {} n={} attempt={} (line {})",
                    e.record, e.samples, e.attempt, e.line
                )
            })
            .unwrap_or_default();
        o += &format!(
            "  segment     phase {}: segment {} of {} (lines {}–{}){excite}\n",
            self.phase, self.index, self.count, self.lines.0, self.lines.1
        );
        match self.operating_point {
            Some((u0, y0)) => {
                o += &format!(
                    "  op. point   u0 = {u0}, y0 = {y0} subtracted; the model below is the \
                     absolute one, c = y0 (1 - sum theta) - u0 sum phi\n"
                )
            }
            None => o += "  op. point   none subtracted\n",
        }
        if let Some(d) = &self.device {
            let a = d.agreement(model);
            let list = |v: &[f64]| {
                v.iter()
                    .map(|x| format!("{x}"))
                    .collect::<Vec<_>>()
                    .join(",")
            };
            o += &format!(
                "  pump's ID   (line {}) p = {}, q = {}, d = {}, offset {}, theta = [{}], phi = [{}], c = {}\n",
                d.line,
                d.p,
                d.q,
                d.d,
                if d.offset { "intercept" } else { "none" },
                list(&d.theta),
                list(&d.phi),
                d.c
            );
            o += &match (a.same_structure, a.theta, a.phi, a.c) {
                (true, Some(t), Some(f), Some(c)) => format!(
                    "  agreement   same structure; largest |ridge-id - pump|: theta {t:.2e}, \
                     phi {f:.2e}, c {c:.2e} (the pump prints 6 decimals and computes in f32)\n"
                ),
                _ => "  agreement   DIFFERENT structure from the pump's\n".to_string(),
            };
        }
        o
    }

    /// The `"segment"` object of the JSON report.
    pub fn to_json(&self, model: &ArxModel<f64>) -> serde_json::Value {
        #[derive(Serialize)]
        struct Device<'a> {
            line: u64,
            structure: [u8; 3],
            offset: bool,
            theta: &'a [f64],
            phi: &'a [f64],
            c: f64,
            iterations: Option<u32>,
            agreement: Agreement,
        }
        #[derive(Serialize)]
        struct Json<'a> {
            phase: &'a str,
            index: u32,
            count: u32,
            lines: [u64; 2],
            excite_line: Option<u64>,
            operating_point: Option<[f64; 2]>,
            device: Option<Device<'a>>,
        }
        let j = Json {
            phase: &self.phase,
            index: self.index,
            count: self.count,
            lines: [self.lines.0, self.lines.1],
            excite_line: self.excite.as_ref().map(|e| e.line),
            operating_point: self.operating_point.map(|(u, y)| [u, y]),
            device: self.device.as_ref().map(|d| Device {
                line: d.line,
                structure: [d.p, d.q, d.d],
                offset: d.offset,
                theta: &d.theta,
                phi: &d.phi,
                c: d.c,
                iterations: d.iterations,
                agreement: d.agreement(model),
            }),
        };
        serde_json::to_value(j).unwrap_or(serde_json::Value::Null)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXCITE1: &str = "# EXCITE A-Multistep n=3 u0=30.00 y0=19.058 attempt=1/3";
    const EXCITE2: &str = "# EXCITE A-Multistep n=3 u0=30.00 y0=20.000 attempt=2/3";
    const ID: &str = "# ID p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000 c=-0.125000 \
                      score=-1234.5 eval=14/252 skip=0 iters=200";

    fn capture(lines: &[&str]) -> String {
        let mut s = String::from("t,u,y,r,phase\n");
        for l in lines {
            s.push_str(l);
            s.push('\n');
        }
        s
    }

    fn read_text(text: &str, opts: &SegmentOptions) -> Result<Segment, IdError> {
        read_from(text.as_bytes(), Path::new("CAP.csv"), opts)
    }

    fn excite() -> SegmentOptions {
        SegmentOptions::excite()
    }

    /// Two attempts: the first refused by the pump (a REJECT line, no ID), the second with
    /// its ID line.
    fn two_attempts() -> String {
        capture(&[
            "0.01,0.0000,0.00000,,wait",
            "0.02,0.3000,19.05833,,settle",
            EXCITE1,
            "0.03,0.3000,19.05833,,settle",
            "0.04,0.5000,19.05833,,excite",
            "0.05,0.5000,20.00000,,excite",
            "0.06,0.2000,22.00000,,excite",
            "# REJECT not-excited rms=0.012 attempt=1/3",
            "0.07,0.3000,21.00000,,settle",
            EXCITE2,
            "0.08,0.3000,20.00000,,settle",
            "0.09,0.6000,20.00000,,excite",
            "0.10,0.6000,21.00000,,excite",
            "0.11,0.3000,23.00000,,excite",
            ID,
            "0.12,0.3000,22.00000,,validate",
        ])
    }

    #[test]
    fn picks_the_last_complete_segment_its_operating_point_and_id() {
        let s = read_text(&two_attempts(), &excite()).unwrap();
        assert_eq!((s.index, s.count), (2, 2));
        assert_eq!(s.lines(), (13, 15));
        let got: Vec<(f64, f64)> = s.samples.iter().map(|s| (s.u, s.y)).collect();
        assert_eq!(got, [(0.6, 20.0), (0.6, 21.0), (0.3, 23.0)]);
        assert_eq!(s.operating_point, Some((0.3, 20.0)));
        let d = s.device.unwrap();
        assert_eq!((d.line, d.p, d.q, d.d, d.offset), (16, 1, 1, 3, true));
        assert_eq!((d.theta, d.phi, d.c), (vec![0.935], vec![6.5], -0.125));
        assert_eq!(d.iterations, Some(200));
        // --attempt 1: the first, around its own operating point; y0 = 19.058 slm is the
        // count 2287 (19.058333… slm).
        let mut o = excite();
        o.attempt = Some(1);
        let s = read_text(&two_attempts(), &o).unwrap();
        assert_eq!((s.index, s.lines()), (1, (6, 8)));
        assert_eq!(s.operating_point, Some((0.3, 2287.0 / 120.0)));
        assert!(s.device.is_none(), "the REJECT attempt has no ID");
        o.attempt = Some(3);
        let e = read_text(&two_attempts(), &o).unwrap_err().to_string();
        assert!(
            e.contains("--attempt 3") && e.contains("2 segment(s)"),
            "{e}"
        );
        // Explicit or no operating point.
        o.attempt = None;
        o.operating_point = "0.25,-1e1".parse().unwrap();
        assert_eq!(
            read_text(&two_attempts(), &o).unwrap().operating_point,
            Some((0.25, -10.0))
        );
        o.operating_point = OperatingPoint::None;
        assert_eq!(
            read_text(&two_attempts(), &o).unwrap().operating_point,
            None
        );
    }

    #[test]
    fn missing_rows_are_refused() {
        // A row dropped inside (t jumps).
        let text = two_attempts().replace("0.10,0.6000,21.00000,,excite\n", "");
        let e = read_text(&text, &excite()).unwrap_err().to_string();
        assert!(e.starts_with("CAP.csv line 14:"), "{e}");
        assert!(
            e.contains("segment 2 of 2") && e.contains("t steps from 0.09"),
            "{e}"
        );
        // Fewer rows than the EXCITE line announces (the first row dropped: no gap).
        let text = two_attempts().replace("0.09,0.6000,20.00000,,excite\n", "");
        let e = read_text(&text, &excite()).unwrap_err().to_string();
        assert!(e.contains("has 2 rows") && e.contains("n=3"), "{e}");
        // A damaged row at the end of the segment.
        let text = two_attempts().replace("0.11,0.3000,23.00000,,excite", "0.11,0.30");
        let e = read_text(&text, &excite()).unwrap_err().to_string();
        assert!(e.starts_with("CAP.csv line 15:"), "{e}");
        assert!(e.contains("damaged row"), "{e}");
        // A bad number inside.
        let text = two_attempts().replace("0.10,0.6000,21.00000", "0.10,0.6000,2x");
        let e = read_text(&text, &excite()).unwrap_err().to_string();
        assert_eq!(e, "CAP.csv line 14: column y: \"2x\" is not a number");
        // A LOG dropped comment inside a complete segment is not an error ...
        let text = two_attempts().replace(EXCITE2, &format!("{EXCITE2}\n# LOG dropped=1"));
        let text = text.replace(ID, &format!("# LOG dropped=2\n{ID}"));
        assert_eq!(read_text(&text, &excite()).unwrap().samples.len(), 3);
        // ... without a t column it is.
        let no_t: String = text
            .lines()
            .map(|l| match l.starts_with('#') {
                true => format!("{l}\n"),
                false => format!("{}\n", l.split_once(',').unwrap().1),
            })
            .collect();
        assert!(no_t.starts_with("u,y,r,phase\n"));
        let text = no_t.replace(
            "0.6000,21.00000,,excite",
            "0.6000,21.00000,,excite\n# LOG dropped=1",
        );
        let e = read_text(&text, &excite()).unwrap_err().to_string();
        assert!(e.contains("dropped inside"), "{e}");
    }

    #[test]
    fn a_segment_cut_off_by_the_end_is_not_taken() {
        // The last attempt cut off: the previous complete one is taken.
        let text = two_attempts();
        let cut = &text[..text.find("0.10,").unwrap()];
        let s = read_text(cut, &excite()).unwrap();
        assert_eq!(s.index, 1);
        // Only a cut one: refused.
        let text = capture(&[EXCITE1, "0.01,0.5,19,,excite", "0.02,0.5,20,,excite"]);
        let e = read_text(&text, &excite()).unwrap_err().to_string();
        assert!(
            e.contains("cut off by the end of the file (2 rows of the 3"),
            "{e}"
        );
        // Complete by its count even at the very end of the file.
        let text = capture(&[
            EXCITE1,
            "0.01,0.5,19,,excite",
            "0.02,0.5,20,,excite",
            "0.03,0.3,21,,excite",
        ]);
        assert_eq!(read_text(&text, &excite()).unwrap().samples.len(), 3);
    }

    #[test]
    fn bad_captures_are_clear_errors() {
        let msg = |text: &str| read_text(text, &excite()).unwrap_err().to_string();
        assert!(msg("t,u,y\n0,1,2\n").contains("no column named phase"));
        assert!(msg("").contains("no header row"));
        assert!(msg("# only a comment\n").contains("no header row"));
        let e = msg(&capture(&["0.01,0.3,19,,settle", "0.02,0.3,19,,run"]));
        assert!(
            e.contains("no rows with phase excite (phases found: settle, run)"),
            "{e}"
        );
        let e = msg(&capture(&[
            "# EXCITE A-Multistep n=x u0=30 y0=1 attempt=1/3",
        ]));
        assert!(
            e.starts_with("CAP.csv line 2: EXCITE line: no whole number n="),
            "{e}"
        );
        // No EXCITE line: the operating point must be given.
        let e = msg(&capture(&["0.01,0.5,19,,excite", "0.02,0.3,19,,run"]));
        assert!(e.contains("--operating-point"), "{e}");
        // Not UTF-8, too long a line.
        let e = read_from(
            &b"t,u,y,r,phase\n\xff\n"[..],
            Path::new("CAP.csv"),
            &excite(),
        );
        assert_eq!(
            e.unwrap_err().to_string(),
            "CAP.csv line 2: not valid UTF-8 text"
        );
        let long = format!("t,u,y,r,phase\n{}\n", "#".repeat(MAX_LINE as usize + 1));
        assert!(msg(&long).contains("line 2: line longer than"));
        // Operating points on the command line.
        assert!("0.3".parse::<OperatingPoint>().is_err());
        assert!("0.3,nan".parse::<OperatingPoint>().is_err());
        assert_eq!("log".parse::<OperatingPoint>(), Ok(OperatingPoint::Log));
    }

    #[test]
    fn absolute_model_moves_the_operating_point_into_the_intercept() {
        let dev = ArxModel::new(&[0.5, 0.2], &[10.0], 1, Offset::None, 0.0).unwrap();
        let abs = absolute_model(&dev, (0.3, 20.0)).unwrap();
        assert_eq!(abs.offset(), Offset::Intercept);
        // At the operating point the absolute model is in equilibrium.
        let y = 0.5 * 20.0 + 0.2 * 20.0 + 10.0 * 0.3 + abs.intercept();
        assert!((y - 20.0).abs() < 1e-12, "{y}");
    }
}
