//! Host-side parsing of the report lines the firmware writes ([`crate::event`], the console's
//! answers in [`crate::console`]): the one parser of each line, beside its writers, for the
//! host tools (the simavr harness, ridge-id) and the tests.
//!
//! Built on hosts only (`cfg(not(target_os = "none"))`, with `std`): the board targets have
//! no OS, so neither board image contains it, and a plain `cargo test` runs its tests.
//!
//! - [`ParsedLine`]: any line split into its keyword, its bare words and its `key=value`
//!   fields (e.g. `REJECT fit=42.1<70.0 attempt=1/3`), with numbers read by [`number`].
//! - [`IdLine`]: the `ID` line ([`Event::Identified`](crate::event::Event::Identified)), with
//!   [`PrintedModel`], the model part it shares with `LOADED` and `MODEL`.
//! - [`LoadedLine`]: the `LOADED` line; [`ScanLine`], [`ExciteLine`], [`ValidateLine`]: the
//!   records' announcements (`SCAN`, `EXCITE`, `VALIDATE`); [`MapLine`]: the static map
//!   (`MAP`); [`BreathLine`], [`VolumeAlarmLine`], [`ReidLine`]: the ventilation's `BREATH`,
//!   `ALARM volume` and `REID` lines.
//!
//! Errors ([`LineError`]) name the field that is missing or malformed; the caller adds the
//! file and line number.
//!
//! Numbers follow the writers' grammar ([`crate::numfmt`]): an optional `-`, at least one
//! digit, then optionally `.` and at least one digit; or `nan`, `inf`, `-inf`. Nothing else
//! (no `+`, no exponent; `ovf` is no number).

extern crate std;

use std::collections::BTreeMap;
use std::fmt;
use std::string::{String, ToString};
use std::vec::Vec;

use ridge_core::{ArxModel, Error as CoreError, InputMap, Offset, MAP_KNOTS};

use crate::units::{DUTY_FULL_SCALE, FLOW_SCALE};

/// One report line split into its keyword, its bare words and its `key=value` fields.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParsedLine {
    /// First word, e.g. `ID`, `FAULT`, `STACK`.
    pub keyword: String,
    /// Words without `=` after the keyword, in order (e.g. `A-Multistep`, `persist`, `stall`).
    pub words: Vec<String>,
    /// `key=value` fields (a repeated key keeps its last value).
    pub fields: BTreeMap<String, String>,
}

impl ParsedLine {
    /// Splits `text` (one line without its terminator) on whitespace.
    pub fn parse(text: &str) -> Self {
        let mut it = text.split_whitespace();
        let keyword = it.next().unwrap_or("").to_string();
        let mut words = Vec::new();
        let mut fields = BTreeMap::new();
        for w in it {
            match w.split_once('=') {
                Some((k, v)) => {
                    fields.insert(k.to_string(), v.to_string());
                }
                None => words.push(w.to_string()),
            }
        }
        Self {
            keyword,
            words,
            fields,
        }
    }

    /// Raw text of field `key`.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.fields.get(key).map(String::as_str)
    }

    /// Field `key` as a number ([`number`]), of its part before any `<`, `/` or `%`
    /// (`fit=42.1<70.0` → 42.1, `attempt=1/3` → 1).
    pub fn num(&self, key: &str) -> Option<f64> {
        number(head(self.get(key)?))
    }

    /// Field `key` as an integer (of its part before any `<`, `/` or `%`).
    pub fn int(&self, key: &str) -> Option<i64> {
        integer(head(self.get(key)?))
    }

    /// Field `key` as a comma-separated list of numbers; an empty field or `-` is the empty
    /// list, any malformed entry makes it `None`.
    pub fn list(&self, key: &str) -> Option<Vec<f64>> {
        let v = self.get(key)?;
        if v.is_empty() || v == "-" {
            return Some(Vec::new());
        }
        v.split(',').map(number).collect()
    }

    /// Field `key` of the form `a/b` as a pair of integers (`eval=14/252`, `attempt=1/3`).
    pub fn ratio(&self, key: &str) -> Option<(i64, i64)> {
        let (a, b) = self.get(key)?.split_once('/')?;
        Some((integer(a)?, integer(b)?))
    }

    /// Whether the line has the bare word `w`.
    pub fn has_word(&self, w: &str) -> bool {
        self.words.iter().any(|x| x == w)
    }

    /// `Ok` when the keyword is `keyword`.
    fn expect(&self, keyword: &'static str) -> Result<(), LineError> {
        if self.keyword == keyword {
            Ok(())
        } else {
            Err(LineError::Keyword { expected: keyword })
        }
    }

    /// Field `key` as a `T` read from an integer, or the error naming it.
    fn whole<T: TryFrom<i64>>(&self, key: &'static str) -> Result<T, LineError> {
        self.get(key)
            .and_then(integer)
            .and_then(|v| T::try_from(v).ok())
            .ok_or(LineError::Field {
                key,
                expected: "whole number",
            })
    }

    /// Field `key` as a finite number, or the error naming it.
    fn finite(&self, key: &'static str) -> Result<f64, LineError> {
        self.get(key)
            .and_then(number)
            .filter(|v| v.is_finite())
            .ok_or(LineError::Field {
                key,
                expected: "number",
            })
    }

    /// The first bare word (a record's name), or the error.
    fn record(&self) -> Result<String, LineError> {
        self.words.first().cloned().ok_or(LineError::NoRecord)
    }
}

/// The part of a field before any `<`, `/` or `%`.
fn head(v: &str) -> &str {
    v.split(['<', '/', '%']).next().unwrap_or(v)
}

/// Reads a number as the firmware prints it ([`crate::numfmt`]): `-?D+(.D+)?`, `nan`, `inf` or
/// `-inf`; `None` for anything else (`+1`, `1e3`, `.5`, `5.`, `ovf`, an empty string).
///
/// ```
/// use ridge_pump_firmware::lines::number;
/// assert_eq!(number("-19.058"), Some(-19.058));
/// assert_eq!(number("1e3"), None);
/// assert!(number("nan").is_some_and(f64::is_nan));
/// ```
pub fn number(s: &str) -> Option<f64> {
    match s {
        "nan" => return Some(f64::NAN),
        "inf" => return Some(f64::INFINITY),
        "-inf" => return Some(f64::NEG_INFINITY),
        _ => {}
    }
    let digits = s.strip_prefix('-').unwrap_or(s);
    let (int, frac) = match digits.split_once('.') {
        Some((i, f)) => (i, Some(f)),
        None => (digits, None),
    };
    let all_digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
    if !all_digits(int) || frac.is_some_and(|f| !all_digits(f)) {
        return None;
    }
    s.parse().ok()
}

/// Reads an integer as the firmware prints it: `-?D+`.
fn integer(s: &str) -> Option<i64> {
    let digits = s.strip_prefix('-').unwrap_or(s);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// Why a line is not the line asked for. The caller names the file and line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LineError {
    /// The line has another keyword.
    Keyword {
        /// The keyword asked for.
        expected: &'static str,
    },
    /// A field is missing or not of its kind.
    Field {
        /// The field's key.
        key: &'static str,
        /// What it must hold: `whole number`, `number`, `list of numbers`, `0 or 1`, ….
        expected: &'static str,
    },
    /// An `EXCITE` or `VALIDATE` line without the record's name.
    NoRecord,
    /// A coefficient list does not have as many entries as its order says.
    Length {
        /// The list's key (`theta`, `phi`).
        key: &'static str,
        /// Entries its order says.
        expected: usize,
        /// Entries it has.
        found: usize,
    },
}

impl fmt::Display for LineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LineError::Keyword { expected } => write!(f, "the keyword is not {expected}"),
            LineError::NoRecord => f.write_str("no record name"),
            LineError::Field { key, expected } => write!(f, "no {expected} {key}="),
            LineError::Length {
                key,
                expected,
                found,
            } => write!(f, "{key}= has {found} values, its order says {expected}"),
        }
    }
}

impl std::error::Error for LineError {}

/// A model as the report lines print it (`p=.. q=.. d=.. off=.. theta=.. phi=.. c=..`, in
/// `ID`, `LOADED` and `MODEL`): physical units, flow in slm, duty as a fraction 0..1;
/// coefficients with 6 decimals.
#[derive(Clone, Debug, PartialEq)]
pub struct PrintedModel {
    /// Output order: θ has `p` entries.
    pub p: u8,
    /// Input order: φ has `q` entries.
    pub q: u8,
    /// Input delay, samples.
    pub d: u8,
    /// [`Offset::Intercept`] when the line says `off=1`, [`Offset::None`] for `off=0`.
    pub offset: Offset,
    /// Output coefficients θ_1..θ_p.
    pub theta: Vec<f64>,
    /// Input coefficients φ_0..φ_{q−1}, slm per unit duty.
    pub phi: Vec<f64>,
    /// Intercept, slm.
    pub c: f64,
}

impl PrintedModel {
    /// The model fields of `line` (any keyword). Every field is required; the coefficients
    /// must be finite and as many as the orders say.
    pub fn from_line(line: &ParsedLine) -> Result<Self, LineError> {
        let list = |key: &'static str, order: u8| -> Result<Vec<f64>, LineError> {
            let v = line
                .list(key)
                .filter(|v| v.iter().all(|x| x.is_finite()))
                .ok_or(LineError::Field {
                    key,
                    expected: "list of numbers",
                })?;
            if v.len() == usize::from(order) {
                Ok(v)
            } else {
                Err(LineError::Length {
                    key,
                    expected: usize::from(order),
                    found: v.len(),
                })
            }
        };
        let p = line.whole("p")?;
        let q = line.whole("q")?;
        let offset = match line.get("off") {
            Some("0") => Offset::None,
            Some("1") => Offset::Intercept,
            _ => {
                return Err(LineError::Field {
                    key: "off",
                    expected: "0 or 1",
                })
            }
        };
        Ok(Self {
            p,
            q,
            d: line.whole("d")?,
            offset,
            theta: list("theta", p)?,
            phi: list("phi", q)?,
            c: line.finite("c")?,
        })
    }

    /// As a ridge-core model (ridge-core refuses what it cannot hold, e.g. orders above its
    /// limits).
    pub fn arx(&self) -> Result<ArxModel<f64>, CoreError> {
        ArxModel::new(&self.theta, &self.phi, self.d, self.offset, self.c)
    }
}

/// The `ID` line: the model the structure search chose and its figures
/// ([`Event::Identified`](crate::event::Event::Identified)), e.g.
/// `ID p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000 c=-0.125000 score=-1234.5 eval=14/252
/// skip=0 iters=200`.
#[derive(Clone, Debug, PartialEq)]
pub struct IdLine {
    /// The model.
    pub model: PrintedModel,
    /// Criterion value of the chosen structure (1 decimal; `nan`/`inf` as printed).
    pub score: f64,
    /// Candidates the estimator ran on (`eval=<evaluated>/<candidates>`).
    pub evaluated: u16,
    /// Candidates in the grid.
    pub candidates: u16,
    /// Candidates that could not be fitted (`skip=`).
    pub skipped: u16,
    /// Estimator iterations on the chosen structure (`iters=`).
    pub iterations: u32,
}

impl IdLine {
    /// Parses an `ID` line (every field required).
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("ID")?;
        let (evaluated, candidates) = line
            .ratio("eval")
            .and_then(|(a, b)| Some((u16::try_from(a).ok()?, u16::try_from(b).ok()?)))
            .ok_or(LineError::Field {
                key: "eval",
                expected: "ratio",
            })?;
        Ok(Self {
            model: PrintedModel::from_line(&line)?,
            score: line.num("score").ok_or(LineError::Field {
                key: "score",
                expected: "number",
            })?,
            evaluated,
            candidates,
            skipped: line.whole("skip")?,
            iterations: line.whole("iters")?,
        })
    }
}

/// The `LOADED` line: a stored model taken at power-up and its stored validation fit
/// ([`Event::Loaded`](crate::event::Event::Loaded)), e.g. `LOADED p=1 … c=-0.125000
/// fit=87.3`.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedLine {
    /// The model.
    pub model: PrintedModel,
    /// Its validation fit, percent (1 decimal).
    pub fit: f64,
}

impl LoadedLine {
    /// Parses a `LOADED` line.
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("LOADED")?;
        Ok(Self {
            model: PrintedModel::from_line(&line)?,
            fit: line.finite("fit")?,
        })
    }
}

/// The `SCAN` line: an identification attempt starts with the scan
/// ([`Event::Scan`](crate::event::Event::Scan)), e.g.
/// `SCAN n=520 lag=20 u0=30.00 y0=19.058 attempt=1/3` (operating point read back exactly, as
/// on [`ExciteLine`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ScanLine {
    /// Ticks of the scan (`n=`).
    pub samples: u32,
    /// The lag its readings are credited with, ticks (`lag=`).
    pub lag: u8,
    /// Operating point: base duty, 1/10 000 of full scale.
    pub u0: u16,
    /// Operating point: settled flow, counts of 1/120 slm.
    pub y0: i16,
    /// Attempt and attempts configured (`attempt=1/3`).
    pub attempt: (u8, u8),
}

impl ScanLine {
    /// Parses a `SCAN` line (every field required).
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("SCAN")?;
        let (u0, y0) = operating_point(&line)?;
        let attempt = line
            .ratio("attempt")
            .and_then(|(a, b)| Some((u8::try_from(a).ok()?, u8::try_from(b).ok()?)))
            .ok_or(LineError::Field {
                key: "attempt",
                expected: "ratio",
            })?;
        Ok(Self {
            samples: line.whole("n")?,
            lag: line.whole("lag")?,
            u0,
            y0,
            attempt,
        })
    }
}

/// The `MAP` line: the static map from duty to flow
/// ([`Event::Map`](crate::event::Event::Map)), e.g. `MAP first=15.00 step=5.33
/// flow=0.125,6.608,…` (16 flows), read back exactly: the duties in percent with 2 decimals
/// are whole 1/10 000, the flows in slm with 3 decimals whole counts of 1/120 slm.
#[derive(Clone, Debug, PartialEq)]
pub struct MapLine {
    /// The map.
    pub map: InputMap,
}

impl MapLine {
    /// Parses a `MAP` line; the map must be one (16 strictly increasing flows, a positive
    /// spacing).
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("MAP")?;
        let duty = |key: &'static str| -> Result<u16, LineError> {
            in_range((line.finite(key)? * 100.0).round(), key)
        };
        let flows = line
            .list("flow")
            .filter(|v| v.iter().all(|x| x.is_finite()))
            .ok_or(LineError::Field {
                key: "flow",
                expected: "list of numbers",
            })?;
        if flows.len() != MAP_KNOTS {
            return Err(LineError::Length {
                key: "flow",
                expected: MAP_KNOTS,
                found: flows.len(),
            });
        }
        let mut knots = [0i16; MAP_KNOTS];
        for (k, f) in knots.iter_mut().zip(&flows) {
            *k = in_range((f * f64::from(FLOW_SCALE)).round(), "flow")?;
        }
        let map =
            InputMap::new(duty("first")?, duty("step")?, knots).map_err(|_| LineError::Field {
                key: "flow",
                expected: "increasing flows",
            })?;
        Ok(Self { map })
    }
}

/// The operating point `u0=` (percent, 2 decimals) and `y0=` (slm, 3 decimals) of a line, in
/// the firmware's units: 1/10 000 duty and counts of 1/120 slm (nearest).
fn operating_point(line: &ParsedLine) -> Result<(u16, i16), LineError> {
    let percent = line.finite("u0")?;
    let slm = line.finite("y0")?;
    // Percent · 100 = 1/10 000 of full scale.
    const _: () = assert!(DUTY_FULL_SCALE == 10_000);
    let u0 = (percent * 100.0).round();
    let y0 = (slm * f64::from(FLOW_SCALE)).round();
    Ok((in_range(u0, "u0")?, in_range(y0, "y0")?))
}

/// The `EXCITE` line: the estimation record starts
/// ([`Event::Excite`](crate::event::Event::Excite)), e.g.
/// `EXCITE flow-steps n=700 u0=30.00 y0=19.058 attempt=1/3`. The operating point is read
/// back in the firmware's units, exactly: the line prints `u0` (1/10 000 duty) in percent with
/// 2 decimals and `y0` (whole counts of 1/120 slm) in slm with 3.
#[derive(Clone, Debug, PartialEq)]
pub struct ExciteLine {
    /// The record's name: `flow-steps`
    /// ([`RECORD_NAME`](crate::event::RECORD_NAME)).
    pub record: String,
    /// Samples announced (`n=`).
    pub samples: u32,
    /// Operating point: base duty, 1/10 000 of full scale (nearest to `u0=`).
    pub u0: u16,
    /// Operating point: settled flow, counts of 1/120 slm (nearest to `y0=`).
    pub y0: i16,
    /// Attempt and attempts configured (`attempt=1/3`), if the line has them.
    pub attempt: Option<(u8, u8)>,
}

impl ExciteLine {
    /// Parses an `EXCITE` line (`record`, `n`, `u0`, `y0` required, `attempt` optional).
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("EXCITE")?;
        let (u0, y0) = operating_point(&line)?;
        let attempt = line
            .ratio("attempt")
            .and_then(|(a, b)| Some((u8::try_from(a).ok()?, u8::try_from(b).ok()?)));
        Ok(Self {
            record: line.record()?,
            samples: line.whole("n")?,
            u0,
            y0,
            attempt,
        })
    }

    /// The operating point in physical units: duty as a fraction 0..1, flow in slm.
    pub fn operating_point(&self) -> (f64, f64) {
        (
            f64::from(self.u0) / f64::from(DUTY_FULL_SCALE),
            f64::from(self.y0) / f64::from(FLOW_SCALE),
        )
    }
}

/// A rounded value as an integer type, or the error naming its field.
fn in_range<T: TryFrom<i64>>(v: f64, key: &'static str) -> Result<T, LineError> {
    // `v` is a whole number; `as` saturates, and the range check refuses what does not fit.
    T::try_from(v as i64).map_err(|_| LineError::Field {
        key,
        expected: "number in range",
    })
}

/// The `VALIDATE` line: the validation record starts
/// ([`Event::Validate`](crate::event::Event::Validate)), e.g. `VALIDATE flow-steps n=300`.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidateLine {
    /// The record's name.
    pub record: String,
    /// Samples announced (`n=`).
    pub samples: u32,
}

impl ValidateLine {
    /// Parses a `VALIDATE` line.
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("VALIDATE")?;
        Ok(Self {
            record: line.record()?,
            samples: line.whole("n")?,
        })
    }
}

/// The `BREATH` line: one volume-controlled breath
/// ([`Event::Breath`](crate::event::Event::Breath)), e.g. `BREATH n=3 vt=500.0 peep=5.0
/// vd=497.2 cmd=512.3 peak=31.250 rms=1.234`.
#[derive(Clone, Debug, PartialEq)]
pub struct BreathLine {
    /// The breath's number, from 1 (`n=`).
    pub number: u32,
    /// Set tidal volume, mL (`vt=`, 1 decimal).
    pub tidal: f64,
    /// Set PEEP, cmH₂O (`peep=`, 1 decimal).
    pub peep: f64,
    /// Delivered volume as the firmware measured it, mL (`vd=`, 1 decimal).
    pub delivered: f64,
    /// The volume the breath was programmed for, mL (`cmd=`, 1 decimal).
    pub command: f64,
    /// Largest reading of the inspiration, slm (`peak=`, 3 decimals).
    pub peak: f64,
    /// RMS of setpoint − reading over the breath, slm (`rms=`, 3 decimals).
    pub rms: f64,
}

impl BreathLine {
    /// Parses a `BREATH` line (every field required, finite).
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("BREATH")?;
        Ok(Self {
            number: line.whole("n")?,
            tidal: line.finite("vt")?,
            peep: line.finite("peep")?,
            delivered: line.finite("vd")?,
            command: line.finite("cmd")?,
            peak: line.finite("peak")?,
            rms: line.finite("rms")?,
        })
    }
}

/// The `ALARM volume` line ([`Event::VolumeAlarm`](crate::event::Event::VolumeAlarm)):
/// `ALARM volume vd=612.5 vt=500.0` (raised, with the last breath's delivered and the set
/// volume, mL) or `ALARM volume clear`.
#[derive(Clone, Debug, PartialEq)]
pub enum VolumeAlarmLine {
    /// Raised.
    On {
        /// The last breath's delivered volume, mL.
        delivered: f64,
        /// The set volume, mL.
        tidal: f64,
    },
    /// Cleared.
    Clear,
}

impl VolumeAlarmLine {
    /// Parses an `ALARM volume` line; another `ALARM` (the tracking's) is
    /// [`LineError::Keyword`].
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("ALARM")?;
        if line.words.first().map(String::as_str) != Some("volume") {
            return Err(LineError::Keyword {
                expected: "ALARM volume",
            });
        }
        if line.has_word("clear") {
            return Ok(Self::Clear);
        }
        Ok(Self::On {
            delivered: line.finite("vd")?,
            tidal: line.finite("vt")?,
        })
    }
}

/// The `REID` line: one re-estimate of run mode's re-identification
/// ([`Event::Reid`](crate::event::Event::Reid)), e.g. `REID breath=12 verdict=kept gain=1.035
/// fit=92.3/90.1 v-rms=22.150`. The figures a verdict has none of print `nan` and parse as NaN.
#[derive(Clone, Debug, PartialEq)]
pub struct ReidLine {
    /// The breath at whose start the snapshot was taken (`breath=`).
    pub breath: u32,
    /// The verdict's name (`verdict=`: `accepted`, `kept`, `not-excited`, `model`, `fit`,
    /// `numeric`, `design`).
    pub verdict: String,
    /// The estimate's static gain, slm/slm (`gain=`, 3 decimals).
    pub gain: f64,
    /// The estimate's held-out free-run fit, percent (`fit=` before the `/`, 1 decimal).
    pub fit: f64,
    /// The running model's held-out free-run fit, percent (`fit=` after the `/`).
    pub running: f64,
    /// The window's input RMS about its mean, slm (`v-rms=`, 3 decimals).
    pub v_rms: f64,
    /// Why the controller design was refused (`why=`, only with `verdict=design`): one of
    /// [`ReidLine::WHY`].
    pub why: Option<String>,
    /// The refused design's modulus margin (`margin=`, with `why=margin`).
    pub margin: Option<f64>,
    /// Designs made before the refusal (`tries=`, with a design's `why=`).
    pub tries: Option<u32>,
}

impl ReidLine {
    /// The reasons a `verdict=design` line gives (`why=`): the model check's (`nonfinite`,
    /// `unstable`, `gain`) and the design's (`spec`, `singular`, `slow-poles`, `poles`,
    /// `margin`), the words of the `FAULT control` line.
    pub const WHY: [&'static str; 8] = [
        "nonfinite",
        "unstable",
        "gain",
        "spec",
        "singular",
        "slow-poles",
        "poles",
        "margin",
    ];

    /// The verdicts the firmware prints.
    pub const VERDICTS: [&'static str; 7] = [
        "accepted",
        "kept",
        "not-excited",
        "model",
        "fit",
        "numeric",
        "design",
    ];

    /// Parses a `REID` line (every field required; the numbers may be `nan`).
    pub fn parse(text: &str) -> Result<Self, LineError> {
        let line = ParsedLine::parse(text);
        line.expect("REID")?;
        let num = |key: &'static str, v: Option<&str>| {
            v.and_then(number).ok_or(LineError::Field {
                key,
                expected: "number",
            })
        };
        let verdict = line
            .get("verdict")
            .filter(|v| Self::VERDICTS.contains(v))
            .ok_or(LineError::Field {
                key: "verdict",
                expected: "verdict",
            })?;
        let (fit, running) = line.get("fit").and_then(|f| f.split_once('/')).unzip();
        // `why=` with `verdict=design` only, and then required.
        let why = match (verdict, line.get("why")) {
            ("design", Some(w)) if Self::WHY.contains(&w) => Some(w.to_string()),
            (_, None) if verdict != "design" => None,
            _ => {
                return Err(LineError::Field {
                    key: "why",
                    expected: "a design refusal's reason, with verdict=design only",
                })
            }
        };
        let margin = match why.as_deref() {
            Some("margin") => Some(line.finite("margin")?),
            _ => None,
        };
        let tries = match why.as_deref() {
            Some("nonfinite" | "unstable" | "gain") | None => None,
            Some(_) => Some(line.whole("tries")?),
        };
        Ok(Self {
            breath: line.whole("breath")?,
            verdict: verdict.to_string(),
            gain: num("gain", line.get("gain"))?,
            fit: num("fit", fit)?,
            running: num("fit", running)?,
            v_rms: num("v-rms", line.get("v-rms"))?,
            why,
            margin,
            tries,
        })
    }
}
