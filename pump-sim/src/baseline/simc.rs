//! SIMC PI tuning (Skogestad 2003) from a first-order-plus-dead-time fit of an ARX model.
//!
//! # The fit ([`fit_fopdt`])
//! The model's unit step response is simulated (input 1 from time 0 on, so sample `t` of the
//! response is the flow at `(t + 1)·Ts`, the rig's timing) until it has stayed within 2 % of
//! the static gain for as long again as it took to get there. Then:
//! - `K` is the model's static gain `Σφ / (1 − Σθ)` (exact, not fitted);
//! - `θ` and `τ` minimise the sum of squared differences between that response and the
//!   continuous-time FOPDT step response `K (1 − e^{−(t − θ)/τ})` (0 before `θ`) at the same
//!   instants: `θ` on a grid (`Ts/4` steps from 0 to the 63 % time, then `Ts/100` steps around
//!   the best), `τ` by golden-section search on `ln τ` for each `θ`.
//!
//! A discretised FOPDT (`y_t = a y_{t−1} + K (1 − a) u_{t−d}`) is fitted exactly:
//! `τ = −Ts / ln a`, `θ = d·Ts`.
//!
//! # The rule ([`simc_pi`])
//! With the effective delay `θ_e = θ + Ts/2` (the zero-order hold of a sampled controller adds
//! half a sample of delay) and SIMC's "tight" closed-loop time constant `τ_c = θ_e`:
//! `K_c = τ / (K (τ_c + θ_e))`, `T_i = min(τ, 4 (τ_c + θ_e))`.

use ridge_core::ArxModel;

use super::pid::PidGains;
use super::stepped::{ArxPlant, Plant};

/// A first-order-plus-dead-time model `K e^{−θ s} / (τ s + 1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fopdt {
    /// Static gain `K`, output units per input unit (slm per duty fraction).
    pub k: f64,
    /// Time constant `τ`, s.
    pub tau_s: f64,
    /// Dead time `θ`, s.
    pub theta_s: f64,
    /// RMS difference between the fitted and the model's step response, relative to `K`
    /// (dimensionless; 0 for an exact FOPDT).
    pub rms_rel: f64,
}

impl Fopdt {
    /// Step response of the FOPDT to a unit step at time 0, at time `t_s` (s).
    pub fn step_at(&self, t_s: f64) -> f64 {
        if t_s <= self.theta_s {
            0.0
        } else {
            self.k * (1.0 - (-(t_s - self.theta_s) / self.tau_s).exp())
        }
    }
}

/// Largest step-response length simulated for a fit, samples.
const MAX_SAMPLES: usize = 5000;

/// Unit step response of the ARX model `theta`, `phi`, `d` (crate convention), `n` samples:
/// element `t` is the output at the end of interval `t`, the input being 1 from interval 0 on.
pub fn step_response(theta: &[f64], phi: &[f64], d: usize, n: usize) -> Vec<f64> {
    let mut p = ArxPlant::new(theta, phi, d);
    (0..n).map(|_| p.apply(1.0)).collect()
}

/// Sum of squared differences between `s` (sampled at `(t + 1)·ts`) and the FOPDT.
fn cost(s: &[f64], f: &Fopdt, ts_s: f64) -> f64 {
    s.iter()
        .enumerate()
        .map(|(t, &v)| (v - f.step_at((t + 1) as f64 * ts_s)).powi(2))
        .sum()
}

/// The best `τ` for dead time `theta_s` (golden section on `ln τ` in `[ln lo, ln hi]`) and its
/// cost.
fn best_tau(s: &[f64], k: f64, theta_s: f64, lo: f64, hi: f64, ts_s: f64) -> (f64, f64) {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo.ln(), hi.ln());
    let eval = |ln_tau: f64| {
        let f = Fopdt {
            k,
            tau_s: ln_tau.exp(),
            theta_s,
            rms_rel: 0.0,
        };
        cost(s, &f, ts_s)
    };
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (eval(c), eval(d));
    for _ in 0..80 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = eval(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = eval(d);
        }
    }
    let ln_tau = 0.5 * (a + b);
    (ln_tau.exp(), eval(ln_tau))
}

/// FOPDT fit of the ARX model `theta`, `phi`, `d` at sample period `ts_s` (see the module
/// docs). `None` when the static gain is not positive and finite or the step response does
/// not settle within 5000 samples.
pub fn fit_fopdt(theta: &[f64], phi: &[f64], d: usize, ts_s: f64) -> Option<Fopdt> {
    let k = phi.iter().sum::<f64>() / (1.0 - theta.iter().sum::<f64>());
    if !(k.is_finite() && k > 0.0 && ts_s > 0.0) {
        return None;
    }
    let long = step_response(theta, phi, d, MAX_SAMPLES);
    // Settled: within 2 % of K from `settle` on; keep as long again after it.
    let settle = long.iter().rposition(|v| (v - k).abs() > 0.02 * k)? + 1;
    if settle >= MAX_SAMPLES / 2 {
        return None;
    }
    let s = &long[..(2 * settle + 20).min(MAX_SAMPLES)];
    let t63 = s.iter().position(|&v| v >= (1.0 - (-1f64).exp()) * k)?;
    let t63_s = (t63 + 1) as f64 * ts_s;
    let (tau_lo, tau_hi) = (ts_s / 20.0, 10.0 * t63_s + ts_s);
    // (cost, θ, τ) of the best of `thetas`.
    let best_of = |thetas: &mut dyn Iterator<Item = f64>| {
        thetas.fold((f64::INFINITY, 0.0, 0.0), |best, theta_s| {
            let (tau, c) = best_tau(s, k, theta_s, tau_lo, tau_hi, ts_s);
            if c < best.0 {
                (c, theta_s, tau)
            } else {
                best
            }
        })
    };
    let coarse = ts_s / 4.0;
    let steps = (t63_s / coarse).ceil() as u32;
    let centre = best_of(&mut (0..=steps).map(|i| f64::from(i) * coarse)).1;
    let fine = (-25i32..=25)
        .map(|i| centre + f64::from(i) * ts_s / 100.0)
        .filter(|&t| t >= 0.0);
    let (c, theta_s, tau_s) = best_of(&mut fine.into_iter());
    let rms_rel = (c / s.len() as f64).sqrt() / k;
    Some(Fopdt {
        k,
        tau_s,
        theta_s,
        rms_rel,
    })
}

/// FOPDT fit of an identified model (physical units: slm per duty fraction), its intercept
/// ignored (see [`fit_fopdt`]).
pub fn fit_model(model: &ArxModel<f32>, ts_s: f64) -> Option<Fopdt> {
    let theta: Vec<f64> = model.theta().iter().map(|&v| f64::from(v)).collect();
    let phi: Vec<f64> = model.phi().iter().map(|&v| f64::from(v)).collect();
    fit_fopdt(&theta, &phi, usize::from(model.structure().d), ts_s)
}

/// A SIMC PI tuning and the figures it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Simc {
    /// Effective delay `θ_e = θ + Ts/2`, s.
    pub theta_eff_s: f64,
    /// Closed-loop time constant `τ_c = θ_e`, s.
    pub tau_c_s: f64,
    /// The PI gains: `K_c` (duty fraction per slm) and `T_i` (s).
    pub gains: PidGains,
}

/// SIMC PI for `fopdt` at sample period `ts_s` (see the module docs). `None` when the model
/// is not usable (gain or time constant not positive and finite).
pub fn simc_pi(fopdt: &Fopdt, ts_s: f64) -> Option<Simc> {
    let f = fopdt;
    let ok = |x: f64| x.is_finite() && x > 0.0;
    if !(ok(f.k) && ok(f.tau_s) && f.theta_s >= 0.0 && ok(ts_s)) {
        return None;
    }
    let theta_eff_s = f.theta_s + ts_s / 2.0;
    let tau_c_s = theta_eff_s;
    let kc = f.tau_s / (f.k * (tau_c_s + theta_eff_s));
    let ti_s = f.tau_s.min(4.0 * (tau_c_s + theta_eff_s));
    Some(Simc {
        theta_eff_s,
        tau_c_s,
        gains: PidGains::pi(kc, ti_s),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simc_rule_by_hand() {
        // K 200 slm/duty, τ 0.15 s, θ 0.03 s, Ts 0.01: θe = 0.035 = τc,
        // Kc = 0.15 / (200 · 0.07), Ti = min(0.15, 0.28).
        let f = Fopdt {
            k: 200.0,
            tau_s: 0.15,
            theta_s: 0.03,
            rms_rel: 0.0,
        };
        let s = simc_pi(&f, 0.01).unwrap();
        assert!((s.theta_eff_s - 0.035).abs() < 1e-15);
        assert!((s.gains.kp - 0.15 / 14.0).abs() < 1e-15);
        assert_eq!(s.gains.ti_s, 0.15);
        assert_eq!(s.gains.td_s, 0.0);
        // Slow plant: Ti = 4 (τc + θe).
        let s = simc_pi(&Fopdt { tau_s: 5.0, ..f }, 0.01).unwrap();
        assert!((s.gains.ti_s - 0.28).abs() < 1e-12);
    }

    #[test]
    fn unstable_or_negative_models_are_not_fitted() {
        assert_eq!(fit_fopdt(&[1.01], &[1.0], 0, 0.01), None);
        assert_eq!(fit_fopdt(&[0.5], &[-1.0], 0, 0.01), None);
    }
}
