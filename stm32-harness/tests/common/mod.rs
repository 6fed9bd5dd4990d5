//! Helpers shared by the image tests (each test file is a crate of its own and uses some of
//! them: hence `dead_code` allowed here).
#![allow(dead_code)]

use pump_sim::baseline::experiment::identify_with;
use pump_sim::iso::iso_row;
use pump_sim::vent_bench::power_up_plant;
use pump_sim::LungParams;
use ridge_pump_firmware::flash_store::{self, slot_bytes, PROGRAMMED_LEN, SECTOR_LEN};
use ridge_pump_firmware::persist::RECORD_LEN;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use stm32_harness::bench::{ps, secs, Bench, BenchConfig, RunEnd};
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

/// Row 1's lung (C 50 mL/cmH₂O, R 5 cmH₂O/(L/s), PEEP 5 cmH₂O).
pub fn iso_lung() -> LungParams {
    iso_row(1).expect("row 1").lung(&LungParams::adult())
}

/// A store holding the model the firmware's state machine (compiled for the host) identifies
/// on `pump_sim`'s rig with row 1's lung, the PEEP valve at 0, in its first slot.
pub fn flash_with_row1_model() -> Vec<u8> {
    let l = iso_lung();
    let plant = power_up_plant(&l);
    let (_, sm, _) = identify_with(&plant, 3, &DEFAULT_CONFIG).expect("identification");
    let record: [u8; RECORD_LEN] = sm.persist_bytes().expect("model");
    let mut mem = Bench::new(BenchConfig::new(elf())).expect("bench").flash();
    let (_, offset) = flash_store::SECTORS[0];
    let mut sector = vec![0xFF; SECTOR_LEN];
    sector[..PROGRAMMED_LEN].copy_from_slice(&slot_bytes(&record, 0).expect("slot"));
    mem[offset as usize..offset as usize + SECTOR_LEN].copy_from_slice(&sector);
    mem
}

/// Row 1's breaths: `VENT` with its volume and PEEP, 20 /min, Ti 1 s, square, the trim on.
pub fn vent_row1() -> String {
    let r = iso_row(1).expect("row 1");
    format!(
        "VENT vt={} rate=20 ti=1 wave=square peep={} trim=on\n",
        r.tidal, r.peep
    )
}

/// A bench with row 1's lung and the stored row-1 model, run to its controller (`CTRL`).
pub fn row1_in_run_mode() -> Bench {
    let mut cfg = BenchConfig::new(elf());
    cfg.lung = Some(iso_lung());
    cfg.flash = Some(flash_with_row1_model());
    let mut b = Bench::new(cfg).expect("bench");
    assert!(run_to(&mut b, 10.0, "CTRL").is_some(), "{}", transcript(&b));
    b
}

/// Sends [`vent_row1`] now and runs to its answer; the `OK vent` line's index.
pub fn start_vent_row1(b: &mut Bench) -> usize {
    b.send_at(b.time_s(), vent_row1().as_bytes());
    run_to(b, 0.2, "OK vent").unwrap_or_else(|| panic!("{}", transcript(b)))
}
