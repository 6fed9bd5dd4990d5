//! The breath-plant study's tables: the re-estimates of each candidate, its adaptive loop on
//! the lung changes and on the ISO rows.

use crate::study::{
    candidates, closed_truth, figures, runs, under, why, Candidate, Figures, Outcome, Run, Runs,
    KEEP_RADIUS,
};
use pump_sim::iso::IsoRow;
use pump_sim::reid;
use pump_sim::vent_bench::{
    change_cell, change_verdict, outcomes, row1_lung, row_lung, score, BreathPlant, Cell, ChangeAt,
    Ctrl, NamedChange, SwapWhen, CHANGES, CHANGE_BREATH,
};
use ridge_pump_firmware::selfid::preview_ticks;
use ridge_pump_firmware::setpoint::Shape;

/// Breaths of the estimates table's runs (the change in breath [`CHANGE_BREATH`]).
const ESTIMATE_RUN: u32 = 20;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn mean(v: impl IntoIterator<Item = f64>) -> f64 {
    let (s, n) = v
        .into_iter()
        .fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

fn max(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(f64::NEG_INFINITY, f64::max)
}

/// Prints the re-estimates of every candidate on a frozen loop (the adaptive loop never
/// swapping: every candidate sees the same data), seeds 1 to `seeds`.
pub fn estimates(runs_of: &Runs) {
    let seeds = runs_of.seeds;
    let adult = (50.0, 5.0);
    let ups = runs_of.power_ups(&row1_lung(adult.0, adult.1));
    let Some(first) = ups.first() else {
        return;
    };
    let table = first.switchover.map.table();
    let s = first.switchover.model.structure();
    println!(
        "## Re-estimates of the breath's plant (frozen loop: the power-up controller, trim on; \
         row 1's breath; power-up into C 50 R 5, the lung changed at breath {CHANGE_BREATH}'s \
         boundary; {ESTIMATE_RUN} breaths), seeds 1-{seeds}\n"
    );
    let preview = reid::design(&first.switchover.model)
        .map_or(0, |d| preview_ticks(d.mean_delay(&first.switchover.model)));
    println!(
        "Power-up structure (seed 1): p {}, q {}, d {}, {:?}; the controller's preview \
         {preview} ticks (the duty's rise leads the valve's closing by as much). Windows: the adult lung (held out \
         before the change), the new lung from its 3rd breath. Step: the model's unit step after \
         50 / 100 ticks (slm per slm of the map); truth: the closed-valve step from the 5 slm bias \
         flow at the duty of 35 slm (seed 1's map). Design: at the power-up design's τ, every \
         model (the firmware's `why=` words).\n",
        s.p,
        s.q,
        s.d,
        first.switchover.model.offset()
    );
    println!(
        "| lung | candidate | estimates | accepted / fit / gain / unstable / other | step at 50 / 100 (truth) | static gain min-max | held-out fit %, estimate / running (median) | window's `v` RMS (median, slm) | design: ok / slow-poles / singular / margin / poles (accepted and designed) | the same keeping poles within {KEEP_RADIUS} |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let scenarios = [(10.0, 5.0), (50.0, 50.0), (10.0, 50.0)];
    let cands = candidates();
    for (k, &to) in scenarios.iter().enumerate() {
        let truth_new = closed_truth(&table, to);
        for c in &cands {
            let cell = Cell {
                breaths: ESTIMATE_RUN,
                ..under(
                    change_cell(adult, to, ChangeAt::Boundary, Ctrl::Adaptive),
                    Some(c.plant),
                    SwapWhen::Never,
                    true,
                )
            };
            let all = runs(&ups, &cell);
            let figs = |lo: u32, hi: u32| -> Vec<Figures> {
                all.iter()
                    .flat_map(|(r, _)| {
                        let tau = r.designs.first().map_or(f32::NAN, |d| d.1);
                        r.estimates
                            .iter()
                            .filter(move |e| e.breath >= lo && e.breath <= hi)
                            .map(move |e| figures(e, tau))
                    })
                    .filter(|f| f.outcome != Outcome::NoModel)
                    .collect()
            };
            // The adult lung's estimates are the same in every scenario: printed once.
            if k == 0 {
                let truth = closed_truth(&table, adult);
                row_of("C 50 R 5", c, &figs(1, CHANGE_BREATH - 3), &truth);
            }
            let name = format!("C {} R {}", to.0, to.1);
            row_of(&name, c, &figs(CHANGE_BREATH + 2, u32::MAX), &truth_new);
        }
    }
    println!();
}

/// One row of the estimates table.
fn row_of(lung: &str, c: &Candidate, f: &[Figures], truth: &[f64]) {
    let count = |o: Outcome| f.iter().filter(|x| x.outcome == o).count();
    let steps = (
        mean(f.iter().map(|x| x.step.0).filter(|v| v.is_finite())),
        mean(f.iter().map(|x| x.step.1).filter(|v| v.is_finite())),
    );
    let gains: Vec<f64> = f.iter().map(|x| x.gain).filter(|v| !v.is_nan()).collect();
    let fits: Vec<(f64, f64)> = f.iter().filter_map(|x| x.fit).collect();
    let verdicts = |kept: bool| {
        let of = |x: &Figures| if kept { x.design_kept } else { x.design };
        let n = |w: &str| {
            f.iter()
                .filter(|x| of(x).as_ref().is_some_and(|d| why(d) == w))
                .count()
        };
        let designed = f
            .iter()
            .filter(|x| x.outcome == Outcome::Accepted && of(x) == Some(Ok(())))
            .count();
        format!(
            "{} / {} / {} / {} / {} ({designed})",
            n("ok"),
            n("slow-poles"),
            n("singular"),
            n("margin"),
            n("poles")
        )
    };
    println!(
        "| {lung} | {} | {} | {} / {} / {} / {} / {} | {:.3} / {:.3} ({:.3} / {:.3}) | {:.2} to {:.2} | {} | {:.1} | {} | {} |",
        c.name,
        f.len(),
        count(Outcome::Accepted),
        count(Outcome::Fit),
        count(Outcome::Gain),
        count(Outcome::Unstable),
        count(Outcome::Other),
        steps.0,
        steps.1,
        truth.get(49).copied().unwrap_or(f64::NAN),
        truth.get(99).copied().unwrap_or(f64::NAN),
        gains.iter().copied().fold(f64::INFINITY, f64::min),
        gains.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        if fits.is_empty() {
            "–".to_string()
        } else {
            format!(
                "{:.0} / {:.0}",
                median(fits.iter().map(|v| v.0).collect()),
                median(fits.iter().map(|v| v.1).collect())
            )
        },
        median(f.iter().map(|x| x.v_rms).collect()),
        verdicts(false),
        verdicts(true),
    );
}

/// The candidates of the loop tables: the frozen power-up design first (`None`), then each
/// candidate's adaptive loop.
fn loops() -> Vec<(&'static str, Option<BreathPlant>)> {
    let mut v = vec![("frozen power-up design", None)];
    v.extend(candidates().into_iter().map(|c| (c.name, Some(c.plant))));
    v
}

/// Prints every candidate's adaptive loop (swapping `when`, re-designed at the power-up
/// design's speed) and the frozen design on the 12 lung changes, trim on and off.
pub fn changes(runs_of: &Runs, when: SwapWhen) {
    let seeds = runs_of.seeds;
    println!(
        "## The 12 lung changes (row 1's breath, change in breath {CHANGE_BREATH}, at the boundary \
         and mid-inspiration), adaptive loops swapping {when:?} at the power-up design's τ, \
         seeds 1-{seeds}\n"
    );
    println!(
        "Changes missing a target in any seed (15 % by the 2nd breath, 5 % by the 4th, a breath \
         outside 35 %); worst breath; peak pressure max and its largest rise over the previous \
         breath from the change's 2nd breath; inspiration's tracking RMS (slm, the true flow \
         against the program) from the change's 3rd breath, all changes and the three to C 10; \
         mean |volume error| from the change's 4th breath; re-estimates.\n"
    );
    println!(
        "| loop | trim | missed 15 % / 5 % / 35 % | worst breath (%) | peak max (cmH₂O) | peak rise max (cmH₂O) | insp. RMS, all / to C 10 | mean \\|error\\| from 4th (%) | swaps / held / refused: fit, model, other, design |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let ups: Vec<_> = CHANGES
        .iter()
        .map(|c| runs_of.power_ups(&row1_lung(c.from.0, c.from.1)))
        .collect();
    for (name, plant) in loops() {
        for trim in [true, false] {
            let (mut m15, mut m5, mut m35) = (0, 0, 0);
            let (mut worst, mut peak, mut rise) = (0.0f64, 0.0f64, f64::NEG_INFINITY);
            let (mut rms_all, mut rms_c10, mut err) = (Vec::new(), Vec::new(), Vec::new());
            let mut est = Vec::new();
            for (&NamedChange { from, to, .. }, ups) in CHANGES.iter().zip(&ups) {
                for at in [ChangeAt::Boundary, ChangeAt::Mid] {
                    let cell = under(change_cell(from, to, at, Ctrl::Adaptive), plant, when, trim);
                    let all: Vec<Run> = runs(ups, &cell);
                    let v: Vec<_> = all
                        .iter()
                        .map(|(r, _)| change_verdict(r, CHANGE_BREATH))
                        .collect();
                    m15 += usize::from(!v.iter().all(|v| v.meets15()));
                    m5 += usize::from(!v.iter().all(|v| v.meets5()));
                    m35 += usize::from(!v.iter().all(|v| v.meets35()));
                    worst = worst.max(max(v.iter().map(|v| v.worst_pct)));
                    peak = peak.max(max(v.iter().map(|v| v.peak_pressure)));
                    for (r, insp) in &all {
                        rise = rise.max(score(r, CHANGE_BREATH + 1).peak_rise);
                        let after = insp.iter().skip(CHANGE_BREATH as usize + 1).copied();
                        rms_all.extend(after.clone());
                        if to.0 == 10.0 {
                            rms_c10.extend(after);
                        }
                        err.extend(
                            r.breaths
                                .iter()
                                .filter(|b| b.number >= CHANGE_BREATH + 3)
                                .map(|b| b.error_pct().abs()),
                        );
                        est.extend(r.estimates.iter().cloned());
                    }
                }
            }
            let o = outcomes(est.iter());
            println!(
                "| {name} | {} | {m15} / {m5} / {m35} | {worst:.1} | {peak:.1} | {rise:+.1} | {:.2} / {:.2} | {:.2} | {} |",
                if trim { "on" } else { "off" },
                mean(rms_all),
                mean(rms_c10),
                mean(err),
                if plant.is_some() {
                    format!(
                        "{} / {} / {}, {}, {}, {}",
                        o.swapped, o.held, o.fit, o.model, o.other, o.design_refused
                    )
                } else {
                    "–".into()
                }
            );
        }
    }
    println!();
}

/// Prints every candidate's adaptive loop and the frozen design on `rows` (square, `breaths`
/// breaths, no change), trim on and off.
pub fn rows(rows: &[IsoRow], breaths: u32, runs_of: &Runs, when: SwapWhen) {
    let seeds = runs_of.seeds;
    println!(
        "## ISO rows (square, {breaths} breaths, no change), adaptive loops swapping {when:?} at \
         the power-up design's τ, seeds 1-{seeds}\n"
    );
    println!(
        "Per row: worst \\|error\\| of breaths ≥ 3 (%), seeds within ±(4 mL + 5 %) from breath 3, \
         inspiration's tracking RMS from breath 3 (slm), swaps.\n"
    );
    println!(
        "| loop | trim | {} |",
        rows.iter()
            .map(|r| format!("row {}", r.row))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!("|---|---|{}", "---|".repeat(rows.len()));
    let ups: Vec<_> = rows
        .iter()
        .map(|r| {
            let l = row_lung(r, r.peep);
            runs_of.power_ups(&l)
        })
        .collect();
    for (name, plant) in loops() {
        for trim in [true, false] {
            let cells: Vec<String> = rows
                .iter()
                .zip(&ups)
                .map(|(row, ups)| {
                    let cell = under(
                        Cell {
                            breaths,
                            ..Cell::new(*row, Shape::Square, Ctrl::Adaptive)
                        },
                        plant,
                        when,
                        trim,
                    );
                    let all = runs(ups, &cell);
                    let s: Vec<_> = all.iter().map(|(r, _)| score(r, 3)).collect();
                    let rms = mean(
                        all.iter()
                            .flat_map(|(_, insp)| insp.iter().skip(2).copied()),
                    );
                    let swaps: usize = all.iter().map(|(r, _)| r.swaps()).sum();
                    format!(
                        "{:.1}, {}/{}, {rms:.2}, {swaps}",
                        max(s.iter().map(|s| s.worst_pct)),
                        s.iter().filter(|s| s.pass5).count(),
                        s.len(),
                    )
                })
                .collect();
            println!(
                "| {name} | {} | {} |",
                if trim { "on" } else { "off" },
                cells.join(" | ")
            );
        }
    }
    println!();
}
