//! Issue 32's ventilation targets on the ATmega2560 image in simavr: ISO 80601-2-12 rows ×
//! {square, ramp} and the lung changes (C 50 → 10, R 5 → 50, both, and each reverse; at the
//! breath boundary and mid-inspiration) with the controller the firmware runs on this board
//! (the power-up design, frozen), scored on the simulated lung's truth with the host
//! benchmark's rules (`pump-sim`'s `vent-bench`), the firmware's `BREATH` figures beside them.
//!
//! ```text
//! cargo run --release -p simavr-harness --bin avr-vent-bench              # both tables
//! cargo run --release -p simavr-harness --bin avr-vent-bench -- --table rows --rows 1,4 \
//!     --waves ramp --per-breath
//! ```
//!
//! Every run powers the image up into its (first) lung, so each run has the firmware's own
//! identification and design; `--stored-model` starts it from the model the firmware's state
//! machine identifies on the host's rig instead (the image loads and designs it, ~15 s less
//! simulated time a run). This file: the flags, turned into the runs'
//! settings (`simavr_harness::vent_bench::Case`), run `--jobs` at a time; `print` prints the
//! tables.

mod print;

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Mutex;

use clap::{Parser, ValueEnum};
use pump_sim::iso::{iso_row, IsoRow, ISO_ROWS};
use pump_sim::vent_bench::{ChangeAt, CHANGES};
use ridge_pump_firmware::setpoint::Shape;
use simavr_harness::firmware;
use simavr_harness::vent_bench::{run_case, Case, CaseRun};

/// Which tables to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Table {
    /// ISO rows × waves.
    Rows,
    /// The lung changes on row 1's breath.
    Changes,
    /// Both.
    All,
}

/// Inspiratory wave (`VENT wave=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Wave {
    /// Constant flow.
    Square,
    /// Decelerating ramp.
    Ramp,
}

/// Where in its breath the lung changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum At {
    /// At the breath boundary (the valve closing).
    Boundary,
    /// Half-way through the inspiration.
    Mid,
}

/// Runs issue 32's ventilation targets on the ATmega2560 image in simavr.
#[derive(Debug, Parser)]
#[command(name = "avr-vent-bench")]
struct Args {
    /// The ATmega2560 image (default: the release build, built if out of date).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Which tables.
    #[arg(long, value_enum, default_value = "all")]
    table: Table,
    /// The ISO rows of the rows table (default 1-8).
    #[arg(long, value_delimiter = ',')]
    rows: Vec<u8>,
    /// The waves of the rows table (default both).
    #[arg(long, value_enum, value_delimiter = ',')]
    waves: Vec<Wave>,
    /// Breaths per run of the rows table.
    #[arg(long, default_value_t = 12)]
    breaths: u32,
    /// The lung changes (1-6, the host's lung-change table's order; default all).
    #[arg(long, value_delimiter = ',')]
    changes: Vec<usize>,
    /// Where the lung changes (default both).
    #[arg(long, value_enum, value_delimiter = ',')]
    at: Vec<At>,
    /// Sensor-noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulations run at once (one thread each).
    #[arg(long, default_value_t = 2)]
    jobs: usize,
    /// Also print every run's breaths.
    #[arg(long)]
    per_breath: bool,
    /// Start every run from a model the firmware's state machine identified on the host's rig
    /// (same lung, same seed), loaded from the EEPROM, instead of the image's own power-up.
    #[arg(long)]
    stored_model: bool,
}

impl Args {
    /// The rows table's runs.
    fn row_cases(&self) -> Vec<Case> {
        let rows: Vec<IsoRow> = if self.rows.is_empty() {
            ISO_ROWS.to_vec()
        } else {
            self.rows.iter().filter_map(|&n| iso_row(n)).collect()
        };
        let waves = if self.waves.is_empty() {
            vec![Wave::Square, Wave::Ramp]
        } else {
            self.waves.clone()
        };
        let mut cases = Vec::new();
        for row in rows {
            for &w in &waves {
                let wave = match w {
                    Wave::Square => Shape::Square,
                    Wave::Ramp => Shape::Ramp,
                };
                cases.push(Case {
                    seed: self.seed,
                    stored: self.stored_model,
                    ..Case::row(row, wave, self.breaths)
                });
            }
        }
        cases
    }

    /// The lung-change table's runs, with each change's name.
    fn change_cases(&self) -> Vec<(&'static str, Case)> {
        let which: Vec<usize> = if self.changes.is_empty() {
            (1..=CHANGES.len()).collect()
        } else {
            self.changes.clone()
        };
        let ats = if self.at.is_empty() {
            vec![At::Boundary, At::Mid]
        } else {
            self.at.clone()
        };
        let mut cases = Vec::new();
        for k in which {
            let Some(c) = k.checked_sub(1).and_then(|i| CHANGES.get(i)) else {
                continue;
            };
            for &a in &ats {
                let at = match a {
                    At::Boundary => ChangeAt::Boundary,
                    At::Mid => ChangeAt::Mid,
                };
                let case = Case {
                    seed: self.seed,
                    stored: self.stored_model,
                    ..Case::change(ISO_ROWS[0], c.from, c.to, at)
                };
                cases.push((c.name, case));
            }
        }
        cases
    }
}

/// Runs `cases` on `elf`, `jobs` at a time, in order of the result; progress on stderr.
fn run_all(elf: &std::path::Path, cases: &[Case], jobs: usize) -> Vec<Result<CaseRun, String>> {
    let next = Mutex::new(0usize);
    let results: Mutex<Vec<Option<Result<CaseRun, String>>>> =
        Mutex::new((0..cases.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| loop {
                let i = {
                    let mut n = next.lock().unwrap_or_else(|e| e.into_inner());
                    let i = *n;
                    *n += 1;
                    i
                };
                let Some(case) = cases.get(i) else { break };
                let r = run_case(elf, case);
                eprintln!(
                    "avr-vent-bench: run {}/{} done ({})",
                    i + 1,
                    cases.len(),
                    r.as_ref()
                        .map_or_else(|e| e.clone(), |r| format!("{:.1} s", r.wall_s))
                );
                results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err("not run".into())))
        .collect()
}

fn main() -> ExitCode {
    let args = Args::parse();
    let elf = match args.elf.clone().map_or_else(firmware::ensure_elf, Ok) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("avr-vent-bench: {e}");
            return ExitCode::from(2);
        }
    };
    let t0 = std::time::Instant::now();
    let mut ok = true;
    if matches!(args.table, Table::Rows | Table::All) {
        let cases = args.row_cases();
        let runs = run_all(&elf, &cases, args.jobs);
        ok &= print::rows(&cases, &runs, args.per_breath);
    }
    if matches!(args.table, Table::Changes | Table::All) {
        let named = args.change_cases();
        let cases: Vec<Case> = named.iter().map(|(_, c)| *c).collect();
        let runs = run_all(&elf, &cases, args.jobs);
        ok &= print::changes(&named, &runs, args.per_breath);
    }
    println!(
        "avr-vent-bench: {:.0} s wall, {} at a time",
        t0.elapsed().as_secs_f64(),
        args.jobs
    );
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
