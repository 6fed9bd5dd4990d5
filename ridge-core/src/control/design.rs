//! Pole placement with an integrator, from an identified ARX model to an [`Rst`] controller.
//!
//! # Method
//! The model `A(q⁻¹) y_t = q^{−d} B(q⁻¹) u_t + c` (`A = [1, −θ₁, …, −θ_p]`, `B = [φ₀, …]`) is
//! seen by the controller with one more sample of delay (the duty for the next interval is
//! computed from the reading that ends this one). The controller
//! `R u_{t+1} = T r_{t+1} − S y_t` with `R = (1 − q⁻¹) R'` (integral action: no steady-state
//! error whatever the offset `c` or a gain error) places the closed-loop poles at the roots
//! of a chosen `P` by solving the Diophantine equation
//!
//! ```text
//! A (1 − q⁻¹) R' + q^{−d−1} B S = P,   deg R' = d + q − 1,  deg S = p,  deg P ≤ p + q + d
//! ```
//!
//! (no plant zero is cancelled, so zeros near or outside the unit circle are harmless). The
//! chosen `P` is
//!
//! ```text
//! P = (1 − α q⁻¹) · (1 − β q⁻¹) · A_fast(q⁻¹)        (the other poles of the closed loop at 0)
//! ```
//!
//! - `α = e^{−Ts/τ}`: **the speed knob** `τ`, the time constant of the setpoint response;
//! - `β = e^{−Ts/τ_o}`: an observer pole (`τ_o` ≈ 95 ms by default) that buys robustness:
//!   the slower it is, the larger the modulus margin, at the price of a slower rejection of
//!   disturbances (not of a slower setpoint response, see `T`);
//! - `A_fast`: the model's own fast poles (within [`Spec::keep_radius`]), kept where the plant
//!   has them: the controller spends no effort moving them. Only the slow pole, which must be
//!   real and alone (a blower's dominant lag), is moved, to `α`; a model with more slow poles
//!   or a slow complex pair is refused ([`DesignError::SlowPoles`]).
//!
//! `T = t₀ (1 − β q⁻¹) A_fast` with `t₀` such that `T(1) = S(1)` cancels everything but `α` from
//! the setpoint response: `y = q^{−d−1} (B / B(1)) (1 − α) / (1 − α q⁻¹) · r`, a first-order
//! response with the time constant `τ` after the loop's delay, without overshoot (for a `B`
//! with positive coefficients).
//!
//! The anti-windup observer polynomial is `A_o = (1 − β q⁻¹) A_fast` (see
//! [`Controller`](super::Controller)).
//!
//! A reference model for the setpoint ([`Design::set_reference`]; the firmware's has the time
//! constant [`REFERENCE_S`] = 0.08 s) then replaces `α` in the setpoint response by
//! `γ = e^{−Ts/τ_ref}` ([`Rst::set_reference`]):
//! `y = q^{−d−1} (B / B(1)) (1 − γ) / (1 − γ q⁻¹) · r`. So the regulation loop keeps the
//! plant-derived `τ` (disturbances, margin) while the setpoint response has one time constant
//! on every plant.
//!
//! Why this method: it needs only the model (no tuning experiment), a solve of the size of the
//! slow poles (see [`design`]: milliseconds on the ATmega2560), it has integral action and
//! anti-windup in the same
//! polynomial form, its closed-loop poles are known by construction (so the check that they
//! are where they were put is exact), and it separates the setpoint response (`τ`) from the
//! robustness (`β`). On the simulated pumps this reaches a modulus margin of 0.55–0.65 with
//! `τ` a quarter of the plant's open-loop time constant (see `docs/control.md`).

use crate::model::ArxModel;
use crate::real::Real;
use crate::P_MAX;

use super::margin::modulus_margin;
use super::poly::{deflate, dominant_real_root, eval, mul, roots_within, POLY_LEN};
use super::rst::{Rst, R_LEN, S_LEN};

/// The design's settings. Times in seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec<T> {
    /// Sample period (0.01 s at 100 Hz).
    pub ts: T,
    /// The speed knob: time constant of the setpoint response after the loop delay. `None`:
    /// a quarter of the model's open-loop time constant `−Ts / ln λ` (`λ` its slow pole), at
    /// least `2 Ts` and at most 2 s; 0.1 s when the model has no slow pole.
    pub tau: Option<T>,
    /// Time constant of the observer pole `β` (0.095 s: `β = 0.9` at 100 Hz).
    pub observer: T,
    /// Both time constants are multiplied by this (1; [`Spec::slower`] raises it).
    pub slowdown: T,
    /// Model poles within this radius (all but the dominant one) are kept in `P` (0.8).
    pub keep_radius: T,
    /// Smallest accepted modulus margin (0.5).
    pub min_margin: T,
}

/// The time constant of the setpoint's reference model the firmware and `ridge-id` use when no
/// speed is given, s ([`Design::set_reference`] with `γ = e^{−Ts/REFERENCE_S}`). It decouples
/// the setpoint response from the regulation loop's `τ`, which the default design takes from
/// the plant (a quarter of its open-loop time constant, 0.04–0.1 s on the simulated pumps). On
/// the simulated blowers with a test lung, a `τ`-sized response overshoots by up to 19 %
/// (noise-free; 25 % in simavr with noise) where the duty saturates on the stiff lung (small
/// blower, `τ` = 0.047 s) and lags the breath's ramps by up to 5.3 % of peak on the sluggish
/// blower (`τ` ≈ 0.095 s); a fixed reference between 0.07 and 0.09 s meets both targets
/// (overshoot ≤ 10 %, breath RMS ≤ 5 %) on all nine plants of `docs/control.md`, 0.08 s in the
/// middle.
pub const REFERENCE_S: f64 = 0.08;

impl<T: Real> Spec<T> {
    /// The default design at the sample period `ts` (see each field).
    pub fn new(ts: T) -> Self {
        Spec {
            ts,
            tau: None,
            observer: T::from_f64(0.095),
            slowdown: T::ONE,
            keep_radius: T::from_f64(0.8),
            min_margin: T::from_f64(0.5),
        }
    }

    /// The same design `factor` times slower (both time constants scaled).
    pub fn slower(&self, factor: T) -> Self {
        Spec {
            slowdown: self.slowdown * factor,
            ..*self
        }
    }
}

/// A checked design: the controller, where its closed-loop poles are, and its margin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Design<T: Real> {
    /// The controller.
    pub rst: Rst<T>,
    /// The settings it was made with.
    pub spec: Spec<T>,
    /// The time constant of the setpoint response, s (the speed knob as resolved and slowed).
    pub tau: T,
    /// Closed-loop pole of the setpoint response, `e^{−Ts/τ}`.
    pub alpha: T,
    /// Observer pole, `e^{−Ts/τ_o}`.
    pub beta: T,
    /// Pole of the setpoint response: `α`, or after [`set_reference`](Self::set_reference)
    /// the reference model's `e^{−Ts/τ_ref}`.
    pub gamma: T,
    /// Model poles kept in `P` (0 when none were kept).
    pub kept: u8,
    /// `1 / max_ω |A R / P|` on the unit circle.
    pub modulus_margin: T,
}

impl<T: Real> Design<T> {
    /// The mean delay of the designed setpoint response, in samples: the centre of gravity of
    /// the impulse response of `q^{−d−1} (B / B(1)) (1 − γ) / (1 − γ q⁻¹)`, which is
    /// `d + 1 + Σ k φₖ / Σ φₖ + γ / (1 − γ)` (`γ` = [`gamma`](Self::gamma)). Given a setpoint
    /// known ahead (a breath program) this many samples early, the flow follows it in time (a
    /// ramp without lag). `model` is the model the design was made for; the result is not
    /// finite when `B(1) = 0`.
    pub fn mean_delay(&self, model: &ArxModel<T>) -> T {
        let (mut sum, mut moment, mut k) = (T::ZERO, T::ZERO, T::ZERO);
        for &phi in model.phi() {
            sum += phi;
            moment += k * phi;
            k += T::ONE;
        }
        T::from_u32(u32::from(model.structure().d))
            + T::ONE
            + moment / sum
            + self.gamma / (T::ONE - self.gamma)
    }

    /// Gives the setpoint a first-order reference model with the pole `gamma`, in `0 ≤ γ < 1`
    /// (`e^{−Ts/τ_ref}` for the time constant `τ_ref`, s; the firmware's is [`REFERENCE_S`]):
    /// the setpoint response becomes `q^{−d−1} (B / B(1)) (1 − γ) / (1 − γ q⁻¹)`, `γ` in
    /// place of `α` ([`Rst::set_reference`]). `R`, `S`, the closed-loop poles and the margin
    /// do not change, so the checks made by [`design`] still hold. Refused
    /// ([`DesignError::Spec`], nothing changed) for any other `gamma`.
    pub fn set_reference(&mut self, gamma: T) -> Result<(), DesignError<T>> {
        self.rst
            .set_reference(self.alpha, gamma)
            .map_err(|_| DesignError::Spec)?;
        self.gamma = gamma;
        Ok(())
    }
}

/// Why a design was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DesignError<T> {
    /// The settings are not positive and finite (`τ`, `τ_o`, `Ts`), or the model has no input
    /// coefficient.
    Spec,
    /// The Diophantine equation is singular: `A (1 − q⁻¹)` and `B` have a common root (the
    /// model cannot be controlled), or the solution is not finite.
    Singular,
    /// The model has more than one pole outside [`Spec::keep_radius`], or a slow pole that
    /// is not real (an oscillating plant): this design moves one real slow pole (a blower's
    /// lag) and keeps the rest.
    SlowPoles,
    /// The closed loop `A R + q^{−d−1} B S` is not the designed `P` (numerical failure), or not
    /// all its roots lie within the radius of the slowest designed pole plus 0.01.
    Poles,
    /// The modulus margin is below [`Spec::min_margin`].
    Margin {
        /// The margin reached.
        margin: T,
    },
}

/// Factor on [`Spec::min_margin`] covering the margin sweep's sampling error.
const MARGIN_SLACK: f64 = 1.001;

/// Largest relative mismatch between the designed `P` and `A R + q^{−d−1} B S`.
const P_TOLERANCE: f64 = 1e-3;

/// `A = [1, −θ₁, …, −θ_p]` of `model` into `a`; returns its length.
fn denominator<T: Real>(model: &ArxModel<T>, a: &mut [T; P_MAX + 1]) -> usize {
    let theta = model.theta();
    let n = theta.len().min(P_MAX) + 1;
    a[0] = T::ONE;
    for k in 1..n {
        a[k] = -theta[k - 1];
    }
    n
}

fn clamp<T: Real>(x: T, lo: T, hi: T) -> T {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

/// Designs the controller for `model` with `spec` (see the module docs) and checks it: the
/// closed loop equals the designed `P` to 1e-3, all its roots lie within the slowest designed
/// pole plus 0.01, and the modulus margin is at least [`Spec::min_margin`].
///
/// # Computation
/// At most one model pole may lie outside [`Spec::keep_radius`], and it must be real (a
/// blower's lag: found by Newton's method from `z = 1` and deflated, `A = (1 − λ q⁻¹) A_fast`);
/// more slow poles, or a slow complex pair, are refused ([`DesignError::SlowPoles`]). The kept
/// factor `A_fast` is common to `A (1 − q⁻¹)` and `P` and cancels from the Diophantine
/// equation:
///
/// ```text
/// (1 − λ q⁻¹)(1 − q⁻¹) R' + q^{−d−1} B S'' = (1 − α q⁻¹)(1 − β q⁻¹),   S = A_fast S''
/// ```
///
/// Its two unknowns `S'' = s₀ + s₁ q⁻¹` follow from the equation at `q⁻¹ = 1` and
/// `q⁻¹ = 1/λ`, where the `R'` term vanishes; `R = (1 − q⁻¹) R'` is then the exact quotient
/// of `P_small − q^{−d−1} B S''` by `1 − λ q⁻¹`. No `(p + q + d)`-square Sylvester matrix:
/// a few hundred bytes of stack
/// on the ATmega2560 instead of two kilobytes.
#[inline(never)]
pub fn design<T: Real>(model: &ArxModel<T>, spec: &Spec<T>) -> Result<Design<T>, DesignError<T>> {
    let s = model.structure();
    let (p, q, d) = (usize::from(s.p), usize::from(s.q), usize::from(s.d));
    // The structure's maxima bound every length below (p ≤ 6, q ≤ 6, d ≤ 6).
    if q == 0 || p > P_MAX || p + q + d >= POLY_LEN {
        return Err(DesignError::Spec);
    }
    let tol = T::from_f64(P_TOLERANCE);

    // A = [1, −θ] = A_slow A_fast, with at most one slow pole, real (a blower's lag): the
    // largest real root λ, if the model is not fast as a whole.
    let mut a = [T::ZERO; P_MAX + 1];
    let na = denominator(model, &mut a);
    let (mut fast, mut nf) = (a, na);
    let mut lambda = T::ZERO;
    let slow = !roots_within(&a[..na], spec.keep_radius);
    if slow {
        lambda = dominant_real_root(&a[..na]).ok_or(DesignError::SlowPoles)?;
        let remainder = deflate(&a[..na], lambda, &mut fast);
        nf = na - 1;
        if !at_most(remainder.abs(), tol) || !roots_within(&fast[..nf], spec.keep_radius) {
            return Err(DesignError::SlowPoles);
        }
    }

    // The speed knob, resolved from the slow pole when not given; then slowed down.
    let tau = match spec.tau {
        Some(tau) => tau,
        None if slow => clamp(
            -spec.ts / (lambda.ln() * T::from_f64(4.0)),
            spec.ts + spec.ts,
            T::from_f64(2.0),
        ),
        None => T::from_f64(0.1),
    } * spec.slowdown;
    // Positive and finite (NaN fails every comparison; +∞ makes Ts/τ 0 or ∞).
    let ratio_a = spec.ts / tau;
    let ratio_b = spec.ts / (spec.observer * spec.slowdown);
    let fine = |x: T| at_most(T::ZERO, x) && at_most(x, T::MAX) && x != T::ZERO;
    if !(fine(spec.ts) && fine(ratio_a) && fine(ratio_b)) {
        return Err(DesignError::Spec);
    }
    let alpha = exp_neg(ratio_a);
    let beta = exp_neg(ratio_b);
    // The reduced target P_small: (1 − α q⁻¹)(1 − β q⁻¹), or (1 − α q⁻¹) alone when the
    // reduced equation is too small for two poles (no slow pole and d + q = 1).
    let mut small = [T::ONE, -alpha, T::ZERO];
    let ns = if usize::from(slow) + d + q >= 2 {
        small = [T::ONE, -(alpha + beta), alpha * beta];
        3
    } else {
        2
    };
    let small = &small[..ns];
    // B' = q^{−d−1} B.
    let mut b1 = [T::ZERO; POLY_LEN];
    let nb = d + 1 + q;
    b1[d + 1..nb].copy_from_slice(model.phi());
    let b1 = &b1[..nb];

    // S'' = s₀ (+ s₁ q⁻¹ with the slow pole) from B'(z) S''(z) = P_small(z) at the roots
    // z = 1 (and z = 1/λ) of A_slow (1 − q⁻¹), where the R' term vanishes.
    let u = eval(small, T::ONE) / eval(b1, T::ONE);
    let mut s2 = [u, T::ZERO];
    let n_s2 = if slow {
        let z = T::ONE / lambda;
        // B' vanishing at 1/λ (to rounding) means B shares the slow pole: it cannot be moved.
        let (bz, mut size) = (eval(b1, z), T::ZERO);
        for &b in b1.iter().rev() {
            size = size * z + b.abs();
        }
        if !at_most(T::from_f64(1e-4) * size, bz.abs()) {
            return Err(DesignError::Singular);
        }
        let v = eval(small, z) / bz;
        // s₀ + s₁ = u, s₀ + s₁ z = v.
        s2[1] = (v - u) / (z - T::ONE);
        s2[0] = u - s2[1];
        2
    } else {
        1
    };
    let s2 = &s2[..n_s2];
    if !s2.iter().all(|x| x.is_finite()) {
        return Err(DesignError::Singular);
    }

    // R = (1 − q⁻¹) R' = (P_small − B' S'') / A_slow, an exact division: the numerator
    // vanishes at q⁻¹ = 1/λ by the choice of S''. Monic: B' starts with d + 1 zeros.
    let mut num = [T::ZERO; POLY_LEN];
    let nn = mul(b1, s2, &mut num).max(ns);
    for k in 0..nn {
        num[k] = -num[k];
    }
    for k in 0..ns {
        num[k] += small[k];
    }
    let mut r = [T::ZERO; R_LEN];
    let nr = if slow {
        deflate(&num[..nn], lambda, &mut r);
        nn - 1
    } else {
        r[..nn].copy_from_slice(&num[..nn]);
        nn
    };
    let mut sv = [T::ZERO; S_LEN];
    let nsv = mul(&fast[..nf], s2, &mut sv);
    let mut ao = [T::ZERO; S_LEN];
    let nao = mul(&[T::ONE, -beta], &fast[..nf], &mut ao);
    // T = t₀ A_o with T(1) = S(1): unit static gain.
    let t0 = eval(&sv[..nsv], T::ONE) / eval(&ao[..nao], T::ONE);
    let rst = Rst::new(&r[..nr], &sv[..nsv], t0, &ao[..nao]).map_err(|_| DesignError::Singular)?;

    // The checks. The closed loop as built, A R + q^{−d−1} B S, against the designed
    // P = P_small A_fast; its roots; the modulus margin.
    let mut want = [T::ZERO; POLY_LEN];
    mul(small, &fast[..nf], &mut want);
    let mut ar = [T::ZERO; POLY_LEN];
    let nar = mul(&a[..na], rst.r(), &mut ar);
    let mut closed = [T::ZERO; POLY_LEN];
    let nbs = mul(b1, rst.s(), &mut closed);
    let np = nar.max(nbs);
    let mut scale = T::ONE;
    for k in 0..np {
        closed[k] += ar[k];
        scale = max(scale, want[k].abs());
    }
    for k in 0..np {
        if !at_most((closed[k] - want[k]).abs(), tol * scale) {
            return Err(DesignError::Poles);
        }
    }
    let slowest = if nf > 1 {
        max(max(alpha, beta), spec.keep_radius)
    } else {
        max(alpha, beta)
    };
    if !roots_within(&closed[..np], min(slowest + T::from_f64(0.01), T::ONE)) {
        return Err(DesignError::Poles);
    }
    let margin = modulus_margin(&ar[..nar], &closed[..np]);
    // The sweep can miss the top of the peak (up to 5e-4 relative, on the high side): ask
    // for 0.1 % more than the minimum.
    if !at_most(spec.min_margin * T::from_f64(MARGIN_SLACK), margin) {
        return Err(DesignError::Margin { margin });
    }
    Ok(Design {
        rst,
        spec: *spec,
        tau,
        alpha,
        beta,
        gamma: alpha,
        kept: (nf - 1) as u8,
        modulus_margin: margin,
    })
}

/// Designs with `spec`, and while the margin or the pole check fails, again up to
/// `tries − 1` times, each [`Spec::slower`] by `factor`, calling `progress` after each design
/// (a watchdog). Returns the first design that passes with the number of designs made, or the
/// last refusal with that number. The refusals a slower design cannot change
/// ([`DesignError::Spec`], [`DesignError::Singular`], [`DesignError::SlowPoles`]: the settings
/// or the model's own poles) end it at once.
pub fn design_slower_on_failure<T: Real>(
    model: &ArxModel<T>,
    spec: &Spec<T>,
    tries: u8,
    factor: T,
    mut progress: impl FnMut(),
) -> (Result<Design<T>, DesignError<T>>, u8) {
    let mut spec = *spec;
    let mut last = Err(DesignError::Spec);
    for k in 1..=tries.max(1) {
        last = design(model, &spec);
        progress();
        match last {
            Ok(_)
            | Err(DesignError::Spec)
            | Err(DesignError::Singular)
            | Err(DesignError::SlowPoles) => return (last, k),
            Err(_) => spec = spec.slower(factor),
        }
    }
    (last, tries.max(1))
}

/// `e^{−x}` for `x ≥ 0`: halved `k` times to at most 1/16, a 6-term Taylor series
/// (truncation below 1e-10 relative), squared back `k` times: within 2e-8 relative in `f64` for
/// `x ≤ 5`, and within `2ᵏ` roundings in `f32` (5e-7 for the design's `x = Ts/τ ≤ 0.5`). A few
/// hundred bytes on the ATmega2560 instead of libm's 1.3 KB `expf`. NaN for `x < 0`.
#[inline(never)]
pub fn exp_neg<T: Real>(x: T) -> T {
    if !x.is_finite() || x < T::ZERO {
        // NaN: no exponential of a negative or non-finite argument here.
        return T::from_f64(f64::NAN);
    }
    let sixteenth = T::from_f64(0.0625);
    let half = T::from_f64(0.5);
    let mut y = x;
    let mut k = 0u8;
    while y > sixteenth && k < 40 {
        y *= half;
        k += 1;
    }
    // 1 − y + y²/2 − y³/6 + y⁴/24 − y⁵/120, Horner.
    let mut e = T::ONE;
    // The divisors as integers: a runtime f64 → f32 conversion would pull 0.8 KB of
    // soft-float code into the ATmega2560 image.
    for d in (1..=5u32).rev() {
        e = T::ONE - y * e / T::from_u32(d);
    }
    for _ in 0..k {
        e *= e;
    }
    e
}

/// `a ≤ b`, false when either is NaN.
fn at_most<T: Real>(a: T, b: T) -> bool {
    a <= b
}

fn max<T: Real>(a: T, b: T) -> T {
    if b > a {
        b
    } else {
        a
    }
}

fn min<T: Real>(a: T, b: T) -> T {
    if b < a {
        b
    } else {
        a
    }
}
