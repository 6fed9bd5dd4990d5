//! The pump's report lines in a capture that `--phase` reads: `# EXCITE` (the record
//! announced before an excitation segment, [`ExciteLine`]) and `# ID` (the model the pump
//! identified on it, [`DeviceId`]), and their parsers. The firmware writes them
//! (`firmware/src/event.rs`); this file is ridge-id's only reader of them.

use std::path::Path;

use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_SCALE};

use crate::error::IdError;

/// The pump's `# EXCITE` line: the record announced before an excitation segment.
#[derive(Debug, Clone, PartialEq)]
pub struct ExciteLine {
    /// Line number of the comment.
    pub line: u64,
    /// The excitation preset, e.g. `A-Multistep`.
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

/// The model the pump reported after a segment (its `# ID` line): the absolute model
/// (duty as a fraction, flow in slm) with its intercept.
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
    /// Input coefficients φ_0..φ_{q−1}, slm per unit duty.
    pub phi: Vec<f64>,
    /// Intercept, slm.
    pub c: f64,
    /// Ridge-M iterations the pump ran on the chosen structure.
    pub iterations: Option<u32>,
}

/// The value after `key=` among the space-separated fields of `text`.
fn field<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.split_ascii_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
}

/// Parses the rest of an `EXCITE` comment: `A-Multistep n=3000 u0=30.00 y0=19.058
/// attempt=1/3`.
pub(super) fn parse_excite(rest: &str, name: &Path, line: u64) -> Result<ExciteLine, IdError> {
    let bad = |what: &str| {
        IdError::line(
            name,
            line,
            format!(
                "EXCITE line: {what} (expected `# EXCITE <record> n=<samples> u0=<duty %> \
                 y0=<slm> attempt=<k>/<n>`)"
            ),
        )
    };
    let num = |key: &str| -> Result<f64, IdError> {
        field(rest, key)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad(&format!("no number {key}=")))
    };
    let samples = field(rest, "n")
        .and_then(|v| v.parse::<u32>().ok())
        .ok_or_else(|| bad("no whole number n="))?;
    let u0_percent = num("u0")?;
    let y0_slm = num("y0")?;
    // The pump prints u0 (1/10 000 duty) in percent with 2 decimals and y0 (whole counts of
    // 1/120 slm) in slm with 3: both are recovered exactly.
    let full = f64::from(DUTY_FULL_SCALE);
    let scale = f64::from(FLOW_SCALE);
    let u0 = (u0_percent * full / 100.0).round() / full;
    let y0 = (y0_slm * scale).round() / scale;
    Ok(ExciteLine {
        line,
        record: rest
            .split_ascii_whitespace()
            .next()
            .unwrap_or("")
            .to_string(),
        samples,
        u0,
        y0,
        attempt: field(rest, "attempt").unwrap_or("").to_string(),
    })
}

/// Parses the rest of an `ID` comment (`p=1 q=1 d=3 off=1 theta=… phi=… c=… … iters=200`);
/// `None` when it is not one (the pump's line is informative here, never required).
pub(super) fn parse_id(rest: &str, line: u64) -> Option<DeviceId> {
    let order = |k: &str| field(rest, k)?.parse::<u8>().ok();
    let list = |k: &str| -> Option<Vec<f64>> {
        field(rest, k)?
            .split(',')
            .map(|v| v.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect()
    };
    let id = DeviceId {
        line,
        p: order("p")?,
        q: order("q")?,
        d: order("d")?,
        offset: field(rest, "off")? == "1",
        theta: list("theta")?,
        phi: list("phi")?,
        c: field(rest, "c")?
            .parse()
            .ok()
            .filter(|c: &f64| c.is_finite())?,
        iterations: field(rest, "iters").and_then(|v| v.parse().ok()),
    };
    (id.theta.len() == usize::from(id.p) && id.phi.len() == usize::from(id.q)).then_some(id)
}
