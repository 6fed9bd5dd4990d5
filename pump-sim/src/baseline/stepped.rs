//! [`Plant`]: what the tuning experiments step — the simulated rig (true flow, no sensor) or a
//! linear ARX plant with known dynamics ([`ArxPlant`], for tests with an analytic truth).

use std::collections::VecDeque;

use ridge_pump_firmware::units::DUTY_FULL_SCALE;

use crate::Rig;

/// A single-input single-output plant stepped once per sample period.
///
/// Timing is the rig's (see the crate docs): [`apply`](Plant::apply) takes the input for the
/// coming interval and returns the output at the end of that interval.
pub trait Plant {
    /// Applies the input `u` (duty fraction 0..1 for the rig) for one sample period and
    /// returns the true output at the end of it (slm for the rig; no sensor noise).
    fn apply(&mut self, u: f64) -> f64;
}

/// Duty fraction (0..1) → duty (1/10 000 of full scale, the firmware's `u16` duty), rounded as
/// the firmware rounds its controller's output (`u · 10 000 + 0.5`, truncated), clamped to
/// `0..=10 000` (NaN → 0).
pub fn fraction_to_duty(u: f64) -> u16 {
    if u.is_nan() {
        return 0;
    }
    let full = f64::from(DUTY_FULL_SCALE);
    (u * full + 0.5).clamp(0.0, full) as u16
}

impl Plant for Rig {
    /// The duty rounded to 1/10 000 ([`fraction_to_duty`]) drives the rig; returns its true
    /// flow, slm (the sensor is not read, so its noise stream does not advance).
    fn apply(&mut self, u: f64) -> f64 {
        self.true_flow(fraction_to_duty(u))
    }
}

/// The rig driven by the unrounded duty ([`Rig::flow_at`]): the plant as a smooth function of
/// its input, for the optimisation of [`super::optimal`], which differentiates it numerically
/// (the counts' 1/10 000 steps would make the differences 0 or 10 000 times too large).
#[derive(Clone, Debug)]
pub struct UnroundedRig(pub Rig);

impl Plant for UnroundedRig {
    /// The duty fraction drives the rig as it is; returns its true flow, slm.
    fn apply(&mut self, u: f64) -> f64 {
        self.0.flow_at(u)
    }
}

/// A linear ARX plant `y_t = Σ θ_i y_{t−i} + Σ φ_j u_{t−j−d}` (the crate's sample
/// convention: `φ_0` multiplies the input applied during the interval that ends `d` samples
/// before `y_t`), zero history, no noise.
#[derive(Clone, Debug)]
pub struct ArxPlant {
    theta: Vec<f64>,
    phi: Vec<f64>,
    /// Past outputs, newest first.
    y: VecDeque<f64>,
    /// Past inputs, newest first (`d + q` of them).
    u: VecDeque<f64>,
    d: usize,
}

impl ArxPlant {
    /// The plant with AR coefficients `theta = [θ_1 … θ_p]`, input coefficients
    /// `phi = [φ_0 … φ_{q−1}]` and input delay `d` samples, at rest.
    pub fn new(theta: &[f64], phi: &[f64], d: usize) -> Self {
        ArxPlant {
            theta: theta.to_vec(),
            phi: phi.to_vec(),
            y: std::iter::repeat_n(0.0, theta.len()).collect(),
            u: std::iter::repeat_n(0.0, d + phi.len()).collect(),
            d,
        }
    }

    /// A first-order plant with dead time, discretised exactly with a zero-order hold:
    /// static gain `k` (output units per input unit), time constant `tau_s` and a delay of
    /// `delay` whole samples of `ts_s` seconds. Its continuous-time equivalent is
    /// `k e^{−θ s} / (τ s + 1)` with `θ = delay · ts_s`.
    pub fn fopdt(k: f64, tau_s: f64, delay: usize, ts_s: f64) -> Self {
        let a = (-ts_s / tau_s).exp();
        Self::new(&[a], &[k * (1.0 - a)], delay)
    }

    /// Static gain `Σφ / (1 − Σθ)`.
    pub fn static_gain(&self) -> f64 {
        self.phi.iter().sum::<f64>() / (1.0 - self.theta.iter().sum::<f64>())
    }
}

impl Plant for ArxPlant {
    fn apply(&mut self, u: f64) -> f64 {
        self.u.push_front(u);
        self.u.truncate(self.d + self.phi.len());
        let ar: f64 = self.theta.iter().zip(&self.y).map(|(t, y)| t * y).sum();
        let x: f64 = self
            .phi
            .iter()
            .zip(self.u.iter().skip(self.d))
            .map(|(p, u)| p * u)
            .sum();
        let y = ar + x;
        if !self.theta.is_empty() {
            self.y.push_front(y);
            self.y.truncate(self.theta.len());
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arx_plant_matches_the_crate_simulator() {
        let (theta, phi, d) = ([0.5, -0.25], [2.0, 1.0], 1);
        let u: Vec<f64> = (0..20)
            .map(|t| f64::from((t * 7 % 5) as u8) - 2.0)
            .collect();
        let expect = crate::simulate_arx(&theta, &phi, d, &u, 0.0, 0);
        let mut p = ArxPlant::new(&theta, &phi, d);
        for (ut, yt) in u.iter().zip(expect) {
            assert!((p.apply(*ut) - yt).abs() < 1e-12);
        }
    }

    #[test]
    fn fopdt_plant_delays_and_settles_to_its_gain() {
        let mut p = ArxPlant::fopdt(3.0, 0.05, 2, 0.01);
        assert_eq!(p.apply(1.0), 0.0);
        assert_eq!(p.apply(1.0), 0.0);
        let a = (-0.2f64).exp();
        assert!((p.apply(1.0) - 3.0 * (1.0 - a)).abs() < 1e-12);
        let mut y = 0.0;
        for _ in 0..500 {
            y = p.apply(1.0);
        }
        assert!((y - 3.0).abs() < 1e-9 && (p.static_gain() - 3.0).abs() < 1e-12);
    }

    #[test]
    fn duty_rounds_like_the_firmware() {
        assert_eq!(fraction_to_duty(0.30004), 3000);
        assert_eq!(fraction_to_duty(0.30006), 3001);
        assert_eq!(fraction_to_duty(-1.0), 0);
        assert_eq!(fraction_to_duty(2.0), 10_000);
        assert_eq!(fraction_to_duty(f64::NAN), 0);
    }
}
