//! What `--phase` asks for: the phase, which of its segments, and the operating point
//! subtracted ([`SegmentOptions`], [`OperatingPoint`]).

use crate::csv::quote;

/// Where the operating point `(u0, y0)` subtracted from the segment's samples comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum OperatingPoint {
    /// From the last `# EXCITE … u0=… y0=…` comment before the segment (the pump's own):
    /// `u0` percent → fraction, `y0` slm → the nearest 1/120 slm (the pump's `y0` is a whole
    /// SFM3300 count, printed to 3 decimals). The default of `--phase`.
    #[default]
    Log,
    /// Nothing is subtracted.
    None,
    /// These values, in the log's units (`u` as a fraction, `y` in slm).
    Given {
        /// Input operating point.
        u0: f64,
        /// Output operating point.
        y0: f64,
    },
}

impl std::str::FromStr for OperatingPoint {
    type Err = String;
    /// `log`, `none` or `U0,Y0` (two finite numbers, e.g. `0.3,19.058`).
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "log" => Ok(OperatingPoint::Log),
            "none" => Ok(OperatingPoint::None),
            other => {
                let num = |t: &str| {
                    t.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| format!("{} is not a finite number", quote(t.trim())))
                };
                let (u, y) = other
                    .split_once(',')
                    .ok_or_else(|| format!("{}: expected log, none or U0,Y0", quote(other)))?;
                Ok(OperatingPoint::Given {
                    u0: num(u)?,
                    y0: num(y)?,
                })
            }
        }
    }
}

/// What `--phase` selects.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentOptions {
    /// The `phase` cell of the wanted rows, e.g. `excite`.
    pub phase: String,
    /// The segment's number in the file, from 1 (`--attempt N`); `None`: the last complete one.
    pub attempt: Option<u32>,
    /// The operating point subtracted before the statistics (`--operating-point`).
    pub operating_point: OperatingPoint,
}

impl SegmentOptions {
    /// The pump's estimation record: phase `excite`, the last complete segment, the operating
    /// point of its `# EXCITE` line.
    pub fn excite() -> Self {
        SegmentOptions {
            phase: EXCITE_PHASE.to_string(),
            attempt: None,
            operating_point: OperatingPoint::Log,
        }
    }
}

/// The `phase` of the pump's estimation rows (`State::Excite.name()` of the firmware).
pub const EXCITE_PHASE: &str = "excite";
