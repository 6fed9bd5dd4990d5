//! The lung-change table: row 1's breath, the lung changed mid-run, under each controller;
//! then what the ideal lung allows under a pressure limit.

use crate::run::{max, power_ups_on, runs, Knobs};
use pump_sim::iso::ISO_ROWS;
use pump_sim::vent_bench::{
    change_cell, last_outside, pressure_limited, score, ChangeAt, Ctrl, NamedChange, CHANGES,
    CHANGE_BREATH, CHANGE_RUN,
};

/// Prints the lung-change table (seeds 1 to `seeds`, the adaptive controller with `knobs`) and
/// what the ideal lung allows.
pub fn print(seeds: u64, knobs: Knobs) {
    let row = ISO_ROWS[0];
    println!(
        "## Lung changes: row 1's breath (500 mL, 20 /min, Ti 1 s, PEEP 5, square, trim on), \
         power-up into the first lung, change in breath {CHANGE_BREATH} of {CHANGE_RUN}, seeds 1-{}\n",
        seeds
    );
    println!("Counts from the change breath (= 1): the last breath outside the band (0: none).\n");
    println!(
        "| change | at | controller | last outside ±(4 mL + 15 %) | last outside ±(4 mL + 5 %) | worst breath error (%) | peak pressure vs previous breath, max (cmH₂O) | peak pressure before → after (cmH₂O) | \\|PEEP error\\| max (cmH₂O) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for NamedChange { name, from, to } in CHANGES {
        let ups = power_ups_on(from, seeds);
        for at in [ChangeAt::Boundary, ChangeAt::Mid] {
            for ctrl in Ctrl::ALL {
                let all = runs(&ups, &knobs.apply(change_cell(from, to, at, ctrl)));
                let n15 = all
                    .iter()
                    .map(|r| last_outside(r, CHANGE_BREATH, 0.15))
                    .max();
                let n5 = all
                    .iter()
                    .map(|r| last_outside(r, CHANGE_BREATH, 0.05))
                    .max();
                let s: Vec<_> = all.iter().map(|r| score(r, CHANGE_BREATH)).collect();
                let before = max(all.iter().filter_map(|r| {
                    r.breaths
                        .iter()
                        .find(|b| b.number == CHANGE_BREATH - 1)
                        .map(|b| b.peak_pressure)
                }));
                let after = max(all.iter().filter_map(|r| {
                    r.breaths
                        .iter()
                        .filter(|b| b.number >= CHANGE_BREATH)
                        .map(|b| b.peak_pressure)
                        .reduce(f64::max)
                }));
                println!(
                    "| {name} | {} | {} | {} | {} | {:.1} | {:+.1} | {:.1} → {:.1} | {:.2} |",
                    match at {
                        ChangeAt::Boundary => "boundary",
                        ChangeAt::Mid => "mid-inspiration",
                    },
                    ctrl.name(),
                    n15.map_or("–".into(), |n| n.to_string()),
                    n5.map_or("–".into(), |n| n.to_string()),
                    max(s.iter().map(|s| s.worst_pct)),
                    max(s.iter().map(|s| s.peak_rise)),
                    before,
                    after,
                    max(s.iter().map(|s| s.peep_err)),
                );
            }
        }
    }
    println!();
    println!(
        "### What the ideal lung allows: peak pressure +5 cmH₂O a breath against volume back in the band\n"
    );
    println!(
        "Square breath of 500 mL in 1 s, PEEP 5, on the single-compartment lung (peak = PEEP + V/C + \
         R·V/Ti; no bias flow, no rise): the change breath = 1.\n"
    );
    println!("| change | elastic pressure VT/C before → after (cmH₂O) | peak before → after (cmH₂O) | change breath's volume under +5 cmH₂O (%) | breath within ±(4 mL + 15 %) | breath within ±(4 mL + 5 %) |");
    println!("|---|---|---|---|---|---|");
    for NamedChange { name, from, to } in CHANGES {
        let p = pressure_limited(row.tidal, row.ti(), row.peep, from, to, 5.0);
        println!(
            "| {name} | {:.0} → {:.0} | {:.1} → {:.1} | {:+.1} | {} | {} |",
            row.tidal / from.0,
            row.tidal / to.0,
            p.peak_before,
            p.peak_after,
            p.first_pct,
            p.within15,
            p.within5
        );
    }
    println!();
}
