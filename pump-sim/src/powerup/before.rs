//! The power-up identification before issue 31, reproduced from the firmware's parts, for
//! the comparison: from rest, 2 s at the 30 % base duty (the operating point `y0`: the rounded
//! mean of the last 50 readings), the A-Multistep record (30 s) into the exact integer
//! statistics of the deviations `(u − u0, y − y0)` of the duty and the flow, ridge-core's
//! `Search::<f32>::DEFAULT` (no intercept) on them in duty fraction and slm, and the absolute
//! model `c = c_dev + y0 (1 − Σθ) − u0 Σφ`. Its validation record (B-Multistep, 30 s) changed
//! no model, so it is not run here (see [`super::verdicts`] for its verdicts).

use ridge_core::{ArxModel, IntGram, Offset, Search};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{SCALE, SLM_PER_COUNT};

use crate::{PlantArgs, Sfm3300Params};

/// The base duty and settle time of the power-up before issue 31, 1/10 000 and ticks.
pub const BEFORE_BASE_DUTY: u16 = 3_000;
/// See [`BEFORE_BASE_DUTY`].
pub const BEFORE_SETTLE_TICKS: usize = 200;
/// Its estimation record.
pub const BEFORE_RECORD: Record = Record::AMultistep;
/// Its validation record.
pub const BEFORE_VALIDATION: Record = Record::BMultistep;

/// The model the power-up before issue 31 identified on `plant` with sensor noise `seed`
/// (duty fraction in, slm out), or the search's error.
pub fn model_before(plant: &PlantArgs, seed: u64) -> Result<ArxModel<f32>, String> {
    let mut rig = plant.rig(Sfm3300Params::default(), seed)?;
    // The first reading (at duty 0) is the settle phase's first tick; the others follow the
    // base duty.
    rig.step(0);
    let mut settle = Vec::with_capacity(BEFORE_SETTLE_TICKS);
    for _ in 1..BEFORE_SETTLE_TICKS {
        settle.push(i32::from(raw_to_counts(rig.step(BEFORE_BASE_DUTY))));
    }
    let last: i32 = settle[settle.len() - 50..].iter().sum();
    let y0 = (f64::from(last) / 50.0).round() as i32;
    // Each duty with the reading at the end of its interval: the firmware's pairs.
    let mut gram = IntGram::new();
    for duty in BEFORE_RECORD.generator() {
        let y = i32::from(raw_to_counts(rig.step(duty)));
        gram.push(i32::from(duty) - i32::from(BEFORE_BASE_DUTY), y - y0)
            .map_err(|e| format!("{e:?}"))?;
    }
    let normal = gram.normal::<f32>(SCALE).map_err(|e| format!("{e:?}"))?;
    let dev = Search::DEFAULT
        .run(&normal, None)
        .map_err(|e| format!("{e:?}"))?
        .fit
        .model();
    let (sum_theta, sum_phi): (f32, f32) = (dev.theta().iter().sum(), dev.phi().iter().sum());
    let u0 = f32::from(BEFORE_BASE_DUTY) * 1e-4;
    let c = dev.intercept() + y0 as f32 * SLM_PER_COUNT * (1.0 - sum_theta) - u0 * sum_phi;
    ArxModel::new(
        dev.theta(),
        dev.phi(),
        dev.structure().d,
        Offset::Intercept,
        c,
    )
    .map_err(|e| format!("{e:?}"))
}
