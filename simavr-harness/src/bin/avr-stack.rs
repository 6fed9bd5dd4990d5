//! Worst-case stack of an AVR ELF by static analysis (call graph of `avr-objdump -d`, see
//! `simavr_harness::stack`), and the SRAM budget check: static RAM + worst-case stack.
//!
//! Usage: `avr-stack ELF [--budget BYTES] [--path]`; exits 1 when static RAM + stack exceeds
//! the budget (default 6144) or the analysis is incomplete (recursion, indirect calls).

use simavr_harness::firmware::sizes;
use simavr_harness::stack::analyze_elf;
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut elf: Option<PathBuf> = None;
    let mut budget: u32 = 6144;
    let mut show_path = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--budget" => match args.next().and_then(|v| v.parse().ok()) {
                Some(b) => budget = b,
                None => {
                    eprintln!("avr-stack: --budget needs a number of bytes");
                    return ExitCode::from(2);
                }
            },
            "--path" => show_path = true,
            "-h" | "--help" => {
                println!("usage: avr-stack ELF [--budget BYTES] [--path]");
                return ExitCode::SUCCESS;
            }
            _ => elf = Some(PathBuf::from(a)),
        }
    }
    let Some(elf) = elf else {
        eprintln!("usage: avr-stack ELF [--budget BYTES] [--path]");
        return ExitCode::from(2);
    };
    let (report, sizes) = match (analyze_elf(&elf), sizes(&elf)) {
        (Ok(r), Ok(s)) => (r, s),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("avr-stack: {e}");
            return ExitCode::from(2);
        }
    };
    let total = sizes.ram() + report.worst();
    println!(
        "           stack  {:5} B worst case (call graph: main {} B + interrupt {} B)",
        report.worst(),
        report.main.bytes,
        report.interrupt.bytes
    );
    println!(
        "           SRAM   {:5} B static RAM + stack, limit {budget}",
        total
    );
    if show_path {
        for (name, own) in &report.main.frames {
            println!("             {own:5} B  {name}");
        }
    }
    let mut ok = true;
    if !report.complete() {
        eprintln!(
            "avr-stack: incomplete bound: recursion {:?}, indirect calls {:?}, pushes past the prologue {:?}",
            report.recursive, report.indirect, report.late_pushes
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
