//! What `stm32-run` (`scripts/simulate --board stm32f411`) prints from a session: the report
//! `harness_kit::report` prints for both boards, section by section, filled with this
//! harness's figures: instructions at the HCLK the RCC selects (100 MHz), counted at 1 cycle
//! each ([`CPI`]), the stack's high-water mark from the RAM paint.

use std::path::PathBuf;

use harness_kit::report::{self, Board, Control, Validation, Work};
use harness_kit::validation;

use crate::bench::secs;
use crate::machine::CPI;
use crate::session::{self, Outcome, SessionConfig, TICK_PS};
use crate::tracking;

/// Target instructions per control tick (0.1 ms at 100 MHz, issue 30).
pub const TICK_TARGET: u64 = 10_000;

/// The board as the report names it and counts its work.
pub fn board(hclk_hz: u32) -> Board {
    let mhz = hclk_hz / 1_000_000;
    Board {
        name: "STM32F411",
        emulator: "Unicorn",
        unit: "instructions",
        per_s: f64::from(hclk_hz) / CPI as f64,
        clock: format!("HCLK {mhz} MHz, {CPI} cycle per instruction assumed"),
        control_span: "tick start -> TIM3_CCR1 written: sensor read + state machine + PWM",
        run_control_span: "tick start -> TIM3_CCR1 written, incl. the controller",
        tick_budget: format!("target {TICK_TARGET} instructions ({:.1} ms)", {
            TICK_TARGET as f64 * CPI as f64 / f64::from(hclk_hz) * 1e3
        }),
        search_kind: "ticking",
    }
}

/// Where the report's files go and what it shows.
#[derive(Clone, Debug)]
pub struct Options {
    /// Every line (log rows too), not only the events.
    pub all_lines: bool,
    /// PNG of measured vs model flow.
    pub png: PathBuf,
    /// PNG of the setpoint vs the flow in run mode.
    pub track_png: PathBuf,
    /// Per-tick CSV of the session, if asked.
    pub trace: Option<PathBuf>,
    /// The plant as `PlantArgs::describe` says it.
    pub plant: String,
}

/// The report of `out` (run with `cfg`). Returns the text and whether the run identified an
/// accepted model without a fault or an unmodelled access.
pub fn render(out: &Outcome, cfg: &SessionConfig, opts: &Options) -> (String, bool) {
    let mut s = String::new();
    let bench = &out.bench;
    let m = &bench.machine;
    let hclk = m.chip().clocks().hclk;
    let board = board(hclk);
    let lines: Vec<(f64, &str)> = bench
        .lines
        .iter()
        .map(|l| (secs(l.start), l.text.as_str()))
        .collect();
    report::lines(&mut s, &lines, opts.all_lines);

    let resets = m.resets.len().saturating_sub(1);
    let extra = format!(
        ", {} instructions, {:.2} s of polling skipped by the clock jump{}",
        m.instructions(),
        secs(m.core().jumped),
        if resets > 0 {
            format!(", {resets} reset(s): {:?}", &m.resets[1..])
        } else {
            String::new()
        }
    );
    let misses = &m.chip().misses;
    let mut notes = Vec::new();
    if !misses.is_empty() {
        notes.push(format!("unmodelled accesses: {misses:?}"));
    }
    if !m.faults.is_empty() {
        notes.push(format!("CPU faults: {:?}", m.faults));
    }
    report::run_summary(&mut s, bench.time_s(), out.wall_s, &extra, &notes);
    let mut ok = misses.is_empty() && m.faults.is_empty();

    ok &= report::model(
        &mut s,
        out.map.as_ref(),
        out.id.as_ref(),
        out.estimation.as_ref(),
    );

    let model = out.id.as_ref().and_then(|id| id.model.arx().ok());
    let fresh = model.as_ref().map(|_| {
        let latency = out
            .estimation
            .as_ref()
            .map(|e| session::write_latency(bench, e));
        let period = bench.duty_now().period;
        validation::fresh_signal(
            &cfg.bench.pump,
            cfg.bench.lung.as_ref(),
            &cfg.bench.sensor,
            cfg.bench.seed,
            out.map,
            latency,
            |d| session::duty_fraction(d, period),
        )
    });
    report::validation(
        &mut s,
        &Validation {
            accept: out.accept.as_ref(),
            rejects: &out.rejects,
            model,
            record: out.validation.as_ref(),
            fresh,
            png: &opts.png,
        },
    );

    let t = &out.timing;
    if cfg.track_s > 0.0 {
        let run = tracking::run_trace(bench);
        let control = match &run {
            Ok(r) => m
                .core()
                .ticks
                .ticks
                .iter()
                .filter(|k| k.start >= r.first_at && k.busy_ps < TICK_PS)
                .filter_map(|k| k.control_instr)
                .collect(),
            Err(_) => Vec::new(),
        };
        let c = Control {
            ctrl: bench.find("CTRL").next().map(|l| l.text.as_str()),
            run,
            per_s: crate::periph::PS_PER_S as f64,
            design: t.design_instr,
            control,
            plant: opts.plant.clone(),
            png: &opts.track_png,
            trace: opts.trace.clone(),
        };
        ok &= report::control(&mut s, &board, &c);
    }

    let ticks = &m.core().ticks.ticks;
    let normal = ticks.iter().filter(|k| k.busy_ps < TICK_PS);
    let control_worst = normal
        .clone()
        .filter_map(|k| k.control_instr.map(|c| (c, secs(k.start))))
        .fold((0, 0.0), |a, b| if b.0 > a.0 { b } else { a });
    let tick_worst = normal
        .map(|k| (k.busy_instr, secs(k.start)))
        .fold((0, 0.0), |a, b| if b.0 > a.0 { b } else { a });
    let work = Work {
        control_ticks: ticks
            .iter()
            .filter(|k| k.busy_ps < TICK_PS && k.control_instr.is_some())
            .count(),
        control_worst,
        control_mean: t.control_mean,
        control_note: format!(
            "; worst {:.3} ms emulated incl. the I2C transfer (100 kHz)",
            secs(t.control_worst_ps) * 1e3
        ),
        ticks: t.ticks,
        tick_worst,
        tick_mean: t.tick_mean,
        load: t.load,
        missed: t.missed,
        during_search: t.search_ticks.map_or(0, |n| n.max(0) as usize),
        during_design: t.design_ps.map_or(0, |p| (p / TICK_PS) as usize),
        firmware_missed: t.firmware_missed,
        search: t.search_instr,
        faults: out
            .faults
            .iter()
            .map(|(at, f)| (secs(*at), f.clone()))
            .collect(),
    };
    ok &= report::work(&mut s, &board, &work);

    let sizes = out.sizes;
    let stack = bench.machine.stack_used();
    report::sizes(
        &mut s,
        sizes,
        "the image's 256 KB (sectors 0-5; 6 and 7 hold the record)",
        &[format!(
            "stack high-water (measured: RAM below the stack top no longer holding the power-up pattern) {} B  ->  static RAM + stack {} B of 128 KB",
            stack.map_or_else(|| "n/a".to_string(), |b| b.to_string()),
            sizes.ram() + stack.unwrap_or(0)
        )],
    );
    ok &= out.accept.is_some();
    (s, ok)
}
