//! The adaptive controller's re-estimates on the lung changes by where their window lies,
//! against the truth (`--table estimates`).

use crate::run::{power_ups_on, runs};
use crate::truth::{truth_of, INSPIRATION_FLOW};
use pump_sim::reid::{self, mean_sd};
use pump_sim::vent_bench::{change_cell, ChangeAt, Ctrl, NamedChange, CHANGES, CHANGE_BREATH};

/// Prints the adaptive (swap always) runs' re-estimates on the lung changes at the boundary
/// (seeds 1 to `seeds`), by where their window lies, against the truth; the regulation speed of the designs swapped in.
pub fn print(seeds: u64) {
    println!(
        "## Re-estimates on volume breaths (adaptive, swap always, row 1's breath, change at \
         breath {CHANGE_BREATH}'s boundary), seeds 1-{seeds}\n"
    );
    println!(
        "Model: static gain through the map (slm/slm) mean ± sd, 63 % rise (ticks) mean; truth \
         (seed 1's map): valve open at {INSPIRATION_FLOW} slm gain / rise, valve closed from \
         the bias flow after 50 / 100 ticks. τ: the swapped-in designs' regulation time constant \
         (s), min-max; the power-up design's in brackets.\n"
    );
    println!("| change | window | models (accepted) | gain | 63 % rise | truth: open gain / rise, closed at 50 / 100 | designs swapped in: τ (power-up) |");
    println!("|---|---|---|---|---|---|---|");
    for &NamedChange { name, from, to } in CHANGES.iter().take(3) {
        let ups = power_ups_on(from, seeds);
        let Some(table) = ups.first().map(|p| p.switchover.map.table()) else {
            continue;
        };
        let all = runs(
            &ups,
            &change_cell(from, to, ChangeAt::Boundary, Ctrl::Adaptive),
        );
        // Windows: the old lung only (snapshot before the change), both (1-2 breaths of the
        // new lung), the new lung from its 3rd breath (old lung weighted (3/4)^3 = 42 % or
        // less).
        let windows: [(&str, u32, u32, (f64, f64)); 3] = [
            ("old lung only", 0, CHANGE_BREATH, from),
            ("both lungs", CHANGE_BREATH, CHANGE_BREATH + 2, to),
            (
                "3+ breaths of the new lung",
                CHANGE_BREATH + 2,
                u32::MAX,
                to,
            ),
        ];
        for (wname, lo, hi, lung_now) in windows {
            // `e.breath`: the last breath (from 1) in the window.
            let es: Vec<_> = all
                .iter()
                .flat_map(|r| r.estimates.iter().map(move |e| (r, e)))
                .filter(|(_, e)| e.breath + 1 > lo && e.breath < hi)
                .collect();
            let models: Vec<_> = es
                .iter()
                .filter_map(|(_, e)| e.model.and_then(Result::ok))
                .collect();
            let gains: Vec<f64> = models.iter().map(|m| f64::from(m.static_gain())).collect();
            let rises: Vec<f64> = models
                .iter()
                .filter_map(|m| reid::rise63(&reid::model_step(m, reid::STEP_TICKS)))
                .map(|v| v as f64)
                .collect();
            let accepted = es
                .iter()
                .filter(|(_, e)| matches!(e.verdict, Some(Ok(_))))
                .count();
            let taus: Vec<f64> = es
                .iter()
                .filter_map(|(r, e)| {
                    let at = e.swapped_at? + 1;
                    r.designs.iter().find(|d| d.0 == at).map(|d| f64::from(d.1))
                })
                .collect();
            let t0: Vec<f64> = all
                .iter()
                .filter_map(|r| r.designs.first().map(|d| f64::from(d.1)))
                .collect();
            let (g, gs) = mean_sd(&gains);
            let truth = truth_of(&table, lung_now);
            let (tg, tr) = (truth.gain, truth.rise);
            let (c50, c100) = (truth.closed_after(50), truth.closed_after(100));
            let lo_hi = |v: &[f64]| {
                format!(
                    "{:.3}-{:.3}",
                    v.iter().copied().fold(f64::INFINITY, f64::min),
                    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                )
            };
            println!(
                "| {name} | {wname} | {} ({accepted}) | {g:.3} ± {gs:.3} | {:.1} | {tg:.3} / {tr}, {c50:.3} / {c100:.3} | {} ({}) |",
                models.len(),
                mean_sd(&rises).0,
                if taus.is_empty() { "none".into() } else { format!("{} s: {}", taus.len(), lo_hi(&taus)) },
                lo_hi(&t0)
            );
        }
    }
    println!();
}
