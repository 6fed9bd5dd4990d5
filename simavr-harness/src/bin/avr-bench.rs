//! Runs `avr-bench` images (firmware/src/bin/avr-bench.rs, one per variant, built by
//! `scripts/avr-bench`) in simavr at 16 MHz and prints, for each measurement, the core cycles
//! and stack bytes of the routine, and for each image its flash and static RAM next to the
//! `empty` image's: the figures of `docs/hand-written.md`.
//!
//! - Cycles: simavr's cycle counter at the two edges of the marker pin PB7 that the image
//!   raises before and lowers after the call; `net` subtracts the `empty` image's bare call
//!   (`empty/call`).
//! - Stack: at the rising edge every SRAM byte from the end of static RAM (`__heap_start`, or
//!   `__bss_end`) up to the stack pointer is painted `0xAA`; at the falling edge the lowest byte
//!   that no longer holds the paint is the deepest the routine reached (its return address
//!   included).
//! - Results: the words the image prints after each measurement are checked here (datasheet
//!   CRC vectors and check values, ring contents, `{:.4}` of the printed floats, the backward
//!   error of the Cholesky solution in `f64`, the eigenvalues against a two-sided Jacobi in
//!   `f64`). A failed check is shown, not hidden.
//!
//! Usage: `avr-bench ELF...` (the file stem names the variant; include `empty.elf`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use simavr_harness::firmware::{sizes, Sizes};
use simavr_harness::machine::{Halt, Machine};

/// Measures avr-bench images in simavr (ATmega2560, 16 MHz).
#[derive(Parser, Debug)]
#[command(name = "avr-bench")]
struct Args {
    /// avr-bench ELFs, one per variant (file stem = variant); `empty.elf` is the baseline.
    #[arg(required = true)]
    elfs: Vec<PathBuf>,
    /// Simulated-cycle limit per image.
    #[arg(long, default_value_t = 400_000_000)]
    max_cycles: u64,
}

const PAINT: u8 = 0xAA;
const SRAM_START: u16 = 0x200;

/// One marker pulse: cycles between the edges and stack bytes below the SP at the rising edge.
#[derive(Clone, Copy, Debug)]
struct Pulse {
    cycles: u64,
    stack: u16,
}

/// One measurement: the image's `M` line and its pulse.
#[derive(Clone, Debug)]
struct Measurement {
    variant: String,
    label: String,
    words: Vec<String>,
    pulse: Pulse,
}

struct Image {
    name: String,
    sizes: Sizes,
    /// Code of the timed routines.
    code: Code,
    measurements: Vec<Measurement>,
    error: Option<String>,
}

fn run(
    elf: &std::path::Path,
    max_cycles: u64,
) -> Result<(Vec<Measurement>, Option<String>), String> {
    let mut m = Machine::new("atmega2560", 16_000_000, elf)?;
    let pin = m.watch_pin('B', 7);
    let s = sizes(elf)?;
    let bottom = m
        .symbol("__heap_start")
        .or_else(|| m.symbol("__bss_end"))
        .map(|s| (s.addr & 0xFFFF) as u16)
        .unwrap_or(SRAM_START + (s.ram() as u16));
    let mut pulses = Vec::new();
    let mut seen = 0;
    let mut rise: Option<(u64, u16)> = None;
    let mut problem = None;
    loop {
        let halt = m.step();
        let edges = pin.borrow().clone();
        for e in &edges[seen..] {
            if e.high {
                let sp = m.sp();
                for a in bottom..=sp {
                    m.poke(a, PAINT);
                }
                rise = Some((e.cycle, sp));
            } else if let Some((c0, sp)) = rise.take() {
                let mut lowest = sp + 1;
                for a in bottom..=sp {
                    if m.data(a) != PAINT {
                        lowest = a;
                        break;
                    }
                }
                pulses.push(Pulse {
                    cycles: e.cycle - c0,
                    stack: sp + 1 - lowest,
                });
            }
        }
        seen = edges.len();
        match halt {
            Halt::Reached if m.cycle() < max_cycles => {}
            Halt::Reached => {
                problem = Some(format!("no DONE within {max_cycles} cycles"));
                break;
            }
            Halt::Done => break,
            Halt::Crashed => {
                problem = Some(format!("crashed at pc {:#x}", m.pc()));
                break;
            }
        }
    }
    let text: Vec<u8> = m.uart0().borrow().iter().map(|b| b.byte).collect();
    let text = String::from_utf8_lossy(&text).into_owned();
    if !text.lines().any(|l| l == "DONE") && problem.is_none() {
        problem = Some(format!("no DONE line; UART: {text:?}"));
    }
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with("M ")).collect();
    if lines.len() != pulses.len() {
        problem = Some(format!(
            "{} measurement lines but {} marker pulses",
            lines.len(),
            pulses.len()
        ));
    }
    let measurements = lines
        .iter()
        .zip(pulses)
        .map(|(line, pulse)| {
            let mut w = line.split_whitespace().skip(1);
            Measurement {
                variant: w.next().unwrap_or("?").to_string(),
                label: w.next().unwrap_or("?").to_string(),
                words: w.map(str::to_string).collect(),
                pulse,
            }
        })
        .collect();
    Ok((measurements, problem))
}

// ---------------------------------------------------------------------- code size

/// Families of the timed routines (`<family>_<variant>` in the image).
const FAMILIES: [&str; 9] = [
    "sqrt_", "chol_", "eig_", "push_", "pop_", "crc8_", "crc32_", "fmt_", "reid_",
];

/// The timed routine a (Rust v0) mangled symbol names, if any: an identifier `<len><family>_…`.
fn routine(symbol: &str) -> Option<&str> {
    for family in FAMILIES {
        for (at, _) in symbol.match_indices(family) {
            let digits = symbol[..at]
                .bytes()
                .rev()
                .take_while(u8::is_ascii_digit)
                .count();
            let Ok(len) = symbol[at - digits..at].parse::<usize>() else {
                continue;
            };
            let ident = symbol.get(at..at + len)?;
            if ident
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
            {
                return Some(ident);
            }
        }
    }
    None
}

/// Code bytes of the image's timed routines: their own functions, and everything they reach
/// through calls and jumps (helpers such as the float and 64-bit arithmetic routines, `memcpy`;
/// from the `avr-objdump -d` call graph, sizes from `avr-nm -S`); `true` when an indirect call
/// was met on the way (then the second figure is a lower bound).
fn code_size(elf: &std::path::Path) -> Result<Code, String> {
    let run = |tool: &str, args: &[&str]| -> Result<String, String> {
        let out = std::process::Command::new(tool)
            .args(args)
            .arg(elf)
            .output()
            .map_err(|e| format!("{tool}: {e}"))?;
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let funcs = simavr_harness::stack::parse(&run("avr-objdump", &["-d"])?);
    let mut size: std::collections::HashMap<String, u32> = std::collections::HashMap::new();
    for line in run("avr-nm", &["-S"])?.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if let [_, sz, kind, name] = f[..] {
            if kind.eq_ignore_ascii_case("t") || kind.eq_ignore_ascii_case("w") {
                let sz = u32::from_str_radix(sz, 16).unwrap_or(0);
                size.insert(name.to_string(), sz);
            }
        }
    }
    let roots: Vec<&String> = funcs.keys().filter(|n| routine(n).is_some()).collect();
    let own = roots
        .iter()
        .map(|n| size.get(*n).copied().unwrap_or(0))
        .sum();
    let mut seen: std::collections::BTreeSet<&String> = roots.iter().copied().collect();
    let mut todo: Vec<&String> = roots.clone();
    while let Some(n) = todo.pop() {
        if let Some(f) = funcs.get(n) {
            for c in f.callees.iter().chain(f.jumps.iter()) {
                if seen.insert(c) {
                    todo.push(c);
                }
            }
        }
    }
    let reach = seen
        .iter()
        .map(|n| size.get(*n).copied().unwrap_or(0))
        .sum();
    let indirect = seen
        .iter()
        .any(|n| funcs.get(*n).is_some_and(|f| f.indirect > 0));
    Ok(Code {
        own,
        reach,
        indirect,
    })
}

/// See [`code_size`].
#[derive(Clone, Copy, Debug, Default)]
struct Code {
    own: u32,
    reach: u32,
    indirect: bool,
}

// ---------------------------------------------------------------------- result checks

/// The image's Cholesky problem (see `problem` in firmware/src/bin/avr-bench.rs), in f64.
fn chol_problem(n: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    let m = |i: usize, j: usize| -> f64 {
        if j == i {
            4.0
        } else if j < i {
            ((5 * i + 3 * j) % 3) as f64 - 1.0
        } else {
            0.0
        }
    };
    let a = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| (0..n).map(|k| m(i, k) * m(j, k)).sum())
                .collect()
        })
        .collect();
    let b = (0..n).map(|i| i as f64 - 6.0).collect();
    (a, b)
}

/// Normwise backward error `‖A x − b‖∞ / (‖A‖∞ ‖x‖∞ + ‖b‖∞)` of the printed solution.
fn chol_check(n: usize, words: &[String]) -> String {
    if words.first().map(String::as_str) != Some("1") {
        return "FAILED: not positive definite".into();
    }
    let x: Vec<f64> = words[1..]
        .iter()
        .filter_map(|w| w.parse::<u32>().ok())
        .map(|b| f64::from(f32::from_bits(b)))
        .collect();
    if x.len() != n {
        return format!("FAILED: {} values for n = {n}", x.len());
    }
    let (a, b) = chol_problem(n);
    let inf = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let r: Vec<f64> = (0..n)
        .map(|i| (0..n).map(|j| a[i][j] * x[j]).sum::<f64>() - b[i])
        .collect();
    let norm_a = a
        .iter()
        .map(|row| row.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let eta = inf(&r) / (norm_a * inf(&x) + inf(&b));
    format!("backward error {eta:.1e} (f32 eps 6.0e-8)")
}

/// The image's eigen-decomposition problem (see `eig_problem` in firmware/src/bin/avr-bench.rs):
/// the same `f32` values, formed by the same operations, widened.
fn eig_problem(n: usize) -> Vec<Vec<f64>> {
    let rho = 0.99f32;
    let s = (1.0 - rho * rho).sqrt();
    let mut pow = vec![1.0f32; n];
    for k in 1..n {
        pow[k] = pow[k - 1] * rho;
    }
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| match j {
                    0 => f64::from(pow[i]),
                    j if j <= i => f64::from(pow[i - j] * s),
                    _ => 0.0,
                })
                .collect()
        })
        .collect()
}

/// Eigenvalues of the symmetric `b` (ascending) by cyclic two-sided Jacobi in `f64`: a different
/// method, and 2⁻⁵² against the images' 2⁻²³.
fn jacobi_eigenvalues(mut b: Vec<Vec<f64>>) -> Vec<f64> {
    let n = b.len();
    for _ in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| b[i][j] * b[i][j])
            .sum();
        if off < 1e-60 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if b[p][q] == 0.0 {
                    continue;
                }
                let theta = (b[q][q] - b[p][p]) / (2.0 * b[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in b.iter_mut() {
                    let (bkp, bkq) = (row[p], row[q]);
                    row[p] = c * bkp - s * bkq;
                    row[q] = s * bkp + c * bkq;
                }
                let (rp, rq) = (b[p].clone(), b[q].clone());
                for (k, (bpk, bqk)) in rp.iter().zip(&rq).enumerate() {
                    b[p][k] = c * bpk - s * bqk;
                    b[q][k] = s * bpk + c * bqk;
                }
            }
        }
    }
    let mut e: Vec<f64> = (0..n).map(|i| b[i][i]).collect();
    e.sort_by(f64::total_cmp);
    e
}

/// The printed eigenvalues of `M Mᵀ` against the `f64` ones: the largest relative error, and
/// that of the smallest eigenvalue.
fn eig_check(n: usize, words: &[String]) -> String {
    if words.first().map(String::as_str) != Some("1") {
        return "FAILED: no decomposition".into();
    }
    let mut got: Vec<f64> = words[1..]
        .iter()
        .filter_map(|w| w.parse::<u32>().ok())
        .map(|b| f64::from(f32::from_bits(b)))
        .collect();
    if got.len() != n {
        return format!("FAILED: {} values for n = {n}", got.len());
    }
    got.sort_by(f64::total_cmp);
    let m = eig_problem(n);
    let b = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| (0..n).map(|k| m[i][k] * m[j][k]).sum())
                .collect()
        })
        .collect();
    let want = jacobi_eigenvalues(b);
    let rel: Vec<f64> = got
        .iter()
        .zip(&want)
        .map(|(g, w)| (g - w).abs() / w)
        .collect();
    format!(
        "eigenvalues {:.1e}..{:.1e}: relative error max {:.1e}, of the smallest {:.1e}",
        want[0],
        want[n - 1],
        rel.iter().fold(0.0f64, |a, &b| a.max(b)),
        rel[0]
    )
}

fn expect(words: &[String], want: &[&str]) -> String {
    let got: Vec<&str> = words.iter().map(String::as_str).collect();
    if got == want {
        format!("ok {}", got.join(" "))
    } else {
        format!("FAILED: got {got:?}, want {want:?}")
    }
}

const FMT_VALUES: [f32; 6] = [-1.9472, 273.0671, -0.5, 0.00049, 1.00005, -12345.678];

fn check(m: &Measurement) -> String {
    let family = m.variant.split('-').next().unwrap_or("");
    match (family, m.label.as_str()) {
        ("empty", _) => String::new(),
        ("sqrt", _) => expect(&m.words, &[2.0f32.sqrt().to_bits().to_string().as_str()]),
        ("chol", l) => chol_check(if l == "chol12" { 12 } else { 13 }, &m.words),
        ("eig", l) => eig_check(if l == "eig8" { 8 } else { 12 }, &m.words),
        ("ring", "push") => expect(&m.words, &["1"]),
        ("ring", "pop") => expect(&m.words, &["0"]),
        // 255 bytes into an empty queue of capacity 255; 0 + 1 + … + 254 = 32385.
        ("ring", "burst255") => expect(&m.words, &["255", "32385"]),
        // Frame accepted; [BE EF] → 0x13, [80 00] → 0x23 (datasheet); "123456789" → 0xA2.
        ("crc8", _) => expect(&m.words, &["1", "19", "35", "162"]),
        ("crc32", _) => {
            let rec: Vec<u8> = (0..65u8)
                .map(|i| i.wrapping_mul(37).wrapping_add(11))
                .collect();
            let want = ridge_pump_firmware::persist::crc32(&rec).to_string();
            expect(&m.words, &[want.as_str(), "3421780262"]) // 0xCBF43926
        }
        ("fmt", l) => {
            let i: usize = l.trim_start_matches('f').parse().unwrap_or(0);
            let v = FMT_VALUES.get(i).copied().unwrap_or(f32::NAN);
            let want = format!("{v:.4}");
            let got = m.words.join(" ");
            if got == want {
                format!("ok {got}")
            } else if got.chars().all(|c| c.is_ascii_graphic()) {
                format!("WRONG {got} (value {want})")
            } else {
                let shown: String = got.escape_debug().take(24).collect();
                format!("GARBAGE {} bytes \"{shown}…\" (value {want})", got.len())
            }
        }
        _ => m.words.join(" "),
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    let mut images = Vec::new();
    for elf in &args.elfs {
        let name = elf
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let sizes = match sizes(elf) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("avr-bench: {e}");
                return ExitCode::from(2);
            }
        };
        let code = code_size(elf).unwrap_or_default();
        let (measurements, error) = match run(elf, args.max_cycles) {
            Ok(r) => r,
            Err(e) => (Vec::new(), Some(e)),
        };
        images.push(Image {
            name,
            sizes,
            code,
            measurements,
            error,
        });
    }
    let base = images.iter().find(|i| i.name == "empty");
    let base_sizes = base.map(|i| i.sizes).unwrap_or_default();
    let base_call = base
        .and_then(|i| i.measurements.first())
        .map(|m| m.pulse)
        .unwrap_or(Pulse {
            cycles: 0,
            stack: 0,
        });

    println!("ATmega2560 at 16 MHz in simavr; flash = text + data, RAM = data + bss (static).");
    println!(
        "Sizes relative to the empty image (flash {} B, data {} B, bss {} B).",
        base_sizes.flash(),
        base_sizes.data,
        base_sizes.bss
    );
    println!(
        "Cycles and stack: marker to marker (net: minus the empty call, {} cycles, {} B).",
        base_call.cycles, base_call.stack
    );
    println!();
    println!(
        "flash+, data+, bss+: the image minus the empty image (the routine and its measurement"
    );
    println!(
        "glue); code: the timed routines' own functions / with all they call (>=: indirect calls,"
    );
    println!("whose targets are not counted).");
    println!();
    println!(
        "{:<16} {:>7} {:>6} {:>5} {:>11}  {:<9} {:>8} {:>8} {:>5} {:>5}  check",
        "variant", "flash+", "data+", "bss+", "code", "label", "cycles", "net", "stack", "net"
    );
    let mut failed = false;
    for img in &images {
        let d = |a: u32, b: u32| i64::from(a) - i64::from(b);
        let head = format!(
            "{:<16} {:>7} {:>6} {:>5} {:>11}",
            img.name,
            d(img.sizes.flash(), base_sizes.flash()),
            d(img.sizes.data, base_sizes.data),
            d(img.sizes.bss, base_sizes.bss),
            format!(
                "{}/{}{}",
                img.code.own,
                if img.code.indirect { ">=" } else { "" },
                img.code.reach
            )
        );
        if img.measurements.len() <= usize::from(img.name != "empty") {
            println!("{head}  (no measurement)");
        }
        let shown = img
            .measurements
            .iter()
            .filter(|m| m.label != "call" || img.name == "empty");
        for (k, m) in shown.enumerate() {
            let c = check(m);
            let label = if m.variant == img.name {
                m.label.clone()
            } else {
                format!("{}/{}", m.variant, m.label)
            };
            failed |= c.starts_with("FAILED");
            println!(
                "{:<49}  {:<9} {:>8} {:>8} {:>5} {:>5}  {}",
                if k == 0 { head.as_str() } else { "" },
                label,
                m.pulse.cycles,
                m.pulse.cycles as i64 - base_call.cycles as i64,
                m.pulse.stack,
                i32::from(m.pulse.stack) - i32::from(base_call.stack),
                c
            );
        }
        if let Some(e) = &img.error {
            println!("  {}: {e}", img.name);
            failed = true;
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
