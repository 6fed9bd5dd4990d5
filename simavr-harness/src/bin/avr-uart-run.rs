//! Runs an ATmega2560 image in simavr (16 MHz) until it prints a given line on USART0 and
//! writes everything USART0 sent to stdout: `scripts/avr-arith-check --above-64k` runs its
//! padded image here, because qemu-system-avr (7.2) reads `ELPM` without RAMPZ and so copies
//! a `.data` that lies above 64 KB of flash from the wrong 64 KB page; simavr honours RAMPZ.
//!
//! Usage: `avr-uart-run ELF [--until LINE] [--max-cycles N]`; prints the cycle count of the
//! line on stderr; exits non-zero when the core crashes or the line does not come within the
//! cycle limit.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use simavr_harness::machine::{Halt, Machine};

/// Runs an ATmega2560 image in simavr and prints its USART0 output.
#[derive(Parser, Debug)]
#[command(name = "avr-uart-run")]
struct Args {
    /// The image (ELF).
    elf: PathBuf,
    /// Stop after USART0 has sent this line (with its line end).
    #[arg(long, default_value = "end")]
    until: String,
    /// Simulated-cycle limit (16 MHz cycles).
    #[arg(long, default_value_t = 2_000_000_000)]
    max_cycles: u64,
}

/// Cycles simulated between two looks at USART0's output.
const CHUNK: u64 = 100_000;

fn main() -> ExitCode {
    let args = Args::parse();
    let mut m = match Machine::new("atmega2560", 16_000_000, &args.elf) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("avr-uart-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    let uart = m.uart0();
    let text = |u: &std::cell::RefCell<Vec<simavr_harness::machine::UartByte>>| {
        String::from_utf8_lossy(&u.borrow().iter().map(|b| b.byte).collect::<Vec<u8>>())
            .into_owned()
    };
    let problem = loop {
        let halt = m.run_until(m.cycle() + CHUNK);
        let out = text(&uart);
        if out
            .split_inclusive('\n')
            .any(|l| l.trim_end_matches(['\r', '\n']) == args.until && l.ends_with('\n'))
        {
            break None;
        }
        match halt {
            Halt::Reached if m.cycle() < args.max_cycles => {}
            Halt::Reached => {
                break Some(format!(
                    "no `{}` line within {} cycles",
                    args.until, args.max_cycles
                ))
            }
            Halt::Done => break Some(format!("the core stopped before `{}`", args.until)),
            Halt::Crashed => break Some(format!("crashed at pc {:#x}", m.pc())),
        }
    };
    let out = text(&uart);
    let mut stdout = std::io::stdout();
    // ok to ignore: a closed stdout only loses the copy the caller asked for.
    let _ = stdout.write_all(out.as_bytes());
    match problem {
        None => {
            eprintln!("avr-uart-run: `{}` after {} cycles", args.until, m.cycle());
            ExitCode::SUCCESS
        }
        Some(p) => {
            eprintln!("avr-uart-run: {p}");
            ExitCode::FAILURE
        }
    }
}
