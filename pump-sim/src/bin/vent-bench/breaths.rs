//! One lung change's breaths under every controller, one seed (`--table breaths`), and the
//! adaptive run's re-estimates against the truth.

use crate::run::{power_ups_on, refused, Knobs};
use crate::truth::{truth_of, Truth, INSPIRATION_FLOW};
use pump_sim::reid;
use pump_sim::vent_bench::{
    change_cell, outcomes, run_cell, CellRun, ChangeAt, Ctrl, NamedChange, PowerUp, CHANGE_BREATH,
    CHANGE_RUN,
};

/// Prints the lung change `change`'s breaths (`at` in its breath) under every controller, the
/// adaptive one with `knobs`, from the power-up of `seed`; then the adaptive run's
/// re-estimates.
pub fn print(change: &NamedChange, at: ChangeAt, seed: u64, knobs: Knobs) {
    let NamedChange { name, from, to } = *change;
    let ups = power_ups_on(from, seed);
    let Some(p) = ups.iter().find(|p| p.seed == seed) else {
        return;
    };
    println!("## {name} in breath {CHANGE_BREATH} ({at:?}), row 1's breath, seed {seed}\n");
    println!("Per controller: delivered volume mL (error %) / programmed volume mL / peak pressure cmH₂O.\n");
    println!("| breath | {} |", Ctrl::ALL.map(Ctrl::name).join(" | "));
    println!("|---|{}", "---|".repeat(Ctrl::ALL.len()));
    let all: Vec<CellRun> = Ctrl::ALL
        .iter()
        .filter_map(|&ctrl| {
            run_cell(p, &knobs.apply(change_cell(from, to, at, ctrl)))
                .map_err(|e| eprintln!("{}: {e}", ctrl.name()))
                .ok()
        })
        .collect();
    for n in 1..=CHANGE_RUN {
        let cells: Vec<String> = all
            .iter()
            .map(|r| match r.breaths.iter().find(|b| b.number == n) {
                Some(b) => format!(
                    "{:.0} ({:+.1}) / {:.0} / {:.1}",
                    b.delivered_ml,
                    b.error_pct(),
                    b.command_ml,
                    b.peak_pressure
                ),
                None => "–".into(),
            })
            .collect();
        println!("| {n} | {} |", cells.join(" | "));
    }
    if let Some(r) = all.first() {
        let swaps: Vec<String> = r
            .estimates
            .iter()
            .filter_map(|e| e.swapped_at.map(|b| (b + 1).to_string()))
            .collect();
        let o = outcomes(r.estimates.iter());
        println!(
            "\nAdaptive: new controllers from the start of breaths {}; refused: fit, model, other, design {}.\n",
            if swaps.is_empty() { "none".to_string() } else { swaps.join(", ") },
            refused(&o)
        );
        estimates_table(p, r, (from, to));
    }
}

/// The adaptive run `r`'s re-estimates against the truth (`--table breaths`).
fn estimates_table(p: &PowerUp, r: &CellRun, (from, to): ((f64, f64), (f64, f64))) {
    let table = p.switchover.map.table();
    let (before, after) = (truth_of(&table, from), truth_of(&table, to));
    let (g0, r0, g1, r1) = (before.gain, before.rise, after.gain, after.rise);
    let closed = |t: &Truth| {
        let peak = t.closed.iter().copied().fold(0.0, f64::max);
        let at_peak = t.closed.iter().position(|&v| v >= peak).unwrap_or(0);
        format!(
            "peak {peak:.3} at tick {at_peak}, {:.3} at 50, {:.3} at 100",
            t.closed_after(50),
            t.closed_after(100)
        )
    };
    println!(
        "Truth with the valve closed from the 5 slm bias flow, the duty of {INSPIRATION_FLOW} slm \
         held (through the map): before {}; after {}.\n",
        closed(&before),
        closed(&after)
    );
    let m = &p.switchover.model;
    println!(
        "Truth at {INSPIRATION_FLOW} slm through the power-up map (valve open, PEEP 5): before \
         gain {g0:.3}, 63 % rise {r0} ticks; after {g1:.3}, {r1}. Power-up model: gain {:.3}, \
         rise {} ticks. Designs (breath from 1: τ s): {}.\n",
        m.static_gain(),
        reid::rise63(&reid::model_step(m, reid::STEP_TICKS)).unwrap_or(0),
        r.designs
            .iter()
            .map(|(b, t)| format!("{b}: {t:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("| snapshot after breath | gain | 63 % rise (ticks) | verdict (fit: estimate / running %) | swapped at |");
    println!("|---|---|---|---|---|");
    for e in &r.estimates {
        let (g, rise) = match &e.model {
            Some(Ok(m)) => (
                format!("{:.3}", m.static_gain()),
                reid::rise63(&reid::model_step(m, reid::STEP_TICKS))
                    .map_or("–".into(), |v| v.to_string()),
            ),
            _ => ("–".into(), "–".into()),
        };
        let verdict = match &e.verdict {
            Some(Ok((c, run))) => format!("accepted {c:.0} / {run:.0}"),
            Some(Err(why)) => format!("{why:?}"),
            None => "–".into(),
        };
        println!(
            "| {} | {g} | {rise} | {verdict} | {} |",
            e.breath,
            e.swapped_at.map_or("–".into(), |b| (b + 1).to_string())
        );
    }
    println!();
}
