//! The open-loop optimum of the demo's setpoint steps beside the controllers' IAE: the least
//! IAE any duty sequence reaches on the noise-free plant under the firmware's duty limits and
//! rate limit, with the RST's preview and an overshoot cap (see `pump_sim::baseline::optimal`).
//!
//! ```text
//! cargo run --release -p pump-sim --bin step-optimum -- --all
//! cargo run --release -p pump-sim --bin step-optimum -- --plant sluggish --lung stiff --seeds 1
//! ```
//!
//! The computations live in `pump_sim::baseline`; this binary only parses flags and prints.

use std::collections::HashMap;
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use pump_sim::baseline::optimal::demo_steps;
use pump_sim::baseline::table::{lung_label, run_plant, Cases, PlantSummary, IAE_RATIO_TARGET};
use pump_sim::baseline::Controller;
use pump_sim::PlantArgs;
use ridge_pump_firmware::setpoint::DEMO_STEPS;

/// Prints, per plant, the least step IAE of any duty sequence and the controllers' IAE on
/// the demo's steps (markdown).
#[derive(Debug, Parser)]
#[command(name = "step-optimum")]
struct Args {
    /// Which plants and seeds (each seed's start flow and preview give the optimum's first
    /// step and lead).
    #[command(flatten)]
    cases: Cases,
    /// Overshoot cap of the optimum, percent of the step.
    #[arg(long, value_name = "PCT", default_value_t = 10.0)]
    overshoot: f64,
    /// No overshoot cap (the least IAE of any sequence whatever it overshoots).
    #[arg(long, conflicts_with = "overshoot")]
    no_cap: bool,
}

/// One plant's row: the controllers' summary and the optimum's mean IAE per step.
struct Row {
    summary: PlantSummary,
    optimum: f64,
}

fn row(plant: &PlantArgs, seeds: &[u64], cap: Option<f64>) -> Result<Row, String> {
    let summary = run_plant(plant, seeds).map_err(|e| e.to_string())?;
    // Steps 2–4 start from the programmed levels: the same for every seed with the same
    // preview; the first starts from the seed's switch-over flow.
    let mut later: HashMap<u8, Vec<f64>> = HashMap::new();
    let mut iae = Vec::new();
    for (&(preview, _), &start) in summary.previews.iter().zip(&summary.starts) {
        let lead = usize::from(preview);
        let known = later.contains_key(&preview);
        let count = if known { 1 } else { DEMO_STEPS.len() };
        let steps = demo_steps(plant, start, lead, cap, count)?;
        iae.extend(steps.first().map(|o| o.iae));
        let rest = later
            .entry(preview)
            .or_insert_with(|| steps.iter().skip(1).map(|o| o.iae).collect());
        iae.extend(rest.iter().copied());
    }
    let optimum = iae.iter().sum::<f64>() / iae.len().max(1) as f64;
    Ok(Row { summary, optimum })
}

fn main() -> ExitCode {
    let args = Args::parse();
    let start = Instant::now();
    let plants = args.cases.plants();
    let seeds = args.cases.seeds();
    let cap = (!args.no_cap).then_some(args.overshoot / 100.0);
    // Two workers: the machine's two cores.
    let rows: Vec<Result<Row, String>> = std::thread::scope(|s| {
        let (a, b): (Vec<_>, Vec<_>) = plants.iter().enumerate().partition(|(i, _)| i % 2 == 0);
        let a_index: Vec<usize> = a.iter().map(|(i, _)| *i).collect();
        let run = |part: Vec<(usize, &PlantArgs)>| {
            part.into_iter()
                .map(|(i, p)| (i, row(p, &seeds, cap)))
                .collect::<Vec<_>>()
        };
        let ha = s.spawn(move || run(a));
        let rb = run(b);
        // A worker that panicked loses its rows: each is reported as failed, none dropped.
        let mut all = ha.join().unwrap_or_else(|_| {
            a_index
                .into_iter()
                .map(|i| (i, Err("worker panicked".to_owned())))
                .collect()
        });
        all.extend(rb);
        all.sort_by_key(|(i, _)| *i);
        all.into_iter().map(|(_, r)| r).collect()
    });
    let cap_text = cap.map_or_else(
        || "no cap".to_owned(),
        |c| format!("overshoot ≤ {:.0} %", 100.0 * c),
    );
    println!(
        "| plant | lung | RST preview (ticks) | optimum ({cap_text}) | RST noise-free | RST | ZN PID | \
         ZN PID × {IAE_RATIO_TARGET} | RST / optimum | optimum ≤ ZN × {IAE_RATIO_TARGET} |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---|");
    let mut failed = false;
    for (p, r) in plants.iter().zip(rows) {
        match r {
            Ok(r) => {
                let rst = &r.summary.rows[Controller::Rst.index()];
                let zn = &r.summary.rows[Controller::ZnPid.index()];
                // The issue's target for the controllers' IAE on this plant.
                let target = zn.iae * IAE_RATIO_TARGET;
                let previews: Vec<String> =
                    r.summary.previews.iter().map(|p| p.0.to_string()).collect();
                println!(
                    "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2} | {} |",
                    p.plant.name(),
                    lung_label(p),
                    previews.join("/"),
                    r.optimum,
                    rst.iae_clean,
                    rst.iae,
                    zn.iae,
                    target,
                    rst.iae / r.optimum,
                    if r.optimum <= target { "yes" } else { "**no**" }
                );
            }
            Err(e) => {
                eprintln!("step-optimum: {}: {e}", p.describe());
                failed = true;
            }
        }
    }
    println!();
    println!(
        "IAE per step, slm·s, mean over the 4 steps and seeds {}..={} (RST and ZN PID: with sensor noise, true flow, as in the comparison). Run time {:.0} s.",
        seeds.first().copied().unwrap_or(1),
        seeds.last().copied().unwrap_or(1),
        start.elapsed().as_secs_f64()
    );
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
