//! The residual analysis plot: autocorrelation of the one-step residuals and their
//! cross-correlation with the input, with the 99 % bound ([`write_residuals_png`]).

use std::path::Path;

use plotters::prelude::*;

use super::fonts::register_fonts;
use crate::error::IdError;
use crate::residuals::{Residuals, LAGS};

/// Writes one row per analysed record (title, residuals) into the PNG file `path`
/// (1200 px wide, 360 px a row): the autocorrelation `r_k` (left) and the cross-correlation
/// `c_k` with the input (right) as bars, the 99 % bound as dashed lines.
pub fn write_residuals_png(path: &Path, rows: &[(String, &Residuals)]) -> Result<(), IdError> {
    register_fonts();
    let err = |e: &dyn std::fmt::Display| IdError::Plot {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let root = BitMapBackend::new(path, (1200, 360 * rows.len().max(1) as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let areas = root.split_evenly((rows.len().max(1), 2));
    for (i, (title, r)) in rows.iter().enumerate() {
        let panels: [(&str, Vec<(i32, f64)>); 2] = [
            (
                "autocorrelation of the residuals r_k",
                r.autocorr
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| (k as i32 + 1, v))
                    .collect(),
            ),
            (
                "cross-correlation residuals / input c_k",
                r.crosscorr
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| (k as i32, v))
                    .collect(),
            ),
        ];
        for (j, (what, bars)) in panels.iter().enumerate() {
            let Some(area) = areas.get(2 * i + j) else {
                continue;
            };
            let top = bars
                .iter()
                .map(|b| b.1.abs())
                .fold(r.bound, f64::max)
                .max(1e-12)
                * 1.15;
            let verdict = match (j, r.white, r.independent) {
                (0, true, _) => "white",
                (0, false, _) => "not white",
                (_, _, true) => "independent",
                _ => "not independent",
            };
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!("{title}: {what} ({verdict}, 99 % bound {:.3})", r.bound),
                    ("sans-serif", 15),
                )
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(64)
                .build_cartesian_2d(-1i32..LAGS as i32 + 1, -top..top)
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .x_desc("lag k, samples")
                .y_desc(["r_k, no unit", "c_k, no unit"][j])
                .axis_desc_style(("sans-serif", 13))
                .label_style(("sans-serif", 13))
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(|e| err(&e))?;
            let blue = RGBColor(20, 90, 220);
            chart
                .draw_series(bars.iter().map(|&(k, v)| {
                    let (a, b) = if v >= 0.0 { (0.0, v) } else { (v, 0.0) };
                    Rectangle::new([(k, a), (k, b)], blue.stroke_width(4))
                }))
                .map_err(|e| err(&e))?;
            for b in [r.bound, -r.bound] {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(-1, b), (LAGS as i32 + 1, b)],
                        6,
                        4,
                        RGBColor(225, 50, 20).stroke_width(1),
                    ))
                    .map_err(|e| err(&e))?;
            }
        }
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
