//! One power-up self-identification of the firmware in the closed-loop bench, and the figures
//! taken from it: the identified model (from the `ID` line), the firmware's validation fit
//! (`ACCEPT`/`REJECT`), a host-side free-run fit on a fresh validation signal, the same
//! search rerun on the host from the exact samples the firmware saw, tick timing, CPU load,
//! missed ticks, search time, stack and image sizes.
//!
//! Sample convention (firmware `selfid`): at each tick the firmware reads `y_t` and pushes
//! `(v, y_t)` with `v` the static map's flow at the duty applied during the interval that ends
//! with that reading, i.e. the duty it wrote in the previous tick. The bench records every
//! frame it served and every PWM change, so the pairs are rebuilt from the bench's own logs:
//! the duty in effect when a frame was read, mapped back to the record generator's duty
//! (1/10 000; the generator rebuilt from the `MAP` and `SCAN` lines and the firmware's
//! settings) and checked against the timer count it must produce.

use std::path::Path;
use std::time::Instant;

use ridge_core::{ArxModel, Evaluation, InputMap, IntGram, Real, Search};

use crate::bench::{Bench, BenchConfig, RunEnd, TickTiming, SUBSTEPS};
use crate::firmware::{self, Sizes};
use crate::transcript::Line;
use pump_sim::{Lung, LungParams, Pump, PumpParams, Sfm3300, Sfm3300Params};
use ridge_id::eval::Trace;
use ridge_id::plot::{write_fit_png, Axes, Panel};
use ridge_pump_firmware::excitation::{FlowSteps, Record};
use ridge_pump_firmware::lines::{
    ExciteLine, IdLine, MapLine, ParsedLine, PrintedModel, ScanLine, ValidateLine,
};
use ridge_pump_firmware::pump::duty_to_counts;
use ridge_pump_firmware::selfid::{absolute_model, DEFAULT_CONFIG};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{MODEL_SCALE, SLM_PER_COUNT};

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

/// A record as the firmware saw it: duty (1/10 000) in effect at each read, the raw word read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Samples {
    /// The preset the duties follow ([`fresh_record`]); `None` for the device's own records
    /// (`flow-steps`).
    pub record: Option<Record>,
    /// The static map the model's input goes through (the `MAP` line before the record, or
    /// the model's for a fresh record).
    pub map: Option<InputMap>,
    /// Duties, 1/10 000.
    pub u: Vec<u16>,
    /// SFM3300 raw words.
    pub raw: Vec<u16>,
    /// Core cycle of each read.
    pub cycle: Vec<u64>,
    /// Operating point the firmware subtracts (`EXCITE … u0= y0=`): duty 1/10 000 (the map's
    /// flow there is what it subtracts from the map's flow).
    pub u0: u16,
    /// Operating point flow, counts (`raw − 32768`).
    pub y0: i16,
    /// The operating point recomputed from the served frames as the firmware defines it:
    /// rounded mean (halves away from zero) of the last 50 readings of the settle phase (the
    /// one read in the tick that printed `SCAN` the last).
    pub y0_frames: Option<i16>,
}

impl Samples {
    /// The model's input at sample `i`: the map's flow at its duty, slm (the duty as a
    /// fraction without a map).
    pub fn input(&self, i: usize) -> f64 {
        let u = self.u.get(i).copied().unwrap_or(0);
        match &self.map {
            Some(m) => f64::from(m.at(u)) * f64::from(SLM_PER_COUNT),
            None => f64::from(u) / 10_000.0,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// Whether empty.
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }
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
        (Some(s), Some(j)) => s
            .cycle
            .last()
            .map(|c| bench.line_starts[j].saturating_sub(*c)),
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
/// `VALIDATE flow-steps n=..`) from the frames served and the PWM log, aligned on the record
/// generator's duty sequence: [`FlowSteps`] on the map of the last `MAP` line before it, with
/// the firmware's settings and the lag of the last `SCAN` line (the validation record's seed
/// is the complement of the estimation record's).
pub fn rebuild(bench: &Bench, idx: usize) -> Option<Samples> {
    let text = &bench.lines.get(idx)?.text;
    // (samples, operating point: duty 1/10 000, flow counts (none on VALIDATE), seed)
    let r = &DEFAULT_CONFIG.records;
    let (n, u0, y0, seed) = match ExciteLine::parse(text) {
        Ok(e) => (e.samples, e.u0, e.y0, r.seed),
        Err(_) => {
            let v = ValidateLine::parse(text).ok()?;
            (v.samples, 0, 0, !r.seed)
        }
    };
    let before = |keyword: &str| {
        bench.lines[..idx]
            .iter()
            .rev()
            .find(|l| l.text.split_whitespace().next() == Some(keyword))
    };
    let map = MapLine::parse(&before("MAP")?.text).ok()?.map;
    let scan = before("SCAN")?;
    let lag = ScanLine::parse(&scan.text).ok()?.lag;
    let scan_at = bench.lines.iter().position(|l| std::ptr::eq(l, scan))?;
    let samples = u16::try_from(n).ok()?;
    let mut steps = FlowSteps::new(&map, &r.shape(lag, samples, seed))?;
    let gen: Vec<u16> = std::iter::from_fn(|| steps.next_step().map(|(d, _)| d)).collect();
    let frames = bench.sensor.borrow().served();
    let at = bench.line_starts[idx];
    let j0 = frames.partition_point(|(c, _)| *c < at);
    let counts_at = |c: u64| {
        bench
            .duty_at(c)
            .map_or(0, |d| if d.connected { u32::from(d.ocr) + 1 } else { 0 })
    };
    for k in j0.saturating_sub(3)..=j0 + 3 {
        if k + gen.len() > frames.len() {
            break;
        }
        let ok = gen
            .iter()
            .enumerate()
            .all(|(i, &g)| counts_at(frames[k + i].0) == pwm_counts(g));
        if ok {
            let settled = frames.partition_point(|(c, _)| *c < bench.line_starts[scan_at]);
            let y0_frames = (settled >= 50).then(|| {
                let sum: i32 = frames[settled - 50..settled]
                    .iter()
                    .map(|(_, raw)| i32::from(raw_to_counts(*raw)))
                    .sum();
                let half = if sum >= 0 { 25 } else { -25 };
                ((sum + half) / 50) as i16
            });
            let mut s = Samples {
                map: Some(map),
                u0,
                y0,
                y0_frames,
                ..Samples::default()
            };
            for (i, &g) in gen.iter().enumerate() {
                s.u.push(g);
                s.raw.push(frames[k + i].1);
                s.cycle.push(frames[k + i].0);
            }
            return Some(s);
        }
    }
    None
}

/// The firmware's search configuration (`selfid::DEFAULT_CONFIG.search`: ridge-core's
/// default search on the device's grid, p ≤ 5, with an intercept, on deviations from the
/// operating point), in `T`.
pub fn firmware_search<T: Real>() -> Search<T> {
    Search {
        grid: DEFAULT_CONFIG.search.grid,
        offset: DEFAULT_CONFIG.search.offset,
        ..Search::default()
    }
}

/// Reruns the firmware's search on the host from `samples` with exact integer statistics and
/// `f64` normal equations (ridge-core `IntGram` + `Search<f64>` on the deviations
/// `(v − v0, y − y0)`, `v` the map's flow at the duty), and converts the result to the absolute
/// model with an intercept as the firmware does (`selfid::absolute_model`:
/// `c = c_dev + y0 (1 − Σθ) − v0 Σφ`).
pub fn host_search(samples: &Samples) -> Result<IdLine, String> {
    host_search_in::<f64>(samples)
}

/// [`host_search`] with the normal equations and the search in `T` (`f32` is what the
/// firmware runs).
pub fn host_search_in<T: Real>(samples: &Samples) -> Result<IdLine, String> {
    let map = samples.map.ok_or("no MAP line before the record")?;
    let mut g = IntGram::new();
    let (v0, y0) = (map.at(samples.u0), i32::from(samples.y0));
    for (&u, &raw) in samples.u.iter().zip(&samples.raw) {
        let dv = i32::from(map.at(u)) - i32::from(v0);
        g.push(dv, i32::from(raw_to_counts(raw)) - y0)
            .map_err(|e| format!("{e:?}"))?;
    }
    let normal = g.normal::<T>(MODEL_SCALE).map_err(|e| format!("{e:?}"))?;
    let sel = firmware_search::<T>()
        .run(&normal, None)
        .map_err(|e| format!("{e:?}"))?;
    let m = absolute_model(&sel.fit.model(), v0, samples.y0).map_err(|e| format!("{e:?}"))?;
    let s = m.structure();
    Ok(IdLine {
        model: PrintedModel {
            p: s.p,
            q: s.q,
            d: s.d,
            offset: m.offset(),
            theta: m.theta().iter().map(|v| v.to_f64()).collect(),
            phi: m.phi().iter().map(|v| v.to_f64()).collect(),
            c: m.intercept().to_f64(),
        },
        score: sel.score.to_f64(),
        evaluated: sel.evaluated,
        candidates: sel.candidates,
        skipped: sel.skipped,
        iterations: sel.fit.iterations,
    })
}

/// Largest coefficient difference between two models of the same structure, relative to
/// `max(1, |b|)` per coefficient (θ, φ, c); `None` if the structures differ.
pub fn coefficient_error(a: &PrintedModel, b: &PrintedModel) -> Option<f64> {
    if (a.p, a.q, a.d) != (b.p, b.q, b.d) || a.theta.len() != b.theta.len() {
        return None;
    }
    let pairs = a
        .theta
        .iter()
        .zip(&b.theta)
        .chain(a.phi.iter().zip(&b.phi))
        .chain(std::iter::once((&a.c, &b.c)));
    Some(
        pairs
            .map(|(x, y)| (x - y).abs() / y.abs().max(1.0))
            .fold(0.0, f64::max),
    )
}

/// Free-run and one-step scores of `model` on `samples` (physical units, the input through the
/// samples' map), with the trace for a plot.
pub fn score(model: &ArxModel<f64>, samples: &Samples) -> (Option<f64>, Option<f64>, Trace) {
    let mut ev = Evaluation::new(*model);
    let mut trace = Trace::new(samples.len() as u64, 2000);
    for (i, &raw) in samples.raw.iter().enumerate() {
        let y = pump_sim::sfm3300::raw_to_flow(raw);
        let p = ev.push(samples.input(i), y);
        trace.push(i as u64, y, p);
    }
    trace.finish();
    (
        ev.free_run().map(|m| m.fit),
        ev.one_step().map(|m| m.fit),
        trace,
    )
}

/// A fresh validation signal on the host, with the loop's timing: the plant (blower `pump`,
/// test lung `lung` if any) sub-stepped as in the bench, the reading taken at the tick, the new
/// duty applied `latency` sub-steps later, the sensor noise from `seed`. Starts from `base`
/// duty held for 2 s, as the firmware settles. `map`: the model's map, kept with the samples
/// for scoring.
#[allow(clippy::too_many_arguments)]
pub fn fresh_record(
    pump: &PumpParams,
    lung: Option<&LungParams>,
    sensor: &Sfm3300Params,
    seed: u64,
    record: Record,
    map: Option<InputMap>,
    base: u16,
    latency: usize,
) -> Samples {
    let mut p = pump.clone();
    p.ts_s /= SUBSTEPS as f64;
    p.delay_samples *= SUBSTEPS;
    let mut pump = Pump::new(p);
    let mut lung = lung.cloned().map(Lung::new);
    let mut sfm = Sfm3300::new(sensor.clone(), seed);
    let frac = |d: u16| pwm_counts(d) as f64 / f64::from(PWM_MAX);
    // One 0.5 ms plant step at duty `d`: the flow at its end.
    let mut step = |d: u16| {
        let open = pump.step(frac(d));
        match &mut lung {
            Some(l) => {
                let p = pump.params();
                l.step(open, p.shutoff_of_speed(pump.speed()), p.ts_s)
            }
            None => open,
        }
    };
    let latency = latency.min(SUBSTEPS);
    let mut prev = base;
    let mut flow = 0.0;
    for _ in 0..200 * SUBSTEPS {
        flow = step(base);
    }
    let mut s = Samples {
        record: Some(record),
        map,
        ..Samples::default()
    };
    for g in record.generator() {
        for _ in 0..latency {
            flow = step(prev);
        }
        for _ in latency..SUBSTEPS {
            flow = step(g);
        }
        prev = g;
        let raw = sfm.measure_raw(flow);
        s.u.push(g);
        s.raw.push(raw);
        s.cycle.push(0);
    }
    s.u0 = base;
    s
}

/// Median sub-steps between a read and the PWM change that follows it in the same tick, over
/// `samples` (the duty written is seen by the plant at the next 0.5 ms step).
pub fn write_latency(bench: &Bench, samples: &Samples) -> usize {
    let step = TICK_CYCLES / SUBSTEPS as u64;
    let mut lat: Vec<u64> = samples
        .cycle
        .iter()
        .filter_map(|&c| {
            let i = bench.duty_log.partition_point(|d| d.cycle <= c);
            let d = bench.duty_log.get(i)?;
            (d.cycle - c < TICK_CYCLES).then(|| (d.cycle - c).div_ceil(step))
        })
        .collect();
    if lat.is_empty() {
        return 1;
    }
    lat.sort_unstable();
    lat[lat.len() / 2] as usize
}

/// Writes a PNG with one panel per `(title, trace)`.
pub fn plot(path: &Path, panels: &[(String, Trace)]) -> Result<(), String> {
    let p: Vec<Panel<'_>> = panels
        .iter()
        .map(|(t, tr)| Panel {
            title: t.clone(),
            trace: tr,
        })
        .collect();
    write_fit_png(path, &Axes::pump(), &p).map_err(|e| e.to_string())
}
