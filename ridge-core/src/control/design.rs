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
//! (one `(p + q + d)`-square linear solve; no plant zero is cancelled, so zeros near or outside
//! the unit circle are harmless). The chosen `P` is
//!
//! ```text
//! P = (1 − α q⁻¹) · (1 − β q⁻¹) · A_fast(q⁻¹)        (the other p + q + d − 2 − deg A_fast poles at 0)
//! ```
//!
//! - `α = e^{−Ts/τ}`: **the speed knob** `τ`, the time constant of the setpoint response;
//! - `β = e^{−Ts/τ_o}`: an observer pole (`τ_o` ≈ 95 ms by default) that buys robustness:
//!   the slower it is, the larger the modulus margin, at the price of a slower rejection of
//!   disturbances (not of a slower setpoint response, see `T`);
//! - `A_fast`: the model's own poles except its dominant real one, kept where the plant has
//!   them when they are fast (all within [`Spec::keep_radius`]): the controller then spends no
//!   effort moving them. Only the slow dominant pole is moved, to `α`.
//!
//! `T = t₀ (1 − β q⁻¹) A_fast` with `t₀` such that `T(1) = S(1)` cancels everything but `α` from
//! the setpoint response: `y = q^{−d−1} (B / B(1)) (1 − α) / (1 − α q⁻¹) · r`, a first-order
//! response with the time constant `τ` after the loop's delay, without overshoot (for a `B`
//! with positive coefficients).
//!
//! The anti-windup observer polynomial is `A_o = (1 − β q⁻¹) A_fast` (see
//! [`Controller`](super::Controller)).
//!
//! Why this method: it needs only the model (no tuning experiment), one small linear solve
//! (milliseconds on the ATmega2560), it has integral action and anti-windup in the same
//! polynomial form, its closed-loop poles are known by construction (so the check that they
//! are where they were put is exact), and it separates the setpoint response (`τ`) from the
//! robustness (`β`). On the simulated pumps this reaches a modulus margin of 0.55–0.65 with
//! `τ` a quarter of the plant's open-loop time constant (see `docs/control.md`).

use crate::model::ArxModel;
use crate::real::Real;
use crate::{D_MAX, P_MAX, Q_MAX};

use super::margin::modulus_margin;
use super::poly::{at_one, deflate, dominant_real_root, mul, roots_within, POLY_LEN};
use super::rst::{Rst, R_LEN, S_LEN};

/// Unknowns of the Diophantine equation: `d + q − 1` of `R'` and `p + 1` of `S`.
const N_MAX: usize = P_MAX + Q_MAX + D_MAX;

/// The design's settings. Times in seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec<T> {
    /// Sample period (0.01 s at 100 Hz).
    pub ts: T,
    /// The speed knob: time constant of the setpoint response after the loop delay.
    pub tau: T,
    /// Time constant of the observer pole `β`.
    pub observer: T,
    /// Model poles within this radius (all but the dominant one) are kept in `P` (0.8).
    pub keep_radius: T,
    /// Smallest accepted modulus margin (0.5).
    pub min_margin: T,
}

impl<T: Real> Spec<T> {
    /// The default design for `model` sampled every `ts` seconds: `τ` a quarter of the
    /// model's open-loop time constant `−Ts / ln λ` (`λ` its dominant real pole), at least
    /// `2 Ts` and at most 2 s (`0.1 s` when the model has no real dominant pole); observer
    /// pole `β = 0.9` at 100 Hz (`τ_o = 95 ms`); keep radius 0.8; margin ≥ 0.5.
    pub fn for_model(model: &ArxModel<T>, ts: T) -> Self {
        let mut a = [T::ZERO; P_MAX + 1];
        let n = denominator(model, &mut a);
        let tau = match dominant_real_root(a.get(..n).unwrap_or(&[])) {
            Some(l) if l > T::ZERO => {
                let tau_ol = -ts / l.ln();
                clamp(tau_ol / T::from_f64(4.0), ts + ts, T::from_f64(2.0))
            }
            _ => T::from_f64(0.1),
        };
        Spec {
            ts,
            tau,
            observer: T::from_f64(0.095),
            keep_radius: T::from_f64(0.8),
            min_margin: T::from_f64(0.5),
        }
    }

    /// The same design `factor` times slower (`τ` and the observer time constant scaled).
    pub fn slower(&self, factor: T) -> Self {
        Spec {
            tau: self.tau * factor,
            observer: self.observer * factor,
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
    /// Closed-loop pole of the setpoint response, `e^{−Ts/τ}`.
    pub alpha: T,
    /// Observer pole, `e^{−Ts/τ_o}`.
    pub beta: T,
    /// Model poles kept in `P` (0 when none were kept).
    pub kept: u8,
    /// Coefficients of `P = A R + q^{−d−1} B S` (ascending powers of `q⁻¹`), as designed.
    p: [T; POLY_LEN],
    np: u8,
    /// `1 / max_ω |A R / P|` on the unit circle.
    pub modulus_margin: T,
}

impl<T: Real> Design<T> {
    /// The closed-loop polynomial `P` the controller was designed for.
    pub fn closed_loop(&self) -> &[T] {
        self.p.get(..usize::from(self.np)).unwrap_or(&[])
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
    /// The closed loop `A R + q^{−d−1} B S` is not the designed `P` (numerical failure), or not
    /// all its roots lie within the radius of the slowest designed pole plus 0.01.
    Poles,
    /// The modulus margin is below [`Spec::min_margin`].
    Margin {
        /// The margin reached.
        margin: T,
    },
}

/// Largest relative mismatch between the designed `P` and `A R + q^{−d−1} B S`.
const P_TOLERANCE: f64 = 1e-3;

/// `A = [1, −θ₁, …, −θ_p]` of `model` into `a`; returns its length.
fn denominator<T: Real>(model: &ArxModel<T>, a: &mut [T; P_MAX + 1]) -> usize {
    a[0] = T::ONE;
    let mut n = 1;
    for (dst, &th) in a.iter_mut().skip(1).zip(model.theta()) {
        *dst = -th;
        n += 1;
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
pub fn design<T: Real>(model: &ArxModel<T>, spec: &Spec<T>) -> Result<Design<T>, DesignError<T>> {
    let positive = |x: T| x.is_finite() && x > T::ZERO;
    if !(positive(spec.ts) && positive(spec.tau) && positive(spec.observer)) {
        return Err(DesignError::Spec);
    }
    let s = model.structure();
    let (p, q, d) = (usize::from(s.p), usize::from(s.q), usize::from(s.d));
    if q == 0 {
        return Err(DesignError::Spec);
    }
    let mut a = [T::ZERO; P_MAX + 1];
    let na = denominator(model, &mut a);
    let a = a.get(..na).unwrap_or(&[]);

    // A_fast: the model's poles but the dominant real one, if they are all fast.
    let mut fast = [T::ZERO; P_MAX + 1];
    let mut n_fast = 1;
    fast[0] = T::ONE;
    if let Some(lambda) = dominant_real_root(a) {
        let mut rest = [T::ZERO; P_MAX];
        if deflate(a, lambda, &mut rest).is_some() {
            let rest = rest.get(..na - 1).unwrap_or(&[]);
            if roots_within(rest, spec.keep_radius) {
                for (f, &x) in fast.iter_mut().zip(rest) {
                    *f = x;
                }
                n_fast = rest.len();
            }
        }
    }
    let fast = fast.get(..n_fast).unwrap_or(&[]);

    let alpha = (-spec.ts / spec.tau).exp();
    let beta = (-spec.ts / spec.observer).exp();
    // Po = (1 − β q⁻¹) A_fast;  P = (1 − α q⁻¹) Po, zero-padded to p + q + d + 1.
    let mut po = [T::ZERO; P_MAX + 1];
    let npo = mul(&[T::ONE, -beta], fast, &mut po).ok_or(DesignError::Spec)?;
    let po = po.get(..npo).unwrap_or(&[]);
    let n = p + q + d;
    let mut pp = [T::ZERO; POLY_LEN];
    mul(&[T::ONE, -alpha], po, &mut pp).ok_or(DesignError::Spec)?;

    // A' = A (1 − q⁻¹) (p + 2 coefficients), B' = q^{−d−1} B (d + 1 + q coefficients).
    let mut a1 = [T::ZERO; P_MAX + 2];
    let na1 = mul(a, &[T::ONE, -T::ONE], &mut a1).ok_or(DesignError::Spec)?;
    let mut b1 = [T::ZERO; POLY_LEN];
    for (dst, &ph) in b1.iter_mut().skip(d + 1).zip(model.phi()) {
        *dst = ph;
    }
    let nr1 = d + q - 1; // unknowns r'₁ … r'_{nr1}
    let ns = p + 1; // unknowns s₀ … s_p
    let mut m = [[T::ZERO; N_MAX]; N_MAX];
    let mut x = [T::ZERO; N_MAX];
    // Row k−1 is the coefficient of q⁻ᵏ, k = 1..=n.
    for k in 1..=n {
        let Some(row) = m.get_mut(k - 1) else {
            return Err(DesignError::Spec);
        };
        for i in 1..=nr1.min(k) {
            if let (Some(cell), Some(&ai)) = (row.get_mut(i - 1), a1.get(k - i)) {
                if k - i < na1 {
                    *cell = ai;
                }
            }
        }
        for j in 0..ns.min(k + 1) {
            if let (Some(cell), Some(&bj)) = (row.get_mut(nr1 + j), b1.get(k - j)) {
                *cell = bj;
            }
        }
        let a1k = if k < na1 {
            a1.get(k).copied().unwrap_or(T::ZERO)
        } else {
            T::ZERO
        };
        if let Some(xk) = x.get_mut(k - 1) {
            *xk = pp.get(k).copied().unwrap_or(T::ZERO) - a1k;
        }
    }
    solve(&mut m, &mut x, n)?;

    // R = (1 − q⁻¹) R', S, T = t₀ Po with T(1) = S(1).
    let mut r1 = [T::ZERO; R_LEN];
    r1[0] = T::ONE;
    for (dst, &v) in r1.iter_mut().skip(1).zip(x.iter().take(nr1)) {
        *dst = v;
    }
    let mut r = [T::ZERO; R_LEN];
    let nr = mul(r1.get(..nr1 + 1).unwrap_or(&[]), &[T::ONE, -T::ONE], &mut r)
        .ok_or(DesignError::Spec)?;
    let mut sv = [T::ZERO; S_LEN];
    for (dst, &v) in sv.iter_mut().zip(x.iter().skip(nr1).take(ns)) {
        *dst = v;
    }
    let sv = sv.get(..ns).unwrap_or(&[]);
    let t0 = at_one(sv) / at_one(po);
    let mut t = [T::ZERO; S_LEN];
    for (dst, &v) in t.iter_mut().zip(po) {
        *dst = t0 * v;
    }
    let rst = Rst::new(
        r.get(..nr).unwrap_or(&[]),
        sv,
        t.get(..npo).unwrap_or(&[]),
        po,
    )
    .map_err(|_| DesignError::Singular)?;

    // The closed loop as built: A R + q^{−d−1} B S, against the designed P.
    let mut ar = [T::ZERO; POLY_LEN];
    let nar = mul(a, rst.r(), &mut ar).ok_or(DesignError::Spec)?;
    let mut bs = [T::ZERO; POLY_LEN];
    let nbs = mul(b1.get(..d + 1 + q).unwrap_or(&[]), rst.s(), &mut bs).ok_or(DesignError::Spec)?;
    let np = nar.max(nbs).max(n + 1);
    let mut scale = T::ONE;
    for &v in pp.iter().take(np) {
        scale = max(scale, v.abs());
    }
    let mut closed = [T::ZERO; POLY_LEN];
    for k in 0..np {
        let v = ar.get(k).copied().unwrap_or(T::ZERO) + bs.get(k).copied().unwrap_or(T::ZERO);
        let want = pp.get(k).copied().unwrap_or(T::ZERO);
        let err = (v - want).abs();
        if !err.is_finite() || err > T::from_f64(P_TOLERANCE) * scale {
            return Err(DesignError::Poles);
        }
        if let Some(c) = closed.get_mut(k) {
            *c = v;
        }
    }
    let slowest = max(
        max(alpha, beta),
        spec.keep_radius * T::from_u32(u32::from(n_fast > 1)),
    );
    let radius = min(slowest + T::from_f64(0.01), T::ONE);
    let closed_loop = closed.get(..np).unwrap_or(&[]);
    if !roots_within(closed_loop, radius) {
        return Err(DesignError::Poles);
    }
    let margin = modulus_margin(ar.get(..nar).unwrap_or(&[]), closed_loop);
    if !margin.is_finite() || margin < spec.min_margin {
        return Err(DesignError::Margin { margin });
    }
    Ok(Design {
        rst,
        spec: *spec,
        alpha,
        beta,
        kept: (n_fast - 1) as u8,
        p: closed,
        np: np as u8,
        modulus_margin: margin,
    })
}

/// Designs with `spec`, and while the margin or the pole check fails, again up to
/// `tries − 1` times, each [`Spec::slower`] by `factor`. Returns the first design that passes
/// with the number of designs made, or the last refusal with that number.
pub fn design_slower_on_failure<T: Real>(
    model: &ArxModel<T>,
    spec: &Spec<T>,
    tries: u8,
    factor: T,
) -> (Result<Design<T>, DesignError<T>>, u8) {
    let mut spec = *spec;
    let mut last = Err(DesignError::Spec);
    for k in 1..=tries.max(1) {
        last = design(model, &spec);
        match last {
            Ok(_) | Err(DesignError::Spec) | Err(DesignError::Singular) => return (last, k),
            Err(_) => spec = spec.slower(factor),
        }
    }
    (last, tries.max(1))
}

/// Gaussian elimination with partial pivoting on the leading `n × n` block; the solution
/// replaces `x`. [`DesignError::Singular`] when a pivot vanishes or the result is not finite.
fn solve<T: Real>(
    m: &mut [[T; N_MAX]; N_MAX],
    x: &mut [T; N_MAX],
    n: usize,
) -> Result<(), DesignError<T>> {
    let n = n.min(N_MAX);
    let mut norm = T::ZERO;
    for row in m.iter().take(n) {
        for &v in row.iter().take(n) {
            norm = max(norm, v.abs());
        }
    }
    let tiny = norm * T::EPSILON * T::from_u32(n as u32 * 4);
    for col in 0..n {
        // Pivot: the largest magnitude in this column at or below the diagonal.
        let mut piv = col;
        let mut best = T::ZERO;
        for (i, row) in m.iter().enumerate().take(n).skip(col) {
            let v = row.get(col).copied().unwrap_or(T::ZERO).abs();
            if v > best {
                best = v;
                piv = i;
            }
        }
        if !best.is_finite() || best <= tiny {
            return Err(DesignError::Singular);
        }
        m.swap(col, piv);
        x.swap(col, piv);
        let (top, bottom) = m.split_at_mut(col + 1);
        let Some(prow) = top.last() else {
            return Err(DesignError::Singular);
        };
        let pv = prow.get(col).copied().unwrap_or(T::ONE);
        let xc = x.get(col).copied().unwrap_or(T::ZERO);
        for (off, row) in bottom.iter_mut().take(n - col - 1).enumerate() {
            let f = row.get(col).copied().unwrap_or(T::ZERO) / pv;
            if f == T::ZERO {
                continue;
            }
            for (c, &pc) in row.iter_mut().zip(prow.iter()).take(n).skip(col) {
                *c -= f * pc;
            }
            if let Some(xi) = x.get_mut(col + 1 + off) {
                *xi -= f * xc;
            }
        }
    }
    for col in (0..n).rev() {
        let row = m.get(col).ok_or(DesignError::Singular)?;
        let mut v = x.get(col).copied().unwrap_or(T::ZERO);
        for (c, &xc) in row.iter().zip(x.iter()).take(n).skip(col + 1) {
            v -= *c * xc;
        }
        let v = v / row.get(col).copied().unwrap_or(T::ONE);
        if !v.is_finite() {
            return Err(DesignError::Singular);
        }
        if let Some(xc) = x.get_mut(col) {
            *xc = v;
        }
    }
    Ok(())
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
