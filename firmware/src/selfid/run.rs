//! Run mode: the flow controller tracking the setpoint program through the static map, with the
//! model monitor and the tracking figures.
//!
//! The model is Hammerstein (see [`crate::selfid`]): the map `v = g(u)` from duty to flow, then
//! the ARX dynamics from `v` to the measured flow. The controller is designed on the dynamics,
//! so its output is a flow `v` (slm); the duty is the map's inverse at `v` within the duty
//! limits and the rate limit ([`MapTable::inverse`]: segment compares and one fixed-point
//! product, no division), and the controller's memory gets the map's flow at the duty actually
//! applied (its anti-windup follows what the pump did).
//!
//! A tick is split at the PWM write, so that only what sets this tick's duty delays it:
//! [`RunMode::control`] (setpoint, controller output, inverse, limits) before, and
//! [`RunMode::after_write`] (the map's flow at the written duty for the controller, the monitor,
//! the tracking figures, the flow the fault checks expect next) after.
//!
//! With a volume program run mode also gives the exhalation valve's state for the interval in
//! progress ([`RunMode::valve`]) and keeps the per-breath bookkeeping ([`crate::ventilation`],
//! [`RunMode::after_pwm`], after the PWM write too); the breaths' duty goes through the map's
//! inverse like any other program's.

use ridge_core::control::{Controller, Design, Limits};
use ridge_core::{ArxModel, MapTable};

use crate::event::Event;
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
use crate::event::{ControlRefusal, ReidReport, ReidVerdict};
use crate::monitor::Monitor;
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
use crate::reid::Reid;
use crate::setpoint::{Program, Setpoint};
use crate::tracking::Tracking;
use crate::units::{DUTY_FULL_SCALE, FLOW_SCALE, SLM_PER_COUNT};
use crate::ventilation::{Anchor, Valve, Ventilation};

use super::Config;

/// Everything run mode keeps.
#[derive(Debug, Clone)]
pub(super) struct RunMode {
    monitor: Monitor,
    ctrl: Controller<f32>,
    /// The static map, prepared for the tick.
    table: MapTable,
    setpoint: Setpoint,
    tracking: Tracking,
    /// The setpoint of the interval in progress (for the tracking figures), slm.
    current: f32,
    /// The setpoint of the interval the written duty starts (`current` after the write), slm.
    next: f32,
    /// Ticks the controller sees the program ahead of time: the mean delay of the designed
    /// setpoint response ([`Design::mean_delay`]), so that the flow follows the program in time.
    preview: u8,
    /// Duty limits, 1/10 000: lowest, highest, largest change per tick.
    duty_min: u16,
    duty_max: u16,
    duty_step: u16,
    /// The duty applied during the interval that ended with the tick's reading, and that
    /// reading (counts; `None` after a sensor error): for [`after_write`](Self::after_write).
    applied: u16,
    reading: Option<i16>,
    /// The map's flow at `applied`, slm (the model's input for that interval).
    v: f32,
    /// The model's steady state through the map: flow = `gain · g(u) + offset` (counts).
    gain: f32,
    offset: f32,
    /// A volume program's breath phase of the interval in progress and whether it is in the
    /// inspiration (the valve closed); `None` for other programs.
    breath: Option<(bool, u32)>,
    /// The setpoint of the interval that ended with this tick's reading, slm.
    ended: f32,
    /// The per-breath bookkeeping of a volume program.
    vent: Ventilation,
}

/// Run mode's re-identification while a volume program runs ([`crate::reid`]; on the
/// ATmega2560 only with the feature `atmega2560-reid`, over its flash budget: docs/boards.md)
/// and its swap. The state machine keeps it beside its phase, not in run mode, and
/// [`start`](Self::start)s it in place when run mode starts: in run mode it was built in a
/// stack frame and copied with it (2.9 KB; the ATmega2560 has 8 KB of SRAM).
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
#[derive(Debug, Clone)]
pub(super) struct Reidentification {
    reid: Reid,
    /// The re-estimate accepted for a swap, waiting for its design
    /// ([`Reidentification::take_candidate`]).
    candidate: Option<ArxModel<f32>>,
    /// The designed swap, waiting for the breath boundary as the controller sees it.
    swap: Option<(ArxModel<f32>, Design<f32>)>,
    /// The regulation speed of the design run mode started with ([`Design::tau`], s): the
    /// re-designs' (docs/ventilation.md: the default speed, from a re-estimate's slow pole,
    /// made loops 0.54–4.96 times slower and the breaths short).
    speed: f32,
}

impl RunMode {
    /// Run mode with `design` for `model` on the map `table`, tracking `program`, starting
    /// bumplessly from the duty `applied` and the reading `counts`; `gain` is the model's
    /// static gain.
    ///
    /// Out of line in the default ATmega2560 image; in its caller's frame with the
    /// re-identification (the state machine then lives in `main`'s frame, and this saved
    /// 0.5 KB of that image's deepest stack: docs/boards.md).
    #[cfg_attr(
        all(target_arch = "avr", not(feature = "atmega2560-reid")),
        inline(never)
    )]
    #[cfg_attr(
        any(not(target_arch = "avr"), feature = "atmega2560-reid"),
        inline(always)
    )]
    pub(super) fn new(
        cfg: &Config,
        model: ArxModel<f32>,
        table: MapTable,
        design: &Design<f32>,
        program: Program,
        applied: u16,
        counts: i16,
    ) -> Self {
        let c = &cfg.control;
        let slm = |duty: u16| f32::from(table.at(duty)) * SLM_PER_COUNT;
        let duty_max = c.duty_max.min(DUTY_FULL_SCALE);
        // The controller's limits in its own unit, the map's flow: the duty limits through the
        // map (it is increasing). The rate limit is the duty's, applied after the inverse.
        let limits = Limits {
            min: slm(c.duty_min),
            max: slm(duty_max),
            max_step: f32::MAX,
        };
        let mut ctrl = Controller::new(design.rst, limits);
        let y0 = f32::from(counts) * SLM_PER_COUNT;
        let v = slm(applied);
        ctrl.start(v, y0);
        let (gain, offset) = steady_state(&model);
        RunMode {
            monitor: Monitor::new(model, cfg.monitor, matches!(program, Program::Volume(_))),
            ctrl,
            table,
            setpoint: Setpoint::new(program, y0),
            // Half a window out of step with the monitor's lines.
            tracking: Tracking::new(c.tracking, c.tracking.window / 2),
            current: y0,
            next: y0,
            preview: preview_ticks(design.mean_delay(&model)),
            duty_min: c.duty_min,
            duty_max,
            duty_step: c.duty_step,
            applied,
            reading: None,
            v,
            gain,
            offset,
            breath: None,
            ended: y0,
            vent: ventilation_for(program),
        }
    }

    /// The part of a tick before the PWM write: the duty `applied` during the interval that
    /// ended with `reading` (counts; `None` after a sensor error, `last` is then the held
    /// reading). Returns the duty for the next interval: the map's inverse at the controller's
    /// output, within the duty limits and at most the rate limit from `applied` (`applied`
    /// again when the output is not finite).
    pub(super) fn control(&mut self, applied: u16, reading: Option<i16>, last: i16) -> u16 {
        self.applied = applied;
        self.reading = reading;
        let y = f32::from(reading.unwrap_or(last)) * SLM_PER_COUNT;
        let ahead = self.setpoint.ahead(u32::from(self.preview));
        self.breath = self.setpoint.volume_phase();
        self.next = self.setpoint.advance();
        let v = self.ctrl.output(ahead, y);
        duty_for_flow(
            &self.table,
            v,
            applied,
            self.duty_min,
            self.duty_max,
            self.duty_step,
        )
    }

    /// The part of a tick after the PWM write of `written` (the duty [`control`](Self::control)
    /// returned, or 0 after a fault): the controller's memory takes the map's flow at it, the
    /// monitor and the tracking take the interval that ended. Puts at most one event into
    /// `event`, which must be empty (the monitor's; the tracking's waits a tick when both fall
    /// on the same tick). Returns the flow the fault checks expect at `written` (counts): the
    /// model's steady state there.
    pub(super) fn after_write(&mut self, written: u16, event: &mut Option<Event>) -> i16 {
        let counts = self.table.at(written);
        let v = f32::from(counts) * SLM_PER_COUNT;
        self.ctrl.commit(v);
        let measured = self.reading.map(|c| f32::from(c) * SLM_PER_COUNT);
        self.monitor.step(self.applied, self.v, self.reading, event);
        self.tracking
            .step(self.current, measured, self.applied, event);
        self.ended = self.current;
        self.current = self.next;
        self.v = v;
        // `as` saturates (and maps NaN to 0).
        (self.gain * f32::from(counts) + self.offset) as i16
    }

    /// After the tick's PWM write and [`after_write`](Self::after_write): a volume program's
    /// per-breath bookkeeping with the tick's reading `reading` (counts, held over sensor
    /// errors); one event into `event` if empty (the breath's). The re-identification follows
    /// ([`reidentify`](Self::reidentify)). Returns what the fault checks take from the tick,
    /// with the duty applied during the interval that ended with the reading.
    pub(super) fn after_pwm(
        &mut self,
        reading: i16,
        event: &mut Option<Event>,
    ) -> Option<(Anchor, u16)> {
        let (_, phase) = self.breath?;
        let anchor = self
            .vent
            .after_pwm(&mut self.setpoint, phase, reading, self.ended, event)
            .map(|a| (a, self.applied));
        if phase == 0 {
            self.monitor.breath_end();
        }
        anchor
    }

    /// The re-identification's tick after [`after_pwm`](Self::after_pwm) (see
    /// [`crate::reid`]): the breath boundary at a volume breath's phase 0, triggered by
    /// `drift` or an alarm, with the tick's reading `reading` (counts); its `REID` line into
    /// `event` if empty.
    ///
    /// Never inlined: the job's temporaries (a fit started, a hold-out, the estimate) then live
    /// in this frame, entered only from here, not in the board's tick's frame, which every
    /// other call of the tick stacks on (ATmega2560: see docs/boards.md for the frames).
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    #[inline(never)]
    pub(super) fn reidentify(
        &self,
        re: &mut Reidentification,
        reading: i16,
        drift: bool,
        event: &mut Option<Event>,
    ) {
        let Some((_, phase)) = self.breath else {
            return;
        };
        // Not in the program's lead-in: the window starts with breath 1.
        if self.vent.breath() == 0 {
            return;
        }
        let boundary = (phase == 0).then(|| self.vent.breath());
        let volume_alarm = self.vent.alarm();
        let trigger = drift || volume_alarm || self.tracking.alarm();
        let v = self.table.at(self.applied);
        if let Some(model) = re
            .reid
            .after_pwm(v, reading, boundary, trigger, volume_alarm)
        {
            re.candidate = Some(model);
        }
        // An accepted estimate's line waits for its re-design's verdict (`redesign`, in the
        // same pass): `accepted` once designed, `design` if refused.
        if event.is_none() && re.candidate.is_none() {
            *event = re.reid.take_report().map(Event::Reid);
        }
    }

    /// The design for the accepted re-estimate `model` was refused (`why`): the running model
    /// and controller stay; the `REID … verdict=design why=…` line into `event` if empty, else
    /// at the next tick without another event.
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    pub(super) fn swap_refused(
        &self,
        re: &mut Reidentification,
        model: &ArxModel<f32>,
        why: ControlRefusal,
        event: &mut Option<Event>,
    ) {
        re.reid.report(ReidReport {
            breath: self.vent.breath(),
            verdict: ReidVerdict::Design(why),
            gain: model.static_gain(),
            fit: f32::NAN,
            running: f32::NAN,
            v_rms: f32::NAN,
        });
        if event.is_none() {
            *event = re.reid.take_report().map(Event::Reid);
        }
    }

    /// The designed swap of `re`, if one waits, at the breath boundary as the controller sees
    /// it (the setpoint it is given is the flat end of the expiration), before
    /// [`control`](Self::control) with the same `reading` and `last`: the new controller starts
    /// bumplessly at the map's flow of the applied duty and the reading, with its own preview;
    /// the monitor and the fault checks' steady state follow the new model.
    #[inline(never)]
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    pub(super) fn swap_at_boundary(
        &mut self,
        re: &mut Reidentification,
        reading: Option<i16>,
        last: i16,
    ) {
        if re.swap.is_none() {
            return;
        }
        let y = f32::from(reading.unwrap_or(last)) * SLM_PER_COUNT;
        // The coming interval's phase (the program has not advanced yet this tick).
        let (Some((_, phase)), Some(period)) =
            (self.setpoint.volume_phase(), self.setpoint.volume())
        else {
            return;
        };
        let period = u32::from(period.wave.period());
        if (phase + u32::from(self.preview)) % period.max(1) != 0 {
            return;
        }
        let Some((model, d)) = re.swap.take() else {
            return;
        };
        let limits = *self.ctrl.limits();
        let mut ctrl = Controller::new(d.rst, limits);
        ctrl.start(self.v, y);
        self.ctrl = ctrl;
        self.preview = preview_ticks(d.mean_delay(&model));
        self.monitor.set_model(model);
        let (gain, offset) = steady_state(&model);
        self.gain = gain;
        self.offset = offset;
        re.reid.swapped(model);
    }

    /// The exhalation valve for the interval in progress: closed in a volume breath's
    /// inspiration, open otherwise.
    pub(super) fn valve(&self) -> Valve {
        match self.breath {
            Some((true, _)) => Valve::Closed,
            _ => Valve::Open,
        }
    }

    /// Whether a volume program runs (its breaths against the PEEP valve and the lung: the
    /// map's steady state, identified without them, does not hold).
    pub(super) fn ventilating(&self) -> bool {
        self.breath.is_some()
    }

    /// Whether the program is a volume program (from its first tick, before
    /// [`ventilating`](Self::ventilating) says so).
    pub(super) fn volume_program(&self) -> bool {
        matches!(self.setpoint.program(), Program::Volume(_))
    }

    /// Tracks `program` from now on, starting from the setpoint in progress (the
    /// re-identification starts afresh, its held-out span the program's breath).
    pub(super) fn set_program(&mut self, program: Program) {
        self.setpoint = Setpoint::new(program, self.current);
        self.vent = ventilation_for(program);
        self.monitor
            .set_ventilating(matches!(program, Program::Volume(_)));
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

/// Ticks of a volume program's breath (0 for other programs): the re-identification's
/// held-out span.
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
fn breath_ticks(program: Program) -> u32 {
    match program {
        Program::Volume(b) => u32::from(b.wave.period()),
        _ => 0,
    }
}

#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
impl Reidentification {
    /// An idle one until run mode starts ([`crate::reid::Reid::dormant`]; its model a
    /// placeholder, [`ArxModel::zero`]).
    pub(super) fn dormant(cfg: &Config) -> Self {
        Reidentification {
            reid: cfg.dormant_reidentification(ArxModel::zero()),
            candidate: None,
            swap: None,
            speed: 0.0,
        }
    }

    /// Run mode starts with `design` for `model` tracking `program`: the re-identification of
    /// `model` from `cfg`, started afresh in place, no swap waiting.
    pub(super) fn start(
        &mut self,
        cfg: &Config,
        model: ArxModel<f32>,
        design: &Design<f32>,
        program: Program,
    ) {
        cfg.reset_reidentification(&mut self.reid, model, breath_ticks(program));
        self.candidate = None;
        self.swap = None;
        self.speed = design.tau;
    }

    /// Run mode tracks `program` from now on: the window emptied, a re-estimate in progress
    /// and a waiting swap dropped, the held-out span the program's breath.
    pub(super) fn restart(&mut self, program: Program) {
        self.reid.restart(breath_ticks(program));
        self.candidate = None;
        self.swap = None;
    }

    /// The regulation speed the re-designs use: the power-up design's `τ`, s.
    pub(super) fn speed(&self) -> f32 {
        self.speed
    }

    /// The re-estimate accepted for a swap, once: its controller is to be designed
    /// ([`set_swap`](Self::set_swap), or [`RunMode::swap_refused`]).
    pub(super) fn take_candidate(&mut self) -> Option<ArxModel<f32>> {
        self.candidate.take()
    }

    /// The design `d` for the accepted re-estimate `model`: swapped in at the next breath
    /// boundary as the controller sees it ([`RunMode::swap_at_boundary`]); its
    /// `REID … verdict=accepted` line into `event` if empty, else at the next tick without
    /// another event.
    pub(super) fn set_swap(
        &mut self,
        model: ArxModel<f32>,
        d: Design<f32>,
        event: &mut Option<Event>,
    ) {
        self.swap = Some((model, d));
        if event.is_none() {
            *event = self.reid.take_report().map(Event::Reid);
        }
    }
}

/// A model's steady state through the map: flow = `gain · g(u) + offset` (counts).
fn steady_state(model: &ArxModel<f32>) -> (f32, f32) {
    let mut sum_theta = 0.0;
    for t in model.theta() {
        sum_theta += *t;
    }
    (
        model.static_gain(),
        model.intercept() / (1.0 - sum_theta) * f32::from(FLOW_SCALE),
    )
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

/// Run mode's duty for the controller's output `v` (the map's flow, slm): the map's inverse at
/// `v`, within `duty_min..=duty_max` (1/10 000) and at most `duty_step` from `applied`;
/// `applied` again when `v` is not finite. The host's studies of run mode call it too.
#[inline(always)]
pub fn duty_for_flow(
    table: &MapTable,
    v: f32,
    applied: u16,
    duty_min: u16,
    duty_max: u16,
    duty_step: u16,
) -> u16 {
    if !v.is_finite() {
        return applied;
    }
    let lo = applied.saturating_sub(duty_step).max(duty_min);
    let hi = applied.saturating_add(duty_step).min(duty_max);
    // `as` saturates: a flow beyond the i16 counts lands on the duty limits.
    let counts = (v * f32::from(FLOW_SCALE)) as i16;
    // Not `clamp`: it panics when lo > hi (a start below the lowest duty's step).
    table.inverse(counts).max(lo).min(hi)
}
