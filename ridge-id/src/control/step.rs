//! The simulated closed-loop setpoint step of `--control --plot` ([`simulate_step`]): the
//! designed controller run on the model itself.

use ridge_core::control::{Controller, Design, Limits};
use ridge_core::ArxModel;

/// A simulated closed-loop setpoint response (for the plot): sample `k` at `k · ts` s.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// Sample period, s.
    pub ts: f64,
    /// Setpoint `r_k` (output units).
    pub r: Vec<f64>,
    /// Output `y_k` of the simulated plant (output units).
    pub y: Vec<f64>,
    /// Input `u_k` applied during the interval that ends with `y_k` (input units).
    pub u: Vec<f64>,
    /// The controller's input limits.
    pub limits: Limits<f64>,
}

/// Simulates the designed controller ([`Controller`], with `limits`) on `model` itself as
/// the plant (intercept included, no noise): from the steady state at the middle of the input
/// range, the setpoint steps to the steady output of the input at 70 % of the range, and back.
/// Each step is held for `10 τ` plus `2 (d + q) + 10` samples (at least 40, at most 3000),
/// after a lead of a fifth of that. `None` when the model has no finite steady state.
pub fn simulate_step(
    model: &ArxModel<f64>,
    design: &Design<f64>,
    limits: Limits<f64>,
    ts: f64,
) -> Option<StepResponse> {
    let a1: f64 = 1.0 - model.theta().iter().sum::<f64>();
    let b1: f64 = model.phi().iter().sum();
    let c = model.intercept();
    let steady = |u: f64| (b1 * u + c) / a1;
    let u0 = 0.5 * (limits.min + limits.max);
    let u1 = limits.min + 0.7 * (limits.max - limits.min);
    let (y0, y1) = (steady(u0), steady(u1));
    if !(y0.is_finite() && y1.is_finite()) {
        return None;
    }
    let s = model.structure();
    let (p, q, d) = (usize::from(s.p), usize::from(s.q), usize::from(s.d));
    // Long enough for the slower of the regulation loop and the setpoint response (the
    // reference model's time constant, `−Ts / ln γ`).
    let tau = design.tau.max(-ts / design.gamma.ln());
    let hold = (10.0 * tau / ts).ceil() + (2 * (d + q) + 10) as f64;
    let hold = if hold.is_finite() {
        hold.clamp(40.0, 3000.0) as usize
    } else {
        3000
    };
    let lead = (hold / 5).max(5);
    let n = lead + 2 * hold;
    let r: Vec<f64> = (0..=n)
        .map(|k| {
            if (lead..lead + hold).contains(&k) {
                y1
            } else {
                y0
            }
        })
        .collect();
    // Histories before sample 0 at the operating point; index `pad + k` is sample k.
    let pad = p.max(d + q);
    let mut u = vec![u0; pad + n + 1];
    let mut y = vec![y0; pad + n + 1];
    let mut ctrl = Controller::new(design.rst, limits);
    ctrl.start(u0, y0);
    for k in 0..n {
        let t = pad + k + 1;
        u[t] = ctrl.step(r[k + 1], y[t - 1]);
        let mut v = c;
        for (i, th) in model.theta().iter().enumerate() {
            v += th * y[t - 1 - i];
        }
        for (j, ph) in model.phi().iter().enumerate() {
            v += ph * u[t - d - j];
        }
        y[t] = v;
    }
    Some(StepResponse {
        ts,
        r,
        y: y.split_off(pad),
        u: u.split_off(pad),
        limits,
    })
}
