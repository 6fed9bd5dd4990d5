//! Flow setpoints for run mode, one value per 10 ms tick, in slm: a constant, the demo's
//! steps, breath profiles (square or decelerating-ramp inspiratory flow) and volume-controlled
//! breaths (the same shapes sized to deliver a tidal volume, [`VolumeBreath`]).
//!
//! # Breath profile
//! A breath of period `60 / rate` s is split by the I:E ratio `1 : ie` into an inspiration of
//! `T_i = period / (1 + ie)` and an expiration `T_e = period − T_i`.
//! - **Square**: the flow rises from the bias flow to the peak flow in `rise` seconds
//!   (linear), holds the peak, and at the end of the inspiration falls back to the bias flow in
//!   `rise` seconds.
//! - **Decelerating ramp**: the flow rises to the peak in `rise` seconds, then decreases
//!   linearly to the bias flow at the end of the inspiration.
//! - Expiration: the bias flow.
//!
//! The breath period is rounded to whole ticks.
//!
//! # Volume-controlled breath
//! A [`VolumeWave`] is defined in whole ticks: period `N`, inspiration `N_i` (phases
//! `0..N_i`, while the exhalation valve is closed), rise `R`. During the inspiration the flow
//! is `bias + amp · f_k` with
//! - **square**: `f_k = min(1, (k + 1)/(R + 1))`;
//! - **decelerating ramp**: `f_k = min((k + 1)/(R + 1), (N_i − k)/(N_i − R))`, falling to the
//!   bias flow at the end of the inspiration;
//!
//! then the bias flow during the expiration. The setpoint summed over the inspiration is
//! `bias · N_i + amp · S` with `S = Σ f_k` = `N_i − R/2` (square) or `(N_i + 1)/2` (ramp), exactly,
//! so the amplitude for a volume `V` (mL) is `amp = (V / ML_PER_SLM_TICK − bias · N_i) / S`
//! ([`VolumeWave::amplitude_for`]): the program delivers `V` over the inspiration's ticks.
//!
//! **Lead-in**: a volume program starts at the phase `N_i`, the end of an inspiration, so its
//! first `N − N_i` ticks are an expiration (the bias flow, the exhalation valve open, the PEEP
//! valve already set) before breath 1's inspiration at phase 0. The lung, whatever it held
//! before, fills towards the PEEP (by `bias · (N − N_i)` at most: 167 mL at 5 slm over 2 s) or
//! empties to it, so that breath 1 starts near where every later breath starts, not from the
//! pressure the flow before `VENT` left (docs/ventilation.md measures what is left).
//!
//! Every setpoint is a function of the tick count
//! ([`value`]): the sequence is exactly repeatable, and a host tool regenerates it from the
//! same code. [`Setpoint`] produces the same values incrementally (a phase counter instead of a
//! modulo, [`BreathWave`] instead of divisions), cheap enough for the 100 Hz tick.

use ridge_core::Real;

use crate::units::{ML_PER_SLM_TICK, SAMPLE_RATE_HZ, TS_S};

/// The shape of the inspiratory flow.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Constant peak flow during the inspiration.
    Square,
    /// Peak flow at the start of the inspiration, falling linearly to the bias flow.
    Ramp,
}

/// A breath profile (see the module docs). Flows in slm, times in s, rate in breaths/min.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breath {
    /// Inspiratory flow shape.
    pub shape: Shape,
    /// Breaths per minute (> 0).
    pub rate: f32,
    /// Expiratory part of the I:E ratio `1 : ie` (> 0; 2 means 1:2).
    pub ie: f32,
    /// Peak inspiratory flow, slm.
    pub peak: f32,
    /// Bias flow during expiration, slm.
    pub bias: f32,
    /// Rise (and square fall) time, s.
    pub rise: f32,
}

impl Breath {
    /// Why a profile is unusable, or `Ok`: positive finite rate and I:E, finite flows, a rise
    /// time from 0 to half the inspiration.
    pub fn check(&self) -> Result<(), &'static str> {
        let ok = |x: f32| Real::is_finite(x) && x > 0.0;
        if !ok(self.rate) || self.rate > 60.0 {
            return Err("rate");
        }
        if !ok(self.ie) || self.ie > 10.0 {
            return Err("ie");
        }
        if !Real::is_finite(self.peak) || !Real::is_finite(self.bias) {
            return Err("flow");
        }
        if !Real::is_finite(self.rise) || self.rise < 0.0 || self.rise > 0.5 * self.inspiration() {
            return Err("rise");
        }
        Ok(())
    }

    /// Breath period, s.
    pub const fn period(&self) -> f32 {
        60.0 / self.rate
    }

    /// Inspiration time, s.
    pub const fn inspiration(&self) -> f32 {
        self.period() / (1.0 + self.ie)
    }

    /// The setpoint `t` seconds into a breath (`0 ≤ t < period`), slm: `bias + (peak −
    /// bias) · f(t)` with `f` the rise (`t / rise`, at most 1) capped by the shape during the
    /// inspiration (square: 1; ramp: falling linearly from 1 at `rise` to 0 at `T_i`), and after
    /// it the square's fall (`1 − (t − T_i) / rise`, at least 0) or 0 for the ramp.
    pub fn at(&self, t: f32) -> f32 {
        let ti = self.inspiration();
        let ramp = |x: f32, over: f32| if over > 0.0 { x / over } else { 1.0 };
        let f = if t < ti {
            let up = ramp(t, self.rise);
            let shape = match self.shape {
                Shape::Square => 1.0,
                Shape::Ramp => 1.0 - ramp(t - self.rise, ti - self.rise),
            };
            up.min(shape).min(1.0)
        } else if self.shape == Shape::Square {
            (1.0 - ramp(t - ti, self.rise)).max(0.0)
        } else {
            0.0
        };
        self.bias + (self.peak - self.bias) * f
    }
}

/// One level of a step sequence: `slm` for `ticks` ticks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Level {
    /// Flow, slm.
    pub slm: f32,
    /// Duration in 10 ms ticks.
    pub ticks: u16,
}

/// The step sequence of the [`Program::Demo`] program: 2 s at each of 40, 25, 60, 35 slm.
pub const DEMO_STEPS: &[Level] = &[
    Level {
        slm: 40.0,
        ticks: 200,
    },
    Level {
        slm: 25.0,
        ticks: 200,
    },
    Level {
        slm: 60.0,
        ticks: 200,
    },
    Level {
        slm: 35.0,
        ticks: 200,
    },
];

/// The breath profile of the [`Program::Demo`] program: square, 20 breaths/min, I:E 1:2,
/// 60 slm peak, 10 slm bias, 0.3 s rise.
pub const DEMO_BREATH: Breath = Breath {
    shape: Shape::Square,
    rate: 20.0,
    ie: 2.0,
    peak: 60.0,
    bias: 10.0,
    rise: 0.3,
};

/// What run mode tracks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Program {
    /// The flow at the start of run mode (bumpless hold of the operating point).
    Hold,
    /// A constant flow, slm.
    Constant(f32),
    /// A breath profile, repeated (prepared: `Program::Breath(BreathWave::new(&breath))`).
    Breath(BreathWave),
    /// The demonstration: 2 s holding the start flow, [`DEMO_STEPS`] once, then
    /// [`DEMO_BREATH`] for ever.
    Demo,
    /// Volume-controlled breaths, repeated from the first tick after a lead-in of one
    /// expiration (module docs; the `VENT` command; the per-breath bookkeeping is
    /// [`crate::ventilation`]'s).
    Volume(VolumeBreath),
}

/// A breath profile prepared for evaluation per tick: its period in whole ticks and the
/// reciprocals of its ramp times, computed once. A setpoint then costs a few multiplications on
/// the ATmega2560 instead of three divisions and a 32-bit modulo (about 3 500 cycles, twice
/// per tick with the preview).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BreathWave {
    /// Breath period, ticks (at least 1).
    period: u32,
    shape: Shape,
    /// Inspiration time, s.
    ti: f32,
    /// Rise time, s.
    rise: f32,
    /// `1 / rise` (0 for no rise), 1/s.
    inv_rise: f32,
    /// `1 / (T_i − rise)` (0 when the ramp has no time to fall), 1/s.
    inv_fall: f32,
    /// Bias flow, slm.
    bias: f32,
    /// Peak minus bias flow, slm.
    amp: f32,
}

impl BreathWave {
    /// Prepares `b` (see [`Breath::check`] for sensible settings; any values give finite
    /// ticks). A `const fn`: a program in the settings is prepared at compile time, and no
    /// division is left for the device.
    pub const fn new(b: &Breath) -> Self {
        let period = (b.period() * SAMPLE_RATE_HZ as f32 + 0.5) as u32;
        let ti = b.inspiration();
        BreathWave {
            period: if period == 0 { 1 } else { period },
            shape: b.shape,
            ti,
            rise: b.rise,
            inv_rise: reciprocal(b.rise),
            inv_fall: reciprocal(ti - b.rise),
            bias: b.bias,
            amp: b.peak - b.bias,
        }
    }

    /// Breath period, ticks.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// The setpoint `phase` ticks into a breath (`phase < period`), slm: [`Breath::at`] of
    /// `phase · Ts` with the divisions as multiplications by the reciprocals.
    pub fn at_phase(&self, phase: u32) -> f32 {
        // Comparisons rather than f32::min/max: those are 280 bytes of libm on the ATmega2560.
        let t = phase as f32 * TS_S;
        let f = if t < self.ti {
            let mut f = 1.0;
            if t < self.rise {
                f = t * self.inv_rise;
            }
            if self.shape == Shape::Ramp {
                let fall = if self.inv_fall > 0.0 {
                    1.0 - (t - self.rise) * self.inv_fall
                } else {
                    0.0
                };
                if fall < f {
                    f = fall;
                }
            }
            f
        } else if self.shape == Shape::Square && t - self.ti < self.rise {
            1.0 - (t - self.ti) * self.inv_rise
        } else {
            0.0
        };
        self.bias + self.amp * f
    }
}

/// A volume-controlled breath's flow program (see the module docs), in whole ticks, with the
/// inspiratory amplitude for the volume it is to deliver. Built by
/// [`ventilation::settings`](crate::ventilation::settings) from a `VENT` command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeWave {
    /// Breath period `N`, ticks (at least 2).
    period: u16,
    /// Inspiration `N_i`, ticks (`1..period`).
    insp: u16,
    /// Rise `R`, ticks (`≤ N_i / 2`).
    rise: u16,
    shape: Shape,
    /// `1 / (R + 1)`.
    inv_rise: f32,
    /// `1 / (N_i − R)` (ramp).
    inv_fall: f32,
    /// `1 / S`, the reciprocal of the shape's sum over the inspiration.
    inv_sum: f32,
    /// Bias flow (expiration; the inspiration's flow rises from it), slm.
    bias: f32,
    /// Inspiratory amplitude above the bias flow, slm.
    amp: f32,
}

impl VolumeWave {
    /// A wave of `period` ticks with an inspiration of `insp` ticks and a rise of `rise`
    /// ticks, `shape`, bias flow `bias` (slm), sized for `volume` mL
    /// ([`amplitude_for`](Self::amplitude_for)). The caller keeps `2 ≤ period`,
    /// `1 ≤ insp < period` and `2 · rise ≤ insp` ([`ventilation::settings`] checks them); other
    /// values give a finite wave.
    ///
    /// [`ventilation::settings`]: crate::ventilation::settings
    pub fn new(period: u16, insp: u16, rise: u16, shape: Shape, bias: f32, volume: f32) -> Self {
        let rise = rise.min(insp / 2);
        let sum = match shape {
            Shape::Square => f32::from(insp) - 0.5 * f32::from(rise),
            Shape::Ramp => 0.5 * (f32::from(insp) + 1.0),
        };
        let mut w = VolumeWave {
            period: period.max(1),
            insp,
            rise,
            shape,
            inv_rise: 1.0 / (f32::from(rise) + 1.0),
            inv_fall: reciprocal(f32::from(insp - rise)),
            inv_sum: reciprocal(sum),
            bias,
            amp: 0.0,
        };
        w.amp = w.amplitude_for(volume);
        w
    }

    /// Breath period, ticks.
    pub fn period(&self) -> u16 {
        self.period
    }

    /// Inspiration, ticks: phases `0..inspiration()` are the inspiration.
    pub fn inspiration(&self) -> u16 {
        self.insp
    }

    /// Rise, ticks.
    pub fn rise(&self) -> u16 {
        self.rise
    }

    /// The inspiratory shape.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// Bias flow, slm.
    pub fn bias(&self) -> f32 {
        self.bias
    }

    /// Inspiratory amplitude above the bias flow, slm (the peak flow is `bias + amp`).
    pub fn amplitude(&self) -> f32 {
        self.amp
    }

    /// Sets the inspiratory amplitude (the volume trim of [`crate::ventilation`]), slm.
    pub fn set_amplitude(&mut self, amp: f32) {
        self.amp = amp;
    }

    /// The amplitude (slm) that makes the inspiration's setpoints sum to `volume` mL:
    /// `(volume / ML_PER_SLM_TICK − bias · N_i) / S` (module docs).
    pub fn amplitude_for(&self, volume: f32) -> f32 {
        (volume * (1.0 / ML_PER_SLM_TICK) - self.bias * f32::from(self.insp)) * self.inv_sum
    }

    /// The setpoint `phase` ticks into a breath (`phase < period`), slm.
    pub fn at_phase(&self, phase: u32) -> f32 {
        let insp = u32::from(self.insp);
        if phase >= insp {
            return self.bias;
        }
        let mut f = 1.0;
        if phase < u32::from(self.rise) {
            f = (phase + 1) as f32 * self.inv_rise;
        }
        if self.shape == Shape::Ramp {
            let fall = (insp - phase) as f32 * self.inv_fall;
            if fall < f {
                f = fall;
            }
        }
        self.bias + self.amp * f
    }
}

/// The settings of volume-controlled ventilation ([`Program::Volume`], the `VENT` command):
/// the set tidal volume and PEEP, whether the per-breath volume trim runs, and the flow
/// program.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeBreath {
    /// Set tidal volume, mL.
    pub tidal: f32,
    /// PEEP set on the expiratory limb's PEEP valve, cmH₂O. The firmware has no pressure
    /// sensor: it is checked and reported (`BREATH` lines), not controlled.
    pub peep: f32,
    /// Whether the per-breath volume trim runs ([`crate::ventilation`]).
    pub trim: bool,
    /// The flow program, sized for `tidal`.
    pub wave: VolumeWave,
}

/// `1 / x` for `x > 0`, else 0.
const fn reciprocal(x: f32) -> f32 {
    if x > 0.0 {
        1.0 / x
    } else {
        0.0
    }
}

/// The demo's breaths, prepared.
pub const DEMO_WAVE: BreathWave = BreathWave::new(&DEMO_BREATH);

/// The repeated breath of a program: a profile or a volume-controlled breath.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Wave {
    Profile(BreathWave),
    Volume(VolumeWave),
}

impl Wave {
    fn period(&self) -> u32 {
        match self {
            Wave::Profile(w) => w.period,
            Wave::Volume(w) => u32::from(w.period),
        }
    }

    fn at_phase(&self, phase: u32) -> f32 {
        match self {
            Wave::Profile(w) => w.at_phase(phase),
            Wave::Volume(w) => w.at_phase(phase),
        }
    }
}

/// A [`Program`] running: one setpoint per tick.
///
/// The breath part is evaluated from a [`BreathWave`] (or a [`VolumeWave`]) and a phase
/// counter kept with the tick (no division per tick); the values equal [`value`]'s for every
/// tick (a volume program's while its amplitude is the one it was built with).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    program: Program,
    /// Flow at the start of run mode, slm (for [`Program::Hold`] and the demo's first part).
    start: f32,
    /// Ticks since the start.
    tick: u32,
    /// The breaths of the program ([`Program::Breath`], [`Program::Volume`], the demo's
    /// [`DEMO_BREATH`]).
    wave: Wave,
    /// The tick the breaths start at (`u32::MAX`: none).
    breath_from: u32,
    /// Ticks into the current breath, once `tick ≥ breath_from`.
    phase: u32,
}

/// Ticks the demo holds the start flow before its steps.
pub const DEMO_HOLD_TICKS: u32 = 200;

/// Ticks of the demo's step sequence.
fn demo_steps_ticks() -> u32 {
    let mut total = 0u32;
    for l in DEMO_STEPS {
        total += u32::from(l.ticks);
    }
    total
}

/// The phase a program's breaths start at: a volume program's lead-in (module docs) starts at
/// the end of the inspiration, every other at 0.
fn first_phase(wave: &Wave) -> u32 {
    match wave {
        Wave::Volume(w) => u32::from(w.insp),
        Wave::Profile(_) => 0,
    }
}

/// The program's breaths and the tick they start at (`u32::MAX`: none).
fn breaths(program: Program) -> (Wave, u32) {
    match program {
        Program::Breath(w) => (Wave::Profile(w), 0),
        Program::Volume(v) => (Wave::Volume(v.wave), 0),
        Program::Demo => (
            Wave::Profile(DEMO_WAVE),
            DEMO_HOLD_TICKS + demo_steps_ticks(),
        ),
        _ => (Wave::Profile(DEMO_WAVE), u32::MAX),
    }
}

impl Setpoint {
    /// Starts `program` with `start_flow` (slm) as the flow at the start.
    pub fn new(program: Program, start_flow: f32) -> Self {
        let (wave, breath_from) = breaths(program);
        Setpoint {
            program,
            start: start_flow,
            tick: 0,
            wave,
            breath_from,
            phase: first_phase(&wave),
        }
    }

    /// The program.
    pub fn program(&self) -> Program {
        self.program
    }

    /// Ticks since the start.
    pub fn ticks(&self) -> u32 {
        self.tick
    }

    /// The setpoint `ticks` ticks after the coming one (slm), without advancing: a program is
    /// known ahead, which lets a controller be given it early by the loop's delay.
    pub fn ahead(&self, ticks: u32) -> f32 {
        let t = self.tick.saturating_add(ticks);
        if t < self.breath_from {
            return before_breaths(self.program, self.start, t);
        }
        let mut p = if self.tick >= self.breath_from {
            self.phase.saturating_add(ticks)
        } else {
            t - self.breath_from
        };
        let n = self.wave.period();
        while p >= n {
            p -= n;
        }
        self.wave.at_phase(p)
    }

    /// The setpoint for the coming tick (slm), and advances by one tick.
    pub fn advance(&mut self) -> f32 {
        let v = self.ahead(0);
        self.tick = self.tick.saturating_add(1);
        if self.tick > self.breath_from {
            self.phase += 1;
            if self.phase >= self.wave.period() {
                self.phase = 0;
            }
        }
        v
    }

    /// For a volume program: whether the coming tick's interval is in the inspiration (the
    /// exhalation valve closed), and its phase in the breath (ticks since the breath
    /// started; the lead-in before breath 1 runs the phases from `N_i` on, module docs).
    /// `None` for every other program. Read before [`advance`](Self::advance).
    pub fn volume_phase(&self) -> Option<(bool, u32)> {
        match &self.wave {
            Wave::Volume(w) if self.tick >= self.breath_from => {
                Some((self.phase < u32::from(w.insp), self.phase))
            }
            _ => None,
        }
    }

    /// The volume program's settings with its wave as it runs now (its amplitude trimmed),
    /// `None` for every other program.
    pub fn volume(&self) -> Option<VolumeBreath> {
        match (self.program, &self.wave) {
            (Program::Volume(b), Wave::Volume(w)) => Some(VolumeBreath { wave: *w, ..b }),
            _ => None,
        }
    }

    /// Sets a volume program's inspiratory amplitude (slm) from the next setpoint on (the
    /// volume trim); nothing for other programs.
    pub fn set_amplitude(&mut self, amp: f32) {
        if let Wave::Volume(w) = &mut self.wave {
            w.set_amplitude(amp);
        }
    }
}

/// The setpoint of `program` at `tick` (ticks since the start), for a start flow `start`: the
/// definition [`Setpoint`] follows (host tools regenerate a run's setpoints with it).
pub fn value(program: Program, start: f32, tick: u32) -> f32 {
    let (wave, from) = breaths(program);
    if tick < from {
        return before_breaths(program, start, tick);
    }
    let n = wave.period();
    let p = (tick - from) % n + first_phase(&wave);
    wave.at_phase(if p >= n { p - n } else { p })
}

/// [`value`] before the program's breaths.
fn before_breaths(program: Program, start: f32, tick: u32) -> f32 {
    match program {
        Program::Hold | Program::Breath(_) | Program::Volume(_) => start,
        Program::Constant(v) => v,
        Program::Demo => match tick.checked_sub(DEMO_HOLD_TICKS) {
            None => start,
            Some(t) => demo_step_at(t),
        },
    }
}

/// The level of [`DEMO_STEPS`] at `tick` ticks into them (the last one after their end: the
/// breaths start there). (The demo's constant steps fold into a few comparisons; a step
/// program of the settings' own, `Program::Steps` until it was removed, cost the ATmega2560
/// 200 bytes of flash.)
fn demo_step_at(tick: u32) -> f32 {
    let mut t = tick;
    for l in DEMO_STEPS {
        if t < u32::from(l.ticks) {
            return l.slm;
        }
        t -= u32::from(l.ticks);
    }
    DEMO_STEPS.last().map_or(0.0, |l| l.slm)
}
