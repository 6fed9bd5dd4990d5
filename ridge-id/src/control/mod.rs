//! `ridge-id identify … --control`: the flow controller for the identified model, designed
//! with the same ridge-core code the firmware runs ([`ridge_core::control`], here in `f64`),
//! its closed-loop poles, and a simulated setpoint step for the plot.
//!
//! # Conventions
//! Polynomials in the backward shift `q⁻¹`, coefficient lists in ascending powers
//! (`a[k]` multiplies `q⁻ᵏ`).
//! - Model: `A(q⁻¹) y_t = q^{−d} B(q⁻¹) u_t + c`, `A = [1, −θ₁, …, −θ_p]`,
//!   `B = [φ₀, …, φ_{q−1}]`.
//! - Controller: `R(q⁻¹) u_{t+1} = T(q⁻¹) r_{t+1} − S(q⁻¹) y_t`, `R` monic: the input for the
//!   next sample interval from the readings up to `y_t`.
//! - Closed loop: `P = A R + q^{−d−1} B S`; its poles are the roots `z` of
//!   `P₀ zⁿ + P₁ zⁿ⁻¹ + … + Pₙ` (inside the unit circle: stable). Integral action:
//!   `R(1) = 0`; unit static gain: `T(1) = S(1)`.
//! - Modulus margin: `1 / max_ω |A R / P|` on the unit circle (the smallest distance of the
//!   loop transfer to −1; at least 0.5 is required).
//!
//! # What is checked, in this order
//! 1. The model ([`check_model`]): finite coefficients; every pole of `A` within
//!    [`STABLE_RADIUS`] (the firmware's); static gain `B(1)/A(1)` positive (more input, more
//!    output), or within `--gain-min..=--gain-max` when given (the firmware accepts 20..2000
//!    slm per unit duty: pass `--gain-min 20 --gain-max 2000` for a pump log in those units;
//!    there is no absolute default, the log's units being unknown here). A unit-free size
//!    check too: over the log's `u` span the gain must move `y` by at least [`MIN_EFFECT`]
//!    (1 %) of the log's `y` span (this refuses a model with `B(1) ≈ 0`).
//! 2. The design ([`design_slower_on_failure`], as the firmware calls it: [`TRIES`] designs,
//!    each [`SLOWDOWN`] times slower than the last while the closed-loop pole check or the
//!    modulus-margin check fails): the closed loop built equals the designed `P`, its roots
//!    lie within the slowest designed pole + 0.01, the modulus margin is at least 0.5.
//!
//! A refusal is a [`Refusal`] (which check, with its numbers), not an error: the
//! identification is still reported, and the binary exits with [`EXIT_REFUSED`].
//!
//! [`check_model`]: ridge_core::control::check_model
//! [`design_slower_on_failure`]: ridge_core::control::design_slower_on_failure
//!
//! Files: `options.rs` (what `--control` asks for), `poly.rs` (polynomials and their roots),
//! `design.rs` (the checks and the design), `step.rs` (the simulated setpoint step). The text
//! of the report's section is the printer's (`printer/text_control.rs`).

mod design;
mod options;
mod poly;
mod step;

pub use design::{
    closed_loop, control, conventions, device_model, Check, ControlReport, Designed, LogSpan,
    Refusal, EXIT_REFUSED, MIN_EFFECT, SLOWDOWN, TRIES,
};
pub use options::{ControlOptions, DEFAULT_TS, STABLE_RADIUS};
pub use poly::{denominator, format_pole, mul, pole_list, roots, Pole};
pub use step::{simulate_step, StepResponse};
