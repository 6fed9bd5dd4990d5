//! Run mode: the flow controller tracking the setpoint program, with the model monitor and the
//! tracking figures; with a volume program, the exhalation valve's state and the per-breath
//! bookkeeping ([`crate::ventilation`], after the PWM write).

use ridge_core::control::{Controller, Design};
use ridge_core::ArxModel;

use crate::event::Event;
use crate::monitor::Monitor;
use crate::setpoint::{Program, Setpoint};
use crate::tracking::Tracking;
use crate::units::{DUTY_FULL_SCALE, FRACTION_PER_DUTY, SLM_PER_COUNT};
use crate::ventilation::{Anchor, Valve, Ventilation};

use super::Config;

/// Everything run mode keeps.
#[derive(Debug, Clone)]
pub(super) struct RunMode {
    monitor: Monitor,
    ctrl: Controller<f32>,
    setpoint: Setpoint,
    tracking: Tracking,
    /// The setpoint of the interval in progress (for the tracking figures), slm.
    current: f32,
    /// Ticks the controller sees the program ahead of time: the mean delay of the designed
    /// setpoint response ([`Design::mean_delay`]), so that the flow follows the program in time.
    preview: u8,
    /// A volume program's breath phase of the interval in progress and whether it is in the
    /// inspiration (the valve closed); `None` for other programs.
    breath: Option<(bool, u32)>,
    /// The setpoint of the interval that ended with this tick's reading, slm.
    ended: f32,
    /// The per-breath bookkeeping of a volume program.
    vent: Ventilation,
    /// The duty applied during the interval that ended with this tick's reading, 1/10 000.
    applied: u16,
}

impl RunMode {
    /// Run mode with `design` for `model`, tracking `program`, starting bumplessly from the
    /// duty `applied` and the reading `counts`.
    #[inline(never)]
    pub(super) fn new(
        cfg: &Config,
        model: ArxModel<f32>,
        design: &Design<f32>,
        program: Program,
        applied: u16,
        counts: i16,
    ) -> Self {
        let c = &cfg.control;
        let mut ctrl = Controller::new(design.rst, c.limits());
        let y0 = f32::from(counts) * SLM_PER_COUNT;
        ctrl.start(f32::from(applied) * FRACTION_PER_DUTY, y0);
        RunMode {
            monitor: Monitor::new(model, cfg.monitor),
            ctrl,
            setpoint: Setpoint::new(program, y0),
            // Half a window out of step with the monitor's lines.
            tracking: Tracking::new(c.tracking, c.tracking.window / 2),
            current: y0,
            preview: preview_ticks(design.mean_delay(&model)),
            breath: None,
            ended: y0,
            vent: ventilation_for(program),
            applied,
        }
    }

    /// One tick: the duty `applied` during the interval that ended with `reading` (counts;
    /// `None` after a sensor error, `last` is then the held reading). Returns the duty for the
    /// next interval; puts at most one event into `event`, which must be empty (the
    /// monitor's; the tracking's waits a tick when both fall on the same tick). Events are
    /// written in place, not returned and moved: each move of a 74-byte event costs ~550
    /// cycles of the ATmega2560's control tick.
    pub(super) fn step(
        &mut self,
        applied: u16,
        reading: Option<i16>,
        last: i16,
        event: &mut Option<Event>,
    ) -> u16 {
        self.applied = applied;
        let y = f32::from(reading.unwrap_or(last)) * SLM_PER_COUNT;
        let ahead = self.setpoint.ahead(u32::from(self.preview));
        self.breath = self.setpoint.volume_phase();
        let r = self.setpoint.advance();
        let u = self.ctrl.step(ahead, y);
        let duty = (u * f32::from(DUTY_FULL_SCALE) + 0.5) as u16;
        let measured = reading.map(|c| f32::from(c) * SLM_PER_COUNT);
        self.monitor.step(applied, reading, event);
        self.tracking.step(self.current, measured, applied, event);
        self.ended = self.current;
        self.current = r;
        duty.min(DUTY_FULL_SCALE)
    }

    /// After the tick's PWM write: a volume program's per-breath bookkeeping with the tick's
    /// reading `reading` (counts, held over sensor errors); its event into `event` if empty.
    /// Returns what the fault checks take from the tick, with the duty applied during the
    /// interval that ended with the reading.
    pub(super) fn after_pwm(
        &mut self,
        reading: i16,
        event: &mut Option<Event>,
    ) -> Option<(Anchor, u16)> {
        let (_, phase) = self.breath?;
        self.vent
            .after_pwm(&mut self.setpoint, phase, reading, self.ended, event)
            .map(|a| (a, self.applied))
    }

    /// The exhalation valve for the interval in progress: closed in a volume breath's
    /// inspiration, open otherwise.
    pub(super) fn valve(&self) -> Valve {
        match self.breath {
            Some((true, _)) => Valve::Closed,
            _ => Valve::Open,
        }
    }

    /// Tracks `program` from now on, starting from the setpoint in progress.
    pub(super) fn set_program(&mut self, program: Program) {
        self.setpoint = Setpoint::new(program, self.current);
        self.vent = ventilation_for(program);
    }

    /// The controller.
    pub(super) fn controller(&self) -> &Controller<f32> {
        &self.ctrl
    }

    /// Whether the tracking alarm is raised.
    pub(super) fn alarm(&self) -> bool {
        self.tracking.alarm()
    }

    /// The setpoint of the interval in progress, slm.
    pub(super) fn setpoint(&self) -> f32 {
        self.current
    }

    /// Ticks of setpoint preview.
    pub(super) fn preview(&self) -> u8 {
        self.preview
    }
}

/// The per-breath bookkeeping for `program` (idle unless it is a volume program).
fn ventilation_for(program: Program) -> Ventilation {
    match program {
        Program::Volume(b) => Ventilation::new(b.tidal),
        _ => Ventilation::new(0.0),
    }
}

/// Whole ticks of setpoint preview for a mean delay of `delay` samples
/// ([`Design::mean_delay`]): rounded, within 0..=255 (`as` saturates), 0 when NaN.
pub fn preview_ticks(delay: f32) -> u8 {
    (delay + 0.5) as u8
}
