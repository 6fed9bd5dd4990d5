//! Prints the analogues of the paper's Tables 1–5 on simulated pump records, as markdown.
//!
//! ```text
//! cargo run --release -p pump-sim --bin paper-tables -- [--seed N] [--markdown-out PATH]
//! ```
//!
//! The computations live in `pump_sim::paper`; this binary only parses flags and prints.

use std::process::ExitCode;
use std::time::Instant;

use pump_sim::paper::{render_markdown, run, DEFAULT_SEED};

const USAGE: &str = "usage: paper-tables [--seed N] [--markdown-out PATH]";

struct Args {
    seed: u64,
    markdown_out: Option<String>,
}

fn parse(mut it: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut args = Args {
        seed: DEFAULT_SEED,
        markdown_out: None,
    };
    while let Some(a) = it.next() {
        let (flag, inline) = match a.split_once('=') {
            Some((f, v)) => (f.to_string(), Some(v.to_string())),
            None => (a, None),
        };
        let mut value = |name: &str| {
            inline
                .clone()
                .or_else(|| it.next())
                .ok_or_else(|| format!("{name} needs a value\n{USAGE}"))
        };
        match flag.as_str() {
            "--seed" => {
                let v = value("--seed")?;
                args.seed = v
                    .parse()
                    .map_err(|_| format!("--seed: not an unsigned integer: {v}\n{USAGE}"))?;
            }
            "--markdown-out" => args.markdown_out = Some(value("--markdown-out")?),
            "-h" | "--help" => return Err(USAGE.to_string()),
            other => return Err(format!("unknown argument: {other}\n{USAGE}")),
        }
    }
    Ok(args)
}

fn main() -> ExitCode {
    let args = match parse(std::env::args().skip(1)) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let start = Instant::now();
    let report = match run(args.seed) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("paper-tables: {e}");
            return ExitCode::FAILURE;
        }
    };
    let md = render_markdown(&report);
    print!("{md}");
    if let Some(path) = &args.markdown_out {
        if let Err(e) = std::fs::write(path, &md) {
            eprintln!("paper-tables: cannot write {path}: {e}");
            return ExitCode::FAILURE;
        }
    }
    eprintln!(
        "paper-tables: seed {}, computed in {:.3} s",
        args.seed,
        start.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
