//! The release image of the STM32F411 (`cargo flash-f411`'s), unchanged, in the emulated
//! chip, closed loop with the simulated blower and SFM3300: the power-up identification, the
//! record across a reset. Truths: the host rerun of ridge-core's search on the
//! samples the sensor served, the plant's true flow, the reset flags RM0383 defines.
//!
//! The image is built (incrementally) if missing or stale; `STM32_ELF` names another.

use harness_kit::host::{coefficient_error, host_search_in};
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use stm32_harness::bench::{ps, secs, Action, Bench, BenchConfig};
use stm32_harness::firmware;
use stm32_harness::session::{self, SessionConfig};
use stm32_harness::transcript::Line;

fn elf() -> std::path::PathBuf {
    firmware::ensure_elf().expect("STM32F411 image")
}

fn keywords(lines: &[Line]) -> Vec<&str> {
    lines.iter().map(Line::keyword).collect()
}

/// Index of the first line with keyword `kw` at or after `from`.
fn find_after(lines: &[Line], from: usize, kw: &str) -> usize {
    lines[from..]
        .iter()
        .position(|l| l.keyword() == kw)
        .map(|i| from + i)
        .unwrap_or_else(|| panic!("no {kw} after line {from}: {:?}", keywords(lines)))
}

#[test]
fn default_blower_boots_identifies_persists_designs_and_tracks() {
    let mut cfg = SessionConfig::new(elf());
    cfg.track_s = 12.0;
    let out = session::run(&cfg).unwrap();
    let b = &out.bench;
    let l = &b.lines;
    // The sequence, in order.
    let boot = find_after(l, 0, "BOOT");
    assert_eq!(l[boot].text, "BOOT board=stm32f411 reset=14 record=none");
    let mut at = boot;
    for kw in [
        "SENSOR", "SCAN", "MAP", "EXCITE", "ID", "VALIDATE", "ACCEPT", "PERSIST", "CTRL", "TRACK",
    ] {
        at = find_after(l, at, kw);
    }
    assert!(l.iter().any(|x| x.text == "SENSOR ready tries=1"));
    assert!(l.iter().any(|x| x.text == "PERSIST saved"));
    assert!(out.faults.is_empty(), "{:?}", out.faults);
    // Every access answered by a model, no CPU fault, no reset, a clean sensor protocol.
    let m = &b.machine;
    assert!(m.chip().misses.is_empty(), "{:?}", m.chip().misses);
    assert!(m.faults.is_empty(), "{:?}", m.faults);
    assert_eq!(m.resets.len(), 1);
    assert!(b.sensor.borrow().errors.is_empty());
    // The record is in the store's flash sectors (6 and 7).
    assert!(b.store_used());
    // USART1's interrupt kept every line's bytes back to back: each frame starts when the one
    // before it ends (the interrupt refills DR within the 86.8 µs frame), so neither the clock
    // jump nor the chunking delayed a TXE interrupt past its frame.
    let sent = &m.chip().usart1.sent;
    let frame = sent[0].end - sent[0].start;
    assert_eq!(frame, 86_800_000, "10 bits at BRR 868 and PCLK2 100 MHz");
    let mut gaps = 0;
    for w in sent.windows(2) {
        if w[0].byte != b'\n' {
            assert_eq!(
                w[1].start,
                w[0].end,
                "gap inside a line at {} s",
                secs(w[0].end)
            );
            gaps += 1;
        }
    }
    assert!(gaps > 1_000, "{gaps} byte pairs checked");
    // Run mode: each TRACK line's measured mean flow (over the run ticks since the previous
    // line, `tick=`) is the plant's true flow over the same window (sensor noise and offset
    // averaged: within 0.3 slm), and tracks its setpoint.
    let tracks: Vec<&Line> = b.find("TRACK").collect();
    assert!(tracks.len() >= 10, "{} TRACK lines", tracks.len());
    let mut prev = 0;
    for t in &tracks {
        let p = t.parsed();
        let (sp, flow) = (p.num("sp").unwrap(), p.num("flow").unwrap());
        let tick = p.int("tick").unwrap();
        let span = ps(0.01 * (tick - prev) as f64);
        prev = tick;
        let window: Vec<f64> = b
            .plant_log
            .iter()
            .filter(|s| s.at <= t.start && s.at + span > t.start)
            .map(|s| s.flow)
            .collect();
        let truth = window.iter().sum::<f64>() / window.len() as f64;
        assert!(
            (flow - truth).abs() < 0.3,
            "{}: true mean {truth:.3}",
            t.text
        );
        assert!((flow - sp).abs() < 1.0, "{}", t.text);
    }
    // Instructions per control tick against the 10 k target (0.1 ms at 100 MHz).
    let tm = &out.timing;
    assert!(tm.ticks > 2_500, "{} ticks", tm.ticks);
    assert!(tm.control_worst > 0 && tm.control_worst <= 10_000, "{tm:?}");
    assert!(
        tm.search_instr.is_some() && tm.design_instr.is_some(),
        "{tm:?}"
    );
}

#[test]
fn identification_equals_the_host_rerun_on_the_samples_served() {
    let cfg = SessionConfig::new(elf());
    let out = session::run(&cfg).unwrap();
    let id = out.id.as_ref().expect("ID line");
    let est = out.estimation.as_ref().expect("estimation record rebuilt");
    assert_eq!(est.len(), usize::from(DEFAULT_CONFIG.records.samples));
    for host in [host_search_in::<f64>(est), host_search_in::<f32>(est)] {
        let host = host.unwrap();
        let err = coefficient_error(&id.model, &host.model)
            .unwrap_or_else(|| panic!("structure differs: firmware {id:?}, host {host:?}"));
        // The ID line prints 6 decimals; the firmware computes in f32.
        assert!(err < 1e-4, "max coefficient difference {err:e}");
        assert_eq!(
            (id.evaluated, id.candidates),
            (host.evaluated, host.candidates)
        );
    }
}

#[test]
fn a_stalled_blower_stops_the_pump() {
    // Stalled in run mode: the firmware's stall check drives the duty to 0.
    let mut b = Bench::new(BenchConfig::new(elf())).unwrap();
    b.run_until(80.0, |l| l.keyword() == "CTRL").unwrap();
    let at = b.time_s() + 2.0;
    b.schedule(at, Action::Stall(true));
    b.run_until(at + 5.0, |l| l.keyword() == "FAULT").unwrap();
    let fault = b.find("FAULT").next().expect("FAULT line");
    assert!(fault.parsed().has_word("stall"), "{}", fault.text);
    b.run_for(0.1).unwrap();
    assert_eq!(b.duty_now().fraction, 0.0, "pump off");
}

#[test]
fn the_clock_jump_changes_nothing_the_firmware_observes() {
    // The first 2.5 s (clock setup, BOOT, the sensor's start, the settling at the base duty,
    // SCAN and the start of the scan) with and without the jump: the same lines, and the same frames served at the
    // same times up to the few instructions a poll loop takes to see an event (< 1 µs).
    let run = |jump: bool| {
        let mut b = Bench::new(BenchConfig::new(elf())).unwrap();
        b.machine.core_mut().clock_jump = jump;
        b.run_until(2.5, |_| false).unwrap();
        let lines: Vec<String> = b.lines.iter().map(|l| l.text.clone()).collect();
        let frames = b.sensor.borrow().served();
        (
            lines,
            frames,
            b.machine.core().jumped,
            b.machine.instructions(),
        )
    };
    let (lines_j, frames_j, jumped, instr_j) = run(true);
    let (lines_n, frames_n, not_jumped, instr_n) = run(false);
    assert_eq!(not_jumped, 0);
    assert!(secs(jumped) > 2.0, "the jump skipped {:.3} s", secs(jumped));
    assert!(
        instr_n > 50 * instr_j,
        "{instr_n} instructions without, {instr_j} with"
    );
    assert!(lines_j.iter().any(|l| l.starts_with("SCAN")), "{lines_j:?}");
    assert_eq!(lines_j, lines_n);
    assert_eq!(frames_j.len(), frames_n.len());
    for (a, b) in frames_j.iter().zip(&frames_n) {
        assert_eq!(a.1, b.1, "raw word");
        assert!(
            a.0.abs_diff(b.0) < ps(1e-6),
            "frame at {} s vs {} s",
            secs(a.0),
            secs(b.0)
        );
    }
}

#[test]
fn console_bytes_reach_the_firmware_through_usart1_receive_interrupt() {
    // `LOG on` at 115 200 baud into PA10: the receive interrupt queues the bytes, the loop
    // answers `OK log`, the CSV header, then one log row per 10 ms tick.
    let mut b = Bench::new(BenchConfig::new(elf())).unwrap();
    b.run_until(1.0, |_| false).unwrap();
    b.send_at(1.0, b"LOG on\n");
    b.run_until(3.0, |_| false).unwrap();
    let received = &b.machine.chip().usart1.received;
    assert_eq!(received.len(), 7);
    assert!(received.iter().all(|r| !r.lost), "no overrun");
    let ok = b
        .lines
        .iter()
        .position(|l| l.text == "OK log")
        .expect("OK log");
    let last_byte = received.last().unwrap().at;
    assert!(b.lines[ok].start > last_byte);
    // Answered within the pass after the line completed (≤ 2 ticks).
    assert!(
        b.lines[ok].start - last_byte < ps(0.02),
        "{} s",
        secs(b.lines[ok].start - last_byte)
    );
    assert_eq!(b.lines[ok + 1].text, "t,u,y,r,phase");
    let rows = b.lines[ok + 2..]
        .iter()
        .filter(|l| l.start > ps(2.0) && l.start <= ps(3.0))
        .count();
    assert!((99..=101).contains(&rows), "{rows} rows in one second");
}
