//! PNG plots: measured vs one-step vs free-run output, one panel per record ([`write_png`]);
//! the simulated closed-loop setpoint step of `--control` ([`write_step_png`]).
//!
//! Drawn with `plotters` (bitmap backend, PNG encoder) and text rendered by `ab_glyph`
//! from the DejaVu Sans font embedded by the `dejavu` crate: no system fonts, fontconfig
//! or freetype are needed.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

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

static FONTS: Once = Once::new();

pub(crate) fn register_fonts() {
    FONTS.call_once(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            // The font is a valid TTF shipped by the crate; failure would only lose text.
            let _ = register_font(family, FontStyle::Normal, dejavu::sans::regular());
        }
    });
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
/// panel). Values outside a panel's axis range are clipped to its edge. A decimated
/// trace is drawn as two outlines per signal: the bucket minima and maxima.
pub fn write_png(path: &Path, panels: &[Panel<'_>]) -> Result<(), IdError> {
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
            .x_desc(if t.decimated() {
                "sample (decimated: min and max of each bucket)"
            } else {
                "sample"
            })
            .y_desc("output y")
            .x_label_formatter(&|x| format!("{x:.0}"))
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

/// Axis range of `series`, padded by 5 % (and 4 × that above, for the legend); a flat
/// series gets a unit-wide range.
fn padded_range<'a>(series: impl IntoIterator<Item = &'a [f64]>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in series {
        for &v in s.iter().filter(|v| v.is_finite()) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if lo > hi {
        return (0.0, 1.0);
    }
    let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
    let pad = 0.05 * span;
    (lo - pad, hi + 4.0 * pad)
}

/// Writes the simulated closed-loop setpoint response `step` of `--control` into the PNG
/// file `path` (1200 × 840 px): setpoint and output on top, the input with its limits below,
/// time in seconds. Every sample is drawn (a step response is short: at most ~6000 samples).
pub fn write_step_png(
    path: &Path,
    title: &str,
    step: &crate::control::StepResponse,
) -> Result<(), IdError> {
    register_fonts();
    let err = |e: &dyn std::fmt::Display| IdError::Plot {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let root = BitMapBackend::new(path, (1200, 840)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(title, ("sans-serif", 22))
        .map_err(|e| err(&e))?;
    let (top, bottom) = root.split_vertically(450);
    let n = step.y.len().min(step.r.len()).min(step.u.len());
    let x_max = ((n.max(2) - 1) as f64) * step.ts;
    let series = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .take(n)
            .enumerate()
            .map(|(k, &x)| (k as f64 * step.ts, x))
            .collect()
    };
    let lim = step.limits;
    let panels = [
        (
            &top,
            "output",
            vec![
                ("setpoint r", &step.r[..], RGBColor(110, 110, 110)),
                ("output y", &step.y[..], RGBColor(225, 50, 20)),
            ],
        ),
        (
            &bottom,
            "input u",
            vec![("input u", &step.u[..], RGBColor(20, 90, 220))],
        ),
    ];
    for (k, (area, y_desc, lines)) in panels.into_iter().enumerate() {
        let (mut y0, mut y1) = padded_range(lines.iter().map(|l| l.1));
        if k == 1 {
            // The input panel shows the limits too.
            let bounds = [lim.min, lim.max];
            let (a, b) =
                padded_range(std::iter::once(&bounds[..]).chain(lines.iter().map(|l| l.1)));
            y0 = y0.min(a);
            y1 = y1.max(b);
        }
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..x_max, y0..y1)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("time, s")
            .y_desc(y_desc)
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(|e| err(&e))?;
        if k == 1 {
            let grey = RGBColor(150, 150, 150);
            for (label, v) in [("limits", lim.min), ("", lim.max)] {
                let s = chart
                    .draw_series(DashedLineSeries::new(
                        vec![(0.0, v), (x_max, v)],
                        6,
                        4,
                        grey.stroke_width(1),
                    ))
                    .map_err(|e| err(&e))?;
                if !label.is_empty() {
                    s.label(label).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 24, y)], grey.stroke_width(1))
                    });
                }
            }
        }
        // 1-pixel lines, as in `write_png`.
        for (label, v, color) in lines {
            chart
                .draw_series(LineSeries::new(series(v), color.stroke_width(1)))
                .map_err(|e| err(&e))?
                .label(label)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 1), (x + 24, y + 2)], color.filled())
                });
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
