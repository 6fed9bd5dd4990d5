//! Prints the analogues of the paper's Tables 1–5 on simulated pump records, as markdown.
//!
//! ```text
//! cargo run --release -p pump-sim --bin paper-tables -- [--seed N] [--markdown-out PATH]
//! ```
//!
//! The computations live in `pump_sim::paper`; this binary only parses flags and prints.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use pump_sim::paper::{Tables, DEFAULT_SEED};

/// Prints the analogues of the paper's Tables 1–5 (and the checks with no paper counterpart)
/// computed on records of the simulated pump, as markdown on standard output.
#[derive(Debug, Parser)]
#[command(name = "paper-tables")]
struct Args {
    /// Sensor-noise seed of the simulated records (the seed census uses N, N+1, …).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SEED)]
    seed: u64,
    /// Also write the markdown to this file.
    #[arg(long, value_name = "PATH")]
    markdown_out: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let start = Instant::now();
    let tables = match Tables::compute(args.seed) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("paper-tables: {e}");
            return ExitCode::FAILURE;
        }
    };
    let md = tables.to_markdown();
    print!("{md}");
    if let Some(path) = &args.markdown_out {
        if let Err(e) = std::fs::write(path, &md) {
            eprintln!("paper-tables: cannot write {}: {e}", path.display());
            return ExitCode::FAILURE;
        }
    }
    eprintln!(
        "paper-tables: seed {}, computed in {:.3} s",
        args.seed,
        start.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
