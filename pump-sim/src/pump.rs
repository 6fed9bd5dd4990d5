//! Nonlinear BLDC blower model: PWM duty in, true flow (slm) out, one call per sample.
//!
//! Structure, per sample of length `ts_s` (10 ms by default):
//!
//! 1. **Transport delay**: the duty that acts now is the one commanded `delay_samples` calls
//!    ago (zero before the start).
//! 2. **Dead zone with start/stop hysteresis**: a stopped rotor starts only once the delayed
//!    duty reaches `start_duty`; a running rotor loses drive when the duty falls to
//!    `stop_duty` or below. While driven, the target speed is
//!    `(duty − stop_duty) / (1 − stop_duty)` (normalised, 0..1); otherwise it is 0.
//! 3. **First-order speed lag**, exact zero-order-hold discretisation:
//!    `speed ← a·speed + (1 − a)·target` with `a = exp(−ts/τ)`, `τ = tau_up_s` when
//!    accelerating and `tau_down_s` when slowing down (a blower coasts down).
//! 4. **Fan curve**: `flow = max_flow_slm · speed^flow_exponent` (exponent > 1: flow rises
//!    faster than linearly with speed and with duty).
//!
//! Timing convention: [`Pump::step`] takes the duty applied during the coming interval and
//! returns the flow at the end of that interval. With `delay_samples = k` the first flow change
//! after a duty step appears exactly `k` calls later (`k = 0`: in the same call), so the plant's
//! ARX delay is `d = k`.
//!
//! A rotor can be blocked for fault injection ([`Pump::set_stalled`]): speed and flow drop to 0
//! at once and stay there while stalled.

use std::collections::VecDeque;

/// Parameters of the blower model. All duties are fractions of full scale (0..1).
#[derive(Clone, Debug, PartialEq)]
pub struct PumpParams {
    /// Sample period, seconds (0.01 = 100 Hz).
    pub ts_s: f64,
    /// Duty (0..1) at which a stopped rotor starts turning.
    pub start_duty: f64,
    /// Duty (0..1) at or below which a running rotor loses drive; also the zero of the
    /// duty-to-speed map. `stop_duty <= start_duty < 1`.
    pub stop_duty: f64,
    /// Speed time constant while accelerating, seconds.
    pub tau_up_s: f64,
    /// Speed time constant while decelerating, seconds.
    pub tau_down_s: f64,
    /// Exponent of the fan curve `flow = max_flow · speed^flow_exponent` (> 1: convex).
    pub flow_exponent: f64,
    /// Flow at full speed (duty 1), standard litres per minute.
    pub max_flow_slm: f64,
    /// Transport delay in samples (the plant's ARX delay).
    pub delay_samples: usize,
    /// Shut-off pressure at full speed (no flow), cmH₂O; the pressure at speed `s` is
    /// `shutoff_cmh2o · s²` (fan law). Only a [`crate::lung::Lung`] behind the blower uses it.
    pub shutoff_cmh2o: f64,
}

impl Default for PumpParams {
    /// The reference blower: dead zone 12 % (start at 15 %), τ = 0.15 s both ways,
    /// flow ∝ speed^1.3, 150 slm at 100 %, 3 samples (30 ms) of transport delay, 100 cmH₂O
    /// shut-off pressure.
    fn default() -> Self {
        Self {
            ts_s: 0.01,
            start_duty: 0.15,
            stop_duty: 0.12,
            tau_up_s: 0.15,
            tau_down_s: 0.15,
            flow_exponent: 1.3,
            max_flow_slm: 150.0,
            delay_samples: 3,
            shutoff_cmh2o: 100.0,
        }
    }
}

impl PumpParams {
    /// A small, quick blower: start 14 % / stop 12 %, τ = 0.08 s up and 0.10 s down,
    /// flow ∝ speed^1.2, 120 slm at 100 %, 2 samples of delay.
    pub fn small() -> Self {
        Self {
            start_duty: 0.14,
            stop_duty: 0.12,
            tau_up_s: 0.08,
            tau_down_s: 0.10,
            flow_exponent: 1.2,
            max_flow_slm: 120.0,
            delay_samples: 2,
            ..Self::default()
        }
    }

    /// A large, sluggish blower: start 17 % / stop 14 %, τ = 0.30 s up and 0.45 s down
    /// (coasting), flow ∝ speed^1.5, 180 slm at 100 %, 5 samples of delay.
    pub fn sluggish() -> Self {
        Self {
            start_duty: 0.17,
            stop_duty: 0.14,
            tau_up_s: 0.30,
            tau_down_s: 0.45,
            flow_exponent: 1.5,
            max_flow_slm: 180.0,
            delay_samples: 5,
            ..Self::default()
        }
    }

    /// Target (steady-state) normalised speed 0..1 for a constant `duty` (0..1), assuming the
    /// rotor starts from rest: 0 below `start_duty`.
    pub fn steady_state_speed(&self, duty: f64) -> f64 {
        let d = sanitize_duty(duty);
        if d < self.start_duty || d <= self.stop_duty {
            0.0
        } else {
            ((d - self.stop_duty) / (1.0 - self.stop_duty)).clamp(0.0, 1.0)
        }
    }

    /// Steady-state flow (slm) for a constant `duty` (0..1), starting from rest.
    pub fn steady_state_flow(&self, duty: f64) -> f64 {
        self.flow_of_speed(self.steady_state_speed(duty))
    }

    /// Fan curve: flow (slm) at normalised speed `speed` (0..1).
    pub fn flow_of_speed(&self, speed: f64) -> f64 {
        self.max_flow_slm * speed.max(0.0).powf(self.flow_exponent)
    }

    /// Shut-off pressure (cmH₂O) at normalised speed `speed` (0..1): `shutoff · speed²`.
    pub fn shutoff_of_speed(&self, speed: f64) -> f64 {
        self.shutoff_cmh2o * speed.max(0.0).powi(2)
    }
}

/// Clamps a duty to 0..1 (NaN → 0).
fn sanitize_duty(duty: f64) -> f64 {
    if duty.is_nan() {
        0.0
    } else {
        duty.clamp(0.0, 1.0)
    }
}

/// Pole `exp(−ts/τ)` of the discretised lag (0 for τ ≤ 0: no lag).
fn pole(ts: f64, tau: f64) -> f64 {
    if tau > 0.0 {
        (-ts / tau).exp()
    } else {
        0.0
    }
}

/// The blower's state. Deterministic: no randomness in the plant (noise is the sensor's).
#[derive(Clone, Debug)]
pub struct Pump {
    params: PumpParams,
    /// `exp(−ts/τ_up)`.
    a_up: f64,
    /// `exp(−ts/τ_down)`.
    a_down: f64,
    /// Duties commanded but not acting yet (length `delay_samples`).
    delay_line: VecDeque<f64>,
    /// Normalised rotor speed 0..1.
    speed: f64,
    /// Whether the driver is commutating (hysteresis state of the dead zone).
    driven: bool,
    /// Rotor blocked (fault injection).
    stalled: bool,
    /// Flow at the end of the last step, slm.
    flow: f64,
}

impl Pump {
    /// A pump at rest (speed 0, delay line full of zero duty).
    pub fn new(params: PumpParams) -> Self {
        let a_up = pole(params.ts_s, params.tau_up_s);
        let a_down = pole(params.ts_s, params.tau_down_s);
        let delay_line = std::iter::repeat_n(0.0, params.delay_samples).collect();
        Self {
            params,
            a_up,
            a_down,
            delay_line,
            speed: 0.0,
            driven: false,
            stalled: false,
            flow: 0.0,
        }
    }

    /// The model's parameters.
    pub fn params(&self) -> &PumpParams {
        &self.params
    }

    /// Back to rest: speed 0, empty (zero) delay line, not stalled.
    pub fn reset(&mut self) {
        *self = Self::new(self.params.clone());
    }

    /// Normalised rotor speed 0..1 after the last step.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// True flow (slm) after the last step.
    pub fn flow_slm(&self) -> f64 {
        self.flow
    }

    /// Blocks (`true`) or frees (`false`) the rotor. Blocking drops speed and flow to 0 at
    /// once; a freed rotor restarts from rest and needs `start_duty` again.
    pub fn set_stalled(&mut self, stalled: bool) {
        self.stalled = stalled;
        if stalled {
            self.speed = 0.0;
            self.driven = false;
            self.flow = 0.0;
        }
    }

    /// Whether the rotor is blocked.
    pub fn is_stalled(&self) -> bool {
        self.stalled
    }

    /// Applies `duty` (0..1; clamped, NaN → 0) for one sample period and returns the true flow
    /// (slm) at the end of it. See the module docs for the timing convention.
    pub fn step(&mut self, duty: f64) -> f64 {
        let d = sanitize_duty(duty);
        let acting = if self.params.delay_samples == 0 {
            d
        } else {
            self.delay_line.push_back(d);
            self.delay_line.pop_front().unwrap_or(0.0)
        };
        if self.stalled {
            self.speed = 0.0;
            self.driven = false;
            self.flow = 0.0;
            return 0.0;
        }
        let p = &self.params;
        if !self.driven && acting >= p.start_duty && acting > p.stop_duty {
            self.driven = true;
        } else if self.driven && acting <= p.stop_duty {
            self.driven = false;
        }
        let target = if self.driven {
            ((acting - p.stop_duty) / (1.0 - p.stop_duty)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let a = if target > self.speed {
            self.a_up
        } else {
            self.a_down
        };
        self.speed = a * self.speed + (1.0 - a) * target;
        self.flow = p.flow_of_speed(self.speed);
        self.flow
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_differ_and_are_sane() {
        for p in [
            PumpParams::default(),
            PumpParams::small(),
            PumpParams::sluggish(),
        ] {
            assert!(p.stop_duty <= p.start_duty && p.start_duty < 0.2);
            assert!(p.flow_exponent > 1.0);
            assert!((120.0..=180.0).contains(&p.max_flow_slm));
            assert!(p.delay_samples <= 6);
            assert!((p.steady_state_flow(1.0) - p.max_flow_slm).abs() < 1e-9);
        }
        assert_ne!(PumpParams::default(), PumpParams::small());
        assert_ne!(PumpParams::default(), PumpParams::sluggish());
    }

    #[test]
    fn hysteresis_keeps_running_between_stop_and_start() {
        let p = PumpParams::default();
        let mut pump = Pump::new(p.clone());
        // 13 % from rest: below start, stays still.
        for _ in 0..200 {
            assert_eq!(pump.step(0.13), 0.0);
        }
        // Spin up at 50 %, then drop to 13 %: still driven, small positive flow.
        for _ in 0..300 {
            pump.step(0.5);
        }
        for _ in 0..300 {
            pump.step(0.13);
        }
        let expect = p.flow_of_speed((0.13 - p.stop_duty) / (1.0 - p.stop_duty));
        assert!((pump.flow_slm() - expect).abs() < 1e-6 * p.max_flow_slm);
        assert!(pump.flow_slm() > 0.0);
        // 10 %: drive lost, coasts to zero.
        for _ in 0..500 {
            pump.step(0.10);
        }
        assert!(pump.flow_slm() < 1e-6);
    }

    #[test]
    fn nan_and_out_of_range_duty_are_clamped() {
        let mut a = Pump::new(PumpParams::default());
        let mut b = Pump::new(PumpParams::default());
        for _ in 0..100 {
            assert_eq!(a.step(f64::NAN), 0.0);
        }
        for _ in 0..500 {
            a.step(7.0);
            b.step(1.0);
        }
        assert_eq!(a.flow_slm(), b.flow_slm());
    }
}
