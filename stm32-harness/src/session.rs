//! One power-up of the image in the closed-loop bench and the figures taken from it: the
//! identified model (`ID` line), the firmware's validation (`ACCEPT`/`REJECT`), the same
//! search rerun on the host from the exact samples the firmware saw, the design (`CTRL`),
//! instructions per control tick, of the search and of the design, and the image's sizes.
//!
//! Sample convention (firmware `selfid`): at each tick the firmware reads `y_t` and pushes
//! `(v, y_t)` with `v` the static map's flow at the duty applied during the interval that ends
//! with that reading. The bench logged every frame the sensor served and every duty on the
//! pin, so the record is rebuilt from them: the frames of the record are the run of
//! consecutive frames whose duty at the read matches the record generator's sequence (in TIM3
//! counts; the generator rebuilt from the `MAP` and `SCAN` lines and the firmware's settings),
//! as `simavr-harness` rebuilds it from the ATmega2560's timer.

use std::time::Instant;

use pump_sim::{Lung, LungParams, Pump, PumpParams, Sfm3300, Sfm3300Params};
use ridge_core::{ArxModel, Evaluation, InputMap, IntGram, Offset, Real, Search};
use ridge_pump_firmware::excitation::{FlowSteps, Record};
use ridge_pump_firmware::lines::{ExciteLine, MapLine, ScanLine};
use ridge_pump_firmware::pump::duty_to_counts;
use ridge_pump_firmware::selfid::{absolute_model, DEFAULT_CONFIG};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{MODEL_SCALE, SLM_PER_COUNT};

use crate::bench::{Bench, BenchConfig, RunEnd, SUBSTEPS};
use crate::elf::Sizes;
use crate::lines::{Line, ParsedLine};
use crate::periph::Time;
use crate::ticks::Tick;

/// One loop tick: 10 ms, ps.
pub const TICK_PS: Time = 10_000_000_000;

/// The model of an `ID` / `LOADED` line.
#[derive(Clone, Debug, PartialEq)]
pub struct IdLine {
    /// Output orders.
    pub p: u8,
    /// Input coefficients.
    pub q: u8,
    /// Delay.
    pub d: u8,
    /// Constant term.
    pub offset: Offset,
    /// θ.
    pub theta: Vec<f64>,
    /// φ.
    pub phi: Vec<f64>,
    /// Intercept.
    pub c: f64,
    /// Criterion value.
    pub score: Option<f64>,
    /// Candidates evaluated / in the grid.
    pub eval: Option<(i64, i64)>,
}

impl IdLine {
    /// Parses an `ID` or `LOADED` line.
    pub fn parse(r: &ParsedLine) -> Option<Self> {
        Some(IdLine {
            p: u8::try_from(r.int("p")?).ok()?,
            q: u8::try_from(r.int("q")?).ok()?,
            d: u8::try_from(r.int("d")?).ok()?,
            offset: if r.int("off").unwrap_or(0) != 0 {
                Offset::Intercept
            } else {
                Offset::None
            },
            theta: r.list("theta")?,
            phi: r.list("phi")?,
            c: r.num("c").unwrap_or(0.0),
            score: r.num("score"),
            eval: r.ratio("eval"),
        })
    }

    /// As a ridge-core model (from the map's flow to the flow, slm).
    pub fn model(&self) -> Option<ArxModel<f64>> {
        ArxModel::new(&self.theta, &self.phi, self.d, self.offset, self.c).ok()
    }
}

/// A record as the firmware saw it.
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
    /// Time of each read, ps.
    pub at: Vec<Time>,
    /// Operating point duty (`EXCITE … u0=`), 1/10 000.
    pub u0: u16,
    /// Operating point flow (`y0=`), counts.
    pub y0: i16,
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
    /// `FAULT` lines.
    pub faults: Vec<ParsedLine>,
    /// The estimation record as the firmware saw it.
    pub estimation: Option<Samples>,
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
    let id = id_idx.and_then(|i| IdLine::parse(&parsed[i]));
    let accept = parsed.iter().find(|r| r.keyword == "ACCEPT").cloned();
    let rejects = parsed
        .iter()
        .filter(|r| r.keyword == "REJECT")
        .cloned()
        .collect();
    let faults = parsed
        .iter()
        .filter(|r| r.keyword == "FAULT")
        .cloned()
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
    Timing {
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

/// Rebuilds the record announced by line `idx` (`EXCITE flow-steps n=.. u0=.. y0=..`) from
/// the frames served and the duty log, aligned on the record generator's duty sequence:
/// [`FlowSteps`] on the map of the last `MAP` line before it, with the firmware's settings
/// and the lag of the last `SCAN` line.
pub fn rebuild(bench: &Bench, idx: usize) -> Option<Samples> {
    let e = ExciteLine::parse(&bench.lines.get(idx)?.text).ok()?;
    let before = |keyword: &str| {
        bench.lines[..idx]
            .iter()
            .rev()
            .find(|l| l.keyword() == keyword)
    };
    let map = MapLine::parse(&before("MAP")?.text).ok()?.map;
    let lag = ScanLine::parse(&before("SCAN")?.text).ok()?.lag;
    let r = &DEFAULT_CONFIG.records;
    let samples = u16::try_from(e.samples).ok()?;
    let mut steps = FlowSteps::new(&map, &r.shape(lag, samples, r.seed))?;
    let gen: Vec<u16> = std::iter::from_fn(|| steps.next_step().map(|(d, _)| d)).collect();
    let frames = bench.sensor.borrow().served();
    let at = bench.lines[idx].start;
    let j0 = frames.partition_point(|f| f.0 < at);
    let counts_at = |t: Time| bench.duty_at(t).map(|d| (d.ccr, d.period));
    for k in j0.saturating_sub(3)..=j0 + 3 {
        if k + gen.len() > frames.len() {
            break;
        }
        let ok = gen.iter().enumerate().all(|(i, &g)| {
            counts_at(frames[k + i].0).is_some_and(|(ccr, period)| ccr == duty_counts(g, period))
        });
        if ok {
            let mut s = Samples {
                map: Some(map),
                u0: e.u0,
                y0: e.y0,
                ..Samples::default()
            };
            for (i, &g) in gen.iter().enumerate() {
                s.u.push(g);
                s.raw.push(frames[k + i].1);
                s.at.push(frames[k + i].0);
            }
            return Some(s);
        }
    }
    None
}

/// Reruns the firmware's search on the host from `samples`: ridge-core's exact integer
/// statistics (`IntGram`) and the firmware's search (`selfid::DEFAULT_CONFIG.search`: the
/// default search on the device's grid, p ≤ 5, with an intercept) in `T` on the deviations `(v − v0, y − y0)` from the
/// operating point (`v` the map's flow at the duty), then the absolute model as the firmware
/// forms it (`selfid::absolute_model`).
pub fn host_search<T: Real>(samples: &Samples) -> Result<IdLine, String> {
    let map = samples.map.ok_or("no MAP line before the record")?;
    let mut g = IntGram::new();
    let (v0, y0) = (map.at(samples.u0), i32::from(samples.y0));
    for (&u, &raw) in samples.u.iter().zip(&samples.raw) {
        let dv = i32::from(map.at(u)) - i32::from(v0);
        g.push(dv, i32::from(raw_to_counts(raw)) - y0)
            .map_err(|e| format!("{e:?}"))?;
    }
    let normal = g.normal::<T>(MODEL_SCALE).map_err(|e| format!("{e:?}"))?;
    let search = Search::<T> {
        grid: DEFAULT_CONFIG.search.grid,
        offset: DEFAULT_CONFIG.search.offset,
        ..Search::default()
    };
    let sel = search.run(&normal, None).map_err(|e| format!("{e:?}"))?;
    let m = absolute_model(&sel.fit.model(), v0, samples.y0).map_err(|e| format!("{e:?}"))?;
    let s = m.structure();
    Ok(IdLine {
        p: s.p,
        q: s.q,
        d: s.d,
        offset: m.offset(),
        theta: m.theta().iter().map(|v| v.to_f64()).collect(),
        phi: m.phi().iter().map(|v| v.to_f64()).collect(),
        c: m.intercept().to_f64(),
        score: Some(sel.score.to_f64()),
        eval: Some((i64::from(sel.evaluated), i64::from(sel.candidates))),
    })
}

/// Largest coefficient difference relative to `max(1, |b|)` (θ, φ, c); `None` if the
/// structures differ.
pub fn coefficient_error(a: &IdLine, b: &IdLine) -> Option<f64> {
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

/// Free-run fit (%) of `model` on `samples` (the input through the samples' map, flows in
/// slm), ridge-core's `Evaluation` (eq. 16 of the paper).
pub fn free_run_fit(model: &ArxModel<f64>, samples: &Samples) -> Option<f64> {
    let mut ev = Evaluation::new(*model);
    for (i, &raw) in samples.raw.iter().enumerate() {
        ev.push(samples.input(i), pump_sim::sfm3300::raw_to_flow(raw));
    }
    ev.free_run().map(|m| m.fit)
}

/// A fresh validation signal on the host with the loop's timing, as `simavr-harness` makes
/// it: the plant (blower `pump`, test lung `lung` if any) sub-stepped as in the bench, the
/// reading taken at the tick, the new duty (TIM3 counts of a `period`-count PWM period) seen
/// `latency` sub-steps later, the sensor noise from `seed`; from `base` duty held for 2 s, as
/// the firmware settles. `map`: the model's map, kept with the samples for scoring.
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
    period: u32,
) -> Samples {
    let mut p = pump.clone();
    p.ts_s /= SUBSTEPS as f64;
    p.delay_samples *= SUBSTEPS;
    let mut pump = Pump::new(p);
    let mut lung = lung.cloned().map(Lung::new);
    let mut sfm = Sfm3300::new(sensor.clone(), seed);
    let frac = |d: u16| f64::from(duty_counts(d, period)) / f64::from(period.max(1));
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
        u0: base,
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
        s.u.push(g);
        s.raw.push(sfm.measure_raw(flow));
        s.at.push(0);
    }
    s
}

/// Median plant sub-steps (0.5 ms) between a read of `samples` and the PWM change that
/// follows it in the same tick (the duty written is seen by the plant at the next step).
pub fn write_latency(bench: &Bench, samples: &Samples) -> usize {
    let step = TICK_PS / SUBSTEPS as u64;
    let mut lat: Vec<u64> = samples
        .at
        .iter()
        .filter_map(|&t| {
            let i = bench.duty_log.partition_point(|d| d.at <= t);
            let d = bench.duty_log.get(i)?;
            (d.at - t < TICK_PS).then(|| (d.at - t).div_ceil(step))
        })
        .collect();
    if lat.is_empty() {
        return 1;
    }
    lat.sort_unstable();
    lat[lat.len() / 2] as usize
}
