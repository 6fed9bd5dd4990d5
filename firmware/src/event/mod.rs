//! Events of the self-identification state machine ([`crate::selfid`]) and their
//! machine-readable report lines (printed by `print.rs`, the only part that formats).
//!
//! Every [`Event`] prints (with [`ufmt`], no `core::fmt`, no float formatting code) as one line
//! without the line terminator: a keyword, then `key=value` fields separated by single spaces.
//! Numbers use [`crate::numfmt`]: flows in slm with 3 decimals, duties in percent with 2
//! decimals, fit in percent with 1 decimal, coefficients with 6 decimals, lists comma-separated.
//! The host tools read them back with the parsers of `lines` (host builds only), which the
//! round-trip test `tests/lines.rs` checks against every event kind printed here.
//!
//! | Event | Line |
//! |---|---|
//! | [`Event::StoredRejected`] | `STORED-REJECTED crc`, `STORED-REJECTED unstable`, `STORED-REJECTED map-slope=0.500`, `STORED-REJECTED fit=-1000.0<70.0` |
//! | [`Event::Loaded`] | `LOADED p=1 q=1 d=3 off=1 theta=0.935000 phi=0.065000 c=-0.125000 fit=87.3` |
//! | [`Event::Scan`] | `SCAN n=520 lag=20 u0=30.00 y0=19.058 attempt=1/3` |
//! | [`Event::Map`] | `MAP first=15.00 step=5.33 flow=0.125,6.608,…` (16 flows) |
//! | [`Event::Excite`] | `EXCITE flow-steps n=700 u0=30.00 y0=19.058 attempt=1/3` |
//! | [`Event::Identified`] | `ID p=1 q=1 d=3 off=1 theta=0.935000 phi=0.065000 c=-0.125000 score=-1234.5 eval=14/252 skip=0 iters=200` |
//! | [`Event::Validate`] | `VALIDATE flow-steps n=300` |
//! | [`Event::Accepted`] | `ACCEPT fit=87.3 rmse=3.230 one=2.094 n=2994 persist` |
//! | [`Event::Rejected`] | `REJECT fit=42.1<70.0 attempt=1/3`, `REJECT map=unscanned attempt=1/3` |
//! | [`Event::Control`] | `CTRL method=pole-placement tau=0.040 poles=0.779,0.900 kept=4 mm=0.571 tries=1 preview=8` |
//! | [`Event::Track`] | `TRACK sp=40.000 flow=39.875 rms=0.512 max=1.250 duty=35.20 tick=1050` |
//! | [`Event::Alarm`] | `ALARM track err=5.125 s=0.50` / `ALARM track clear` |
//! | [`Event::Breath`] | `BREATH n=3 vt=500.0 peep=5.0 vd=497.2 cmd=512.3 peak=31.250 rms=1.234` |
//! | [`Event::VolumeAlarm`] | `ALARM volume vd=612.5 vt=500.0` / `ALARM volume clear` |
//! | `Event::Reid` | `REID breath=12 verdict=kept gain=1.035 fit=92.3/90.1 v-rms=22.150`, `REID breath=4 verdict=design gain=1.006 fit=nan/nan v-rms=nan why=slow-poles tries=1` (on the ATmega2560 only with the feature `atmega2560-reid`; the verdicts: `ReidVerdict`; `nan` where a figure does not exist) |
//! | [`Event::Residual`] | `RES rms=0.812 mean=-0.013 flow=50.125 n=100` |
//! | [`Event::Drift`] | `DRIFT rms=3.200 mean=-2.997 flow=35.400 s=3 reid=0` |
//! | [`Event::Fault`] | `FAULT stall duty=45.00 flow=0.125`, `FAULT sensor=frozen flow=19.058`, `FAULT noflow duty=30.00 flow=0.125 expect=19.058`, `FAULT control margin=0.412 tries=5`, `FAULT resets watchdog=2 brownout=1` |

use ridge_core::control::{DesignError, ModelFault};
use ridge_core::{ArxModel, Error as CoreError, InputMap, MapError};

use crate::persist::PersistError;
use crate::sfm3300;

mod print;

pub use print::{core_error_name, map_error_name, Line, LINE_MAX, RECORD_NAME};
pub(crate) use print::{write_list, write_model, COEF_DIGITS};

/// Why a flow reading failed, as the board reports it to
/// [`SelfIdentification::tick`](crate::selfid::SelfIdentification::tick).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorFault {
    /// Every read attempt was NACKed (no new value, or no sensor).
    Nack,
    /// The CRC-8 of the flow word did not match.
    Crc,
    /// Any other bus error.
    Bus,
}

impl<E> From<sfm3300::Error<E>> for SensorFault {
    /// `NotReady` → [`SensorFault::Nack`], `Crc` → [`SensorFault::Crc`], `I2c(_)` →
    /// [`SensorFault::Bus`].
    fn from(e: sfm3300::Error<E>) -> Self {
        match e {
            sfm3300::Error::NotReady => SensorFault::Nack,
            sfm3300::Error::Crc => SensorFault::Crc,
            sfm3300::Error::I2c(_) => SensorFault::Bus,
        }
    }
}

impl SensorFault {
    /// Short lower-case name used in report lines: `nack`, `crc`, `bus`.
    pub const fn name(self) -> &'static str {
        match self {
            SensorFault::Nack => "nack",
            SensorFault::Crc => "crc",
            SensorFault::Bus => "bus",
        }
    }
}

/// Why the flow controller was refused: the pump never runs on it (see
/// [`FaultReason::Control`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlRefusal {
    /// The model is not fit to design from (unstable, static gain of the wrong sign or an
    /// implausible size, non-finite). Line: `FAULT control unstable`, `FAULT control
    /// gain=0.412`.
    Model(ModelFault<f32>),
    /// Every design, slowed down `tries − 1` times, failed its checks; the last one for this
    /// reason. Line: `FAULT control margin=0.412 tries=5`, `FAULT control poles tries=5`,
    /// `FAULT control singular tries=1`.
    Design {
        /// The last design's failure.
        error: DesignError<f32>,
        /// Designs made.
        tries: u8,
    },
}

/// Why a stored model record is not used (a new model is identified instead).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StoredReason {
    /// The record itself is invalid (see [`PersistError::name`]). Line: `STORED-REJECTED crc`.
    Record(PersistError),
    /// The record is valid but its model is unfit for control (the same checks as an
    /// identified one). Line: `STORED-REJECTED unstable`, `STORED-REJECTED gain=-3.125`.
    Model(ModelFault<f32>),
    /// The record's map rises implausibly little or much over the records' duty range (see
    /// `ControlConfig::map_slope`): `slope` in slm per unit duty. Line:
    /// `STORED-REJECTED map-slope=0.500`.
    MapSlope {
        /// The map's mean slope, slm per unit duty.
        slope: f32,
    },
    /// The record's validation fit is below the acceptance fit. Line:
    /// `STORED-REJECTED fit=-1000.0<70.0`.
    Fit {
        /// The stored fit, percent.
        fit: f32,
        /// The configured acceptance fit, percent.
        min: f32,
    },
}

/// Why the state machine stopped the pump and latched the fault state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultReason {
    /// `count` consecutive sensor errors, the last one `error`.
    /// Line: `FAULT sensor=crc n=5`.
    Sensor {
        /// The last error.
        error: SensorFault,
        /// Consecutive errors counted (the configured limit).
        count: u8,
    },
    /// A reading outside the configured flow range. `counts` is the reading
    /// (`raw − 32768`, 1/120 slm). Line: `FAULT range flow=-260.375` (slm).
    FlowRange {
        /// The offending reading, 1/120 slm.
        counts: i16,
    },
    /// The pump was commanded at least the stall duty but the flow stayed below the stall
    /// flow for the configured time. `duty` is the last commanded duty (1/10 000), `counts`
    /// the last reading (1/120 slm). Line: `FAULT stall duty=45.00 flow=0.125` (%, slm).
    Stall {
        /// Duty applied during the last interval, 1/10 000 of full scale.
        duty: u16,
        /// Last flow reading, 1/120 slm.
        counts: i16,
    },
    /// The sensor repeated the same reading `Config::frozen_ticks` times in a row at a flow
    /// where its noise makes that implausible: frozen. Line: `FAULT sensor=frozen
    /// flow=19.058` (slm).
    Frozen {
        /// The repeated reading, 1/120 slm.
        counts: i16,
    },
    /// The flow stayed below half the flow expected at the applied duty for the configured
    /// time (see `Config::loss_ticks`): the pump or its PWM line gives no flow. `duty` is the
    /// last applied duty (1/10 000), `counts` the last reading and `expected` the flow
    /// expected at that duty (1/120 slm). Line: `FAULT noflow duty=30.00 flow=0.125
    /// expect=19.058` (%, slm, slm).
    NoFlow {
        /// Duty applied during the last interval, 1/10 000 of full scale.
        duty: u16,
        /// Last flow reading, 1/120 slm.
        counts: i16,
        /// Flow expected at `duty`, 1/120 slm.
        expected: i16,
    },
    /// The board reset itself [`resets::LIMIT`](crate::resets::LIMIT) times (watchdog,
    /// brown-out) without a clean minute in between: a reset loop, reported at boot (see
    /// [`crate::resets`]). Line: `FAULT resets watchdog=2 brownout=1`.
    ResetLoop {
        /// Watchdog resets counted (panics included).
        watchdog: u8,
        /// Brown-out resets counted.
        brownout: u8,
    },
    /// Every identification attempt was rejected. Line: `FAULT unidentified attempts=3`.
    Unidentified {
        /// Attempts made.
        attempts: u8,
    },
    /// The flow controller for the accepted (or loaded) model was refused: the pump is
    /// stopped rather than run without a checked controller.
    Control(ControlRefusal),
}

/// Why an identification attempt was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RejectReason {
    /// The flow did not respond to the excitation: the RMS deviation of the flow from its
    /// mean over the excitation record, `rms` in slm, is below the configured minimum (or
    /// the input/output was exactly constant: `rms = 0`). Line: `REJECT not-excited rms=0.012`.
    NotExcited {
        /// RMS of the flow around its mean over the record, slm.
        rms: f32,
    },
    /// The scan gave no static map (see [`map_error_name`]). Line: `REJECT map=unscanned`.
    Map(MapError),
    /// The structure search failed with this ridge-core error.
    /// Line: `REJECT search=no-candidate` (see [`core_error_name`]).
    Search(CoreError),
    /// The free-run fit on the validation record, `fit` %, is below the configured `min` %.
    /// Line: `REJECT fit=42.1<70.0`.
    Fit {
        /// Free-run fit on the validation record, percent.
        fit: f32,
        /// Configured minimum, percent.
        min: f32,
    },
    /// The validation produced no finite score (too short a record, or a diverging model).
    /// Line: `REJECT nonfinite`.
    NonFinite,
    /// More sensor errors during a record than allowed (each one replaced by the previous
    /// reading). Line: `REJECT gaps=11`.
    SensorGaps {
        /// Sensor errors in the record so far.
        gaps: u16,
    },
}

/// Figures of a structure search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchStats {
    /// Criterion value of the chosen structure (dimensionless, e.g. delay-free AIC).
    pub score: f32,
    /// Candidates in the grid (252 by default).
    pub candidates: u16,
    /// Candidates on which the estimator ran (the rest was pruned by exact bounds).
    pub evaluated: u16,
    /// Candidates that could not be fitted on this record.
    pub skipped: u16,
    /// Estimator iterations of the chosen structure (Ridge-M iterates).
    pub iterations: u32,
    /// Samples in the estimation record.
    pub samples: u32,
}

/// Something the board should report (one line each, see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// The stored model given to `SelfIdentification::new` is unusable; the pump
    /// identifies a new one. Line: `STORED-REJECTED <reason>` (see [`PersistError::name`]).
    StoredRejected(StoredReason),
    /// A valid stored model was loaded (its map comes on the [`Event::Map`] before);
    /// identification is skipped and the pump runs.
    Loaded {
        /// The model's dynamics (physical units: the map's flow in slm in, slm out).
        model: ArxModel<f32>,
        /// Its stored validation fit, percent.
        fit: f32,
    },
    /// An identification attempt starts with the scan of the duty range (`samples` ticks:
    /// the ramps and the lead-in at the base duty), attempt `attempt` of `attempts`.
    Scan {
        /// Ticks of the scan.
        samples: u16,
        /// The plant's lag the scan credits its readings with, ticks.
        lag: u8,
        /// Operating point: the base duty, 1/10 000 of full scale.
        u0: u16,
        /// Operating point: the mean settled flow, counts (1/120 slm).
        y0: i16,
        /// This attempt, from 1.
        attempt: u8,
        /// Configured number of attempts.
        attempts: u8,
    },
    /// The scan's static map from duty to flow (the model's input map).
    Map(InputMap),
    /// The estimation record starts ([`crate::excitation::FlowSteps`], `samples` ticks),
    /// around the operating point of the attempt's [`Event::Scan`].
    Excite {
        /// Its length in samples (10 ms each).
        samples: u32,
        /// Operating point: the base duty, 1/10 000 of full scale.
        u0: u16,
        /// Operating point: the mean settled flow, counts (1/120 slm).
        y0: i16,
        /// This attempt, from 1.
        attempt: u8,
        /// Configured number of attempts.
        attempts: u8,
    },
    /// The structure search picked `model`.
    Identified {
        /// The identified model's dynamics (physical units: the map's flow in slm in, slm
        /// out).
        model: ArxModel<f32>,
        /// Search figures.
        stats: SearchStats,
    },
    /// The validation record starts ([`crate::excitation::FlowSteps`], `samples` ticks).
    Validate {
        /// Its length in samples.
        samples: u32,
    },
    /// The model passed validation. **The board must now write
    /// [`SelfIdentification::persist_bytes`](crate::selfid::SelfIdentification::persist_bytes)
    /// to non-volatile memory** ([`Event::persist`] is `true`). Scores are on the
    /// validation record from sample `m` on, seeded with the first `m = max(p, d + q − 1)`
    /// measured samples (as MATLAB `compare` scores).
    Accepted {
        /// Free-run fit, percent.
        fit: f32,
        /// Free-run RMSE, slm.
        rmse: f32,
        /// One-step-ahead RMSE, slm.
        one_step: f32,
        /// Samples scored.
        samples: u32,
    },
    /// The attempt was refused for `reason`. When `attempt == attempts` the fault state
    /// follows ([`FaultReason::Unidentified`]); otherwise the next attempt starts.
    Rejected {
        /// Why.
        reason: RejectReason,
        /// This attempt, from 1.
        attempt: u8,
        /// Configured number of attempts.
        attempts: u8,
    },
    /// The flow controller was designed and passed its checks; run mode starts.
    Control {
        /// The regulation loop's time constant, s (the speed knob as resolved and slowed).
        tau: f32,
        /// Closed-loop pole of the regulation loop, `e^{−Ts/τ}`.
        alpha: f32,
        /// Observer pole.
        beta: f32,
        /// Pole of the setpoint response: the reference model's (`e^{−Ts/0.08 s}` without a
        /// speed given), else `alpha`.
        gamma: f32,
        /// Model poles kept in place (the others of the closed loop are at 0).
        kept: u8,
        /// Modulus margin.
        margin: f32,
        /// Designs made (1 unless slowed down).
        tries: u8,
        /// Ticks the controller is given the setpoint program ahead (the designed setpoint
        /// response's mean delay).
        preview: u8,
    },
    /// Run mode, once per tracking window (1 s by default): sums over the window's scored
    /// ticks; the line prints their means (taken when printing, after the tick's PWM write:
    /// on the ATmega2560 a division costs ~500 cycles of the tick).
    Track {
        /// Σ setpoint, slm.
        sum_setpoint: f32,
        /// Σ measured flow, slm.
        sum_flow: f32,
        /// Σ (setpoint − flow)², slm² (the line prints the root of its mean).
        sum_sq: f32,
        /// Largest |error|, slm.
        max: f32,
        /// Σ duty, 1/10 000 of full scale.
        sum_duty: u32,
        /// Ticks scored (with a reading), ≥ 1.
        samples: u16,
        /// Run-mode ticks at the end of the window, counted from the first (the setpoint
        /// program's time: `tick / 100` s).
        tick: u32,
    },
    /// Run mode: the tracking error left its band for the alarm time (`on`, with the error
    /// and the time out of band), or came back (`!on`).
    Alarm {
        /// Raised (`true`) or cleared.
        on: bool,
        /// Setpoint − flow when raised, slm.
        error: f32,
        /// Ticks out of band when raised.
        ticks: u16,
    },
    /// Run mode, once per monitor window (100 ticks = 1 s by default): one-step prediction
    /// residuals of the model against the measured flow.
    Residual(Residuals),
    /// Run mode: the residual RMS or bias exceeded its limit for `seconds` consecutive
    /// windows (see [`crate::monitor`]). The drift flag is set; with `reidentify` a new
    /// identification starts.
    Drift {
        /// The residuals of the last window.
        residuals: Residuals,
        /// Consecutive windows above the limit.
        seconds: u8,
        /// Whether re-identification was started.
        reidentify: bool,
    },
    /// Volume-controlled ventilation, at each breath boundary: the breath that just ended
    /// ([`crate::ventilation`]).
    Breath(BreathSummary),
    /// Volume-controlled ventilation: the delivered volume left the band
    /// `±(4 mL + 15 %)` of the set volume for two breaths in a row (`on`, with the last
    /// breath's volume), or came back for as many (`!on`).
    VolumeAlarm {
        /// Raised (`true`) or cleared.
        on: bool,
        /// The last breath's delivered volume, mL.
        delivered: f32,
        /// The set volume, mL.
        tidal: f32,
    },
    /// Run mode's re-identification (`crate::reid`): one re-estimate's verdict (on the
    /// ATmega2560 only with the feature `atmega2560-reid`: docs/boards.md).
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    Reid(ReidReport),
    /// The pump was stopped (duty 0) and the state machine latched its fault state.
    Fault(FaultReason),
}

/// What became of one re-estimate ([`crate::reid`]), as the `REID` line's `verdict=` names it.
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReidVerdict {
    /// `accepted`: it passed every check and the swap rule (`crate::reid::SwapRule`; by
    /// default: the volume alarm is raised): swapped in at the next breath boundary.
    Accepted,
    /// `kept`: it passed every check, but not the swap rule: reported, the running controller
    /// kept.
    Kept,
    /// `not-excited`: the window's input or output moved too little.
    NotExcited,
    /// `model`: unstable, not finite, or the static gain out of range (the design's model
    /// check).
    Model,
    /// `fit`: the held-out free-run fit below the minimum or below the running model's.
    Fit,
    /// `numeric`: the fit's normal equations were not positive definite or its iterates not
    /// finite.
    Numeric,
    /// `design`: the controller design for the accepted estimate was refused, for this reason
    /// (the running one stays). The line adds `why=` and the reason in the words of the
    /// `FAULT control` line: `why=margin margin=0.412 tries=4`, `why=slow-poles tries=1`,
    /// `why=unstable`, `why=gain` (the estimate's gain is on the line already).
    Design(ControlRefusal),
}

#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
impl ReidVerdict {
    /// The name on the `REID` line.
    pub const fn name(self) -> &'static str {
        match self {
            ReidVerdict::Accepted => "accepted",
            ReidVerdict::Kept => "kept",
            ReidVerdict::NotExcited => "not-excited",
            ReidVerdict::Model => "model",
            ReidVerdict::Fit => "fit",
            ReidVerdict::Numeric => "numeric",
            ReidVerdict::Design(_) => "design",
        }
    }
}

/// One re-estimate as its `REID` line reports it.
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReidReport {
    /// The breath at whose start the snapshot was taken (from 1).
    pub breath: u32,
    /// What became of it.
    pub verdict: ReidVerdict,
    /// The estimate's static gain, slm/slm (NaN without an estimate).
    pub gain: f32,
    /// The estimate's free-run fit on the held-out breath, percent (NaN when not scored).
    pub fit: f32,
    /// The running model's free-run fit on the same samples, percent (NaN when not scored).
    pub running: f32,
    /// The window's input (the map's flow) RMS about its mean, slm.
    pub v_rms: f32,
}

/// One volume-controlled breath as its `BREATH` line reports it: sums and counts, the means
/// taken when printing (after the tick's PWM write).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BreathSummary {
    /// The breath's number, from 1 when ventilation started.
    pub number: u32,
    /// Set tidal volume, mL.
    pub tidal: f32,
    /// Set PEEP, cmH₂O.
    pub peep: f32,
    /// Delivered volume: the readings integrated over the inspiration, mL.
    pub delivered: f32,
    /// The volume the breath was programmed for (set volume and trim), mL.
    pub command: f32,
    /// Largest reading of the inspiration, counts (1/120 slm).
    pub peak: i16,
    /// Σ (setpoint − reading)² over the breath, slm².
    pub sum_sq: f32,
    /// Ticks in the sum, ≥ 1.
    pub samples: u16,
}

/// One monitor window's one-step prediction residuals (measured − predicted), as sums: the
/// means are taken when printing, after the tick's PWM write (on the ATmega2560 a division
/// costs ~500 cycles of the tick).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Residuals {
    /// Σ residual, slm.
    pub sum: f32,
    /// Σ residual², slm².
    pub sum_sq: f32,
    /// Σ measured flow, slm.
    pub sum_flow: f32,
    /// Samples scored, ≥ 1.
    pub samples: u16,
}

impl Residuals {
    /// `(mean, rms, mean flow)`, slm (one division; an empty window counts as 1 sample).
    pub fn means(&self) -> (f32, f32, f32) {
        let inv = 1.0 / f32::from(self.samples.max(1));
        (self.sum * inv, root(self.sum_sq * inv), self.sum_flow * inv)
    }
}

impl Event {
    /// `true` when the board must write
    /// [`persist_bytes`](crate::selfid::SelfIdentification::persist_bytes) to non-volatile
    /// memory ([`Event::Accepted`]).
    pub fn persist(&self) -> bool {
        matches!(self, Event::Accepted { .. })
    }
}

/// `√x` for a mean square as an RMS.
fn root(x: f32) -> f32 {
    ridge_core::Real::sqrt(x)
}
