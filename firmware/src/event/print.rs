//! How each [`Event`] prints: its report line (see the [module docs](super) for every kind),
//! with [`ufmt`] and [`crate::numfmt`], into any [`uWrite`] or a fixed [`Line`] buffer.

use ridge_core::control::{DesignError, ModelFault};
use ridge_core::{ArxModel, Error as CoreError, InputMap, MapError, Offset};
use ufmt::{uDisplay, uWrite, Formatter};

use crate::numfmt::{Decimal, Fixed, Int, Milli};
use crate::sfm3300;

#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
use super::ReidVerdict;
use super::{root, ControlRefusal, Event, FaultReason, RejectReason, Residuals, StoredReason};

impl uDisplay for Residuals {
    /// `rms=… mean=… flow=…` (slm, 3 decimals).
    fn fmt<W: uWrite + ?Sized>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error> {
        let (mean, rms, flow) = self.means();
        ufmt::uwrite!(
            f,
            "rms={} mean={} flow={}",
            Fixed::new(rms, 3),
            Fixed::new(mean, 3),
            Fixed::new(flow, 3)
        )
    }
}

/// A report line that always fits in [`LINE_MAX`] bytes (an `ID` line with 12 coefficients of
/// magnitude below 10⁴ is about 210 bytes).
pub const LINE_MAX: usize = 256;

/// A fixed-capacity ASCII line buffer implementing [`uWrite`], e.g. to format an event once
/// and send it over a UART, or to compare lines in host tests. Writing past the capacity
/// keeps what fits and returns an error.
#[derive(Clone)]
pub struct Line<const N: usize> {
    buf: [u8; N],
    len: usize,
    truncated: bool,
}

impl<const N: usize> Default for Line<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Line<N> {
    /// An empty line.
    pub const fn new() -> Self {
        Line {
            buf: [0; N],
            len: 0,
            truncated: false,
        }
    }

    /// The text written so far.
    pub fn as_str(&self) -> &str {
        self.buf
            .get(..self.len)
            .and_then(|b| core::str::from_utf8(b).ok())
            .unwrap_or("")
    }

    /// Whether a write did not fit.
    pub fn is_truncated(&self) -> bool {
        self.truncated
    }
}

impl<const N: usize> uWrite for Line<N> {
    type Error = ();
    fn write_str(&mut self, s: &str) -> Result<(), ()> {
        let room = N.saturating_sub(self.len);
        // Report text is ASCII, so any byte boundary is a character boundary; cut at one
        // anyway so that `as_str` stays valid for any input.
        let mut take = s.len().min(room);
        while take > 0 && !s.is_char_boundary(take) {
            take -= 1;
        }
        let end = self.len.saturating_add(take);
        if let (Some(dst), Some(src)) = (self.buf.get_mut(self.len..end), s.as_bytes().get(..take))
        {
            dst.copy_from_slice(src);
            self.len = end;
        }
        if take < s.len() {
            self.truncated = true;
            return Err(());
        }
        Ok(())
    }
}

impl Event {
    /// The event's report line (see the [module docs](super)) in a `N`-byte buffer;
    /// [`LINE_MAX`] always suffices.
    pub fn line<const N: usize>(&self) -> Line<N> {
        let mut l = Line::new();
        // A truncated line is still returned (and flagged).
        let _ = ufmt::uwrite!(l, "{}", self);
        l
    }
}

/// Short kebab-case name of a map error, as used in `REJECT map=<name>`: `grid`,
/// `not-increasing`, `unscanned`.
pub const fn map_error_name(e: MapError) -> &'static str {
    match e {
        MapError::Grid => "grid",
        MapError::NotIncreasing => "not-increasing",
        MapError::Unscanned => "unscanned",
    }
}

/// Short kebab-case name of a ridge-core error, as used in `REJECT search=<name>`:
/// `nonfinite`, `overflow`, `too-short`, `invalid-structure`, `invalid-parameter`,
/// `not-excited`, `not-positive-definite`, `no-candidate`.
pub const fn core_error_name(e: CoreError) -> &'static str {
    match e {
        CoreError::NonFinite => "nonfinite",
        CoreError::Overflow => "overflow",
        CoreError::TooShort { .. } => "too-short",
        CoreError::InvalidStructure => "invalid-structure",
        CoreError::InvalidParameter => "invalid-parameter",
        CoreError::NotExcited => "not-excited",
        CoreError::NotPositiveDefinite => "not-positive-definite",
        CoreError::NoCandidate => "no-candidate",
    }
}

/// Digits of coefficients in report lines.
pub(crate) const COEF_DIGITS: u8 = 6;

/// Writes `values`, each times `scale`, comma-separated with `digits` decimals.
pub(crate) fn write_list<W>(
    f: &mut Formatter<'_, W>,
    values: &[f32],
    scale: f32,
    digits: u8,
) -> Result<(), W::Error>
where
    W: uWrite + ?Sized,
{
    for (i, v) in values.iter().enumerate() {
        if i > 0 {
            f.write_str(",")?;
        }
        uDisplay::fmt(&Fixed::new(*v * scale, digits), f)?;
    }
    Ok(())
}

/// The records' name on the `EXCITE` and `VALIDATE` lines ([`crate::excitation::FlowSteps`]).
pub const RECORD_NAME: &str = "flow-steps";

/// Writes `MAP first=<duty %> step=<duty %> flow=<16 flows, slm>` (the knots in counts printed
/// as slm with 3 decimals, which read back to the same counts).
fn write_map<W>(f: &mut Formatter<'_, W>, map: &InputMap) -> Result<(), W::Error>
where
    W: uWrite + ?Sized,
{
    ufmt::uwrite!(
        f,
        "MAP first={} step={} flow=",
        percent(map.first()),
        percent(map.step())
    )?;
    for (i, k) in map.knots().iter().enumerate() {
        if i > 0 {
            f.write_str(",")?;
        }
        uDisplay::fmt(&slm(*k), f)?;
    }
    Ok(())
}

/// Writes `p=.. q=.. d=.. off=.. theta=.. phi=.. c=..`.
pub(crate) fn write_model<W>(f: &mut Formatter<'_, W>, m: &ArxModel<f32>) -> Result<(), W::Error>
where
    W: uWrite + ?Sized,
{
    let s = m.structure();
    let off: u8 = match m.offset() {
        Offset::None => 0,
        Offset::Intercept => 1,
    };
    ufmt::uwrite!(
        f,
        "p={} q={} d={} off={} theta=",
        Int::from(s.p),
        Int::from(s.q),
        Int::from(s.d),
        Int::from(off)
    )?;
    write_list(f, m.theta(), 1.0, COEF_DIGITS)?;
    f.write_str(" phi=")?;
    write_list(f, m.phi(), 1.0, COEF_DIGITS)?;
    ufmt::uwrite!(f, " c={}", Fixed::new(m.intercept(), COEF_DIGITS))
}

/// Flow counts (1/120 slm) as milli-slm for printing.
fn slm(counts: i16) -> Milli {
    Milli(sfm3300::counts_to_millislm(counts))
}

/// Duty (1/10 000) as percent with 2 decimals.
fn percent(duty: u16) -> Decimal {
    Decimal::new(i32::from(duty), 2)
}

impl uDisplay for RejectReason {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        match *self {
            RejectReason::NotExcited { rms } => {
                ufmt::uwrite!(f, "not-excited rms={}", Fixed::new(rms, 3))
            }
            RejectReason::Map(e) => ufmt::uwrite!(f, "map={}", map_error_name(e)),
            RejectReason::Search(e) => ufmt::uwrite!(f, "search={}", core_error_name(e)),
            RejectReason::Fit { fit, min } => {
                ufmt::uwrite!(f, "fit={}<{}", Fixed::new(fit, 1), Fixed::new(min, 1))
            }
            RejectReason::NonFinite => f.write_str("nonfinite"),
            RejectReason::SensorGaps { gaps } => ufmt::uwrite!(f, "gaps={}", Int::from(gaps)),
        }
    }
}

impl uDisplay for FaultReason {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        match *self {
            FaultReason::Sensor { error, count } => {
                ufmt::uwrite!(f, "sensor={} n={}", error.name(), Int::from(count))
            }
            FaultReason::FlowRange { counts } => ufmt::uwrite!(f, "range flow={}", slm(counts)),
            FaultReason::Stall { duty, counts } => {
                ufmt::uwrite!(f, "stall duty={} flow={}", percent(duty), slm(counts))
            }
            FaultReason::Frozen { counts } => {
                ufmt::uwrite!(f, "sensor=frozen flow={}", slm(counts))
            }
            FaultReason::NoFlow {
                duty,
                counts,
                expected,
            } => ufmt::uwrite!(
                f,
                "noflow duty={} flow={} expect={}",
                percent(duty),
                slm(counts),
                slm(expected)
            ),
            FaultReason::ResetLoop { watchdog, brownout } => ufmt::uwrite!(
                f,
                "resets watchdog={} brownout={}",
                Int::from(watchdog),
                Int::from(brownout)
            ),
            FaultReason::Unidentified { attempts } => {
                ufmt::uwrite!(f, "unidentified attempts={}", Int::from(attempts))
            }
            FaultReason::Control(r) => ufmt::uwrite!(f, "control {}", r),
        }
    }
}

/// `unstable`, `nonfinite` or `gain=<B(1)/A(1)>` (slm per duty fraction).
fn write_model_fault<W>(f: &mut Formatter<'_, W>, m: &ModelFault<f32>) -> Result<(), W::Error>
where
    W: uWrite + ?Sized,
{
    match m {
        ModelFault::NonFinite => f.write_str("nonfinite"),
        ModelFault::Unstable => f.write_str("unstable"),
        ModelFault::Gain { gain } => ufmt::uwrite!(f, "gain={}", Fixed::new(*gain, 3)),
    }
}

/// The `why=` tail of a `REID … verdict=design` line (see [`ReidVerdict::Design`]).
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
fn write_reid_refusal<W>(f: &mut Formatter<'_, W>, why: &ControlRefusal) -> Result<(), W::Error>
where
    W: uWrite + ?Sized,
{
    match why {
        ControlRefusal::Model(ModelFault::Gain { .. }) => f.write_str(" why=gain"),
        ControlRefusal::Model(m) => {
            f.write_str(" why=")?;
            write_model_fault(f, m)
        }
        ControlRefusal::Design {
            error: DesignError::Margin { margin },
            tries,
        } => ufmt::uwrite!(
            f,
            " why=margin margin={} tries={}",
            Fixed::new(*margin, 3),
            Int::from(*tries)
        ),
        ControlRefusal::Design { .. } => ufmt::uwrite!(f, " why={}", why),
    }
}

impl uDisplay for ControlRefusal {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        match self {
            ControlRefusal::Model(m) => write_model_fault(f, m),
            ControlRefusal::Design { error, tries } => {
                match error {
                    DesignError::Spec => f.write_str("spec")?,
                    DesignError::Singular => f.write_str("singular")?,
                    DesignError::SlowPoles => f.write_str("slow-poles")?,
                    DesignError::Poles => f.write_str("poles")?,
                    DesignError::Margin { margin } => {
                        ufmt::uwrite!(f, "margin={}", Fixed::new(*margin, 3))?
                    }
                }
                ufmt::uwrite!(f, " tries={}", Int::from(*tries))
            }
        }
    }
}

impl uDisplay for StoredReason {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        match self {
            StoredReason::Record(e) => f.write_str(e.name()),
            StoredReason::Model(m) => write_model_fault(f, m),
            StoredReason::MapSlope { slope } => {
                ufmt::uwrite!(f, "map-slope={}", Fixed::new(*slope, 3))
            }
            StoredReason::Fit { fit, min } => {
                ufmt::uwrite!(f, "fit={}<{}", Fixed::new(*fit, 1), Fixed::new(*min, 1))
            }
        }
    }
}

impl uDisplay for Event {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        match self {
            Event::StoredRejected(r) => ufmt::uwrite!(f, "STORED-REJECTED {}", r),
            Event::Loaded { model, fit } => {
                f.write_str("LOADED ")?;
                write_model(f, model)?;
                ufmt::uwrite!(f, " fit={}", Fixed::new(*fit, 1))
            }
            Event::Scan {
                samples,
                lag,
                u0,
                y0,
                attempt,
                attempts,
            } => ufmt::uwrite!(
                f,
                "SCAN n={} lag={} u0={} y0={} attempt={}/{}",
                Int::from(*samples),
                Int::from(*lag),
                percent(*u0),
                slm(*y0),
                Int::from(*attempt),
                Int::from(*attempts)
            ),
            Event::Map(map) => write_map(f, map),
            Event::Excite {
                samples,
                u0,
                y0,
                attempt,
                attempts,
            } => ufmt::uwrite!(
                f,
                "EXCITE {} n={} u0={} y0={} attempt={}/{}",
                RECORD_NAME,
                Int::from(*samples),
                percent(*u0),
                slm(*y0),
                Int::from(*attempt),
                Int::from(*attempts)
            ),
            Event::Identified { model, stats } => {
                f.write_str("ID ")?;
                write_model(f, model)?;
                ufmt::uwrite!(
                    f,
                    " score={} eval={}/{} skip={} iters={}",
                    Fixed::new(stats.score, 1),
                    Int::from(stats.evaluated),
                    Int::from(stats.candidates),
                    Int::from(stats.skipped),
                    Int::from(stats.iterations)
                )
            }
            Event::Validate { samples } => {
                ufmt::uwrite!(f, "VALIDATE {} n={}", RECORD_NAME, Int::from(*samples))
            }
            Event::Accepted {
                fit,
                rmse,
                one_step,
                samples,
            } => ufmt::uwrite!(
                f,
                "ACCEPT fit={} rmse={} one={} n={} persist",
                Fixed::new(*fit, 1),
                Fixed::new(*rmse, 3),
                Fixed::new(*one_step, 3),
                Int::from(*samples)
            ),
            Event::Rejected {
                reason,
                attempt,
                attempts,
            } => ufmt::uwrite!(
                f,
                "REJECT {} attempt={}/{}",
                reason,
                Int::from(*attempt),
                Int::from(*attempts)
            ),
            Event::Control {
                tau,
                alpha,
                beta,
                gamma,
                kept,
                margin,
                tries,
                preview,
            } => ufmt::uwrite!(
                f,
                "CTRL method=pole-placement tau={} poles={},{} ref={} kept={} mm={} tries={} \
                 preview={}",
                Fixed::new(*tau, 3),
                Fixed::new(*alpha, 3),
                Fixed::new(*beta, 3),
                Fixed::new(*gamma, 3),
                Int::from(*kept),
                Fixed::new(*margin, 3),
                Int::from(*tries),
                Int::from(*preview)
            ),
            Event::Track {
                sum_setpoint,
                sum_flow,
                sum_sq,
                max,
                sum_duty,
                samples,
                tick,
            } => {
                let inv = 1.0 / f32::from((*samples).max(1));
                // < 2¹⁶ (a mean duty ≤ 10 000): `as` cannot saturate.
                let duty = (*sum_duty as f32 * inv + 0.5) as u16;
                ufmt::uwrite!(
                    f,
                    "TRACK sp={} flow={} rms={} max={} duty={} tick={}",
                    Fixed::new(sum_setpoint * inv, 3),
                    Fixed::new(sum_flow * inv, 3),
                    Fixed::new(root(sum_sq * inv), 3),
                    Fixed::new(*max, 3),
                    percent(duty),
                    Int::from(*tick)
                )
            }
            Event::Alarm { on: false, .. } => f.write_str("ALARM track clear"),
            Event::Alarm {
                on: true,
                error,
                ticks,
            } => ufmt::uwrite!(
                f,
                "ALARM track err={} s={}",
                Fixed::new(*error, 3),
                Decimal::new(i32::from(*ticks), 2)
            ),
            Event::Residual(r) => {
                ufmt::uwrite!(f, "RES {} n={}", r, Int::from(r.samples))
            }
            Event::Drift {
                residuals,
                seconds,
                reidentify,
            } => ufmt::uwrite!(
                f,
                "DRIFT {} s={} reid={}",
                residuals,
                Int::from(*seconds),
                Int(u32::from(*reidentify))
            ),
            Event::Breath(b) => ufmt::uwrite!(
                f,
                "BREATH n={} vt={} peep={} vd={} cmd={} peak={} rms={}",
                Int::from(b.number),
                Fixed::new(b.tidal, 1),
                Fixed::new(b.peep, 1),
                Fixed::new(b.delivered, 1),
                Fixed::new(b.command, 1),
                slm(b.peak),
                Fixed::new(root(b.sum_sq / f32::from(b.samples.max(1))), 3)
            ),
            Event::VolumeAlarm { on: false, .. } => f.write_str("ALARM volume clear"),
            Event::VolumeAlarm {
                on: true,
                delivered,
                tidal,
            } => ufmt::uwrite!(
                f,
                "ALARM volume vd={} vt={}",
                Fixed::new(*delivered, 1),
                Fixed::new(*tidal, 1)
            ),
            #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
            Event::Reid(r) => {
                ufmt::uwrite!(
                    f,
                    "REID breath={} verdict={} gain={} fit={}/{} v-rms={}",
                    Int::from(r.breath),
                    r.verdict.name(),
                    Fixed::new(r.gain, 3),
                    Fixed::new(r.fit, 1),
                    Fixed::new(r.running, 1),
                    Fixed::new(r.v_rms, 3)
                )?;
                match &r.verdict {
                    ReidVerdict::Design(why) => write_reid_refusal(f, why),
                    _ => Ok(()),
                }
            }
            Event::Fault(reason) => ufmt::uwrite!(f, "FAULT {}", reason),
        }
    }
}
