//! The truth of the re-identification study: the noise-free plant's small-signal step response
//! and static gain at a steady flow ([`linearisation`], central differences of `±δ` duty steps;
//! [`closed_valve_step`] a volume breath's inspiration with the exhalation valve closed), the
//! same as the model sees it after the power-up's static map ([`through_map`],
//! [`secant_through_map`]), and how an estimate's step response compares with it
//! ([`model_step`], [`rise63`], [`step_error_pct`]).

use ridge_core::input_map::MapTable;
use ridge_core::ArxModel;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, SLM_PER_COUNT};

use crate::{LungParams, PlantArgs, Rig, Sfm3300Params};

/// The small-signal behaviour of the noise-free plant at one steady flow.
#[derive(Clone, Debug, PartialEq)]
pub struct Linearisation {
    /// The steady flow, slm.
    pub flow: f64,
    /// The duty that holds it, fraction 0..1.
    pub duty: f64,
    /// Step response to a unit duty step (slm per duty fraction; through the map, slm per slm of
    /// the map's flow), tick `k` = the flow at the
    /// end of interval `k` after the step at interval 0, as `(y₊ − y₋) / 2δ`.
    pub step: Vec<f64>,
    /// The static gain, slm per duty fraction (through the map, slm per slm; the step response's
    /// last value).
    pub gain: f64,
}

/// Ticks of the truth's step responses (3 s: the slowest lung's time constant is ~0.55 s).
pub const STEP_TICKS: usize = 300;

/// The duty step of [`linearisation`], fraction (±0.5 % of full scale).
pub const DELTA: f64 = 0.005;

/// A noise-free rig with the plant's blower and `lung`, settled at `duty` (fraction).
fn settled(plant: &PlantArgs, lung: &LungParams, duty: f64) -> Rig {
    let mut rig = Rig::new(plant.pump(), Sfm3300Params::ideal(), 0).with_lung(lung.clone());
    for _ in 0..1500 {
        rig.flow_at(duty);
    }
    rig
}

/// The true linearisation of `plant`'s blower behind `lung` at the steady flow `flow` (slm):
/// the duty found by bisection on the settled flow, then `±DELTA` steps from there.
pub fn linearisation(plant: &PlantArgs, lung: &LungParams, flow: f64) -> Linearisation {
    let duty = steady_duty(plant, lung, flow);
    dithered(&settled(plant, lung, duty), flow, duty, STEP_TICKS)
}

/// The response of `base` (already set up: settled, its valve as wanted) to the duty `duty`
/// `±DELTA` for `ticks` ticks: the flow's difference over `2 DELTA` tick by tick (slm per duty
/// fraction) and its last value as the gain; `flow` (slm) is the operating point it is named by.
fn dithered(base: &Rig, flow: f64, duty: f64, ticks: usize) -> Linearisation {
    let run = |d: f64| {
        let mut rig = base.clone();
        (0..ticks).map(|_| rig.flow_at(d)).collect::<Vec<_>>()
    };
    let (up, down) = (run(duty + DELTA), run(duty - DELTA));
    let step: Vec<f64> = up
        .iter()
        .zip(&down)
        .map(|(a, b)| (a - b) / (2.0 * DELTA))
        .collect();
    let gain = step.last().copied().unwrap_or(0.0);
    Linearisation {
        flow,
        duty,
        step,
        gain,
    }
}

/// The duty (fraction) that holds the steady flow `flow` (slm) of `plant`'s blower behind
/// `lung` with the exhalation valve open, by bisection on the settled flow.
fn steady_duty(plant: &PlantArgs, lung: &LungParams, flow: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        let mut rig = settled(plant, lung, mid);
        if rig.flow_at(mid) < flow {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The small-signal response of a volume breath's inspiration, the plant the adaptive loop
/// identifies in ventilation: the noise-free blower behind `lung` settled at the steady flow
/// `from` (slm, the bias flow) with the valve open, then the valve closed and the duty stepped
/// to the one that holds `flow` (slm) with the valve open, `±DELTA`; `step` is the flow's
/// difference over `2 DELTA` tick by tick (slm per duty fraction) while the lung fills, `gain`
/// its value after `ticks` ticks (the inspiration's end). With the valve closed there is no
/// steady flow: the response rises with the blower's lag and falls as the lung's pressure
/// builds.
pub fn closed_valve_step(
    plant: &PlantArgs,
    lung: &LungParams,
    from: f64,
    flow: f64,
    ticks: usize,
) -> Linearisation {
    let mut base = settled(plant, lung, steady_duty(plant, lung, from));
    let duty = steady_duty(plant, lung, flow);
    base.valve = crate::Valve::Closed;
    dithered(&base, flow, duty, ticks)
}

/// The truth as the model sees it, through the power-up's static map `table` (duty → the map's
/// flow): `lin`'s step response and gain divided by the map's local slope at `lin`'s duty
/// (central difference over ±1 % duty), slm per slm of the map's flow.
pub fn through_map(lin: &Linearisation, table: &MapTable) -> Linearisation {
    let d = (lin.duty * f64::from(DUTY_FULL_SCALE)).round() as u16;
    let (a, b) = (
        table.at(d.saturating_sub(100)),
        table.at(d.saturating_add(100)),
    );
    // slm per duty fraction.
    let slope = f64::from(i32::from(b) - i32::from(a)) * f64::from(SLM_PER_COUNT) / 0.02;
    Linearisation {
        flow: lin.flow,
        duty: lin.duty,
        step: lin.step.iter().map(|v| v / slope).collect(),
        gain: lin.gain / slope,
    }
}

/// The secant gain of the noise-free plant between two steady flows seen through the map
/// `table`: the flows' difference over the map's flows at their duties, slm per slm.
pub fn secant_through_map(lo: &Linearisation, hi: &Linearisation, table: &MapTable) -> f64 {
    let at = |l: &Linearisation| {
        f64::from(table.at((l.duty * f64::from(DUTY_FULL_SCALE)).round() as u16))
            * f64::from(SLM_PER_COUNT)
    };
    (hi.flow - lo.flow) / (at(hi) - at(lo))
}

/// The unit step response of `model` (the map's flow → slm) over `ticks` ticks, in the same
/// convention as [`Linearisation::step`].
pub fn model_step(model: &ArxModel<f32>, ticks: usize) -> Vec<f64> {
    let theta: Vec<f64> = model.theta().iter().map(|&v| f64::from(v)).collect();
    let phi: Vec<f64> = model.phi().iter().map(|&v| f64::from(v)).collect();
    let d = usize::from(model.structure().d);
    let mut y = vec![0.0; ticks];
    for k in 0..ticks {
        let mut v = 0.0;
        for (i, th) in theta.iter().enumerate() {
            if k > i {
                v += th * y[k - 1 - i];
            }
        }
        for (j, ph) in phi.iter().enumerate() {
            if k >= d + j {
                v += ph;
            }
        }
        y[k] = v;
    }
    y
}

/// The first tick at which a step response reaches 63 % of its final value, or `None`.
pub fn rise63(step: &[f64]) -> Option<usize> {
    let last = *step.last()?;
    step.iter().position(|&v| v.abs() >= 0.632 * last.abs())
}

/// The RMS difference of two step responses over their common length, in percent of the
/// second's final value: how far an estimate's response is from the truth's.
pub fn step_error_pct(est: &[f64], truth: &[f64]) -> f64 {
    let n = est.len().min(truth.len());
    let last = truth.get(n.wrapping_sub(1)).copied().unwrap_or(1.0);
    let sse: f64 = est
        .iter()
        .zip(truth)
        .take(n)
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    100.0 * (sse / n.max(1) as f64).sqrt() / last.abs()
}

/// The secant gain of the noise-free plant between the breath's two flows (10 and 60 slm),
/// slm per duty fraction.
pub fn secant_gain(lo: &Linearisation, hi: &Linearisation) -> f64 {
    (hi.flow - lo.flow) / (hi.duty - lo.duty)
}
