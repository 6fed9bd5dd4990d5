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
use pump_sim::baseline::table::{markdown, plain, run_plant};
use pump_sim::{Blower, Outlet, PlantArgs};

/// Runs the firmware's identification and RST controller, a Ziegler–Nichols PID and a SIMC PI
/// on the simulated rig and prints their tracking figures on the demo setpoint program.
#[derive(Debug, Parser)]
#[command(name = "control-table")]
struct Args {
    /// The plant of a single case (ignored with `--all`).
    #[command(flatten)]
    plant: PlantArgs,
    /// Every blower preset × every outlet preset (default, small, sluggish × open, adult,
    /// stiff).
    #[arg(long, conflicts_with_all = ["plant", "lung", "compliance", "resistance", "peep", "valve_resistance"])]
    all: bool,
    /// Sensor-noise seeds 1..=N; figures are means over them.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    seeds: u64,
    /// Print the markdown report (tunings, comparison, targets) instead of plain text.
    #[arg(long)]
    markdown: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let start = Instant::now();
    let plants: Vec<PlantArgs> = if args.all {
        Blower::ALL
            .iter()
            .flat_map(|&b| Outlet::ALL.iter().map(move |&o| PlantArgs::preset(b, o)))
            .collect()
    } else {
        vec![args.plant.clone()]
    };
    let seeds: Vec<u64> = (1..=args.seeds).collect();
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
