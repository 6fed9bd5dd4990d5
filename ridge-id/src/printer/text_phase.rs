//! The text printer's lines about the segment of `--phase` and the pump's `ID` line
//! ([`SegmentInfo::to_text`]).

use ridge_core_host::ArxModel;

use crate::phase::SegmentInfo;

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
        if let Some(m) = &self.map {
            let knots: Vec<String> = m
                .map
                .knots()
                .iter()
                .map(|k| format!("{:.3}", f64::from(*k) / 120.0))
                .collect();
            o += &format!(
                "  map         MAP line {}: duty {:.2} % + k x {:.2} % -> flow [{}] slm; u is \
                 the map's flow at the logged duty (the pump's model is from it)\n",
                m.line,
                f64::from(m.map.first()) / 100.0,
                f64::from(m.map.step()) / 100.0,
                knots.join(", ")
            );
        }
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
}
