//! The segment `--phase` asks for, read from a capture: which rows, checked complete, with the
//! `EXCITE` line before them and the `ID` line after them ([`read`], [`Segment`]).

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ridge_pump_firmware::units::SAMPLE_RATE_HZ;

use super::device_lines::{parse_excite, parse_id, parse_map, DeviceId, DeviceMap, ExciteLine};
use super::lines::Lines;
use super::options::{OperatingPoint, SegmentOptions, EXCITE_PHASE};
use crate::csv::{column, found, number, unquote, Sample};
use crate::error::IdError;
use crate::input::{Input, MEMORY_ROWS};

/// The chosen segment.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// The capture file.
    pub path: PathBuf,
    /// Its rows as samples (absolute values: as logged, the input through [`Segment::map`]
    /// when there is one), with their lines.
    pub samples: Vec<Sample>,
    /// Which segment of the file it is (from 1) and how many of that phase the file has.
    pub index: u32,
    /// Segments of the phase in the file.
    pub count: u32,
    /// The `# EXCITE` comment that announced it, if any.
    pub excite: Option<ExciteLine>,
    /// The `# MAP` comment before that `# EXCITE` line, if any: the samples' input and the
    /// operating point's are the map's flow (slm) at the logged duty.
    pub map: Option<DeviceMap>,
    /// The first `# ID` comment after it (before the next segment), if any.
    pub device: Option<DeviceId>,
    /// The operating point subtracted, `(u0, y0)` in the samples' units (`None`: nothing).
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
    map: Option<DeviceMap>,
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

/// Reads the segment `opts` asks for from the capture at `path` (see the [module docs](super)).
///
/// Errors (file and line named): the file cannot be read, has no header or no `u`, `y` or
/// `phase` column, a line longer than [`MAX_LINE`] or not UTF-8, a malformed `# EXCITE`
/// line, no segment of the phase, `--attempt` past the last one, no complete one, rows
/// missing from the chosen one, a bad number in it, more than [`MEMORY_ROWS`] rows, and for
/// [`OperatingPoint::Log`] no `# EXCITE` line before it.
///
/// [`MAX_LINE`]: crate::csv::MAX_LINE
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
    // The last `# MAP` line, and the one current when the last `# EXCITE` line came.
    let mut last_map: Option<DeviceMap> = None;
    let mut excite_map: Option<DeviceMap> = None;
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
                excite_map = last_map.take();
            } else if let Some(rest) = comment.strip_prefix("MAP ") {
                last_map = Some(parse_map(rest, name, line)?);
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
                map: excite.as_ref().and(excite_map.take()),
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
    // Through the map: the input is its flow at the logged duty, the logged operating
    // point's too (a given one is in the samples' units already).
    let mut samples = b.samples;
    if let Some(m) = &b.map {
        for s in &mut samples {
            s.u = m.flow(s.u);
        }
    }
    let through = |u0: f64| b.map.as_ref().map_or(u0, |m| m.flow(u0));
    let operating_point = match opts.operating_point {
        OperatingPoint::None => None,
        OperatingPoint::Given { u0, y0 } => Some((u0, y0)),
        OperatingPoint::Log => match &b.excite {
            Some(e) => Some((through(e.u0), e.y0)),
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
        samples,
        index: b.index,
        count,
        excite: b.excite,
        map: b.map,
        device: b.device,
        operating_point,
    })
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

impl Segment {
    /// The segment's rows as an in-memory record (absolute values).
    pub fn input(&self) -> Input {
        Input::Memory {
            name: self.path.clone(),
            samples: Arc::new(self.samples.clone()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csv::MAX_LINE;

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
}
