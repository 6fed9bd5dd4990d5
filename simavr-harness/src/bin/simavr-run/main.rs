//! Runs the ATmega2560 firmware in simavr against the simulated pump (optionally into a test
//! lung) and SFM3300 (the main command, `scripts/simulate`, calls this) and prints what the
//! firmware identified, how good the model is, the controller it designed and how it tracked
//! its setpoint program, the cycle figures, flash and RAM; writes a PNG of measured vs model
//! flow, a PNG of setpoint vs flow, with `--trace` a per-tick CSV, and with `--log` the console's
//! CSV log as `ridge-id capture` writes it. With `--mode volume` (`vent.rs`) run mode
//! ventilates: the bench sends `VENT` over the console and reports every breath.

mod vent;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use harness_kit::report::{self, Board, Control, Validation, Work};
use harness_kit::validation;
use pump_sim::baseline::experiment::run_ticks;
use pump_sim::PlantArgs;
use simavr_harness::session::{self, Outcome, SessionConfig};
use simavr_harness::tracking;
use simavr_harness::uart::UartTiming;
use simavr_harness::ventilation::{self, VentConfig};
use simavr_harness::{capture, firmware};
use vent::Mode;

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
    /// Write every tick as CSV `t,setpoint,duty,flow,breath,phase` (s, slm or empty before
    /// run mode, duty 0..1, true flow in slm, breaths the exhalation valve started (0 before
    /// the first), `i` inspiration / `e` expiration / empty before the first breath).
    #[arg(long, value_name = "PATH")]
    trace: Option<PathBuf>,
    /// Volume-controlled ventilation (`--mode volume`).
    #[command(flatten)]
    vent: vent::VentArgs,
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

/// The board as the report names it and counts its work: cycles at 16 MHz, cycle-exact.
fn board() -> Board {
    Board {
        name: "ATmega2560",
        emulator: "simavr",
        unit: "cycles",
        per_s: 16e6,
        clock: "16 MHz".into(),
        control_span: "tick ISR -> pump PWM written: sensor read + statistics + PWM",
        run_control_span: "ISR -> PWM written, incl. the controller",
        tick_budget: "budget 1.6 ms".into(),
        search_kind: "blocking",
    }
}

fn main() -> ExitCode {
    let mut args = Args::parse();
    if let Err(e) = args.vent.fill_plant(&mut args.plant) {
        eprintln!("simavr-run: {e}");
        return ExitCode::from(2);
    }
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
    if args.vent.mode == Mode::Volume {
        return ventilate(&args, cfg);
    }
    let out = match session::run(&cfg) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    let status = print_outcome(&args, &cfg, &out, None);
    write_log(&args, &out, status)
}

/// `--log PATH`: what the firmware streamed after `LOG on`, as `ridge-id capture` writes it;
/// `status` becomes a failure when it cannot be written.
fn write_log(args: &Args, out: &Outcome, status: ExitCode) -> ExitCode {
    let Some(path) = &args.log else {
        return status;
    };
    match capture::write_capture(&out.bench, path) {
        Ok(c) => {
            println!("\n== log\n  {} ({c})", path.display());
            status
        }
        Err(e) => {
            println!("\n== log\n  failed: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `--mode volume`: identify, design, send `VENT`, run the breaths, print.
fn ventilate(args: &Args, cfg: SessionConfig) -> ExitCode {
    let lung = match cfg.bench.lung.clone() {
        Some(l) => l,
        None => {
            eprintln!("simavr-run: --mode volume needs a lung (--lung, --compliance, --iso ...)");
            return ExitCode::from(2);
        }
    };
    let command = match args.vent.command(lung.peep) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::from(2);
        }
    };
    let breath = match ventilation::parse_vent(&command) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::from(2);
        }
    };
    let ti = f64::from(breath.wave.inspiration()) * 0.01;
    let change = match args.vent.change(ti) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::from(2);
        }
    };
    let period = f64::from(breath.wave.period()) * 0.01;
    let mut session = cfg.clone();
    // Identification and design (~70 s), then the breaths and a margin.
    session.max_s = cfg.max_s + period * f64::from(args.vent.breaths + 2);
    let vc = VentConfig {
        session,
        command: command.clone(),
        identify_peep: args.vent.identify_peep,
        peep: lung.peep,
        breaths: args.vent.breaths,
        change,
    };
    println!(
        "simavr: ATmega2560 @ 16 MHz, {}, {}, sensor seed {}; volume control: {command}{}",
        cfg.bench.elf.display(),
        args.plant.describe(),
        args.seed,
        args.vent
            .iso
            .map_or(String::new(), |n| format!(" (ISO 80601-2-12 row {n})"))
    );
    println!(
        "  power-up identification with the PEEP valve at {} cmH2O; PEEP {} cmH2O from VENT on",
        args.vent.identify_peep, lung.peep
    );
    let out = match ventilation::run(&vc) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("simavr-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    let status = print_outcome(args, &vc.session, &out.outcome, Some(out.breath));
    let ok = vent::print(&out, &command, args.vent.breaths);
    let status = if status == ExitCode::SUCCESS && ok {
        ExitCode::SUCCESS
    } else {
        println!("\nsimavr-run: the firmware did not ventilate as asked");
        ExitCode::FAILURE
    };
    write_log(args, &out.outcome, status)
}

fn print_outcome(
    args: &Args,
    cfg: &SessionConfig,
    out: &Outcome,
    vent: Option<ridge_pump_firmware::setpoint::VolumeBreath>,
) -> ExitCode {
    let bench = &out.bench;
    let board = board();
    let mut s = String::new();
    let lines: Vec<(f64, &str)> = bench
        .lines
        .iter()
        .map(|l| (l.cycle as f64 / 16e6, l.text.as_str()))
        .collect();
    report::lines(&mut s, &lines, args.lines);
    let resets = bench.machine.resets().len();
    let extra = if resets == 0 {
        String::new()
    } else {
        format!(", {resets} reset(s)")
    };
    report::run_summary(&mut s, bench.time_s(), out.wall_s, &extra, &[]);
    let mut ok = report::model(
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
        validation::fresh_signal(
            &cfg.bench.pump,
            cfg.bench.lung.as_ref(),
            &cfg.bench.sensor,
            cfg.bench.seed,
            out.map,
            latency,
            session::pwm_fraction,
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
            png: &args.png,
        },
    );

    if cfg.track_s > 0.0 || vent.is_some() {
        let run = match vent {
            Some(b) => tracking::run_trace_ventilated(bench, b),
            None => tracking::run_trace(bench),
        };
        let control = match &run {
            Ok(r) => bench
                .ticks()
                .iter()
                .filter(|t| t.start >= r.first_at)
                .filter_map(|t| t.control)
                .collect(),
            Err(_) => Vec::new(),
        };
        let c = Control {
            ctrl: bench
                .lines
                .iter()
                .find(|l| l.text.starts_with("CTRL"))
                .map(|l| l.text.as_str()),
            run,
            per_s: f64::from(bench.frequency()),
            design: tracking::design_cycles(bench),
            control,
            plant: args.plant.describe(),
            png: &args.track_png,
            trace: args.trace.clone(),
        };
        ok &= report::control(&mut s, &board, &c);
    }

    let t = &out.timing;
    let work = Work {
        control_ticks: t.control_ticks,
        control_worst: (t.control_worst, t.control_worst_at as f64 / 16e6),
        control_mean: t.control_mean,
        control_note: String::new(),
        ticks: t.ticks,
        tick_worst: (t.worst, t.worst_at as f64 / 16e6),
        tick_mean: t.mean,
        load: t.load,
        missed: t.missed,
        during_search: t.during_search,
        during_design: t.during_design,
        firmware_missed: t.firmware_missed,
        search: t.search_cycles,
        faults: out
            .faults
            .iter()
            .map(|(c, f)| (*c as f64 / 16e6, f.clone()))
            .collect(),
    };
    ok &= report::work(&mut s, &board, &work);

    let z = out.sizes;
    let mut stack = vec![format!(
        "stack high-water: STACK line {} B, SRAM paint {} B  ->  static RAM + stack {} B of 8192",
        out.stack_used
            .map_or_else(|| "n/a".into(), |v| v.to_string()),
        bench
            .stack_used()
            .map_or_else(|| "n/a".into(), |v| v.to_string()),
        z.ram() + bench.stack_used().or(out.stack_used).unwrap_or(0)
    )];
    stack.push(match simavr_harness::stack::analyze_elf(&cfg.bench.elf) {
        Ok(r) => format!(
            "worst-case stack over every path (call graph): {} B (main {} + interrupt {})  ->  static RAM + stack {} B (budget 6144){}",
            r.worst(),
            r.main.bytes,
            r.interrupt.bytes,
            z.ram() + r.worst(),
            if r.complete() { "" } else { " [incomplete: recursion or indirect calls]" }
        ),
        Err(e) => format!("worst-case stack: {e}"),
    });
    report::sizes(&mut s, z, "256 KB", &stack);
    print!("{s}");
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
