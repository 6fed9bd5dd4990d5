//! A discrete PID controller with the firmware's duty limits: [`Pid`].
//!
//! Parallel (ISA) form at sample period `h` (Åström and Wittenmark, *Computer-Controlled
//! Systems*, the digital PID):
//!
//! ```text
//! P_k     = K_p (r_k − y_k)                                   (setpoint weight b = 1)
//! D_k     = a_d D_{k−1} − K_p N a_d (y_k − y_{k−1}),   a_d = T_d / (T_d + N h)
//! v_k     = P_k + I_k + D_k
//! u_k     = v_k limited to [max(u_min, u_{k−1} − Δ), min(u_max, u_{k−1} + Δ)]
//! I_{k+1} = I_k + K_p h / T_i · (r_k − y_k)   unless u_k ≠ v_k and the error pushes v further out
//! ```
//!
//! - **Derivative on the measurement**, filtered with `T_d / N` (backward difference: stable
//!   for every `N`), so that setpoint steps do not kick the derivative.
//! - **Anti-windup by conditional integration**: while the output is limited (magnitude or
//!   rate) and the error would drive it further into the limit, the integral is frozen. Back
//!   calculation was not used because the rate limit (5 % per tick) is active on every large
//!   setpoint step: tracking `u − v` there would unload the integral during every proportional
//!   kick and undershoot afterwards.
//! - **Bumpless start** ([`Pid::start`]): the integral is set to the applied duty, the filter
//!   state to 0 and the previous reading and setpoint to the current flow, so the first output
//!   is the applied duty unless the flow or the setpoint moved.
//!
//! Units: setpoint and flow in slm, output in duty fraction 0..1, `K_p` in duty fraction per
//! slm, times in seconds.

use ridge_core::control::Limits;
use ridge_pump_firmware::selfid::{ControlConfig, DEFAULT_CONFIG};
use ridge_pump_firmware::units::DUTY_FULL_SCALE;

/// The limits of a firmware control configuration (`duty_min`, `duty_max`, `duty_step` in
/// 1/10 000 of full scale) as the controllers' [`Limits`] in `f64`, duty fraction 0..1.
///
/// Computed from the integers in `f64` (1 500 / 10 000 = 0.15 exactly as `f64` rounds it), not
/// widened from the firmware's `f32` [`ControlConfig::limits`] (0.15 as `f32` is
/// 0.150000006): the host's PID and optimum run at the limits the configuration states.
pub fn config_limits(c: &ControlConfig) -> Limits<f64> {
    let full = f64::from(DUTY_FULL_SCALE);
    Limits {
        min: f64::from(c.duty_min) / full,
        max: f64::from(c.duty_max.min(DUTY_FULL_SCALE)) / full,
        max_step: f64::from(c.duty_step) / full,
    }
}

/// The limits the firmware's RST controller runs with ([`DEFAULT_CONFIG`]`.control`:
/// 15 %..95 %, 5 % per tick), in `f64` ([`config_limits`]).
pub fn firmware_limits() -> Limits<f64> {
    config_limits(&DEFAULT_CONFIG.control)
}

/// No limits: any output, any rate.
pub fn no_limits() -> Limits<f64> {
    Limits {
        min: f64::NEG_INFINITY,
        max: f64::INFINITY,
        max_step: f64::INFINITY,
    }
}

/// Gains of a PID controller in the parallel (ISA) form
/// `K_p (e + (1/T_i) ∫e + T_d de/dt)`, with the derivative filtered by `T_d / N`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PidGains {
    /// Proportional gain `K_p`, duty fraction per slm.
    pub kp: f64,
    /// Integral time `T_i`, s (`f64::INFINITY`: no integral action).
    pub ti_s: f64,
    /// Derivative time `T_d`, s (0: no derivative action).
    pub td_s: f64,
    /// Derivative filter: the filter time constant is `T_d / N` (dimensionless).
    pub n: f64,
}

/// The derivative filter of every baseline: `T_d / 10`.
pub const DERIVATIVE_FILTER_N: f64 = 10.0;

impl PidGains {
    /// A PI controller: `K_p` (duty fraction per slm), `T_i` (s).
    pub fn pi(kp: f64, ti_s: f64) -> Self {
        PidGains {
            kp,
            ti_s,
            td_s: 0.0,
            n: DERIVATIVE_FILTER_N,
        }
    }

    /// A PID controller: `K_p` (duty fraction per slm), `T_i`, `T_d` (s), filter
    /// `N` = [`DERIVATIVE_FILTER_N`].
    pub fn pid(kp: f64, ti_s: f64, td_s: f64) -> Self {
        PidGains {
            kp,
            ti_s,
            td_s,
            n: DERIVATIVE_FILTER_N,
        }
    }

    /// A proportional-only controller.
    pub fn p(kp: f64) -> Self {
        Self::pi(kp, f64::INFINITY)
    }
}

/// Why a [`Pid`] cannot be built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PidError {
    /// `K_p` not finite, `T_i` not positive (∞ allowed), `T_d` negative or not finite, or
    /// `N` not positive and finite.
    Gains,
    /// `min > max`, a NaN limit or a rate limit that is not positive.
    Limits,
    /// The sample period is not positive and finite.
    SamplePeriod,
}

impl std::fmt::Display for PidError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PidError::Gains => "invalid PID gains",
            PidError::Limits => "invalid duty limits",
            PidError::SamplePeriod => "invalid sample period",
        })
    }
}

impl std::error::Error for PidError {}

/// A running discrete PID controller (see the [module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct Pid {
    gains: PidGains,
    limits: Limits<f64>,
    /// Integral gain per sample `K_p h / T_i` (0 without integral action).
    bi: f64,
    /// Derivative filter pole `T_d / (T_d + N h)`.
    ad: f64,
    /// Derivative gain per sample `K_p N a_d`.
    bd: f64,
    /// Integral term `I_k`, duty fraction.
    integral: f64,
    /// Filtered derivative term `D_k`, duty fraction.
    derivative: f64,
    /// Previous reading, slm.
    y_prev: f64,
    /// Output applied last, duty fraction.
    u_prev: f64,
}

impl Pid {
    /// A controller with `gains`, output `limits` and sample period `ts_s` (s), started at
    /// zero duty and zero flow (call [`start`](Self::start) before use).
    pub fn new(gains: PidGains, limits: Limits<f64>, ts_s: f64) -> Result<Self, PidError> {
        if !(ts_s.is_finite() && ts_s > 0.0) {
            return Err(PidError::SamplePeriod);
        }
        let g = gains;
        let gains_ok = g.kp.is_finite()
            && g.ti_s > 0.0
            && !g.ti_s.is_nan()
            && g.td_s.is_finite()
            && g.td_s >= 0.0
            && g.n.is_finite()
            && g.n > 0.0;
        if !gains_ok {
            return Err(PidError::Gains);
        }
        let l = limits;
        if l.min.is_nan() || l.max.is_nan() || l.min > l.max || l.max_step.is_nan() {
            return Err(PidError::Limits);
        }
        if l.max_step <= 0.0 {
            return Err(PidError::Limits);
        }
        let bi = if g.ti_s.is_finite() {
            g.kp * ts_s / g.ti_s
        } else {
            0.0
        };
        let ad = g.td_s / (g.td_s + g.n * ts_s);
        let bd = g.kp * g.n * ad;
        Ok(Pid {
            gains,
            limits,
            bi,
            ad,
            bd,
            integral: 0.0,
            derivative: 0.0,
            y_prev: 0.0,
            u_prev: 0.0,
        })
    }

    /// The gains.
    pub fn gains(&self) -> &PidGains {
        &self.gains
    }

    /// The output limits.
    pub fn limits(&self) -> &Limits<f64> {
        &self.limits
    }

    /// Bumpless start: the duty `u0` (fraction) is applied now and the flow reads `y0` (slm);
    /// the setpoint is taken to be `y0`, which makes `(u0, y0)` an equilibrium of the
    /// controller.
    pub fn start(&mut self, u0: f64, y0: f64) {
        self.integral = u0;
        self.derivative = 0.0;
        self.y_prev = y0;
        self.u_prev = u0;
    }

    /// The integral term, duty fraction (for tests of the anti-windup).
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// The output applied last, duty fraction.
    pub fn last(&self) -> f64 {
        self.u_prev
    }

    /// One sample: takes the setpoint `r` (slm) for the coming interval and the reading `y`
    /// (slm) at the end of the last one; returns the duty fraction for the coming interval,
    /// within the limits and the rate limit. A NaN input or a non-finite result holds the
    /// last output and leaves the state unchanged.
    pub fn step(&mut self, r: f64, y: f64) -> f64 {
        let e = r - y;
        let derivative = self.ad * self.derivative - self.bd * (y - self.y_prev);
        let v = self.gains.kp * e + self.integral + derivative;
        if !v.is_finite() {
            return self.u_prev;
        }
        let lo = self.limits.min.max(self.u_prev - self.limits.max_step);
        let hi = self.limits.max.min(self.u_prev + self.limits.max_step);
        // A start outside the limits moves towards them at the rate limit.
        let u = if lo <= hi {
            v.clamp(lo, hi)
        } else if self.u_prev < self.limits.min {
            hi
        } else {
            lo
        };
        let winding = (v - u) * e > 0.0;
        if !winding {
            self.integral += self.bi * e;
        }
        self.derivative = derivative;
        self.y_prev = y;
        self.u_prev = u;
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn firmware_limits_are_the_default_configs() {
        let l = firmware_limits();
        assert_eq!((l.min, l.max, l.max_step), (0.15, 0.95, 0.05));
    }

    #[test]
    fn hand_computed_first_outputs() {
        // Kp 0.1, Ti 0.5 s, Td 0.1 s, N 10, h 0.01: bi = 0.002, ad = 0.5, bd = 0.5.
        let mut pid = Pid::new(PidGains::pid(0.1, 0.5, 0.1), no_limits(), 0.01).unwrap();
        pid.start(0.3, 20.0);
        assert_eq!(pid.step(20.0, 20.0), 0.3);
        // e = 2: P 0.2, D 0, I 0.3 → 0.5; then I = 0.304.
        assert!((pid.step(22.0, 20.0) - 0.5).abs() < 1e-12);
        // y 21 (Δy 1): e = 1, P 0.1, D = −0.5, I 0.304 → −0.096.
        assert!((pid.step(22.0, 21.0) - (0.1 + 0.304 - 0.5)).abs() < 1e-12);
        // y 21 again: D = 0.5 · (−0.5) = −0.25, I = 0.306.
        assert!((pid.step(22.0, 21.0) - (0.1 + 0.306 - 0.25)).abs() < 1e-12);
    }

    #[test]
    fn limits_and_rate_limit() {
        let limits = Limits {
            min: 0.15,
            max: 0.95,
            max_step: 0.05,
        };
        let mut pid = Pid::new(PidGains::p(1.0), limits, 0.01).unwrap();
        pid.start(0.3, 0.0);
        assert!((pid.step(10.0, 0.0) - 0.35).abs() < 1e-12);
        assert!((pid.step(-10.0, 0.0) - 0.30).abs() < 1e-12);
        pid.start(0.9, 0.0);
        assert!((pid.step(10.0, 0.0) - 0.95).abs() < 1e-12);
        // Started below the limits: up at the rate limit.
        pid.start(0.0, 0.0);
        assert!((pid.step(-10.0, 0.0) - 0.05).abs() < 1e-12);
    }

    #[test]
    fn integral_is_frozen_while_limited_in_the_error_direction() {
        let mut pid = Pid::new(PidGains::pi(0.01, 0.1), firmware_limits(), 0.01).unwrap();
        pid.start(0.9, 50.0);
        for _ in 0..100 {
            pid.step(200.0, 50.0);
        }
        assert_eq!(pid.last(), 0.95);
        assert!(pid.integral() < 0.95, "{}", pid.integral());
        // The error changes sign: the output leaves the limit at once.
        let u = pid.step(40.0, 50.0);
        assert!(u < 0.95, "{u}");
    }

    #[test]
    fn rejects_bad_settings() {
        let l = firmware_limits();
        assert_eq!(
            Pid::new(PidGains::pi(f64::NAN, 1.0), l, 0.01),
            Err(PidError::Gains)
        );
        assert_eq!(
            Pid::new(PidGains::pi(1.0, 0.0), l, 0.01),
            Err(PidError::Gains)
        );
        assert_eq!(
            Pid::new(PidGains::pid(1.0, 1.0, -1.0), l, 0.01),
            Err(PidError::Gains)
        );
        let bad = Limits {
            min: 1.0,
            max: 0.0,
            max_step: 0.1,
        };
        assert_eq!(Pid::new(PidGains::p(1.0), bad, 0.01), Err(PidError::Limits));
        assert_eq!(
            Pid::new(PidGains::p(1.0), l, 0.0),
            Err(PidError::SamplePeriod)
        );
    }
}
