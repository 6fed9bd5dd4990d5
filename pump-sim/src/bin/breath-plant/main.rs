//! Prints the breath-plant study (docs/control.md, "Closed-loop re-identification", *A model
//! of the breath's plant*): which model of the breath's plant the closed loop's own data
//! identify (the window fed every tick or each inspiration only, at the power-up structure or
//! with more lags, with or without the static-gain check), what the checks and the design say
//! of the estimates, and what their re-designs at the power-up design's speed do on the lung
//! changes and on ISO rows 1-8 against the frozen power-up design.
//!
//! ```text
//! cargo run --release -p pump-sim --bin breath-plant -- --seeds 5
//! cargo run --release -p pump-sim --bin breath-plant -- --table changes --seeds 10
//! ```
//!
//! This file: the flags, turned into each table's settings; `tables` prints; `study` holds the
//! candidates, the runs and the figures (on `pump_sim::vent_bench` and `pump_sim::reid`).

mod study;
mod tables;

use clap::{Parser, ValueEnum};
use pump_sim::iso::{iso_row, IsoRow, ISO_ROWS};
use pump_sim::vent_bench::SwapWhen;

/// Which tables to print.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Table {
    /// The re-estimates of each candidate on a frozen loop, against the truth, with the
    /// checks' and the design's verdicts.
    Estimates,
    /// Each candidate's adaptive loop on the 12 lung changes, trim on and off.
    Changes,
    /// Each candidate's adaptive loop on ISO rows 1-8 (square), trim on and off.
    Rows,
    /// All three.
    All,
}

/// When the adaptive loops swap an accepted estimate in (`--swap-when`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum When {
    /// Every accepted estimate.
    Always,
    /// While the volume alarm is raised (the firmware's default rule).
    Alarm,
}

/// Runs the study and prints its tables.
#[derive(Debug, Parser)]
#[command(name = "breath-plant")]
struct Args {
    /// Noise seeds per cell (1, 2, …).
    #[arg(long, default_value_t = 5)]
    seeds: u64,
    /// Which tables.
    #[arg(long, value_enum, default_value = "all")]
    table: Table,
    /// `--table changes|rows`: when the adaptive loops swap.
    #[arg(long, value_enum, default_value = "always")]
    swap_when: When,
    /// `--table rows`: the ISO rows (default 1-8).
    #[arg(long, value_delimiter = ',')]
    rows: Vec<u8>,
    /// `--table rows`: breaths per run.
    #[arg(long, default_value_t = 12)]
    breaths: u32,
    /// The breaths read by a noise-free sensor (its quantisation only; the power-up keeps the
    /// noise model): a diagnosis.
    #[arg(long)]
    ideal_sensor: bool,
}

impl Args {
    fn when(&self) -> SwapWhen {
        match self.swap_when {
            When::Always => SwapWhen::Always,
            When::Alarm => SwapWhen::VolumeAlarm,
        }
    }

    fn rows(&self) -> Vec<IsoRow> {
        if self.rows.is_empty() {
            ISO_ROWS.to_vec()
        } else {
            self.rows.iter().filter_map(|&n| iso_row(n)).collect()
        }
    }
}

fn main() {
    let args = Args::parse();
    let t0 = std::time::Instant::now();
    let runs = study::Runs {
        seeds: args.seeds,
        ideal_sensor: args.ideal_sensor,
    };
    if matches!(args.table, Table::Estimates | Table::All) {
        tables::estimates(&runs);
    }
    if matches!(args.table, Table::Changes | Table::All) {
        tables::changes(&runs, args.when());
    }
    if matches!(args.table, Table::Rows | Table::All) {
        tables::rows(&args.rows(), args.breaths, &runs, args.when());
    }
    eprintln!("{:.1} s", t0.elapsed().as_secs_f64());
}
