//! The power spectrum of a record's input against the blower's band: where a record puts its
//! excitation, for `docs/identification.md`.
//!
//! A record is taken as the flow it asks of the blower, `v_t = g(u_t)` through a static map
//! `g` (slm), so that records of different kinds and lengths compare in one unit; its
//! periodogram `P_k = |Σ_t (v_t − v̄) e^{−2πi k t / N}|² / N²` (k = 1..N/2, so that
//! `Σ_k 2 P_k` is the variance) is summed over bands relative to the blower's corner
//! frequency `f_c = 1 / (2π τ)`, `τ` its speed time constant: below `f_c/4` (mostly the static
//! gain: the flow follows), `f_c/4 .. 4 f_c` (the dynamics: lag and delay show), above `4 f_c`
//! (filtered out by the blower: spent).

use std::f64::consts::PI;

/// Power of a record in three bands around a corner frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bands {
    /// Samples.
    pub samples: usize,
    /// Variance of the input, its unit squared.
    pub variance: f64,
    /// Fractions of the variance below `f_c/4`, in `f_c/4 .. 4 f_c`, above `4 f_c`.
    pub fractions: [f64; 3],
}

impl Bands {
    /// The power in the dynamics' band (`f_c/4 .. 4 f_c`), the input's unit squared: what
    /// each second of the record gives an estimate of the dynamics (its information per
    /// second, for the same noise).
    pub fn band_power(&self) -> f64 {
        self.variance * self.fractions[1]
    }
}

/// The bands of `x` sampled at `rate_hz` around `f_c` Hz (direct DFT: records here are a few
/// thousand samples).
pub fn bands(x: &[f64], rate_hz: f64, f_c: f64) -> Bands {
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n.max(1) as f64;
    let mut power = [0.0f64; 3];
    for k in 1..=n / 2 {
        let w = 2.0 * PI * k as f64 / n as f64;
        let (mut re, mut im) = (0.0, 0.0);
        for (t, v) in x.iter().enumerate() {
            let (s, c) = (w * t as f64).sin_cos();
            re += (v - mean) * c;
            im -= (v - mean) * s;
        }
        // One-sided: both halves of the spectrum (the Nyquist bin once).
        let p = (re * re + im * im) / (n * n) as f64 * if 2 * k == n { 1.0 } else { 2.0 };
        let f = k as f64 * rate_hz / n as f64;
        let band = if f < f_c / 4.0 {
            0
        } else if f <= 4.0 * f_c {
            1
        } else {
            2
        };
        power[band] += p;
    }
    let variance: f64 = power.iter().sum();
    let fractions = power.map(|p| if variance > 0.0 { p / variance } else { 0.0 });
    Bands {
        samples: n,
        variance,
        fractions,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sine_lands_in_its_band_and_its_variance_is_kept() {
        // 100 Hz, f_c = 1 Hz: sines of 0.1, 1 and 10 Hz, amplitude 2 (variance 2).
        for (f, band) in [(0.1, 0), (1.0, 1), (10.0, 2)] {
            let x: Vec<f64> = (0..2_000)
                .map(|t| 2.0 * (2.0 * PI * f * t as f64 / 100.0).sin())
                .collect();
            let b = bands(&x, 100.0, 1.0);
            assert!((b.variance - 2.0).abs() < 1e-9, "{f}: {b:?}");
            assert!(b.fractions[band] > 1.0 - 1e-9, "{f}: {b:?}");
        }
    }
}
