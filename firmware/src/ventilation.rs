//! Volume-controlled ventilation (the console's `VENT` command): its settings checked into a
//! [`VolumeBreath`] ([`settings`]), the exhalation valve the firmware drives ([`Valve`]), and
//! run mode's per-breath bookkeeping ([`Ventilation`]): the delivered volume measured from the
//! readings, the `BREATH` line, the volume alarm and the per-breath volume trim.
//!
//! The flow program itself (square or decelerating ramp, sized in whole ticks to deliver the
//! tidal volume) is [`crate::setpoint`]'s [`VolumeWave`]; the flow controller tracks it like
//! any other program.
//!
//! # The exhalation valve
//! A digital output: **closed** during the inspiration of a volume-controlled breath (every
//! litre the blower delivers goes into the lung), **open** otherwise: in the expiration (the
//! lung empties through the PEEP valve), in every other program, while identifying, stopped,
//! on any fault and before the loop runs. Open is the safe state: the board's pin drives it
//! closed when high, and a pull-down keeps it open while the MCU is in reset (docs/boards.md).
//!
//! # Delivered volume
//! The valve is closed over the inspiration's `N_i` intervals, from the reading `y_0` at the
//! tick that starts the breath to the reading `y_{N_i}` at the tick that ends its
//! inspiration. The delivered volume is their trapezoid sum, kept in integer counts:
//! `V = (y_0 + 2 y_1 + … + 2 y_{N_i − 1} + y_{N_i}) · ML_PER_COUNT_TICK / 2` (mL). A reading
//! lost to a sensor error counts as the last good one, as the controller takes it.
//!
//! # Per breath
//! - at the end of the inspiration the volume is known: the **volume alarm** is raised when it
//!   is outside `±(BAND_ML + BAND_REL · VT)` (ISO 80601-2-12's ±(4 mL + 15 %)) for
//!   [`ALARM_BREATHS`] breaths in a row, and cleared after as many back inside
//!   (`ALARM volume vd=… vt=…` / `ALARM volume clear`); with the **trim** on, the volume the
//!   next breath is programmed for moves by [`TRIM_GAIN`] times the error, within
//!   [`TRIM_PERCENT`] % of the set volume (the program's amplitude is resized for it:
//!   the flow controller still tracks the flow, the trim only corrects the volume its tracking
//!   loses, breath to breath);
//! - in the middle of the expiration the lung has emptied to the PEEP and the bias flow holds:
//!   the **no-flow check** of the tick's faults expects from this operating point on (the
//!   guard's law, its slope kept, moved through it, [`Anchor`]); it is paused from the
//!   program's first tick (through the lead-in, whose lung is still filling towards the PEEP)
//!   until breath 1's, and run mode gives it no flow from the static map while
//!   a volume program runs, since neither the settled operating point nor the map of the
//!   identification had the PEEP valve's and the lung's back pressure (at 10 cmH₂O the blower
//!   needs about 40 % duty before any flow);
//! - at the start of the next breath the breath is complete: its `BREATH` line (number, set
//!   volume and PEEP, delivered volume, the volume it was programmed for, peak flow, tracking
//!   RMS over the breath). This tick is the **breath boundary**.
//!
//! Before breath 1 the program's lead-in (one expiration, [`crate::setpoint`]'s module docs)
//! brings the lung to the PEEP: nothing is counted, no line, the breath number stays 0.
//!
//! All of it runs after the tick's PWM write ([`Ventilation::after_pwm`]); before it run mode
//! only evaluates the program and reads the valve's state.

use crate::command::{Milli, VentArgs};
use crate::event::{BreathSummary, Event};
use crate::setpoint::{Setpoint, Shape, VolumeBreath, VolumeWave};
use crate::units::{FLOW_SCALE, ML_PER_COUNT_TICK, SAMPLE_RATE_HZ};

/// The exhalation valve's state (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Valve {
    /// Open to the PEEP valve: the safe state.
    Open,
    /// Closed: the inspiration of a volume-controlled breath.
    Closed,
}

/// Smallest and largest tidal volume, mL (thousandths).
pub const VT_RANGE: (Milli, Milli) = (20_000, 2_000_000);
/// Smallest and largest rate, breaths/min (thousandths).
pub const RATE_RANGE: (Milli, Milli) = (1_000, 60_000);
/// Shortest inspiration, s (thousandths); the longest is half the breath (I:E 1:1).
pub const TI_MIN: Milli = 100;
/// Smallest and largest `ie` of the I:E ratio `1 : ie` (thousandths).
pub const IE_RANGE: (Milli, Milli) = (1_000, 10_000);
/// Largest PEEP, cmH₂O (thousandths).
pub const PEEP_MAX: Milli = 30_000;
/// Defaults of the keys a `VENT` line may leave out (thousandths): I:E 1:2, PEEP 5 cmH₂O,
/// bias flow 5 slm, rise 0.1 s.
pub const DEFAULT_IE: Milli = 2_000;
/// Default PEEP, cmH₂O (thousandths).
pub const DEFAULT_PEEP: Milli = 5_000;
/// Default bias flow, slm (thousandths).
pub const DEFAULT_BIAS: Milli = 5_000;
/// Default rise time, s (thousandths).
pub const DEFAULT_RISE: Milli = 100;

/// Absolute part of the volume band, mL.
pub const BAND_ML: f32 = 4.0;
/// Relative part of the volume band, fraction of the set volume.
pub const BAND_REL: f32 = 0.15;
/// Breaths in a row out of (back in) the band that raise (clear) the volume alarm.
pub const ALARM_BREATHS: u8 = 2;
/// The trim's gain: the next breath's programmed volume moves by this fraction of the error.
pub const TRIM_GAIN: f32 = 0.5;
/// The trim's bound: the programmed volume stays within this many percent of the set volume.
pub const TRIM_PERCENT: u8 = 25;

/// Ticks per second, as the integer checks use it.
const TICKS_PER_S: Milli = SAMPLE_RATE_HZ as Milli;

/// The volume breath of a `VENT` command, checked exactly in thousandths (`Err(name)` of the
/// first setting out of range; nothing is rounded before it is checked):
/// - `vt` in [`VT_RANGE`] (mL), `rate` in [`RATE_RANGE`] (/min);
/// - `ti` from [`TI_MIN`] to half the period (`ti · rate ≤ 30`), or `ie` in [`IE_RANGE`]
///   ([`DEFAULT_IE`] when neither is given);
/// - `rise` ≥ 0, at most half the inspiration once both are rounded to ticks;
/// - `peep` from 0 to [`PEEP_MAX`]; `bias` from 0 to the flow limit (`flow_limit` counts);
/// - `flow`: the bias flow alone must not deliver more than the set volume in the
///   inspiration, and the peak flow for the largest trimmed volume (`VT · (1 + TRIM_PERCENT
///   %)`) must be within the flow limit.
///
/// Times are rounded to whole ticks: the period `round(6000 / rate)`, the inspiration
/// `round(100 · ti)` or `round(period / (1 + ie))`, the rise `round(100 · rise)`.
// Out of line: one copy for the console, none in the tick.
#[inline(never)]
pub fn settings(args: &VentArgs, flow_limit: i16) -> Result<VolumeBreath, &'static str> {
    let within = |v: Milli, (lo, hi): (Milli, Milli)| v >= lo && v <= hi;
    if !within(args.vt, VT_RANGE) {
        return Err("vt");
    }
    if !within(args.rate, RATE_RANGE) {
        return Err("rate");
    }
    // Divisions in 32 bits: every operand below is at most 6·10⁶ (the 64-bit division would
    // pull in a libgcc helper that returns through an indirect jump, which the stack bound
    // cannot follow).
    let rate = args.rate;
    // 60 · 100 ticks a minute / rate (rate in thousandths): ≤ 6000 for rate ≥ 1.
    let period = (60 * TICKS_PER_S * 1_000 + rate / 2) / rate;
    let insp = match (args.ti, args.ie) {
        (Some(ti), _) => {
            // ti ≤ 30 / rate (half the period) ⇔ ti · rate ≤ 30 · 10⁶ in thousandths.
            if ti < TI_MIN || i64::from(ti) * i64::from(rate) > 30_000_000 {
                return Err("ti");
            }
            // ti ≤ 30 s here.
            (ti * TICKS_PER_S + 500) / 1_000
        }
        (None, ie) => {
            let ie = ie.unwrap_or(DEFAULT_IE);
            if ie < IE_RANGE.0 || ie > IE_RANGE.1 {
                return Err("ie");
            }
            let den = 1_000 + ie;
            (period * 1_000 + den / 2) / den
        }
    };
    let rise = args.rise.unwrap_or(DEFAULT_RISE);
    // A rise beyond a minute is longer than half of any inspiration (at most 30 s): refused
    // before it is scaled, so that the scaling cannot overflow.
    if !(0..=60_000).contains(&rise) || 2 * ((rise * TICKS_PER_S + 500) / 1_000) > insp {
        return Err("rise");
    }
    let rise_ticks = (rise * TICKS_PER_S + 500) / 1_000;
    let peep = args.peep.unwrap_or(DEFAULT_PEEP);
    if !within(peep, (0, PEEP_MAX)) {
        return Err("peep");
    }
    let bias = i64::from(args.bias.unwrap_or(DEFAULT_BIAS));
    // bias ≤ limit / FLOW_SCALE ⇔ bias · FLOW_SCALE ≤ limit · 10³.
    let limit = i64::from(flow_limit) * 1_000;
    let scale = i64::from(FLOW_SCALE);
    if bias < 0 || bias * scale > limit {
        return Err("bias");
    }
    // In thousandths of mL and slm, with 6 = 1 / ML_PER_SLM_TICK ticks · slm per mL and
    // 2 S = 2 N_i − R (square) or N_i + 1 (ramp):
    // amp ≥ 0 ⇔ 6 vt ≥ bias · N_i; the peak for the largest volume, bias + amp_max ≤ limit,
    // ⇔ 100 · (2 · 6 · vt · (100 + P) / 100 − 2 · bias · N_i) ≤ 100 · (limit/scale − bias) · 2S.
    let vt = i64::from(args.vt);
    let shape = args.wave.unwrap_or(Shape::Square);
    let sum2 = i64::from(match shape {
        Shape::Square => 2 * insp - rise_ticks,
        Shape::Ramp => insp + 1,
    });
    let insp_ticks = insp;
    let insp = i64::from(insp);
    let trim = i64::from(TRIM_PERCENT);
    let need = 12 * vt * (100 + trim) - 200 * bias * insp;
    if 6 * vt < bias * insp || need * scale > 100 * (limit - bias * scale) * sum2 {
        return Err("flow");
    }
    let milli = |v: i64| v as f32 / 1_000.0;
    // Every tick count fits u16: period ≤ 6000, insp < period, rise ≤ insp / 2.
    let ticks = |v: Milli| u16::try_from(v).unwrap_or(u16::MAX);
    Ok(VolumeBreath {
        tidal: milli(vt),
        peep: milli(i64::from(peep)),
        trim: args.trim.unwrap_or(true),
        wave: VolumeWave::new(
            ticks(period),
            ticks(insp_ticks),
            ticks(rise_ticks),
            shape,
            milli(bias),
            milli(vt),
        ),
    })
}

/// Whether `delivered` mL is within `±(BAND_ML + BAND_REL · tidal)` of `tidal` mL.
pub fn within_band(delivered: f32, tidal: f32) -> bool {
    let e = delivered - tidal;
    let band = BAND_ML + BAND_REL * tidal;
    // Written so that NaN is out of the band.
    e <= band && e >= -band
}

/// What the tick's fault checks take from a volume program ([`Ventilation::after_pwm`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Anchor {
    /// Every tick before breath 1 (the lead-in) and breath 1's first: pause the no-flow
    /// check (its expected flow comes from an operating point without the PEEP valve's back
    /// pressure, and the lead-in's lung is still filling).
    Pause,
    /// Mid-expiration with the bias flow held (the reading within `1 slm + 15 %` of it):
    /// the pump demonstrably gives this tick's reading at the duty of the interval that ended
    /// with it; expect from there on.
    Hold,
    /// Mid-expiration without the bias flow held: the expectation stays as it was (and a
    /// pause ends: the no-flow check judges the pump by it).
    Keep,
}

/// Run mode's per-breath bookkeeping of a volume program (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ventilation {
    /// The breath in progress, from 1 (0 before the first).
    number: u32,
    /// Twice the trapezoid sum of the inspiration's readings so far, counts.
    sum2: i32,
    /// Largest reading of the inspiration, counts.
    peak: i16,
    /// Σ (setpoint − reading)² over the breath so far, slm², and its terms.
    sum_sq: f32,
    samples: u16,
    /// The volume the next breath is programmed for (set volume and trim), mL.
    command: f32,
    /// The volume the breath in progress was programmed for, mL.
    used: f32,
    /// The delivered volume of the breath in progress (once its inspiration ended), mL.
    delivered: f32,
    /// Breaths in a row out of the band (alarm off) or back in it (alarm on).
    run: u8,
    alarm: bool,
    /// The last complete breath, for its line.
    last: BreathSummary,
    /// Lines waiting for a tick without another event.
    breath_due: bool,
    alarm_due: bool,
}

impl Ventilation {
    /// Before the first breath of a program for `tidal` mL.
    pub fn new(tidal: f32) -> Self {
        Ventilation {
            number: 0,
            sum2: 0,
            peak: 0,
            sum_sq: 0.0,
            samples: 0,
            command: tidal,
            used: tidal,
            delivered: 0.0,
            run: 0,
            alarm: false,
            last: BreathSummary::default(),
            breath_due: false,
            alarm_due: false,
        }
    }

    /// The breath in progress, from 1 (0 before the first).
    pub fn breath(&self) -> u32 {
        self.number
    }

    /// Whether the volume alarm is raised.
    pub fn alarm(&self) -> bool {
        self.alarm
    }

    /// The volume the next breath is programmed for, mL.
    pub fn command(&self) -> f32 {
        self.command
    }

    /// One tick, after its PWM write: `phase` the breath phase of the interval that started
    /// at this tick ([`Setpoint::volume_phase`] before the program advanced), `reading` the
    /// tick's reading (counts; the held one after a sensor error), `ended` the setpoint of the
    /// interval that ended with it (slm). Puts a `BREATH` or `ALARM volume` event into
    /// `event` when it is empty (one waiting for a free tick goes first); resizes the
    /// program's amplitude when the trim moves; returns what the fault checks take from the
    /// tick ([`Anchor`]). Nothing for other programs.
    // Out of line: once, after the PWM write.
    #[inline(never)]
    pub fn after_pwm(
        &mut self,
        setpoint: &mut Setpoint,
        phase: u32,
        reading: i16,
        ended: f32,
        event: &mut Option<Event>,
    ) -> Option<Anchor> {
        let b = setpoint.volume()?;
        let insp = u32::from(b.wave.inspiration());
        let y = reading;
        let mut anchor = None;
        // Mid-expiration: the lung has emptied to the PEEP, and the preview of the next
        // breath has not yet raised the flow.
        let period = u32::from(b.wave.period());
        if self.number == 0 {
            // The lead-in and breath 1's first tick.
            anchor = Some(Anchor::Pause);
        } else if phase == insp + (period - insp) / 2 {
            let bias = b.wave.bias();
            let e = f32::from(y) * crate::units::SLM_PER_COUNT - bias;
            let band = 1.0 + 0.15 * bias;
            anchor = Some(if e <= band && e >= -band {
                Anchor::Hold
            } else {
                Anchor::Keep
            });
        }
        if phase == 0 {
            if self.number > 0 {
                self.add_error(ended, y);
                self.last = BreathSummary {
                    number: self.number,
                    tidal: b.tidal,
                    peep: b.peep,
                    delivered: self.delivered,
                    command: self.used,
                    peak: self.peak,
                    sum_sq: self.sum_sq,
                    samples: self.samples,
                };
                self.breath_due = true;
            }
            self.number = self.number.saturating_add(1);
            self.used = self.command;
            self.sum2 = i32::from(y);
            self.peak = i16::MIN;
            self.sum_sq = 0.0;
            self.samples = 0;
        } else {
            self.add_error(ended, y);
            if phase <= insp && self.number > 0 {
                let weight = if phase < insp { 2 } else { 1 };
                self.sum2 = self.sum2.saturating_add(weight * i32::from(y));
                if y > self.peak {
                    self.peak = y;
                }
                if phase == insp {
                    self.end_inspiration(&b, setpoint);
                }
            }
        }
        if event.is_none() {
            if self.breath_due {
                self.breath_due = false;
                *event = Some(Event::Breath(self.last));
            } else if self.alarm_due {
                self.alarm_due = false;
                *event = Some(Event::VolumeAlarm {
                    on: self.alarm,
                    delivered: self.delivered,
                    tidal: b.tidal,
                });
            }
        }
        anchor
    }

    fn add_error(&mut self, setpoint: f32, reading: i16) {
        let e = setpoint - f32::from(reading) * crate::units::SLM_PER_COUNT;
        self.sum_sq += e * e;
        self.samples = self.samples.saturating_add(1);
    }

    /// The inspiration's volume is complete: alarm and trim.
    fn end_inspiration(&mut self, b: &VolumeBreath, setpoint: &mut Setpoint) {
        // Half the doubled trapezoid sum, in mL.
        self.delivered = self.sum2 as f32 * (0.5 * ML_PER_COUNT_TICK);
        let inside = within_band(self.delivered, b.tidal);
        // Out of the band with the alarm off, or back in with it on: one more in a row.
        if inside == self.alarm {
            self.run = self.run.saturating_add(1);
            if self.run >= ALARM_BREATHS {
                self.alarm = !self.alarm;
                self.run = 0;
                self.alarm_due = true;
            }
        } else {
            self.run = 0;
        }
        if b.trim {
            let span = b.tidal * (f32::from(TRIM_PERCENT) / 100.0);
            let mut next = self.command + TRIM_GAIN * (b.tidal - self.delivered);
            // Comparisons rather than f32::clamp: libm's is 280 bytes on the ATmega2560.
            if next < b.tidal - span {
                next = b.tidal - span;
            }
            if next > b.tidal + span {
                next = b.tidal + span;
            }
            self.command = next;
            setpoint.set_amplitude(b.wave.amplitude_for(next));
        }
    }
}
