//! One power-up of the image in the closed-loop bench and the figures taken from it: the
//! identified model (`ID` line), the firmware's validation (`ACCEPT`/`REJECT`), the records it
//! estimated and validated on rebuilt from what the bench served (for the host rerun and the
//! scoring in `harness_kit`), the design (`CTRL`), instructions per control tick, of the search
//! and of the design, and the image's sizes.
//!
//! The records are rebuilt as `harness_kit::samples` describes, the duty checked in TIM3
//! counts ([`duty_counts`]).

use std::time::Instant;

use harness_kit::samples::{self, Samples};
use harness_kit::validation::{self, FreshRecord};
use ridge_core::InputMap;
use ridge_pump_firmware::lines::{IdLine, MapLine, ParsedLine};
use ridge_pump_firmware::pump::duty_to_counts;

use crate::bench::{Bench, BenchConfig, RunEnd};
use crate::elf::Sizes;
use crate::periph::Time;
use crate::ticks::Tick;
use crate::transcript::Line;

/// One loop tick: 10 ms, ps.
pub const TICK_PS: Time = 10_000_000_000;

/// Instructions per tick and of the blocking jobs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Timing {
    /// Ticks that returned to the idle wait within 10 ms.
    pub ticks: usize,
    /// Control latency (tick start → `TIM3_CCR1` written): mean and worst instructions.
    pub control_mean: f64,
    /// Worst control latency, instructions.
    pub control_worst: u64,
    /// Worst control latency in emulated time (includes the I2C transfer), ps.
    pub control_worst_ps: Time,
    /// Whole tick (to the idle wait): mean and worst instructions.
    pub tick_mean: f64,
    /// Worst whole tick, instructions.
    pub tick_worst: u64,
    /// Search: instructions from the PWM write of the tick that completed the record to the
    /// first byte of the `ID` (or `REJECT`) line leaving USART1, the ticks run inside it
    /// included. `None` when that byte waited in the transmit queue past the tick (the
    /// console's log on): then the line's start no longer marks the end of the job.
    pub search_instr: Option<u64>,
    /// The same in emulated time, ps.
    pub search_ps: Option<Time>,
    /// Ticks the firmware ran inside the search (`SEARCH ticks=`).
    pub search_ticks: Option<i64>,
    /// Design: instructions from the PWM write of its tick to the first byte of `CTRL`.
    pub design_instr: Option<u64>,
    /// The same in emulated time, ps.
    pub design_ps: Option<Time>,
    /// Ticks that overran 10 ms outside the search and the design.
    pub missed: usize,
    /// CPU load over the ticks within 10 ms: busy time / time to the next tick.
    pub load: f64,
    /// The firmware's own `MISSED late=.. lost=..` totals (last line), if printed.
    pub firmware_missed: Option<(i64, i64)>,
}

/// What a session produced.
#[derive(Debug)]
pub struct Outcome {
    /// The bench after the run.
    pub bench: Bench,
    /// The last `ID` line's model.
    pub id: Option<IdLine>,
    /// The static map of that model (the last `MAP` line before it; without an `ID` line the
    /// last `MAP` line, e.g. a loaded model's).
    pub map: Option<InputMap>,
    /// The `ACCEPT` line.
    pub accept: Option<ParsedLine>,
    /// `REJECT` lines.
    pub rejects: Vec<ParsedLine>,
    /// `FAULT` lines with when they started.
    pub faults: Vec<(Time, ParsedLine)>,
    /// The estimation record as the firmware saw it.
    pub estimation: Option<Samples>,
    /// The validation record as the firmware saw it.
    pub validation: Option<Samples>,
    /// Timing.
    pub timing: Timing,
    /// Image sizes.
    pub sizes: Sizes,
    /// Wall-clock time, s.
    pub wall_s: f64,
}

/// What to run.
#[derive(Clone, Debug)]
pub struct SessionConfig {
    /// Bench settings.
    pub bench: BenchConfig,
    /// Emulated-time limit, s.
    pub max_s: f64,
    /// Keep running this long after the final line, s.
    pub linger_s: f64,
    /// After `ACCEPT`/`LOADED`: on to the design (`CTRL`), then this many seconds of run mode.
    pub track_s: f64,
    /// Send `LOG on` once the firmware printed its first line (the console's CSV log).
    pub log: bool,
    /// Jump the clock over polling (see [`crate::machine`]).
    pub clock_jump: bool,
}

impl SessionConfig {
    /// Default plant, seed 1, 200 s limit, 0.5 s linger, no run mode.
    pub fn new(elf: impl Into<std::path::PathBuf>) -> Self {
        SessionConfig {
            bench: BenchConfig::new(elf),
            max_s: 200.0,
            linger_s: 0.5,
            track_s: 0.0,
            log: false,
            clock_jump: true,
        }
    }
}

fn is_final(l: &Line) -> bool {
    matches!(l.keyword(), "ACCEPT" | "FAULT" | "LOADED" | "PANIC")
}

/// Runs one session.
pub fn run(cfg: &SessionConfig) -> Result<Outcome, String> {
    let mut bench = Bench::new(cfg.bench.clone())?;
    bench.machine.core_mut().clock_jump = cfg.clock_jump;
    let t0 = Instant::now();
    if cfg.log {
        bench.run_until(cfg.max_s, |_| true)?;
        bench.send_at(0.0, b"LOG on\n");
    }
    let end = bench.run_until(cfg.max_s, is_final)?;
    if let RunEnd::Line(i) = end {
        let accept = bench.lines[i].keyword() == "ACCEPT";
        if accept && bench.lines[i].parsed().has_word("persist") {
            let t = (bench.time_s() + 5.0).min(cfg.max_s);
            bench.run_until(t, |l| l.keyword() == "PERSIST")?;
        }
        let t = (bench.time_s() + cfg.linger_s).min(cfg.max_s);
        bench.run_until(t, |_| false)?;
        let k = bench.lines[i].keyword().to_string();
        if cfg.track_s > 0.0 && matches!(k.as_str(), "ACCEPT" | "LOADED") {
            let designed = |l: &Line| matches!(l.keyword(), "CTRL" | "FAULT");
            if !bench.lines.iter().any(designed) {
                bench.run_until(cfg.max_s, designed)?;
            }
            let t = (bench.time_s() + cfg.track_s).min(cfg.max_s);
            bench.run_until(t, |_| false)?;
        }
    }
    let wall_s = t0.elapsed().as_secs_f64();
    Ok(analyse(bench, wall_s))
}

/// The figures of a finished bench.
pub fn analyse(bench: Bench, wall_s: f64) -> Outcome {
    let parsed: Vec<ParsedLine> = bench.lines.iter().map(Line::parsed).collect();
    let id_idx = parsed.iter().rposition(|r| r.keyword == "ID");
    let id = id_idx.and_then(|i| IdLine::parse(&bench.lines[i].text).ok());
    let accept = parsed.iter().find(|r| r.keyword == "ACCEPT").cloned();
    let rejects = parsed
        .iter()
        .filter(|r| r.keyword == "REJECT")
        .cloned()
        .collect();
    let faults = parsed
        .iter()
        .zip(&bench.lines)
        .filter(|(r, _)| r.keyword == "FAULT")
        .map(|(r, l)| (l.start, r.clone()))
        .collect();
    let excite = match id_idx {
        Some(j) => parsed[..j].iter().rposition(|r| r.keyword == "EXCITE"),
        None => parsed.iter().position(|r| r.keyword == "EXCITE"),
    };
    let map_before = id_idx.unwrap_or(bench.lines.len());
    let map = bench.lines[..map_before]
        .iter()
        .rev()
        .find(|l| l.keyword() == "MAP")
        .and_then(|l| MapLine::parse(&l.text).ok())
        .map(|m| m.map);
    let estimation = excite.and_then(|i| rebuild(&bench, i));
    let validate = id_idx.and_then(|j| {
        parsed
            .iter()
            .enumerate()
            .position(|(i, r)| i > j && r.keyword == "VALIDATE")
    });
    let validation = validate.and_then(|i| rebuild(&bench, i));
    let timing = timing(&bench, &parsed, id_idx);
    let sizes = bench.machine.image().sizes;
    Outcome {
        bench,
        id,
        map,
        accept,
        rejects,
        faults,
        estimation,
        validation,
        timing,
        sizes,
        wall_s,
    }
}

/// The tick whose span contains `t`.
fn tick_at(ticks: &[Tick], t: Time) -> Option<&Tick> {
    let i = ticks.partition_point(|k| k.start <= t).checked_sub(1)?;
    let k = &ticks[i];
    (t <= k.start + k.busy_ps).then_some(k)
}

/// Instructions and time from the PWM write of the tick containing line `i` to the line's
/// first byte.
fn job(bench: &Bench, i: usize) -> Option<(u64, Time)> {
    let line = bench.lines.get(i)?;
    let ticks = &bench.machine.core().ticks.ticks;
    let k = tick_at(ticks, line.start)?;
    let from_instr = k.start_instr + k.control_instr?;
    let from_t = k.start + k.control_ps?;
    Some((
        line.start_instr.checked_sub(from_instr)?,
        line.start.checked_sub(from_t)?,
    ))
}

fn timing(bench: &Bench, parsed: &[ParsedLine], id_idx: Option<usize>) -> Timing {
    let ticks = &bench.machine.core().ticks.ticks;
    let normal: Vec<&Tick> = ticks.iter().filter(|k| k.busy_ps < TICK_PS).collect();
    let control: Vec<u64> = normal.iter().filter_map(|k| k.control_instr).collect();
    let mean = |v: &[u64]| {
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<u64>() as f64 / v.len() as f64
        }
    };
    let busy: Vec<u64> = normal.iter().map(|k| k.busy_instr).collect();
    let search_line = id_idx.or_else(|| parsed.iter().position(|r| r.keyword == "REJECT"));
    let search = search_line.and_then(|i| job(bench, i));
    let design_line = parsed.iter().position(|r| r.keyword == "CTRL");
    let design = design_line.and_then(|i| job(bench, i));
    // Overruns: ticks past 10 ms but for those in which the search or the design ran.
    let jobs: Vec<Time> = [search_line, design_line]
        .into_iter()
        .flatten()
        .filter_map(|i| bench.lines.get(i).map(|l| l.start))
        .collect();
    let missed = ticks
        .iter()
        .filter(|k| k.busy_ps >= TICK_PS)
        .filter(|k| {
            !jobs
                .iter()
                .any(|&t| (k.start..=k.start + k.busy_ps).contains(&t))
        })
        .count();
    let (busy_ps, span_ps) = ticks
        .windows(2)
        .filter(|w| w[0].busy_ps < TICK_PS)
        .fold((0u64, 0u64), |(b, s), w| {
            (b + w[0].busy_ps, s + (w[1].start - w[0].start))
        });
    Timing {
        missed,
        load: busy_ps as f64 / span_ps.max(1) as f64,
        firmware_missed: parsed
            .iter()
            .rfind(|r| r.keyword == "MISSED")
            .and_then(|r| Some((r.int("late")?, r.int("lost")?))),
        ticks: normal.len(),
        control_mean: mean(&control),
        control_worst: control.iter().copied().max().unwrap_or(0),
        control_worst_ps: normal
            .iter()
            .filter_map(|k| k.control_ps)
            .max()
            .unwrap_or(0),
        tick_mean: mean(&busy),
        tick_worst: busy.iter().copied().max().unwrap_or(0),
        search_instr: search.map(|s| s.0),
        search_ps: search.map(|s| s.1),
        search_ticks: parsed
            .iter()
            .find(|r| r.keyword == "SEARCH")
            .and_then(|r| r.int("ticks")),
        design_instr: design.map(|s| s.0),
        design_ps: design.map(|s| s.1),
    }
}

/// TIM3 counts the firmware writes for a duty in 1/10 000, with `period` = ARR + 1.
pub fn duty_counts(duty: u16, period: u32) -> u32 {
    u32::from(duty_to_counts(
        duty,
        u16::try_from(period).unwrap_or(u16::MAX),
    ))
}

/// The duty fraction the pump sees for a duty in 1/10 000 with a `period`-count PWM period
/// ([`duty_counts`] of it).
pub fn duty_fraction(duty: u16, period: u32) -> f64 {
    f64::from(duty_counts(duty, period)) / f64::from(period.max(1))
}

/// Rebuilds the record announced by line `idx` (`EXCITE` / `VALIDATE`) from the frames served
/// and the duty log (`harness_kit::samples::rebuild`, the duty checked in TIM3 counts).
pub fn rebuild(bench: &Bench, idx: usize) -> Option<Samples> {
    let lines: Vec<(u64, &str)> = bench
        .lines
        .iter()
        .map(|l| (l.start, l.text.as_str()))
        .collect();
    let frames = bench.sensor.borrow().served();
    samples::rebuild(&lines, idx, &frames, |at, g| {
        bench
            .duty_at(at)
            .is_some_and(|d| d.ccr == duty_counts(g, d.period))
    })
}

/// Writes what USART1 sent as the CSV `ridge-id capture` writes (its `Capture`, so the formats
/// cannot differ); returns its counts.
pub fn write_capture(
    bench: &Bench,
    path: &std::path::Path,
) -> Result<ridge_id::capture::Counts, String> {
    let bytes: Vec<u8> = bench
        .machine
        .chip()
        .usart1
        .sent
        .iter()
        .map(|s| s.byte)
        .collect();
    let mut csv = Vec::new();
    let mut cap = ridge_id::capture::Capture::new(&mut csv).map_err(|e| e.to_string())?;
    cap.feed(&bytes).map_err(|e| e.to_string())?;
    let counts = cap.finish().map_err(|e| e.to_string())?;
    std::fs::write(path, csv).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(counts)
}

/// A fresh validation signal on the host with the loop's timing
/// (`harness_kit::validation::fresh_record`), the duty as TIM3 makes it of a `period`-count
/// PWM period.
pub fn fresh_record(fresh: &FreshRecord<'_>, period: u32) -> Samples {
    validation::fresh_record(fresh, |d| duty_fraction(d, period))
}

/// Median plant sub-steps (0.5 ms) between a read of `samples` and the PWM change that
/// follows it in the same tick (`harness_kit::validation::write_latency`).
pub fn write_latency(bench: &Bench, samples: &Samples) -> usize {
    let changes: Vec<u64> = bench.duty_log.iter().map(|d| d.at).collect();
    validation::write_latency(samples, &changes, TICK_PS)
}
