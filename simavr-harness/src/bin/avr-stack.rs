//! Worst-case stack of an AVR ELF by static analysis (call graph of `avr-objdump -d`, see
//! `simavr_harness::stack`), and the SRAM budget check: static RAM + worst-case stack.
//!
//! Usage: `avr-stack ELF [--budget BYTES] [--path]`; exits 1 when static RAM + stack exceeds
//! the budget (default 6144), the analysis is incomplete (recursion, indirect calls) or a
//! function uses arguments passed on the stack (read one byte off on the ATmega2560, see
//! `simavr_harness::stack`), 2 on a usage error or an ELF that cannot be read or
//! disassembled.

use clap::Parser;
use simavr_harness::firmware::sizes;
use simavr_harness::stack::analyze_elf;
use std::path::PathBuf;
use std::process::ExitCode;

/// Worst-case stack of an AVR ELF from its call graph (`avr-objdump -d`), and the SRAM budget
/// check: static RAM (`.data + .bss + .noinit`) + worst-case stack ≤ `--budget`.
#[derive(Parser, Debug)]
#[command(name = "avr-stack")]
struct Args {
    /// The AVR ELF to analyse.
    elf: PathBuf,
    /// SRAM budget for static RAM + worst-case stack, bytes.
    #[arg(long, value_name = "BYTES", default_value_t = 6144)]
    budget: u32,
    /// Also print the deepest call path from `main`, one function and its own frame per line.
    #[arg(long)]
    path: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let (analysis, sizes) = match (analyze_elf(&args.elf), sizes(&args.elf)) {
        (Ok(r), Ok(s)) => (r, s),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("avr-stack: {e}");
            return ExitCode::from(2);
        }
    };
    let budget = args.budget;
    let total = sizes.ram() + analysis.worst();
    println!(
        "           stack  {:5} B worst case (call graph: main {} B + interrupt {} B)",
        analysis.worst(),
        analysis.main.bytes,
        analysis.interrupt.bytes
    );
    println!(
        "           SRAM   {:5} B static RAM + stack, limit {budget}",
        total
    );
    if args.path {
        for (name, own) in &analysis.main.frames {
            println!("             {own:5} B  {name}");
        }
    }
    let mut ok = true;
    if !analysis.complete() {
        eprintln!(
            "avr-stack: incomplete bound: recursion {:?}, indirect calls {:?}, pushes past the prologue {:?}",
            analysis.recursive, analysis.indirect, analysis.late_pushes
        );
        ok = false;
    }
    if !analysis.stack_arguments.is_empty() {
        eprintln!(
            "avr-stack: arguments passed on the stack (addressed one byte off on the ATmega2560): {:?}",
            analysis.stack_arguments
        );
        ok = false;
    }
    if total > budget {
        eprintln!("avr-stack: static RAM + stack {total} B exceeds {budget} B");
        ok = false;
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
