//! Checks that linker relaxation changed no control flow of an AVR image (see
//! `simavr_harness::relax`): compares the image linked without relaxation (the linker
//! wrapper's `<elf>.norelax`) with the relaxed one.
//!
//! Usage: `avr-relax-check PLAIN_ELF RELAXED_ELF`; exits 1 listing the functions that differ,
//! 2 when an ELF cannot be disassembled.

use simavr_harness::relax::compare;
use simavr_harness::stack::disassemble;
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [plain, relaxed] = args.as_slice() else {
        eprintln!("usage: avr-relax-check PLAIN_ELF RELAXED_ELF");
        return ExitCode::from(2);
    };
    let (a, b) = match (disassemble(plain), disassemble(relaxed)) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("avr-relax-check: {e}");
            return ExitCode::from(2);
        }
    };
    let problems = compare(&a, &b);
    if problems.is_empty() {
        let functions = a.lines().filter(|l| l.ends_with(">:")).count();
        println!("           relax   control flow unchanged ({functions} functions)");
        ExitCode::SUCCESS
    } else {
        for p in &problems {
            eprintln!("avr-relax-check: {p}");
        }
        ExitCode::FAILURE
    }
}
