//! The operator's console commands: one ASCII line each, parsed without allocation, floats or
//! `core::fmt` (a float parser would cost the ATmega2560 several KB of flash).
//!
//! | line | effect (answer) |
//! |---|---|
//! | `STATUS` | one `STATUS ...` line (state, duty, flow, setpoint, fault, log) |
//! | `STOP` | pump off in the same tick, latched until `START` (`OK stop`) |
//! | `START` | leaves the stop (or a latched fault) and starts as after a reset (`OK start`) |
//! | `SET flow=<slm>` | run mode tracks a constant flow (`OK set`) |
//! | `PROFILE <square\|ramp> [peak=<slm>] [bias=<slm>] [rate=<1/min>] [ie=<x>] [rise=<s>]` | run mode tracks breaths; a key left out keeps the demo breath's value (`OK profile`) |
//! | `VENT vt=<mL> rate=<1/min> [ti=<s>\|ie=<x>] [wave=square\|ramp] [peep=<cmH₂O>] [bias=<slm>] [rise=<s>] [trim=on\|off]` | run mode ventilates: volume-controlled breaths, the exhalation valve driven ([`crate::ventilation`]; `OK vent`) |
//! | `REID` | identifies again now (`OK reid`) |
//! | `MODEL` | the model and the controller in use (`MODEL ...`, `RST ...`) |
//! | `FORGET` | erases the stored model; the one in use stays until the next reset (`OK forget`) |
//! | `LOG on` / `LOG off` | starts / stops the CSV log (`OK log`, then the header) |
//!
//! Keywords and keys are case-insensitive; fields are separated by spaces. Numbers are decimals
//! with an optional sign, at most [`MAX_INTEGER_DIGITS`] digits before the point and at most
//! [`MAX_DECIMALS`] after it (`25`, `-0.5`, `12.125`). A line that does not parse answers
//! `ERR <why>` (see [`CommandError::name`]) and changes nothing; so does a command the state
//! machine refuses (a value out of range, `REID` in the fault state).

use crate::setpoint::Shape;

/// The byte a receiver puts in its queue where it lost bytes (its queue was full, or a
/// framing or overrun error): the line it falls in answers [`CommandError::Overrun`]. A NUL
/// is no part of a command.
pub const LOST: u8 = 0;

/// Longest accepted line, bytes without the terminator: the longest valid command, `VENT`
/// with every key but one of `ti`/`ie`, each number at its largest with 3 decimals, is 95
/// bytes (`VENT vt=2000.000 rate=60.000 ie=10.000 wave=square peep=30.000 bias=250.000
/// rise=0.050 trim=off`; with `ti` one byte shorter).
pub const MAX_LINE: usize = 100;

/// Most fractional digits a number may have.
pub const MAX_DECIMALS: u8 = 3;

/// Most digits a number may have before the point (so |value| < 10⁶ units).
pub const MAX_INTEGER_DIGITS: u8 = 6;

/// A parsed number: thousandths of the unit (`12.125` → `12_125`), |value| < 10⁶ units.
pub type Milli = i32;

/// A breath profile as typed: every value in thousandths of its unit, `None` where the key was
/// left out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProfileArgs {
    /// Inspiratory shape.
    pub shape: Shape,
    /// Peak inspiratory flow, milli-slm.
    pub peak: Option<Milli>,
    /// Bias (expiratory) flow, milli-slm.
    pub bias: Option<Milli>,
    /// Breaths per minute, thousandths.
    pub rate: Option<Milli>,
    /// Expiratory part of the I:E ratio `1 : ie`, thousandths.
    pub ie: Option<Milli>,
    /// Rise time, ms.
    pub rise: Option<Milli>,
}

/// A `VENT` line as typed: numbers in thousandths of their unit, `None` where the key was left
/// out (see [`crate::ventilation::settings`] for the defaults and ranges).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VentArgs {
    /// Tidal volume, thousandths of a mL (required).
    pub vt: Milli,
    /// Breaths per minute, thousandths (required).
    pub rate: Milli,
    /// Inspiratory time, ms (at most one of `ti` and `ie`).
    pub ti: Option<Milli>,
    /// Expiratory part of the I:E ratio `1 : ie`, thousandths.
    pub ie: Option<Milli>,
    /// Inspiratory flow shape.
    pub wave: Option<Shape>,
    /// PEEP, thousandths of a cmH₂O.
    pub peep: Option<Milli>,
    /// Bias (expiratory) flow, milli-slm.
    pub bias: Option<Milli>,
    /// Rise time, ms.
    pub rise: Option<Milli>,
    /// Per-breath volume trim on (`true`) or off.
    pub trim: Option<bool>,
}

impl VentArgs {
    /// The two required settings, `vt` (thousandths of a mL) and `rate` (thousandths of a
    /// breath per minute), every optional one left out (its default applies).
    pub const fn new(vt: Milli, rate: Milli) -> Self {
        VentArgs {
            vt,
            rate,
            ti: None,
            ie: None,
            wave: None,
            peep: None,
            bias: None,
            rise: None,
            trim: None,
        }
    }
}

/// A console command (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `STATUS`.
    Status,
    /// `STOP`.
    Stop,
    /// `START`.
    Start,
    /// `SET flow=<slm>`: the flow in milli-slm.
    Set(Milli),
    /// `PROFILE ...`.
    Profile(ProfileArgs),
    /// `VENT ...`.
    Vent(VentArgs),
    /// `REID`.
    Reid,
    /// `MODEL`.
    Model,
    /// `FORGET`.
    Forget,
    /// `LOG on` (`true`) / `LOG off` (`false`).
    Log(bool),
}

/// Why a line is not a command. Flat, like the answer it produces: `ERR <name>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandError {
    /// Longer than [`MAX_LINE`] bytes (the rest of the line is skipped).
    TooLong,
    /// Bytes were lost by the receiver (its queue was full): the line is not trusted.
    Overrun,
    /// Not one of the keywords.
    Unknown,
    /// A required field is missing.
    Missing,
    /// A field that the command does not take, or a key given without `=`.
    BadField,
    /// A value that is not a number of the accepted form.
    BadNumber,
    /// A value the state machine refuses; the name of the setting.
    Range(&'static str),
    /// The command does not apply in the current state.
    State,
}

impl CommandError {
    /// The answer's reason: `too-long`, `overrun`, `unknown`, `missing`, `field`, `number`,
    /// `range <setting>` (printed by the caller), `state`.
    pub const fn name(self) -> &'static str {
        match self {
            CommandError::TooLong => "too-long",
            CommandError::Overrun => "overrun",
            CommandError::Unknown => "unknown",
            CommandError::Missing => "missing",
            CommandError::BadField => "field",
            CommandError::BadNumber => "number",
            CommandError::Range(_) => "range",
            CommandError::State => "state",
        }
    }
}

/// Parses one line (without its terminator; a trailing `\r` and surrounding spaces are
/// ignored). Never panics, for any bytes.
pub fn parse(line: &[u8]) -> Result<Command, CommandError> {
    if line.len() > MAX_LINE {
        return Err(CommandError::TooLong);
    }
    let mut words = line
        .split(|&b| blank(b) || b == b'\r')
        .filter(|w| !w.is_empty());
    let keyword = words.next().ok_or(CommandError::Unknown)?;
    let command = if eq(keyword, b"STATUS") {
        Command::Status
    } else if eq(keyword, b"STOP") {
        Command::Stop
    } else if eq(keyword, b"START") {
        Command::Start
    } else if eq(keyword, b"REID") {
        Command::Reid
    } else if eq(keyword, b"MODEL") {
        Command::Model
    } else if eq(keyword, b"FORGET") {
        Command::Forget
    } else if eq(keyword, b"LOG") {
        let arg = words.next().ok_or(CommandError::Missing)?;
        if eq(arg, b"ON") {
            Command::Log(true)
        } else if eq(arg, b"OFF") {
            Command::Log(false)
        } else {
            return Err(CommandError::BadField);
        }
    } else if eq(keyword, b"SET") {
        let field = words.next().ok_or(CommandError::Missing)?;
        let (key, value) = key_value(field)?;
        if !eq(key, b"FLOW") {
            return Err(CommandError::BadField);
        }
        Command::Set(number(value)?)
    } else if eq(keyword, b"PROFILE") {
        let shape = words.next().ok_or(CommandError::Missing)?;
        let shape = if eq(shape, b"SQUARE") {
            Shape::Square
        } else if eq(shape, b"RAMP") {
            Shape::Ramp
        } else {
            return Err(CommandError::BadField);
        };
        let mut args = ProfileArgs {
            shape,
            peak: None,
            bias: None,
            rate: None,
            ie: None,
            rise: None,
        };
        for field in words.by_ref() {
            let (key, value) = key_value(field)?;
            let slot = if eq(key, b"PEAK") {
                &mut args.peak
            } else if eq(key, b"BIAS") {
                &mut args.bias
            } else if eq(key, b"RATE") {
                &mut args.rate
            } else if eq(key, b"IE") {
                &mut args.ie
            } else if eq(key, b"RISE") {
                &mut args.rise
            } else {
                return Err(CommandError::BadField);
            };
            *slot = Some(number(value)?);
        }
        Command::Profile(args)
    } else if eq(keyword, b"VENT") {
        Command::Vent(vent(words.by_ref())?)
    } else {
        return Err(CommandError::Unknown);
    };
    if words.next().is_some() {
        return Err(CommandError::BadField);
    }
    Ok(command)
}

/// The fields of a `VENT` line: `vt` and `rate` required ([`CommandError::Missing`]), at most
/// one of `ti` and `ie` ([`CommandError::BadField`]), each key at most once.
fn vent<'a>(fields: impl Iterator<Item = &'a [u8]>) -> Result<VentArgs, CommandError> {
    let (mut vt, mut rate) = (None, None);
    let mut args = VentArgs::new(0, 0);
    for field in fields {
        let (key, value) = key_value(field)?;
        if eq(key, b"WAVE") {
            let shape = if eq(value, b"SQUARE") {
                Shape::Square
            } else if eq(value, b"RAMP") {
                Shape::Ramp
            } else {
                return Err(CommandError::BadField);
            };
            if args.wave.replace(shape).is_some() {
                return Err(CommandError::BadField);
            }
            continue;
        }
        if eq(key, b"TRIM") {
            let on = if eq(value, b"ON") {
                true
            } else if eq(value, b"OFF") {
                false
            } else {
                return Err(CommandError::BadField);
            };
            if args.trim.replace(on).is_some() {
                return Err(CommandError::BadField);
            }
            continue;
        }
        let slot = if eq(key, b"VT") {
            &mut vt
        } else if eq(key, b"RATE") {
            &mut rate
        } else if eq(key, b"TI") {
            &mut args.ti
        } else if eq(key, b"IE") {
            &mut args.ie
        } else if eq(key, b"PEEP") {
            &mut args.peep
        } else if eq(key, b"BIAS") {
            &mut args.bias
        } else if eq(key, b"RISE") {
            &mut args.rise
        } else {
            return Err(CommandError::BadField);
        };
        if slot.replace(number(value)?).is_some() {
            return Err(CommandError::BadField);
        }
    }
    if args.ti.is_some() && args.ie.is_some() {
        return Err(CommandError::BadField);
    }
    args.vt = vt.ok_or(CommandError::Missing)?;
    args.rate = rate.ok_or(CommandError::Missing)?;
    Ok(args)
}

/// A blank inside a line: what separates words, besides a `\r` that [`Line`] takes as a line
/// end.
fn blank(b: u8) -> bool {
    b == b' ' || b == b'\t'
}

/// `word` equals the upper-case `keyword`, ignoring ASCII case.
fn eq(word: &[u8], keyword: &[u8]) -> bool {
    word.eq_ignore_ascii_case(keyword)
}

/// Splits `key=value` (both non-empty).
fn key_value(field: &[u8]) -> Result<(&[u8], &[u8]), CommandError> {
    let at = field
        .iter()
        .position(|&b| b == b'=')
        .ok_or(CommandError::BadField)?;
    let (key, rest) = field.split_at(at);
    let value = rest.get(1..).unwrap_or_default();
    if key.is_empty() || value.is_empty() {
        return Err(CommandError::BadField);
    }
    Ok((key, value))
}

/// `[-|+]digits[.digits]` with at least one digit, at most [`MAX_INTEGER_DIGITS`] before the
/// point and [`MAX_DECIMALS`] after it, as thousandths. The digit limits keep every value
/// below 10⁹ < 2³¹ without overflow checks (i32 products are library calls on the ATmega2560).
fn number(text: &[u8]) -> Result<Milli, CommandError> {
    let (negative, digits) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        Some((b'+', rest)) => (false, rest),
        _ => (false, text),
    };
    let mut value: Milli = 0;
    let (mut integer, mut decimals, mut point) = (0u8, 0u8, false);
    for &b in digits {
        if b == b'.' && !point {
            point = true;
            continue;
        }
        let digit = b.wrapping_sub(b'0');
        if digit > 9 {
            return Err(CommandError::BadNumber);
        }
        let count = if point { &mut decimals } else { &mut integer };
        *count += 1;
        if integer > MAX_INTEGER_DIGITS || decimals > MAX_DECIMALS {
            return Err(CommandError::BadNumber);
        }
        value = value * 10 + Milli::from(digit);
    }
    if integer + decimals == 0 {
        return Err(CommandError::BadNumber);
    }
    for _ in decimals..MAX_DECIMALS {
        value *= 10;
    }
    Ok(if negative { -value } else { value })
}

/// Assembles received bytes into lines: [`push`](Line::push) one byte at a time; a `\n` or
/// `\r` completes a line. Bytes beyond [`MAX_LINE`] are dropped and the line answers
/// [`CommandError::TooLong`]; [`overrun`](Line::overrun) marks the line in progress as
/// damaged.
#[derive(Debug, Clone)]
pub struct Line {
    buf: [u8; MAX_LINE],
    len: u8,
    /// What the line in progress will answer instead of being parsed.
    damaged: Option<CommandError>,
    /// A line end completed the line, held until [`Line::take`].
    complete: bool,
}

impl Default for Line {
    fn default() -> Self {
        Self::new()
    }
}

impl Line {
    /// An empty line.
    pub const fn new() -> Self {
        Line {
            buf: [0; MAX_LINE],
            len: 0,
            damaged: None,
            complete: false,
        }
    }

    /// Adds `byte`; at a line end returns the line's command (or why it is none) and starts a
    /// new line. Empty lines return `None` (a `\r\n` ends one line, not two). The same as
    /// [`feed`](Line::feed) then [`take`](Line::take).
    pub fn push(&mut self, byte: u8) -> Option<Result<Command, CommandError>> {
        if self.feed(byte) {
            return Some(self.take());
        }
        None
    }

    /// Adds `byte` without parsing: `true` when it completes a line that is not blank, which
    /// is then held until [`take`](Line::take) (bytes fed meanwhile start no new line: they
    /// are dropped and the held line answers [`CommandError::TooLong`]). A few dozen cycles on
    /// the ATmega2560, so that the main loop can collect bytes while it waits for a tick.
    pub fn feed(&mut self, byte: u8) -> bool {
        if self.complete {
            self.damaged.get_or_insert(CommandError::TooLong);
            return false;
        }
        if byte == LOST {
            self.damaged = Some(CommandError::Overrun);
            return false;
        }
        if byte == b'\n' || byte == b'\r' {
            let blank = self.text().iter().copied().all(blank);
            if blank && self.damaged.is_none() {
                self.len = 0;
                return false;
            }
            self.complete = true;
            return true;
        }
        match self.buf.get_mut(usize::from(self.len)) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
            }
            None => {
                self.damaged.get_or_insert(CommandError::TooLong);
            }
        }
        false
    }

    /// Whether a complete line is held (see [`feed`](Line::feed)).
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// Whether a complete line is held and is `STOP` (the one command [`parse`] reads from
    /// it, without parsing: case-insensitive, blanks around it), so that it can act before the
    /// line is parsed. `false` for a line in progress or a damaged line.
    pub fn is_stop(&self) -> bool {
        let mut text = self.text();
        while let [first, rest @ ..] = text {
            if !blank(*first) {
                break;
            }
            text = rest;
        }
        while let [rest @ .., last] = text {
            if !blank(*last) {
                break;
            }
            text = rest;
        }
        self.complete && self.damaged.is_none() && eq(text, b"STOP")
    }

    /// The held line's command (or why it is none), and starts a new line.
    pub fn take(&mut self) -> Result<Command, CommandError> {
        let command = match self.damaged.take() {
            Some(e) => Err(e),
            None => parse(self.text()),
        };
        self.len = 0;
        self.complete = false;
        command
    }

    /// The bytes of the line so far.
    fn text(&self) -> &[u8] {
        self.buf.get(..usize::from(self.len)).unwrap_or_default()
    }

    /// The receiver lost bytes: the line in progress answers [`CommandError::Overrun`].
    pub fn overrun(&mut self) {
        self.damaged = Some(CommandError::Overrun);
    }
}
