//! A test lung behind the blower: the flow then depends on the back pressure.
//!
//! - **Blower pressure–flow curve** at rotor speed `s` (normalised 0..1): a quadratic fan
//!   curve `P_b(Q) = P_shut(s) · (1 − (Q / Q_open(s))²)` between the shut-off pressure
//!   `P_shut(s) = shutoff · s²` (fan law: pressure ∝ speed²) and the open-outlet flow
//!   `Q_open(s)` of the blower model ([`crate::PumpParams::flow_of_speed`]).
//! - **Single-compartment lung**: compliance `C` (mL/cmH₂O) and airway resistance `R`
//!   (cmH₂O/(L/s)); its pressure `P_L = V / C` with `V` the volume above the relaxed lung.
//!   The blower's flow `Q` satisfies `P_b(Q) = P_L + R·Q` (no backflow: `Q ≥ 0`, the
//!   inspiratory limb's check valve); `P_L + R·Q` is the airway pressure at the blower's
//!   outlet ([`Lung::airway_pressure`]).
//! - **Exhalation valve with PEEP**, an input of [`Lung::step`] ([`Valve`]):
//!   - open: a threshold valve that vents `(P_L − PEEP) / R_v` when the lung pressure is
//!     above PEEP, nothing below. This is also the passive valve the identification and the
//!     flow-control tables run with (it vents during inspiration too);
//!   - closed (the inspiration of a volume-controlled breath): no outflow, every millilitre
//!     the blower delivers stays in the lung.
//!
//!   The valve vents the lung itself, not the airway's far end: the airway resistance `R` is
//!   in the inspiratory path only, and in the expiration the lung empties with the time
//!   constant `R_v·C`, faster than a real lung would through `R + R_v`.
//! - **Leak** (optional, [`LungParams::leak`]): `P_L / R_leak` from the lung to the room at
//!   every step, whatever the valve; the sensor at the blower does not see it.
//!
//! `V` is integrated with explicit Euler in steps of at most 0.5 ms (the lung's time constants
//! `R_v·C` and `R·C` are 25 ms or more in every preset). The flow the sensor measures is the
//! blower's, at the end of the step. Units: flows in slm at the interface (L/s inside),
//! pressures in cmH₂O, volumes in mL. [`Lung::set_params`] changes the lung at once (a sudden
//! change of compliance, resistance or leak) keeping its volume.

pub use ridge_pump_firmware::ventilation::Valve;

/// Parameters of the lung and its exhalation valve.
#[derive(Clone, Debug, PartialEq)]
pub struct LungParams {
    /// Compliance `C`, mL/cmH₂O (adult 30–50, paediatric 10–20).
    pub compliance: f64,
    /// Airway resistance `R`, cmH₂O/(L/s) (5–50).
    pub resistance: f64,
    /// Positive end-expiratory pressure held by the exhalation valve, cmH₂O.
    pub peep: f64,
    /// Resistance of the open exhalation valve `R_v`, cmH₂O/(L/s).
    pub valve_resistance: f64,
    /// Resistance of a leak from the lung to the room, cmH₂O/(L/s); `None`: no leak.
    pub leak: Option<f64>,
}

impl LungParams {
    /// An adult lung: C = 50 mL/cmH₂O, R = 5 cmH₂O/(L/s), PEEP 3 cmH₂O, valve 5 cmH₂O/(L/s).
    pub fn adult() -> Self {
        LungParams {
            compliance: 50.0,
            resistance: 5.0,
            peep: 3.0,
            valve_resistance: 5.0,
            leak: None,
        }
    }

    /// A stiff, resistive lung (the paediatric end of ventilator checks): C = 15 mL/cmH₂O,
    /// R = 30 cmH₂O/(L/s), PEEP 3 cmH₂O, valve 10 cmH₂O/(L/s).
    pub fn stiff() -> Self {
        LungParams {
            compliance: 15.0,
            resistance: 30.0,
            peep: 3.0,
            valve_resistance: 10.0,
            leak: None,
        }
    }

    /// `Ok` when every parameter is finite, `C`, `R`, `R_v` (and a leak's resistance)
    /// positive and PEEP at least 0.
    pub fn check(&self) -> Result<(), String> {
        let mut positive = vec![
            ("compliance", self.compliance),
            ("resistance", self.resistance),
            ("valve resistance", self.valve_resistance),
        ];
        if let Some(r) = self.leak {
            positive.push(("leak resistance", r));
        }
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("lung {name} must be positive, got {v}"));
            }
        }
        if !(self.peep.is_finite() && self.peep >= 0.0) {
            return Err(format!("PEEP must be 0 or more, got {}", self.peep));
        }
        Ok(())
    }
}

/// The lung's state.
#[derive(Clone, Debug)]
pub struct Lung {
    params: LungParams,
    /// Volume above the relaxed lung, mL.
    volume: f64,
    /// Blower flow at the end of the last step, slm.
    flow: f64,
}

/// Largest Euler step, s.
const MAX_STEP_S: f64 = 0.0005;

impl Lung {
    /// A relaxed lung (at atmospheric pressure).
    pub fn new(params: LungParams) -> Self {
        Lung {
            params,
            volume: 0.0,
            flow: 0.0,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &LungParams {
        &self.params
    }

    /// Changes the lung's parameters now (a sudden change of compliance, resistance, PEEP or
    /// leak), keeping its volume: the pressure jumps to `V / C'`.
    pub fn set_params(&mut self, params: LungParams) {
        self.params = params;
    }

    /// Lung pressure `V / C`, cmH₂O.
    pub fn pressure(&self) -> f64 {
        self.volume / self.params.compliance
    }

    /// Airway pressure at the blower's outlet at the end of the last step,
    /// `P_L + R · Q`, cmH₂O.
    pub fn airway_pressure(&self) -> f64 {
        self.pressure() + self.params.resistance * self.flow / 60.0
    }

    /// Volume above the relaxed lung, mL.
    pub fn volume(&self) -> f64 {
        self.volume
    }

    /// Blower flow into the lung at the end of the last step, slm.
    pub fn flow(&self) -> f64 {
        self.flow
    }

    /// The blower flow (slm) against the lung's pressure for a blower with open-outlet flow
    /// `open` (slm) and shut-off pressure `shutoff` (cmH₂O) at its current speed: the root of
    /// `P_shut (1 − (Q/Q_open)²) = P_L + R Q` in `0..=Q_open`.
    pub fn blower_flow(&self, open: f64, shutoff: f64) -> f64 {
        let p_l = self.pressure();
        if !(open > 0.0 && shutoff > p_l) {
            return 0.0;
        }
        // a Q² + b Q + c = 0 in L/s: a = P_shut / Q_open², b = R, c = P_L − P_shut < 0.
        let q_open = open / 60.0;
        let a = shutoff / (q_open * q_open);
        let b = self.params.resistance;
        let c = p_l - shutoff;
        let q = (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a);
        (q * 60.0).clamp(0.0, open)
    }

    /// Runs `dt` seconds with the exhalation valve `valve`, the blower at open-outlet flow
    /// `open` (slm) and shut-off pressure `shutoff` (cmH₂O); returns the blower flow at the
    /// end, slm.
    pub fn step(&mut self, valve: Valve, open: f64, shutoff: f64, dt: f64) -> f64 {
        let n = (dt / MAX_STEP_S).ceil().max(1.0);
        let h = dt / n;
        for _ in 0..n as u32 {
            let q_in = self.blower_flow(open, shutoff) / 60.0; // L/s
            let p = self.pressure();
            let over = p - self.params.peep;
            let mut q_out = if over > 0.0 && valve == Valve::Open {
                over / self.params.valve_resistance
            } else {
                0.0
            };
            if let Some(r) = self.params.leak {
                q_out += p / r;
            }
            self.volume = (self.volume + (q_in - q_out) * 1000.0 * h).max(0.0);
        }
        self.flow = self.blower_flow(open, shutoff);
        self.flow
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blower_flow_solves_the_pressure_balance() {
        let mut lung = Lung::new(LungParams::adult());
        lung.volume = 400.0; // 8 cmH2O
        let (open, shutoff) = (120.0, 40.0);
        let q = lung.blower_flow(open, shutoff);
        let p_b = shutoff * (1.0 - (q / open).powi(2));
        let load = lung.pressure() + lung.params.resistance * q / 60.0;
        assert!((p_b - load).abs() < 1e-9, "{p_b} vs {load}");
        // Above the shut-off pressure no flow; an empty lung takes less than the open flow.
        lung.volume = 50.0 * 41.0;
        assert_eq!(lung.blower_flow(open, shutoff), 0.0);
        lung.volume = 0.0;
        assert!(lung.blower_flow(open, shutoff) < open);
    }

    #[test]
    fn steady_state_is_peep_plus_the_valve_drop() {
        // Constant blower: the lung settles where inflow = outflow through the valve.
        let p = LungParams::adult();
        let mut lung = Lung::new(p.clone());
        let mut q = 0.0;
        for _ in 0..2_000 {
            q = lung.step(Valve::Open, 100.0, 60.0, 0.01);
        }
        let expect = p.peep + p.valve_resistance * q / 60.0;
        assert!(
            (lung.pressure() - expect).abs() < 1e-6,
            "{} vs {expect}",
            lung.pressure()
        );
        assert!(q > 10.0, "{q}");
    }

    /// Closed valve: no outflow, so the volume gained is the blower's flow integrated, checked
    /// against a fine Runge–Kutta integration of `dV/dt = Q_b(V)` (the blower's flow solved
    /// from the pressure balance at each volume). Open, the same lung vents and ends lower.
    #[test]
    fn closed_valve_keeps_what_the_blower_delivers() {
        let p = LungParams::adult();
        let (open, shutoff) = (60.0, 40.0);
        let mut lung = Lung::new(p.clone());
        lung.volume = 50.0 * p.peep; // at PEEP
        let v0 = lung.volume;
        for _ in 0..100 {
            lung.step(Valve::Closed, open, shutoff, 0.01);
        }
        // Reference: RK4 with 10 µs steps over the same second.
        let q = |v: f64| {
            let mut l = Lung::new(p.clone());
            l.volume = v;
            l.blower_flow(open, shutoff) / 60.0 * 1000.0 // mL/s
        };
        let (mut v, h) = (v0, 1e-5);
        for _ in 0..100_000 {
            let k1 = q(v);
            let k2 = q(v + 0.5 * h * k1);
            let k3 = q(v + 0.5 * h * k2);
            let k4 = q(v + h * k3);
            v += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        }
        assert!(
            (lung.volume - v).abs() < 1e-3 * (v - v0),
            "{} vs {v}",
            lung.volume
        );
        let mut vented = Lung::new(p);
        vented.volume = v0;
        for _ in 0..100 {
            vented.step(Valve::Open, open, shutoff, 0.01);
        }
        assert!(vented.volume < lung.volume - 100.0);
    }

    /// Blower off, valve open: the volume above PEEP decays with the time constant `R_v·C`;
    /// closed with a leak: the whole volume decays with `R_leak·C` (exact exponentials; Euler
    /// at 0.5 ms is within 1 % after 1 s).
    #[test]
    fn valve_and_leak_empty_the_lung_as_their_exponentials() {
        let p = LungParams::adult(); // C 50 mL/cmH2O, R_v 5: tau 0.25 s
        let mut lung = Lung::new(p.clone());
        lung.volume = 1000.0;
        for _ in 0..100 {
            lung.step(Valve::Open, 0.0, 0.0, 0.01);
        }
        let floor = p.compliance * p.peep;
        let want = floor + (1000.0 - floor) * (-1.0f64 / 0.25).exp();
        assert!(
            (lung.volume - want).abs() < 0.01 * (want - floor),
            "{}",
            lung.volume
        );
        let leaky = LungParams {
            leak: Some(20.0), // tau = 20 · 0.05 = 1 s
            ..p
        };
        let mut lung = Lung::new(leaky);
        lung.volume = 1000.0;
        for _ in 0..100 {
            lung.step(Valve::Closed, 0.0, 0.0, 0.01);
        }
        let want = 1000.0 * (-1.0f64).exp();
        assert!((lung.volume - want).abs() < 0.01 * want, "{}", lung.volume);
    }

    /// ISO row 1's lung (C 50, R 5, PEEP 5) filled from PEEP by a square 30 slm for 1 s with
    /// the valve closed (a blower so strong its flow is its open-outlet flow): 500 mL, lung
    /// pressure PEEP + VT/C = 15, airway pressure + R·Q = 17.5 cmH2O.
    #[test]
    fn square_breath_reaches_peep_plus_vt_over_c_plus_r_q() {
        let p = LungParams {
            compliance: 50.0,
            resistance: 5.0,
            peep: 5.0,
            ..LungParams::adult()
        };
        let mut lung = Lung::new(p);
        lung.volume = 250.0;
        for _ in 0..100 {
            lung.step(Valve::Closed, 30.0, 1e9, 0.01);
        }
        assert!((lung.volume - 750.0).abs() < 0.01, "{}", lung.volume);
        assert!((lung.pressure() - 15.0).abs() < 1e-3);
        assert!((lung.airway_pressure() - 17.5).abs() < 1e-3);
        // A sudden change keeps the volume: half the compliance doubles the pressure.
        let stiffer = LungParams {
            compliance: 25.0,
            ..lung.params().clone()
        };
        lung.set_params(stiffer);
        assert!((lung.pressure() - 30.0).abs() < 1e-3);
    }
}
