//! The signals issue 31 scores a power-up model on, and the score.
//!
//! - The breath program ([`breaths`]): square breaths between the duties whose steady flows
//!   are 10 and 60 slm on the plant at hand (found by bisection on its steady state), 1 s at
//!   the peak and 2 s at the bias, 6 breaths, from the bias duty held 6 s: the flows the
//!   demo's breaths ask of the pump, open loop.
//! - The fresh ramp ([`Record::BRamp`]): 25 ↔ 85 % at 30 %/s, a signal neither power-up
//!   estimates or validates on, from its first duty held 6 s.
//!
//! A model is scored by its free-run fit (MATLAB's `compare`: seeded with the first measured
//! samples, `100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)`), either against the **true flow** of the
//! noise-free plant (what the model should predict, the sensor's noise left out) or against
//! the **measured flow** with a fresh noise seed (what `simavr-run`'s "fresh validation
//! signal" line and a validation on the device see).

use ridge_core::{ArxModel, Evaluation, InputMap};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, SLM_PER_COUNT};

use crate::sfm3300::raw_to_flow;
use crate::{PlantArgs, Sfm3300Params};

/// Ticks a duty is held before a signal starts (6 s: every preset settled).
pub const LEAD_TICKS: usize = 600;

/// Breaths of the program.
pub const BREATHS: usize = 6;

/// The duty (1/10 000) whose steady flow on `plant` is `flow` slm (the smallest such, within
/// one unit), by bisection on the noise-free steady state.
pub fn duty_for(plant: &PlantArgs, flow: f64) -> Result<u16, String> {
    let (mut lo, mut hi) = (0u16, DUTY_FULL_SCALE);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        let mut rig = plant.rig(Sfm3300Params::ideal(), 1)?;
        let mut f = 0.0;
        for _ in 0..LEAD_TICKS {
            f = rig.true_flow(mid);
        }
        if f < flow {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(hi)
}

/// The breath program on `plant` (see the [module docs](self)): its duties, and the bias duty
/// it starts from.
pub fn breaths(plant: &PlantArgs) -> Result<(Vec<u16>, u16), String> {
    let (bias, peak) = (duty_for(plant, 10.0)?, duty_for(plant, 60.0)?);
    let mut duties = Vec::with_capacity(BREATHS * 300);
    for _ in 0..BREATHS {
        duties.extend(std::iter::repeat_n(peak, 100));
        duties.extend(std::iter::repeat_n(bias, 200));
    }
    Ok((duties, bias))
}

/// The fresh ramp's duties and the duty it starts from.
pub fn fresh_ramp() -> (Vec<u16>, u16) {
    let duties: Vec<u16> = Record::BRamp.generator().collect();
    let start = duties.first().copied().unwrap_or(0);
    (duties, start)
}

/// What a fit is taken against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Against {
    /// The true flow of the noise-free plant.
    TrueFlow,
    /// The flow the sensor measures, with noise seed `seed`.
    Measured(u64),
}

/// A model as the pump runs it: the dynamics from the map's flow (`Some(map)`), or a model
/// from the duty fraction (`None`: the model before issue 31).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PumpModel {
    /// The ARX model.
    pub model: ArxModel<f32>,
    /// Its map, if it has one.
    pub map: Option<InputMap>,
}

impl PumpModel {
    /// The model's input at `duty` (1/10 000): the map's flow (slm), or the duty fraction.
    pub fn input(&self, duty: u16) -> f32 {
        match &self.map {
            Some(m) => f32::from(m.at(duty)) * SLM_PER_COUNT,
            None => f32::from(duty) / f32::from(DUTY_FULL_SCALE),
        }
    }
}

/// The free-run fit (%) of `m` on `duties` applied to `plant` from `start` held
/// [`LEAD_TICKS`], against the true or the measured flow.
pub fn free_run_fit(
    plant: &PlantArgs,
    m: &PumpModel,
    duties: &[u16],
    start: u16,
    against: Against,
) -> Result<f32, String> {
    let seed = match against {
        Against::TrueFlow => 1,
        Against::Measured(s) => s,
    };
    let mut rig = plant.rig(Sfm3300Params::default(), seed)?;
    for _ in 0..LEAD_TICKS {
        rig.true_flow(start);
    }
    let mut ev = Evaluation::new(m.model);
    for &d in duties {
        let flow = rig.true_flow(d);
        let y = match against {
            Against::TrueFlow => flow,
            Against::Measured(_) => raw_to_flow(rig.sensor.measure_raw(flow)),
        };
        ev.push(m.input(d), y as f32);
    }
    ev.free_run()
        .map(|s| s.fit)
        .ok_or_else(|| "too short to score".to_string())
}
