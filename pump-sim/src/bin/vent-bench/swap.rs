//! The swap-rule tables: the adaptive controller swapping a re-estimate in only below a
//! held-out fit, on volume breaths and on the re-identification study's demo breaths.

use crate::run::{max, power_ups_on, refused, runs};
use pump_sim::iso::ISO_ROWS;
use pump_sim::reid::{self, breaths_in, mean_sd, Mode, Study};
use pump_sim::vent_bench::row1_lung;
use pump_sim::vent_bench::{outcomes, Cell, ChangeAt, Ctrl, LungChange};
use ridge_pump_firmware::setpoint::Shape;

/// The swap rule's thresholds: always, then percent.
const SWAP_RULES: [Option<f64>; 5] = [None, Some(90.0), Some(85.0), Some(80.0), Some(70.0)];

/// The swap rule `x`'s name: `always`, or the threshold.
fn rule_name(x: Option<f64>) -> String {
    x.map_or("always".into(), |x| format!("below {x} %"))
}

/// One table cell of the swap-rule tables: mean tracking RMS (slm), mean |volume error| and
/// the worst (percent) of `breaths` (RMS, volume error in percent).
fn phase_cell(breaths: &[(f64, f64)]) -> String {
    let rms: Vec<f64> = breaths.iter().map(|b| b.0).collect();
    let vol: Vec<f64> = breaths.iter().map(|b| b.1.abs()).collect();
    format!(
        "{:.2} / {:.1} ({:.1})",
        mean_sd(&rms).0,
        mean_sd(&vol).0,
        max(vol.iter().copied())
    )
}

/// The header of a swap-rule table with the phases `labels`.
fn swap_header(labels: &[&str]) {
    println!(
        "Each phase: tracking RMS (slm) / mean \\|volume error\\| (worst) (%).\n\n\
         | swap when the running model's held-out fit is | {} | swaps (before the change) / held by the rule / refused: fit, model, other, design |",
        labels.join(" | ")
    );
    println!("|---|{}---|", "---|".repeat(labels.len()));
}

/// Counts of `estimates`: swaps, swaps at a breath before `change` (from 0), held by the
/// rule, refused (by the hold-out's fit, the model check, otherwise; the design).
fn swap_counts<'a>(
    estimates: impl Iterator<Item = &'a reid::Estimate> + Clone,
    change: u32,
) -> String {
    let o = outcomes(estimates.clone());
    let early = estimates
        .filter(|e| e.swapped_at.is_some_and(|b| b < change))
        .count();
    format!("{} ({early}) / {} / {}", o.swapped, o.held, refused(&o))
}

/// The held-out free-run fits (running model, candidate; percent) of the re-estimates
/// snapshot at least two breaths before `change` (breath from 0; a hold-out runs into the
/// breath after its fit) while the power-up model still ran (up to the first swap).
fn power_up_fits(estimates: &[reid::Estimate], change: u32) -> Vec<(f32, f32)> {
    let mut out = Vec::new();
    for e in estimates.iter().filter(|e| e.breath + 2 < change) {
        match e.verdict {
            Some(Ok((c, r))) => out.push((r, c)),
            Some(Err(ridge_core::reid::Rejection::Fit { candidate, running })) => {
                out.push((running, candidate))
            }
            _ => {}
        }
        if e.swapped_at.is_some() {
            break;
        }
    }
    out
}

/// `min…max` of `v`.
fn range(v: impl Iterator<Item = f32> + Clone) -> String {
    let lo = v.clone().fold(f32::INFINITY, f32::min);
    let hi = v.fold(f32::NEG_INFINITY, f32::max);
    format!("{lo:.0}…{hi:.0}")
}

/// A swap-rule table's phases: name, breaths from (inclusive) to (exclusive).
type Phase = (&'static str, u32, u32);

/// Prints a swap-rule table over `phases` and the power-up fits line under it. `run(x,
/// adaptive)`: the runs of the swap rule `x` (`adaptive` false: the frozen design, for
/// reference); `breaths(r, from, to)`: run `r`'s breaths from `from` to before `to` as
/// (tracking RMS, volume error in percent); `estimates(r)`: its re-estimates. The change is
/// at breath 10 from 0.
fn swap_table<R>(
    phases: &[Phase],
    run: impl Fn(Option<f64>, bool) -> Vec<R>,
    breaths: impl Fn(&R, u32, u32) -> Vec<(f64, f64)>,
    estimates: impl Fn(&R) -> &[reid::Estimate],
) {
    swap_header(&phases.iter().map(|p| p.0).collect::<Vec<_>>());
    let mut fits = Vec::new();
    for (x, adaptive) in SWAP_RULES.iter().map(|&x| (x, true)).chain([(None, false)]) {
        let all = run(x, adaptive);
        let cells: Vec<String> = phases
            .iter()
            .map(|&(_, from, to)| {
                let b: Vec<(f64, f64)> = all.iter().flat_map(|r| breaths(r, from, to)).collect();
                phase_cell(&b)
            })
            .collect();
        let (name, counts) = if adaptive {
            (
                rule_name(x),
                swap_counts(all.iter().flat_map(|r| estimates(r).iter()), 10),
            )
        } else {
            ("(frozen, for reference)".to_string(), "–".to_string())
        };
        println!("| {name} | {} | {counts} |", cells.join(" | "));
        if x.is_none() && adaptive {
            fits = all
                .iter()
                .flat_map(|r| power_up_fits(estimates(r), 10))
                .collect();
        }
    }
    println!(
        "\nOn the adult lung, until the first swap: the power-up model's own held-out fit {} %, \
         the re-estimates' {} % ({} verdicts).\n",
        range(fits.iter().map(|f| f.0)),
        range(fits.iter().map(|f| f.1)),
        fits.len()
    );
}

/// Prints the swap-rule tables, seeds 1 to `seeds`.
pub fn print(seeds: u64) {
    let row = ISO_ROWS[0];
    let adult = row1_lung(50.0, 5.0);
    let stiff = row1_lung(10.0, 50.0);
    println!(
        "## Swap rule, volume breaths: adaptive, row 1's breath (square, trim on), C 10 R 50 from \
         breath 11, row 1's lung again from breath 31, 50 breaths, seeds 1-{seeds}\n"
    );
    let ups = power_ups_on((50.0, 5.0), seeds);
    swap_table(
        &[
            ("adult, breaths 3-10", 3, 11),
            ("C10 R50, breaths 11-14", 11, 15),
            ("C10 R50, breaths 21-30", 21, 31),
            ("adult again, breaths 31-34", 31, 35),
            ("adult again, breaths 41-50", 41, 51),
        ],
        |x, adaptive| {
            let cell = Cell {
                breaths: 50,
                changes: vec![
                    LungChange {
                        breath: 11,
                        at: ChangeAt::Boundary,
                        lung: stiff.clone(),
                    },
                    LungChange {
                        breath: 31,
                        at: ChangeAt::Boundary,
                        lung: adult.clone(),
                    },
                ],
                swap_below_fit: x,
                ..Cell::new(
                    row,
                    Shape::Square,
                    if adaptive {
                        Ctrl::Adaptive
                    } else {
                        Ctrl::Frozen
                    },
                )
            };
            runs(&ups, &cell)
        },
        |r, from, to| {
            r.breaths
                .iter()
                .filter(|b| b.number >= from && b.number < to)
                .map(|b| (b.rms, b.error_pct()))
                .collect()
        },
        |r| &r.estimates,
    );
    println!(
        "## Swap rule, the study's demo breaths (`reid-study`'s scenario: square 10 → 60 slm, \
         adult lung → C 10 R 50 at breath 10 → adult at breath 30, breaths from 0), seeds 1-{seeds}\n"
    );
    swap_table(
        &[
            ("adult, breaths 1-9", 1, 10),
            ("C10 R50, breaths 10-13", 10, 14),
            ("C10 R50, breaths 20-29", 20, 30),
            ("adult again, breaths 30-33", 30, 34),
            ("adult again, breaths 40-49", 40, 50),
        ],
        |x, adaptive| {
            (1..=seeds)
                .filter_map(|seed| {
                    reid::run(&Study {
                        swap_below_fit: x,
                        mode: if adaptive { Mode::Adapt } else { Mode::Frozen },
                        ..Study::lung_change(seed)
                    })
                    .map_err(|e| eprintln!("seed {seed}: {e}"))
                    .ok()
                })
                .collect()
        },
        |r, from, to| {
            breaths_in(r, from, to)
                .into_iter()
                .map(|b| (b.rms, b.volume_error_pct()))
                .collect()
        },
        |r| &r.estimates,
    );
}
