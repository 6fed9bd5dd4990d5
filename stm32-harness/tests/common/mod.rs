//! Helpers shared by the image tests (each test file is a crate of its own and uses some of
//! them: hence `dead_code` allowed here).
#![allow(dead_code)]

use stm32_harness::bench::{ps, secs, Bench, RunEnd};
use stm32_harness::firmware;
use stm32_harness::periph::Time;
use stm32_harness::transcript::Line;

/// One loop tick, ps.
pub const TICK: Time = 10_000_000_000;

/// The release image, brought up to date once per test process.
pub fn elf() -> std::path::PathBuf {
    firmware::ensure_elf().unwrap_or_else(|e| panic!("cannot build the STM32F411 image: {e}"))
}

/// The lines' texts.
pub fn texts(lines: &[Line]) -> Vec<&str> {
    lines.iter().map(|l| l.text.as_str()).collect()
}

/// The transcript for failure messages (log rows left out).
pub fn transcript(b: &Bench) -> String {
    b.lines
        .iter()
        .filter(|l| !l.text.starts_with(|c: char| c.is_ascii_digit()))
        .map(|l| format!("  [{:8.4} s] {}\n", secs(l.start), l.text))
        .collect()
}

/// Runs for at most `within_s` more, until a line starting with `prefix`; its index.
pub fn run_to(b: &mut Bench, within_s: f64, prefix: &str) -> Option<usize> {
    let until = b.time_s() + within_s;
    match b
        .run_until(until, |l| l.text.starts_with(prefix))
        .expect("run")
    {
        RunEnd::Line(i) => Some(i),
        RunEnd::Time => None,
    }
}

/// The pump is off (duty 0 on the pin) from at most two ticks after the start of line `idx`
/// on, to the end of the run.
pub fn assert_stopped(b: &Bench, idx: usize, what: &str) {
    let line = b.lines[idx].start;
    let deadline = line + 2 * TICK;
    let last_on = b.duty_log.iter().rev().find(|d| d.fraction > 0.0);
    let off_since = last_on
        .and_then(|on| b.duty_log.iter().find(|d| d.at > on.at))
        .map(|d| d.at);
    assert_eq!(
        b.duty_now().fraction,
        0.0,
        "{what}: pump still running at the end"
    );
    assert!(
        off_since.is_some_and(|t| t <= deadline),
        "{what}: pump off at {:?} s (last on {:?}), line at {} s\n{}",
        off_since.map(secs),
        last_on.map(|d| secs(d.at)),
        secs(line),
        transcript(b)
    );
    assert!(
        b.machine.now() >= deadline + ps(0.01),
        "{what}: run too short"
    );
}
