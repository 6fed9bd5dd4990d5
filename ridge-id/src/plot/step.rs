//! The closed-loop plot of `--control`: the simulated setpoint step, output and input
//! ([`write_control_png`]).

use std::path::Path;

use plotters::prelude::*;

use super::axes::Axes;
use super::fonts::register_fonts;
use crate::control::StepResponse;
use crate::error::IdError;

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
/// file `path` (1200 × 840 px): setpoint and output on top (labelled `axes.output`), the input
/// with its limits below (`axes.input`), time in seconds. Every sample is drawn (a step
/// response is short: at most ~6000 samples).
pub fn write_control_png(
    path: &Path,
    axes: &Axes,
    title: &str,
    step: &StepResponse,
) -> Result<(), IdError> {
    let (output, input) = (axes.output.as_str(), axes.input.as_str());
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
            output,
            vec![
                ("setpoint r", &step.r[..], RGBColor(110, 110, 110)),
                (output, &step.y[..], RGBColor(225, 50, 20)),
            ],
        ),
        (
            &bottom,
            input,
            vec![(input, &step.u[..], RGBColor(20, 90, 220))],
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
        // 1-pixel lines, as in `write_fit_png`.
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
