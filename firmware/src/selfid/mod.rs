//! The power-up self-identification state machine: hardware-agnostic and pure.
//!
//! The board glue reads the SFM3300 every 10 ms, calls [`SelfIdentification::tick_into`] with
//! the reading, applies the returned duty to the pump at once, then calls
//! [`SelfIdentification::after_write`] and reports the event (one line, see [`crate::event`]);
//! [`SelfIdentification::tick`] is the two in one. When [`SelfIdentification::needs_search`] is
//! true it runs the structure search from its main loop: either [`SelfIdentification::search`]
//! (blocking, no ticks meanwhile: the PWM keeps the base duty) or, to keep ticking from the
//! timer interrupt while the search runs, [`SelfIdentification::take_search`] →
//! [`SearchJob::run`] → [`SelfIdentification::finish_search`]. When
//! [`SelfIdentification::needs_design`] is true it runs [`SelfIdentification::design`] the same
//! blocking way (tens of milliseconds). When [`SelfIdentification::needs_judgement`] is true
//! (the scan's readings or the validation record are complete) it calls
//! [`SelfIdentification::judge`] after the tick's PWM write, applies
//! [`SelfIdentification::duty`] if that is 0 (a latched fault), and reports the event. All of
//! them are kept out of `tick_into`, which therefore costs about the same every time (a sensor
//! read, one statistics update; in run mode the controller and the map's inverse).
//!
//! # The model
//! Hammerstein: the static map `v = g(u)` from duty to flow (slm; the flow the blower settles
//! at, `ridge_core::InputMap`, 16 knots), then the ARX dynamics of the paper from `v` to the
//! measured flow, with an intercept. The map carries the blower's nonlinearity (dead zone, fan
//! curve, a lung's back pressure), so that one linear model holds over the whole flow range;
//! the structure search, Ridge-M and the controller design are the linear ones, on `v`
//! (docs/identification.md).
//!
//! # States
//! ```text
//! WaitSensor ─first good reading─▶ Settle ─┬─(valid stored model: MAP)─────────────────▶ Design (LOADED) ─▶ Run (CTRL)
//!                                          └▶ Scan (SCAN, MAP) ─▶ Excite ─▶ Search ─▶ Validate ─┬─▶ Settle (ACCEPT, persist) ─▶ Design ─▶ Run (CTRL)
//!                        ▲                                                 │           │
//!                        └──────────────────── REJECT (attempt < attempts) ┴───────────┘
//! any state ─sensor errors / flow out of range / stall / all attempts rejected
//!            / controller refused (Design) ─▶ Fault (duty 0, latched)
//! ```
//! - **WaitSensor**: duty 0 until the first good reading.
//! - **Settle**: [`Config::base_duty`] for [`Config::settle_ticks`]. The rounded mean flow of
//!   the last [`SETTLE_MEAN_TICKS`] ticks is the operating point `y0` (counts), with
//!   `u0` = the base duty. A settle phase that starts the pump from rest also measures its lag
//!   (see [`Records`]).
//! - **Scan**: ramps over the duty range ([`Records`]); each reading is credited to the duty
//!   one lag before it, and the map is the mean of the rising and the falling readings at each
//!   knot ([`SelfIdentification::judge`] computes it, `MAP`); then a lead-in at the base duty.
//! - **Excite**: the estimation record ([`crate::excitation::FlowSteps`]: random steps uniform
//!   in the map's flow); every tick feeds the exact integer statistics with
//!   `IntGram::push(v − v0, y − y0)`, `v` the map's flow at the duty applied during the
//!   interval that ends with the reading `y` (both counts of 1/120 slm), `v0` the map's flow at
//!   the base duty.
//! - **Search**: base duty until the search is done (ridge-core `Search<f32>` on the
//!   statistics in slm, [`Config::search`]); the model of the deviations is turned into the
//!   absolute model ([`absolute_model`]).
//!
//! ## Why deviations from the operating point
//! The statistics assume zero history before the record (paper, Algorithm 1), but the pump
//! enters the record running at the base duty. With absolute values the first rows of the
//! regression would see zero past flows while the flow is ~20 slm: on a noise-free linear
//! plant those few rows dominate the residual sum of squares (20² slm² each against
//! quantisation noise of 2·10⁻⁵ slm² per sample) and bias every estimate. With deviations
//! from the settled operating point the zero history is what the plant really had (the scan's
//! lead-in settles it there), so the records are exactly the ARX regression of eq. (6); the
//! operating point goes into the intercept of the stored model.
//! - **Validate**: the validation record (the same kind, another seed), scored with a
//!   streaming [`Evaluation<f32>`] in physical units (seeded with the first `m` measured
//!   samples); a model with a free-run fit below [`Config::min_fit`] is rejected by
//!   [`SelfIdentification::judge`] (base duty from the end of the record until then).
//! - **Design** (after a settle phase at the base duty, so that control starts from the settled
//!   operating point): base duty until [`SelfIdentification::design`] has checked the model
//!   (stable, static gain of the expected sign and size; see [`ControlConfig::model`]),
//!   designed the flow controller on the dynamics (`ridge_core::control`: pole placement with
//!   an integrator, slowed down and retried while its checks fail) and accepted it
//!   ([`Event::Control`]). A refused model or design latches [`FaultReason::Control`]: the pump
//!   stops (duty 0) rather than run without a checked controller.
//! - **Run**: the controller tracks [`ControlConfig::program`] (setpoints from
//!   [`crate::setpoint`]); its output, a flow, goes through the map's inverse to the duty
//!   within the duty limits and rate limit, starting bumplessly from the base duty and the
//!   current flow; the one-step residual monitor ([`crate::monitor`]) and the tracking figures
//!   and alarm ([`crate::tracking`]) report once a second.
//! - **Fault**: duty 0 from the tick that detected it on, for ever (until a new
//!   [`SelfIdentification::new`]).
//!
//! Sensor errors shorter than [`Config::sensor_fault_limit`] are bridged: during a record the
//! previous reading is used (counted as a gap, at most [`Config::max_gaps`] per record; the
//! scan credits nothing for it), in run mode the tick is not scored.
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the machine: phases, [`SelfIdentification::tick`], validation, run mode, faults |
//! | `config.rs` | [`Config`], [`Records`] and their defaults |
//! | `guard.rs` | [`Guard`]: the fault checks of every tick |
//! | `operator.rs` | the operator's commands: stop, start, the setpoint program |
//! | `scan.rs` | the lag from the start-up, the scan's ramps and the map's accumulators |
//! | `recording.rs` | the estimation record's statistics around the operating point, and [`absolute_model`] |
//! | `search.rs` | the structure search: blocking, or as a [`SearchJob`] while ticks go on |
//! | `design.rs` | the controller design and the start of run mode |
//! | `run.rs` | run mode: controller, map inverse, monitor, tracking, the re-identification ([`crate::reid`], not on the ATmega2560) and its swap |

mod config;
mod design;
mod guard;
mod operator;
mod phases;
mod recording;
mod run;
mod scan;
mod search;

pub use config::{Config, ControlConfig, Defaults, Records, Settings, DEFAULT_CONFIG, LOSS_SHIFT};
pub use design::{REFERENCE_POLE, SLOWDOWN};
pub use guard::Guard;
pub use recording::{absolute_model, SETTLE_MEAN_TICKS};
pub use run::{duty_for_flow, preview_ticks};
pub use scan::RESPONSE_COUNTS;
pub use search::{SearchJob, SearchOutcome};

use ridge_core::{ArxModel, Evaluation, InputMap, IntGram, Normal, Real};

use crate::event::{Event, FaultReason, RejectReason, SensorFault, StoredReason};
use crate::excitation::FlowSteps;
use crate::persist::{self, RECORD_LEN};
use crate::setpoint::Program;
use crate::units::SLM_PER_COUNT;
use crate::ventilation::{Anchor, Valve};

use recording::Recording;
use run::RunMode;
use scan::{Scan, Startup};

/// The checks a stored record must pass before its model is used (at boot; `ridge-id`'s
/// export runs them too): it decodes ([`persist::decode`]), its dynamics pass the model checks
/// an identified model must pass ([`ControlConfig::model`]), its map rises by a plausible slope
/// over the records' duty range ([`ControlConfig::map_slope`]), and its fit is at least
/// [`Config::min_fit`]. Returns the model, its map and its fit.
///
/// Errors: the first check failed, as the `STORED-REJECTED` line reports it.
pub fn check_stored(
    bytes: &[u8],
    config: &Config,
) -> Result<(ArxModel<f32>, InputMap, f32), StoredReason> {
    let (m, map, fit) = persist::decode(bytes).map_err(StoredReason::Record)?;
    ridge_core::control::check_model(&m, &config.control.model).map_err(StoredReason::Model)?;
    let r = &config.records;
    // slm per unit duty: counts / 120 over duty / 10 000.
    let rise = f32::from(map.at(r.high)) - f32::from(map.at(r.low));
    let slope = rise * SLM_PER_COUNT / (f32::from(r.high.saturating_sub(r.low).max(1)) * 1e-4);
    let [lo, hi] = config.control.map_slope;
    // Written so that NaN fails.
    if !(slope >= lo && slope <= hi) {
        return Err(StoredReason::MapSlope { slope });
    }
    if !Real::is_finite(fit) || fit < config.min_fit {
        return Err(StoredReason::Fit {
            fit,
            min: config.min_fit,
        });
    }
    Ok((m, map, fit))
}

/// The externally visible state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// Waiting for the first good sensor reading (duty 0).
    WaitSensor,
    /// Holding the base duty before an identification attempt or run mode.
    Settle,
    /// Scanning the duty range for the static map (and the lead-in at the base duty).
    Scan,
    /// Running the estimation record.
    Excite,
    /// Waiting for (or running) the structure search, at the base duty.
    Search,
    /// Running the validation record.
    Validate,
    /// Waiting for (or running) the controller design, at the base duty.
    Design,
    /// Controlling the flow, monitoring the model and the tracking.
    Run,
    /// Stopped by the operator (duty 0) until [`SelfIdentification::start`].
    Stopped,
    /// Stopped (duty 0), latched.
    Fault,
}

impl State {
    /// Lower-case name used in `STATUS` lines and the log's `phase` column: `wait`, `settle`,
    /// `scan`, `excite`, `search`, `validate`, `design`, `run`, `stopped`, `fault`.
    pub const fn name(self) -> &'static str {
        match self {
            State::WaitSensor => "wait",
            State::Settle => "settle",
            State::Scan => "scan",
            State::Excite => "excite",
            State::Search => "search",
            State::Validate => "validate",
            State::Design => "design",
            State::Run => "run",
            State::Stopped => "stopped",
            State::Fault => "fault",
        }
    }
}

/// What one [`SelfIdentification::tick`] returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Duty to apply now, 1/10 000 of full scale (0 = stop).
    pub duty: u16,
    /// At most one event to report.
    pub event: Option<Event>,
}

/// What follows a settle phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Then {
    /// The stored model: report it (`LOADED`), then design its controller.
    Load,
    /// The accepted model: design its controller.
    Design,
    /// An identification attempt.
    Excite,
}

// One phase at a time, in the state machine's static storage: the variants share its bytes, and
// `no_std` without a heap has no box to move the search's normal equations into.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
enum Phase {
    Wait,
    Settle {
        left: u16,
        then: Then,
        /// Sum and count of the good readings of the last [`SETTLE_MEAN_TICKS`] ticks.
        sum: i32,
        n: u8,
        /// The lag measurement, when the phase started the pump from rest.
        startup: Option<Startup>,
    },
    /// The ramps over the duty range and the lead-in; `u0`, `y0`: the operating point.
    Scan {
        scan: Scan,
        u0: u16,
        y0: i16,
        gaps: u16,
    },
    /// The estimation record, prepared by [`SelfIdentification::judge`] with the scan's map
    /// while the scan's lead-in goes on: `lead` ticks of it are left (their last one applies
    /// `start`, the record's first duty).
    Excite {
        lead: u16,
        start: u16,
        gen: FlowSteps,
        rec: Recording,
        /// The map's flow at the duty applied during the interval that ends with the next
        /// reading, counts.
        v: i16,
    },
    SearchReady {
        rec: Recording,
    },
    Searching,
    /// The blocking search's normal equations, built from the record in its place
    /// ([`SelfIdentification::prepare_search`]), the record's map and operating point (the
    /// map's flow and the measured flow, counts).
    SearchNormal {
        normal: Normal<f32>,
        map: InputMap,
        v0: i16,
        y0: i16,
    },
    /// [`SelfIdentification::prepare_search`] refused the record (reported by
    /// [`SelfIdentification::run_search`]); the record's map.
    SearchRefused(RejectReason, InputMap),
    Validate {
        gen: FlowSteps,
        eval: Evaluation<f32>,
        model: ArxModel<f32>,
        map: InputMap,
        /// The map's flow at the applied duty, as in [`Phase::Excite`].
        v: i16,
        gaps: u16,
        started: bool,
        /// The record is complete: waiting for [`SelfIdentification::judge`].
        complete: bool,
    },
    /// The model (accepted or loaded) waits for its controller design.
    Design {
        model: ArxModel<f32>,
        map: InputMap,
    },
    Run(RunMode),
    /// Stopped by the operator.
    Stopped,
    Fault,
}

fn settle(left: u16, then: Then) -> Phase {
    Phase::Settle {
        left,
        then,
        sum: 0,
        n: 0,
        startup: None,
    }
}

/// The self-identification state machine; all state, fixed size, no heap
/// (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct SelfIdentification<S: Settings = &'static Config> {
    /// The settings (static: on the ATmega2560 a static costs data, a by-value copy built at
    /// run time cost 1 KB of code; see [`Settings`] for the compile-time choice).
    settings: S,
    phase: Phase,
    /// Duty returned by the last tick: applied during the interval that ends with the next
    /// reading.
    duty: u16,
    /// Last good reading, counts.
    last_counts: i16,
    /// The fault checks and their counters.
    guard: Guard,
    /// Identification attempt in progress (1-based; 0 before the first).
    attempt: u8,
    /// Bumped whenever a search result would be stale.
    generation: u8,
    /// The model in use: its dynamics and its map (both or neither).
    model: Option<ArxModel<f32>>,
    map: Option<InputMap>,
    fit: f32,
    /// The plant's lag measured at the last start from rest, ticks.
    lag: Option<u8>,
    stored_error: Option<StoredReason>,
    fault: Option<FaultReason>,
    fault_announced: bool,
    drift: bool,
    /// A (re-)identification was requested: never settle into the stored model.
    identify: bool,
    /// What run mode tracks (the settings' program until the operator sets another).
    program: Program,
    /// Run mode's re-identification and its swap, idle outside run mode (beside the phase,
    /// not in run mode: see [`run::Reidentification`]).
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    reid: run::Reidentification,
}

// RAM guard: 998 bytes on the ATmega2560 (the largest phase is the blocking search's normal
// equations, 848 B, `prepare_search`; run mode is 617 B). The search's factors and candidates
// are on the stack (ridge-core `Search::run_with_progress`).
#[cfg(target_arch = "avr")]
const _: () = assert!(core::mem::size_of::<SelfIdentification>() <= 4000);

impl<S: Settings> SelfIdentification<S> {
    /// A state machine with settings `settings` (a `&'static Config`, or [`Defaults`]). `stored` is the persisted record read from
    /// EEPROM/flash (see [`crate::persist`]) or `None`. A valid record skips identification:
    /// after settling, the controller is designed for that model ([`Event::Loaded`]) and the
    /// pump runs. A record that fails [`check_stored`] (invalid, or a model that fails the
    /// checks an identified model must pass, an implausible map, a fit below
    /// [`Config::min_fit`]) is reported once ([`Event::StoredRejected`], on the first tick)
    /// and a new model is identified.
    #[inline(never)]
    pub fn new(settings: S, stored: Option<&[u8]>) -> Self {
        let config = settings.config();
        let checked = stored.map(|bytes| check_stored(bytes, config));
        let (model, map, fit, stored_error) = match checked {
            Some(Ok((m, map, fit))) => (Some(m), Some(map), fit, None),
            Some(Err(e)) => (None, None, 0.0, Some(e)),
            None => (None, None, 0.0, None),
        };
        SelfIdentification {
            settings,
            phase: Phase::Wait,
            duty: 0,
            last_counts: 0,
            guard: Guard::new(config),
            attempt: 0,
            generation: 0,
            model,
            map,
            fit,
            lag: None,
            stored_error,
            fault: None,
            fault_announced: false,
            drift: false,
            identify: false,
            program: config.control.program,
            #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
            reid: run::Reidentification::dormant(config),
        }
    }

    /// Called once per 10 ms tick with the sensor result of this tick (counts = raw − 32768,
    /// 1/120 slm). Returns the duty to apply now (1/10 000 of full scale, 0 = stop) and at most
    /// one event to report: [`tick_into`](Self::tick_into) and
    /// [`after_write`](Self::after_write) in one.
    ///
    /// Faults take effect in the same tick: the returned duty is 0 and stays 0.
    pub fn tick(&mut self, flow: Result<i16, SensorFault>) -> Tick {
        let mut event = None;
        let duty = self.tick_into(flow, &mut event);
        self.after_write(&mut event);
        Tick { duty, event }
    }

    /// The work of a tick that does not set its duty, for after the PWM write
    /// ([`tick_into`](Self::tick_into) must come first, in the same tick): in run mode the
    /// controller's memory of the applied duty (the map's flow there), the monitor, the
    /// tracking figures and the flow the next tick's fault checks expect. Puts at most one
    /// event into `event` when it is empty (the monitor's or the tracking's).
    pub fn after_write(&mut self, event: &mut Option<Event>) {
        if event.is_some() {
            // The tick's own event goes first; run mode's windows come at their next tick.
            if let Phase::Run(run) = &mut self.phase {
                let mut later = None;
                let expected = run.after_write(self.duty, &mut later);
                // A volume program's breaths run against the PEEP valve and the lung, which the
                // map did not see: its steady state is no expectation then (`after_pwm` moves the
                // no-flow check to the breaths' own operating point).
                if !run.ventilating() {
                    self.guard.expect_flow(expected);
                }
                self.run_event(later.as_ref());
            }
            return;
        }
        if let Phase::Run(run) = &mut self.phase {
            let expected = run.after_write(self.duty, event);
            if !run.ventilating() {
                self.guard.expect_flow(expected);
            }
            self.run_event(event.as_ref());
        }
    }

    /// A drift from the monitor: the flag, and a new identification when it asks for one
    /// (from the next tick on, which then holds the base duty), never while a volume program
    /// runs: the drift is then reported (and on boards with [`crate::reid`] it triggers a
    /// re-estimate at the next breath boundary), the breaths go on.
    fn run_event(&mut self, event: Option<&Event>) {
        if let Some(Event::Drift { reidentify, .. }) = event {
            self.drift = true;
            let ventilating = matches!(&self.phase, Phase::Run(run) if run.volume_program());
            if *reidentify && !ventilating {
                self.request_reidentification();
            }
        }
    }

    /// The part of [`tick`](Self::tick) that sets the tick's duty, with its event written into
    /// `event` (which must be empty), the duty returned: the board loop's form, which applies
    /// the duty and then calls [`after_write`](Self::after_write). A returned [`Tick`] is a
    /// 76-byte copy, ~600 cycles of the ATmega2560's control tick, paid in every tick.
    pub fn tick_into(&mut self, flow: Result<i16, SensorFault>, event: &mut Option<Event>) -> u16 {
        let applied = self.duty;
        if matches!(self.phase, Phase::Fault) {
            *event = self.fault_event();
            return 0;
        }
        let reading = match self.guard.check(applied, flow) {
            Ok(reading) => reading,
            Err(reason) => {
                self.enter_fault(reason);
                *event = self.fault_event();
                return 0;
            }
        };
        if let Some(c) = reading {
            self.last_counts = c;
        }
        self.advance(applied, reading, event);
        if matches!(self.phase, Phase::Fault) {
            self.duty = 0;
        }
        if event.is_none() {
            *event = self.stored_error.take().map(Event::StoredRejected);
        }
        self.duty
    }

    /// A copy of the tick's fault checks with their current counters, for a board that cannot
    /// tick the state machine for a while (the ATmega2560's blocking search): it reads the
    /// sensor at every tick boundary, stops the pump itself when [`Guard::check`] returns a
    /// fault, and hands that to [`fault_detected`](Self::fault_detected) afterwards.
    pub fn guard(&self) -> Guard {
        self.guard
    }

    /// Continues the tick's checks from the counters of `watched`, the copy from
    /// [`guard`](Self::guard) that checked the tick boundaries of a blocking search or design
    /// without a fault (see [`Guard::resume`]).
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    pub fn resume_guard(&mut self, watched: &Guard) {
        self.guard.resume(watched);
    }

    /// Latches a fault that a [`Guard`] found outside [`tick`](Self::tick): duty 0 from now on,
    /// any search result or record in progress is dropped. Returns the [`Event::Fault`] to
    /// report (it is not repeated by the next tick).
    pub fn fault_detected(&mut self, reason: FaultReason) -> Event {
        self.enter_fault(reason);
        self.fault_announced = true;
        Event::Fault(reason)
    }

    /// `true` once the scan's readings or the validation record are complete: the board
    /// should call [`judge`](Self::judge) from its main loop (after the tick's PWM write).
    /// Until then the ticks hold the base duty.
    pub fn needs_judgement(&self) -> bool {
        match &self.phase {
            Phase::Validate { complete, .. } => *complete,
            Phase::Scan { scan, .. } => scan.complete,
            _ => false,
        }
    }

    /// The verdicts too costly for the tick:
    /// - the scan's map ([`Event::Map`]; a scan that gives none is rejected,
    ///   [`Event::Rejected`]);
    /// - the validation record's score: the model is accepted (the controller design follows,
    ///   see [`design`](Self::design); [`Event::Accepted`], whose [`persist`](Event::persist)
    ///   asks for [`persist_bytes`](Self::persist_bytes) to be stored) or rejected
    ///   ([`Event::Rejected`]).
    ///
    /// After the last attempt a rejection latches the fault and [`duty`](Self::duty) is 0 at
    /// once. `None` when no judgement is due.
    ///
    /// Kept out of [`tick`](Self::tick) because each costs one to two milliseconds on the
    /// ATmega2560 (the map: a division per knot; the score: three square roots, divisions,
    /// moving the model into run mode), which would push that tick's PWM write past its
    /// 1.6 ms budget.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    pub fn judge(&mut self) -> Option<Event> {
        if !self.needs_judgement() {
            return None;
        }
        if let Phase::Scan { .. } = self.phase {
            return self.end_scan();
        }
        Some(self.end_validation())
    }

    /// The scan's readings are complete: its map in one pass, then in the next the estimation
    /// record prepared on it, to start at the end of the lead-in, and the map's line
    /// ([`Event::Map`]); or the rejection. The map's divisions, the record's first level and
    /// the line's 16 numbers are worked out here, after a PWM write, not in a tick, and in two
    /// passes: together they took 8.9 ms of the ATmega2560's 10 ms tick.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    fn end_scan(&mut self) -> Option<Event> {
        let r = &self.settings.config().records;
        let Phase::Scan { scan, u0, y0, .. } = &mut self.phase else {
            return None;
        };
        let Some(map) = scan.map() else {
            return match scan.finish()? {
                Ok(_) => None,
                Err(e) => Some(self.reject(RejectReason::Map(e))),
            };
        };
        // The lead-in duties still to apply, and the tick that applies the record's first.
        let lead = scan.len(r).saturating_sub(scan.next).saturating_add(1);
        let (lag, u0, y0) = (scan.lag, *u0, *y0);
        let Some((gen, (start, v))) = self
            .record(&map, lag, r.samples, r.seed)
            .and_then(|mut gen| gen.next_step().map(|first| (gen, first)))
        else {
            return Some(self.reject(RejectReason::NotExcited { rms: 0.0 }));
        };
        self.phase = Phase::Excite {
            lead,
            start,
            gen,
            rec: Recording::new(map, map.at(u0), y0),
            v,
        };
        Some(Event::Map(map))
    }

    /// The operating point's flow of the record in progress (counts), 0 outside one.
    fn y0(&self) -> i16 {
        match &self.phase {
            Phase::Excite { rec, .. } | Phase::SearchReady { rec } => rec.y0,
            Phase::Scan { y0, .. } => *y0,
            _ => 0,
        }
    }

    /// The current state.
    pub fn state(&self) -> State {
        match self.phase {
            Phase::Wait => State::WaitSensor,
            Phase::Settle { .. } => State::Settle,
            Phase::Scan { .. } | Phase::Excite { lead: 1.., .. } => State::Scan,
            Phase::Excite { .. } => State::Excite,
            Phase::SearchReady { .. }
            | Phase::Searching
            | Phase::SearchNormal { .. }
            | Phase::SearchRefused(..) => State::Search,
            Phase::Validate { .. } => State::Validate,
            Phase::Design { .. } => State::Design,
            Phase::Run(_) => State::Run,
            Phase::Stopped => State::Stopped,
            Phase::Fault => State::Fault,
        }
    }

    /// The dynamics of the model in use, loaded from the stored record or accepted by
    /// validation (physical units: the map's flow in slm in, the measured flow in slm out).
    pub fn model(&self) -> Option<&ArxModel<f32>> {
        self.model.as_ref()
    }

    /// The static map of the model in use, from duty (1/10 000) to flow (counts).
    pub fn map(&self) -> Option<&InputMap> {
        self.map.as_ref()
    }

    /// The plant's lag measured at the last start from rest, ticks (`None` before).
    pub fn lag(&self) -> Option<u8> {
        self.lag
    }

    /// The validation free-run fit of [`model`](Self::model), percent.
    pub fn fit(&self) -> Option<f32> {
        self.model.map(|_| self.fit)
    }

    /// The record to persist for [`model`](Self::model) (write it when an event says
    /// [`Event::persist`]).
    pub fn persist_bytes(&self) -> Option<[u8; RECORD_LEN]> {
        match (&self.model, &self.map) {
            (Some(m), Some(map)) => Some(persist::encode(m, map, self.fit)),
            _ => None,
        }
    }

    /// Starts a new identification (settle, scan, excite, search, validate) from the next tick.
    /// Ignored in the fault and the stopped state. The current model (and the drift flag) stay until a new
    /// model is accepted.
    pub fn request_reidentification(&mut self) {
        if matches!(self.phase, Phase::Fault | Phase::Stopped) {
            return;
        }
        self.attempt = 0;
        self.identify = true;
        self.generation = self.generation.wrapping_add(1);
        // Still waiting for the sensor: the identification starts after it, as at boot.
        if !matches!(self.phase, Phase::Wait) {
            // The base duty takes effect with the next tick's return value.
            self.phase = settle(self.settings.config().settle_ticks, Then::Excite);
        }
    }

    /// The exhalation valve's state for the interval in progress: closed only in the
    /// inspiration of a volume-controlled breath in run mode ([`crate::ventilation`]), open
    /// in every other state (identifying, stopped, fault).
    pub fn valve(&self) -> Valve {
        match &self.phase {
            Phase::Run(run) => run.valve(),
            _ => Valve::Open,
        }
    }

    /// Run mode's work after the tick's PWM write: a volume program's per-breath bookkeeping
    /// (`BREATH`, `ALARM volume`, the trim), its event into `event` if that is empty. Call it
    /// once per tick, after [`tick_into`](Self::tick_into) and the PWM write.
    ///
    /// The no-flow check follows a volume program's operating point (see
    /// [`Guard::pause_expectation`]): paused from its first tick until the middle of its first
    /// expiration, then expecting from the bias flow held in the middle of each expiration.
    pub fn after_pwm(&mut self, event: &mut Option<Event>) {
        if let Phase::Run(run) = &mut self.phase {
            match run.after_pwm(self.last_counts, event) {
                Some((Anchor::Pause, _)) => self.guard.pause_expectation(),
                Some((Anchor::Hold, applied)) => {
                    self.guard.move_operating_point(applied, self.last_counts)
                }
                Some((Anchor::Keep, _)) => self.guard.resume_expectation(),
                None => {}
            }
            #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
            {
                run.reidentify(&mut self.reid, self.last_counts, self.drift, event);
                self.redesign(event);
            }
        }
    }

    /// Whether run mode's tracking alarm is raised.
    pub fn tracking_alarm(&self) -> bool {
        matches!(&self.phase, Phase::Run(run) if run.alarm())
    }

    /// The setpoint of the interval in progress (run mode), slm.
    pub fn setpoint(&self) -> Option<f32> {
        match &self.phase {
            Phase::Run(run) => Some(run.setpoint()),
            _ => None,
        }
    }

    /// How many ticks ahead run mode gives the controller the setpoint program (the designed
    /// setpoint response's mean delay, rounded), `None` outside run mode.
    pub fn preview(&self) -> Option<u8> {
        match &self.phase {
            Phase::Run(run) => Some(run.preview()),
            _ => None,
        }
    }

    /// The last good reading (held over sensor errors), counts (1/120 slm): the flow the
    /// statistics and the controller use.
    pub fn reading(&self) -> i16 {
        self.last_counts
    }

    /// The settings.
    pub fn config(&self) -> &'static Config {
        self.settings.config()
    }

    /// The duty returned by the last tick, 1/10 000 of full scale.
    pub fn duty(&self) -> u16 {
        self.duty
    }

    /// Whether the run-mode monitor raised a model drift (cleared when a new model is
    /// accepted).
    pub fn drift(&self) -> bool {
        self.drift
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<FaultReason> {
        self.fault
    }

    /// The identification attempt in progress or last made (1-based; 0 before the first).
    pub fn attempt(&self) -> u8 {
        self.attempt
    }

    /// The exact statistics of the estimation record while it is being recorded or waits for
    /// the search (for diagnostics and host tests).
    pub fn gram(&self) -> Option<&IntGram> {
        match &self.phase {
            Phase::Excite { rec, .. } | Phase::SearchReady { rec } => Some(&rec.gram),
            _ => None,
        }
    }

    fn fault_event(&mut self) -> Option<Event> {
        self.duty = 0;
        if self.fault_announced {
            None
        } else {
            self.fault_announced = true;
            self.fault.map(Event::Fault)
        }
    }

    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    fn enter_fault(&mut self, reason: FaultReason) {
        self.phase = Phase::Fault;
        self.duty = 0;
        self.fault = Some(reason);
        self.fault_announced = false;
        self.generation = self.generation.wrapping_add(1);
    }

    /// Refuses the current attempt: next attempt, or the fault state after the last one.
    fn reject(&mut self, reason: RejectReason) -> Event {
        let attempts = self.settings.config().attempts.max(1);
        let attempt = self.attempt;
        if attempt >= attempts {
            self.enter_fault(FaultReason::Unidentified { attempts });
        } else {
            self.phase = settle(self.settings.config().settle_ticks, Then::Excite);
            self.duty = self.settings.config().base_duty;
        }
        Event::Rejected {
            reason,
            attempt,
            attempts,
        }
    }
}
