//! Compares the firmware's RST flow controller with a Ziegler–Nichols PID and a SIMC PI on the
//! simulated rig (same plant, setpoints, sensor noise and start), as a table.
//!
//! ```text
//! cargo run --release -p pump-sim --bin control-table -- --all --markdown
//! cargo run --release -p pump-sim --bin control-table -- --plant sluggish --lung stiff --seeds 5
//! cargo run --release -p pump-sim --bin control-table -- --plant small --compliance 10
//! ```
//!
//! The computations live in `pump_sim::baseline`; this binary only parses flags and prints.

use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use pump_sim::baseline::table::{markdown, plain, run_plant, Cases};

/// Runs the firmware's identification and RST controller, a Ziegler–Nichols PID and a SIMC PI
/// on the simulated rig and prints their tracking figures on the demo setpoint program.
#[derive(Debug, Parser)]
#[command(name = "control-table")]
struct Args {
    /// Which plants and seeds.
    #[command(flatten)]
    cases: Cases,
    /// Print the markdown report (tunings, comparison, targets) instead of plain text.
    #[arg(long)]
    markdown: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let start = Instant::now();
    let plants = args.cases.plants();
    let seeds = args.cases.seeds();
    let mut summaries = Vec::new();
    for p in &plants {
        match run_plant(p, &seeds) {
            Ok(s) => summaries.push(s),
            Err(e) => {
                eprintln!("control-table: {}: {e}", p.describe());
                return ExitCode::FAILURE;
            }
        }
    }
    if args.markdown {
        let command: Vec<String> = std::env::args().skip(1).collect();
        let cmd = format!(
            "cargo run --release -p pump-sim --bin control-table -- {}",
            command.join(" ")
        );
        print!("{}", markdown(&summaries, &cmd));
    } else {
        print!("{}", plain(&summaries));
    }
    eprintln!(
        "control-table: {} plant(s) × {} seed(s) in {:.2} s",
        plants.len(),
        seeds.len(),
        start.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
