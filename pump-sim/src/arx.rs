//! Linear ARX "known plant" simulator for the core's tests (the paper's eq. (1)):
//!
//! `y_t = Σ_{i=1..p} θ_i y_{t−i} + Σ_{j=0..q−1} φ_j u_{t−j−d} + e_t`,
//!
//! with `p = theta.len()`, `q = phi.len()`, zero history (`y_t = u_t = 0` for `t < 0`) and
//! `e_t ~ N(0, noise_std²)` i.i.d. from a seeded xoshiro256++ stream.

use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

/// Simulates the ARX model above over the input `u` and returns `y` (same length).
///
/// - `theta = [θ_1 … θ_p]` (AR coefficients, `theta[0]` multiplies `y_{t−1}`),
/// - `phi = [φ_0 … φ_{q−1}]` (input coefficients, `phi[0]` multiplies `u_{t−d}`),
/// - `d`: input delay in samples,
/// - `noise_std`: standard deviation of the white equation error `e_t` (0 → noise-free),
/// - `seed`: noise stream; the same arguments give the same output.
///
/// One normal draw is made per sample even when `noise_std == 0`, so changing only
/// `noise_std` scales the same noise realisation.
pub fn simulate_arx(
    theta: &[f64],
    phi: &[f64],
    d: usize,
    u: &[f64],
    noise_std: f64,
    seed: u64,
) -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut y: Vec<f64> = Vec::with_capacity(u.len());
    for t in 0..u.len() {
        // y_{t-1}, y_{t-2}, … : the already computed outputs, newest first.
        let ar: f64 = theta
            .iter()
            .zip(y.iter().rev())
            .map(|(th, yl)| th * yl)
            .sum();
        // u_{t-d}, u_{t-d-1}, … : inputs up to index t-d, newest first (none if t < d).
        let x: f64 = match t.checked_sub(d) {
            Some(last) => phi
                .iter()
                .zip(u.iter().take(last + 1).rev())
                .map(|(ph, ul)| ph * ul)
                .sum(),
            None => 0.0,
        };
        let z: f64 = rng.sample(StandardNormal);
        y.push(ar + x + noise_std * z);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_sequence() {
        // y_t = 0.5 y_{t-1} - 0.25 y_{t-2} + 2 u_{t-1} + 1 u_{t-2}   (p = 2, q = 2, d = 1)
        let theta = [0.5, -0.25];
        let phi = [2.0, 1.0];
        let u = [1.0, 0.0, 0.0, 3.0, 0.0, 0.0];
        // t=0: 0
        // t=1: 0.5*0 - 0 + 2*u0 + 1*0            = 2
        // t=2: 0.5*2 - 0.25*0 + 2*u1 + 1*u0      = 1 + 0 + 1 = 2
        // t=3: 0.5*2 - 0.25*2 + 2*u2 + u1        = 1 - 0.5 = 0.5
        // t=4: 0.5*0.5 - 0.25*2 + 2*u3 + u2      = 0.25 - 0.5 + 6 = 5.75
        // t=5: 0.5*5.75 - 0.25*0.5 + 2*u4 + u3   = 2.875 - 0.125 + 3 = 5.75
        let y = simulate_arx(&theta, &phi, 1, &u, 0.0, 0);
        assert_eq!(y, vec![0.0, 2.0, 2.0, 0.5, 5.75, 5.75]);
    }

    #[test]
    fn delay_zero_uses_current_input_and_large_delay_gives_zero() {
        let u = [1.0, 2.0, 3.0];
        assert_eq!(
            simulate_arx(&[], &[1.0], 0, &u, 0.0, 0),
            vec![1.0, 2.0, 3.0]
        );
        assert_eq!(simulate_arx(&[], &[1.0], 5, &u, 0.0, 0), vec![0.0; 3]);
        assert_eq!(
            simulate_arx(&[0.9], &[1.0], 0, &[], 0.0, 0),
            Vec::<f64>::new()
        );
    }

    #[test]
    fn noise_is_seeded_and_has_the_requested_std() {
        let u = vec![0.0; 20_000];
        let a = simulate_arx(&[], &[], 0, &u, 0.5, 42);
        let b = simulate_arx(&[], &[], 0, &u, 0.5, 42);
        let c = simulate_arx(&[], &[], 0, &u, 0.5, 43);
        assert_eq!(a, b);
        assert_ne!(a, c);
        let n = a.len() as f64;
        let mean = a.iter().sum::<f64>() / n;
        let std = (a.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!(mean.abs() < 0.02, "mean {mean}");
        assert!((std - 0.5).abs() < 0.02, "std {std}");
    }
}
