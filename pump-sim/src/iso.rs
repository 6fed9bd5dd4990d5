//! The ISO 80601-2-12 volume-control test lungs: rows 1–8 (adult) of Table 201.104 of
//! ISO 80601-2-12:2020 (*Medical electrical equipment — Particular requirements for basic
//! safety and essential performance of critical care ventilators*), as transcribed in
//! RespiraWorks' ventilator repository, `software/tools/scenarios/iso_volume_tests.csv`
//! (scenarios `iso_vc_1` … `iso_vc_8`): compliance, airway resistance, rate, I:E, PEEP and
//! tidal volume; every adult row has an inspiration of 1 s.
//!
//! What each row asks of the blower ([`IsoRow::needs`]): with a square inspiratory flow
//! `Q = VT / Ti` the airway pressure rises to `PEEP + VT / C + R · Q` at the end of the
//! inspiration (17.5 cmH₂O on row 1 to 55 on row 7); with a decelerating ramp (to zero flow)
//! the flow starts at `2 VT / Ti` against `PEEP + R · Q`. The blower gives a flow `Q` at a
//! pressure `P` at the speed `s` where `P_shut · s² · (1 − (Q / Q_open(s))²) = P` (the fan curve
//! of [`crate::lung`]); [`duty_for`] solves it and maps the speed back to the duty (the
//! blower's static map, [`crate::pump`]). A row the blower cannot serve within the
//! controller's largest duty is named by [`IsoRow::needs`] with the duty it would need.

use crate::{LungParams, PumpParams};
use ridge_pump_firmware::setpoint::Shape;

/// One volume-control scenario (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsoRow {
    /// Row of Table 201.104 (1–8).
    pub row: u8,
    /// Compliance, mL/cmH₂O.
    pub compliance: f64,
    /// Airway resistance, cmH₂O/(L/s).
    pub resistance: f64,
    /// Breaths per minute.
    pub rate: f64,
    /// Expiratory part of the I:E ratio `1 : ie`.
    pub ie: f64,
    /// PEEP, cmH₂O.
    pub peep: f64,
    /// Tidal volume, mL.
    pub tidal: f64,
}

const fn row(
    row: u8,
    compliance: f64,
    resistance: f64,
    rate: f64,
    ie: f64,
    peep: f64,
    tidal: f64,
) -> IsoRow {
    IsoRow {
        row,
        compliance,
        resistance,
        rate,
        ie,
        peep,
        tidal,
    }
}

/// Rows 1–8 of ISO 80601-2-12:2020 Table 201.104 (see the [module docs](self) for the source).
pub const ISO_ROWS: [IsoRow; 8] = [
    row(1, 50.0, 5.0, 20.0, 2.0, 5.0, 500.0),
    row(2, 50.0, 20.0, 12.0, 4.0, 10.0, 500.0),
    row(3, 20.0, 5.0, 20.0, 2.0, 5.0, 500.0),
    row(4, 20.0, 20.0, 20.0, 2.0, 10.0, 500.0),
    row(5, 20.0, 20.0, 20.0, 2.0, 5.0, 300.0),
    row(6, 20.0, 50.0, 12.0, 4.0, 10.0, 300.0),
    row(7, 10.0, 50.0, 20.0, 2.0, 10.0, 300.0),
    row(8, 10.0, 10.0, 20.0, 2.0, 5.0, 200.0),
];

/// Row `n` (1–8), or `None`.
pub fn iso_row(n: u8) -> Option<IsoRow> {
    ISO_ROWS.iter().copied().find(|r| r.row == n)
}

/// The blower's duty (0..1) at which it gives `flow` slm against `pressure` cmH₂O in steady
/// state, `None` if not even full speed does. Solves `P_shut s² (1 − (Q / Q_open(s))²) = P`
/// for the speed `s` by bisection (the left side rises with `s` wherever it is positive),
/// then `duty = stop + (1 − stop) · s` (the blower model's speed map above its dead zone).
pub fn duty_for(pump: &PumpParams, flow: f64, pressure: f64) -> Option<f64> {
    let gives = |s: f64| {
        let open = pump.flow_of_speed(s);
        if open <= flow {
            return f64::NEG_INFINITY;
        }
        pump.shutoff_of_speed(s) * (1.0 - (flow / open).powi(2))
    };
    if gives(1.0) < pressure {
        return None;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if gives(mid) >= pressure {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(pump.stop_duty + (1.0 - pump.stop_duty) * hi)
}

/// What a row asks of the blower for one inspiratory shape: the largest airway pressure and
/// flow, and the largest duty any instant of the inspiration needs (`None`: beyond full
/// speed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Needs {
    /// Largest airway pressure of the inspiration, cmH₂O.
    pub peak_pressure: f64,
    /// Largest flow, slm.
    pub peak_flow: f64,
    /// The largest steady-state duty over the inspiration, 0..1 (`None`: not reachable).
    pub duty: Option<f64>,
}

impl IsoRow {
    /// Inspiratory time, s: `60 / (rate (1 + ie))`.
    pub fn ti(&self) -> f64 {
        60.0 / (self.rate * (1.0 + self.ie))
    }

    /// The row's lung with the exhalation valve of `base` (its resistance; no leak).
    pub fn lung(&self, base: &LungParams) -> LungParams {
        LungParams {
            compliance: self.compliance,
            resistance: self.resistance,
            peep: self.peep,
            ..base.clone()
        }
    }

    /// What the inspiration of `shape` (no bias flow; the ramp falls to zero) asks of
    /// `pump`, evaluated at 1 000 instants of the inspiration (see the [module docs](self)).
    pub fn needs(&self, pump: &PumpParams, shape: Shape) -> Needs {
        let ti = self.ti();
        let v = self.tidal / 1000.0; // L
        let mut worst = Needs {
            peak_pressure: 0.0,
            peak_flow: 0.0,
            duty: Some(0.0),
        };
        for i in 0..=1000 {
            let t = ti * f64::from(i) / 1000.0;
            // Flow (L/s) and volume delivered so far (L).
            let (q, vol) = match shape {
                Shape::Square => (v / ti, v * t / ti),
                Shape::Ramp => {
                    let q0 = 2.0 * v / ti;
                    (q0 * (1.0 - t / ti), q0 * (t - t * t / (2.0 * ti)))
                }
            };
            let p = self.peep + vol * 1000.0 / self.compliance + self.resistance * q;
            worst.peak_pressure = worst.peak_pressure.max(p);
            worst.peak_flow = worst.peak_flow.max(q * 60.0);
            worst.duty = match (worst.duty, duty_for(pump, q * 60.0, p)) {
                (Some(a), Some(b)) => Some(a.max(b)),
                _ => None,
            };
        }
        worst
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rows' square-flow peak pressures are `PEEP + VT/C + R·VT/Ti` (17.5 to 55 cmH₂O).
    #[test]
    fn square_peak_pressure_is_the_formula() {
        let want = [17.5, 30.0, 32.5, 45.0, 26.0, 40.0, 55.0, 27.0];
        for (r, w) in ISO_ROWS.iter().zip(want) {
            assert!((r.ti() - 1.0).abs() < 1e-12);
            let n = r.needs(&PumpParams::default(), Shape::Square);
            assert!((n.peak_pressure - w).abs() < 1e-9, "row {}", r.row);
        }
    }

    /// At the duty `duty_for` returns, the blower model in steady state (its own static map
    /// from duty to speed) gives the flow against the pressure on its fan curve.
    #[test]
    fn duty_for_lands_on_the_fan_curve() {
        for pump in [
            PumpParams::default(),
            PumpParams::small(),
            PumpParams::sluggish(),
        ] {
            for (q, p) in [(30.0, 17.5), (18.0, 55.0), (60.0, 30.0), (1.0, 1.0)] {
                let d = duty_for(&pump, q, p).unwrap();
                let s = pump.steady_state_speed(d);
                let open = pump.flow_of_speed(s);
                let given = pump.shutoff_of_speed(s) * (1.0 - (q / open).powi(2));
                assert!((given - p).abs() < 1e-6, "{q} slm at {p}: {given}");
            }
            // Beyond full speed's shut-off pressure: none.
            assert_eq!(duty_for(&pump, 1.0, 101.0), None);
        }
    }
}
