//! The benchmark table: ISO rows × {square, ramp} × {adaptive, frozen, SIMC PI, ZN PID}.

use crate::run::{max, power_ups, refused, runs};
use pump_sim::iso::IsoRow;
use pump_sim::reid::mean_sd;
use pump_sim::vent_bench::{outcomes, row_lung, score, Cell, Ctrl};
use ridge_pump_firmware::setpoint::Shape;

/// The name of the wave `w`.
fn wave_name(w: Shape) -> &'static str {
    match w {
        Shape::Square => "square",
        Shape::Ramp => "ramp",
    }
}

/// Prints the benchmark table: `rows` × {square, ramp} × the four controllers, `breaths`
/// breaths per cell, seeds 1 to `seeds`.
pub fn print(rows: &[IsoRow], breaths: u32, seeds: u64) {
    println!(
        "## Benchmark: {breaths} breaths, seeds 1-{seeds}, default blower, SFM3300 noise on, trim on\n"
    );
    println!(
        "| row | wave | controller | worst \\|error\\| breaths ≥ 3 (%) | ±(4 mL + 5 %) from 3 (seeds) | ±(4 mL + 15 %) from 3 | breath 1 error (%, mean) | lung at breath 1's start − PEEP (cmH₂O, mean) | peak pressure rise on the breath before, max: breaths ≥ 3 / breath 2 (cmH₂O) | \\|PEEP error\\| max (cmH₂O) | tracking RMS (slm) | swaps / refused: fit, model, other, design |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &row in rows {
        let ups = power_ups(&row_lung(&row, 0.0), seeds);
        for wave in [Shape::Square, Shape::Ramp] {
            for ctrl in Ctrl::ALL {
                let cell = Cell {
                    breaths,
                    ..Cell::new(row, wave, ctrl)
                };
                let all = runs(&ups, &cell);
                let s: Vec<_> = all.iter().map(|r| score(r, 3)).collect();
                let first: Vec<f64> = all
                    .iter()
                    .filter_map(|r| r.breaths.first().map(|b| b.error_pct()))
                    .collect();
                let start: Vec<f64> = all
                    .iter()
                    .filter_map(|r| r.breaths.first().map(|b| b.start_pressure - b.peep))
                    .collect();
                let o = outcomes(all.iter().flat_map(|r| r.estimates.iter()));
                println!(
                    "| {} | {} | {} | {:.1} | {}/{} | {}/{} | {:+.1} | {:+.1} | {:+.1} / {:+.1} | {:.2} | {:.2} | {} |",
                    row.row,
                    wave_name(wave),
                    ctrl.name(),
                    max(s.iter().map(|s| s.worst_pct)),
                    s.iter().filter(|s| s.pass5).count(),
                    s.len(),
                    s.iter().filter(|s| s.pass15).count(),
                    s.len(),
                    mean_sd(&first).0,
                    mean_sd(&start).0,
                    max(s.iter().map(|s| s.peak_rise)),
                    max(all.iter().filter_map(|r| {
                        let b = &r.breaths;
                        Some(b.get(1)?.peak_pressure - b.first()?.peak_pressure)
                    })),
                    max(s.iter().map(|s| s.peep_err)),
                    mean_sd(&s.iter().map(|s| s.rms).collect::<Vec<_>>()).0,
                    if ctrl == Ctrl::Adaptive {
                        format!("{} / {}", o.swapped, refused(&o))
                    } else {
                        "–".into()
                    },
                );
            }
        }
    }
    println!();
}
