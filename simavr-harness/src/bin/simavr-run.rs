//! Runs the ATmega2560 firmware in simavr against the simulated pump (optionally into a test
//! lung) and SFM3300 (the main command, `scripts/simulate`, calls this) and prints what the
//! firmware identified, how good the model is, the controller it designed and how it tracked
//! its setpoint program, the cycle figures, flash and RAM; writes a PNG of measured vs model
//! flow, a PNG of setpoint vs flow, with `--trace` a per-tick CSV, and with `--log` the console's
//! CSV log as `ridge-id capture` writes it.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use pump_sim::baseline::experiment::run_ticks;
use pump_sim::PlantArgs;
use ridge_id::capture::{classify, Kind};
use ridge_pump_firmware::event::RECORD_NAME;
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::lines::PrintedModel;
use simavr_harness::session::{self, Outcome, SessionConfig, TICK_CYCLES};
use simavr_harness::tracking::RunTrace;
use simavr_harness::uart::UartTiming;
use simavr_harness::{capture, firmware};

/// Power-up self-identification of the ATmega2560 firmware in simavr (16 MHz), closed loop
/// with a simulated SFM3300 (TWI 0x40) and blower.
#[derive(Parser, Debug)]
#[command(name = "simavr-run")]
struct Args {
    /// Firmware ELF (default: target/avr-none/release/atmega2560.elf, built if missing).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Blower and test lung.
    #[command(flatten)]
    plant: PlantArgs,
    /// Sensor noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated-time limit, seconds.
    #[arg(long, default_value_t = 200.0)]
    max_s: f64,
    /// PNG of measured vs model flow.
    #[arg(long, default_value = "target/simavr/flow.png")]
    png: PathBuf,
    /// PNG of the setpoint vs the flow in run mode.
    #[arg(long, default_value = "target/simavr/tracking.png")]
    track_png: PathBuf,
    /// Seconds of run mode after the controller design (default: the demo program's hold,
    /// steps and six breaths, plus 0.5 s); 0 stops after ACCEPT.
    #[arg(long, value_name = "SECONDS")]
    track_s: Option<f64>,
    /// Write every tick as CSV `t,setpoint,duty,flow` (s, slm or empty before run mode,
    /// duty 0..1, true flow in slm).
    #[arg(long, value_name = "PATH")]
    trace: Option<PathBuf>,
    /// Print every UART line as it arrives.
    #[arg(long)]
    lines: bool,
    /// Send `LOG on` to the console once the firmware printed its first line and write what it
    /// streamed to PATH as `ridge-id capture` does (header `t,u,y,r,phase`, one row per tick,
    /// every other line as a `# ` comment); `ridge-id identify --input PATH --device` reads it.
    #[arg(long, value_name = "PATH")]
    log: Option<PathBuf>,
    /// USART0 frame timing: `simavr` (simavr's own, 2 992 cycles a byte with the firmware's
    /// settings, 2.2 times slower than the chip) or `chip` (the datasheet's, 1 360 cycles).
    #[arg(long, value_enum, default_value = "simavr")]
    uart_timing: Timing,
}

/// `--uart-timing` (see `simavr_harness::uart::UartTiming`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Timing {
    /// simavr's own frame time.
    Simavr,
    /// The chip's frame time.
    Chip,
}

/// Excitation preset of the fresh host-side validation signal (a record the firmware neither
/// estimates nor validates on).
const FRESH_RECORD: Record = Record::BRamp;

fn ms(cycles: f64) -> f64 {
    cycles / 16_000.0
}

fn show_model(m: &PrintedModel) -> String {
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

fn main() -> ExitCode {
    let args = Args::parse();
    let elf = match args.elf.clone().map_or_else(firmware::ensure_elf, Ok) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut cfg = SessionConfig::new(&elf);
    cfg.max_s = args.max_s;
    cfg.bench.seed = args.seed;
    cfg.bench.pump = args.plant.pump();
    cfg.bench.lung = match args.plant.lung() {
        Ok(l) => l,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    cfg.track_s = args.track_s.unwrap_or(f64::from(run_ticks()) * 0.01 + 0.5);
    cfg.log = args.log.is_some();
    cfg.bench.uart_timing = match args.uart_timing {
        Timing::Simavr => UartTiming::Simavr,
        Timing::Chip => UartTiming::Chip,
    };
    println!(
        "simavr: ATmega2560 @ 16 MHz, {}, {}, sensor seed {}",
        elf.display(),
        args.plant.describe(),
        args.seed
    );
    let out = match session::run(&cfg) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut status = print_outcome(&args, &cfg, &out);
    if let Some(path) = &args.log {
        match capture::write_capture(&out.bench, path) {
            Ok(c) => println!("\n== log\n  {} ({c})", path.display()),
            Err(e) => {
                println!("\n== log\n  failed: {e}");
                status = ExitCode::FAILURE;
            }
        }
    }
    status
}

fn print_outcome(args: &Args, cfg: &SessionConfig, out: &Outcome) -> ExitCode {
    let bench = &out.bench;
    if args.lines {
        for l in &bench.lines {
            println!("  [{:8.3} s] {}", l.cycle as f64 / 16e6, l.text);
        }
    } else {
        println!("firmware lines (events; log rows left out):");
        for l in bench.lines.iter().filter(|l| {
            let k = l.text.split_whitespace().next().unwrap_or("");
            !matches!(k, "RES") && classify(l.text.as_bytes()) != Kind::Row
        }) {
            println!("  [{:8.3} s] {}", l.cycle as f64 / 16e6, l.text);
        }
    }
    let sim_s = bench.time_s();
    println!(
        "\nsimulated {:.2} s in {:.2} s wall ({:.1}x real time){}",
        sim_s,
        out.wall_s,
        sim_s / out.wall_s.max(1e-9),
        if bench.machine.resets().is_empty() {
            String::new()
        } else {
            format!(", {} reset(s)", bench.machine.resets().len())
        }
    );
    let mut ok = true;

    println!("\n== identified model (ID line: dynamics from the map's flow to the flow, slm/slm)");
    if let Some(map) = &out.map {
        let flows: Vec<String> = map
            .knots()
            .iter()
            .map(|k| format!("{:.1}", f64::from(*k) / 120.0))
            .collect();
        println!(
            "  map (MAP line): duty {:.2} % + k x {:.2} % -> flow [{}] slm",
            f64::from(map.first()) / 100.0,
            f64::from(map.step()) / 100.0,
            flows.join(", ")
        );
    }
    match &out.id {
        Some(id) => {
            println!("  {}", show_model(&id.model));
            println!(
                "  candidates evaluated {} of {} (exact pruning)",
                id.evaluated, id.candidates
            );
        }
        None => {
            println!("  none");
            ok = false;
        }
    }
    if let (Some(id), Some(est)) = (&out.id, &out.estimation) {
        println!(
            "  operating point: EXCITE y0 = {} counts, from the served frames {:?}",
            est.y0, est.y0_frames
        );
        match session::host_search(est) {
            Ok(host) => {
                let err = session::coefficient_error(&id.model, &host.model);
                println!(
                    "  host rerun (IntGram + Search<f64> on the {} samples served): {}",
                    est.len(),
                    match err {
                        Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                        None => format!("DIFFERENT: {}", show_model(&host.model)),
                    }
                );
            }
            Err(e) => println!("  host rerun failed: {e}"),
        }
        if let Ok(h32) = session::host_search_in::<f32>(est) {
            println!(
                "  host rerun in f32 (as the firmware computes): {}",
                match session::coefficient_error(&id.model, &h32.model) {
                    Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                    None => format!("DIFFERENT: {}", show_model(&h32.model)),
                }
            );
        }
    } else if let Some(est) = &out.estimation {
        for (name, r) in [
            ("f64", session::host_search(est)),
            ("f32", session::host_search_in::<f32>(est)),
        ] {
            match r {
                Ok(h) => println!(
                    "  host ({name}) on the first record the firmware saw: {}",
                    show_model(&h.model)
                ),
                Err(e) => println!("  host ({name}) on the first record: {e}"),
            }
        }
    } else if out.id.is_some() {
        println!("  (estimation record could not be rebuilt from the logs)");
    }

    println!("\n== validation");
    if let Some(a) = &out.accept {
        println!(
            "  firmware: ACCEPT free-run fit {} %, rmse {} slm, one-step rmse {} slm",
            a.get("fit").unwrap_or("?"),
            a.get("rmse").unwrap_or("?"),
            a.get("one").unwrap_or("?")
        );
    }
    for r in &out.rejects {
        println!(
            "  firmware: REJECT {}",
            r.fields
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    let mut panels = Vec::new();
    if let Some(model) = out.id.as_ref().and_then(|id| id.model.arx().ok()) {
        if let Some(val) = &out.validation {
            let (free, one, trace) = session::score(&model, val);
            println!(
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
        let latency = out
            .estimation
            .as_ref()
            .map_or(2, |e| session::write_latency(bench, e));
        let fresh = session::fresh_record(
            &cfg.bench.pump,
            cfg.bench.lung.as_ref(),
            &cfg.bench.sensor,
            cfg.bench.seed.wrapping_add(1000),
            FRESH_RECORD,
            out.map,
            3_000,
            latency,
        );
        let (free, one, trace) = session::score(&model, &fresh);
        println!(
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
    if !panels.is_empty() {
        if let Some(dir) = args.png.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        match session::plot(&args.png, &panels) {
            Ok(()) => println!("  plot: {}", args.png.display()),
            Err(e) => println!("  plot failed: {e}"),
        }
    }

    if cfg.track_s > 0.0 && !print_tracking(args, out) {
        ok = false;
    }

    println!("\n== cycles (16 MHz; tick = 10 ms = {TICK_CYCLES} cycles)");
    let t = &out.timing;
    println!(
        "  control (tick ISR -> pump PWM written: sensor read + statistics + PWM) over {} ticks: worst {} cycles ({:.3} ms, at {:.3} s), mean {:.0} cycles ({:.3} ms); budget 1.6 ms",
        t.control_ticks,
        t.control_worst,
        ms(t.control_worst as f64),
        t.control_worst_at as f64 / 16e6,
        t.control_mean,
        ms(t.control_mean)
    );
    println!(
        "  whole tick incl. report lines and persistence over {}: worst {} cycles ({:.3} ms, at {:.3} s), mean {:.0} cycles ({:.3} ms)",
        t.ticks,
        t.worst,
        ms(t.worst as f64),
        t.worst_at as f64 / 16e6,
        t.mean,
        ms(t.mean)
    );
    println!(
        "  CPU load outside the search {:.1} %; missed ticks (overruns) {}; ticks during the blocking search {}, during the blocking design {}",
        100.0 * t.load,
        t.missed,
        t.during_search,
        t.during_design
    );
    if let Some((late, lost)) = t.firmware_missed {
        println!("  firmware's own count: MISSED late={late} lost={lost}");
    }
    match t.search_cycles {
        Some(c) => println!("  search time {} cycles = {:.3} s", c, c as f64 / 16e6),
        None => println!("  search time: n/a"),
    }
    if !out.faults.is_empty() {
        for (c, f) in &out.faults {
            println!(
                "  FAULT at {:.3} s: {} {}",
                *c as f64 / 16e6,
                f.words.join(" "),
                f.fields
                    .iter()
                    .map(|(k, v)| format!("{k}={v}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
        ok = false;
    }

    println!("\n== flash and RAM");
    let s = out.sizes;
    println!(
        "  flash {} B (text {} + data {}) of 256 KB; static RAM {} B (data {} + bss {})",
        s.flash(),
        s.text,
        s.data,
        s.ram(),
        s.data,
        s.bss
    );
    println!(
        "  stack high-water: STACK line {} B, SRAM paint {} B  ->  static RAM + stack {} B of 8192",
        out.stack_used
            .map_or_else(|| "n/a".into(), |v| v.to_string()),
        bench
            .stack_used()
            .map_or_else(|| "n/a".into(), |v| v.to_string()),
        s.ram() + bench.stack_used().or(out.stack_used).unwrap_or(0)
    );
    match simavr_harness::stack::analyze_elf(&cfg.bench.elf) {
        Ok(r) => println!(
            "  worst-case stack over every path (call graph): {} B (main {} + interrupt {})  ->  static RAM + stack {} B (budget 6144){}",
            r.worst(),
            r.main.bytes,
            r.interrupt.bytes,
            s.ram() + r.worst(),
            if r.complete() { "" } else { " [incomplete: recursion or indirect calls]" }
        ),
        Err(e) => println!("  worst-case stack: {e}"),
    }
    if out.accept.is_none() {
        ok = false;
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        println!("\nsimavr-run: the firmware did not identify an accepted model");
        ExitCode::FAILURE
    }
}

/// The flow-control section: the design, run mode rebuilt from the bench and checked against
/// the firmware's TRACK lines, the step and breath figures, the plot and the CSV. `false` when
/// there was no run mode to show.
fn print_tracking(args: &Args, out: &Outcome) -> bool {
    let bench = &out.bench;
    println!("\n== flow control (run mode: the firmware's demo program)");
    if let Some(l) = bench.lines.iter().find(|l| l.text.starts_with("CTRL")) {
        println!("  firmware: {}", l.text);
    }
    let run = match RunTrace::from_bench(bench) {
        Ok(r) => r,
        Err(e) => {
            println!("  no run mode: {e}");
            return false;
        }
    };
    if let Some(c) = run.design_cycles {
        println!(
            "  design (model checks, pole placement, closed-loop checks) at most {} cycles = {:.1} ms; budget 100 ms",
            c,
            ms(c as f64)
        );
    }
    println!(
        "  run mode from {:.3} s, start flow {:.3} slm, setpoint preview {} ticks; {} TRACK lines recomputed from the bench: largest sp/flow difference {:.4} slm, {} misaligned",
        run.first_cycle as f64 / 16e6,
        run.start,
        run.preview,
        run.track_lines,
        run.track_mismatch,
        run.misaligned
    );
    let control: Vec<u64> = bench
        .ticks()
        .iter()
        .filter(|t| t.start >= run.first_cycle)
        .filter_map(|t| t.control)
        .collect();
    if let Some(&worst) = control.iter().max() {
        println!(
            "  control tick in run mode (ISR -> PWM written, incl. the controller) over {} ticks: worst {} cycles ({:.3} ms), mean {:.3} ms; budget 1.6 ms",
            control.len(),
            worst,
            ms(worst as f64),
            ms(control.iter().sum::<u64>() as f64 / control.len() as f64)
        );
    }
    match run.scores() {
        Some(sc) => {
            println!("  steps (true flow; rise 10-90 %, overshoot of the step, settling to +-max(2 %, 1 slm), steady-state error over the last 0.5 s, IAE over the level):");
            let mut from = run.start;
            for (m, to) in sc.steps.iter().zip(&sc.levels) {
                match m {
                    Some(m) => println!(
                        "    {:6.2} -> {:6.2} slm: rise {}, overshoot {:5.1} %, settling {}, steady-state error {:+.3} slm, IAE {:.3} slm s",
                        from,
                        to,
                        m.rise_s.map_or("  n/a  ".into(), |v| format!("{v:.3} s")),
                        m.overshoot_pct,
                        m.settling_s.map_or("  n/a  ".into(), |v| format!("{v:.3} s")),
                        m.ss_error,
                        m.iae
                    ),
                    None => println!("    {from:6.2} -> {to:6.2} slm: n/a"),
                }
                from = *to;
            }
            let peak = ridge_pump_firmware::setpoint::DEMO_BREATH.peak;
            println!(
                "  breaths 2-6 (square, 20/min, peak {} slm): RMS error {:.3} slm = {:.1} % of peak",
                peak,
                sc.breath_rms,
                pump_sim::baseline::table::breath_pct(sc.breath_rms)
            );
            println!("  duty total variation {:.0} %/s", 100.0 * sc.duty_tv);
        }
        None => println!(
            "  run mode too short to score ({} intervals; the demo needs {})",
            run.trace.setpoint.len(),
            run_ticks()
        ),
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
    if let Some(dir) = args.track_png.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let title = format!(
        "ATmega2560 in simavr, {}: setpoint vs true flow (slm), duty below",
        args.plant.describe()
    );
    match ridge_id::plot::write_control_png(
        &args.track_png,
        &ridge_id::plot::Axes::pump(),
        &title,
        &step,
    ) {
        Ok(()) => println!("  plot: {}", args.track_png.display()),
        Err(e) => println!("  plot failed: {e}"),
    }
    if let Some(path) = &args.trace {
        match run.write_csv(path) {
            Ok(()) => println!("  trace: {} ({} ticks)", path.display(), run.rows.len()),
            Err(e) => {
                println!("  trace failed: {e}");
                return false;
            }
        }
    }
    true
}
