//! Runs the STM32F411 release image in the emulated chip against the simulated blower (into a
//! test lung, optionally) and SFM3300 (`scripts/simulate --board stm32f411` calls this) and
//! prints the report `simavr-run` prints for the ATmega2560 (`harness_kit::report`): what the
//! firmware identified and the host's rerun of its search, the validation, the design and how
//! it tracked its setpoint program, instructions per control tick, of the search and of the
//! design, flash and RAM; writes a PNG of measured vs model flow, a PNG of setpoint vs flow,
//! with `--trace` a per-tick CSV, and with `--log` the console's CSV log as `ridge-id capture`
//! writes it.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use pump_sim::baseline::experiment::run_ticks;
use pump_sim::PlantArgs;
use stm32_harness::session::{self, SessionConfig};
use stm32_harness::{firmware, report};

/// Power-up self-identification of the STM32F411 image in Unicorn (100 MHz), closed loop with
/// a simulated SFM3300 (I2C1, 0x40) and blower.
#[derive(Parser, Debug)]
#[command(name = "stm32-run")]
struct Args {
    /// Firmware ELF (default: target/thumbv7em-none-eabihf/release/stm32f411, built if
    /// missing or stale).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Blower and test lung.
    #[command(flatten)]
    plant: PlantArgs,
    /// Sensor noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Emulated-time limit, seconds.
    #[arg(long, default_value_t = 200.0)]
    max_s: f64,
    /// Seconds of run mode after the design (default: the demo program's, plus 0.5 s); 0
    /// stops after ACCEPT.
    #[arg(long, value_name = "SECONDS")]
    track_s: Option<f64>,
    /// PNG of measured vs model flow.
    #[arg(long, default_value = "target/stm32/flow.png")]
    png: PathBuf,
    /// PNG of the setpoint vs the flow in run mode.
    #[arg(long, default_value = "target/stm32/tracking.png")]
    track_png: PathBuf,
    /// Write every tick as CSV `t,setpoint,duty,flow` (s, slm or empty before run mode,
    /// duty 0..1, true flow in slm).
    #[arg(long, value_name = "PATH")]
    trace: Option<PathBuf>,
    /// Print every line (log rows too).
    #[arg(long)]
    lines: bool,
    /// Send `LOG on` once the firmware printed its first line and write what it streamed to
    /// PATH as `ridge-id capture` does.
    #[arg(long, value_name = "PATH")]
    log: Option<PathBuf>,
    /// Run every poll iteration instead of jumping the clock to the next event (slow: for
    /// checking the jump).
    #[arg(long)]
    no_jump: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let elf = match args.elf.clone().map_or_else(firmware::ensure_elf, Ok) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("stm32-run: {e}");
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
            eprintln!("stm32-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    cfg.track_s = args.track_s.unwrap_or(f64::from(run_ticks()) * 0.01 + 0.5);
    cfg.log = args.log.is_some();
    cfg.clock_jump = !args.no_jump;
    println!(
        "stm32: STM32F411 @ 100 MHz in Unicorn, {}, {}, sensor seed {}",
        elf.display(),
        args.plant.describe(),
        args.seed
    );
    let out = match session::run(&cfg) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("stm32-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    let opts = report::Options {
        all_lines: args.lines,
        png: args.png.clone(),
        track_png: args.track_png.clone(),
        trace: args.trace.clone(),
        plant: args.plant.describe(),
    };
    let (text, ok) = report::render(&out, &cfg, &opts);
    print!("{text}");
    let mut status = if ok {
        ExitCode::SUCCESS
    } else {
        println!("\nstm32-run: the firmware did not identify an accepted model cleanly");
        ExitCode::FAILURE
    };
    if let Some(path) = &args.log {
        match session::write_capture(&out.bench, path) {
            Ok(c) => println!("\n== log\n  {} ({c})", path.display()),
            Err(e) => {
                println!("\n== log\n  failed: {e}");
                status = ExitCode::FAILURE;
            }
        }
    }
    status
}
