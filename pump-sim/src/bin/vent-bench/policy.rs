//! The adaptive controller's candidate swap policies (`--table policy`) on the lung changes
//! and on the ISO rows.

use crate::run::{max, power_ups, power_ups_on, refused, runs};
use pump_sim::iso::IsoRow;
use pump_sim::vent_bench::{
    change_cell, change_verdict, outcomes, row_lung, score, Cell, ChangeAt, Ctrl, NamedChange,
    Policy, PowerUp, SwapWhen, CHANGES, CHANGE_BREATH, CHANGE_RUN,
};
use ridge_pump_firmware::setpoint::Shape;

/// A candidate policy of the policy table: name, trim on, the policy; `None`: the frozen
/// design (for reference).
type Candidate = (String, bool, Option<Policy>);

/// The candidates of `--table policy`: the diagnosis's knobs, then the firmware's options.
fn candidates(rms_above: f32) -> Vec<Candidate> {
    let p = Policy::ALWAYS;
    vec![
        ("(iv) swap always (today)".to_string(), true, Some(p)),
        ("swap always, trim off".to_string(), false, Some(p)),
        ("frozen, trim off".to_string(), false, None),
        (
            "swap always, trim restarted at each swap".to_string(),
            true,
            Some(Policy {
                trim_reset: true,
                ..p
            }),
        ),
        (
            "swap always, k = 1".to_string(),
            true,
            Some(Policy { shift: 1, ..p }),
        ),
        (
            "swap always, k = 3".to_string(),
            true,
            Some(Policy { shift: 3, ..p }),
        ),
        (
            "swap always after 2 breaths of the new lung".to_string(),
            true,
            Some(Policy { settle: 2, ..p }),
        ),
        (
            "swap always after 4 breaths of the new lung".to_string(),
            true,
            Some(Policy { settle: 4, ..p }),
        ),
        (
            "(iii) swap always, power-up speed".to_string(),
            true,
            Some(Policy {
                fixed_speed: true,
                ..p
            }),
        ),
        (
            "(iii) swap always, power-up speed, trim off".to_string(),
            false,
            Some(Policy {
                fixed_speed: true,
                ..p
            }),
        ),
        (
            "(ii) swap on the volume alarm".to_string(),
            true,
            Some(Policy {
                when: SwapWhen::VolumeAlarm,
                ..p
            }),
        ),
        (
            "(ii) swap on the volume alarm, power-up speed".to_string(),
            true,
            Some(Policy {
                when: SwapWhen::VolumeAlarm,
                fixed_speed: true,
                ..p
            }),
        ),
        (
            format!("(ii) swap when the last breath's tracking RMS is above {rms_above} slm"),
            true,
            Some(Policy {
                when: SwapWhen::RmsAbove(rms_above),
                ..p
            }),
        ),
        (
            "(i) monitor only (never swap)".to_string(),
            true,
            Some(Policy {
                when: SwapWhen::Never,
                ..p
            }),
        ),
        ("frozen (for reference)".to_string(), true, None),
    ]
}

/// `cell` under the candidate's trim and policy (`None`: the frozen design).
fn under(cell: Cell, trim: bool, policy: Option<Policy>) -> Cell {
    Cell {
        trim,
        policy: policy.unwrap_or(Policy::ALWAYS),
        ctrl: if policy.is_some() {
            Ctrl::Adaptive
        } else {
            Ctrl::Frozen
        },
        ..cell
    }
}

/// Prints the candidate policies (`rms_above`: the RMS policy's threshold, slm) on the 12 lung
/// changes, then on `rows` (square, `breaths` breaths, no change); seeds 1 to `seeds`.
pub fn print(rows: &[IsoRow], breaths: u32, seeds: u64, rms_above: f32) {
    let cands = candidates(rms_above);
    println!(
        "## Swap policies: the 12 lung changes of the lung-change table (row 1's breath, change \
         in breath {CHANGE_BREATH} of {CHANGE_RUN}), seeds 1-{seeds}\n"
    );
    println!(
        "Changes missing a target in any seed: back within ±(4 mL + 15 %) by the 2nd breath, \
         ±(4 mL + 5 %) by the 4th, no breath outside ±35 %.\n"
    );
    println!(
        "| policy | missed 15 % by 2nd | missed 5 % by 4th | a breath outside 35 % | worst breath (%) | peak pressure max (cmH₂O) | swaps / held / refused: fit, model, other, design | designs swapped in: τ / power-up τ, min-median-max (above 1.4) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    // Power-ups once per first lung.
    let ups: Vec<Vec<PowerUp>> = CHANGES
        .iter()
        .map(|c| power_ups_on(c.from, seeds))
        .collect();
    for (name, trim, policy) in &cands {
        let (mut m15, mut m5, mut m35, mut worst, mut peak) = (0, 0, 0, 0.0f64, 0.0f64);
        let mut est = Vec::new();
        let mut ratios: Vec<f64> = Vec::new();
        for (NamedChange { from, to, .. }, ups) in CHANGES.iter().zip(&ups) {
            for at in [ChangeAt::Boundary, ChangeAt::Mid] {
                let cell = under(change_cell(*from, *to, at, Ctrl::Adaptive), *trim, *policy);
                let all = runs(ups, &cell);
                let v: Vec<_> = all
                    .iter()
                    .map(|r| change_verdict(r, CHANGE_BREATH))
                    .collect();
                m15 += usize::from(!v.iter().all(|v| v.meets15()));
                m5 += usize::from(!v.iter().all(|v| v.meets5()));
                m35 += usize::from(!v.iter().all(|v| v.meets35()));
                worst = worst.max(max(v.iter().map(|v| v.worst_pct)));
                peak = peak.max(max(v.iter().map(|v| v.peak_pressure)));
                for r in &all {
                    if let Some(&(_, t0)) = r.designs.first() {
                        ratios.extend(r.designs.iter().skip(1).map(|d| f64::from(d.1 / t0)));
                    }
                }
                est.extend(all.into_iter().flat_map(|r| r.estimates));
            }
        }
        let o = outcomes(est.iter());
        ratios.sort_by(f64::total_cmp);
        let spread = match (ratios.first(), ratios.get(ratios.len() / 2), ratios.last()) {
            (Some(lo), Some(mid), Some(hi)) => format!(
                "{lo:.2}-{mid:.2}-{hi:.2} ({})",
                ratios.iter().filter(|&&r| r > 1.4).count()
            ),
            _ => "–".into(),
        };
        println!(
            "| {name} | {m15} | {m5} | {m35} | {worst:.1} | {peak:.1} | {} | {spread} |",
            if policy.is_some() {
                format!("{} / {} / {}", o.swapped, o.held, refused(&o))
            } else {
                "–".into()
            }
        );
    }
    println!();
    println!(
        "## Swap policies on rows 1-8 (square, {} breaths, no change), seeds 1-{}\n",
        breaths, seeds
    );
    println!(
        "Per row: worst \\|error\\| of breaths ≥ 3 (%), seeds within ±(4 mL + 5 %) from breath 3; swaps.\n"
    );
    println!(
        "| policy | {} |",
        rows.iter()
            .map(|r| format!("row {}", r.row))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!("|---|{}", "---|".repeat(rows.len()));
    let ups: Vec<Vec<PowerUp>> = rows
        .iter()
        .map(|r| power_ups(&row_lung(r, 0.0), seeds))
        .collect();
    for (name, trim, policy) in cands.iter().filter(|c| c.1) {
        let cells: Vec<String> = rows
            .iter()
            .zip(&ups)
            .map(|(row, ups)| {
                let cell = under(
                    Cell {
                        breaths,
                        ..Cell::new(*row, Shape::Square, Ctrl::Adaptive)
                    },
                    *trim,
                    *policy,
                );
                let all = runs(ups, &cell);
                let s: Vec<_> = all.iter().map(|r| score(r, 3)).collect();
                let swaps: usize = all.iter().map(|r| r.swaps()).sum();
                format!(
                    "{:.1}, {}/{}, {}",
                    max(s.iter().map(|s| s.worst_pct)),
                    s.iter().filter(|s| s.pass5).count(),
                    s.len(),
                    swaps
                )
            })
            .collect();
        println!("| {name} | {} |", cells.join(" | "));
    }
    println!();
}
