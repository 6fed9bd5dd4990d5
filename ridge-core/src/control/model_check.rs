//! Is a model fit to design a controller from (identified, or loaded from storage)?

use crate::model::ArxModel;
use crate::real::Real;
use crate::P_MAX;

use super::poly::{at_one, roots_within};

/// What a model must satisfy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelLimits<T> {
    /// Every pole of the model within this radius (stable with margin; 0.995).
    pub stable_radius: T,
    /// Smallest static gain `B(1) / A(1)`, output units per input unit (positive: more input,
    /// more output).
    pub gain_min: T,
    /// Largest static gain.
    pub gain_max: T,
}

/// Why a model is not fit for control.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ModelFault<T> {
    /// A coefficient is NaN or ±∞.
    NonFinite,
    /// A pole lies outside [`ModelLimits::stable_radius`].
    Unstable,
    /// The static gain is outside `gain_min..=gain_max` (of the wrong sign, too small or too
    /// large); `gain` is its value (±∞ for an integrating model).
    Gain {
        /// `B(1) / A(1)`.
        gain: T,
    },
}

/// Checks `model` against `limits`: finite coefficients, every pole of `A` within
/// `stable_radius` (Schur–Cohn test), static gain within `gain_min..=gain_max`.
pub fn check_model<T: Real>(
    model: &ArxModel<T>,
    limits: &ModelLimits<T>,
) -> Result<(), ModelFault<T>> {
    let mut a = [T::ZERO; P_MAX + 1];
    a[0] = T::ONE;
    for (dst, &th) in a.iter_mut().skip(1).zip(model.theta()) {
        if !th.is_finite() {
            return Err(ModelFault::NonFinite);
        }
        *dst = -th;
    }
    let a = a.get(..model.theta().len() + 1).unwrap_or(&[]);
    if model.phi().iter().any(|v| !v.is_finite()) || !model.intercept().is_finite() {
        return Err(ModelFault::NonFinite);
    }
    if !roots_within(a, limits.stable_radius) {
        return Err(ModelFault::Unstable);
    }
    let gain = at_one(model.phi()) / at_one(a);
    if !(gain >= limits.gain_min && gain <= limits.gain_max) {
        return Err(ModelFault::Gain { gain });
    }
    Ok(())
}
