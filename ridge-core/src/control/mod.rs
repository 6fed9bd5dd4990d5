//! Flow control from the identified model: a pole-placement RST controller with integral
//! action designed on the device, the checks it must pass before it may drive the pump, and the
//! controller running with limits, a rate limit, anti-windup and a bumpless start.
//!
//! # Conventions
//! Polynomials in the backward shift `q⁻¹`, coefficient lists in ascending powers.
//! - Model: `A(q⁻¹) y_t = q^{−d} B(q⁻¹) u_t + c`, `A = [1, −θ₁, …, −θ_p]`,
//!   `B = [φ₀, …, φ_{q−1}]`; `u_t` is the input applied during the interval that ends with the
//!   reading `y_t`.
//! - Controller: `R(q⁻¹) u_{t+1} = T(q⁻¹) r_{t+1} − S(q⁻¹) y_t`, `R` monic: the input for the
//!   next interval is computed from readings up to `y_t`.
//! - Closed loop: `P = A R + q^{−d−1} B S`. Integral action: `R(1) = 0`; unit static gain:
//!   `T(1) = S(1)`. Modulus margin: `1 / max_ω |A R / P|` on the unit circle.
//!
//! # Parts
//! - [`design`](design::design): pole placement with an integrator ([`Spec`] holds the speed
//!   knob `τ`), checked: closed-loop polynomial as designed, its roots within the slowest
//!   designed pole, modulus margin ≥ 0.5; [`design_slower_on_failure`] retries slower.
//! - [`check_model`]: is the model fit to design from (stable, static gain of the expected sign
//!   and a plausible size).
//! - [`Controller`]: an [`Rst`] running, in the model's units.
//! - [`poly`]: the polynomial tools (products, Schur–Cohn root test, dominant root).

pub mod design;
mod margin;
mod model_check;
pub mod poly;
mod rst;

pub use design::{
    design, design_slower_on_failure, exp_neg, Design, DesignError, Spec, REFERENCE_S,
};
pub use margin::{modulus_margin, SWEEP_POINTS};
pub use model_check::{check_model, ModelFault, ModelLimits};
pub use rst::{Coefficients, Controller, Limits, Rst, RstError, R_LEN, S_LEN};
