//! What the report says about the segment of `--phase` ([`SegmentInfo`]) and how the model
//! agrees with the pump's own `ID` line ([`Agreement`]).

use ridge_core_host::{ArxModel, Offset};
use serde::Serialize;

use super::device_lines::{DeviceId, DeviceMap, ExciteLine};
use super::options::SegmentOptions;
use super::read::Segment;

/// What the report says about the segment (`--phase`).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentInfo {
    /// The phase asked for.
    pub phase: String,
    /// Which segment of that phase (from 1) and how many the file has.
    pub index: u32,
    /// Segments of the phase in the file.
    pub count: u32,
    /// Lines of its first and last row.
    pub lines: (u64, u64),
    /// The `# EXCITE` line before it, if any.
    pub excite: Option<ExciteLine>,
    /// The `# MAP` line its input went through, if any.
    pub map: Option<DeviceMap>,
    /// The pump's `# ID` line after it, if any.
    pub device: Option<DeviceId>,
    /// The operating point subtracted, `(u0, y0)` in the log's units.
    pub operating_point: Option<(f64, f64)>,
}

impl Segment {
    /// The report's account of it, for the phase of `opts`.
    pub fn info(&self, opts: &Option<SegmentOptions>) -> SegmentInfo {
        SegmentInfo {
            phase: opts.as_ref().map(|o| o.phase.clone()).unwrap_or_default(),
            index: self.index,
            count: self.count,
            lines: self.lines(),
            excite: self.excite.clone(),
            map: self.map,
            device: self.device.clone(),
            operating_point: self.operating_point,
        }
    }
}

/// `ridge-id`'s model against the pump's `# ID` line.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Agreement {
    /// Same `p`, `q`, `d` and offset flag.
    pub same_structure: bool,
    /// Largest |Δθ_i| (with the same structure; else `None`).
    pub theta: Option<f64>,
    /// Largest |Δφ_j|, in the model's units (slm per slm of the map's flow).
    pub phi: Option<f64>,
    /// |Δc|, slm.
    pub c: Option<f64>,
}

/// Largest absolute difference of two equally long lists (`None` when they are not).
fn max_diff(a: &[f64], b: &[f64]) -> Option<f64> {
    (a.len() == b.len()).then(|| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    })
}

impl DeviceId {
    /// How `model` agrees with this line.
    pub fn agreement(&self, model: &ArxModel<f64>) -> Agreement {
        let s = model.structure();
        let same = (s.p, s.q, s.d, model.offset() == Offset::Intercept)
            == (self.p, self.q, self.d, self.offset);
        let c = same.then(|| (model.intercept() - self.c).abs());
        Agreement {
            same_structure: same,
            theta: max_diff(model.theta(), &self.theta).filter(|_| same),
            phi: max_diff(model.phi(), &self.phi).filter(|_| same),
            c,
        }
    }
}
