//! The console's answers and the CSV log, as [`ufmt`] lines (the commands themselves are in
//! [`crate::command`], their execution in [`crate::app`]).
//!
//! | line | example |
//! |---|---|
//! | [`Status`] | `STATUS state=run duty=35.20 flow=40.125 sp=40.000 log=1 fault=none` |
//! | [`ModelLine`] | `MODEL p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000 c=-0.125000 fit=87.3` |
//! | [`RstLine`] | `RST r=1.000000,-1.000000`, then `RST s=0.120000,-0.080000`, `RST t=0.040000` |
//! | [`LOG_HEADER`] | `t,u,y,r,phase` |
//! | [`LogRow`] | `12.34,0.3500,40.12500,40.000,run` |
//!
//! # The log
//! One [`LogRow`] per tick while the log is on: `t` the time of the reading in s since the
//! board started (two decimals, one tick = 0.01 s), `u` the duty as a fraction 0..1 applied
//! during the interval that ended with the reading, `y` that reading in slm (the SFM3300's
//! counts / 120 with 5 decimals; after a failed read the held reading, as the statistics and the
//! controller use it), `r` the setpoint of that interval in run mode (empty otherwise, slm, 3
//! decimals), `phase` the state the reading was used in ([`State::name`]). The rows with
//! `phase = excite` are exactly the samples of the estimation record; the `EXCITE` line before
//! them gives its operating point. A row that does not fit in the transmit queue is dropped and
//! counted (`LOG dropped=<n>`), never sent in part.

use ufmt::{uDisplay, uWrite, Formatter};

use crate::event::{write_list, write_model, FaultReason, COEF_DIGITS};
use crate::numfmt::{Decimal, Fixed, Milli};
use crate::selfid::State;
use crate::sfm3300::counts_to_millislm;
use crate::units::FLOW_SCALE;
use ridge_core::control::Rst;
use ridge_core::ArxModel;

/// The log's header line.
pub const LOG_HEADER: &str = "t,u,y,r,phase";

/// Longest [`LogRow`] in bytes with its `\n` (`t` up to 10 digits, `-250.00000`, a setpoint
/// of `-1000000.000`, `validate`): the transmit queue must have this much room for a row.
pub const LOG_ROW_MAX: usize = 48;

/// Digits of `y` in the log.
const FLOW_DIGITS: u8 = 5;

/// One tick of the log (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogRow {
    /// Ticks since the board started (10 ms each).
    pub tick: u32,
    /// Duty applied during the interval that ended with the reading, 1/10 000.
    pub duty: u16,
    /// The reading as used, counts (1/120 slm).
    pub counts: i16,
    /// Setpoint of the interval, slm (run mode).
    pub setpoint: Option<f32>,
    /// The state the reading was used in.
    pub state: State,
}

/// `counts` (1/120 slm) in units of 10⁻⁵ slm, rounded half away from zero (exact in `i32`:
/// |counts| ≤ 32 768).
pub const fn counts_to_slm_e5(counts: i16) -> i32 {
    // 10⁵ / 120 = 2500 / 3 (the factor below holds for the SFM3300's scale only).
    const _: () = assert!(FLOW_SCALE == 120);
    let scaled = counts as i32 * 2_500;
    if scaled < 0 {
        (scaled - 1) / 3
    } else {
        (scaled + 1) / 3
    }
}

impl uDisplay for LogRow {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        // `tick` as i32: 248 days before it would wrap.
        let t = Decimal::new(self.tick as i32, 2);
        let y = Decimal::new(counts_to_slm_e5(self.counts), FLOW_DIGITS);
        ufmt::uwrite!(f, "{},{},{},", t, Decimal::new(i32::from(self.duty), 4), y)?;
        if let Some(r) = self.setpoint {
            uDisplay::fmt(&Fixed::new(r, 3), f)?;
        }
        ufmt::uwrite!(f, ",{}", self.state.name())
    }
}

/// The `STATUS` answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Status {
    /// The state.
    pub state: State,
    /// The duty applied now, 1/10 000.
    pub duty: u16,
    /// The last reading, counts.
    pub counts: i16,
    /// The setpoint in run mode, slm.
    pub setpoint: Option<f32>,
    /// Whether the log is on.
    pub log: bool,
    /// The latched fault.
    pub fault: Option<FaultReason>,
}

impl uDisplay for Status {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        ufmt::uwrite!(
            f,
            "STATUS state={} duty={} flow={} sp=",
            self.state.name(),
            Decimal::new(i32::from(self.duty), 2),
            Milli(counts_to_millislm(self.counts))
        )?;
        match self.setpoint {
            Some(r) => uDisplay::fmt(&Fixed::new(r, 3), f)?,
            None => f.write_str("none")?,
        }
        // A str, not `u8::from(log)`: ufmt's u8 formatting costs the ATmega2560 232 B.
        f.write_str(if self.log {
            " log=1 fault="
        } else {
            " log=0 fault="
        })?;
        match &self.fault {
            Some(reason) => uDisplay::fmt(reason, f),
            None => f.write_str("none"),
        }
    }
}

/// The `MODEL` answer: the model in use and its validation fit (percent), or `MODEL none`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelLine<'a> {
    /// The model and its fit, if there is one.
    pub model: Option<(&'a ArxModel<f32>, f32)>,
}

impl uDisplay for ModelLine<'_> {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        f.write_str("MODEL ")?;
        match self.model {
            Some((m, fit)) => {
                write_model(f, m)?;
                ufmt::uwrite!(f, " fit={}", Fixed::new(fit, 1))
            }
            None => f.write_str("none"),
        }
    }
}

/// One of the controller's polynomials in `R(q⁻¹) u = T(q⁻¹) r − S(q⁻¹) y`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Poly {
    /// `R`, acting on the duty.
    R,
    /// `S`, acting on the flow.
    S,
    /// `T`, acting on the setpoint.
    T,
}

impl Poly {
    /// The polynomial printed after this one, `None` after `T`.
    pub fn next(self) -> Option<Poly> {
        match self {
            Poly::R => Some(Poly::S),
            Poly::S => Some(Poly::T),
            Poly::T => None,
        }
    }
}

/// One polynomial of the controller in use, coefficients from `q⁰` (`RST r=…`, `RST s=…`,
/// `RST t=…`: after `MODEL` in run mode, one line per pass). One line holds at most
/// [`R_LEN`](ridge_core::control::R_LEN) = 13 coefficients, so each stays shorter than the
/// console's answer room (≤ 175 bytes with 12-character numbers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RstLine<'a>(pub &'a Rst<f32>, pub Poly);

impl uDisplay for RstLine<'_> {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        // One arm each: a table of the names would take static RAM on the ATmega2560.
        let coefficients = match self.1 {
            Poly::R => {
                f.write_str("RST r=")?;
                self.0.r()
            }
            Poly::S => {
                f.write_str("RST s=")?;
                self.0.s()
            }
            Poly::T => {
                f.write_str("RST t=")?;
                return write_list(f, self.0.ao(), self.0.t0(), COEF_DIGITS);
            }
        };
        write_list(f, coefficients, 1.0, COEF_DIGITS)
    }
}
