//! Run mode's closed-loop re-identification while a volume program ventilates: the running
//! model's structure re-estimated from the loop's own data (`ridge_core::reid`), checked, and
//! reported on a `REID` line; the estimate that passes and finds the running model no longer
//! describing the lung is handed to run mode for a swap at a breath boundary.
//!
//! Everything here runs after the tick's PWM write ([`Reid::after_pwm`], called by run mode):
//! - **Statistics**: every tick, `(v, y)` in counts into a [`Window`] of the running model's
//!   structure and intercept: `v` the map's flow at the duty applied during the interval that
//!   ended with the reading `y` (what the controller's memory takes); forgetting at each
//!   breath's start by [`SHIFT`] (`λ = 3/4` a breath).
//! - **Trigger**: at a breath boundary with no re-estimate running, when the monitor raised
//!   `DRIFT`, a volume or tracking alarm is on, or [`ReidConfig::every`] breaths passed since
//!   the last start.
//! - **Fit**: the snapshot is of the window as the boundary's tick leaves it, taken over the
//!   two ticks after it ([`Refit::begin`] and [`Refit::take_rows`], then
//!   [`Refit::take_responses`]) while those ticks' samples are held back ([`HELD_MAX`]) and
//!   pushed on the third; one unit ([`Refit::step`]`(1)`) a tick, as if the first had run in
//!   the boundary's tick (two units the tick after it), so that every unit and the fit's end
//!   fall on the ticks they would with the whole snapshot in the boundary's tick. The checks
//!   of a finished fit run in the tick after its last unit, before that tick's sample, the
//!   held-out breath's first. On the ATmega2560 none of this shares a tick with another
//!   large part: the boundary's tick has the window's update and a verdict, not the snapshot
//!   (docs/boards.md, the opt-in image's ticks).
//! - **Checks**: [`Acceptance::check_estimate`] (the window excited, the design's model check),
//!   then the breath after the snapshot held out ([`Holdout`]): the estimate's free-run fit at
//!   least `min_fit` and at least the running model's ([`Acceptance::judge`]).
//! - **Swap rule** ([`SwapRule`], [`ReidConfig::swap`]): by default an estimate that passes
//!   replaces the running model only while the volume alarm is raised when its verdict comes
//!   (the breaths are failing); otherwise it is reported (`kept`) and the running controller
//!   stays. The re-designed controller tracks worse than the power-up one on the lung the
//!   power-up saw, and after the ISO lung changes the power-up controller with the volume trim
//!   meets every volume target (docs/ventilation.md, "Why the re-designed controller loses
//!   volume"), so a better fit alone is no reason to swap.
//!
//! Any fault ends run mode and with it the re-estimate (the state lives in run mode).
//!
//! Memory: the window's storage for the largest structure ([`WINDOW_LEN_MAX`] `i64`), one of a
//! [`Refit`] or a [`Holdout`] at a time (never both), and [`HELD_MAX`] held-back samples.

use ridge_core::reid::{
    Acceptance, Holdout, Refit, RefitStep, Rejection, Window, WindowState, WINDOW_LEN_MAX,
};
use ridge_core::{ArxModel, RidgeM};

use crate::event::{ReidReport, ReidVerdict};
use crate::units::{MODEL_SCALE, SLM_PER_COUNT};

/// The window's forgetting per breath, `λ = 1 − 2^{−SHIFT}` = 3/4 (docs/control.md: no window
/// length is better in the bias table, and this one forgets a lung change twice as fast as
/// `λ = 7/8`).
pub const SHIFT: u8 = 2;

/// The re-identification's settings ([`Config::reid`](crate::selfid::Config::reid)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReidConfig {
    /// A re-estimate starts at least every this many breaths (and at once on a drift or an
    /// alarm); default 1, as the study (docs/control.md) re-estimated.
    pub every: u32,
    /// The smallest RMS of the window's input (the map's flow) about its mean, slm (default
    /// 5): square breaths move it by 22 slm RMS on the adult lung, a constant setpoint by
    /// 2.3–2.7 (the sensor noise fed back), whose estimates rise 20 % too fast
    /// (docs/control.md).
    pub min_input_response: f32,
    /// When a passing estimate replaces the running model (default
    /// [`SwapRule::VolumeAlarm`]).
    pub swap: SwapRule,
}

impl ReidConfig {
    /// The defaults (see each field).
    pub const DEFAULT: ReidConfig = ReidConfig {
        every: 1,
        min_input_response: 5.0,
        swap: SwapRule::VolumeAlarm,
    };
}

/// When an estimate that passed its checks replaces the running model ([`ReidConfig::swap`]);
/// it is reported `accepted` then, `kept` otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SwapRule {
    /// Never: the re-estimates are made, judged and reported, the power-up controller runs on.
    Never,
    /// Only while the volume alarm (`ALARM volume`: 2 breaths in a row outside
    /// ±(4 mL + 15 %)) is raised when the estimate's verdict comes. The default: on the host
    /// benchmark's 12 lung changes it meets every volume target where swapping every passing
    /// estimate misses the ±(4 mL + 5 %) band on 9 (docs/ventilation.md, policy (ii)).
    VolumeAlarm,
    /// Only when the running model's free-run fit on the held-out breath is below this,
    /// percent (it no longer describes the lung). On the STM32F411 image
    /// (`stm32-harness/tests/reid.rs`) the power-up model's held-out fit on the adult lung's
    /// breaths was −23 to −11 % (identified without the PEEP and exhalation valves): no
    /// threshold keeps the adult lung's controller and swaps on the stiff one.
    BelowFit(f32),
}

impl SwapRule {
    /// Whether a passing estimate is swapped in: `volume_alarm` whether the volume alarm is
    /// raised, `running_fit` the running model's held-out fit, percent.
    pub fn allows(self, volume_alarm: bool, running_fit: f32) -> bool {
        match self {
            SwapRule::Never => false,
            SwapRule::VolumeAlarm => volume_alarm,
            SwapRule::BelowFit(below) => running_fit < below,
        }
    }
}

/// Ticks whose samples are held back from the window while a snapshot of it is taken: the two
/// after a breath boundary's (the snapshot's two parts); they go in on the third.
pub const HELD_MAX: usize = 2;

/// Where the current re-estimate stands.
// One of the two at a time, in run mode's static storage.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
enum Job {
    Idle,
    /// A snapshot of the window as the start of breath `breath` left it, begun next tick.
    Due {
        breath: u32,
    },
    /// The fit of the snapshot taken at the start of breath `breath`; `responses` whether the
    /// snapshot's second part is taken (the window's samples are held back until then).
    Fitting {
        refit: Refit<f32>,
        breath: u32,
        responses: bool,
    },
    /// The estimate `model` scored on the breath after its snapshot.
    HoldingOut {
        holdout: Holdout<f32>,
        model: ArxModel<f32>,
        breath: u32,
        v_rms: f32,
    },
}

/// The re-identification's state (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct Reid {
    store: [i64; WINDOW_LEN_MAX],
    /// The window, detached from `store`; `None` when the running model's structure has none.
    window: Option<WindowState>,
    job: Job,
    method: RidgeM<f32>,
    accept: Acceptance<f32>,
    /// The running model.
    running: ArxModel<f32>,
    /// Breaths since the last re-estimate started.
    since: u32,
    /// Re-estimate at least every this many breaths, and the swap rule ([`ReidConfig`]).
    every: u32,
    swap: SwapRule,
    /// A report waiting for a tick without another event.
    due: Option<ReidReport>,
    /// Samples `(v, y, boundary)` held back from the window while its snapshot is taken, in
    /// order; the first `held_len`.
    held: [(i16, i16, bool); HELD_MAX],
    held_len: u8,
}

impl Reid {
    /// Re-identification of `running`'s structure and intercept with the estimator `method`,
    /// the checks `accept` (its `holdout_min` ticks held out: one breath) and `cfg`'s trigger
    /// and swap rule. Run mode builds them from its settings
    /// ([`crate::selfid::Config::reidentification`]).
    pub fn new(
        method: RidgeM<f32>,
        accept: Acceptance<f32>,
        cfg: &ReidConfig,
        running: ArxModel<f32>,
    ) -> Self {
        let mut store = [0i64; WINDOW_LEN_MAX];
        let window = Window::new(running.structure(), running.offset(), SHIFT, &mut store)
            .ok()
            .map(Window::detach);
        Reid {
            store,
            window,
            job: Job::Idle,
            method,
            accept,
            running,
            since: 0,
            every: cfg.every,
            swap: cfg.swap,
            due: None,
            held: [(0, 0, false); HELD_MAX],
            held_len: 0,
        }
    }

    /// The running model.
    pub fn running(&self) -> &ArxModel<f32> {
        &self.running
    }

    /// The model swapped in: it runs from now on (the window goes on: same structure).
    pub fn swapped(&mut self, model: ArxModel<f32>) {
        self.running = model;
    }

    /// Starts afresh (a new program): the window emptied, a re-estimate in progress dropped, the
    /// held-out span `holdout` ticks.
    pub fn restart(&mut self, holdout: u32) {
        if let Some(state) = self.window {
            if let Ok(mut w) = Window::attach(state, &mut self.store) {
                w.clear();
                self.window = Some(w.detach());
            }
        }
        self.job = Job::Idle;
        self.since = 0;
        self.due = None;
        self.held_len = 0;
        self.accept.holdout_min = holdout;
    }

    /// Whether a re-estimate is in progress.
    pub fn busy(&self) -> bool {
        !matches!(self.job, Job::Idle)
    }

    /// One tick after the PWM write: `v` the map's flow at the duty applied during the interval
    /// that ended with the reading `y` (both counts); `boundary` the breath number when this
    /// tick starts a breath, `trigger` whether a drift or an alarm is on, `volume_alarm`
    /// whether the volume alarm is (for the swap rule). Returns the estimate to swap in (at the
    /// next breath boundary as the controller sees it), if one passed the swap rule; its report
    /// waits in [`take_report`](Self::take_report). The work of a tick is bounded (see the
    /// [module docs](self)): the window's update (with at most [`HELD_MAX`] held-back samples),
    /// and one of a verdict, a part of the snapshot with two units, a finished fit's checks, a
    /// unit or a held-out sample.
    pub fn after_pwm(
        &mut self,
        v: i16,
        y: i16,
        boundary: Option<u32>,
        trigger: bool,
        volume_alarm: bool,
    ) -> Option<ArxModel<f32>> {
        self.update_window(v, y, boundary.is_some())?;
        // A fit whose last unit ran last tick: its checks (its held-out breath starts now).
        self.finish_fit();
        let mut swap = None;
        if boundary.is_some() {
            self.since = self.since.saturating_add(1);
            swap = self.judge(volume_alarm);
        }
        let (u, y) = (f32::from(v) * SLM_PER_COUNT, f32::from(y) * SLM_PER_COUNT);
        self.step(u, y);
        if let Some(breath) = boundary {
            if matches!(self.job, Job::Idle) && (trigger || self.since >= self.every) {
                self.job = Job::Due { breath };
            }
        }
        swap
    }

    /// The window's update with the sample `(v, y)` (`boundary`: forgetting after it), held
    /// back while a snapshot of the window is being taken; otherwise the held-back samples go
    /// in first, in order. `None` when the running model's structure has no window.
    #[inline(never)]
    fn update_window(&mut self, v: i16, y: i16, boundary: bool) -> Option<()> {
        let state = self.window?;
        let snapshot = matches!(
            self.job,
            Job::Due { .. }
                | Job::Fitting {
                    responses: false,
                    ..
                }
        );
        let held = usize::from(self.held_len);
        if snapshot && held < HELD_MAX {
            if let Some(slot) = self.held.get_mut(held) {
                *slot = (v, y, boundary);
                self.held_len += 1;
                return Some(());
            }
        }
        let Ok(mut window) = Window::attach(state, &mut self.store) else {
            self.window = None;
            return None;
        };
        let sample = (v, y, boundary);
        for &(v, y, boundary) in self.held.iter().take(held).chain(Some(&sample)) {
            // A row that could overflow is refused and changes nothing but the lag history.
            window.push(v, y).ok();
            if boundary {
                window.end_breath();
            }
        }
        self.held_len = 0;
        self.window = Some(window.detach());
        Some(())
    }

    /// A report waiting to be printed, once; none in the two ticks that take a snapshot (the
    /// largest parts of the re-estimate: a line printed beside them would make the longest
    /// tick), it waits for the next.
    pub fn take_report(&mut self) -> Option<ReidReport> {
        if matches!(
            self.job,
            Job::Due { .. }
                | Job::Fitting {
                    responses: false,
                    ..
                }
        ) {
            return None;
        }
        self.due.take()
    }

    /// The verdict of run mode's re-design for the accepted estimate (`design`: refused),
    /// put where [`take_report`](Self::take_report) finds it. One re-estimate runs at a time
    /// and run mode holds an accepted estimate's line until its re-design's verdict, so the
    /// report waiting is this estimate's `accepted`: the refusal takes its place (one line per
    /// re-estimate), and nothing is dropped when the tick already has an event.
    pub fn report(&mut self, report: ReidReport) {
        self.due = Some(report);
    }

    /// This tick's part of the re-estimate: the snapshot's first part and two units, its
    /// second part and a unit, a unit, or one held-out sample `(u, y)` (slm).
    #[inline(never)]
    fn step(&mut self, u: f32, y: f32) {
        let units = match &mut self.job {
            Job::Idle => return,
            Job::HoldingOut { holdout, .. } => {
                holdout.push(u, y);
                return;
            }
            Job::Due { breath } => {
                let breath = *breath;
                self.job = Job::Idle;
                let Some(state) = self.window else {
                    return;
                };
                let Ok(window) = Window::attach(state, &mut self.store) else {
                    return;
                };
                // A window too short for the structure starts nothing (the next boundary tries).
                let Ok(refit) = Refit::begin(&window, self.method) else {
                    return;
                };
                // Built in place: a `Refit` is 700 bytes, each move of it 6 k cycles here.
                self.job = Job::Fitting {
                    refit,
                    breath,
                    responses: false,
                };
                let Job::Fitting { refit, .. } = &mut self.job else {
                    return;
                };
                if refit.take_rows(&window, &MODEL_SCALE).is_err() {
                    self.job = Job::Idle;
                    return;
                }
                self.since = 0;
                // This unit and the one the boundary's tick did not run.
                2
            }
            Job::Fitting {
                refit, responses, ..
            } => {
                if !*responses {
                    // Never an error with the window held back; were it one, the responses
                    // would stay zero and the estimate be refused as not excited.
                    let _ = self
                        .window
                        .ok_or(ridge_core::Error::InvalidStructure)
                        .and_then(|state| Window::attach(state, &mut self.store))
                        .and_then(|window| refit.take_responses(&window, &MODEL_SCALE));
                    *responses = true;
                }
                1
            }
        };
        if let Job::Fitting { refit, .. } = &mut self.job {
            refit.step(units);
        }
    }

    /// The checks of a fit whose last unit ran (the estimate held out from now on, or
    /// refused with its report); nothing for a fit still working or another job.
    #[inline(never)]
    fn finish_fit(&mut self) {
        // No work: where the fit stands.
        let (now, breath, response, v_rms) = match &self.job {
            Job::Fitting {
                refit,
                breath,
                responses: true,
            } => (
                refit.outcome(),
                *breath,
                refit.response(),
                refit.input_response(),
            ),
            _ => return,
        };
        match now {
            RefitStep::Working => {}
            RefitStep::Done(model, _) => {
                match self.accept.check_estimate(&model, response, v_rms) {
                    Ok(_) => {
                        self.job = Job::HoldingOut {
                            holdout: Holdout::new(model, self.running),
                            model,
                            breath,
                            v_rms,
                        }
                    }
                    Err(why) => self.refused(breath, &model, v_rms, &why),
                }
            }
            RefitStep::Refused(_) => {
                self.due = Some(ReidReport {
                    breath,
                    verdict: ReidVerdict::Numeric,
                    gain: f32::NAN,
                    fit: f32::NAN,
                    running: f32::NAN,
                    v_rms,
                });
                self.job = Job::Idle;
            }
        }
    }

    /// A refused estimate: its report, nothing else changes.
    fn refused(&mut self, breath: u32, model: &ArxModel<f32>, v_rms: f32, why: &Rejection<f32>) {
        let (verdict, fit, running) = match why {
            Rejection::Model(_) => (ReidVerdict::Model, f32::NAN, f32::NAN),
            Rejection::NotExcited { .. } => (ReidVerdict::NotExcited, f32::NAN, f32::NAN),
            Rejection::Fit { candidate, running } => (ReidVerdict::Fit, *candidate, *running),
            Rejection::TooFewHeldOut { .. } => (ReidVerdict::Fit, f32::NAN, f32::NAN),
        };
        self.due = Some(ReidReport {
            breath,
            verdict,
            gain: model.static_gain(),
            fit,
            running,
            v_rms,
        });
        self.job = Job::Idle;
    }

    /// At a breath boundary: the verdict of a held-out estimate once a breath of samples is
    /// scored (`volume_alarm` for the swap rule); the estimate when it is to be swapped in.
    fn judge(&mut self, volume_alarm: bool) -> Option<ArxModel<f32>> {
        let Job::HoldingOut {
            holdout,
            model,
            breath,
            v_rms,
        } = &self.job
        else {
            return None;
        };
        let (model, breath, v_rms) = (*model, *breath, *v_rms);
        if holdout.scored() < self.accept.holdout_min {
            return None;
        }
        match self.accept.judge(holdout) {
            Ok(v) => {
                let swap = self.swap.allows(volume_alarm, v.running.fit);
                self.due = Some(ReidReport {
                    breath,
                    verdict: if swap {
                        ReidVerdict::Accepted
                    } else {
                        ReidVerdict::Kept
                    },
                    gain: model.static_gain(),
                    fit: v.candidate.fit,
                    running: v.running.fit,
                    v_rms,
                });
                self.job = Job::Idle;
                swap.then_some(model)
            }
            Err(why) => {
                self.refused(breath, &model, v_rms, &why);
                None
            }
        }
    }
}

// Built in place: run mode keeps the re-identification beside its phase, not in it, so that
// starting run mode does not build 1.8 KB in a stack frame and copy it (the ATmega2560's SRAM;
// docs/boards.md).
impl Reid {
    /// An idle re-identification with no window (it takes no samples and starts nothing) for
    /// `running`, until [`reset`](Self::reset): what the state machine holds before run mode.
    /// Built without the window's storage in the frame (it is zeros until `reset`).
    pub fn dormant(
        method: RidgeM<f32>,
        accept: Acceptance<f32>,
        cfg: &ReidConfig,
        running: ArxModel<f32>,
    ) -> Self {
        Reid {
            store: [0; WINDOW_LEN_MAX],
            window: None,
            job: Job::Idle,
            method,
            accept,
            running,
            since: 0,
            every: cfg.every,
            swap: cfg.swap,
            due: None,
            held: [(0, 0, false); HELD_MAX],
            held_len: 0,
        }
    }

    /// Makes this what [`Reid::new`] with the same arguments builds, in place (its storage
    /// reused: no copy of it in the caller's frame).
    pub fn reset(
        &mut self,
        method: RidgeM<f32>,
        accept: Acceptance<f32>,
        cfg: &ReidConfig,
        running: ArxModel<f32>,
    ) {
        self.store = [0; WINDOW_LEN_MAX];
        self.window = Window::new(
            running.structure(),
            running.offset(),
            SHIFT,
            &mut self.store,
        )
        .ok()
        .map(Window::detach);
        self.job = Job::Idle;
        self.method = method;
        self.accept = accept;
        self.running = running;
        self.since = 0;
        self.every = cfg.every;
        self.swap = cfg.swap;
        self.due = None;
        self.held_len = 0;
    }
}
