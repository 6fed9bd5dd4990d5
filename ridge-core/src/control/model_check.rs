//! Is a model fit to design a controller from (identified, or loaded from storage)?

use crate::model::ArxModel;
use crate::real::Real;
use crate::P_MAX;

use super::poly::{eval, roots_within};

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
/// `stable_radius` (Schur–Cohn test), static gain within `gain_min..=gain_max`. Returns that
/// static gain `B(1) / A(1)` (output units per input unit), which the caller may need too.
pub fn check_model<T: Real>(
    model: &ArxModel<T>,
    limits: &ModelLimits<T>,
) -> Result<T, ModelFault<T>> {
    let theta = model.theta();
    let n = theta.len().min(P_MAX) + 1;
    let mut a = [T::ZERO; P_MAX + 1];
    a[0] = T::ONE;
    for k in 1..n {
        a[k] = -theta[k - 1];
    }
    let finite = |x: &[T]| x.iter().all(|v| v.is_finite());
    if !finite(&a) || !finite(model.phi()) || !model.intercept().is_finite() {
        return Err(ModelFault::NonFinite);
    }
    if !roots_within(&a[..n], limits.stable_radius) {
        return Err(ModelFault::Unstable);
    }
    let gain = eval(model.phi(), T::ONE) / eval(&a[..n], T::ONE);
    if !(gain >= limits.gain_min && gain <= limits.gain_max) {
        return Err(ModelFault::Gain { gain });
    }
    Ok(gain)
}
