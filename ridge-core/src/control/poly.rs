//! Small polynomial tools in the backward shift `q⁻¹`: coefficient slices in ascending powers
//! (`a[k]` multiplies `q⁻ᵏ`), fixed capacity, no allocation.
//!
//! A polynomial `A(q⁻¹) = a₀ + a₁q⁻¹ + … + aₙq⁻ⁿ` has the roots of `a₀zⁿ + a₁zⁿ⁻¹ + … + aₙ`:
//! those are the poles it stands for (`A y = …` is stable when they lie inside the unit circle).
//!
//! Written with index loops rather than iterator adapters: on the ATmega2560 each adapter
//! chain costs tens of instructions per loop, and this code runs there (the indices are bounded
//! by the slices' lengths, checked once).

use crate::real::Real;

/// Largest number of coefficients of any polynomial built here: the closed-loop polynomial
/// `P = A R + q^{−d−1} B S` has degree at most `p + q + d ≤ 18`.
pub const POLY_LEN: usize = crate::P_MAX + crate::Q_MAX + crate::D_MAX + 1;

/// `out[..n] = a · b` with `n = a.len() + b.len() − 1` (0 when both factors are empty; an
/// empty factor, the zero polynomial, gives `n` zeros), the product's coefficients beyond
/// `out.len()` dropped; the rest of `out` is left alone.
/// Returns `n` capped at `out.len()`.
pub fn mul<T: Real>(a: &[T], b: &[T], out: &mut [T]) -> usize {
    let n = (a.len() + b.len()).saturating_sub(1).min(out.len());
    let out = &mut out[..n];
    out.fill(T::ZERO);
    for (i, &ai) in a.iter().enumerate() {
        for (j, &bj) in b.iter().enumerate() {
            if let Some(o) = out.get_mut(i + j) {
                *o += ai * bj;
            }
        }
    }
    n
}

/// `A(z) = Σ aₖ zᵏ`: the polynomial at `q⁻¹ = z` (Horner from the highest power). `A(1)` is
/// the static gain of `1 / A`'s inverse, the sum of the coefficients.
pub fn eval<T: Real>(a: &[T], z: T) -> T {
    let mut v = T::ZERO;
    for &c in a.iter().rev() {
        v = v * z + c;
    }
    v
}

/// Whether every root of `a` lies strictly inside the circle `|z| < radius` (`a[0] ≠ 0`,
/// `radius > 0`), by the Schur–Cohn–Jury recursion on the scaled polynomial `aₖ / radiusᵏ`:
/// each step takes the reflection coefficient `k = cₙ / c₀` (stable needs `|k| < 1`) and
/// reduces the degree by one with `cᵢ ← cᵢ − k cₙ₋ᵢ`. `false` for NaNs, `a[0] = 0`, or more
/// than [`POLY_LEN`] coefficients.
pub fn roots_within<T: Real>(a: &[T], radius: T) -> bool {
    let mut c = [T::ZERO; POLY_LEN];
    let mut prev = [T::ZERO; POLY_LEN];
    let mut n = a.len();
    if n > POLY_LEN || !radius.is_finite() || radius <= T::ZERO {
        return false;
    }
    let mut scale = T::ONE;
    for i in 0..n {
        c[i] = a[i] * scale;
        scale = scale / radius;
    }
    while n > 1 {
        let k = c[n - 1] / c[0];
        if !k.is_finite() || k.abs() >= T::ONE {
            return false;
        }
        // cᵢ ← cᵢ − k cₙ₋₁₋ᵢ for i < n − 1, from a snapshot (the new cₙ₋₁ is 0).
        prev[..n].copy_from_slice(&c[..n]);
        for i in 0..n - 1 {
            c[i] -= k * prev[n - 1 - i];
        }
        n -= 1;
    }
    true
}

/// The largest real root in `(0, 1)` of `a` (`a[0] = 1`), by Newton's method on
/// `zⁿ + a₁zⁿ⁻¹ + … + aₙ` started at `z = 1`: for a stable plant with `A(1) > 0` it descends
/// monotonically onto the largest real root. `None` when `A(1) ≤ 0`, the iteration leaves
/// `(0, 1)`, or it does not settle in 60 steps.
pub fn dominant_real_root<T: Real>(a: &[T]) -> Option<T> {
    let a1 = eval(a, T::ONE);
    if !a1.is_finite() || a1 <= T::ZERO {
        return None;
    }
    let mut z = T::ONE;
    for _ in 0..60 {
        // Horner for f and f'.
        let (mut f, mut df) = (T::ZERO, T::ZERO);
        for &ak in a {
            df = df * z + f;
            f = f * z + ak;
        }
        let step = f / df;
        let next = z - step;
        if !next.is_finite() || next <= T::ZERO || next >= T::ONE {
            return None;
        }
        z = next;
        if step.abs() <= T::from_f64(4.0) * T::EPSILON * z {
            return Some(z);
        }
    }
    None
}

/// `out[..a.len() − 1] = a / (1 − λq⁻¹)` by synthetic division, exact when `λ` is a root
/// (quotient coefficients beyond `out.len()` dropped). Returns the remainder
/// `a₀λⁿ + a₁λⁿ⁻¹ + … + aₙ`: 0 for a root (and for an empty `a`).
pub fn deflate<T: Real>(a: &[T], lambda: T, out: &mut [T]) -> T {
    let mut carry = T::ZERO;
    for (k, &ak) in a.iter().enumerate() {
        if k + 1 == a.len() {
            return ak + lambda * carry;
        }
        carry = ak + lambda * carry;
        if let Some(o) = out.get_mut(k) {
            *o = carry;
        }
    }
    T::ZERO
}

/// `r[k] = Σᵢ aᵢ aᵢ₊ₖ` for `k = 0..r.len()`, so that `|A(e^{−jω})|² = r₀ + 2 Σₖ rₖ cos kω`.
pub fn autocorrelation<T: Real>(a: &[T], r: &mut [T]) {
    for k in 0..r.len() {
        let mut s = T::ZERO;
        for i in k..a.len() {
            s += a[i] * a[i - k];
        }
        r[k] = s;
    }
}

/// `r₀ + 2 Σ_{k≥1} rₖ Tₖ(x)` (Chebyshev polynomials, `x = cos ω`: the squared magnitude whose
/// [`autocorrelation`] `r` is), by Clenshaw's recurrence.
pub fn magnitude_sq<T: Real>(r: &[T], x: T) -> T {
    let two = T::ONE + T::ONE;
    let (mut b1, mut b2) = (T::ZERO, T::ZERO);
    for k in (1..r.len()).rev() {
        let b0 = two * (r[k] + x * b1) - b2;
        b2 = b1;
        b1 = b0;
    }
    match r.first() {
        Some(&r0) => r0 + x * b1 - b2,
        None => T::ZERO,
    }
}
