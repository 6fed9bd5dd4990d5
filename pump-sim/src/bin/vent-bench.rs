//! Prints the ventilation benchmark (issue 32, *Targets*; docs/ventilation.md): ISO rows ×
//! {square, ramp} × {adaptive, frozen, SIMC PI, ZN PID}, the lung changes, and the adaptive
//! controller's swap rule.
//!
//! ```text
//! cargo run --release -p pump-sim --bin vent-bench
//! cargo run --release -p pump-sim --bin vent-bench -- --table changes --seeds 5
//! ```
//!
//! The computations live in `pump_sim::vent_bench` (and `pump_sim::reid` for the study's demo
//! breaths); this binary only runs them and prints.

use clap::{Parser, ValueEnum};
use pump_sim::iso::{iso_row, IsoRow, ISO_ROWS};
use pump_sim::reid::{self, breaths_in, mean_sd, Mode, Study};
use pump_sim::vent_bench::{
    change_verdict, last_outside, outcomes, power_up, power_up_plant, pressure_limited, row_lung,
    run_cell, score, zn_for, Cell, CellRun, ChangeAt, Ctrl, LungChange, Outcomes, Policy, PowerUp,
    SwapWhen,
};
use pump_sim::LungParams;
use ridge_pump_firmware::setpoint::Shape;

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

    /// `cell` with these flags' trim and policy.
    fn study(&self, cell: Cell) -> Cell {
        Cell {
            trim: self.trim == OnOff::On,
            policy: self.policy(),
            ..cell
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

/// The power-ups of `lung` for `seeds`, with their ZN tuning; failures printed and skipped.
fn power_ups(lung: &LungParams, seeds: u64) -> Vec<PowerUp> {
    let zn = match zn_for(lung) {
        Ok(z) => z,
        Err(e) => {
            eprintln!(
                "ZN tuning, C {} R {}: {e}",
                lung.compliance, lung.resistance
            );
            return Vec::new();
        }
    };
    (1..=seeds)
        .filter_map(|seed| match power_up(lung, seed, &zn) {
            Ok(p) => Some(p),
            Err(e) => {
                eprintln!(
                    "power-up C {} R {} seed {seed}: {e}",
                    lung.compliance, lung.resistance
                );
                None
            }
        })
        .collect()
}

/// `cell` from every power-up; failures printed and skipped.
fn runs(ups: &[PowerUp], cell: &Cell) -> Vec<CellRun> {
    ups.iter()
        .filter_map(|p| match run_cell(p, cell) {
            Ok(r) => Some(r),
            Err(e) => {
                eprintln!(
                    "row {} {:?} {} seed {}: {e}",
                    cell.row.row,
                    cell.wave,
                    cell.ctrl.name(),
                    p.seed
                );
                None
            }
        })
        .collect()
}

fn max(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(f64::NEG_INFINITY, f64::max)
}

fn wave_name(w: Shape) -> &'static str {
    match w {
        Shape::Square => "square",
        Shape::Ramp => "ramp",
    }
}

fn bench(args: &Args) {
    let rows: Vec<IsoRow> = if args.rows.is_empty() {
        ISO_ROWS.to_vec()
    } else {
        args.rows.iter().filter_map(|&n| iso_row(n)).collect()
    };
    println!(
        "## Benchmark: {} breaths, seeds 1-{}, default blower, SFM3300 noise on, trim on\n",
        args.breaths, args.seeds
    );
    println!(
        "| row | wave | controller | worst \\|error\\| breaths ≥ 3 (%) | ±(4 mL + 5 %) from 3 (seeds) | ±(4 mL + 15 %) from 3 | breath 1 error (%, mean) | peak pressure rise on the breath before, max: breaths ≥ 3 / breath 2 (cmH₂O) | \\|PEEP error\\| max (cmH₂O) | tracking RMS (slm) | swaps / refused: fit, model, other, design |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for row in rows {
        let ups = power_ups(&row_lung(&row, 0.0), args.seeds);
        for wave in [Shape::Square, Shape::Ramp] {
            for ctrl in Ctrl::ALL {
                let cell = Cell {
                    breaths: args.breaths,
                    ..Cell::new(row, wave, ctrl)
                };
                let all = runs(&ups, &cell);
                let s: Vec<_> = all.iter().map(|r| score(r, 3)).collect();
                let first: Vec<f64> = all
                    .iter()
                    .filter_map(|r| r.breaths.first().map(|b| b.error_pct()))
                    .collect();
                let o = outcomes(all.iter().flat_map(|r| r.estimates.iter()));
                println!(
                    "| {} | {} | {} | {:.1} | {}/{} | {}/{} | {:+.1} | {:+.1} / {:+.1} | {:.2} | {:.2} | {} |",
                    row.row,
                    wave_name(wave),
                    ctrl.name(),
                    max(s.iter().map(|s| s.worst_pct)),
                    s.iter().filter(|s| s.pass5).count(),
                    s.len(),
                    s.iter().filter(|s| s.pass15).count(),
                    s.len(),
                    mean_sd(&first).0,
                    max(s.iter().map(|s| s.peak_rise)),
                    max(all.iter().filter_map(|r| {
                        let b = &r.breaths;
                        Some(b.get(1)?.peak_pressure - b.first()?.peak_pressure)
                    })),
                    max(s.iter().map(|s| s.peep_err)),
                    mean_sd(&s.iter().map(|s| s.rms).collect::<Vec<_>>()).0,
                    if ctrl == Ctrl::Adaptive {
                        format!("{} / {}", o.swapped, refused(&o))
                    } else {
                        "–".into()
                    },
                );
            }
        }
    }
    println!();
}

/// The lung changes: name, `(C, R)` before and after.
type Change = (&'static str, (f64, f64), (f64, f64));

/// The changes of the lung-change table.
const CASES: [Change; 6] = [
    ("C 50 → 10", (50.0, 5.0), (10.0, 5.0)),
    ("R 5 → 50", (50.0, 5.0), (50.0, 50.0)),
    ("C 50 → 10 and R 5 → 50", (50.0, 5.0), (10.0, 50.0)),
    ("C 10 → 50", (10.0, 5.0), (50.0, 5.0)),
    ("R 50 → 5", (50.0, 50.0), (50.0, 5.0)),
    ("C 10 → 50 and R 50 → 5", (10.0, 50.0), (50.0, 5.0)),
];

/// The breath of the lung-change table: row 1's.
const CHANGE_BREATH: u32 = 6;
/// Breaths run in the lung-change table.
const CHANGE_RUN: u32 = 14;

fn lung(c: f64, r: f64) -> LungParams {
    LungParams {
        compliance: c,
        resistance: r,
        ..row_lung(&iso_row(1).unwrap_or(ISO_ROWS[0]), ISO_ROWS[0].peep)
    }
}

fn changes(args: &Args) {
    let row = ISO_ROWS[0];
    println!(
        "## Lung changes: row 1's breath (500 mL, 20 /min, Ti 1 s, PEEP 5, square, trim on), \
         power-up into the first lung, change in breath {CHANGE_BREATH} of {CHANGE_RUN}, seeds 1-{}\n",
        args.seeds
    );
    println!("Counts from the change breath (= 1): the last breath outside the band (0: none).\n");
    println!(
        "| change | at | controller | last outside ±(4 mL + 15 %) | last outside ±(4 mL + 5 %) | worst breath error (%) | peak pressure vs previous breath, max (cmH₂O) | peak pressure before → after (cmH₂O) | \\|PEEP error\\| max (cmH₂O) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, from, to) in CASES {
        let ups = power_ups(
            &LungParams {
                peep: 0.0,
                ..lung(from.0, from.1)
            },
            args.seeds,
        );
        for at in [ChangeAt::Boundary, ChangeAt::Mid] {
            for ctrl in Ctrl::ALL {
                let cell = Cell {
                    breaths: CHANGE_RUN,
                    changes: vec![LungChange {
                        breath: CHANGE_BREATH,
                        at,
                        lung: lung(to.0, to.1),
                    }],
                    ..Cell::new(row, Shape::Square, ctrl)
                };
                // The cell's own lung at power-up is `from`, not row 1's.
                let all = runs(
                    &ups,
                    &args.study(Cell {
                        row: with_lung(row, from),
                        ..cell
                    }),
                );
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
    for (name, from, to) in CASES {
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

/// Row 1's breath on the lung `(C, R)`.
fn with_lung(row: IsoRow, (c, r): (f64, f64)) -> IsoRow {
    IsoRow {
        compliance: c,
        resistance: r,
        ..row
    }
}

/// The swap rule's thresholds: always, then percent.
const SWAP_RULES: [Option<f64>; 5] = [None, Some(90.0), Some(85.0), Some(80.0), Some(70.0)];

fn rule_name(x: Option<f64>) -> String {
    x.map_or("always".into(), |x| format!("below {x} %"))
}

/// One table cell of the swap-rule tables: mean tracking RMS (slm), mean |volume error| and
/// the worst (percent) of `breaths` (RMS, volume error in percent).
fn phase_cell(breaths: &[(f64, f64)]) -> String {
    let rms: Vec<f64> = breaths.iter().map(|b| b.0).collect();
    let vol: Vec<f64> = breaths.iter().map(|b| b.1.abs()).collect();
    format!(
        "{:.2} / {:.1} ({:.1})",
        mean_sd(&rms).0,
        mean_sd(&vol).0,
        max(vol.iter().copied())
    )
}

/// The header of a swap-rule table with the phases `labels`.
fn swap_header(labels: &[&str]) {
    println!(
        "Each phase: tracking RMS (slm) / mean \\|volume error\\| (worst) (%).\n\n\
         | swap when the running model's held-out fit is | {} | swaps (before the change) / held by the rule / refused: fit, model, other, design |",
        labels.join(" | ")
    );
    println!("|---|{}---|", "---|".repeat(labels.len()));
}

/// Counts of `estimates`: swaps, swaps at a breath before `change` (from 0), held by the
/// rule, refused (by the hold-out's fit, the model check, otherwise; the design).
fn swap_counts<'a>(
    estimates: impl Iterator<Item = &'a reid::Estimate> + Clone,
    change: u32,
) -> String {
    let o = outcomes(estimates.clone());
    let early = estimates
        .filter(|e| e.swapped_at.is_some_and(|b| b < change))
        .count();
    format!("{} ({early}) / {} / {}", o.swapped, o.held, refused(&o))
}

/// The refusals of `o`: `fit, model, other, design`.
fn refused(o: &Outcomes) -> String {
    format!("{}, {}, {}, {}", o.fit, o.model, o.other, o.design_refused)
}

/// The held-out free-run fits (running model, candidate; percent) of the re-estimates
/// snapshot at least two breaths before `change` (breath from 0; a hold-out runs into the
/// breath after its fit) while the power-up model still ran (up to the first swap).
fn power_up_fits(estimates: &[reid::Estimate], change: u32) -> Vec<(f32, f32)> {
    let mut out = Vec::new();
    for e in estimates.iter().filter(|e| e.breath + 2 < change) {
        match e.verdict {
            Some(Ok((c, r))) => out.push((r, c)),
            Some(Err(ridge_core::reid::Rejection::Fit { candidate, running })) => {
                out.push((running, candidate))
            }
            _ => {}
        }
        if e.swapped_at.is_some() {
            break;
        }
    }
    out
}

/// `min…max` of `v`.
fn range(v: impl Iterator<Item = f32> + Clone) -> String {
    let lo = v.clone().fold(f32::INFINITY, f32::min);
    let hi = v.fold(f32::NEG_INFINITY, f32::max);
    format!("{lo:.0}…{hi:.0}")
}

fn swap(args: &Args) {
    let row = ISO_ROWS[0];
    let adult = lung(50.0, 5.0);
    let stiff = lung(10.0, 50.0);
    println!(
        "## Swap rule, volume breaths: adaptive, row 1's breath (square, trim on), C 10 R 50 from \
         breath 11, row 1's lung again from breath 31, 50 breaths, seeds 1-{}\n",
        args.seeds
    );
    let phases: [(&str, u32, u32); 5] = [
        ("adult, breaths 3-10", 3, 11),
        ("C10 R50, breaths 11-14", 11, 15),
        ("C10 R50, breaths 21-30", 21, 31),
        ("adult again, breaths 31-34", 31, 35),
        ("adult again, breaths 41-50", 41, 51),
    ];
    swap_header(&phases.map(|p| p.0));
    let mut fits = Vec::new();
    let ups = power_ups(
        &LungParams {
            peep: 0.0,
            ..adult.clone()
        },
        args.seeds,
    );
    for (x, ctrl) in SWAP_RULES
        .iter()
        .map(|&x| (x, Ctrl::Adaptive))
        .chain([(None, Ctrl::Frozen)])
    {
        let cell = Cell {
            breaths: 50,
            changes: vec![
                LungChange {
                    breath: 11,
                    at: ChangeAt::Boundary,
                    lung: stiff.clone(),
                },
                LungChange {
                    breath: 31,
                    at: ChangeAt::Boundary,
                    lung: adult.clone(),
                },
            ],
            swap_below_fit: x,
            ..Cell::new(row, Shape::Square, ctrl)
        };
        let all = runs(&ups, &cell);
        let cells: Vec<String> = phases
            .iter()
            .map(|&(_, from, to)| {
                let b: Vec<(f64, f64)> = all
                    .iter()
                    .flat_map(|r| r.breaths.iter())
                    .filter(|b| b.number >= from && b.number < to)
                    .map(|b| (b.rms, b.error_pct()))
                    .collect();
                phase_cell(&b)
            })
            .collect();
        let (name, counts) = if ctrl == Ctrl::Frozen {
            ("(frozen, for reference)".to_string(), "–".to_string())
        } else {
            (
                rule_name(x),
                swap_counts(all.iter().flat_map(|r| r.estimates.iter()), 10),
            )
        };
        println!("| {name} | {} | {counts} |", cells.join(" | "));
        if x.is_none() && ctrl == Ctrl::Adaptive {
            fits = all
                .iter()
                .flat_map(|r| power_up_fits(&r.estimates, 10))
                .collect();
        }
    }
    println!(
        "\nOn the adult lung, until the first swap: the power-up model's own held-out fit {} %, \
         the re-estimates' {} % ({} verdicts).\n",
        range(fits.iter().map(|f| f.0)),
        range(fits.iter().map(|f| f.1)),
        fits.len()
    );
    println!(
        "## Swap rule, the study's demo breaths (`reid-study`'s scenario: square 10 → 60 slm, \
         adult lung → C 10 R 50 at breath 10 → adult at breath 30, breaths from 0), seeds 1-{}\n",
        args.seeds
    );
    let phases: [(&str, u32, u32); 5] = [
        ("adult, breaths 1-9", 1, 10),
        ("C10 R50, breaths 10-13", 10, 14),
        ("C10 R50, breaths 20-29", 20, 30),
        ("adult again, breaths 30-33", 30, 34),
        ("adult again, breaths 40-49", 40, 50),
    ];
    swap_header(&phases.map(|p| p.0));
    let mut fits = Vec::new();
    for (x, mode) in SWAP_RULES
        .iter()
        .map(|&x| (x, Mode::Adapt))
        .chain([(None, Mode::Frozen)])
    {
        let all: Vec<_> = (1..=args.seeds)
            .filter_map(|seed| {
                reid::run(&Study {
                    swap_below_fit: x,
                    mode,
                    ..Study::lung_change(seed)
                })
                .map_err(|e| eprintln!("seed {seed}: {e}"))
                .ok()
            })
            .collect();
        let cells: Vec<String> = phases
            .iter()
            .map(|&(_, from, to)| {
                let b: Vec<(f64, f64)> = all
                    .iter()
                    .flat_map(|r| breaths_in(r, from, to))
                    .map(|b| (b.rms, b.volume_error_pct()))
                    .collect();
                phase_cell(&b)
            })
            .collect();
        let (name, counts) = if mode == Mode::Frozen {
            ("(frozen, for reference)".to_string(), "–".to_string())
        } else {
            (
                rule_name(x),
                swap_counts(all.iter().flat_map(|r| r.estimates.iter()), 10),
            )
        };
        println!("| {name} | {} | {counts} |", cells.join(" | "));
        if x.is_none() && mode == Mode::Adapt {
            fits = all
                .iter()
                .flat_map(|r| power_up_fits(&r.estimates, 10))
                .collect();
        }
    }
    println!(
        "\nOn the adult lung, until the first swap: the power-up model's own held-out fit {} %, \
         the re-estimates' {} % ({} verdicts).\n",
        range(fits.iter().map(|f| f.0)),
        range(fits.iter().map(|f| f.1)),
        fits.len()
    );
}

/// One lung change's breaths under every controller, one seed.
fn breaths(args: &Args) {
    let Some(&(name, from, to)) = args.change.checked_sub(1).and_then(|i| CASES.get(i)) else {
        eprintln!("--change: 1 to {}", CASES.len());
        return;
    };
    let at = match args.at {
        At::Boundary => ChangeAt::Boundary,
        At::Mid => ChangeAt::Mid,
    };
    let row = with_lung(ISO_ROWS[0], from);
    let ups = power_ups(
        &LungParams {
            peep: 0.0,
            ..lung(from.0, from.1)
        },
        args.seed,
    );
    let Some(p) = ups.iter().find(|p| p.seed == args.seed) else {
        return;
    };
    println!(
        "## {name} in breath {CHANGE_BREATH} ({:?}), row 1's breath, seed {}\n",
        args.at, args.seed
    );
    println!("Per controller: delivered volume mL (error %) / programmed volume mL / peak pressure cmH₂O.\n");
    println!("| breath | {} |", Ctrl::ALL.map(Ctrl::name).join(" | "));
    println!("|---|{}", "---|".repeat(Ctrl::ALL.len()));
    let all: Vec<CellRun> = Ctrl::ALL
        .iter()
        .filter_map(|&ctrl| {
            let cell = Cell {
                breaths: CHANGE_RUN,
                changes: vec![LungChange {
                    breath: CHANGE_BREATH,
                    at,
                    lung: lung(to.0, to.1),
                }],
                ..Cell::new(row, Shape::Square, ctrl)
            };
            run_cell(p, &args.study(cell))
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

fn main() {
    let args = Args::parse();
    if matches!(args.table, Table::Bench | Table::All) {
        bench(&args);
    }
    if matches!(args.table, Table::Changes | Table::All) {
        changes(&args);
    }
    if matches!(args.table, Table::Swap | Table::All) {
        swap(&args);
    }
    if args.table == Table::Breaths {
        breaths(&args);
    }
    if args.table == Table::Policy {
        policies(&args);
    }
    if args.table == Table::Estimates {
        estimates(&args);
    }
}

/// A candidate policy of the policy table: name, trim on, the policy; `None`: the frozen
/// design (for reference).
type Candidate = (String, bool, Option<Policy>);

/// The candidates of `--table policy`: the diagnosis's knobs, then the firmware's options.
fn candidates(rms_above: f32) -> Vec<Candidate> {
    let p = Policy::ALWAYS;
    vec![
        ("(iv) swap always (today)".to_string(), true, Some(p)),
        ("swap always, trim off".to_string(), false, Some(p)),
        ("frozen, trim off".to_string(), false, None),
        (
            "swap always, trim restarted at each swap".to_string(),
            true,
            Some(Policy {
                trim_reset: true,
                ..p
            }),
        ),
        (
            "swap always, k = 1".to_string(),
            true,
            Some(Policy { shift: 1, ..p }),
        ),
        (
            "swap always, k = 3".to_string(),
            true,
            Some(Policy { shift: 3, ..p }),
        ),
        (
            "swap always after 2 breaths of the new lung".to_string(),
            true,
            Some(Policy { settle: 2, ..p }),
        ),
        (
            "swap always after 4 breaths of the new lung".to_string(),
            true,
            Some(Policy { settle: 4, ..p }),
        ),
        (
            "(iii) swap always, power-up speed".to_string(),
            true,
            Some(Policy {
                fixed_speed: true,
                ..p
            }),
        ),
        (
            "(iii) swap always, power-up speed, trim off".to_string(),
            false,
            Some(Policy {
                fixed_speed: true,
                ..p
            }),
        ),
        (
            "(ii) swap on the volume alarm".to_string(),
            true,
            Some(Policy {
                when: SwapWhen::VolumeAlarm,
                ..p
            }),
        ),
        (
            "(ii) swap on the volume alarm, power-up speed".to_string(),
            true,
            Some(Policy {
                when: SwapWhen::VolumeAlarm,
                fixed_speed: true,
                ..p
            }),
        ),
        (
            format!("(ii) swap when the last breath's tracking RMS is above {rms_above} slm"),
            true,
            Some(Policy {
                when: SwapWhen::RmsAbove(rms_above),
                ..p
            }),
        ),
        (
            "(i) monitor only (never swap)".to_string(),
            true,
            Some(Policy {
                when: SwapWhen::Never,
                ..p
            }),
        ),
        ("frozen (for reference)".to_string(), true, None),
    ]
}

/// The candidate policies on the 12 lung changes and on rows 1-8 (square, no change).
fn policies(args: &Args) {
    let row = ISO_ROWS[0];
    let cands = candidates(args.rms_above);
    println!(
        "## Swap policies: the 12 lung changes of the lung-change table (row 1's breath, change \
         in breath {CHANGE_BREATH} of {CHANGE_RUN}), seeds 1-{}\n",
        args.seeds
    );
    println!(
        "Changes missing a target in any seed: back within ±(4 mL + 15 %) by the 2nd breath, \
         ±(4 mL + 5 %) by the 4th, no breath outside ±35 %.\n"
    );
    println!(
        "| policy | missed 15 % by 2nd | missed 5 % by 4th | a breath outside 35 % | worst breath (%) | peak pressure max (cmH₂O) | swaps / held / refused: fit, model, other, design | designs swapped in: τ / power-up τ, min-median-max (above 1.4) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    // Power-ups once per first lung.
    let ups: Vec<Vec<PowerUp>> = CASES
        .iter()
        .map(|(_, from, _)| {
            power_ups(
                &LungParams {
                    peep: 0.0,
                    ..lung(from.0, from.1)
                },
                args.seeds,
            )
        })
        .collect();
    for (name, trim, policy) in &cands {
        let (mut m15, mut m5, mut m35, mut worst, mut peak) = (0, 0, 0, 0.0f64, 0.0f64);
        let mut est = Vec::new();
        let mut ratios: Vec<f64> = Vec::new();
        for ((_, from, to), ups) in CASES.iter().zip(&ups) {
            for at in [ChangeAt::Boundary, ChangeAt::Mid] {
                let cell = Cell {
                    breaths: CHANGE_RUN,
                    changes: vec![LungChange {
                        breath: CHANGE_BREATH,
                        at,
                        lung: lung(to.0, to.1),
                    }],
                    trim: *trim,
                    policy: policy.unwrap_or(Policy::ALWAYS),
                    ..Cell::new(
                        with_lung(row, *from),
                        Shape::Square,
                        if policy.is_some() {
                            Ctrl::Adaptive
                        } else {
                            Ctrl::Frozen
                        },
                    )
                };
                let all = runs(ups, &cell);
                let v: Vec<_> = all
                    .iter()
                    .map(|r| change_verdict(r, CHANGE_BREATH))
                    .collect();
                m15 += usize::from(!v.iter().all(|v| v.meets15()));
                m5 += usize::from(!v.iter().all(|v| v.meets5()));
                m35 += usize::from(!v.iter().all(|v| v.meets35()));
                worst = worst.max(max(v.iter().map(|v| v.worst_pct)));
                peak = peak.max(max(v.iter().map(|v| v.peak_pressure)));
                for r in &all {
                    if let Some(&(_, t0)) = r.designs.first() {
                        ratios.extend(r.designs.iter().skip(1).map(|d| f64::from(d.1 / t0)));
                    }
                }
                est.extend(all.into_iter().flat_map(|r| r.estimates));
            }
        }
        let o = outcomes(est.iter());
        ratios.sort_by(f64::total_cmp);
        let spread = match (ratios.first(), ratios.get(ratios.len() / 2), ratios.last()) {
            (Some(lo), Some(mid), Some(hi)) => format!(
                "{lo:.2}-{mid:.2}-{hi:.2} ({})",
                ratios.iter().filter(|&&r| r > 1.4).count()
            ),
            _ => "–".into(),
        };
        println!(
            "| {name} | {m15} | {m5} | {m35} | {worst:.1} | {peak:.1} | {} | {spread} |",
            if policy.is_some() {
                format!("{} / {} / {}", o.swapped, o.held, refused(&o))
            } else {
                "–".into()
            }
        );
    }
    println!();
    println!(
        "## Swap policies on rows 1-8 (square, {} breaths, no change), seeds 1-{}\n",
        args.breaths, args.seeds
    );
    println!(
        "Per row: worst \\|error\\| of breaths ≥ 3 (%), seeds within ±(4 mL + 5 %) from breath 3; swaps.\n"
    );
    let rows: Vec<IsoRow> = if args.rows.is_empty() {
        ISO_ROWS.to_vec()
    } else {
        args.rows.iter().filter_map(|&n| iso_row(n)).collect()
    };
    println!(
        "| policy | {} |",
        rows.iter()
            .map(|r| format!("row {}", r.row))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!("|---|{}", "---|".repeat(rows.len()));
    let ups: Vec<Vec<PowerUp>> = rows
        .iter()
        .map(|r| power_ups(&row_lung(r, 0.0), args.seeds))
        .collect();
    for (name, trim, policy) in cands.iter().filter(|c| c.1) {
        let cells: Vec<String> = rows
            .iter()
            .zip(&ups)
            .map(|(row, ups)| {
                let cell = Cell {
                    breaths: args.breaths,
                    trim: *trim,
                    policy: policy.unwrap_or(Policy::ALWAYS),
                    ..Cell::new(
                        *row,
                        Shape::Square,
                        if policy.is_some() {
                            Ctrl::Adaptive
                        } else {
                            Ctrl::Frozen
                        },
                    )
                };
                let all = runs(ups, &cell);
                let s: Vec<_> = all.iter().map(|r| score(r, 3)).collect();
                let swaps: usize = all.iter().map(|r| r.swaps()).sum();
                format!(
                    "{:.1}, {}/{}, {}",
                    max(s.iter().map(|s| s.worst_pct)),
                    s.iter().filter(|s| s.pass5).count(),
                    s.len(),
                    swaps
                )
            })
            .collect();
        println!("| {name} | {} |", cells.join(" | "));
    }
    println!();
}

/// The adaptive run `r`'s re-estimates against the truth (`--table breaths`).
fn estimates_table(p: &PowerUp, r: &CellRun, (from, to): ((f64, f64), (f64, f64))) {
    let table = p.switchover.map.table();
    let truth = |(c, rr): (f64, f64)| {
        let l = lung(c, rr);
        let lin = reid::linearisation(&power_up_plant(&l), &l, INSPIRATION_FLOW);
        let t = reid::through_map(&lin, &table);
        (t.gain, reid::rise63(&t.step).unwrap_or(0))
    };
    let (g0, r0) = truth(from);
    let (g1, r1) = truth(to);
    let closed = |(c, rr): (f64, f64)| {
        let l = lung(c, rr);
        let lin = reid::closed_valve_step(&power_up_plant(&l), &l, 5.0, INSPIRATION_FLOW, 100);
        let t = reid::through_map(&lin, &table);
        let peak = t.step.iter().copied().fold(0.0, f64::max);
        let at_peak = t.step.iter().position(|&v| v >= peak).unwrap_or(0);
        let at = |k: usize| t.step.get(k).copied().unwrap_or(f64::NAN);
        format!(
            "peak {peak:.3} at tick {at_peak}, {:.3} at 50, {:.3} at 100",
            at(49),
            at(99)
        )
    };
    println!(
        "Truth with the valve closed from the 5 slm bias flow, the duty of {INSPIRATION_FLOW} slm \
         held (through the map): before {}; after {}.\n",
        closed(from),
        closed(to)
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

/// The flow of the truth's linearisation in `--table breaths`: row 1's square inspiration,
/// 500 mL in 1 s above the 5 slm bias, slm.
const INSPIRATION_FLOW: f64 = 35.0;

/// The truth of row 1's breath on the lung `(C, R)` as the model sees it through `table`: the
/// valve-open linearisation at [`INSPIRATION_FLOW`] (gain, 63 % rise in ticks) and the
/// closed-valve response after 50 and 100 ticks.
fn truth_of(table: &ridge_core::input_map::MapTable, (c, r): (f64, f64)) -> (f64, usize, f64, f64) {
    let l = lung(c, r);
    let plant = power_up_plant(&l);
    let open = reid::through_map(&reid::linearisation(&plant, &l, INSPIRATION_FLOW), table);
    let closed = reid::through_map(
        &reid::closed_valve_step(&plant, &l, 5.0, INSPIRATION_FLOW, 100),
        table,
    );
    let at = |k: usize| closed.step.get(k).copied().unwrap_or(f64::NAN);
    (
        open.gain,
        reid::rise63(&open.step).unwrap_or(0),
        at(49),
        at(99),
    )
}

/// The adaptive (swap always) runs' re-estimates on the lung changes at the boundary, by where
/// their window lies, against the truth; the regulation speed of the designs swapped in.
fn estimates(args: &Args) {
    println!(
        "## Re-estimates on volume breaths (adaptive, swap always, row 1's breath, change at \
         breath {CHANGE_BREATH}'s boundary), seeds 1-{}\n",
        args.seeds
    );
    println!(
        "Model: static gain through the map (slm/slm) mean ± sd, 63 % rise (ticks) mean; truth \
         (seed 1's map): valve open at {INSPIRATION_FLOW} slm gain / rise, valve closed from \
         the bias flow after 50 / 100 ticks. τ: the swapped-in designs' regulation time constant \
         (s), min-max; the power-up design's in brackets.\n"
    );
    println!("| change | window | models (accepted) | gain | 63 % rise | truth: open gain / rise, closed at 50 / 100 | designs swapped in: τ (power-up) |");
    println!("|---|---|---|---|---|---|---|");
    let row = ISO_ROWS[0];
    for &(name, from, to) in CASES.iter().take(3) {
        let ups = power_ups(
            &LungParams {
                peep: 0.0,
                ..lung(from.0, from.1)
            },
            args.seeds,
        );
        let Some(table) = ups.first().map(|p| p.switchover.map.table()) else {
            continue;
        };
        let cell = Cell {
            breaths: CHANGE_RUN,
            changes: vec![LungChange {
                breath: CHANGE_BREATH,
                at: ChangeAt::Boundary,
                lung: lung(to.0, to.1),
            }],
            ..Cell::new(with_lung(row, from), Shape::Square, Ctrl::Adaptive)
        };
        let all = runs(&ups, &cell);
        // Windows: the old lung only (snapshot before the change), both (1-2 breaths of the
        // new lung), the new lung from its 3rd breath (old lung weighted (3/4)^3 = 42 % or
        // less).
        let windows: [(&str, u32, u32, (f64, f64)); 3] = [
            ("old lung only", 0, CHANGE_BREATH, from),
            ("both lungs", CHANGE_BREATH, CHANGE_BREATH + 2, to),
            (
                "3+ breaths of the new lung",
                CHANGE_BREATH + 2,
                u32::MAX,
                to,
            ),
        ];
        for (wname, lo, hi, lung_now) in windows {
            // `e.breath`: the last breath (from 1) in the window.
            let es: Vec<_> = all
                .iter()
                .flat_map(|r| r.estimates.iter().map(move |e| (r, e)))
                .filter(|(_, e)| e.breath + 1 > lo && e.breath < hi)
                .collect();
            let models: Vec<_> = es
                .iter()
                .filter_map(|(_, e)| e.model.and_then(Result::ok))
                .collect();
            let gains: Vec<f64> = models.iter().map(|m| f64::from(m.static_gain())).collect();
            let rises: Vec<f64> = models
                .iter()
                .filter_map(|m| reid::rise63(&reid::model_step(m, reid::STEP_TICKS)))
                .map(|v| v as f64)
                .collect();
            let accepted = es
                .iter()
                .filter(|(_, e)| matches!(e.verdict, Some(Ok(_))))
                .count();
            let taus: Vec<f64> = es
                .iter()
                .filter_map(|(r, e)| {
                    let at = e.swapped_at? + 1;
                    r.designs.iter().find(|d| d.0 == at).map(|d| f64::from(d.1))
                })
                .collect();
            let t0: Vec<f64> = all
                .iter()
                .filter_map(|r| r.designs.first().map(|d| f64::from(d.1)))
                .collect();
            let (g, gs) = mean_sd(&gains);
            let (tg, tr, c50, c100) = truth_of(&table, lung_now);
            let lo_hi = |v: &[f64]| {
                format!(
                    "{:.3}-{:.3}",
                    v.iter().copied().fold(f64::INFINITY, f64::min),
                    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                )
            };
            println!(
                "| {name} | {wname} | {} ({accepted}) | {g:.3} ± {gs:.3} | {:.1} | {tg:.3} / {tr}, {c50:.3} / {c100:.3} | {} ({}) |",
                models.len(),
                mean_sd(&rises).0,
                if taus.is_empty() { "none".into() } else { format!("{} s: {}", taus.len(), lo_hi(&taus)) },
                lo_hi(&t0)
            );
        }
    }
    println!();
}
