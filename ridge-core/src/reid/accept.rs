//! The checks a re-estimate passes before it may replace the running model: [`Acceptance`] on
//! the estimate and its window, [`Holdout`] on the breaths after its snapshot.

use crate::control::{check_model, ModelFault, ModelLimits};
use crate::model::{ArxModel, Metrics, Mode, Predictor, Score};
use crate::real::Real;

/// Why a re-estimate is refused (the running model stays).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rejection<T> {
    /// Not finite, a pole outside the radius, or the static gain out of range (the power-up
    /// model's check, [`check_model`]).
    Model(ModelFault<T>),
    /// The window's output moved less than [`Acceptance::min_response`] or its input less
    /// than [`Acceptance::min_input_response`] (RMS about their means): too little excitation
    /// to identify from.
    NotExcited {
        /// The window's output RMS deviation.
        response: T,
        /// The window's input RMS deviation.
        input_response: T,
    },
    /// On the held-out data the estimate's free-run fit (percent) is below
    /// [`Acceptance::min_fit`] or below the running model's.
    Fit {
        /// The estimate's free-run fit, percent.
        candidate: T,
        /// The running model's free-run fit on the same samples, percent.
        running: T,
    },
    /// Fewer held-out samples were scored than [`Acceptance::holdout_min`].
    TooFewHeldOut {
        /// Samples scored.
        scored: u32,
    },
}

/// The acceptance rules of a re-estimate, those of the power-up model where they apply:
/// - the model check of the controller design ([`ModelLimits`]: poles within the radius, the
///   static gain in range);
/// - the data excited the plant: the window's output RMS about its mean at least
///   `min_response` (the power-up record's "not excited" rule) and, as in closed loop the
///   output's spread is also the sensor noise fed back, the input's at least
///   `min_input_response`;
/// - validation on data the fit did not see: on the samples after the snapshot (the next
///   breath or two), the estimate's free-run fit at least `min_fit` percent (the power-up
///   validation record's rule) and at least the running model's fit on the same samples (a
///   re-estimate replaces the running model only when it predicts better).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Acceptance<T> {
    /// Model limits (the firmware's: poles within 0.995, gain in its range).
    pub model: ModelLimits<T>,
    /// Smallest RMS of the window's output about its mean, output units.
    pub min_response: T,
    /// Smallest RMS of the window's input about its mean, input units.
    pub min_input_response: T,
    /// Smallest free-run fit on the held-out samples, percent (power-up: 70).
    pub min_fit: T,
    /// Held-out samples to score before a verdict (e.g. one breath).
    pub holdout_min: u32,
}

impl<T: Real> Acceptance<T> {
    /// The checks on the estimate itself: the window's `response` and `input_response`
    /// ([`super::Refit::response`], [`super::Refit::input_response`]), then the model check.
    /// Returns the static gain.
    pub fn check_estimate(
        &self,
        model: &ArxModel<T>,
        response: T,
        input_response: T,
    ) -> Result<T, Rejection<T>> {
        // A NaN or infinite response is refused too.
        let low = |x: T, min: T| !x.is_finite() || x < min;
        if low(response, self.min_response) || low(input_response, self.min_input_response) {
            return Err(Rejection::NotExcited {
                response,
                input_response,
            });
        }
        check_model(model, &self.model).map_err(Rejection::Model)
    }

    /// The verdict of a [`Holdout`]: `Ok` with its figures when the estimate may replace the
    /// running model.
    pub fn judge(&self, holdout: &Holdout<T>) -> Result<HoldoutVerdict<T>, Rejection<T>> {
        let v = holdout
            .verdict()
            .ok_or(Rejection::TooFewHeldOut { scored: 0 })?;
        if v.candidate.n < self.holdout_min {
            return Err(Rejection::TooFewHeldOut {
                scored: v.candidate.n,
            });
        }
        let (c, r) = (v.candidate.fit, v.running.fit);
        if !c.is_finite() || c < self.min_fit || c < r {
            return Err(Rejection::Fit {
                candidate: c,
                running: r,
            });
        }
        Ok(v)
    }
}

/// The held-out figures: free-run fits of the estimate and the running model, and the
/// estimate's one-step fit, on the same samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldoutVerdict<T> {
    /// The estimate, free run.
    pub candidate: Metrics<T>,
    /// The estimate, one step ahead.
    pub candidate_one_step: Metrics<T>,
    /// The running model, free run.
    pub running: Metrics<T>,
}

/// Scores an estimate and the running model on samples the estimate was not fitted on (feed
/// it the ticks after the snapshot): both simulated free-run from the same measured seed, and
/// the estimate one step ahead. Three predictors (each seeded with its model's first `m`
/// measured samples) and three scores (504 bytes in `f32` on a 64-bit host); per tick about
/// `p + q + 1` products each.
#[derive(Debug, Clone)]
pub struct Holdout<T: Real> {
    candidate: Predictor<T>,
    candidate_one: Predictor<T>,
    running: Predictor<T>,
    s_candidate: Score<T>,
    s_candidate_one: Score<T>,
    s_running: Score<T>,
    /// Samples scored.
    scored: u32,
}

impl<T: Real> Holdout<T> {
    /// Starts scoring `candidate` against `running`.
    pub fn new(candidate: ArxModel<T>, running: ArxModel<T>) -> Self {
        Holdout {
            candidate: Predictor::new(candidate, Mode::FreeRun),
            candidate_one: Predictor::new(candidate, Mode::OneStep),
            running: Predictor::new(running, Mode::FreeRun),
            s_candidate: Score::new(),
            s_candidate_one: Score::new(),
            s_running: Score::new(),
            scored: 0,
        }
    }

    /// Takes one sample `(u_t, y_t)` in the models' units. A sample is scored only once both
    /// free-run predictors are seeded, so that both are scored on the same samples.
    pub fn push(&mut self, u: T, y: T) {
        let c = self.candidate.step(u, y);
        let o = self.candidate_one.step(u, y);
        let r = self.running.step(u, y);
        if let (Some(c), Some(o), Some(r)) = (c, o, r) {
            self.s_candidate.add(y, c);
            self.s_candidate_one.add(y, o);
            self.s_running.add(y, r);
            self.scored = self.scored.saturating_add(1);
        }
    }

    /// Samples scored so far (each by all three predictors): what [`Acceptance::judge`]
    /// compares with [`Acceptance::holdout_min`], without computing the figures.
    pub fn scored(&self) -> u32 {
        self.scored
    }

    /// The figures so far (`None` before a sample was scored).
    pub fn verdict(&self) -> Option<HoldoutVerdict<T>> {
        Some(HoldoutVerdict {
            candidate: self.s_candidate.metrics()?,
            candidate_one_step: self.s_candidate_one.metrics()?,
            running: self.s_running.metrics()?,
        })
    }
}
