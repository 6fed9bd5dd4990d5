//! The operator console of the STM32F411 release image end to end, as
//! `simavr-harness/tests/console.rs` checks the ATmega2560's: commands played into USART1's
//! receiver at 115 200 baud (PA10; the receive interrupt, the queue, the loop), answers read
//! from its transmitter, closed loop with the simulated SFM3300 and blower.
//!
//! Truths the tests hold the firmware to, none of them a number the firmware printed:
//! - the **pump PWM** (every write of TIM3_CCR1, time-stamped, and the duty on PA6 at every
//!   plant step) for `STOP`, `START`, `STATUS duty=` and the log's `u` column;
//! - the **simulated plant**: the blower's true flow for `SET` (within the sensor's own error)
//!   and for the breath rate of `PROFILE`; the **frames the simulated sensor served** for the
//!   log's `y` column and `STATUS flow=`;
//! - the **flash store** for `FORGET` (`firmware/src/flash_store.rs`) and the record the test
//!   stored for `MODEL` (decoded by `persist::decode`);
//! - **ridge-id on the captured log** for the firmware's `ID` line (`--device`);
//! - the **instruction count** for the tick budget with the log on (tick start → TIM3_CCR1
//!   written, ≤ 10 000 instructions, 0.1 ms at 100 MHz);
//! - **USART1's overrun** (the bytes the model lost while the CPU was stalled by the boot's
//!   flash erase) for `ERR overrun`.

mod common;

use std::path::Path;

use clap::Parser;
use common::{elf, transcript, TICK};
use harness_kit::console::{
    self, device_argv, is_answer, rising_crossings, rst_polynomials, LogRow,
};
use pump_sim::baseline::experiment::identify_with;
use pump_sim::sfm3300::raw_to_flow;
use pump_sim::{Blower, Outlet, PlantArgs, Sfm3300Params};
use ridge_id::cli::{Cli, Command};
use ridge_pump_firmware::command::MAX_LINE;
use ridge_pump_firmware::flash_store::{
    self, slot_bytes, PROGRAMMED_LEN, SECTOR_LEN, SLOTS, SLOT_LEN,
};
use ridge_pump_firmware::lines::{IdLine, MapLine, ParsedLine};
use ridge_pump_firmware::persist::{self, RECORD_LEN};
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use stm32_harness::bench::{ps, secs, Bench, BenchConfig, RunEnd, FRAME_PS};
use stm32_harness::periph::Time;
use stm32_harness::session::{self, duty_counts, SessionConfig};

/// The control tick's budget, instructions (tick start → TIM3_CCR1 written).
const TICK_BUDGET: u64 = 10_000;
/// Noise seed of the host identification that makes the stored model.
const MODEL_SEED: u64 = 11;
/// Longest wait for a command's answer, s.
const ANSWER_S: f64 = 0.2;

/// The record the firmware's own state machine (compiled for the host) persists after
/// identifying the default blower, open outlet, on the host (`pump_sim`'s experiment loop).
fn stored_model() -> [u8; RECORD_LEN] {
    let plant = PlantArgs::preset(Blower::Default, Outlet::Open);
    let (_, sm, _) = identify_with(&plant, MODEL_SEED, &DEFAULT_CONFIG).expect("identification");
    sm.persist_bytes().expect("a model after run mode started")
}

/// The freshly flashed image with `store` in the store's sectors.
fn flash_with(store: &[Vec<u8>; 2]) -> Vec<u8> {
    let mut mem = Bench::new(BenchConfig::new(elf())).expect("bench").flash();
    for ((_, offset), s) in flash_store::SECTORS.iter().zip(store) {
        mem[*offset as usize..*offset as usize + SECTOR_LEN].copy_from_slice(s);
    }
    mem
}

/// A store holding `record` alone, in its first slot.
fn store_with(record: &[u8; RECORD_LEN]) -> [Vec<u8>; 2] {
    let mut s = [vec![0xFF; SECTOR_LEN], vec![0xFF; SECTOR_LEN]];
    s[0][..PROGRAMMED_LEN].copy_from_slice(&slot_bytes(record, 0).expect("slot"));
    s
}

fn bench(flash: Vec<u8>) -> Bench {
    let mut cfg = BenchConfig::new(elf());
    cfg.flash = Some(flash);
    Bench::new(cfg).expect("bench")
}

/// Sends `line` (with `\n`) now; runs until its first answer. Returns when its last stop
/// bit ended and the answer's line index.
fn command(b: &mut Bench, line: &str) -> (Time, usize) {
    let end = b.send_at(b.time_s(), format!("{line}\n").as_bytes());
    (end, answer_after(b, end, line))
}

/// Runs until the first answer line after `from` (ps); its index.
fn answer_after(b: &mut Bench, from: Time, what: &str) -> usize {
    let first = b.lines.len();
    let limit = b.time_s().max(secs(from)) + ANSWER_S;
    match b.run_until(limit, |l| is_answer(&l.text)).expect("run") {
        RunEnd::Line(i) if i >= first => i,
        _ => panic!(
            "no answer to {what:?} within {ANSWER_S} s:\n{}",
            transcript(b)
        ),
    }
}

/// The answer lines from line `from` on.
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

/// Index of the loop pass in progress at `t`.
fn tick_of(b: &Bench, t: Time) -> usize {
    let ticks = &b.machine.core().ticks.ticks;
    ticks.partition_point(|k| k.start <= t).saturating_sub(1)
}

/// The frame the sensor served in pass `j` (the tick's reading): `(time, raw)`.
fn frame_of(b: &Bench, j: usize) -> Option<(Time, u16)> {
    let ticks = &b.machine.core().ticks.ticks;
    let from = ticks.get(j)?.start;
    let to = ticks.get(j + 1).map_or(Time::MAX, |t| t.start);
    let frames = b.sensor.borrow().served();
    let i = frames.partition_point(|f| f.0 < from);
    frames.get(i).filter(|f| f.0 < to).map(|f| (f.0, f.1))
}

/// TIM3 counts on the pin (CCR1 of a period of ARR + 1, 0 when not driving) at `t`.
fn counts_at(b: &Bench, t: Time) -> (u32, u32) {
    b.duty_at(t).map_or((0, 1), |d| {
        if d.fraction > 0.0 {
            (d.ccr, d.period)
        } else {
            (0, d.period)
        }
    })
}

/// Checks `rows` against the bench: consecutive ticks, `y` = the frame the sensor served in
/// that tick (counts / 120, 5 decimals), `u` = the duty on the pin when that frame was read.
/// Returns the pass of the first row.
fn check_rows(b: &Bench, rows: &[LogRow]) -> Result<usize, String> {
    let first = console::consecutive(rows)?;
    let near = tick_of(b, b.lines[first.line].start);
    'candidate: for j0 in near.saturating_sub(4)..=near {
        for (i, r) in rows.iter().enumerate() {
            let Some((t, raw)) = frame_of(b, j0 + i) else {
                continue 'candidate;
            };
            let (ccr, period) = counts_at(b, t);
            let u = duty_counts((r.u * 10_000.0).round() as u16, period);
            if (r.y - raw_to_flow(raw)).abs() > 0.5e-5 + 1e-9 || u != ccr {
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

/// The sensor's own error for a mean flow near `level`: its noise σ plus its zero offset.
fn sensor_bound(level: f64) -> f64 {
    let s = Sfm3300Params::default();
    (s.noise_rel * level).hypot(s.noise_floor_slm) + s.zero_offset_slm.abs()
}

/// Mean true flow of the plant over the 10 ms samples in `from..to`.
fn mean_flow(b: &Bench, from: Time, to: Time) -> f64 {
    let v: Vec<f64> = b
        .plant_log
        .iter()
        .filter(|s| (from..to).contains(&s.at))
        .map(|s| s.flow)
        .collect();
    assert!(!v.is_empty(), "no plant samples");
    v.iter().sum::<f64>() / v.len() as f64
}

/// Sends `STOP` so that its last stop bit ends at `end`, checks `OK stop` and the stop
/// latched for `hold_s` (TIM3_CCR1 0, duty 0 on the pin at every plant step), and returns the
/// time from `end` to the write of 0 into TIM3_CCR1.
fn stop_at(b: &mut Bench, end: Time, hold_s: f64) -> Time {
    let start = end - 5 * FRAME_PS;
    assert!(start > b.machine.now(), "STOP scheduled in the past");
    let sent = b.send_at(secs(start), b"STOP\n");
    assert_eq!(sent, end);
    let ans = answer_after(b, end, "STOP");
    assert_eq!(b.lines[ans].text, "OK stop", "{}", transcript(b));
    b.run_until(b.time_s() + hold_s, |_| false).expect("run");
    let off = b
        .machine
        .core()
        .pwm_writes
        .iter()
        .find(|&&(t, v)| t > end && v == 0)
        .map(|&(t, _)| t)
        .unwrap_or_else(|| panic!("no TIM3_CCR1 write of 0 after STOP:\n{}", transcript(b)));
    for d in b.duty_log.iter().filter(|d| d.at > off) {
        assert!(d.fraction == 0.0, "pump driven after STOP: {d:?}");
    }
    assert!(
        b.machine
            .core()
            .pwm_writes
            .iter()
            .filter(|&&(t, _)| t > off)
            .all(|&(_, v)| v == 0),
        "TIM3_CCR1 written non-zero after STOP"
    );
    off - end
}

/// The last pass measured, after running 50 ms.
fn settled_tick(b: &mut Bench) -> stm32_harness::ticks::Tick {
    b.run_for(0.05).expect("run");
    *b.machine.core().ticks.ticks.last().expect("ticks")
}

/// `START` after a stop: `OK start`, a new design, run mode, the pump driven within 5 ticks.
fn start(b: &mut Bench) {
    let from = b.lines.len();
    let (_, ans) = command(b, "START");
    assert_eq!(b.lines[ans].text, "OK start", "{}", transcript(b));
    let t0 = b.machine.now();
    let end = b
        .run_until(b.time_s() + 3.0, |l| l.text.starts_with("TRACK"))
        .expect("run");
    assert!(matches!(end, RunEnd::Line(_)), "{}", transcript(b));
    assert!(
        b.lines[from..].iter().any(|l| l.text.starts_with("CTRL")),
        "no new CTRL after START:\n{}",
        transcript(b)
    );
    let driven = b
        .duty_log
        .iter()
        .find(|d| d.at > t0 && d.fraction > 0.0)
        .map(|d| d.at - t0);
    assert!(
        driven.is_some_and(|t| t < 5 * TICK),
        "pump not driven within 5 ticks of START: {driven:?}"
    );
}

/// One boot with a stored model: every console command on the running pump, in run mode.
#[test]
fn commands_on_the_running_pump() {
    let wall = std::time::Instant::now();
    let record = stored_model();
    let (model, map, fit) = persist::decode(&record).expect("the record decodes");
    let mut b = bench(flash_with(&store_with(&record)));
    let end = b
        .run_until(4.0, |l| l.text.starts_with("TRACK"))
        .expect("run");
    assert!(matches!(end, RunEnd::Line(_)), "{}", transcript(&b));
    let loaded: ParsedLine = b
        .find("LOADED")
        .next()
        .map(|l| l.parsed())
        .unwrap_or_else(|| panic!("no LOADED:\n{}", transcript(&b)));
    let mut figures = Vec::new();

    // STATUS: the state, and the duty and flow it reports are the pin's and the sensor's.
    let (_, i) = command(&mut b, "STATUS");
    let st = b.lines[i].parsed();
    assert_eq!(st.keyword, "STATUS", "{}", b.lines[i].text);
    assert_eq!(st.get("state"), Some("run"));
    assert_eq!(st.get("log"), Some("0"));
    assert_eq!(st.get("fault"), Some("none"));
    let at = b.lines[i].start;
    let duty = (st.num("duty").expect("duty=") * 100.0).round() as u16;
    let (ccr, period) = counts_at(&b, at + TICK / 20);
    assert_eq!(duty_counts(duty, period), ccr, "{}", b.lines[i].text);
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
    b.run_for(2.0).expect("run");
    let now = b.machine.now();
    let flow = mean_flow(&b, now - ps(0.5), now);
    assert!(
        (flow - 40.0).abs() <= sensor_bound(40.0),
        "SET flow=40: true flow {flow:.3} slm over the last 0.5 s"
    );
    figures.push(format!("SET flow=40: true flow {flow:.3} slm"));

    // LOG on: OK log, the header, then one row per tick matching the pin and the sensor.
    let (_, i) = command(&mut b, "LOG on");
    assert_eq!(b.lines[i].text, "OK log");
    let log_from = i + 2;
    let log_at = b.machine.now();
    b.run_for(1.0).expect("run");
    assert_eq!(
        b.lines.get(i + 1).map(|l| l.text.as_str()),
        Some("t,u,y,r,phase"),
        "{}",
        transcript(&b)
    );

    // Refused lines: exactly one ERR each, nothing changes. A line over MAX_LINE bytes
    // (106 + \n) is `ERR too-long` (the 255-byte receive queue holds it whole).
    let long = format!("SET flow=40{}", " ".repeat(MAX_LINE - 5));
    for (line, want) in [
        ("SET flow=abc", "ERR number"),
        ("SET flow=900", "ERR range flow"),
        ("FOO", "ERR unknown"),
        // 40 breaths a minute at I:E 1:2: 0.5 s inspiration, the default 0.3 s rise is more
        // than half of it.
        ("PROFILE ramp peak=60 bias=5 rate=40", "ERR range rise"),
        (long.as_str(), "ERR too-long"),
    ] {
        let from = b.lines.len();
        let (_, i) = command(&mut b, line);
        assert_eq!(b.lines[i].text, want, "{line}");
        b.run_for(0.1).expect("run");
        assert_eq!(answers_since(&b, from), vec![want], "{line}");
    }
    let (_, i) = command(&mut b, "STATUS");
    let st = b.lines[i].parsed();
    assert_eq!(
        (st.get("state"), st.get("sp"), st.get("fault")),
        (Some("run"), Some("40.000"), Some("none")),
        "after the refused lines: {}",
        b.lines[i].text
    );

    // PROFILE square, then ramp: the log's setpoint and the plant's flow follow the rate.
    let mut profile_rows = Vec::new();
    for (line, rate, peak, bias, secs_run) in [
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
        let from_at = b.machine.now();
        b.run_for(secs_run).expect("run");
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
            .filter(|s| s.at >= from_at)
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
    let log_end = b.machine.now();
    b.run_for(0.5).expect("run");
    assert!(
        rows(&b, off_line, b.lines.len()).is_empty(),
        "rows after LOG off"
    );
    let logged = rows(&b, log_from, off_line);
    let j0 = check_rows(&b, &logged).unwrap_or_else(|e| panic!("{e}\n{}", transcript(&b)));
    let ticks_logged = (tick_of(&b, log_end) - tick_of(&b, log_at)) as i64;
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
    // The ticks with the log on: control work within budget.
    let during = &b.machine.core().ticks.ticks[j0..j0 + logged.len()];
    let control = during
        .iter()
        .filter_map(|t| t.control_instr)
        .max()
        .unwrap_or(0);
    let whole = during.iter().map(|t| t.busy_instr).max().unwrap_or(0);
    assert!(
        control <= TICK_BUDGET && during.iter().all(|t| t.busy_ps < TICK),
        "log on: control worst {control} instructions (budget {TICK_BUDGET})"
    );
    figures.push(format!(
        "log on, run mode, {} ticks: control worst {control} instructions, whole tick worst {whole}",
        during.len()
    ));

    // STOP received 10 µs into a pass (during the tick's work), then 0.1 ms after a pass's
    // work ended (in the idle wait); START after each.
    let last = settled_tick(&mut b);
    let early = stop_at(&mut b, last.start + 3 * TICK + ps(1e-5), 1.0);
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
    let late = stop_at(&mut b, last.start + 3 * TICK + last.busy_ps + ps(1e-4), 0.2);
    start(&mut b);
    figures.push(format!(
        "STOP: TIM3_CCR1 0 {:.3} ms after the line's last stop bit when it ends during a pass's \
         work, {:.3} ms when it ends in the idle wait",
        early as f64 / 1e9,
        late as f64 / 1e9
    ));
    assert!(
        early < TICK && late < TICK,
        "STOP latency {early} / {late} ps"
    );

    // FORGET: the forgotten record (105 × 0xFF) in the store's next slot with the next
    // sequence number; a reboot with that flash has no record.
    let before = b.store();
    let (_, i) = command(&mut b, "FORGET");
    assert_eq!(b.lines[i].text, "OK forget");
    let end = b
        .run_until(b.time_s() + 2.0, |l| l.text.starts_with("PERSIST"))
        .expect("run");
    assert!(
        matches!(end, RunEnd::Line(i) if b.lines[i].text == "PERSIST saved"),
        "{}",
        transcript(&b)
    );
    let after = b.store();
    assert_eq!(
        after[0][..SLOT_LEN],
        before[0][..SLOT_LEN],
        "the record's slot"
    );
    assert_eq!(
        &after[0][SLOT_LEN..SLOT_LEN + PROGRAMMED_LEN],
        &slot_bytes(&[0xFF; RECORD_LEN], 1).unwrap()[..]
    );
    let mut reboot = bench(b.flash());
    reboot
        .run_until(0.1, |l| l.text.starts_with("BOOT"))
        .expect("run");
    assert_eq!(
        reboot.lines.first().map(|l| l.text.as_str()),
        Some("BOOT board=stm32f411 reset=14 record=none")
    );

    // MODEL: the model in use, the stored record's, in the LOADED line's fields; then its
    // map (the record's), then RST.
    let (_, i) = command(&mut b, "MODEL");
    b.run_for(0.1).expect("run");
    let m = b.lines[i].parsed();
    assert_eq!(m.keyword, "MODEL");
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
    // The controller, one polynomial per line: R monic, and the loop's static gain from
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
    let (reid_end, i) = command(&mut b, "REID");
    assert_eq!(b.lines[i].text, "OK reid");
    let end = b
        .run_until(b.time_s() + 2.0, |l| l.text.starts_with("SCAN"))
        .expect("run");
    assert!(matches!(end, RunEnd::Line(_)), "{}", transcript(&b));
    let (ccr, period) = counts_at(&b, b.machine.now() - TICK);
    assert_eq!(
        ccr,
        duty_counts(DEFAULT_CONFIG.base_duty, period),
        "settle duty"
    );
    figures.push(format!(
        "REID: SCAN {:.3} s after the line",
        secs(b.lines[b.lines.len() - 1].start - reid_end)
    ));

    assert_eq!(b.machine.resets.len(), 1);
    assert!(b.machine.faults.is_empty());
    println!(
        "commands_on_the_running_pump: {:.1} s emulated in {:.1} s wall",
        b.time_s(),
        wall.elapsed().as_secs_f64()
    );
    for f in figures {
        println!("  {f}");
    }
}

/// One boot with an erased store and the log on from the first line: the firmware identifies
/// the default blower; its log, captured as `ridge-id capture` writes it, identified by
/// `ridge-id identify --device` gives the firmware's `ID` line; after `ACCEPT`, `MODEL`
/// answers that model.
#[test]
fn identification_on_the_log_matches_ridge_id() {
    let mut cfg = SessionConfig::new(elf());
    cfg.log = true;
    cfg.linger_s = 0.0;
    let mut o = session::run(&cfg).expect("session");
    let accept_fit = o
        .accept
        .as_ref()
        .and_then(|a| a.get("fit").map(String::from));
    let b = &mut o.bench;
    let id_at = b
        .lines
        .iter()
        .position(|l| l.keyword() == "ID")
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
    let excite_at = b
        .lines
        .iter()
        .position(|l| l.keyword() == "EXCITE")
        .expect("EXCITE");
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
    let control = b.machine.core().ticks.ticks[j0..]
        .iter()
        .filter_map(|t| t.control_instr)
        .max()
        .unwrap_or(0);
    assert!(
        control <= TICK_BUDGET,
        "log on: control worst {control} instructions"
    );

    // ridge-id on the capture.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("stm32_console");
    std::fs::create_dir_all(&dir).expect("test directory");
    let path = dir.join("capture.csv");
    let counts = session::write_capture(b, &path).expect("capture");
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
    // The pump solves in f32, ridge-id in f64 from the same integer samples; the line prints
    // 6 decimals: 1e-4 · max(1, |coefficient|), as the ATmega2560's test.
    let mut worst = 0.0f64;
    for (what, host, pump) in [
        ("theta", list("theta"), &id.theta),
        ("phi", list("phi"), &id.phi),
    ] {
        assert_eq!(host.len(), pump.len(), "{what}");
        for (h, p) in host.iter().zip(pump.iter()) {
            let rel = (h - p).abs() / p.abs().max(1.0);
            worst = worst.max(rel);
            assert!(rel <= 1e-4, "{what}: ridge-id {h} vs ID {p}");
        }
    }
    let c = json["offset"].as_f64().expect("offset");
    assert!(
        (c - id.c).abs() / id.c.abs().max(1.0) <= 1e-4,
        "c: {c} vs {}",
        id.c
    );
    println!(
        "identification_on_the_log_matches_ridge_id: ({},{},{}) on both; largest relative \
         difference theta/phi {worst:.2e}; control tick with the log on worst {control} \
         instructions; capture {counts}",
        id.p, id.q, id.d
    );
}

/// A long line and `STOP` in one burst (75 bytes, 6.5 ms at 115 200 baud) right after a
/// pass: the 255-byte receive queue holds it, the `PROFILE` line is answered and the `STOP`
/// after it is executed (the pump stopped).
#[test]
fn a_stop_after_a_long_line_is_executed() {
    let mut b = bench(flash_with(&store_with(&stored_model())));
    b.run_until(4.0, |l| l.text.starts_with("TRACK"))
        .expect("run");
    let last = settled_tick(&mut b);
    let profile = format!("PROFILE square peak=50 bias=10 rate=20{}", " ".repeat(31));
    assert_eq!(profile.len(), 69);
    let from = b.lines.len();
    b.send_at(
        secs(last.start + 2 * TICK + last.busy_ps + ps(5e-4)),
        format!("{profile}\nSTOP\n").as_bytes(),
    );
    b.run_for(0.3).expect("run");
    let got = answers_since(&b, from);
    assert_eq!(got, vec!["OK profile", "OK stop"], "{}", transcript(&b));
    assert_eq!(b.duty_now().fraction, 0.0, "pump still running");
    assert!(b.machine.chip().usart1.received.iter().all(|r| !r.lost));
}

/// An overrun: `STATUS` lines every 20 ms while a flash erase stalls the CPU (the boot's, with
/// sector 6 full and sector 7 not blank: `flash_store::boot_erase`, 2 s; the receiver is
/// enabled before it). The receive interrupt cannot run: USART1 keeps the first byte in DR and
/// sets ORE for the next (RM0383 §19.3.3), the rest is lost; after the erase the interrupt sees
/// ORE, and the line being assembled is refused with one `ERR overrun` (the bytes dropped until
/// the loop has read it may cut one more line, refused too); every line sent after that
/// answer is answered `STATUS`, and so is every line sent before the erase.
#[test]
fn an_overrun_during_a_flash_erase_is_refused_and_the_next_lines_answered() {
    let a = stored_model();
    let mut store = [vec![0xFF; SECTOR_LEN], vec![0xFF; SECTOR_LEN]];
    for i in 0..SLOTS {
        let at = i * SLOT_LEN;
        store[0][at..at + PROGRAMMED_LEN].copy_from_slice(&slot_bytes(&a, 1 + i as u32).unwrap());
    }
    store[1][..PROGRAMMED_LEN].copy_from_slice(&slot_bytes(&a, 0).unwrap());
    assert_eq!(flash_store::boot_erase([&store[0], &store[1]]), Some(1));
    // Where the erase starts (the image is deterministic): a run without input.
    let mut dry = bench(flash_with(&store));
    dry.run_until(0.1, |_| false).expect("run");
    let erase_at = dry
        .machine
        .core()
        .erase_stalls
        .first()
        .unwrap_or_else(|| panic!("no erase:\n{}", transcript(&dry)))
        .at;
    let mut b = bench(flash_with(&store));
    let from = 0;
    // The lines from 10 ms before the erase on (the receiver is on by then).
    let t0 = secs(erase_at) - 0.01;
    let sent: Vec<(Time, Time)> = (0..200)
        .map(|k| {
            let start = ps(t0 + 0.02 * f64::from(k));
            (start, b.send_at(secs(start), b"STATUS\n"))
        })
        .collect();
    b.run_until(t0 + 4.5, |_| false).expect("run");
    let stall = *b
        .machine
        .core()
        .erase_stalls
        .first()
        .unwrap_or_else(|| panic!("no erase:\n{}", transcript(&b)));
    // The bytes before it (interrupts) shift it a little.
    assert!(
        stall.at.abs_diff(erase_at) < ps(0.005),
        "erase at {:.4} s",
        secs(stall.at)
    );
    let stall_end = stall.at + stall.len;
    assert_eq!(stall.len, ps(2.0));
    // USART1 lost bytes, all of them while the CPU was stalled or right after (dropped while
    // the loss was pending).
    let rx = &b.machine.chip().usart1.received;
    let lost: Vec<Time> = rx.iter().filter(|r| r.lost).map(|r| r.at).collect();
    assert!(!lost.is_empty(), "no byte lost");
    assert!(
        lost.iter().all(|&t| t > stall.at && t <= stall_end),
        "bytes lost outside the erase"
    );
    let answers: Vec<&str> = answers_since(&b, from);
    let over: Vec<usize> = answers
        .iter()
        .enumerate()
        .filter(|(_, a)| **a == "ERR overrun")
        .map(|(k, _)| k)
        .collect();
    assert_eq!(over.len(), 1, "{answers:?}");
    let errs = answers.iter().filter(|a| a.starts_with("ERR ")).count();
    assert!(errs <= 2, "{answers:?}");
    let over_at = b
        .lines
        .iter()
        .skip(from)
        .find(|l| l.text == "ERR overrun")
        .map(|l| l.start)
        .expect("ERR overrun");
    assert!(over_at > stall_end, "ERR overrun before the erase ended");
    // Lines wholly before the erase and wholly after the answer: one STATUS each.
    let before = sent.iter().filter(|&&(_, end)| end < stall.at).count();
    let after = sent.iter().filter(|&&(start, _)| start > over_at).count();
    let status_before = b.lines[from..]
        .iter()
        .filter(|l| l.text.starts_with("STATUS ") && l.start < stall.at)
        .count();
    let status_after = b.lines[from..]
        .iter()
        .filter(|l| l.text.starts_with("STATUS ") && l.start > over_at)
        .count();
    assert!(
        status_before + 1 >= before && status_after >= after,
        "STATUS answers {status_before} before the erase ({before} lines sent), \
         {status_after} after ERR overrun ({after} lines sent)\n{}",
        transcript(&b)
    );
    println!(
        "overrun: {} bytes lost in the 2 s erase; ERR overrun {:.2} ms after it ended; \
         {status_after} of {after} lines answered after it",
        lost.len(),
        (over_at - stall_end) as f64 / 1e9
    );
}
