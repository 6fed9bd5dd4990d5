//! A test lung behind the blower: the flow then depends on the back pressure.
//!
//! - **Blower pressure–flow curve** at rotor speed `s` (normalised 0..1): a quadratic fan
//!   curve `P_b(Q) = P_shut(s) · (1 − (Q / Q_open(s))²)` between the shut-off pressure
//!   `P_shut(s) = shutoff · s²` (fan law: pressure ∝ speed²) and the open-outlet flow
//!   `Q_open(s)` of the blower model ([`crate::PumpParams::flow_of_speed`]).
//! - **Single-compartment lung**: compliance `C` (mL/cmH₂O) and airway resistance `R`
//!   (cmH₂O/(L/s)); its pressure `P_L = V / C` with `V` the volume above the relaxed lung.
//!   The blower's flow `Q` satisfies `P_b(Q) = P_L + R·Q` (no backflow: `Q ≥ 0`, the
//!   inspiratory limb's check valve).
//! - **Exhalation valve with PEEP**: a passive threshold valve that vents
//!   `(P_L − PEEP) / R_v` when the lung pressure is above PEEP, nothing below.
//!
//! `V` is integrated with explicit Euler in steps of at most 0.5 ms (the lung's time constants
//! `R_v·C` and `R·C` are 25 ms or more in every preset). The flow the sensor measures is the
//! blower's, at the end of the step. Units: flows in slm at the interface (L/s inside),
//! pressures in cmH₂O, volumes in mL.

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
}

impl LungParams {
    /// An adult lung: C = 50 mL/cmH₂O, R = 5 cmH₂O/(L/s), PEEP 3 cmH₂O, valve 5 cmH₂O/(L/s).
    pub fn adult() -> Self {
        LungParams {
            compliance: 50.0,
            resistance: 5.0,
            peep: 3.0,
            valve_resistance: 5.0,
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
        }
    }

    /// `Ok` when every parameter is finite, `C`, `R` and `R_v` positive and PEEP at least 0.
    pub fn check(&self) -> Result<(), String> {
        let positive = [
            ("compliance", self.compliance),
            ("resistance", self.resistance),
            ("valve resistance", self.valve_resistance),
        ];
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

    /// Runs `dt` seconds with the blower at open-outlet flow `open` (slm) and shut-off
    /// pressure `shutoff` (cmH₂O); returns the blower flow at the end, slm.
    pub fn step(&mut self, open: f64, shutoff: f64, dt: f64) -> f64 {
        let n = (dt / MAX_STEP_S).ceil().max(1.0);
        let h = dt / n;
        for _ in 0..n as u32 {
            let q_in = self.blower_flow(open, shutoff) / 60.0; // L/s
            let over = self.pressure() - self.params.peep;
            let q_out = if over > 0.0 {
                over / self.params.valve_resistance
            } else {
                0.0
            };
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
            q = lung.step(100.0, 60.0, 0.01);
        }
        let expect = p.peep + p.valve_resistance * q / 60.0;
        assert!(
            (lung.pressure() - expect).abs() < 1e-6,
            "{} vs {expect}",
            lung.pressure()
        );
        assert!(q > 10.0, "{q}");
    }
}
