//! Polynomials in `q⁻¹` for the controller's checks: products, the model's denominator, the
//! roots of a polynomial ([`roots`], the poles) and how poles are written in a message.

use nalgebra::{DMatrix, Schur};

/// A pole (or any complex number) `re + j im`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pole {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl Pole {
    /// `|z|`.
    pub fn norm(self) -> f64 {
        self.re.hypot(self.im)
    }
}

/// The roots `z` of the polynomial `a` in `q⁻¹` (ascending powers, `a[0] ≠ 0`): the
/// eigenvalues of the companion matrix of `zⁿ + (a₁/a₀) zⁿ⁻¹ + … + aₙ/a₀` (nalgebra's real
/// Schur decomposition). Trailing coefficients of magnitude at most `zero_below` count as 0
/// (roots at exactly 0). Sorted by decreasing `|z|`, then decreasing imaginary part. `None`
/// for non-finite coefficients, `a[0] = 0`, or no convergence.
pub fn roots(a: &[f64], zero_below: f64) -> Option<Vec<Pole>> {
    let lead = *a.first()?;
    if lead == 0.0 || !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut n = a.len();
    while n > 1 && a[n - 1].abs() <= zero_below {
        n -= 1;
    }
    let zeros = a.len() - n;
    let deg = n - 1;
    let mut out = Vec::with_capacity(a.len() - 1);
    if deg > 0 {
        // Companion matrix: first row −a₁/a₀ … −aₙ/a₀, ones below the diagonal.
        let m = DMatrix::from_fn(deg, deg, |i, j| {
            if i == 0 {
                -a[j + 1] / lead
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let schur = Schur::try_new(m, f64::EPSILON, 10_000)?;
        for z in schur.complex_eigenvalues().iter() {
            if !(z.re.is_finite() && z.im.is_finite()) {
                return None;
            }
            out.push(Pole { re: z.re, im: z.im });
        }
    }
    out.extend(std::iter::repeat_n(Pole { re: 0.0, im: 0.0 }, zeros));
    out.sort_by(|x, y| {
        y.norm()
            .total_cmp(&x.norm())
            .then(y.im.total_cmp(&x.im))
            .then(y.re.total_cmp(&x.re))
    });
    Some(out)
}

/// `A = [1, −θ₁, …, −θ_p]` of a model with autoregressive coefficients `theta`.
pub fn denominator(theta: &[f64]) -> Vec<f64> {
    std::iter::once(1.0)
        .chain(theta.iter().map(|t| -t))
        .collect()
}

/// `a · b` (polynomial product, ascending powers), every coefficient kept: ridge-core's
/// [`poly::mul`](ridge_core::control::poly::mul) into a vector of the product's length.
pub fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; (a.len() + b.len()).saturating_sub(1)];
    ridge_core::control::poly::mul(a, b, &mut out);
    out
}

/// `0.950000, 0.4 ± 0.3i`: poles for a message.
pub fn pole_list(poles: &[Pole]) -> String {
    poles
        .iter()
        .map(|p| format_pole(*p))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `0.400000+0.300000i (|z| 0.500000)` or `0.950000` for a real pole.
pub fn format_pole(p: Pole) -> String {
    if p.im == 0.0 {
        format!("{:.6}", p.re)
    } else {
        format!(
            "{:.6}{}{:.6}i (|z| {:.6})",
            p.re,
            if p.im < 0.0 { "-" } else { "+" },
            p.im.abs(),
            p.norm()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_known_polynomials() {
        // (1 − 0.5 q⁻¹)(1 − 0.25 q⁻¹) q⁻⁰ with a trailing exact zero: roots 0.5, 0.25, 0.
        let r = roots(&[1.0, -0.75, 0.125, 0.0], 1e-12).unwrap();
        let want = [0.5, 0.25, 0.0];
        assert_eq!(r.len(), 3);
        for (p, w) in r.iter().zip(want) {
            assert!((p.re - w).abs() < 1e-12 && p.im == 0.0, "{r:?}");
        }
        // 1 − q⁻¹ + 0.5 q⁻²: 0.5 ± 0.5i, the positive imaginary part first.
        let r = roots(&[1.0, -1.0, 0.5], 0.0).unwrap();
        assert!((r[0].re - 0.5).abs() < 1e-12 && (r[0].im - 0.5).abs() < 1e-12);
        assert!((r[1].im + 0.5).abs() < 1e-12);
        assert!(roots(&[0.0, 1.0], 0.0).is_none());
        assert!(roots(&[1.0, f64::NAN], 0.0).is_none());
        assert_eq!(roots(&[2.0], 0.0), Some(vec![]));
    }

    #[test]
    fn products_of_known_factors() {
        // (1 − 0.5 q⁻¹)(1 − 0.25 q⁻¹) = 1 − 0.75 q⁻¹ + 0.125 q⁻².
        assert_eq!(mul(&[1.0, -0.5], &[1.0, -0.25]), vec![1.0, -0.75, 0.125]);
        // (1 + q⁻¹)³ = 1 + 3 q⁻¹ + 3 q⁻² + q⁻³, every coefficient kept.
        assert_eq!(
            mul(&mul(&[1.0, 1.0], &[1.0, 1.0]), &[1.0, 1.0]),
            vec![1.0, 3.0, 3.0, 1.0]
        );
        assert_eq!(mul(&[2.0], &[0.0, 0.0, 3.0]), vec![0.0, 0.0, 6.0]);
        assert!(mul(&[], &[]).is_empty());
        assert_eq!(mul(&[], &[1.0, 2.0]), vec![0.0]);
    }
}
