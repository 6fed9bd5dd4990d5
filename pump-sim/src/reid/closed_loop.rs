//! The closed loop's two sides, which the study ([`super::run`]) and the ventilation benchmark
//! ([`crate::vent_bench`]) both run: [`Running`], the firmware's controller through the static
//! map ([`Running::tick`]: run mode's step; [`Running::swapped`]: the bumpless swap,
//! [`Running::swapped_at`] with a given regulation speed, [`design_at`]), and [`Reestimation`],
//! the window, the re-estimate ([`Estimate`]), its hold-out and verdict, and the swap rule
//! ([`swap_allowed`]), as [`Rules`] and [`Mode`] say.

use ridge_core::control::Limits;
use ridge_core::control::{Controller, Design, DesignError};
use ridge_core::input_map::MapTable;
use ridge_core::reid::{window_len, Acceptance, Holdout, Refit, RefitStep, Rejection, Window};
use ridge_core::{ArxModel, RidgeM, Structure};
use ridge_pump_firmware::selfid::{duty_for_flow, preview_ticks, REFERENCE_POLE};
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, MODEL_SCALE, SLM_PER_COUNT};

use crate::baseline::experiment::{firmware_design, ExperimentError, EXPERIMENT_CONFIG};

/// What the loop does with the re-estimates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// No re-estimation: the power-up controller throughout.
    Frozen,
    /// Re-estimates and judges them, never swaps (the frozen controller's loop, observed).
    Observe,
    /// Re-estimates, judges, re-designs and swaps at a breath boundary.
    Adapt,
    /// As [`Mode::Adapt`], but each swap restarts the running model's own design: the swaps'
    /// restarts without their new models (the control experiment of the adaptive runs).
    Restart,
}
/// One re-estimate and what became of it.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The breath at whose start the window was snapshot.
    pub breath: u32,
    /// The window's weighted rows at the snapshot.
    pub weight: u32,
    /// The estimate, or why there is none (`Refit` refused it); `None` while (or if the run
    /// ended while) fitting.
    pub model: Option<Result<ArxModel<f32>, ridge_core::Error>>,
    /// Ridge-M iterates.
    pub iterations: u32,
    /// The window's RMS response, slm.
    pub response: f32,
    /// The window's RMS input (duty) about its mean, fraction.
    pub input_response: f32,
    /// The verdict: `Ok` the held-out free-run fits (estimate, running model) in percent, `Err`
    /// why it was refused; `None` when the run ended first.
    pub verdict: Option<Result<(f32, f32), Rejection<f32>>>,
    /// Accepted, but the swap rule ([`Rules::swap_below_fit`]) kept the running model.
    pub held: bool,
    /// The breath at whose start the new controller took over (`Mode::Adapt`, accepted, and
    /// the design not refused).
    pub swapped_at: Option<u32>,
    /// The design refused the accepted estimate.
    pub design_refused: bool,
}
/// The firmware's controller for `model` (its design, retries and reference model), `None`
/// when refused.
pub fn design(model: &ArxModel<f32>) -> Option<Design<f32>> {
    let c = &EXPERIMENT_CONFIG.control;
    let mut d = firmware_design(model, c)?;
    if c.tau.is_none() {
        d.set_reference(REFERENCE_POLE).ok();
    }
    Some(d)
}

/// [`design`] with the regulation loop's speed `tau` (s) given instead of taken from the
/// model's slow pole (`Spec::tau`, the firmware's retries, each 1.5 times slower), and the
/// firmware's reference model on the setpoint all the same (a re-design at the power-up
/// design's `Design::tau`: the same loop speed and setpoint response, new `R`, `S` for the
/// new model), keeping the model's poles within `keep_radius` ([`design_verdict`]; `None`: the
/// firmware's 0.8); [`design`] when `tau` is `None` (`keep_radius` then unused).
pub fn design_at(
    model: &ArxModel<f32>,
    tau: Option<f32>,
    keep_radius: Option<f32>,
) -> Option<Design<f32>> {
    let Some(tau) = tau else {
        return design(model);
    };
    let mut d = design_verdict(model, tau, keep_radius).ok()?;
    d.set_reference(REFERENCE_POLE).ok()?;
    Some(d)
}

/// The design of [`design_at`] at the regulation speed `tau` (s), before the reference model,
/// with the model's poles within `keep_radius` kept in the closed loop (`Spec::keep_radius`;
/// `None`: the firmware's 0.8): the design, or why the last of the firmware's retries refused
/// `model` (the firmware's `FAULT control why=…`).
pub fn design_verdict(
    model: &ArxModel<f32>,
    tau: f32,
    keep_radius: Option<f32>,
) -> Result<Design<f32>, DesignError<f32>> {
    let c = &EXPERIMENT_CONFIG.control;
    let base = c.spec();
    let spec = ridge_core::control::Spec {
        tau: Some(tau),
        keep_radius: keep_radius.unwrap_or(base.keep_radius),
        ..base
    };
    ridge_core::control::design_slower_on_failure(
        model,
        &spec,
        c.tries,
        ridge_pump_firmware::selfid::SLOWDOWN,
        || {},
    )
    .0
}

/// The firmware's running controller (run mode through the static map) with its model (the
/// dynamics from the map's flow) and preview.
#[derive(Clone, Debug)]
pub struct Running {
    /// The model the controller was designed from.
    pub model: ArxModel<f32>,
    /// The controller; its output is the map's flow, slm.
    pub ctrl: Controller<f32>,
    /// Ticks the controller is given the program ahead.
    pub preview: u32,
}

impl Running {
    /// Started bumplessly at the map's flow `v` of the applied duty and the reading `flow`
    /// (slm), with the firmware's duty limits through the map.
    pub fn new(model: ArxModel<f32>, d: &Design<f32>, table: &MapTable, v: f32, flow: f32) -> Self {
        let c = &EXPERIMENT_CONFIG.control;
        let limits = Limits {
            min: map_slm(table, c.duty_min),
            max: map_slm(table, c.duty_max.min(DUTY_FULL_SCALE)),
            max_step: f32::MAX,
        };
        let mut ctrl = Controller::new(d.rst, limits);
        ctrl.start(v, flow);
        Running {
            model,
            ctrl,
            preview: u32::from(preview_ticks(d.mean_delay(&model))),
        }
    }

    /// The controller for `model` (with [`Mode::Restart`], the running model's own design
    /// restarted) started bumplessly at the last output and the reading `y` (slm); `None`
    /// when the design refuses the model.
    pub fn swapped(
        &self,
        model: ArxModel<f32>,
        mode: Mode,
        table: &MapTable,
        y: f32,
    ) -> Option<Self> {
        self.swapped_at(model, mode, table, y, None).map(|(r, _)| r)
    }

    /// [`swapped`](Self::swapped) with the new design's regulation speed `tau` (s;
    /// [`design_at`]), and the design's `tau` as resolved (s).
    pub fn swapped_at(
        &self,
        model: ArxModel<f32>,
        mode: Mode,
        table: &MapTable,
        y: f32,
        tau: Option<f32>,
    ) -> Option<(Self, f32)> {
        self.swapped_keeping(model, mode, table, y, tau, None)
    }

    /// [`swapped_at`](Self::swapped_at) with the new design keeping the model's poles within
    /// `keep_radius` ([`design_at`]: `None`, the firmware's 0.8; unused without `tau`).
    pub fn swapped_keeping(
        &self,
        model: ArxModel<f32>,
        mode: Mode,
        table: &MapTable,
        y: f32,
        tau: Option<f32>,
        keep_radius: Option<f32>,
    ) -> Option<(Self, f32)> {
        let model = if mode == Mode::Restart {
            self.model
        } else {
            model
        };
        let d = design_at(&model, tau, keep_radius)?;
        Some((Running::new(model, &d, table, self.ctrl.last(), y), d.tau))
    }

    /// One control tick of run mode through the map (as `firmware/src/selfid/run.rs`): the
    /// controller's output for the previewed setpoint `ahead` and the reading `y` (slm) is
    /// the map's flow, turned into duty by the map's inverse within the duty limits and the
    /// rate limit from `applied` (1/10 000), and the controller is told the map's flow of the
    /// duty applied. Returns the duty and that flow (counts).
    pub fn tick(&mut self, table: &MapTable, ahead: f32, y: f32, applied: u16) -> (u16, i16) {
        let c = &EXPERIMENT_CONFIG.control;
        let v = self.ctrl.output(ahead, y);
        let duty = duty_for_flow(
            table,
            v,
            applied,
            c.duty_min,
            c.duty_max.min(DUTY_FULL_SCALE),
            c.duty_step,
        );
        let counts = table.at(duty);
        self.ctrl.commit(f32::from(counts) * SLM_PER_COUNT);
        (duty, counts)
    }
}

/// The map's flow at `duty` (1/10 000), slm, as the firmware's run mode converts it.
pub fn map_slm(table: &MapTable, duty: u16) -> f32 {
    f32::from(table.at(duty)) * SLM_PER_COUNT
}

/// Where the current re-estimate stands.
enum Job {
    Idle,
    Fitting(Box<Refit<f32>>, usize),
    /// Fitted and checked, waiting for the next inspiration's start to be held out
    /// ([`Feed::inspiration_only`]).
    Ready(ArxModel<f32>, usize),
    HoldingOut(Box<Holdout<f32>>, usize),
}

/// Which ticks the re-estimation's window takes and at which structure: the candidate models
/// of the breath's plant (the breath-plant study, docs/control.md). [`Feed::ALL`] is the
/// firmware's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Feed {
    /// Only the inspiration's ticks (the exhalation valve closed), the window's lag history
    /// restarted at each inspiration's start ([`Window::restart_lags`], the statistics kept);
    /// the hold-out is one whole inspiration, its predictors seeded at the inspiration's start.
    /// `false`: every tick, expiration included.
    pub inspiration_only: bool,
    /// Output lags added to the running model's `p` (the structure re-estimated).
    pub extra_p: u8,
    /// Input lags added to its `q`.
    pub extra_q: u8,
}

impl Feed {
    /// Every tick, the running model's structure (the firmware's).
    pub const ALL: Feed = Feed {
        inspiration_only: false,
        extra_p: 0,
        extra_q: 0,
    };

    /// The structure re-estimated for a running model of `s`: `p + extra_p`, `q + extra_q`,
    /// the same delay; `None` beyond the crate's maxima.
    pub fn structure(&self, s: Structure) -> Option<Structure> {
        Structure::new(
            s.p.checked_add(self.extra_p)?,
            s.q.checked_add(self.extra_q)?,
            s.d,
        )
        .ok()
    }
}
/// What the re-estimation does with the loop's data: a [`Study`](super::Study)'s settings
/// ([`Study::rules`](super::Study::rules)), or a ventilation benchmark cell's
/// ([`crate::vent_bench`]).
#[derive(Clone, Copy, Debug)]
pub struct Rules {
    /// What is done with the re-estimates.
    pub mode: Mode,
    /// A re-estimate starts every this many breaths (at a boundary, when none is running).
    pub every: u32,
    /// Ridge-M's settings for the re-estimates.
    pub method: RidgeM<f32>,
    /// [`Refit`] units run per tick.
    pub units: u32,
    /// The swap rule ([`swap_allowed`]), percent; `None` (or 100 and more): always.
    pub swap_below_fit: Option<f64>,
    /// The checks of an estimate and its verdict.
    pub acceptance: Acceptance<f32>,
}

/// The swap rule: an estimate the [`Acceptance`] accepted replaces the running model only when
/// the running model's own held-out free-run fit (`running_fit`, percent, the verdict's
/// [`HoldoutVerdict::running`](ridge_core::reid::HoldoutVerdict)) is below `swap_below_fit`
/// percent; `None` or a threshold of 100 or more: always (the acceptance alone). A running fit
/// that is not a number is below every threshold.
pub fn swap_allowed(running_fit: f32, swap_below_fit: Option<f64>) -> bool {
    match swap_below_fit {
        Some(x) if x < 100.0 => f64::from(running_fit) < x || running_fit.is_nan(),
        _ => true,
    }
}

/// The re-estimation side of the closed loop, as the firmware would run it beside the
/// controller: the statistics window ([`Window`]), the re-estimate in progress ([`Refit`]),
/// its hold-out ([`Holdout`]) and verdict, and the accepted model waiting for its swap. The
/// loop ([`run`](super::run), [`crate::vent_bench`]) calls [`boundary`](Self::boundary) at each
/// breath boundary of the program, [`after_pwm`](Self::after_pwm) each tick after the duty is
/// written, and swaps the controller itself when [`take_pending`](Self::take_pending) gives a
/// model.
pub struct Reestimation<'a> {
    rules: Rules,
    window: Window<'a>,
    feed: Feed,
    /// The last tick was in an inspiration ([`after_pwm_in`](Self::after_pwm_in)).
    inspiring: bool,
    job: Job,
    pending: Option<(ArxModel<f32>, usize)>,
    estimates: Vec<Estimate>,
}

/// The statistics window's storage for any structure ([`window_len`] of the largest).
pub type WindowStore = [i64; window_len(ridge_core::PARAMS_MAX)];

impl<'a> Reestimation<'a> {
    /// Re-estimation of `model`'s structure and offset with the forgetting shift `shift`,
    /// the window kept in `store`.
    pub fn new(
        model: &ArxModel<f32>,
        shift: u8,
        rules: Rules,
        store: &'a mut WindowStore,
    ) -> Result<Self, ExperimentError> {
        Self::with_feed(model, shift, rules, store, Feed::ALL)
    }

    /// [`new`](Self::new) with the ticks and structure of `feed` (the loop then calls
    /// [`after_pwm_in`](Self::after_pwm_in)).
    pub fn with_feed(
        model: &ArxModel<f32>,
        shift: u8,
        rules: Rules,
        store: &'a mut WindowStore,
        feed: Feed,
    ) -> Result<Self, ExperimentError> {
        let structure = feed
            .structure(model.structure())
            .ok_or_else(|| ExperimentError::Plant("window: structure beyond the maxima".into()))?;
        let window = Window::new(structure, model.offset(), shift, store)
            .map_err(|e| ExperimentError::Plant(format!("window: {e:?}")))?;
        Ok(Reestimation {
            rules,
            window,
            feed,
            inspiring: false,
            job: Job::Idle,
            pending: None,
            estimates: Vec::new(),
        })
    }

    /// The boundary that starts breath `b` (from 0) of the program: the forgetting, the
    /// verdict of a hold-out that has scored its samples (an accepted estimate the swap rule
    /// lets through waits for its swap), and the next re-estimate.
    pub fn boundary(&mut self, b: u32) {
        let r = self.rules;
        self.window.end_breath();
        if let Job::HoldingOut(h, i) = &self.job {
            if h.verdict()
                .is_some_and(|v| v.candidate.n >= r.acceptance.holdout_min)
            {
                let verdict = r.acceptance.judge(h);
                let i = *i;
                let e = &mut self.estimates[i];
                e.verdict = Some(verdict.map(|v| (v.candidate.fit, v.running.fit)));
                if matches!(r.mode, Mode::Adapt | Mode::Restart) {
                    if let Ok(v) = verdict {
                        if !swap_allowed(v.running.fit, r.swap_below_fit) {
                            e.held = true;
                        } else if let Some(Ok(m)) = e.model {
                            self.pending = Some((m, i));
                        }
                    }
                }
                self.job = Job::Idle;
            }
        }
        if r.mode != Mode::Frozen && matches!(self.job, Job::Idle) && b > 0 && b % r.every == 0 {
            // A window too short for the structure starts nothing (the next boundary tries).
            if let Ok(f) = Refit::start(&self.window, r.method, &MODEL_SCALE) {
                self.estimates.push(Estimate {
                    breath: b,
                    weight: f.weight(),
                    model: None,
                    iterations: 0,
                    response: f.response(),
                    input_response: f.input_response(),
                    verdict: None,
                    held: false,
                    swapped_at: None,
                    design_refused: false,
                });
                self.job = Job::Fitting(Box::new(f), self.estimates.len() - 1);
            }
        }
    }

    /// The accepted model waiting for its swap and its estimate's index, taken.
    pub fn take_pending(&mut self) -> Option<(ArxModel<f32>, usize)> {
        self.pending.take()
    }

    /// Estimate `i`'s controller took over at the start of breath `breath` (`Some`), or the
    /// design refused its model (`None`).
    pub fn swapped(&mut self, i: usize, breath: Option<u32>) {
        if let Some(e) = self.estimates.get_mut(i) {
            match breath {
                Some(b) => e.swapped_at = Some(b),
                None => e.design_refused = true,
            }
        }
    }

    /// After the tick's PWM write: the window takes the map's flow at the written duty
    /// (`v_counts`) and the reading (`counts`); one step of the re-estimate or the hold-out;
    /// `running` is the running controller's model.
    pub fn after_pwm(&mut self, v_counts: i16, counts: i16, running: &ArxModel<f32>) {
        self.step(v_counts, counts, running, true);
    }

    /// [`after_pwm`](Self::after_pwm) for a tick whose interval was in the inspiration
    /// (`inspiring`, the exhalation valve closed) or not. With [`Feed::inspiration_only`] an
    /// expiration tick only advances the fit; an inspiration's first tick restarts the window's
    /// lag history and starts the hold-out of an estimate ready for it. Otherwise as
    /// [`after_pwm`](Self::after_pwm).
    pub fn after_pwm_in(
        &mut self,
        v_counts: i16,
        counts: i16,
        running: &ArxModel<f32>,
        inspiring: bool,
    ) {
        if !self.feed.inspiration_only {
            return self.step(v_counts, counts, running, true);
        }
        if inspiring && !self.inspiring {
            self.window.restart_lags();
            if let Job::Ready(m, i) = self.job {
                self.job = Job::HoldingOut(Box::new(Holdout::new(m, *running)), i);
            }
        }
        self.inspiring = inspiring;
        self.step(v_counts, counts, running, inspiring);
    }

    /// One tick: the sample taken into the window and the hold-out when `take`, one step of
    /// the fit.
    fn step(&mut self, v_counts: i16, counts: i16, running: &ArxModel<f32>, take: bool) {
        if take {
            let _ = self.window.push(v_counts, counts);
        }
        let (uk, yk) = (
            f32::from(v_counts) * SLM_PER_COUNT,
            f32::from(counts) * SLM_PER_COUNT,
        );
        let job = std::mem::replace(&mut self.job, Job::Idle);
        self.job = match job {
            Job::Fitting(mut f, i) => match f.step(self.rules.units) {
                RefitStep::Working => Job::Fitting(f, i),
                RefitStep::Done(m, iters) => {
                    let e = &mut self.estimates[i];
                    e.model = Some(Ok(m));
                    e.iterations = iters;
                    match self
                        .rules
                        .acceptance
                        .check_estimate(&m, e.response, e.input_response)
                    {
                        Ok(_) if self.feed.inspiration_only => Job::Ready(m, i),
                        Ok(_) => Job::HoldingOut(Box::new(Holdout::new(m, *running)), i),
                        Err(why) => {
                            e.verdict = Some(Err(why));
                            Job::Idle
                        }
                    }
                }
                RefitStep::Refused(why) => {
                    self.estimates[i].model = Some(Err(why));
                    Job::Idle
                }
            },
            Job::HoldingOut(mut h, i) => {
                if take {
                    h.push(uk, yk);
                }
                Job::HoldingOut(h, i)
            }
            Job::Ready(m, i) => Job::Ready(m, i),
            Job::Idle => Job::Idle,
        };
    }

    /// Estimate `i` was accepted but the caller's swap policy kept the running controller
    /// (counted as held, as by [`Rules::swap_below_fit`]).
    pub fn hold(&mut self, i: usize) {
        if let Some(e) = self.estimates.get_mut(i) {
            e.held = true;
        }
    }

    /// Every re-estimate so far, in order.
    pub fn estimates(&self) -> &[Estimate] {
        &self.estimates
    }

    /// Every re-estimate, in order.
    pub fn into_estimates(self) -> Vec<Estimate> {
        self.estimates
    }
}
