//! One power-up self-identification of the firmware in the closed-loop bench, and the figures
//! taken from it: the identified model (from the `ID` line), the firmware's validation fit
//! (`ACCEPT`/`REJECT`), a host-side free-run fit on a fresh validation signal, the same
//! search rerun on the host from the exact samples the firmware saw, tick timing, CPU load,
//! missed ticks, search time, stack and image sizes.
//!
//! The records are rebuilt as `harness_kit::samples` describes (the duty checked in the timer
//! counts OCR4A + 1 the board writes, [`pwm_counts`]); the host rerun, the scoring and the fresh
//! validation signal are `harness_kit`'s (re-exported here for the tests).

use std::time::Instant;

pub use harness_kit::host::{coefficient_error, firmware_search, host_search, host_search_in};
pub use harness_kit::samples::Samples;
pub use harness_kit::validation::{plot, score, FreshRecord};

use crate::bench::{Bench, BenchConfig, RunEnd, TickTiming};
use crate::firmware::{self, Sizes};
use crate::transcript::Line;
use harness_kit::{samples, validation};
use ridge_core::InputMap;
use ridge_pump_firmware::lines::{IdLine, MapLine, ParsedLine};
use ridge_pump_firmware::pump::duty_to_counts;

/// Timer TOP + 1 of the board's pump PWM (OC4A, 20 kHz): `max_duty_cycle()`.
pub const PWM_MAX: u32 = 800;
/// One tick, cycles (10 ms at 16 MHz).
pub const TICK_CYCLES: u64 = 160_000;
/// The controller design's budget: 100 ms at 16 MHz, cycles.
pub const DESIGN_BUDGET_CYCLES: u64 = 1_600_000;

/// The ATmega2560 board's PWM timer count (`OCR4A + 1`, 0 = off) for a duty in 1/10 000: the
/// pump driver's [`duty_to_counts`] with `max_duty_cycle() = PWM_MAX`.
pub fn pwm_counts(duty: u16) -> u32 {
    u32::from(duty_to_counts(duty, PWM_MAX as u16))
}

/// The duty fraction the pump sees for a duty in 1/10 000: [`pwm_counts`] of [`PWM_MAX`].
pub fn pwm_fraction(duty: u16) -> f64 {
    pwm_counts(duty) as f64 / f64::from(PWM_MAX)
}

/// Tick timing summary.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Timing {
    /// Ticks measured that ended back in the idle wait.
    pub ticks: usize,
    /// Worst such tick, cycles from ISR entry to idle.
    pub worst: u64,
    /// Cycle at which the worst tick started.
    pub worst_at: u64,
    /// Mean, cycles.
    pub mean: f64,
    /// Ticks with a control latency (ISR entry → pump PWM registers written: sensor read,
    /// state machine with the statistics update, PWM), see [`TickTiming::control`].
    pub control_ticks: usize,
    /// Worst control latency, cycles.
    pub control_worst: u64,
    /// Cycle at which the tick with the worst control latency started.
    pub control_worst_at: u64,
    /// Mean control latency, cycles.
    pub control_mean: f64,
    /// Ticks that found the main loop busy outside the blocking jobs (overruns: missed
    /// deadlines).
    pub missed: usize,
    /// Ticks that fired during the (blocking) search.
    pub during_search: usize,
    /// Ticks that fired during the (blocking) controller design: within its 100 ms budget
    /// before the `CTRL` (or `FAULT control`) line.
    pub during_design: usize,
    /// CPU load outside the search: 1 − idle / elapsed, from the end of learning.
    pub load: f64,
    /// Search time, cycles (last excitation read → first byte of the `ID` line).
    pub search_cycles: Option<u64>,
    /// The firmware's own `MISSED late=.. lost=..` totals (last line), if printed.
    pub firmware_missed: Option<(i64, i64)>,
}

/// Everything a session produced.
#[derive(Debug)]
pub struct Outcome {
    /// The bench after the run (lines, logs, sensor state).
    pub bench: Bench,
    /// The `ID` line's model (the last one).
    pub id: Option<IdLine>,
    /// The static map of that model (the last `MAP` line before it; without an `ID` line the
    /// last `MAP` line, e.g. a loaded model's).
    pub map: Option<InputMap>,
    /// The `ACCEPT` line, if any.
    pub accept: Option<ParsedLine>,
    /// `REJECT` lines.
    pub rejects: Vec<ParsedLine>,
    /// `FAULT` lines with their end cycle.
    pub faults: Vec<(u64, ParsedLine)>,
    /// Stack used, bytes (`STACK used=`).
    pub stack_used: Option<u32>,
    /// Image sizes.
    pub sizes: Sizes,
    /// The estimation record as the firmware saw it (if it could be rebuilt).
    pub estimation: Option<Samples>,
    /// The validation record as the firmware saw it.
    pub validation: Option<Samples>,
    /// Timing.
    pub timing: Timing,
    /// Wall-clock time of the simulation, seconds.
    pub wall_s: f64,
}

/// What to run.
#[derive(Clone, Debug)]
pub struct SessionConfig {
    /// Bench settings (ELF, plant, seed, faults in the EEPROM …).
    pub bench: BenchConfig,
    /// Simulated-time limit, seconds.
    pub max_s: f64,
    /// Keep running this long after the final line (`ACCEPT`, `FAULT`, `LOADED`).
    pub linger_s: f64,
    /// After `ACCEPT` or `LOADED`: run on until the controller is designed (`CTRL`, or a
    /// `FAULT`), then this many seconds of run mode; 0 stops after the linger.
    pub track_s: f64,
    /// Send `LOG on` (the console's CSV log, one row per tick) once the firmware has printed
    /// its first line, as `ridge-id capture --send "LOG on"` does; [`crate::capture`] then
    /// writes what it streamed.
    pub log: bool,
}

impl SessionConfig {
    /// Default plant, seed 1, 200 s limit, 0.5 s linger, no run mode, log off.
    pub fn new(elf: impl Into<std::path::PathBuf>) -> Self {
        Self {
            bench: BenchConfig::new(elf),
            max_s: 200.0,
            linger_s: 0.5,
            track_s: 0.0,
            log: false,
        }
    }
}

/// Keywords that end a session.
fn is_final(l: &Line) -> bool {
    let k = l.text.split_whitespace().next().unwrap_or("");
    matches!(k, "ACCEPT" | "FAULT" | "LOADED" | "PANIC")
}

/// Runs one session.
pub fn run(cfg: &SessionConfig) -> Result<Outcome, String> {
    let sizes = firmware::sizes(&cfg.bench.elf)?;
    let mut bench = Bench::new(cfg.bench.clone())?;
    if cfg.log {
        bench.send_after(|_| true, 0.0, b"LOG on\n".to_vec());
    }
    let t0 = Instant::now();
    let end = bench.run_until(cfg.max_s, is_final);
    if let RunEnd::Line(i) = end {
        if bench.lines[i].text.starts_with("ACCEPT") && bench.lines[i].parsed().has_word("persist")
        {
            // Let the EEPROM write finish (`PERSIST saved` / `PERSIST failed`).
            let t = (bench.time_s() + 5.0).min(cfg.max_s);
            bench.run_until(t, |l| l.text.starts_with("PERSIST"));
        }
        let t = (bench.time_s() + cfg.linger_s).min(cfg.max_s);
        bench.run_until(t, |_| false);
        let k = bench.lines[i].text.split_whitespace().next().unwrap_or("");
        if cfg.track_s > 0.0 && matches!(k, "ACCEPT" | "LOADED") {
            let designed = |l: &Line| l.text.starts_with("CTRL") || l.text.starts_with("FAULT");
            if !bench.lines.iter().any(designed) {
                bench.run_until(cfg.max_s, designed);
            }
            let t = (bench.time_s() + cfg.track_s).min(cfg.max_s);
            bench.run_until(t, |_| false);
        }
    }
    let wall_s = t0.elapsed().as_secs_f64();
    Ok(analyse(bench, sizes, wall_s))
}

/// Extracts the figures from a finished bench.
pub fn analyse(bench: Bench, sizes: Sizes, wall_s: f64) -> Outcome {
    let parsed: Vec<(usize, ParsedLine)> = bench
        .lines
        .iter()
        .enumerate()
        .map(|(i, l)| (i, l.parsed()))
        .collect();
    let id_idx = parsed.iter().rev().find(|(_, r)| r.keyword == "ID");
    let id = id_idx.and_then(|(i, _)| IdLine::parse(&bench.lines[*i].text).ok());
    let map_before = id_idx.map_or(bench.lines.len(), |(i, _)| *i);
    let map = bench.lines[..map_before]
        .iter()
        .rev()
        .find(|l| l.text.starts_with("MAP "))
        .and_then(|l| MapLine::parse(&l.text).ok())
        .map(|m| m.map);
    let accept = parsed
        .iter()
        .find(|(_, r)| r.keyword == "ACCEPT")
        .map(|(_, r)| r.clone());
    let rejects = parsed
        .iter()
        .filter(|(_, r)| r.keyword == "REJECT")
        .map(|(_, r)| r.clone())
        .collect();
    let faults = parsed
        .iter()
        .filter(|(_, r)| r.keyword == "FAULT")
        .map(|(i, r)| (bench.lines[*i].cycle, r.clone()))
        .collect();
    let stack_used = parsed
        .iter()
        .filter(|(_, r)| r.keyword == "STACK")
        .filter_map(|(_, r)| r.int("used"))
        .max()
        .map(|v| v as u32);
    // The estimation record: the last EXCITE before the ID line.
    let id_line = id_idx.map(|(i, _)| *i);
    let excite = match id_line {
        Some(j) => parsed
            .iter()
            .rfind(|(i, r)| r.keyword == "EXCITE" && *i < j),
        // No model: the first record, to compare with what the host finds on it.
        None => parsed.iter().find(|(_, r)| r.keyword == "EXCITE"),
    };
    let estimation = excite.and_then(|(i, _)| rebuild(&bench, *i));
    let validate = parsed
        .iter()
        .find(|(i, r)| r.keyword == "VALIDATE" && id_line.is_some_and(|j| *i > j))
        .map(|(i, _)| *i);
    let validation = validate.and_then(|i| rebuild(&bench, i));
    // The search that followed the rebuilt record: up to its ID or REJECT line.
    let search_end = excite.and_then(|(i, _)| {
        parsed
            .iter()
            .find(|(j, r)| *j > *i && matches!(r.keyword.as_str(), "ID" | "REJECT"))
            .map(|(j, _)| *j)
    });
    let search_cycles = match (&estimation, search_end) {
        (Some(s), Some(j)) => s.at.last().map(|c| bench.line_starts[j].saturating_sub(*c)),
        _ => None,
    };
    // Every search: from the end of an excitation record to the next ID/REJECT line.
    let mut search_windows = Vec::new();
    for (i, r) in parsed.iter().filter(|(_, r)| r.keyword == "EXCITE") {
        let n = r.int("n").unwrap_or(3000).max(0) as u64;
        // The record's last tick starts (n − 1) ticks after the tick that printed EXCITE.
        let from = bench.line_starts[*i] + n.saturating_sub(1) * TICK_CYCLES;
        if let Some((j, _)) = parsed
            .iter()
            .find(|(j, r)| *j > *i && matches!(r.keyword.as_str(), "ID" | "REJECT"))
        {
            search_windows.push((from, bench.lines[*j].cycle + TICK_CYCLES));
        } else {
            search_windows.push((from, u64::MAX));
        }
    }
    // Every controller design: it runs blocking in the main loop and ends with its line; its
    // budget is 100 ms (the firmware's keepalive reads the sensor at each tick boundary meanwhile).
    let design_windows: Vec<(u64, u64)> = bench
        .lines
        .iter()
        .filter(|l| l.text.starts_with("CTRL") || l.text.starts_with("FAULT control"))
        .map(|l| {
            let from = l.cycle.saturating_sub(DESIGN_BUDGET_CYCLES + TICK_CYCLES);
            (from, l.cycle + TICK_CYCLES)
        })
        .collect();
    let firmware_missed = parsed
        .iter()
        .rev()
        .find(|(_, r)| r.keyword == "MISSED")
        .and_then(|(_, r)| Some((r.int("late")?, r.int("lost")?)));
    let timing = timing(
        bench.ticks(),
        &search_windows,
        &design_windows,
        &bench,
        search_cycles,
        firmware_missed,
    );
    Outcome {
        bench,
        id,
        map,
        accept,
        rejects,
        faults,
        stack_used,
        sizes,
        estimation,
        validation,
        timing,
        wall_s,
    }
}

fn timing(
    ticks: &[TickTiming],
    searches: &[(u64, u64)],
    designs: &[(u64, u64)],
    bench: &Bench,
    search_cycles: Option<u64>,
    firmware_missed: Option<(i64, i64)>,
) -> Timing {
    let in_search = |c: u64| searches.iter().any(|&(a, b)| (a..=b).contains(&c));
    let normal: Vec<u64> = ticks
        .iter()
        .filter(|t| !t.interrupted_busy)
        .map(|t| t.busy)
        .collect();
    let worst_at = ticks
        .iter()
        .filter(|t| !t.interrupted_busy)
        .max_by_key(|t| t.busy)
        .map_or(0, |t| t.start);
    let in_design = |c: u64| designs.iter().any(|&(a, b)| (a..=b).contains(&c));
    let missed = ticks
        .iter()
        .filter(|t| t.interrupted_busy && !in_search(t.start) && !in_design(t.start))
        .count();
    let during_design = ticks
        .iter()
        .filter(|t| t.interrupted_busy && !in_search(t.start) && in_design(t.start))
        .count();
    let during_search = ticks
        .iter()
        .filter(|t| t.interrupted_busy && in_search(t.start))
        .count();
    let worst = normal.iter().copied().max().unwrap_or(0);
    let mean = if normal.is_empty() {
        0.0
    } else {
        normal.iter().sum::<u64>() as f64 / normal.len() as f64
    };
    // Load outside the search, from the first measured tick on.
    let from = ticks.first().map_or(0, |t| t.start);
    let elapsed = bench.machine.cycle().saturating_sub(from);
    let now = bench.machine.cycle();
    let search_len: u64 = searches
        .iter()
        .map(|&(a, b)| b.min(now).saturating_sub(a.min(now)))
        .sum();
    let busy_total = elapsed.saturating_sub(bench.idle_cycles());
    let load = if elapsed > search_len {
        busy_total.saturating_sub(search_len) as f64 / (elapsed - search_len) as f64
    } else {
        0.0
    };
    let control: Vec<(u64, u64)> = ticks
        .iter()
        .filter(|t| !t.interrupted_busy)
        .filter_map(|t| t.control.map(|c| (c, t.start)))
        .collect();
    let (control_worst, control_worst_at) = control.iter().copied().max().unwrap_or((0, 0));
    let control_mean = if control.is_empty() {
        0.0
    } else {
        control.iter().map(|c| c.0).sum::<u64>() as f64 / control.len() as f64
    };
    Timing {
        ticks: normal.len(),
        worst,
        worst_at,
        mean,
        control_ticks: control.len(),
        control_worst,
        control_worst_at,
        control_mean,
        missed,
        during_search,
        during_design,
        load,
        search_cycles,
        firmware_missed,
    }
}

/// Rebuilds the record announced by line `idx` (`EXCITE flow-steps n=.. u0=.. y0=..` /
/// `VALIDATE flow-steps n=..`) from the frames served and the PWM log
/// (`harness_kit::samples::rebuild`, the duty checked in the timer's counts).
pub fn rebuild(bench: &Bench, idx: usize) -> Option<Samples> {
    let lines: Vec<(u64, &str)> = bench
        .lines
        .iter()
        .zip(&bench.line_starts)
        .map(|(l, &start)| (start, l.text.as_str()))
        .collect();
    let frames = bench.sensor.borrow().served();
    let counts_at = |c: u64| {
        bench
            .duty_at(c)
            .map_or(0, |d| if d.connected { u32::from(d.ocr) + 1 } else { 0 })
    };
    samples::rebuild(&lines, idx, &frames, |c, g| counts_at(c) == pwm_counts(g))
}

/// A fresh validation signal on the host with the loop's timing
/// (`harness_kit::validation::fresh_record`), the duty as the board's timer makes it
/// ([`pwm_counts`] of [`PWM_MAX`]).
pub fn fresh_record(fresh: &FreshRecord<'_>) -> Samples {
    validation::fresh_record(fresh, pwm_fraction)
}

/// Median sub-steps between a read and the PWM change that follows it in the same tick, over
/// `samples` (`harness_kit::validation::write_latency`).
pub fn write_latency(bench: &Bench, samples: &Samples) -> usize {
    let changes: Vec<u64> = bench.duty_log.iter().map(|d| d.cycle).collect();
    validation::write_latency(samples, &changes, TICK_CYCLES)
}
