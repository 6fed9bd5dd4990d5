//! The modulus margin of a closed loop, `1 / max_ω |A R / P|` on the unit circle: the smallest
//! distance of the loop transfer to −1 (the inverse peak of the output sensitivity).

use crate::real::Real;

use super::poly::{autocorrelation, magnitude_sq, POLY_LEN};

/// Frequencies of the coarse sweep over `0..=π` (the peak is then refined between the
/// neighbours of the largest point).
pub const SWEEP_POINTS: usize = 64;

/// `cos(π / (SWEEP_POINTS − 1))`, the sweep's step (a literal: no trigonometry on the device;
/// a unit test checks it).
const COS_STEP: f64 = 0.9987569212189223;

/// Golden-section steps of the refinement (the bracket shrinks to 0.618²⁴ ≈ 1e-5 of two grid
/// steps).
const REFINE_STEPS: usize = 24;

/// `1 / max_ω |AR(e^{−jω}) / P(e^{−jω})|` for `AR = A·R` and the closed loop `P`: a coarse
/// sweep of [`SWEEP_POINTS`] frequencies over `0..=π` on the squared magnitudes (each a cosine
/// series from the coefficients' autocorrelation, summed by Clenshaw's recurrence), then a
/// golden-section refinement of the peak in `cos ω` between the largest point's neighbours.
/// 0 when `P` vanishes on the unit circle (or for NaNs).
#[inline(never)]
pub fn modulus_margin<T: Real>(ar: &[T], p: &[T]) -> T {
    let mut rar = [T::ZERO; POLY_LEN];
    let mut rp = [T::ZERO; POLY_LEN];
    let (Some(rar), Some(rp)) = (rar.get_mut(..ar.len()), rp.get_mut(..p.len())) else {
        return T::ZERO;
    };
    autocorrelation(ar, rar);
    autocorrelation(p, rp);
    let ratio = |x: T| -> T {
        let num = magnitude_sq(rar, x);
        let den = magnitude_sq(rp, x);
        if den > T::ZERO {
            num / den
        } else {
            T::MAX
        }
    };
    // cos(kh) by the recurrence cos((k+1)h) = 2 cos h cos kh − cos((k−1)h), h = π/(N−1).
    let cos_h = T::from_f64(COS_STEP);
    let two = T::ONE + T::ONE;
    let (mut prev, mut x) = (cos_h, T::ONE);
    let (mut best, mut best_k) = (T::ZERO, 0usize);
    let mut xs = [T::ZERO; SWEEP_POINTS];
    for (k, slot) in xs.iter_mut().enumerate() {
        *slot = x;
        let v = ratio(x);
        if v > best || !v.is_finite() {
            best = v;
            best_k = k;
        }
        let next = two * cos_h * x - prev;
        prev = x;
        x = next;
    }
    if !best.is_finite() {
        return T::ZERO;
    }
    // Refine in x = cos ω between the neighbours (x decreases with ω).
    let hi = xs.get(best_k.saturating_sub(1)).copied().unwrap_or(T::ONE);
    let lo = xs.get(best_k + 1).copied().unwrap_or(-T::ONE);
    let g = T::from_f64(0.618_033_988_749_894_8);
    let (mut a, mut b) = (lo, hi);
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (ratio(c), ratio(d));
    for _ in 0..REFINE_STEPS {
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = ratio(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = ratio(d);
        }
    }
    for v in [fc, fd] {
        if v > best {
            best = v;
        }
    }
    if best > T::ZERO && best.is_finite() {
        T::ONE / best.sqrt()
    } else {
        T::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cos_step_is_the_sweep_step() {
        let step = core::f64::consts::PI / (SWEEP_POINTS - 1) as f64;
        assert_eq!(COS_STEP, libm::cos(step));
    }
}
