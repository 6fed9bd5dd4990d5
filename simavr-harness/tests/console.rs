//! Issue 11, item 4, end to end in simavr: the operator console of the real ATmega2560 release
//! image (`Board::console`, USART0 receive interrupt) driven over a simulated 115 200-baud serial
//! line (`simavr_harness::uart`: one byte per 1 389 cycles, the chip's UART frame timing), closed
//! loop with the simulated SFM3300 and blower.
//!
//! Truths the tests hold the firmware to, none of them a number the firmware printed:
//! - the **pump PWM registers** (OCR4A, TCCR4A: `simavr_harness::pwm`, and every write to them,
//!   cycle-stamped) for `STOP`, `START` and the log's `u` column;
//! - the **simulated plant**: the blower's true flow for `SET` (within the sensor's own error,
//!   as in `tests/record.rs`) and for the breath rate of `PROFILE`; the **frames the simulated
//!   sensor served** for the log's `y` column and `STATUS flow=`;
//! - the **EEPROM bytes** for `FORGET` (the two-slot layout of `firmware/src/slots.rs`) and the
//!   record the test stored for `MODEL` (decoded by `persist::decode`);
//! - **ridge-id on the captured log** for the firmware's `ID` line (`--device`, the options
//!   docs/boards.md and docs/real-logs.md name), and the `ID` line for `MODEL`;
//! - the **cycle counter** for the tick budget with the log on (ISR entry → PWM written,
//!   < 1.6 ms).
//!
//! Two boots, one per scenario, each command checked on the same run:
//! [`commands_on_the_running_pump`] (a stored model: run mode in 2.1 s) and
//! [`identification_on_the_log_matches_ridge_id`] (a blank EEPROM: identification with the
//! log on, then `MODEL`). Three more boots check the receive path's worst cases
//! ([`a_stop_after_a_long_line_is_executed`], [`stop_within_one_tick_of_its_last_byte`]) and
//! the answers' timing ([`model_in_run_mode_keeps_the_ticks`], `#[ignore]`d: it fails on the
//! current image, a known limit stated there).

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use harness_kit::console::{
    self, device_argv, is_answer, rising_crossings, rst_polynomials, LogRow,
};
use pump_sim::baseline::experiment::identify_with;
use pump_sim::sfm3300::raw_to_flow;
use pump_sim::{Blower, Outlet, PlantArgs, Sfm3300Params};
use ridge_id::capture::{classify, Kind};
use ridge_id::cli::{Cli, Command};
use ridge_pump_firmware::command::MAX_LINE;
use ridge_pump_firmware::lines::{IdLine, MapLine};
use ridge_pump_firmware::persist::{self, RECORD_LEN};
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::slots::{self, SLOT_LEN, STORE_LEN};
use simavr_harness::bench::{Bench, BenchConfig, RunEnd};
use simavr_harness::machine::IoWrite;
use simavr_harness::pwm::Channel;
use simavr_harness::session::{pwm_counts, TICK_CYCLES};
use simavr_harness::uart::{SendId, UartTiming};
use simavr_harness::{capture, firmware};

/// The control tick's budget, cycles (1.6 ms at 16 MHz): ISR entry → pump PWM written.
const TICK_BUDGET: u64 = 25_600;
/// The pump's PWM channel (Arduino D6).
const PWM: Channel = Channel {
    timer: 4,
    channel: 'A',
};
/// Noise seed of the host identification that makes the stored model.
const MODEL_SEED: u64 = 11;
/// Longest wait for a command's answer, s.
const ANSWER_S: f64 = 0.2;

fn elf() -> PathBuf {
    firmware::ensure_elf().unwrap_or_else(|e| panic!("cannot build the ATmega2560 firmware: {e}"))
}

/// The record the firmware's own state machine (compiled for the host) persists after
/// identifying the default blower, open outlet, on the host (`pump_sim`'s experiment loop):
/// `(EEPROM offset, slot bytes)` as a first save writes them, and the record.
fn stored_model() -> ((u16, Vec<u8>), [u8; RECORD_LEN]) {
    let plant = PlantArgs::preset(Blower::Default, Outlet::Open);
    let (_, sm, _) = identify_with(&plant, MODEL_SEED, &DEFAULT_CONFIG).expect("identification");
    let record = sm.persist_bytes().expect("a model after run mode started");
    let (at, bytes) = slots::slot_bytes(&record, &slots::plan(&[0xFF; STORE_LEN])).expect("slot");
    ((at, bytes.to_vec()), record)
}

fn bench(eeprom: Vec<(u16, Vec<u8>)>) -> Bench {
    let mut cfg = BenchConfig::new(elf());
    cfg.uart_timing = UartTiming::Chip;
    cfg.eeprom = eeprom;
    Bench::new(cfg).expect("bench")
}

fn transcript(b: &Bench) -> String {
    let mut rows = 0;
    let mut out = String::new();
    for l in &b.lines {
        if classify(l.text.as_bytes()) == Kind::Row {
            rows += 1;
            continue;
        }
        if rows > 0 {
            out += &format!("  ({rows} log rows)\n");
            rows = 0;
        }
        if !l.text.starts_with("RES ") {
            out += &format!("  [{:8.4} s] {}\n", l.cycle as f64 / 16e6, l.text);
        }
    }
    out
}

/// Sends `line` (with `\n`) now and runs until its first answer line; returns the transmission
/// and that line's index.
fn command(b: &mut Bench, line: &str) -> (SendId, usize) {
    let id = b.send_now(format!("{line}\n").into_bytes());
    answer_to(b, id)
}

/// Runs until the first answer after transmission `id` started; its line index.
fn answer_to(b: &mut Bench, id: SendId) -> (SendId, usize) {
    let from = b.lines.len();
    let sent_s = b.sent(id).end.map_or(0.0, |c| c as f64 / 16e6);
    let limit = b.time_s().max(sent_s) + ANSWER_S;
    let end = b.run_until(limit, |l| is_answer(&l.text));
    match end {
        RunEnd::Line(i) if i >= from => (id, i),
        _ => panic!(
            "no answer to {:?} within {ANSWER_S} s:\n{}",
            b.sent(id).text(),
            transcript(b)
        ),
    }
}

/// The answer lines (see [`is_answer`]) from line `from` on.
fn answers_since(b: &Bench, from: usize) -> Vec<&str> {
    b.lines[from..]
        .iter()
        .map(|l| l.text.as_str())
        .filter(|t| is_answer(t))
        .collect()
}

/// The log rows among lines `from..to` (`harness_kit::console::log_rows`).
fn rows(b: &Bench, from: usize, to: usize) -> Vec<LogRow> {
    console::log_rows(b.lines[from..to].iter().map(|l| l.text.as_str()), from)
        .unwrap_or_else(|l| panic!("{l}"))
}

/// Index of the bench tick in progress at `cycle`.
fn tick_of(b: &Bench, cycle: u64) -> usize {
    b.ticks()
        .partition_point(|t| t.start <= cycle)
        .saturating_sub(1)
}

/// The frame the sensor served in bench tick `j` (the tick's reading): `(cycle, raw)`.
fn frame_of(b: &Bench, j: usize) -> Option<(u64, u16)> {
    let ticks = b.ticks();
    let from = ticks.get(j)?.start;
    let to = ticks.get(j + 1).map_or(u64::MAX, |t| t.start);
    let frames = b.sensor.borrow().served();
    let i = frames.partition_point(|f| f.0 < from);
    frames.get(i).copied().filter(|f| f.0 < to)
}

/// Timer counts on the pin (`OCR4A + 1`, 0 when disconnected) in effect at `cycle`.
fn counts_at(b: &Bench, cycle: u64) -> u32 {
    b.duty_at(cycle)
        .map_or(0, |d| if d.connected { u32::from(d.ocr) + 1 } else { 0 })
}

/// Checks `rows` against the bench: consecutive ticks (`t` steps of 0.01 s, one row per bench
/// tick), `y` = the frame the sensor served in that tick (counts / 120, 5 decimals), `u` = the
/// duty on the pin when that frame was read (the interval that ended with the reading).
/// Returns the bench tick of the first row.
fn check_rows(b: &Bench, rows: &[LogRow]) -> Result<usize, String> {
    let first = console::consecutive(rows)?;
    let near = tick_of(b, b.line_starts[first.line]);
    'candidate: for j0 in near.saturating_sub(4)..=near {
        for (i, r) in rows.iter().enumerate() {
            let Some((cycle, raw)) = frame_of(b, j0 + i) else {
                continue 'candidate;
            };
            let u_counts = pwm_counts((r.u * 10_000.0).round() as u16);
            if (r.y - raw_to_flow(raw)).abs() > 0.5e-5 + 1e-9 || u_counts != counts_at(b, cycle) {
                continue 'candidate;
            }
        }
        return Ok(j0);
    }
    Err(format!(
        "{} rows from t={} match no alignment with the served frames and the PWM",
        rows.len(),
        first.tick
    ))
}

/// The sensor's own error for a mean flow near `level`: its noise σ (3 % of the flow and a
/// floor) plus its zero offset, which the closed loop cannot see.
fn sensor_bound(level: f64) -> f64 {
    let s = Sfm3300Params::default();
    (s.noise_rel * level).hypot(s.noise_floor_slm) + s.zero_offset_slm.abs()
}

/// Mean true flow of the plant over the 10 ms samples in `from..to` (cycles).
fn mean_flow(b: &Bench, from: u64, to: u64) -> f64 {
    let v: Vec<f64> = b
        .plant_log
        .iter()
        .filter(|s| (from..to).contains(&s.cycle))
        .map(|s| s.flow)
        .collect();
    assert!(!v.is_empty(), "no plant samples in {from}..{to}");
    v.iter().sum::<f64>() / v.len() as f64
}

/// Writes to the pump's compare register (OCR4A low byte, which completes the 16-bit write)
/// with their cycles, from now on.
fn watch_ocr(b: &mut Bench) -> std::rc::Rc<std::cell::RefCell<Vec<(u64, u8)>>> {
    let log = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
    let sink = log.clone();
    b.machine
        .intercept_write(PWM.ocr_addr(), move |cycle, _, v| {
            sink.borrow_mut().push((cycle, v));
            IoWrite::Pass
        })
        .expect("OCR4A");
    log
}

/// Sends `STOP` so that its last stop bit ends at cycle `end` (the firmware has the byte ~30
/// cycles earlier, simavr's receiver ending the frame at 1 360 cycles), checks `OK stop` and
/// the stop latched for `hold_s` (OCR4A 0, OC4A disconnected, duty 0 on the pin at every plant
/// step), and returns the cycles from `end` to the write of 0 into OCR4A.
fn stop_at(
    b: &mut Bench,
    ocr: &std::rc::Rc<std::cell::RefCell<Vec<(u64, u8)>>>,
    end: u64,
    hold_s: f64,
) -> u64 {
    let len = b.serial().offset(5);
    assert!(end - len > b.machine.cycle(), "STOP scheduled in the past");
    let id = b.serial_at_cycle(end - len, b"STOP\n".to_vec());
    let (id, ans) = answer_to(b, id);
    let t = b.sent(id).clone();
    assert_eq!(t.end, Some(end));
    assert!(t.lost.is_empty(), "{t:?}");
    assert_eq!(b.lines[ans].text, "OK stop", "{}", transcript(b));
    let until = b.time_s() + hold_s;
    b.run_until(until, |_| false);
    let off = ocr
        .borrow()
        .iter()
        .find(|&&(c, v)| c > end && v == 0)
        .map(|&(c, _)| c)
        .unwrap_or_else(|| panic!("no OCR4A write of 0 after STOP:\n{}", transcript(b)));
    for d in b.duty_log.iter().filter(|d| d.cycle > off) {
        assert!(
            d.fraction == 0.0 && d.ocr == 0,
            "pump driven after STOP: {d:?}"
        );
    }
    assert_eq!(b.machine.data16(PWM.ocr_addr()), 0, "OCR4A");
    assert!(PWM.duty(&b.machine).is_none(), "OC4A still driving PH3");
    off - end
}

/// The last tick measured, after running 50 ms: its start is a multiple of 10 ms from the next.
fn settled_tick(b: &mut Bench) -> simavr_harness::bench::TickTiming {
    b.run_for(0.05);
    *b.ticks().last().expect("ticks")
}

/// `START` after a stop: `OK start`, the pump runs again (base duty within a tick, the
/// controller designed again, run mode).
fn start(b: &mut Bench) {
    let from = b.lines.len();
    let (_, ans) = command(b, "START");
    assert_eq!(b.lines[ans].text, "OK start", "{}", transcript(b));
    let t0 = b.machine.cycle();
    let end = b.run_until(b.time_s() + 3.0, |l| l.text.starts_with("TRACK"));
    assert!(matches!(end, RunEnd::Line(_)), "{}", transcript(b));
    let ctrl = b.lines[from..].iter().any(|l| l.text.starts_with("CTRL"));
    assert!(ctrl, "no new CTRL after START:\n{}", transcript(b));
    let driven = b
        .duty_log
        .iter()
        .find(|d| d.cycle > t0 && d.fraction > 0.0)
        .map(|d| d.cycle - t0);
    assert!(
        driven.is_some_and(|c| c < 5 * TICK_CYCLES),
        "pump not driven within 5 ticks of START: {driven:?}"
    );
}

/// One boot with a stored model: every console command on the running pump, in run mode.
#[test]
fn commands_on_the_running_pump() {
    let wall = Instant::now();
    let ((at, slot), record) = stored_model();
    let (model, map, fit) = persist::decode(&record).expect("the record decodes");
    let mut b = bench(vec![(at, slot)]);
    let ocr = watch_ocr(&mut b);
    let end = b.run_until(4.0, |l| l.text.starts_with("TRACK"));
    assert!(matches!(end, RunEnd::Line(_)), "{}", transcript(&b));
    let loaded = b
        .find_lines("LOADED")
        .next()
        .map(|(_, l)| l.parsed())
        .unwrap_or_else(|| panic!("no LOADED:\n{}", transcript(&b)));
    let mut figures = Vec::new();

    // STATUS: the state, and the duty and flow it reports are the pin's and the sensor's.
    let (_, i) = command(&mut b, "STATUS");
    let st = b.lines[i].parsed();
    assert_eq!(st.keyword, "STATUS", "{}", b.lines[i].text);
    assert_eq!(st.get("state"), Some("run"));
    assert_eq!(st.get("log"), Some("0"));
    assert_eq!(st.get("fault"), Some("none"));
    let at = b.line_starts[i];
    let duty = (st.num("duty").expect("duty=") * 100.0).round() as u16;
    // The duty written in this tick, before the answer (the bench logs the pin at its 0.5 ms
    // plant steps: one step after the answer started, and 9 ms before the next write).
    assert_eq!(
        pwm_counts(duty),
        counts_at(&b, at + TICK_CYCLES / 20),
        "{}",
        b.lines[i].text
    );
    let (_, raw) = frame_of(&b, tick_of(&b, at)).expect("a frame");
    assert!(
        (st.num("flow").expect("flow=") - raw_to_flow(raw)).abs() <= 0.0005 + 1e-9,
        "{} vs the frame read {}",
        b.lines[i].text,
        raw_to_flow(raw)
    );

    // SET flow=40: the plant's true flow settles on 40 slm within the sensor's own error.
    let (_, i) = command(&mut b, "SET flow=40");
    assert_eq!(b.lines[i].text, "OK set");
    b.run_for(2.0);
    let now = b.machine.cycle();
    let flow = mean_flow(&b, now - b.cycles(0.5), now);
    assert!(
        (flow - 40.0).abs() <= sensor_bound(40.0),
        "SET flow=40: true flow {flow:.3} slm over the last 0.5 s"
    );
    figures.push(format!("SET flow=40: true flow {flow:.3} slm"));

    // LOG on: OK log, the header, then one row per tick matching the pin and the sensor.
    let (_, i) = command(&mut b, "LOG on");
    assert_eq!(b.lines[i].text, "OK log");
    let log_from = i + 2;
    let log_cycle = b.machine.cycle();
    b.run_for(1.0);
    assert_eq!(
        b.lines.get(i + 1).map(|l| l.text.as_str()),
        Some("t,u,y,r,phase"),
        "{}",
        transcript(&b)
    );

    // Refused lines: exactly one ERR each, nothing changes.
    // MAX_LINE + 6 bytes before the \n (106: the longest valid line is a 95-byte VENT).
    let long = format!("SET flow=40{}", " ".repeat(MAX_LINE - 5));
    for (line, want) in [
        ("SET flow=abc", "ERR number"),
        ("SET flow=900", "ERR range flow"),
        ("FOO", "ERR unknown"),
        // 40 breaths a minute at I:E 1:2: 0.5 s inspiration, the default 0.3 s rise is more
        // than half of it (`Breath::check`).
        ("PROFILE ramp peak=60 bias=5 rate=40", "ERR range rise"),
    ] {
        let from = b.lines.len();
        let (_, i) = command(&mut b, line);
        assert_eq!(b.lines[i].text, want, "{line}");
        b.run_for(0.1);
        assert_eq!(answers_since(&b, from), vec![want], "{line}");
    }
    // A line over MAX_LINE bytes (106 + \n), sent so that the loop reads the receive queue
    // after its 43rd byte and then at most 43 bytes apart: `ERR too-long`. (Sent at another phase the
    // 63-byte queue overflows: see `a_stop_after_a_long_line_is_executed`.)
    let last = *b.ticks().last().expect("ticks");
    let read = last.start + 2 * TICK_CYCLES + last.busy;
    let id = b.serial_at_cycle(
        read - b.serial().offset(43),
        format!("{long}\n").into_bytes(),
    );
    let from = b.lines.len();
    let (id, i) = answer_to(&mut b, id);
    assert_eq!(b.lines[i].text, "ERR too-long", "{}", transcript(&b));
    assert!(b.sent(id).lost.is_empty());
    b.run_for(0.3);
    assert_eq!(answers_since(&b, from), vec!["ERR too-long"]);
    let (_, i) = command(&mut b, "STATUS");
    let st = b.lines[i].parsed();
    assert_eq!(
        (st.get("state"), st.get("sp"), st.get("fault")),
        (Some("run"), Some("40.000"), Some("none")),
        "after the refused lines: {}",
        b.lines[i].text
    );
    let now = b.machine.cycle();
    let flow = mean_flow(&b, now - b.cycles(0.5), now);
    assert!(
        (flow - 40.0).abs() <= sensor_bound(40.0),
        "after the refused lines: true flow {flow:.3} slm"
    );

    // PROFILE square, then ramp: the log's setpoint and the plant's flow follow the rate.
    let mut profile_rows = Vec::new();
    for (line, rate, peak, bias, secs) in [
        (
            "PROFILE square peak=50 bias=10 rate=30 ie=2 rise=0.2",
            30.0,
            50.0,
            10.0,
            6.5,
        ),
        (
            "PROFILE ramp peak=60 bias=5 rate=40 rise=0.2",
            40.0,
            60.0,
            5.0,
            5.0,
        ),
    ] {
        let (_, i) = command(&mut b, line);
        assert_eq!(b.lines[i].text, "OK profile", "{line}");
        let from_line = b.lines.len();
        let from_cycle = b.machine.cycle();
        b.run_for(secs);
        let r = rows(&b, from_line, b.lines.len());
        let sp: Vec<f64> = r.iter().map(|r| r.r.expect("r in run mode")).collect();
        let mid = (peak + bias) / 2.0;
        let want = 6000.0 / rate; // ticks per breath
        let (ups, p) = rising_crossings(&sp, mid);
        assert!(
            ups.len() >= 3 && (p - want).abs() <= 1.0,
            "{line}: setpoint period {p} ticks ({} breaths), want {want}",
            ups.len()
        );
        let top = sp.iter().copied().fold(f64::MIN, f64::max);
        let bottom = sp.iter().copied().fold(f64::MAX, f64::min);
        assert!(
            (top - peak).abs() < 1e-3 && (bottom - bias).abs() < 1e-3,
            "{line}: setpoint {bottom}..{top}"
        );
        let flow: Vec<f64> = b
            .plant_log
            .iter()
            .filter(|s| s.cycle >= from_cycle)
            .map(|s| s.flow)
            .collect();
        let (fups, fp) = rising_crossings(&flow, mid);
        assert!(
            fups.len() >= 3 && (fp - want).abs() <= 2.0,
            "{line}: true flow period {fp} ticks ({} breaths), want {want}",
            fups.len()
        );
        figures.push(format!(
            "{line}: setpoint period {:.2} s, true flow period {:.3} s ({} breaths)",
            p / 100.0,
            fp / 100.0,
            fups.len()
        ));
        profile_rows.extend(r);
    }

    // LOG off: OK log, and no row after it.
    let (_, off_line) = command(&mut b, "LOG off");
    assert_eq!(b.lines[off_line].text, "OK log");
    let log_end_cycle = b.machine.cycle();
    b.run_for(0.5);
    let after = rows(&b, off_line, b.lines.len());
    assert!(after.is_empty(), "{} rows after LOG off", after.len());
    let logged = rows(&b, log_from, off_line);
    let j0 = check_rows(&b, &logged).unwrap_or_else(|e| panic!("{e}\n{}", transcript(&b)));
    let ticks_logged = (tick_of(&b, log_end_cycle) - tick_of(&b, log_cycle)) as i64;
    assert!(
        (logged.len() as i64 - ticks_logged).abs() <= 2,
        "{} rows for {ticks_logged} ticks",
        logged.len()
    );
    assert!(logged.iter().all(|r| r.phase == "run"));
    assert!(
        logged
            .iter()
            .filter(|r| r.line < profile_rows[0].line)
            .all(|r| r.r == Some(40.0)),
        "the refused lines changed the setpoint"
    );
    // The tick with the log on: control work (ISR → PWM written) within budget.
    let during: Vec<_> = b.ticks()[j0..j0 + logged.len()].to_vec();
    let control = during.iter().filter_map(|t| t.control).max().unwrap_or(0);
    let whole = during.iter().map(|t| t.busy).max().unwrap_or(0);
    let mean = during.iter().map(|t| t.busy).sum::<u64>() as f64 / during.len() as f64;
    assert!(
        control < TICK_BUDGET && during.iter().all(|t| !t.interrupted_busy),
        "log on: control worst {control} cycles (budget {TICK_BUDGET}), overruns {}",
        during.iter().filter(|t| t.interrupted_busy).count()
    );
    figures.push(format!(
        "log on, run mode, {} ticks: control worst {control} cycles = {:.3} ms; whole tick worst {:.3} ms, mean {:.3} ms",
        during.len(),
        control as f64 / 16e3,
        whole as f64 / 16e3,
        mean / 16e3
    ));

    // STOP received at the start of a pass (1 000 cycles after the tick interrupt: the loop
    // reads it after that tick's control work), then right after a read (3 000 cycles after
    // the previous tick's work ended: read one pass later); START after each.
    let last = settled_tick(&mut b);
    let early = stop_at(&mut b, &ocr, last.start + 3 * TICK_CYCLES + 1_000, 1.0);
    let (_, i) = command(&mut b, "STATUS");
    assert!(
        b.lines[i]
            .text
            .starts_with("STATUS state=stopped duty=0.00 "),
        "{}",
        b.lines[i].text
    );
    start(&mut b);
    let last = settled_tick(&mut b);
    let late = stop_at(
        &mut b,
        &ocr,
        last.start + 3 * TICK_CYCLES + last.busy + 3_000,
        0.2,
    );
    start(&mut b);
    figures.push(format!(
        "STOP: OCR4A 0 {:.3} ms after the line's last stop bit when it ends at the start of a pass, {:.3} ms when it ends right after the loop's read",
        early as f64 / 16e3,
        late as f64 / 16e3
    ));
    assert!(
        early < TICK_BUDGET && late < TICK_CYCLES,
        "STOP latency {early} / {late} cycles"
    );

    // FORGET: the other slot gets the erased record (69 × 0xFF) and the next sequence number;
    // a reboot with that EEPROM has no record.
    let store = |b: &Bench| b.machine.eeprom()[..STORE_LEN].to_vec();
    let before = store(&b);
    let (_, i) = command(&mut b, "FORGET");
    assert_eq!(b.lines[i].text, "OK forget");
    let end = b.run_until(b.time_s() + 2.0, |l| l.text.starts_with("PERSIST"));
    assert!(
        matches!(end, RunEnd::Line(i) if b.lines[i].text == "PERSIST saved"),
        "{}",
        transcript(&b)
    );
    let after = store(&b);
    let (old, new) = if at_slot(&before, 0) { (0, 1) } else { (1, 0) };
    let slot = |s: &[u8], k: usize| s[k * SLOT_LEN..(k + 1) * SLOT_LEN].to_vec();
    assert_eq!(slot(&after, old), slot(&before, old), "the record's slot");
    assert!(slot(&after, new)[..RECORD_LEN].iter().all(|&x| x == 0xFF));
    assert_eq!(
        after[new * SLOT_LEN + RECORD_LEN],
        before[old * SLOT_LEN + RECORD_LEN] + 1,
        "sequence number"
    );
    let mut reboot = bench(vec![(0, after)]);
    reboot.run_until(0.1, |l| l.text.starts_with("BOOT"));
    assert!(
        reboot
            .lines
            .first()
            .is_some_and(|l| l.text.ends_with(" record=none")),
        "{:?}",
        reboot.lines
    );

    // MODEL: the model in use, the stored record's, in the LOADED line's fields; then its
    // map (the record's), then RST.
    let (_, i) = command(&mut b, "MODEL");
    b.run_for(0.1);
    let m = b.lines[i].parsed();
    assert_eq!(m.keyword, "MODEL");
    let keys =
        |p: &ridge_pump_firmware::lines::ParsedLine| p.fields.keys().cloned().collect::<Vec<_>>();
    assert_eq!(keys(&m), keys(&loaded), "MODEL vs LOADED fields");
    for k in ["p", "q", "d", "off", "theta", "phi", "c", "fit"] {
        assert_eq!(m.get(k), loaded.get(k), "MODEL {k}= vs LOADED");
    }
    let s = model.structure();
    assert_eq!(
        (m.int("p"), m.int("q"), m.int("d")),
        (Some(s.p.into()), Some(s.q.into()), Some(s.d.into()))
    );
    let printed = m
        .list("theta")
        .unwrap()
        .into_iter()
        .chain(m.list("phi").unwrap());
    let stored = model
        .theta()
        .iter()
        .chain(model.phi())
        .map(|&v| f64::from(v));
    for (p, v) in printed.zip(stored) {
        assert!(
            (p - v).abs() <= 0.5e-6 + 1e-12,
            "MODEL {p} vs the record {v}"
        );
    }
    assert!((m.num("fit").unwrap() - f64::from(fit)).abs() <= 0.05 + 1e-9);
    let map_line = b
        .lines
        .get(i + 1)
        .map(|l| l.text.clone())
        .unwrap_or_default();
    assert_eq!(
        MapLine::parse(&map_line).map(|l| l.map),
        Ok(map),
        "MODEL's MAP line:\n{}",
        transcript(&b)
    );
    // The controller, one polynomial per line: R monic, and the static gain of the loop from
    // setpoint to flow is one only if T(1) = S(1) (integral action, R(1) = 0).
    let [r, s, t] = rst_polynomials([2, 3, 4].map(|k| b.lines.get(i + k).map(|l| l.parsed())))
        .unwrap_or_else(|e| panic!("{e}:\n{}", transcript(&b)));
    assert_eq!(r.first().copied(), Some(1.0));
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    assert!(sum(&r).abs() < 1e-5, "R(1) = {}", sum(&r));
    assert!(
        (sum(&s) - sum(&t)).abs() < 1e-4,
        "S(1) {} vs T(1) {}",
        sum(&s),
        sum(&t)
    );

    // REID: a new identification starts (settle 1.5 s at the base duty, then SCAN).
    let (reid, i) = command(&mut b, "REID");
    assert_eq!(b.lines[i].text, "OK reid");
    let reid_end = b.sent(reid).end.unwrap();
    let end = b.run_until(b.time_s() + 2.5, |l| l.text.starts_with("SCAN"));
    assert!(matches!(end, RunEnd::Line(_)), "{}", transcript(&b));
    let settle = counts_at(&b, b.machine.cycle() - TICK_CYCLES);
    assert_eq!(settle, pwm_counts(DEFAULT_CONFIG.base_duty), "settle duty");
    figures.push(format!(
        "REID: SCAN {:.3} s after the line",
        (b.line_starts[b.lines.len() - 1] - reid_end) as f64 / 16e6
    ));

    assert!(b.halted().is_none() && b.machine.resets().is_empty());
    println!(
        "commands_on_the_running_pump: {:.1} s simulated in {:.1} s",
        b.time_s(),
        wall.elapsed().as_secs_f64()
    );
    for f in figures {
        println!("  {f}");
    }
}

/// Whether slot `k` of `store` holds a written record (its sequence number is not 0xFF).
fn at_slot(store: &[u8], k: usize) -> bool {
    store[k * SLOT_LEN + RECORD_LEN] != slots::UNWRITTEN
}

/// One boot with a blank EEPROM and the log on from the first line (what `scripts/simulate
/// --log` does): the firmware identifies the default blower; its log, captured as `ridge-id
/// capture` writes it, identified by `ridge-id identify --device` gives the firmware's `ID`
/// line; after `ACCEPT`, `MODEL` answers that model.
#[test]
fn identification_on_the_log_matches_ridge_id() {
    use simavr_harness::session::{self, SessionConfig};
    let wall = Instant::now();
    let mut cfg = SessionConfig::new(elf());
    cfg.bench.uart_timing = UartTiming::Chip;
    cfg.log = true;
    cfg.linger_s = 0.0;
    let mut o = session::run(&cfg).expect("session");
    let accept_fit = o
        .accept
        .as_ref()
        .and_then(|a| a.get("fit").map(String::from));
    let b = &mut o.bench;
    let id_at = b
        .find_lines("ID")
        .next()
        .map(|(i, _)| i)
        .unwrap_or_else(|| panic!("no ID line:\n{}", transcript(b)));
    let id = IdLine::parse(&b.lines[id_at].text).expect("ID line").model;
    assert!(accept_fit.is_some(), "no ACCEPT:\n{}", transcript(b));

    // MODEL after ACCEPT: the ID line's model, in the ID line's fields and digits.
    let (_, i) = command(b, "MODEL");
    let m = b.lines[i].parsed();
    let idp = b.lines[id_at].parsed();
    assert_eq!(m.keyword, "MODEL", "{}", b.lines[i].text);
    for k in ["p", "q", "d", "off", "theta", "phi", "c"] {
        assert_eq!(m.get(k), idp.get(k), "MODEL {k}= vs ID");
    }
    assert_eq!(m.get("fit").map(String::from), accept_fit);

    // The log: every excite row is a sample the sensor served, with the duty on the pin.
    let excite_at = b.find_lines("EXCITE").next().expect("EXCITE").0;
    let excite: Vec<LogRow> = rows(b, excite_at, id_at)
        .into_iter()
        .filter(|r| r.phase == "excite")
        .collect();
    assert_eq!(
        excite.len(),
        usize::from(DEFAULT_CONFIG.records.samples),
        "excite rows"
    );
    let j0 = check_rows(b, &excite).unwrap_or_else(|e| panic!("excite rows: {e}"));
    let control = b.ticks()[j0..]
        .iter()
        .filter_map(|t| t.control)
        .max()
        .unwrap_or(0);
    assert!(
        control < TICK_BUDGET && o.timing.missed == 0,
        "log on: control worst {control} cycles, overruns {}",
        o.timing.missed
    );

    // ridge-id on the capture.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("simavr_console");
    std::fs::create_dir_all(&dir).expect("test directory");
    let path = dir.join("capture.csv");
    let counts = capture::write_capture(b, &path).expect("capture");
    assert_eq!(counts.bad, 0);
    let argv = device_argv(&path).expect("UTF-8 path");
    let cli = Cli::try_parse_from(&argv).unwrap_or_else(|e| panic!("{argv:?}: {e}"));
    let Command::Identify(args) = cli.command else {
        panic!("not identify: {argv:?}");
    };
    let opts = args.options().unwrap_or_else(|e| panic!("{argv:?}: {e}"));
    let report = ridge_id::run(&opts).unwrap_or_else(|e| panic!("{argv:?}: {e}"));
    let json: serde_json::Value = serde_json::from_str(&report.to_json_string()).expect("JSON");
    let int = |k: &str| json["structure"][k].as_i64().expect(k);
    assert_eq!(
        (int("p"), int("q"), int("d")),
        (i64::from(id.p), i64::from(id.q), i64::from(id.d)),
        "structure: ridge-id vs the ID line"
    );
    let list = |k: &str| -> Vec<f64> {
        json[k]
            .as_array()
            .expect(k)
            .iter()
            .map(|v| v.as_f64().expect("number"))
            .collect()
    };
    // The pump solves in f32 after an exact integer first pivot, ridge-id in f64 from the same
    // integer samples; the README measures f32 vs f64 on exact statistics at ≤ 1.4e-5 relative,
    // and the line prints 6 decimals (±5e-7). Tolerance: 1e-4 · max(1, |coefficient|), as
    // docs/real-logs.md asserts for the host's device-log test, 7 to 100 times those.
    let (theta, phi) = (list("theta"), list("phi"));
    let c = json["offset"].as_f64().expect("offset");
    let mut worst = 0.0f64;
    for (what, host, pump) in [("theta", &theta, &id.theta), ("phi", &phi, &id.phi)] {
        assert_eq!(host.len(), pump.len(), "{what}");
        for (h, p) in host.iter().zip(pump.iter()) {
            let rel = (h - p).abs() / p.abs().max(1.0);
            worst = worst.max(rel);
            assert!(rel <= 1e-4, "{what}: ridge-id {h} vs ID {p}");
        }
    }
    let rel_c = (c - id.c).abs() / id.c.abs().max(1.0);
    assert!(rel_c <= 1e-4, "c: ridge-id {c} vs ID {}", id.c);
    let agree = &json["segment"]["device"]["agreement"];
    println!(
        "identification_on_the_log_matches_ridge_id: {:.1} s simulated in {:.1} s; ({},{},{}) on both; largest relative difference theta/phi {worst:.2e}, c {rel_c:.2e}; ridge-id's agreement {agree}; control tick with the log on worst {control} cycles = {:.3} ms over {} ticks; capture {counts}",
        b.time_s(),
        wall.elapsed().as_secs_f64(),
        id.p,
        id.q,
        id.d,
        control as f64 / 16e3,
        b.ticks().len() - j0,
    );
}

/// A long line followed by `STOP\n` in one burst (75 bytes, 6.5 ms at 115 200 baud), starting
/// just after the loop's pass: more than the 63 bytes the ATmega2560's receive queue holds
/// arrive within one 10 ms tick. The loop moves received bytes into its line while it waits
/// for the tick, so the queue never fills: the `PROFILE` line is held for the next pass and
/// the `STOP` after it is executed (the pump stopped), or, had bytes been lost, a line
/// answers `ERR overrun` and the `STATUS` after it its status. (Before the loop collected
/// bytes in its wait it read them once per pass: the `STOP` was lost without an answer.)
#[test]
fn a_stop_after_a_long_line_is_executed() {
    let ((at, slot), _) = stored_model();
    let mut b = bench(vec![(at, slot)]);
    b.run_until(4.0, |l| l.text.starts_with("TRACK"));
    b.run_for(0.05);
    let last = *b.ticks().last().expect("ticks");
    let profile = format!("PROFILE square peak=50 bias=10 rate=20{}", " ".repeat(31));
    assert_eq!(profile.len(), 69);
    let from = b.lines.len();
    // Starts 0.5 ms after the loop's read in a tick: all 75 bytes arrive before the next read.
    let id = b.serial_at_cycle(
        last.start + 2 * TICK_CYCLES + last.busy + 8_000,
        format!("{profile}\nSTOP\n").into_bytes(),
    );
    b.run_for(0.3);
    let status = b.send_now(b"STATUS\n".to_vec());
    b.run_for(0.3);
    let got = answers_since(&b, from);
    let stopped = b
        .duty_at(b.machine.cycle())
        .is_some_and(|d| d.fraction == 0.0);
    println!(
        "sent {:?} then {:?}; answers {got:?}; pump stopped: {stopped}",
        b.sent(id).text(),
        b.sent(status).text()
    );
    assert!(
        stopped || got.contains(&"ERR overrun") && got.iter().any(|a| a.starts_with("STATUS")),
        "STOP neither executed nor refused; answers {got:?}:\n{}",
        transcript(&b)
    );
}

/// `MODEL` in run mode answers the `MODEL` line and, in the passes after it, one `RST` line
/// per polynomial, each once the 255-byte transmit queue has 200 bytes free. docs/boards.md
/// promises no overruns outside the blocking search and design: every tick's control work
/// runs on time. (With the controller in one ~245-byte `RST` line and a digit loop of 32-bit
/// divisions, one pass ran past the next tick: `MISSED late=1 lost=0`.)
#[test]
fn model_in_run_mode_keeps_the_ticks() {
    let ((at, slot), _) = stored_model();
    let mut b = bench(vec![(at, slot)]);
    b.run_until(4.0, |l| l.text.starts_with("TRACK"));
    let from = b.machine.cycle();
    let (_, i) = command(&mut b, "MODEL");
    assert!(b.lines[i].text.starts_with("MODEL "));
    b.run_for(1.5);
    let busy: Vec<_> = b
        .ticks()
        .iter()
        .filter(|t| t.start > from && t.interrupted_busy)
        .copied()
        .collect();
    let missed: Vec<&str> = b
        .find_lines("MISSED")
        .map(|(_, l)| l.text.as_str())
        .collect();
    assert!(
        busy.is_empty() && missed.is_empty(),
        "ticks that found the loop busy: {busy:?}; {missed:?}\n{}",
        transcript(&b)
    );
    let rst = b.find_lines("RST").count();
    assert_eq!(rst, 3, "{}", transcript(&b));
    let longest = b
        .ticks()
        .iter()
        .filter(|t| t.start > from)
        .map(|t| t.busy)
        .max()
        .unwrap_or(0);
    println!(
        "model_in_run_mode_keeps_the_ticks: longest pass {longest} cycles = {:.2} ms",
        longest as f64 / 16e3
    );
}

/// Issue 11 asks for the pump PWM at 0 "within one tick (10 ms)" of `STOP`'s last byte. The
/// worst case: the `STOP` ends 3 000 cycles after the loop's pass before a pass that prints
/// the once-a-second `TRACK` line. The loop completes the line in its idle wait and stops
/// the pump there, microseconds after the last byte. (When the loop read the console once per
/// pass, after the tick's work, this took 10 ms + the `TRACK` line's formatting.)
#[test]
fn stop_within_one_tick_of_its_last_byte() {
    let ((at, slot), _) = stored_model();
    let mut b = bench(vec![(at, slot)]);
    let ocr = watch_ocr(&mut b);
    let end = b.run_until(4.0, |l| l.text.starts_with("TRACK"));
    let RunEnd::Line(track) = end else {
        panic!("no TRACK:\n{}", transcript(&b));
    };
    let jt = tick_of(&b, b.line_starts[track]);
    let normal = settled_tick(&mut b);
    // The pass that prints the next TRACK line is 100 ticks later; the STOP ends 3 000 cycles
    // after the read of the pass before it.
    let t_track = b.ticks()[jt].start;
    let latency = stop_at(
        &mut b,
        &ocr,
        t_track + 99 * TICK_CYCLES + normal.busy + 3_000,
        0.2,
    );
    assert!(
        latency <= TICK_CYCLES,
        "OCR4A 0 {:.3} ms after STOP's last byte:\n{}",
        latency as f64 / 16e3,
        transcript(&b)
    );
}
