//! The rig's units, defined once: the loop rate, the pump duty scale, the SFM3300's flow
//! encoding, and the [`Scale`] that turns the raw integers the device accumulates into physical
//! units (duty fraction 0..1, slm). Every other crate of the workspace (simulator, simavr
//! harness, tools, on-target tests) takes them from here.
//!
//! | quantity | raw unit | physical unit | conversion |
//! |---|---|---|---|
//! | pump duty | 1/[`DUTY_FULL_SCALE`] of full scale (`0..=10 000`) | fraction 0..1 | `× FRACTION_PER_DUTY` |
//! | flow | SFM3300 word `raw`, offset binary | slm | `(raw − FLOW_OFFSET) / FLOW_SCALE` |
//! | flow counts | `raw − FLOW_OFFSET` (`i16`) | slm | `× SLM_PER_COUNT` |
//! | time | ticks of 1/[`SAMPLE_RATE_HZ`] s | s | `× TS_S` |
//!
//! Sensor constants: Sensirion, *Datasheet SFM3300-AW / SFM3300-D* (specification table:
//! "offset flow 32 768", "scale factor flow 120 (slm)⁻¹", measurement range ±250 slm), the same
//! values as the *SFM3xxx I2C functional description*'s conversion `flow = (measured value −
//! offset) / scale factor`.

use ridge_core::Scale;

/// Control loop and sample rate, Hz: one sensor read, one statistics update and one PWM
/// write per tick of 10 ms.
pub const SAMPLE_RATE_HZ: u16 = 100;

/// Sample period, seconds (`1 / SAMPLE_RATE_HZ`).
pub const TS_S: f32 = 1.0 / SAMPLE_RATE_HZ as f32;

/// Full-scale pump duty in command units: `10_000` = 100 % (1 unit = 0.01 %).
pub const DUTY_FULL_SCALE: u16 = 10_000;

/// Duty fraction per duty unit (`1 / DUTY_FULL_SCALE`).
pub const FRACTION_PER_DUTY: f32 = 1.0 / DUTY_FULL_SCALE as f32;

/// Raw SFM3300 flow word at zero flow (datasheet "offset flow").
pub const FLOW_OFFSET: u16 = 32_768;

/// SFM3300 (-D and -AW) scale factor, counts per slm (datasheet "scale factor flow"):
/// 1 count = 1/120 slm.
pub const FLOW_SCALE: u16 = 120;

/// Slm per flow count (`1 / FLOW_SCALE`).
pub const SLM_PER_COUNT: f32 = 1.0 / FLOW_SCALE as f32;

/// Calibrated measurement range of the SFM3300, ± this many slm (datasheet): ±30 000 counts.
pub const FLOW_RANGE_SLM: u16 = 250;

/// Physical units per raw count of a record of duty and flow: duty units → fraction 0..1, flow
/// counts → slm; models identified on it are in slm per duty fraction (the host tools'
/// records; the device's statistics use [`MODEL_SCALE`]).
pub const SCALE: Scale = Scale {
    u: 1.0 / DUTY_FULL_SCALE as f64,
    y: 1.0 / FLOW_SCALE as f64,
};

/// Physical units per raw count of the device's statistics: the static map's flow in, the
/// measured flow out, both SFM3300 counts → slm. Its models are in slm per slm (see
/// `crate::selfid`: the model's dynamics after the map).
pub const MODEL_SCALE: Scale = Scale {
    u: 1.0 / FLOW_SCALE as f64,
    y: 1.0 / FLOW_SCALE as f64,
};
