//! Flow setpoints for run mode, one value per 10 ms tick, in slm: a constant, the demo's
//! steps, and breath profiles (square or decelerating-ramp inspiratory flow).
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
//! The breath period is rounded to whole ticks. Every setpoint is a function of the tick count
//! ([`value`]): the sequence is exactly repeatable, and a host tool regenerates it from the
//! same code. [`Setpoint`] produces the same values incrementally (a phase counter instead of a
//! modulo, [`BreathWave`] instead of divisions), cheap enough for the 100 Hz tick.

use ridge_core::Real;

use crate::units::{SAMPLE_RATE_HZ, TS_S};

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

/// A [`Program`] running: one setpoint per tick.
///
/// The breath part is evaluated from a [`BreathWave`] and a phase counter kept with the tick
/// (no division per tick); the values equal [`value`]'s for every tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    program: Program,
    /// Flow at the start of run mode, slm (for [`Program::Hold`] and the demo's first part).
    start: f32,
    /// Ticks since the start.
    tick: u32,
    /// The breaths of the program ([`Program::Breath`], the demo's [`DEMO_BREATH`]).
    wave: BreathWave,
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

/// The program's breaths and the tick they start at (`u32::MAX`: none).
fn breaths(program: Program) -> (BreathWave, u32) {
    match program {
        Program::Breath(w) => (w, 0),
        Program::Demo => (DEMO_WAVE, DEMO_HOLD_TICKS + demo_steps_ticks()),
        _ => (DEMO_WAVE, u32::MAX),
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
            phase: 0,
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
        let n = self.wave.period;
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
            if self.phase >= self.wave.period {
                self.phase = 0;
            }
        }
        v
    }
}

/// The setpoint of `program` at `tick` (ticks since the start), for a start flow `start`: the
/// definition [`Setpoint`] follows (host tools regenerate a run's setpoints with it).
pub fn value(program: Program, start: f32, tick: u32) -> f32 {
    let (wave, from) = breaths(program);
    if tick < from {
        return before_breaths(program, start, tick);
    }
    wave.at_phase((tick - from) % wave.period)
}

/// [`value`] before the program's breaths.
fn before_breaths(program: Program, start: f32, tick: u32) -> f32 {
    match program {
        Program::Hold | Program::Breath(_) => start,
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
