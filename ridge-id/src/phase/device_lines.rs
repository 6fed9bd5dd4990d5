//! The pump's report lines in a capture that `--phase` reads: `# MAP` (the static map the
//! attempt measured, [`DeviceMap`]), `# EXCITE` (the record announced before an excitation
//! segment, [`ExciteLine`]) and `# ID` (the model the pump identified on it, [`DeviceId`]). The
//! firmware writes them (`firmware/src/event.rs`) and parses them (`firmware/src/lines.rs`, its
//! one host-side parser); here they become ridge-id's records, in physical units and with the
//! capture's line numbers.

use std::path::Path;

use ridge_core::{InputMap, Offset};
use ridge_pump_firmware::lines;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_SCALE};

use crate::error::IdError;

/// The pump's `# EXCITE` line: the record announced before an excitation segment.
#[derive(Debug, Clone, PartialEq)]
pub struct ExciteLine {
    /// Line number of the comment.
    pub line: u64,
    /// The record's name, e.g. `flow-steps`.
    pub record: String,
    /// Samples announced (`n`).
    pub samples: u32,
    /// Base duty as a fraction 0..1 (the line's `u0`, percent, divided by 100).
    pub u0: f64,
    /// Settled flow, slm: the line's `y0` taken to the nearest SFM3300 count (1/120 slm).
    pub y0: f64,
    /// The attempt as printed, e.g. `1/3`.
    pub attempt: String,
}

/// The pump's `# MAP` line: the static map from duty to flow its model's input goes through
/// (the pump identifies the dynamics from the map's flow to the measured flow).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceMap {
    /// Line number of the comment.
    pub line: u64,
    /// The map: duty in 1/10 000 to flow in counts of 1/120 slm, exactly as the pump holds it.
    pub map: InputMap,
}

impl DeviceMap {
    /// The map's flow (slm) at the duty fraction `u` as the log prints it (4 decimals: the
    /// pump's whole 1/10 000), the pump's `InputMap::at`.
    pub fn flow(&self, u: f64) -> f64 {
        let duty = (u * f64::from(DUTY_FULL_SCALE))
            .round()
            .clamp(0.0, 65_535.0) as u16;
        f64::from(self.map.at(duty)) / f64::from(FLOW_SCALE)
    }
}

/// Parses the rest of a `MAP` comment: `first=15.00 step=5.33 flow=…` (the firmware's parser).
pub(super) fn parse_map(rest: &str, name: &Path, line: u64) -> Result<DeviceMap, IdError> {
    let parsed = lines::MapLine::parse(&format!("MAP {rest}")).map_err(|e| {
        IdError::line(
            name,
            line,
            format!(
                "MAP line: {e} (expected `# MAP first=<duty %> step=<duty %> flow=<16 \
                 increasing flows, slm>`)"
            ),
        )
    })?;
    Ok(DeviceMap {
        line,
        map: parsed.map,
    })
}

/// The model the pump reported after a segment (its `# ID` line): the absolute model (the
/// map's flow in slm in, or the duty as a fraction for a pump without a map; flow in slm out)
/// with its intercept.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceId {
    /// Line number of the comment.
    pub line: u64,
    /// Orders and delay.
    pub p: u8,
    /// Input order.
    pub q: u8,
    /// Input delay, samples.
    pub d: u8,
    /// Whether the model has an intercept (`off=1`).
    pub offset: bool,
    /// Output coefficients θ_1..θ_p (6 decimals as printed).
    pub theta: Vec<f64>,
    /// Input coefficients φ_0..φ_{q−1}, slm of flow per slm of the map's flow.
    pub phi: Vec<f64>,
    /// Intercept, slm.
    pub c: f64,
    /// Ridge-M iterations the pump ran on the chosen structure.
    pub iterations: Option<u32>,
}

/// Parses the rest of an `EXCITE` comment: `flow-steps n=700 u0=30.00 y0=19.058
/// attempt=1/3` (the firmware's parser; the operating point exactly in its units).
pub(super) fn parse_excite(rest: &str, name: &Path, line: u64) -> Result<ExciteLine, IdError> {
    let parsed = lines::ExciteLine::parse(&format!("EXCITE {rest}")).map_err(|e| {
        IdError::line(
            name,
            line,
            format!(
                "EXCITE line: {e} (expected `# EXCITE <record> n=<samples> u0=<duty %> \
                 y0=<slm> attempt=<k>/<n>`)"
            ),
        )
    })?;
    let (u0, y0) = parsed.operating_point();
    Ok(ExciteLine {
        line,
        record: parsed.record,
        samples: parsed.samples,
        u0,
        y0,
        attempt: parsed
            .attempt
            .map(|(k, n)| format!("{k}/{n}"))
            .unwrap_or_default(),
    })
}

/// Parses the rest of an `ID` comment (`p=1 q=1 d=3 off=1 theta=… phi=… c=… … iters=200`,
/// the firmware's parser); `None` when it is not one (the pump's line is informative here,
/// never required).
pub(super) fn parse_id(rest: &str, line: u64) -> Option<DeviceId> {
    let id = lines::IdLine::parse(&format!("ID {rest}")).ok()?;
    let m = id.model;
    Some(DeviceId {
        line,
        p: m.p,
        q: m.q,
        d: m.d,
        offset: m.offset == Offset::Intercept,
        theta: m.theta,
        phi: m.phi,
        c: m.c,
        iterations: Some(id.iterations),
    })
}
