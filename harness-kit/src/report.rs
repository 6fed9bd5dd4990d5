//! The report `scripts/simulate` prints, for either board: one function per section, in the
//! order the report has them, each writing the same figures in the same format for both
//! boards. Where a figure is the board's own (cycles at 16 MHz in simavr, instructions at
//! 100 MHz in Unicorn; how the stack is measured; the flash the image may use) its line says
//! so, through [`Board`] and the lines a harness hands in.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use pump_sim::baseline::experiment::run_ticks;
use ridge_core::{ArxModel, InputMap};
use ridge_id::capture::{classify, Kind};
use ridge_pump_firmware::event::RECORD_NAME;
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::lines::{IdLine, ParsedLine, PrintedModel};

use crate::host;
use crate::image::Sizes;
use crate::run::RunTrace;
use crate::samples::Samples;
use crate::validation::{self, FRESH_RECORD};

/// What the report says about the board and how its work is counted.
#[derive(Clone, Debug)]
pub struct Board {
    /// The chip, e.g. `ATmega2560`.
    pub name: &'static str,
    /// The emulator it runs in, e.g. `simavr`.
    pub emulator: &'static str,
    /// What work is counted in: `cycles` (cycle-exact) or `instructions`.
    pub unit: &'static str,
    /// Units per second (16e6 cycles; 100e6 instructions at the assumed 1 cycle each).
    pub per_s: f64,
    /// The clock as the timing section's title states it, e.g. `16 MHz`.
    pub clock: String,
    /// What the control latency spans, e.g. `tick ISR -> pump PWM written: …`.
    pub control_span: &'static str,
    /// The same in run mode (the controller included).
    pub run_control_span: &'static str,
    /// The control tick's budget as the lines state it, e.g. `budget 1.6 ms`.
    pub tick_budget: String,
    /// How the structure search runs: `blocking` (the loop waits) or `ticking` (the loop
    /// ticks from inside it).
    pub search_kind: &'static str,
}

impl Board {
    /// `count` in milliseconds.
    pub fn ms(&self, count: f64) -> f64 {
        count / self.per_s * 1e3
    }

    /// A time stamp in seconds (`per_s` stamps per second).
    fn secs(at: u64, per_s: f64) -> f64 {
        at as f64 / per_s
    }
}

/// The model as the report prints it.
pub fn show_model(m: &PrintedModel) -> String {
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.6}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        "(p, q, d) = ({}, {}, {})  theta = [{}]  phi = [{}]  c = {:.4}",
        m.p,
        m.q,
        m.d,
        list(&m.theta),
        list(&m.phi),
        m.c
    )
}

/// A line's `key=value` fields as printed (`k=v k=v`).
fn fields(p: &ParsedLine) -> String {
    p.fields
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The firmware's lines with the time each started (s): all of them (`all`), or the events
/// (log rows and `RES` left out) under a heading.
pub fn lines(out: &mut String, lines: &[(f64, &str)], all: bool) {
    if !all {
        let _ = writeln!(out, "firmware lines (events; log rows left out):");
    }
    for &(t, text) in lines {
        let k = text.split_whitespace().next().unwrap_or("");
        if all || (k != "RES" && classify(text.as_bytes()) != Kind::Row) {
            let _ = writeln!(out, "  [{t:8.3} s] {text}");
        }
    }
}

/// Emulated time against wall time; `extra` follows on the same line (the board's figures:
/// resets, instructions), `notes` on lines of their own.
pub fn run_summary(out: &mut String, sim_s: f64, wall_s: f64, extra: &str, notes: &[String]) {
    let _ = writeln!(
        out,
        "\nsimulated {:.2} s in {:.2} s wall ({:.1}x real time){extra}",
        sim_s,
        wall_s,
        sim_s / wall_s.max(1e-9)
    );
    for n in notes {
        let _ = writeln!(out, "  {n}");
    }
}

/// The static map (`MAP` line), the identified model (`ID` line) and the host's rerun of the
/// search on the samples the firmware saw (`est`); without a model, what the host finds on the
/// first record. `false` when there is no model.
pub fn model(
    out: &mut String,
    map: Option<&InputMap>,
    id: Option<&IdLine>,
    est: Option<&Samples>,
) -> bool {
    let mut ok = true;
    let _ = writeln!(
        out,
        "\n== identified model (ID line: dynamics from the map's flow to the flow, slm/slm)"
    );
    if let Some(map) = map {
        let flows: Vec<String> = map
            .knots()
            .iter()
            .map(|k| format!("{:.1}", f64::from(*k) / 120.0))
            .collect();
        let _ = writeln!(
            out,
            "  map (MAP line): duty {:.2} % + k x {:.2} % -> flow [{}] slm",
            f64::from(map.first()) / 100.0,
            f64::from(map.step()) / 100.0,
            flows.join(", ")
        );
    }
    match id {
        Some(id) => {
            let _ = writeln!(out, "  {}", show_model(&id.model));
            let _ = writeln!(
                out,
                "  candidates evaluated {} of {} (exact pruning)",
                id.evaluated, id.candidates
            );
        }
        None => {
            let _ = writeln!(out, "  none");
            ok = false;
        }
    }
    if let (Some(id), Some(est)) = (id, est) {
        let _ = writeln!(
            out,
            "  operating point: EXCITE y0 = {} counts, from the served frames {:?}",
            est.y0, est.y0_frames
        );
        match host::host_search(est) {
            Ok(host) => {
                let err = host::coefficient_error(&id.model, &host.model);
                let _ = writeln!(
                    out,
                    "  host rerun (IntGram + Search<f64> on the {} samples served): {}",
                    est.len(),
                    match err {
                        Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                        None => format!("DIFFERENT: {}", show_model(&host.model)),
                    }
                );
            }
            Err(e) => {
                let _ = writeln!(out, "  host rerun failed: {e}");
            }
        }
        if let Ok(h32) = host::host_search_in::<f32>(est) {
            let _ = writeln!(
                out,
                "  host rerun in f32 (as the firmware computes): {}",
                match host::coefficient_error(&id.model, &h32.model) {
                    Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                    None => format!("DIFFERENT: {}", show_model(&h32.model)),
                }
            );
        }
    } else if let Some(est) = est {
        for (name, r) in [
            ("f64", host::host_search(est)),
            ("f32", host::host_search_in::<f32>(est)),
        ] {
            let _ = match r {
                Ok(h) => writeln!(
                    out,
                    "  host ({name}) on the first record the firmware saw: {}",
                    show_model(&h.model)
                ),
                Err(e) => writeln!(out, "  host ({name}) on the first record: {e}"),
            };
        }
    } else if id.is_some() {
        let _ = writeln!(
            out,
            "  (estimation record could not be rebuilt from the logs)"
        );
    }
    ok
}

/// What the validation section shows.
pub struct Validation<'a> {
    /// The `ACCEPT` line.
    pub accept: Option<&'a ParsedLine>,
    /// The `REJECT` lines.
    pub rejects: &'a [ParsedLine],
    /// The identified model.
    pub model: Option<ArxModel<f64>>,
    /// The firmware's validation record as it saw it (closed loop).
    pub record: Option<&'a Samples>,
    /// The fresh host-side signal ([`validation::fresh_record`]) and the write latency it was
    /// made with (0.5 ms sub-steps).
    pub fresh: Option<(Samples, usize)>,
    /// Where the plot goes.
    pub png: &'a Path,
}

/// The firmware's validation (`ACCEPT` / `REJECT`), the host's scoring of its validation record
/// and of a fresh signal, and the plot of both.
pub fn validation(out: &mut String, v: &Validation<'_>) {
    let _ = writeln!(out, "\n== validation");
    if let Some(a) = v.accept {
        let _ = writeln!(
            out,
            "  firmware: ACCEPT free-run fit {} %, rmse {} slm, one-step rmse {} slm",
            a.get("fit").unwrap_or("?"),
            a.get("rmse").unwrap_or("?"),
            a.get("one").unwrap_or("?")
        );
    }
    for r in v.rejects {
        let _ = writeln!(out, "  firmware: REJECT {}", fields(r));
    }
    let mut panels = Vec::new();
    if let Some(model) = &v.model {
        if let Some(val) = v.record {
            let (free, one, trace) = validation::score(model, val);
            let _ = writeln!(
                out,
                "  host scoring of the firmware's validation record (closed loop): free-run fit {:.1} %, one-step fit {:.1} %",
                free.unwrap_or(f64::NAN),
                one.unwrap_or(f64::NAN)
            );
            panels.push((
                format!(
                    "closed loop, firmware validation record ({}): free-run fit {:.1} %",
                    val.record.map_or(RECORD_NAME, Record::name),
                    free.unwrap_or(f64::NAN)
                ),
                trace,
            ));
        }
        if let Some((fresh, latency)) = &v.fresh {
            let (free, one, trace) = validation::score(model, fresh);
            let _ = writeln!(
                out,
                "  fresh validation signal (host, {}, new noise seed, loop timing: duty applied {latency} x 0.5 ms after the read): free-run fit {:.1} %, one-step fit {:.1} %",
                FRESH_RECORD.name(),
                free.unwrap_or(f64::NAN),
                one.unwrap_or(f64::NAN)
            );
            panels.push((
                format!(
                    "fresh validation signal ({}, host): free-run fit {:.1} %",
                    FRESH_RECORD.name(),
                    free.unwrap_or(f64::NAN)
                ),
                trace,
            ));
        }
    }
    if !panels.is_empty() {
        if let Some(dir) = v.png.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        let _ = match validation::plot(v.png, &panels) {
            Ok(()) => writeln!(out, "  plot: {}", v.png.display()),
            Err(e) => writeln!(out, "  plot failed: {e}"),
        };
    }
}

/// What the flow-control section shows.
pub struct Control<'a> {
    /// The `CTRL` line's text.
    pub ctrl: Option<&'a str>,
    /// Run mode rebuilt from the bench.
    pub run: Result<RunTrace, String>,
    /// Time units per second of the run's stamps.
    pub per_s: f64,
    /// The design's work, at most (the board's unit).
    pub design: Option<u64>,
    /// The control work of each run-mode tick (the board's unit).
    pub control: Vec<u64>,
    /// The plant as `PlantArgs::describe` says it.
    pub plant: String,
    /// Where the plot goes.
    pub png: &'a Path,
    /// Where the per-tick CSV goes, if asked.
    pub trace: Option<PathBuf>,
}

/// The design, run mode rebuilt and checked against the `TRACK` lines, the step and breath
/// figures, the plot and the CSV. `false` when there was no run mode to show.
pub fn control(out: &mut String, board: &Board, c: &Control<'_>) -> bool {
    let vent = c.run.as_ref().is_ok_and(|r| r.vent_tick.is_some());
    let _ = writeln!(
        out,
        "\n== flow control (run mode: the firmware's demo program{})",
        if vent { ", then VENT" } else { "" }
    );
    if let Some(l) = c.ctrl {
        let _ = writeln!(out, "  firmware: {l}");
    }
    let run = match &c.run {
        Ok(r) => r,
        Err(e) => {
            let _ = writeln!(out, "  no run mode: {e}");
            return false;
        }
    };
    if let Some(n) = c.design {
        let _ = writeln!(
            out,
            "  design (model checks, pole placement, closed-loop checks) at most {} {} = {:.1} ms; budget 100 ms",
            n,
            board.unit,
            board.ms(n as f64)
        );
    }
    let _ = writeln!(
        out,
        "  run mode from {:.3} s, start flow {:.3} slm, setpoint preview {} ticks; {} TRACK lines recomputed from the bench: largest sp/flow difference {:.4} slm, {} misaligned",
        Board::secs(run.first_at, c.per_s),
        run.start,
        run.preview,
        run.track_lines,
        run.track_mismatch,
        run.misaligned
    );
    if let Some(&worst) = c.control.iter().max() {
        let _ = writeln!(
            out,
            "  control tick in run mode ({}) over {} ticks: worst {} {} ({:.3} ms), mean {:.3} ms; {}",
            board.run_control_span,
            c.control.len(),
            worst,
            board.unit,
            board.ms(worst as f64),
            board.ms(c.control.iter().sum::<u64>() as f64 / c.control.len() as f64),
            board.tick_budget
        );
    }
    // A volume program's breaths are scored per breath by the caller, not as the demo's steps.
    match run.scores().filter(|_| !vent) {
        Some(sc) => {
            let _ = writeln!(out, "  steps (true flow; rise 10-90 %, overshoot of the step, settling to +-max(2 %, 1 slm), steady-state error over the last 0.5 s, IAE over the level):");
            let mut from = run.start;
            for (m, to) in sc.steps.iter().zip(&sc.levels) {
                let _ = match m {
                    Some(m) => writeln!(
                        out,
                        "    {:6.2} -> {:6.2} slm: rise {}, overshoot {:5.1} %, settling {}, steady-state error {:+.3} slm, IAE {:.3} slm s",
                        from,
                        to,
                        m.rise_s.map_or("  n/a  ".into(), |v| format!("{v:.3} s")),
                        m.overshoot_pct,
                        m.settling_s.map_or("  n/a  ".into(), |v| format!("{v:.3} s")),
                        m.ss_error,
                        m.iae
                    ),
                    None => writeln!(out, "    {from:6.2} -> {to:6.2} slm: n/a"),
                };
                from = *to;
            }
            let peak = ridge_pump_firmware::setpoint::DEMO_BREATH.peak;
            let _ = writeln!(
                out,
                "  breaths 2-6 (square, 20/min, peak {} slm): RMS error {:.3} slm = {:.1} % of peak",
                peak,
                sc.breath_rms,
                pump_sim::baseline::table::breath_pct(sc.breath_rms)
            );
            let _ = writeln!(out, "  duty total variation {:.0} %/s", 100.0 * sc.duty_tv);
        }
        None if vent => {}
        None => {
            let _ = writeln!(
                out,
                "  run mode too short to score ({} intervals; the demo needs {})",
                run.trace.setpoint.len(),
                run_ticks()
            );
        }
    }
    let step = ridge_id::control::StepResponse {
        ts: 0.01,
        r: run.trace.setpoint.clone(),
        y: run.trace.flow.clone(),
        u: run
            .trace
            .duty
            .iter()
            .map(|&d| f64::from(d) / 10_000.0)
            .collect(),
        limits: run.limits,
    };
    if let Some(dir) = c.png.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let title = format!(
        "{} in {}, {}: setpoint vs true flow (slm), duty below",
        board.name, board.emulator, c.plant
    );
    let _ = match ridge_id::plot::write_control_png(
        c.png,
        &ridge_id::plot::Axes::pump(),
        &title,
        &step,
    ) {
        Ok(()) => writeln!(out, "  plot: {}", c.png.display()),
        Err(e) => writeln!(out, "  plot failed: {e}"),
    };
    if let Some(path) = &c.trace {
        match run.write_csv(path) {
            Ok(()) => {
                let _ = writeln!(
                    out,
                    "  trace: {} ({} ticks)",
                    path.display(),
                    run.rows.len()
                );
            }
            Err(e) => {
                let _ = writeln!(out, "  trace failed: {e}");
                return false;
            }
        }
    }
    true
}

/// The work figures of a run, in the board's unit ([`Board::unit`]); times in seconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Work {
    /// Ticks with a control latency measured.
    pub control_ticks: usize,
    /// Worst control latency, and when its tick started (s).
    pub control_worst: (u64, f64),
    /// Mean control latency.
    pub control_mean: f64,
    /// What the control line adds, board-specific (e.g. the emulated time with the bus
    /// transfer), starting with `; `, or empty.
    pub control_note: String,
    /// Ticks measured whole (to the idle wait).
    pub ticks: usize,
    /// Worst whole tick, and when it started (s).
    pub tick_worst: (u64, f64),
    /// Mean whole tick.
    pub tick_mean: f64,
    /// CPU load outside the search, 0..1.
    pub load: f64,
    /// Ticks missed outside the search and the design (overruns).
    pub missed: usize,
    /// Ticks during (or, ticking, run inside) the search.
    pub during_search: usize,
    /// Ticks during the blocking design.
    pub during_design: usize,
    /// The firmware's own `MISSED late=.. lost=..` totals, if it printed them.
    pub firmware_missed: Option<(i64, i64)>,
    /// The search's work (end of the record → first byte of the `ID` line).
    pub search: Option<u64>,
    /// `FAULT` lines: when (s) and the line.
    pub faults: Vec<(f64, ParsedLine)>,
}

/// The timing section: control tick, whole tick, load and missed ticks, the search, faults.
/// `false` when the firmware reported a fault.
pub fn work(out: &mut String, board: &Board, w: &Work) -> bool {
    let tick = (board.per_s / 100.0).round() as u64;
    let _ = writeln!(
        out,
        "\n== {} ({}; tick = 10 ms = {tick} {})",
        board.unit, board.clock, board.unit
    );
    let _ = writeln!(
        out,
        "  control ({}) over {} ticks: worst {} {u} ({:.3} ms, at {:.3} s), mean {:.0} {u} ({:.3} ms); {}{}",
        board.control_span,
        w.control_ticks,
        w.control_worst.0,
        board.ms(w.control_worst.0 as f64),
        w.control_worst.1,
        w.control_mean,
        board.ms(w.control_mean),
        board.tick_budget,
        w.control_note,
        u = board.unit
    );
    let _ = writeln!(
        out,
        "  whole tick incl. report lines and persistence over {}: worst {} {u} ({:.3} ms, at {:.3} s), mean {:.0} {u} ({:.3} ms)",
        w.ticks,
        w.tick_worst.0,
        board.ms(w.tick_worst.0 as f64),
        w.tick_worst.1,
        w.tick_mean,
        board.ms(w.tick_mean),
        u = board.unit
    );
    let _ = writeln!(
        out,
        "  CPU load outside the search {:.1} %; missed ticks (overruns) {}; ticks during the {} search {}, during the blocking design {}",
        100.0 * w.load,
        w.missed,
        board.search_kind,
        w.during_search,
        w.during_design
    );
    if let Some((late, lost)) = w.firmware_missed {
        let _ = writeln!(
            out,
            "  firmware's own count: MISSED late={late} lost={lost}"
        );
    }
    let _ = match w.search {
        Some(c) => writeln!(
            out,
            "  search time {} {} = {:.3} s",
            c,
            board.unit,
            c as f64 / board.per_s
        ),
        None => writeln!(out, "  search time: n/a"),
    };
    for (t, f) in &w.faults {
        let _ = writeln!(
            out,
            "  FAULT at {:.3} s: {} {}",
            t,
            f.words.join(" "),
            fields(f)
        );
    }
    w.faults.is_empty()
}

/// Flash and static RAM of the image (`flash_of`: the flash the image may use, e.g. `256
/// KB`), then the board's stack lines (each says how it was measured).
pub fn sizes(out: &mut String, s: Sizes, flash_of: &str, stack: &[String]) {
    let _ = writeln!(out, "\n== flash and RAM");
    let _ = writeln!(
        out,
        "  flash {} B (text {} + data {}) of {flash_of}; static RAM {} B (data {} + bss {})",
        s.flash(),
        s.text,
        s.data,
        s.ram(),
        s.data,
        s.bss
    );
    for l in stack {
        let _ = writeln!(out, "  {l}");
    }
}
