//! Prints the ventilation benchmark (issue 32, *Targets*; docs/ventilation.md): ISO rows ×
//! {square, ramp} × {adaptive, frozen, SIMC PI, ZN PID}, the lung changes, and the adaptive
//! controller's swap rule.
//!
//! ```text
//! cargo run --release -p pump-sim --bin vent-bench
//! cargo run --release -p pump-sim --bin vent-bench -- --table changes --seeds 5
//! ```
//!
//! This file: the flags, turned into each table's settings. One file per table prints it
//! (`bench`, `changes`, `swap`, `breaths`, `policy`, `estimates`); `run` runs the cells they
//! share, `truth` computes the plant's truth the re-estimates are held against. The computations
//! live in `pump_sim::vent_bench` (and `pump_sim::reid` for the study's demo breaths).

mod bench;
mod breaths;
mod changes;
mod estimates;
mod policy;
mod run;
mod swap;
mod truth;

use clap::{Parser, ValueEnum};
use pump_sim::iso::{iso_row, IsoRow, ISO_ROWS};
use pump_sim::vent_bench::CHANGES;
use pump_sim::vent_bench::{ChangeAt, Policy, SwapWhen};
use run::Knobs;

/// Which tables to print.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Table {
    /// ISO rows × waves × controllers.
    Bench,
    /// Lung changes on row 1's breath.
    Changes,
    /// The adaptive controller's swap rule.
    Swap,
    /// One lung change's breaths, one seed (`--change`, `--at`, `--seed`).
    Breaths,
    /// The adaptive controller's candidate swap policies on the lung changes and on rows 1-8
    /// (`--rms-above`).
    Policy,
    /// The adaptive controller's re-estimates on the lung changes against the truth.
    Estimates,
    /// All three.
    All,
}

/// Runs the benchmark and prints its tables.
#[derive(Debug, Parser)]
#[command(name = "vent-bench")]
struct Args {
    /// Noise seeds per cell (1, 2, …).
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Breaths per cell of the benchmark table.
    #[arg(long, default_value_t = 12)]
    breaths: u32,
    /// The ISO rows of the benchmark table (default 1-8).
    #[arg(long, value_delimiter = ',')]
    rows: Vec<u8>,
    /// Which table.
    #[arg(long, value_enum, default_value = "all")]
    table: Table,
    /// `--table breaths`: the change (1-6, the lung-change table's order).
    #[arg(long, default_value_t = 1)]
    change: usize,
    /// `--table breaths`: where in its breath the lung changes.
    #[arg(long, value_enum, default_value = "boundary")]
    at: At,
    /// `--table breaths`: the seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// `--table changes|breaths`: the per-breath volume trim (`on`, the firmware's default).
    #[arg(long, default_value = "on")]
    trim: OnOff,
    /// `--table changes|breaths`: when the adaptive controller swaps an accepted re-estimate in.
    #[arg(long, value_enum, default_value = "always")]
    swap_when: When,
    /// `--swap-when rms`: the last reported breath's tracking RMS above which it swaps, slm.
    #[arg(long, default_value_t = 6.0)]
    rms_above: f32,
    /// `--table changes|breaths`: re-design at the power-up design's regulation speed.
    #[arg(long)]
    fixed_speed: bool,
    /// `--table changes|breaths`: restart the trim at each swap (emulated, see
    /// `vent_bench::Policy::trim_reset`).
    #[arg(long)]
    trim_reset: bool,
    /// `--table changes|breaths`: the window's forgetting shift `k`.
    #[arg(long, default_value_t = 2)]
    shift: u8,
    /// `--table changes|breaths`: swap only estimates with at least this many breaths of the
    /// changed lung in their window (the bench knows the change; study only).
    #[arg(long, default_value_t = 0)]
    settle: u32,
}

/// On or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum OnOff {
    /// On.
    On,
    /// Off.
    Off,
}

/// The adaptive controller's swap condition (`--swap-when`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum When {
    /// Every accepted re-estimate (today).
    Always,
    /// Never (monitor only).
    Never,
    /// While the volume alarm is raised.
    Alarm,
    /// When the last breath's tracking RMS is above `--rms-above`.
    Rms,
}

impl Args {
    /// The adaptive controller's policy of these flags.
    fn policy(&self) -> Policy {
        Policy {
            when: match self.swap_when {
                When::Always => SwapWhen::Always,
                When::Never => SwapWhen::Never,
                When::Alarm => SwapWhen::VolumeAlarm,
                When::Rms => SwapWhen::RmsAbove(self.rms_above),
            },
            fixed_speed: self.fixed_speed,
            shift: self.shift,
            trim_reset: self.trim_reset,
            settle: self.settle,
        }
    }

    /// The trim and policy of these flags (`--table changes|breaths`).
    fn knobs(&self) -> Knobs {
        Knobs {
            trim: self.trim == OnOff::On,
            policy: self.policy(),
        }
    }

    /// The ISO rows of `--rows` (unknown numbers skipped), all eight without it.
    fn rows(&self) -> Vec<IsoRow> {
        if self.rows.is_empty() {
            ISO_ROWS.to_vec()
        } else {
            self.rows.iter().filter_map(|&n| iso_row(n)).collect()
        }
    }

    /// Where in its breath the lung changes, of `--at`.
    fn at(&self) -> ChangeAt {
        match self.at {
            At::Boundary => ChangeAt::Boundary,
            At::Mid => ChangeAt::Mid,
        }
    }
}

/// Where in its breath the lung changes (`--at`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum At {
    /// At the breath boundary.
    Boundary,
    /// Half-way through the inspiration.
    Mid,
}

fn main() {
    let args = Args::parse();
    let rows = args.rows();
    if matches!(args.table, Table::Bench | Table::All) {
        bench::print(&rows, args.breaths, args.seeds);
    }
    if matches!(args.table, Table::Changes | Table::All) {
        changes::print(args.seeds, args.knobs());
    }
    if matches!(args.table, Table::Swap | Table::All) {
        swap::print(args.seeds);
    }
    if args.table == Table::Breaths {
        match args.change.checked_sub(1).and_then(|i| CHANGES.get(i)) {
            Some(change) => breaths::print(change, args.at(), args.seed, args.knobs()),
            None => eprintln!("--change: 1 to {}", CHANGES.len()),
        }
    }
    if args.table == Table::Policy {
        policy::print(&rows, args.breaths, args.seeds, args.rms_above);
    }
    if args.table == Table::Estimates {
        estimates::print(args.seeds);
    }
}
