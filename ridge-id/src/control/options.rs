//! What `--control` asks for ([`ControlOptions`]): the design's settings, the model's limits
//! and the simulated loop's input limits, with their checks.

use ridge_core::control::{Limits, ModelLimits, Spec};

use crate::error::IdError;

/// Every model pole must lie within this radius: the firmware's default
/// (`ControlConfig::DEFAULT.model.stable_radius`).
pub const STABLE_RADIUS: f64 = 0.995;

/// Default sample period, s: the pump's 100 Hz. (The CSV's `t` column is not read.)
pub const DEFAULT_TS: f64 = 0.01;

/// What `--control` does: the design's settings, the model checks and the step simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOptions {
    /// Sample period of the log, s (default [`DEFAULT_TS`]).
    pub ts: f64,
    /// The speed knob, [`Spec::tau`]: time constant of the setpoint response, s. `None`: a
    /// quarter of the model's open-loop time constant (from its slow pole), between `2 Ts`
    /// and 2 s; 0.1 s for a model without a slow pole (ridge-core's rule).
    pub speed: Option<f64>,
    /// Time constant of the observer pole, [`Spec::observer`], s (default ridge-core's and
    /// the firmware's 0.095 s: `β = 0.9` at 100 Hz). It buys robustness: the slower, the larger
    /// the modulus margin, at the price of a slower disturbance rejection. At another sample
    /// period scale it with `Ts` (e.g. `9.5 Ts` keeps `β = 0.9`).
    pub observer: f64,
    /// Smallest accepted static gain, output units per input unit (`None`: any positive
    /// gain).
    pub gain_min: Option<f64>,
    /// Largest accepted static gain (`None`: no limit).
    pub gain_max: Option<f64>,
    /// Smallest input of the simulated loop (`None`: the smallest `u` of the log).
    pub u_min: Option<f64>,
    /// Largest input of the simulated loop (`None`: the largest `u` of the log).
    pub u_max: Option<f64>,
    /// Largest input change per sample of the simulated loop (`None`: no rate limit).
    pub u_step: Option<f64>,
}

impl Default for ControlOptions {
    fn default() -> Self {
        ControlOptions {
            ts: DEFAULT_TS,
            speed: None,
            observer: Spec::<f64>::new(DEFAULT_TS).observer,
            gain_min: None,
            gain_max: None,
            u_min: None,
            u_max: None,
            u_step: None,
        }
    }
}

impl ControlOptions {
    /// Checks the values, with a message naming the option.
    pub fn check(&self) -> Result<(), IdError> {
        let bad = |m: String| Err(IdError::Usage(m));
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.ts) {
            return bad(format!(
                "--ts {}: must be a sample period in seconds above 0",
                self.ts
            ));
        }
        if let Some(s) = self.speed {
            if !positive(s) {
                return bad(format!(
                    "--speed {s}: must be a time constant in seconds above 0"
                ));
            }
        }
        if !positive(self.observer) {
            return bad(format!(
                "--observer {}: must be a time constant in seconds above 0",
                self.observer
            ));
        }
        for (name, v) in [
            ("--gain-min", self.gain_min),
            ("--gain-max", self.gain_max),
            ("--u-min", self.u_min),
            ("--u-max", self.u_max),
        ] {
            if let Some(v) = v {
                if !v.is_finite() {
                    return bad(format!("{name} {v}: must be a finite number"));
                }
            }
        }
        if let (Some(a), Some(b)) = (self.gain_min, self.gain_max) {
            if a > b {
                return bad(format!("--gain-min {a} is above --gain-max {b}"));
            }
        }
        if let (Some(a), Some(b)) = (self.u_min, self.u_max) {
            if a >= b {
                return bad(format!("--u-min {a} must be below --u-max {b}"));
            }
        }
        if let Some(s) = self.u_step {
            if !positive(s) {
                return bad(format!("--u-step {s}: must be a number above 0"));
            }
        }
        Ok(())
    }

    /// The model limits of these options (see the [module docs](super)).
    pub fn model_limits(&self) -> ModelLimits<f64> {
        ModelLimits {
            stable_radius: STABLE_RADIUS,
            gain_min: self.gain_min.unwrap_or(f64::MIN_POSITIVE),
            gain_max: self.gain_max.unwrap_or(f64::INFINITY),
        }
    }

    /// The design settings: ridge-core's defaults at [`ControlOptions::ts`] with the speed
    /// knob and the observer, as the firmware builds them.
    pub fn spec(&self) -> Spec<f64> {
        Spec {
            tau: self.speed,
            observer: self.observer,
            ..Spec::new(self.ts)
        }
    }

    /// The input limits of the simulated loop: these options, else the log's input range
    /// `u_range`; no rate limit unless [`ControlOptions::u_step`].
    pub fn limits(&self, u_range: (f64, f64)) -> Result<Limits<f64>, IdError> {
        let min = self.u_min.unwrap_or(u_range.0);
        let max = self.u_max.unwrap_or(u_range.1);
        if min.is_nan() || max.is_nan() || min >= max {
            return Err(IdError::Usage(format!(
                "the simulated loop's input limits are empty: u from {min} to {max} \
                 (the log's u range is {} to {}; set --u-min and --u-max)",
                u_range.0, u_range.1
            )));
        }
        Ok(Limits {
            min,
            max,
            max_step: self.u_step.unwrap_or(f64::INFINITY),
        })
    }
}
