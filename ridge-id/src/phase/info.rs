//! What the report says about the segment of `--phase` ([`SegmentInfo`]) and how the model
//! agrees with the pump's own `ID` line ([`Agreement`]).

use ridge_core_host::{ArxModel, Offset};
use serde::Serialize;

use super::device_lines::{DeviceId, ExciteLine};
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
    /// Largest |Δφ_j|, slm per unit duty.
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

impl SegmentInfo {
    /// The report's lines about the segment and, when the pump's `ID` line is there, how
    /// `model` agrees with it (indented by two spaces, each ending with a line end).
    pub fn to_text(&self, model: &ArxModel<f64>) -> String {
        let mut o = String::new();
        let excite = self
            .excite
            .as_ref()
            .map(|e| {
                format!(
                    ", announced by EXCITE {} n={} attempt={} (line {})",
                    e.record, e.samples, e.attempt, e.line
                )
            })
            .unwrap_or_default();
        o += &format!(
            "  segment     phase {}: segment {} of {} (lines {}–{}){excite}\n",
            self.phase, self.index, self.count, self.lines.0, self.lines.1
        );
        match self.operating_point {
            Some((u0, y0)) => {
                o += &format!(
                    "  op. point   u0 = {u0}, y0 = {y0} subtracted; the model below is the \
                     absolute one, c = y0 (1 - sum theta) - u0 sum phi\n"
                )
            }
            None => o += "  op. point   none subtracted\n",
        }
        if let Some(d) = &self.device {
            let a = d.agreement(model);
            let list = |v: &[f64]| {
                v.iter()
                    .map(|x| format!("{x}"))
                    .collect::<Vec<_>>()
                    .join(",")
            };
            o += &format!(
                "  pump's ID   (line {}) p = {}, q = {}, d = {}, offset {}, theta = [{}], phi = [{}], c = {}\n",
                d.line,
                d.p,
                d.q,
                d.d,
                if d.offset { "intercept" } else { "none" },
                list(&d.theta),
                list(&d.phi),
                d.c
            );
            o += &match (a.same_structure, a.theta, a.phi, a.c) {
                (true, Some(t), Some(f), Some(c)) => format!(
                    "  agreement   same structure; largest |ridge-id - pump|: theta {t:.2e}, \
                     phi {f:.2e}, c {c:.2e} (the pump prints 6 decimals and computes in f32)\n"
                ),
                _ => "  agreement   DIFFERENT structure from the pump's\n".to_string(),
            };
        }
        o
    }

    /// The `"segment"` object of the JSON report.
    pub fn to_json(&self, model: &ArxModel<f64>) -> serde_json::Value {
        #[derive(Serialize)]
        struct Device<'a> {
            line: u64,
            structure: [u8; 3],
            offset: bool,
            theta: &'a [f64],
            phi: &'a [f64],
            c: f64,
            iterations: Option<u32>,
            agreement: Agreement,
        }
        #[derive(Serialize)]
        struct Json<'a> {
            phase: &'a str,
            index: u32,
            count: u32,
            lines: [u64; 2],
            excite_line: Option<u64>,
            operating_point: Option<[f64; 2]>,
            device: Option<Device<'a>>,
        }
        let j = Json {
            phase: &self.phase,
            index: self.index,
            count: self.count,
            lines: [self.lines.0, self.lines.1],
            excite_line: self.excite.as_ref().map(|e| e.line),
            operating_point: self.operating_point.map(|(u, y)| [u, y]),
            device: self.device.as_ref().map(|d| Device {
                line: d.line,
                structure: [d.p, d.q, d.d],
                offset: d.offset,
                theta: &d.theta,
                phi: &d.phi,
                c: d.c,
                iterations: d.iterations,
                agreement: d.agreement(model),
            }),
        };
        serde_json::to_value(j).unwrap_or(serde_json::Value::Null)
    }
}
