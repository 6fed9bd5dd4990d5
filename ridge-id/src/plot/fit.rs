//! The fit plot: measured vs one-step vs free-run output, one panel per record
//! ([`write_fit_png`]).

use std::path::Path;

use plotters::prelude::*;

use super::axes::Axes;
use super::fonts::register_fonts;
use crate::error::IdError;
use crate::eval::Trace;

/// One panel: a title and the decimated signals of one record.
#[derive(Debug, Clone)]
pub struct Panel<'a> {
    /// Panel caption, e.g. `validation: VAL.csv`.
    pub title: String,
    /// The signals.
    pub trace: &'a Trace,
}

/// Axis range of a panel: the measured range, widened to the predictions but never past
/// one measured span on either side (a diverging free-run would flatten everything).
fn y_range(trace: &Trace) -> (f64, f64) {
    let (lo, hi) = trace.measured.range().unwrap_or((0.0, 1.0));
    let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
    let (mut a, mut b) = (lo, hi);
    for e in [&trace.one_step, &trace.free_run] {
        if let Some((l, h)) = e.range() {
            a = a.min(l.max(lo - span));
            b = b.max(h.min(hi + span));
        }
    }
    // Head room above the data for the legend.
    let pad = 0.05 * (b - a).max(span);
    (a - pad, b + 4.0 * pad)
}

/// Writes `panels` stacked vertically into the PNG file `path` (1200 px wide, 420 px per
/// panel), the output axis labelled `axes.output`, time in samples or, with `axes.ts`, in
/// seconds. Values outside a panel's axis range are clipped to its edge. A decimated trace is
/// drawn as two outlines per signal: the bucket minima and maxima.
pub fn write_fit_png(path: &Path, axes: &Axes, panels: &[Panel<'_>]) -> Result<(), IdError> {
    register_fonts();
    let err = |e: &dyn std::fmt::Display| IdError::Plot {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let rows = panels.len().max(1);
    let root = BitMapBackend::new(path, (1200, 420 * rows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let areas = root.split_evenly((rows, 1));
    for (area, panel) in areas.iter().zip(panels) {
        let t = panel.trace;
        let x_max = (t.samples.max(2) - 1) as f64;
        let (y0, y1) = y_range(t);
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..x_max, y0..y1)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(match (axes.ts.is_some(), t.decimated()) {
                (false, true) => "sample (decimated: min and max of each bucket)",
                (false, false) => "sample",
                (true, true) => "time, s (decimated: min and max of each bucket)",
                (true, false) => "time, s",
            })
            .y_desc(&axes.output)
            .x_label_formatter(&|x| match axes.ts {
                // The chart counts samples; its labels say their time.
                Some(ts) => format!("{}", (x * ts * 1e6).round() / 1e6),
                None => format!("{x:.0}"),
            })
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| err(&e))?;
        let clip = |pts: Vec<(f64, f64)>| -> Vec<(f64, f64)> {
            pts.into_iter().map(|(x, v)| (x, v.clamp(y0, y1))).collect()
        };
        // 1-pixel lines only: plotters polygonises wider strokes and produces spikes
        // where consecutive points land on the same pixel (dense or decimated data).
        let series = [
            ("measured", &t.measured, RGBColor(110, 110, 110)),
            ("one-step ahead", &t.one_step, RGBColor(20, 90, 220)),
            ("free run", &t.free_run, RGBColor(225, 50, 20)),
        ];
        // About one pixel in data units: the measured line is drawn as a 5-pixel band
        // (five 1-pixel lines) so that the one-step prediction stays visible on top of
        // it, the free run as a 2-pixel line.
        let px = (y1 - y0) / f64::from(area.dim_in_pixel().1.saturating_sub(90).max(1));
        for (k, (label, env, color)) in series.into_iter().enumerate() {
            let style = color.stroke_width(1);
            let offsets: &[f64] = match k {
                _ if t.decimated() => &[],
                0 => &[-2.0, -1.0, 1.0, 2.0],
                2 => &[1.0],
                _ => &[],
            };
            {
                for &off in offsets {
                    let shifted = env.lower().into_iter().map(|(x, v)| (x, v + off * px));
                    chart
                        .draw_series(LineSeries::new(clip(shifted.collect()), style))
                        .map_err(|e| err(&e))?;
                }
            }
            chart
                .draw_series(LineSeries::new(clip(env.lower()), style))
                .map_err(|e| err(&e))?
                .label(label)
                .legend(move |(x, y)| {
                    let h = [2, 0, 1][k];
                    Rectangle::new([(x, y - h), (x + 24, y + h + 1)], color.filled())
                });
            if t.decimated() {
                chart
                    .draw_series(LineSeries::new(clip(env.upper()), style))
                    .map_err(|e| err(&e))?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.5))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
