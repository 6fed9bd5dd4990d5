//! Run-mode model monitor: one-step-ahead prediction of the flow from the identified model
//! against the measured flow, residual statistics per window, and drift detection.
//!
//! Every tick (after the tick's PWM write) the monitor takes the duty applied during the
//! interval that ended with the reading, the static map's flow at it (the model's input, see
//! [`crate::selfid`]), and the reading. A [`ridge_core::Predictor`] in [`Mode::OneStep`]
//! predicts the reading from the measured past flows and the past inputs (seeded with the
//! first `m = max(p, d + q − 1)` samples). The residual `e = y − ŷ` (slm) is accumulated over a
//! window ([`MonitorConfig::window`] ticks, 1 s by default) and reported as
//! [`Event::Residual`].
//!
//! A window is *above the limit* when its residual RMS exceeds
//! `rms_abs + rms_rel · |mean flow|` or the magnitude of its mean residual exceeds
//! `mean_abs + mean_rel · |mean flow|` (slm). After [`MonitorConfig::seconds`] consecutive
//! windows above the limit the monitor raises [`Event::Drift`] once and latches its drift flag
//! (while a volume program runs the breath rule decides instead: "While ventilating" below).
//!
//! Why both: the RMS follows the sensor noise (about 3 % of the reading on the SFM3300, so a
//! healthy one-step RMS is 3.5 % of the flow on the simulated pumps) and catches noisier or
//! faster-changing flow; the mean residual (bias) averages the noise out and catches a
//! changed gain, which the one-step residual sees only through `(1 − Σθ)` of the static error.
//! Defaults from the simulated pumps (`pump-sim`, default/small/sluggish, 25..90 % duty):
//! healthy windows stay below 5.5 % + 0.46 slm RMS and 1.4 % + 0.37 slm bias (the nonlinear
//! fan curve against a linear model); a 30 % gain loss at 50 % duty gives a bias of
//! 1.8..3.6 slm against a limit of about 1.3 slm.
//!
//! Ticks with a sensor error (no reading) feed the predictor the previous reading and are not
//! scored; ticks with a duty below [`MonitorConfig::min_duty`] (outside the identified range,
//! e.g. a stopped pump) are not scored either.
//!
//! Sensitivity: the one-step residual reacts to a plant change only through the part of the
//! flow the model cannot explain from the last measured flows, about `(1 − Σθ)` of a static
//! error (8..25 % for the identified pump models). A gain change of a few percent therefore
//! stays below the limits: this monitor flags gross changes (leak, occlusion, blower wear,
//! a stall below the stall duty), not fine drift.
//!
//! # While ventilating
//! A volume program's breaths run with the exhalation valve closed against the lung and the
//! PEEP valve, which the power-up identification (valve open, no PEEP) did not see: its model's
//! one-step residuals of the breaths exceed the window limits from the first breath on (window
//! RMS 1.3..5.5 slm, bias −1.1..−5.0 slm on ISO 80601-2-12 rows 1, 4 and 7, seeds 1 and 2,
//! against limits of 0.8..2.3 slm RMS and 0.7..1.2 slm bias at their flows), so those limits
//! raised `DRIFT` in breath 1, every time. While a volume program runs
//! ([`Monitor::set_ventilating`]) the windows are still reported, but the drift decision is
//! the **breath rule**: the mean residual of each breath (boundary to boundary,
//! [`Monitor::breath_end`]) against that of a baseline breath, the one that ends at the
//! [`BASELINE_BOUNDARY`]-th boundary: breath 3 of the program (after the lead-in and two
//! breaths, once the volume trim has settled), or the third whole breath on a swapped model.
//! A breath is beyond when its mean residual differs from the baseline's by more than
//! [`BREATH_MEAN_SLM`]; [`DRIFT_BREATHS`] breaths in a row beyond raise `DRIFT` (its `s=` then
//! counts breaths, its figures are those of the window it comes with). `DRIFT` then means: the
//! lung or the plant changed against the ventilated baseline.
//!
//! Measured (`cargo test -p ridge-pump-firmware --test drift -- --nocapture`: the firmware's
//! state machine closed loop with pump-sim's plant, the SFM3300's noise on, rows 1, 4 and 7,
//! seeds 1–5; the deviations from the `RES` windows grouped by breath): without a change
//! breaths 4–19 stay within 0.047 slm of breath 3, no `DRIFT` in 20 breaths (0 of 15 runs); a
//! change as breath 10 starts moves a breath's mean residual by 0.18..0.28 slm (row 1, a leak
//! of 100 cmH₂O/(L/s)), 0.43..0.63 (the leak on rows 4 and 7), 0.66..3.4 (C → 10 mL/cmH₂O on
//! rows 1 and 4) and 1.3..3.3 slm (R → 50 cmH₂O/(L/s)). The threshold, about 3 times the
//! largest unchanged deviation, sits below the smallest change; `DRIFT` came in breath 12 (two
//! breaths after the change) in all 35 changed runs. Row 7's lung already is C 10, R 50: only
//! its leak is a change there. Not measured: a change smaller than these (a leak's flow of a
//! few slm is near the threshold on row 1), rows 2, 3, 5, 6, 8, the ramp wave.
//!
//! A drift never starts the power-up identification while a volume program runs (its sweep
//! would stop the breaths): [`MonitorConfig::reidentify`] applies to the other programs; while
//! ventilating the drift is reported, and on the boards with the re-identification
//! ([`crate::reid`], not the ATmega2560) it triggers a re-estimate at the next breath boundary.

use ridge_core::{ArxModel, Mode, Predictor, Real};

use crate::event::{Event, Residuals};
use crate::units::SLM_PER_COUNT;

/// Settings of the run-mode monitor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorConfig {
    /// Ticks per residual report (100 = 1 s at 100 Hz); 0 counts as 1.
    pub window: u8,
    /// Absolute part of the residual RMS limit, slm.
    pub rms_abs: f32,
    /// Relative part of the RMS limit, as a fraction of the window's mean |flow|.
    pub rms_rel: f32,
    /// Absolute part of the limit of the mean residual's magnitude, slm.
    pub mean_abs: f32,
    /// Relative part of the mean-residual limit, as a fraction of the window's mean |flow|.
    pub mean_rel: f32,
    /// Consecutive windows above the limit that raise a drift (K); 0 counts as 1.
    pub seconds: u8,
    /// Ticks whose duty (1/10 000) is below this are not scored.
    pub min_duty: u16,
    /// Start a new identification when a drift is raised, except while a volume program runs
    /// (the drift is then only reported). Off by default: the excitation sweeps the pump over
    /// 20..90 % for a minute, which the application must allow.
    pub reidentify: bool,
}

impl Default for MonitorConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl MonitorConfig {
    /// The defaults: 1 s windows; RMS limit 0.5 slm + 6 % of the flow, bias limit 0.6 slm +
    /// 2 % of the flow; 3 windows; scored from 20 % duty; no automatic re-identification.
    pub const DEFAULT: MonitorConfig = {
        MonitorConfig {
            window: 100,
            rms_abs: 0.5,
            rms_rel: 0.06,
            mean_abs: 0.6,
            mean_rel: 0.02,
            seconds: 3,
            min_duty: 2_000,
            reidentify: false,
        }
    };
}

/// The run-mode monitor (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct Monitor {
    cfg: MonitorConfig,
    predictor: Predictor<f32>,
    /// Last measured flow, slm (held over sensor errors).
    last_y: f32,
    /// Ticks in the current window.
    ticks: u8,
    /// Scored samples in the current window.
    scored: u16,
    sum_e: f32,
    sum_e2: f32,
    sum_y: f32,
    /// Consecutive windows above the limit.
    over: u8,
    drift: bool,
    /// A volume program runs: the breath rule decides, not the windows'.
    vent: bool,
    /// Σe and scored samples of the breath in progress (volume program), slm.
    breath_sum: f32,
    breath_n: u16,
    /// Breath boundaries since the program started or the model was swapped.
    boundaries: u8,
    /// The baseline breath's mean residual, slm (NaN until it is complete).
    base: f32,
}

/// The breath boundary that ends the ventilated baseline breath, counted from the program's
/// start (the first ends the lead-in: the baseline is breath 3, once the volume trim has
/// settled) or from a model swap (the first ends the swap's part-breath: the baseline is the
/// third whole breath on the new model). Module docs, "While ventilating".
pub const BASELINE_BOUNDARY: u8 = 4;

/// While ventilating: the largest change of a breath's mean residual from the baseline
/// breath's, slm (module docs, "While ventilating").
pub const BREATH_MEAN_SLM: f32 = 0.15;

/// While ventilating: consecutive breaths beyond [`BREATH_MEAN_SLM`] that raise a drift.
pub const DRIFT_BREATHS: u8 = 2;

impl Monitor {
    /// A monitor of `model` (physical units: the map's flow in slm in, the flow in slm out);
    /// `vent`: a volume program runs ([`set_ventilating`](Self::set_ventilating)).
    pub fn new(model: ArxModel<f32>, cfg: MonitorConfig, vent: bool) -> Self {
        Monitor {
            cfg,
            predictor: Predictor::new(model, Mode::OneStep),
            last_y: 0.0,
            ticks: 0,
            scored: 0,
            sum_e: 0.0,
            sum_e2: 0.0,
            sum_y: 0.0,
            over: 0,
            drift: false,
            vent,
            breath_sum: 0.0,
            breath_n: 0,
            boundaries: 0,
            base: f32::NAN,
        }
    }

    /// Monitors `model` from now on (the controller's model was swapped): the windows and the
    /// drift flag start afresh.
    pub fn set_model(&mut self, model: ArxModel<f32>) {
        *self = Monitor::new(model, self.cfg, self.vent);
    }

    /// A program starts: `on` for a volume program (a new `VENT` too: its breaths differ), whose
    /// drift decision is the breath rule with a new baseline, the counts and the drift flag
    /// afresh; back to the windows' rule, afresh, when a volume program ends; nothing between
    /// two other programs (the windows and the flag go on, as before volume programs).
    // Out of line: smaller ATmega2560 image.
    #[inline(never)]
    pub fn set_ventilating(&mut self, on: bool) {
        if !on && !self.vent {
            return;
        }
        self.vent = on;
        self.over = 0;
        self.drift = false;
        self.breath_sum = 0.0;
        self.breath_n = 0;
        self.boundaries = 0;
        self.base = f32::NAN;
    }

    /// A volume program's breath boundary (a breath starts): the mean residual of the breath
    /// (or lead-in) that ended becomes the baseline ([`BASELINE_BOUNDARY`]) or, after it, is
    /// compared with it; a drift is raised with the next window's report. Called by run mode
    /// only while a volume program runs (its breath phase), after
    /// [`set_ventilating`](Self::set_ventilating)`(true)`. A breath without a scored sample
    /// has a NaN mean: beyond.
    // Out of line: once a breath, after the PWM write.
    #[inline(never)]
    pub fn breath_end(&mut self) {
        let mean = self.breath_sum / f32::from(self.breath_n);
        self.breath_sum = 0.0;
        self.breath_n = 0;
        self.boundaries = self.boundaries.saturating_add(1);
        if self.boundaries == BASELINE_BOUNDARY {
            self.base = mean;
        } else if self.boundaries > BASELINE_BOUNDARY {
            // NaN (a diverging model, no baseline) counts as beyond.
            if Real::abs(mean - self.base) <= BREATH_MEAN_SLM {
                self.over = 0;
            } else {
                self.over = self.over.saturating_add(1);
            }
        }
    }

    /// Whether a drift was raised (latched).
    pub fn drift(&self) -> bool {
        self.drift
    }

    /// Takes one tick: `duty` (1/10 000) applied during the interval that ended with the
    /// reading `counts` (1/120 slm; `None` after a sensor error), `u` the model's input for it
    /// (the map's flow at `duty`, slm). Puts [`Event::Residual`] into `event` at the end of
    /// each window with scored samples, or [`Event::Drift`] instead when the drift is raised
    /// in that window; leaves it alone otherwise. (Written in place, not returned: a returned
    /// event is a 74-byte copy, ~550 cycles on the ATmega2560.)
    pub fn step(&mut self, duty: u16, u: f32, counts: Option<i16>, event: &mut Option<Event>) {
        let measured = counts.map(|c| f32::from(c) * SLM_PER_COUNT);
        let y = measured.unwrap_or(self.last_y);
        self.last_y = y;
        let yhat = self.predictor.step(u, y);
        if let (Some(yhat), Some(y)) = (yhat, measured) {
            if duty >= self.cfg.min_duty {
                let e = y - yhat;
                self.sum_e += e;
                self.sum_e2 += e * e;
                self.sum_y += y;
                self.scored = self.scored.saturating_add(1);
                // Only while ventilating: the other programs' ticks stay as they were (with these
                // sums in every tick, simavr's console test `commands_on_the_running_pump` saw
                // one tick overrun with the log on; the cause was not found).
                if self.vent {
                    self.breath_sum += e;
                    self.breath_n = self.breath_n.saturating_add(1);
                }
            }
        }
        self.ticks = self.ticks.saturating_add(1);
        if self.ticks < self.cfg.window.max(1) {
            return;
        }
        self.close_window(event);
        self.ticks = 0;
        self.scored = 0;
        self.sum_e = 0.0;
        self.sum_e2 = 0.0;
        self.sum_y = 0.0;
    }

    /// Residual figures of the finished window and the drift decision.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    fn close_window(&mut self, event: &mut Option<Event>) {
        if self.scored == 0 {
            return;
        }
        let r = Residuals {
            sum: self.sum_e,
            sum_sq: self.sum_e2,
            sum_flow: self.sum_y,
            samples: self.scored,
        };
        // The limits are tested on the sums, without a division (~500 cycles on the
        // ATmega2560) or a square root in the tick: with n samples and level = |Σy| / n,
        // RMS ≤ abs + rel·level ⟺ n·Σe² ≤ (n·abs + rel·|Σy|)², and
        // |mean| ≤ abs + rel·level ⟺ |Σe| ≤ n·abs + rel·|Σy|. NaN residuals (a diverging
        // model) count as above the limit.
        let needed = if self.vent {
            // The breath rule counts `over` at the breath boundaries.
            DRIFT_BREATHS
        } else {
            let n = f32::from(self.scored);
            let level = Real::abs(self.sum_y);
            let rms_limit = n * self.cfg.rms_abs + self.cfg.rms_rel * level;
            let mean_limit = n * self.cfg.mean_abs + self.cfg.mean_rel * level;
            let above =
                !(n * self.sum_e2 <= rms_limit * rms_limit && Real::abs(self.sum_e) <= mean_limit);
            if above {
                self.over = self.over.saturating_add(1);
            } else {
                self.over = 0;
            }
            self.cfg.seconds
        };
        if !self.drift && self.over >= needed.max(1) {
            self.drift = true;
            *event = Some(Event::Drift {
                residuals: r,
                seconds: self.over,
                reidentify: self.cfg.reidentify,
            });
        } else {
            *event = Some(Event::Residual(r));
        }
    }
}
