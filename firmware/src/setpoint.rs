//! Flow setpoints for run mode, one value per 10 ms tick, in slm: a constant, a sequence of
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
//! Everything is computed from the tick count in `f32`, no state but the counter: the
//! sequence is exactly repeatable, and a host tool regenerates it from the same code.

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
        let ok = |x: f32| x.is_finite() && x > 0.0;
        if !ok(self.rate) || self.rate > 60.0 {
            return Err("rate");
        }
        if !ok(self.ie) || self.ie > 10.0 {
            return Err("ie");
        }
        if !self.peak.is_finite() || !self.bias.is_finite() {
            return Err("flow");
        }
        if !self.rise.is_finite() || self.rise < 0.0 || self.rise > 0.5 * self.inspiration() {
            return Err("rise");
        }
        Ok(())
    }

    /// Breath period, s.
    pub fn period(&self) -> f32 {
        60.0 / self.rate
    }

    /// Inspiration time, s.
    pub fn inspiration(&self) -> f32 {
        self.period() / (1.0 + self.ie)
    }

    /// The setpoint `t` seconds into a breath (`0 ≤ t < period`), slm: `bias + (peak −
    /// bias) · f(t)` with `f` the rise (`t / rise`, at most 1) capped by the shape during the
    /// inspiration (square: 1; ramp: falling linearly from 1 at `rise` to 0 at `T_i`), and after
    /// it the square's fall (`1 − (t − T_i) / rise`, at least 0) or 0 for the ramp.
    pub fn at(&self, t: f32) -> f32 {
        self.level(t, self.inspiration())
    }

    /// [`at`](Self::at) with the inspiration time `ti` (s) already computed.
    fn level(&self, t: f32, ti: f32) -> f32 {
        // Comparisons rather than f32::min/max: those are 280 bytes of libm on the ATmega2560.
        let f = if t < ti {
            let mut f = 1.0;
            if t < self.rise {
                f = t / self.rise;
            }
            if self.shape == Shape::Ramp {
                let fall = if ti > self.rise {
                    1.0 - (t - self.rise) / (ti - self.rise)
                } else {
                    0.0
                };
                if fall < f {
                    f = fall;
                }
            }
            f
        } else if self.shape == Shape::Square && t - ti < self.rise {
            1.0 - (t - ti) / self.rise
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
    /// A sequence of levels, repeated.
    Steps(&'static [Level]),
    /// A breath profile, repeated.
    Breath(Breath),
    /// The demonstration: 2 s holding the start flow, [`DEMO_STEPS`] once, then
    /// [`DEMO_BREATH`] for ever.
    Demo,
}

/// A [`Program`] running: one setpoint per tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    program: Program,
    /// Flow at the start of run mode, slm (for [`Program::Hold`] and the demo's first part).
    start: f32,
    /// Ticks since the start.
    tick: u32,
}

/// Ticks the demo holds the start flow before its steps.
pub const DEMO_HOLD_TICKS: u32 = 200;

impl Setpoint {
    /// Starts `program` with `start_flow` (slm) as the flow at the start.
    pub fn new(program: Program, start_flow: f32) -> Self {
        Setpoint {
            program,
            start: start_flow,
            tick: 0,
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
        value(self.program, self.start, self.tick.saturating_add(ticks))
    }

    /// The setpoint for the coming tick (slm), and advances by one tick.
    pub fn advance(&mut self) -> f32 {
        let v = value(self.program, self.start, self.tick);
        self.tick = self.tick.saturating_add(1);
        v
    }
}

/// The setpoint of `program` at `tick` (ticks since the start), for a start flow `start`.
pub fn value(program: Program, start: f32, tick: u32) -> f32 {
    match program {
        Program::Hold => start,
        Program::Constant(v) => v,
        Program::Steps(levels) => steps_at(levels, tick),
        Program::Breath(b) => breath_at(&b, tick),
        Program::Demo => {
            if tick < DEMO_HOLD_TICKS {
                return start;
            }
            let t = tick - DEMO_HOLD_TICKS;
            let total: u32 = DEMO_STEPS.iter().map(|l| u32::from(l.ticks)).sum();
            if t < total {
                steps_at(DEMO_STEPS, t)
            } else {
                breath_at(&DEMO_BREATH, t - total)
            }
        }
    }
}

fn steps_at(levels: &[Level], tick: u32) -> f32 {
    let total: u32 = levels.iter().map(|l| u32::from(l.ticks)).sum();
    if total == 0 {
        return levels.first().map_or(0.0, |l| l.slm);
    }
    let mut t = tick % total;
    for l in levels {
        if t < u32::from(l.ticks) {
            return l.slm;
        }
        t -= u32::from(l.ticks);
    }
    levels.last().map_or(0.0, |l| l.slm)
}

fn breath_at(b: &Breath, tick: u32) -> f32 {
    let period = b.period();
    let period_ticks = (period * f32::from(SAMPLE_RATE_HZ) + 0.5) as u32;
    if period_ticks == 0 {
        return b.bias;
    }
    b.level((tick % period_ticks) as f32 * TS_S, period / (1.0 + b.ie))
}
