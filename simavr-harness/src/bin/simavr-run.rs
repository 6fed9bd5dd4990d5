//! Runs the ATmega2560 firmware in simavr against the simulated pump and SFM3300 (the main
//! command, `scripts/simulate`, calls this) and prints what the firmware identified, how good
//! the model is, the cycle figures, flash and RAM, and writes a PNG of measured vs model flow.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, ValueEnum};
use pump_sim::PumpParams;
use ridge_pump_firmware::excitation::Record;
use simavr_harness::firmware;
use simavr_harness::session::{self, IdLine, Outcome, SessionConfig, TICK_CYCLES};

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Plant {
    Default,
    Small,
    Sluggish,
}

/// Power-up self-identification of the ATmega2560 firmware in simavr (16 MHz), closed loop
/// with a simulated SFM3300 (TWI 0x40) and blower.
#[derive(Parser, Debug)]
#[command(name = "simavr-run")]
struct Args {
    /// Firmware ELF (default: target/avr-none/release/atmega2560.elf, built if missing).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Blower model.
    #[arg(long, value_enum, default_value = "default")]
    plant: Plant,
    /// Sensor noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated-time limit, seconds.
    #[arg(long, default_value_t = 200.0)]
    max_s: f64,
    /// PNG of measured vs model flow.
    #[arg(long, default_value = "target/simavr/flow.png")]
    png: PathBuf,
    /// Print every UART line as it arrives.
    #[arg(long)]
    lines: bool,
}

/// Excitation preset of the fresh host-side validation signal (a record the firmware neither
/// estimates nor validates on).
const FRESH_RECORD: Record = Record::BRamp;

fn ms(cycles: f64) -> f64 {
    cycles / 16_000.0
}

fn show_model(m: &IdLine) -> String {
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
    cfg.bench.pump = match args.plant {
        Plant::Default => PumpParams::default(),
        Plant::Small => PumpParams::small(),
        Plant::Sluggish => PumpParams::sluggish(),
    };
    println!(
        "simavr: ATmega2560 @ 16 MHz, {}, plant {:?}, sensor seed {}",
        elf.display(),
        args.plant,
        args.seed
    );
    let out = match session::run(&cfg) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    print_outcome(&args, &cfg, &out)
}

fn print_outcome(args: &Args, cfg: &SessionConfig, out: &Outcome) -> ExitCode {
    let bench = &out.bench;
    if args.lines {
        for l in &bench.lines {
            println!("  [{:8.3} s] {}", l.cycle as f64 / 16e6, l.text);
        }
    } else {
        println!("firmware lines (events):");
        for l in bench.lines.iter().filter(|l| {
            let k = l.text.split_whitespace().next().unwrap_or("");
            !matches!(k, "RES")
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

    println!("\n== identified model (ID line, physical units: slm, duty 0..1)");
    match &out.id {
        Some(id) => {
            println!("  {}", show_model(id));
            if let Some((e, n)) = id.eval {
                println!("  candidates evaluated {e} of {n} (exact pruning)");
            }
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
                let err = session::coefficient_error(id, &host);
                println!(
                    "  host rerun (IntGram + Search<f64> on the {} samples served): {}",
                    est.len(),
                    match err {
                        Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                        None => format!("DIFFERENT: {}", show_model(&host)),
                    }
                );
            }
            Err(e) => println!("  host rerun failed: {e}"),
        }
        if let Ok(h32) = session::host_search_in::<f32>(est) {
            println!(
                "  host rerun in f32 (as the firmware computes): {}",
                match session::coefficient_error(id, &h32) {
                    Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                    None => format!("DIFFERENT: {}", show_model(&h32)),
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
                    show_model(&h)
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
    if let Some(model) = out.id.as_ref().and_then(IdLine::model) {
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
                    val.record.map_or("?", Record::name),
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
            &cfg.bench.sensor,
            cfg.bench.seed.wrapping_add(1000),
            FRESH_RECORD,
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
        "  CPU load outside the search {:.1} %; missed ticks (overruns) {}; ticks during the blocking search {}",
        100.0 * t.load,
        t.missed,
        t.during_search
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
