//! Issue 31's figures on the simulated rig: the firmware's power-up identification beside the
//! one before it, on the nine blower/outlet presets (`pump_sim::powerup`).
//!
//! ```text
//! cargo run --release -p pump-sim --bin powerup-table               # seeds 1..=3
//! cargo run --release -p pump-sim --bin powerup-table -- --seeds 5
//! ```
//!
//! Prints markdown: per preset and seed the host's ready time (the search takes no time on
//! the host), the model's structure, its free-run fit over the breath program and on a fresh
//! B-Ramp (true and measured flow) beside the model before issue 31, the firmware's validation
//! fit; the estimation records' spectra against each blower's corner frequency; the verdicts
//! of the acceptance rule before and now on healthy and changed plants, and their confusion
//! table.

use std::process::ExitCode;

use clap::Parser;
use pump_sim::powerup::table::{all_verdicts, markdown, presets, run};
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;

/// Prints issue 31's figures (markdown).
#[derive(Debug, Parser)]
#[command(name = "powerup-table")]
struct Args {
    /// Noise seeds 1..=N per preset.
    #[arg(long, default_value_t = 3)]
    seeds: u64,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let plants = presets();
    let mut cases = Vec::new();
    for p in &plants {
        for seed in 1..=args.seeds {
            match run(p, seed, &DEFAULT_CONFIG) {
                Ok(c) => cases.push(c),
                Err(e) => {
                    eprintln!("powerup-table: {} seed {seed}: {e}", p.describe());
                    return ExitCode::FAILURE;
                }
            }
        }
    }
    let verdicts = match all_verdicts(&plants, 1, &DEFAULT_CONFIG) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("powerup-table: verdicts: {e}");
            return ExitCode::FAILURE;
        }
    };
    print!("{}", markdown(&cases, &verdicts));
    ExitCode::SUCCESS
}
