//! The ATmega2560 firmware's release ELF in simavr (16 MHz), closed loop with the simulated
//! SFM3300 and blower (`simavr_harness`). The ELF is brought up to date first (one
//! incremental nightly avr-none build per test process); a failed build fails the tests.
//!
//! Budgets checked: tick control work (ISR → sensor read → statistics → PWM written) < 1.6 ms
//! (25 600 cycles), every whole tick (with report lines, verdicts, persistence) within its
//! 10 ms period and no overruns, search < 10 s, `ACCEPT` within [`ACCEPT_BUDGET_S`] of
//! power-up, flash < 96 KB, static RAM + stack < 6 KB; the identified model's free-run fit on a
//! fresh validation signal ≥ [`MIN_FRESH_FIT`] %; the firmware's result equal to ridge-core's
//! on the host from the same samples (same structure, coefficients within [`COEF_TOL`]).
//!
//! Flow control (`tracks_*`): after `ACCEPT` the image designs its controller (≤ 100 ms) and
//! runs the demo program (steps, then breaths) on the default, small and sluggish blowers with
//! the adult and the stiff test lung; its `TRACK` lines must equal the figures recomputed from
//! the served frames, the run-mode control tick stay < 1.6 ms, and the true flow (scored by
//! `pump_sim`'s metrics) reach each level within the sensor noise, with the overshoot and the
//! breath RMS within the targets (10 %, 5 % of peak) or, where the design is known to
//! miss them (stiff lung), within a regression bound said at the test.

use pump_sim::baseline::table::breath_pct;
use pump_sim::sfm3300::flow_to_raw;
use pump_sim::PumpParams;
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::selfid::Config;
use simavr_harness::bench::{Action, Bench, BenchConfig, RunEnd};
use simavr_harness::bus::{BusEvent, BusState, SdaHold};
use simavr_harness::firmware;
use simavr_harness::sensor::Fault;
use simavr_harness::session::{self, Outcome, SessionConfig, TICK_CYCLES};
use simavr_harness::tracking::{design_cycles, run_trace};

/// Tick budget, cycles (1.6 ms at 16 MHz).
const TICK_BUDGET: u64 = 25_600;
/// Search budget, seconds.
const SEARCH_BUDGET_S: f64 = 10.0;
/// Flash budget, bytes: 96 KB of the ATmega2560's 256 KB (below 128 KB no EIND trampolines;
/// `scripts/build-boards` enforces the same figure, `AVR_FLASH_MAX`).
const FLASH_BUDGET: u32 = 96 * 1024;
/// Static RAM + stack budget, bytes.
const RAM_BUDGET: u32 = 6 * 1024;
/// Smallest free-run fit (%) of the identified model on a fresh host-side validation signal
/// ([`FRESH_RECORD`], new noise seed, the loop's timing): issue 31's target on the open outlet
/// (the model before it reached 92.3 % on the default blower). The firmware's own acceptance
/// threshold on its validation record is 70 %.
const MIN_FRESH_FIT: f64 = 92.0;
/// Excitation preset of the fresh validation signal: ramps over 25..85 %, a record the
/// firmware neither estimates nor validates on (its records are random steps).
const FRESH_RECORD: Record = Record::BRamp;
/// Issue 31's readiness target: the `ACCEPT` line within this long of power-up, s.
const ACCEPT_BUDGET_S: f64 = 20.0;
/// Largest coefficient difference between the firmware (f32 on the AVR) and ridge-core on the
/// host (f64) from the same samples, relative to max(1, |coefficient|). README: f32 vs f64 on
/// exact statistics differ by ≤ 1.4e-5 relative.
const COEF_TOL: f64 = 1e-4;

/// The default blower's steady flow (`pump_sim`) at the firmware's knots: a model's map for
/// records written here.
fn default_blower_map() -> ridge_core::InputMap {
    let r = Config::default().records;
    let pump = PumpParams::default();
    let mut knots = [0i16; ridge_core::MAP_KNOTS];
    for (k, v) in knots.iter_mut().enumerate() {
        let duty = f64::from(r.map_first + k as u16 * r.map_step) / 10_000.0;
        // Strictly increasing through the dead zone (the firmware's map is).
        *v = (pump.steady_state_flow(duty) * 120.0).round() as i16 + k as i16;
    }
    ridge_core::InputMap::new(r.map_first, r.map_step, knots).expect("map")
}

fn elf() -> std::path::PathBuf {
    firmware::ensure_elf().unwrap_or_else(|e| panic!("cannot build the ATmega2560 firmware: {e}"))
}

fn session(pump: PumpParams, seed: u64) -> Outcome {
    let mut cfg = SessionConfig::new(elf());
    cfg.bench.pump = pump;
    cfg.bench.seed = seed;
    cfg.max_s = 200.0;
    // Past the design, which starts 0.5 s after `PERSIST` (its blocking ticks are then known,
    // and its stack is on the STACK line as in the SRAM paint).
    cfg.linger_s = 1.0;
    session::run(&cfg).expect("simavr session")
}

fn transcript(o: &Outcome) -> String {
    o.bench.transcript(&["RES "])
}

/// Checks of one identification session; returns the list of failures.
fn check_identification(o: &Outcome, budgets: bool) -> Vec<String> {
    let firmware_config = Config::default();
    let mut bad = Vec::new();
    if let Some(h) = o.bench.halted() {
        bad.push(format!("core halted: {h:?}"));
    }
    if !o.bench.machine.resets().is_empty() {
        bad.push(format!(
            "{} reset(s) during the run",
            o.bench.machine.resets().len()
        ));
    }
    match o.bench.find_lines("ACCEPT").next() {
        None => bad.push("no ACCEPT line".into()),
        Some((_, l)) if budgets && l.cycle as f64 / 16e6 > ACCEPT_BUDGET_S => bad.push(format!(
            "ACCEPT at {:.2} s > {ACCEPT_BUDGET_S} s after power-up",
            l.cycle as f64 / 16e6
        )),
        Some(_) => {}
    }
    if !o.faults.is_empty() {
        bad.push(format!("FAULT lines: {:?}", o.faults));
    }
    if budgets {
        let t = &o.timing;
        if t.ticks < 1000 {
            bad.push(format!("only {} ticks timed", t.ticks));
        }
        // The budget covers the tick's control work: ISR entry → sensor read → statistics
        // update → PWM written. Report lines, the validation verdict and persistence follow the
        // PWM write; they only have to end before the next tick (no overrun, below).
        if t.control_ticks + 16 < t.ticks {
            bad.push(format!(
                "control latency seen in only {} of {} ticks",
                t.control_ticks, t.ticks
            ));
        }
        if t.control_worst >= TICK_BUDGET {
            bad.push(format!(
                "worst tick control latency {} cycles ≥ {TICK_BUDGET} (mean {:.0})",
                t.control_worst, t.control_mean
            ));
        }
        if t.worst >= TICK_CYCLES {
            bad.push(format!(
                "worst whole tick {} cycles ≥ one period ({TICK_CYCLES})",
                t.worst
            ));
        }
        if t.missed > 0 {
            bad.push(format!("{} tick overrun(s) outside the search", t.missed));
        }
        match t.search_cycles {
            Some(c) if (c as f64 / 16e6) < SEARCH_BUDGET_S => {}
            c => bad.push(format!("search time {c:?} cycles ≥ {SEARCH_BUDGET_S} s")),
        }
        if o.sizes.flash() >= FLASH_BUDGET {
            bad.push(format!("flash {} B ≥ {FLASH_BUDGET} B", o.sizes.flash()));
        }
        let stack = o.bench.stack_used().or(o.stack_used).unwrap_or(u32::MAX);
        if o.sizes.ram() + stack >= RAM_BUDGET {
            bad.push(format!(
                "static RAM {} B + stack {stack} B ≥ {RAM_BUDGET} B",
                o.sizes.ram()
            ));
        }
        // The worst case over every path (call graph), not only those this run took.
        match simavr_harness::stack::analyze_elf(&elf()) {
            Ok(r) if !r.complete() => bad.push(format!("stack bound incomplete: {r:?}")),
            Ok(r) if o.sizes.ram() + r.worst() >= RAM_BUDGET => bad.push(format!(
                "static RAM {} B + worst-case stack {} B ≥ {RAM_BUDGET} B",
                o.sizes.ram(),
                r.worst()
            )),
            Ok(r) if r.worst() < stack => bad.push(format!(
                "call-graph stack bound {} B below the measured {stack} B",
                r.worst()
            )),
            Ok(_) => {}
            Err(e) => bad.push(format!("stack analysis: {e}")),
        }
        if o.stack_used.is_some() && o.stack_used != o.bench.stack_used() {
            bad.push(format!(
                "STACK line {:?} B disagrees with the SRAM paint {:?} B",
                o.stack_used,
                o.bench.stack_used()
            ));
        }
    }
    let Some(id) = &o.id else {
        bad.push("no ID line".into());
        bad.push(format!(
            "the firmware's own state machine replayed on the host with the same readings: {}",
            replay(o)
        ));
        if let Some(est) = &o.estimation {
            match session::host_search(est) {
                Ok(h) => bad.push(format!(
                    "ridge-core on the host finds ({},{},{}) on the firmware's first record: {h:?}",
                    h.model.p, h.model.q, h.model.d
                )),
                Err(e) => bad.push(format!("host search on the first record: {e}")),
            }
        }
        return bad;
    };
    match &o.estimation {
        None => bad.push("estimation record could not be rebuilt from the served frames".into()),
        Some(est) => {
            // The duties matched the generator rebuilt from the MAP and SCAN lines.
            assert_eq!(est.len(), usize::from(firmware_config.records.samples));
            if est.map != o.map {
                bad.push(format!(
                    "the record's map {:?} is not the model's {:?}",
                    est.map, o.map
                ));
            }
            if est.y0_frames != Some(est.y0) {
                bad.push(format!(
                    "operating point: EXCITE says y0={} counts, the served frames give {:?}",
                    est.y0, est.y0_frames
                ));
            }
            match session::host_search(est) {
                Ok(host) => match session::coefficient_error(&id.model, &host.model) {
                    Some(e) if e <= COEF_TOL => {}
                    Some(e) => bad.push(format!(
                        "coefficients differ from the host by {e:.2e} (> {COEF_TOL:e}): firmware {id:?} host {host:?}"
                    )),
                    None => bad.push(format!(
                        "structure differs from the host: firmware ({},{},{}) host ({},{},{}) [host {host:?}]; the firmware's state machine replayed on the host: {}",
                        id.model.p, id.model.q, id.model.d, host.model.p, host.model.q, host.model.d, replay(o)
                    )),
                },
                Err(e) => bad.push(format!("host search failed: {e}")),
            }
        }
    }
    match &o.validation {
        Some(val) if val.len() != usize::from(firmware_config.records.validation) => {
            bad.push(format!("validation record of {} samples", val.len()))
        }
        Some(_) => {}
        None => bad.push("validation record could not be rebuilt from the served frames".into()),
    }
    match id.model.arx() {
        Err(_) => bad.push("ID line does not give a valid model".into()),
        Ok(model) => {
            let lat = o
                .estimation
                .as_ref()
                .map_or(2, |e| session::write_latency(&o.bench, e));
            let cfg = o.bench.config();
            let fresh = session::fresh_record(&session::FreshRecord {
                pump: &cfg.pump,
                lung: cfg.lung.as_ref(),
                sensor: &cfg.sensor,
                seed: cfg.seed + 1000,
                record: FRESH_RECORD,
                map: o.map,
                base: 3_000,
                latency: lat,
            });
            let (free, _, _) = session::score(&model, &fresh);
            match free {
                Some(f) if f >= MIN_FRESH_FIT => {}
                f => bad.push(format!(
                    "fresh validation free-run fit {f:?} < {MIN_FRESH_FIT} %"
                )),
            }
        }
    }
    bad
}

/// Replays the firmware's state machine (`ridge_pump_firmware::selfid`, compiled for the host)
/// with the readings the bench served, in order, and describes its first search result: tells an
/// AVR-specific defect (code generation, float library) from one of the algorithm.
fn replay(o: &Outcome) -> String {
    use ridge_pump_firmware::event::Event;
    use ridge_pump_firmware::selfid::{SelfIdentification, DEFAULT_CONFIG};
    use ridge_pump_firmware::sfm3300::raw_to_counts;
    let frames = o.bench.sensor.borrow().served();
    let mut sid = SelfIdentification::new(&DEFAULT_CONFIG, None);
    for (_, raw) in frames {
        sid.tick(Ok(raw_to_counts(raw)));
        sid.judge();
        if sid.needs_search() {
            return match sid.search(|| {}) {
                Some(Event::Identified { model, .. }) => {
                    let s = model.structure();
                    format!(
                        "({},{},{}) theta {:?} phi {:?} c {}",
                        s.p,
                        s.q,
                        s.d,
                        model.theta(),
                        model.phi(),
                        model.intercept()
                    )
                }
                other => format!("{other:?}"),
            };
        }
    }
    "no search reached".into()
}

fn assert_clean(what: &str, o: &Outcome, bad: Vec<String>) {
    assert!(
        bad.is_empty(),
        "{what}:\n- {}\nfirmware said:\n{}",
        bad.join("\n- "),
        transcript(o)
    );
}

/// Default pump: identification, host equality, fresh-signal fit, all budgets; then the
/// persisted record: an intact copy is loaded at the next boot, a corrupted one is rejected.
#[test]
fn default_pump_identifies_within_budgets_and_persists() {
    let o = session(PumpParams::default(), 1);
    let bad = check_identification(&o, true);
    assert_clean("default pump, seed 1", &o, bad);

    assert!(
        o.bench
            .find_lines("PERSIST")
            .any(|(_, l)| l.text == "PERSIST saved"),
        "no `PERSIST saved` after ACCEPT:\n{}",
        transcript(&o)
    );
    // Next boot with the EEPROM the firmware wrote (simavr keeps EEPROM in the core; the bench
    // programs it into a fresh core before reset).
    let mut machine_eeprom = o.bench.machine.eeprom();
    let written: Vec<usize> = machine_eeprom
        .iter()
        .enumerate()
        .filter(|(_, &b)| b != 0xFF)
        .map(|(i, _)| i)
        .collect();
    assert!(
        !written.is_empty(),
        "ACCEPT … persist, but the EEPROM is blank"
    );
    let boot = |eeprom: &[u8]| {
        let mut cfg = BenchConfig::new(elf());
        cfg.eeprom = vec![(0, eeprom.to_vec())];
        let mut bench = Bench::new(cfg).expect("bench");
        bench.run_until(3.0, |l| {
            l.text.starts_with("LOADED")
                || l.text.starts_with("STORED-REJECTED")
                || l.text.starts_with("SCAN")
        });
        bench
    };
    let intact = boot(&machine_eeprom);
    assert!(
        intact.find_lines("LOADED").next().is_some(),
        "intact record not loaded: {:?}",
        intact.lines
    );
    // Corrupt one byte in the middle of the record.
    let mid = written[written.len() / 2];
    machine_eeprom[mid] ^= 0x10;
    let corrupt = boot(&machine_eeprom);
    let texts: Vec<&str> = corrupt.lines.iter().map(|l| l.text.as_str()).collect();
    assert!(
        corrupt.find_lines("STORED-REJECTED").next().is_some(),
        "corrupted record (byte {mid}) not rejected: {texts:?}"
    );
    assert!(
        corrupt.find_lines("LOADED").next().is_none(),
        "corrupted record loaded: {texts:?}"
    );
}

#[test]
fn small_pump_identifies() {
    let o = session(PumpParams::small(), 7);
    let bad = check_identification(&o, false);
    assert_clean("small pump, seed 7", &o, bad);
}

#[test]
fn sluggish_pump_identifies() {
    let o = session(PumpParams::sluggish(), 11);
    let bad = check_identification(&o, false);
    assert_clean("sluggish pump, seed 11", &o, bad);
}

/// Runs to `at_s` (in the excitation), applies `fault`, runs on until a FAULT line or
/// `at_s + within_s`. Returns the bench and the FAULT line's index.
fn inject(actions: &[(f64, Action)], within_s: f64) -> (Bench, Option<usize>) {
    let mut bench = Bench::new(BenchConfig::new(elf())).expect("bench");
    for &(t, a) in actions {
        bench.schedule(t, a);
    }
    let until = actions.iter().map(|(t, _)| *t).fold(0.0, f64::max) + within_s;
    let end = bench.run_until(until, |l| l.text.starts_with("FAULT"));
    let idx = match end {
        RunEnd::Line(i) => Some(i),
        _ => None,
    };
    if idx.is_some() {
        // Two more ticks so the PWM log covers the stop.
        bench.run_for(0.03);
    }
    (bench, idx)
}

/// The pump must be off (duty 0 on the pin) from at most two ticks after the FAULT line's tick
/// on, to the end of the run.
fn assert_stopped(bench: &Bench, idx: usize, what: &str) {
    let line_start = bench.line_starts[idx];
    let deadline = line_start + 2 * TICK_CYCLES;
    let last_on = bench
        .duty_log
        .iter()
        .rev()
        .find(|d| d.fraction > 0.0)
        .map(|d| d.cycle);
    let off_since = bench
        .duty_log
        .iter()
        .rev()
        .find(|d| d.fraction > 0.0)
        .and_then(|on| bench.duty_log.iter().find(|d| d.cycle > on.cycle))
        .map(|d| d.cycle);
    assert!(
        bench
            .duty_at(bench.machine.cycle())
            .is_some_and(|d| d.fraction == 0.0),
        "{what}: pump still running at the end: {:?}",
        bench.duty_at(bench.machine.cycle())
    );
    assert!(
        off_since.is_some_and(|c| c <= deadline),
        "{what}: pump off at cycle {off_since:?} (last on {last_on:?}), FAULT line at {line_start}, deadline {deadline}"
    );
}

fn fault_case(actions: &[(f64, Action)], within_s: f64, expect: &str) {
    let (bench, idx) = inject(actions, within_s);
    let texts: Vec<&str> = bench.lines.iter().map(|l| l.text.as_str()).collect();
    let Some(idx) = idx else {
        panic!("{expect}: no FAULT line within {within_s} s: {texts:?}");
    };
    assert!(
        bench.lines[idx].text.contains(expect),
        "expected a FAULT with `{expect}`, got `{}`",
        bench.lines[idx].text
    );
    assert_stopped(&bench, idx, expect);
}

/// Fault injection starts at 5 s: the firmware is in the scan (after the 1.5 s settle).
const AT: f64 = 5.0;

#[test]
fn fault_sensor_absent_stops_pump() {
    fault_case(&[(AT, Action::Sensor(Fault::Absent))], 2.0, "sensor=nack");
}

#[test]
fn fault_crc_corruption_stops_pump_but_short_burst_is_bridged() {
    // A burst of three corrupted frames (30 ms) is bridged: no fault.
    let (bench, idx) = inject(
        &[
            (AT, Action::Sensor(Fault::CrcCorrupt)),
            (AT + 0.03, Action::Sensor(Fault::None)),
        ],
        2.0,
    );
    assert!(
        idx.is_none(),
        "a 30 ms CRC burst raised {:?}",
        idx.map(|i| &bench.lines[i].text)
    );
    fault_case(
        &[(AT, Action::Sensor(Fault::CrcCorrupt))],
        2.0,
        "sensor=crc",
    );
}

#[test]
fn fault_flow_out_of_range_stops_pump() {
    fault_case(
        &[(AT, Action::Sensor(Fault::Raw(flow_to_raw(300.0))))],
        1.0,
        "range",
    );
}

#[test]
fn fault_stalled_pump_stops_pump() {
    // After the settle phase a lost flow is the no-flow check's (less than a quarter of the
    // settled flow scaled to the duty, 1 s): `FAULT noflow`.
    fault_case(&[(AT, Action::Stall(true))], 30.0, "noflow");
}

#[test]
fn fault_stuck_reading_at_zero_flow_stops_pump() {
    // A frozen zero-flow reading while the pump is driven looks like a lost flow.
    fault_case(
        &[(AT, Action::Sensor(Fault::Stuck(flow_to_raw(0.0))))],
        30.0,
        "noflow",
    );
}

/// During the blocking structure search (from the end of the 7 s estimation record at
/// 12.94 s to ~13.65 s) the state machine does not tick, but the firmware still reads the sensor at the
/// tick boundaries its progress calls see and runs the fault checks: a sensor that dies in the
/// middle of the search stops the pump within the fault limit (5 ticks) plus the longest gap
/// between those reads, not only when the search is over.
#[test]
fn fault_sensor_absent_during_the_search_stops_pump_before_it_ends() {
    const DIES: f64 = 13.05;
    let (bench, idx) = inject(&[(DIES, Action::Sensor(Fault::Absent))], 4.0);
    let texts: Vec<&str> = bench.lines.iter().map(|l| l.text.as_str()).collect();
    let idx = idx.unwrap_or_else(|| panic!("no FAULT line: {texts:?}"));
    assert!(
        bench.lines[idx].text.contains("sensor=nack"),
        "{}",
        bench.lines[idx].text
    );
    // The search was running: its ID line comes after the sensor died.
    let id = texts
        .iter()
        .position(|t| t.starts_with("ID "))
        .unwrap_or_else(|| panic!("no ID line: {texts:?}"));
    let dies = (DIES * 16e6) as u64;
    assert!(
        bench.line_starts[id] > dies + 16_000_000 * 2 / 5,
        "{texts:?}"
    );
    // The pump stopped long before: 5 failed reads and at most ~0.15 s without a read.
    let off = bench
        .duty_log
        .iter()
        .find(|d| d.cycle > dies && d.fraction == 0.0)
        .map(|d| d.cycle)
        .unwrap_or(u64::MAX);
    let delay_s = off.saturating_sub(dies) as f64 / 16e6;
    assert!(delay_s < 0.25, "pump off {delay_s} s after the sensor died");
    assert!(
        off < bench.line_starts[id],
        "pump off only after the search"
    );
    assert!(
        bench
            .duty_at(bench.machine.cycle())
            .is_some_and(|d| d.fraction == 0.0),
        "pump running at the end"
    );
}

/// Standard-mode I2C clock phases (NXP UM10204, table 10), cycles at 16 MHz: SCL low ≥ 4.7 µs.
const I2C_LOW_MIN: u64 = 76;
/// ... and SCL high ≥ 4.0 µs.
const I2C_HIGH_MIN: u64 = 64;
/// SDA stuck low for good: the pump is off (duty 0 on the pin) and the FAULT line has started
/// within this long after SDA went low (docs/boards.md, Faults: five 10 ms ticks, the last
/// read's 2.5 ms timeout and the tick's work).
const SDA_STUCK_BOUND_S: f64 = 0.055;

/// Every SCL phase in cycles `from..to` that the bus model saw is as long as standard-mode I2C
/// asks (a high phase longer than 1 ms is the idle bus between two recoveries, not a phase).
fn check_clock(bus: &BusState, from: u64, to: u64, what: &str) {
    for (c0, high, len) in bus.scl_phases(from, to) {
        if high {
            assert!(
                len >= I2C_HIGH_MIN || len > 16_000,
                "{what}: SCL high for {len} cycles at {c0}"
            );
        } else {
            assert!(
                len >= I2C_LOW_MIN,
                "{what}: SCL low for {len} cycles at {c0}"
            );
        }
    }
}

/// I2C bus stuck low (issue 12 item 4), a sensor that lets go: after its next frame it keeps
/// SDA low (the harness's bus model: PD1 reads low, a START the TWI is asked for never
/// completes) until it has seen `k` clocks, as a slave stuck in a byte does. For k = 1, 5 and 9
/// (the most such a slave needs) in one run in the excitation, on the harness's own view of
/// the pins and of the slave: exactly k clock pulses, each phase as long as standard-mode I2C
/// asks, a STOP condition after the release, one failed START request and nothing reaching the
/// slave until the STOP, frames served again at every tick from the next one, no FAULT, the
/// pump running throughout.
#[test]
fn sda_held_low_by_the_sensor_is_clocked_free() {
    let mut bench = Bench::new(BenchConfig::new(elf())).expect("bench");
    bench.run_until(AT, |_| false);
    for k in [1u8, 5, 9] {
        let armed = bench.machine.cycle();
        bench.apply(Action::HoldSda(SdaHold::ReleaseAfter(k)));
        bench.run_for(0.3);
        let end = bench.machine.cycle();
        let bus = bench.bus.borrow();
        let what = format!("released after {k} clocks");
        let within = |c: &u64| (armed..end).contains(c);
        let holds = bus.times(|e| matches!(e, BusEvent::Hold(c) if within(c)));
        let releases = bus.times(|e| matches!(e, BusEvent::Release(c) if within(c)));
        assert!(
            holds.len() == 1 && releases.len() == 1,
            "{what}: holds {holds:?}, releases {releases:?}"
        );
        let (hold, release) = (holds[0], releases[0]);
        let pulses = bus.scl_pulses(hold, end);
        assert_eq!(pulses, usize::from(k), "{what}: clock pulses");
        assert!(pulses <= 9, "{what}: {pulses} clock pulses");
        check_clock(&bus, hold, end, &what);
        let blocked = bus.times(|e| matches!(e, BusEvent::BlockedStart(c) if within(c)));
        assert_eq!(blocked.len(), 1, "{what}: START requests on the held bus");
        let stops = bus.times(|e| matches!(e, BusEvent::Stop(c) if within(c)));
        assert!(
            stops.len() == 1 && stops[0] > release,
            "{what}: STOP conditions {stops:?}, release at {release}"
        );
        let stop = stops[0];
        let served: Vec<u64> = bench
            .sensor
            .borrow()
            .served()
            .iter()
            .map(|&(c, _)| c)
            .filter(|c| (hold..end).contains(c))
            .collect();
        assert!(
            served
                .first()
                .is_some_and(|&c| c > stop && c < stop + TICK_CYCLES + 16_000),
            "{what}: first frame after the hold at {:?}, STOP at {stop}",
            served.first()
        );
        let ticks = (end - stop) / TICK_CYCLES;
        assert!(
            served.len() as u64 >= ticks - 1,
            "{what}: {} frames served in the {ticks} ticks after the STOP",
            served.len()
        );
    }
    let texts: Vec<&str> = bench.lines.iter().map(|l| l.text.as_str()).collect();
    assert!(
        !texts.iter().any(|t| t.starts_with("FAULT")),
        "a fault: {texts:?}"
    );
    let since = bench.cycles(AT);
    assert!(
        bench.duty_at(since).is_some_and(|d| d.fraction > 0.0)
            && bench
                .duty_log
                .iter()
                .filter(|d| d.cycle >= since)
                .all(|d| d.fraction > 0.0),
        "the pump stopped: {:?}",
        bench.duty_log
    );
}

/// I2C bus stuck low for good (issue 12 item 4): the sensor never lets go of SDA. Every read
/// times out and is followed by 9 clock pulses that free nothing (no STOP condition can
/// happen); the fifth failed read in a row is the fault, `FAULT sensor=bus n=5`, with the pump
/// off (duty 0 on the pin) and the line started within [`SDA_STUCK_BOUND_S`] of SDA going low,
/// and the pump kept off.
#[test]
fn sda_held_low_for_good_stops_the_pump_within_its_bound() {
    let mut bench = Bench::new(BenchConfig::new(elf())).expect("bench");
    bench.schedule(AT, Action::HoldSda(SdaHold::Forever));
    let end = bench.run_until(AT + 1.0, |l| l.text.starts_with("FAULT"));
    let texts: Vec<&str> = bench.lines.iter().map(|l| l.text.as_str()).collect();
    let RunEnd::Line(idx) = end else {
        panic!("no FAULT line within 1 s: {texts:?}");
    };
    bench.run_for(0.03);
    assert_eq!(bench.lines[idx].text, "FAULT sensor=bus n=5");
    assert_stopped(&bench, idx, "SDA held low");
    let bus = bench.bus.borrow();
    let hold = bus.times(|e| matches!(e, BusEvent::Hold(_)));
    assert_eq!(hold.len(), 1, "holds");
    let hold = hold[0];
    let line = bench.line_starts[idx];
    let off = bench
        .duty_log
        .iter()
        .find(|d| d.cycle > hold && d.fraction == 0.0)
        .map_or(u64::MAX, |d| d.cycle);
    let bound = bench.cycles(SDA_STUCK_BOUND_S);
    assert!(
        off - hold <= bound && line - hold <= bound,
        "pump off {} ms and FAULT line {} ms after SDA went low (bound {} ms)",
        (off - hold) as f64 / 16e3,
        (line - hold) as f64 / 16e3,
        SDA_STUCK_BOUND_S * 1e3
    );
    // One failed read per tick, each followed by the full 9 clocks; the fifth in a row faults.
    let blocked = bus.times(|e| matches!(e, BusEvent::BlockedStart(c) if *c < line));
    assert_eq!(
        blocked.len(),
        usize::from(Config::default().sensor_fault_limit),
        "failed reads before the FAULT line: {blocked:?}"
    );
    for (i, &b) in blocked.iter().enumerate() {
        let next = blocked.get(i + 1).copied().unwrap_or(line);
        assert_eq!(
            bus.scl_pulses(b, next),
            9,
            "clock pulses after failed read {i}"
        );
    }
    check_clock(&bus, hold, line, "SDA held for good");
    let after = |c: &u64| *c > hold;
    assert!(
        bus.times(|e| matches!(e, BusEvent::Release(c) | BusEvent::Stop(c) if after(c)))
            .is_empty(),
        "SDA rose while held: {:?}",
        bus.events
    );
    // The pin itself: PIND (0x29) reads SDA (bit 1) low and SCL (bit 0) high.
    assert_eq!(bench.machine.data(0x29) & 0b11, 0b01, "PIND");
}

/// The same SFM3300 model works as an `avr_tester::TwiSlave` under avr-tester itself: the
/// firmware boots, starts the sensor and reads it (`SENSOR ready`), with UART read through
/// avr-tester.
#[test]
fn avr_tester_runs_the_firmware_with_the_sfm3300_slave() {
    use avr_tester::AvrTester;
    use pump_sim::{Sfm3300, Sfm3300Params};
    use simavr_harness::sensor::{SensorState, Sfm3300Slave, UPDATE_CYCLES_16MHZ};
    use std::cell::{Cell, RefCell};
    use std::rc::Rc;

    let mut avr = AvrTester::atmega2560()
        .with_clock_of_16_mhz()
        .with_timeout_of_s(1)
        .load(elf());
    // avr-tester gives slaves no clock: advance it by hand between short runs.
    let clock = Rc::new(Cell::new(0u64));
    let state = Rc::new(RefCell::new(SensorState::new(
        Sfm3300::new(Sfm3300Params::default(), 1),
        UPDATE_CYCLES_16MHZ,
    )));
    avr.twi0().attach_slave(Sfm3300Slave {
        state: state.clone(),
        clock: clock.clone(),
    });
    let mut out = String::new();
    for ms in 1..=200u64 {
        avr.run_for_ms(1);
        clock.set(ms * 16_000);
        out.push_str(&avr.uart0().read::<String>());
    }
    assert!(out.contains("BOOT board=atmega2560"), "UART: {out:?}");
    assert!(out.contains("SENSOR ready"), "UART: {out:?}");
    assert!(state.borrow().measuring());
    assert!(!state.borrow().served().is_empty());
}

/// The two EEPROM slots in the real firmware: slot A holds a whole record the state machine
/// refuses (fit 50 % < the 70 % acceptance), so the firmware identifies anew and saves record B
/// into the other slot, a byte per tick. The EEPROM is copied at every tick of that save and
/// the board rebooted from copies cut at several points: until B's sequence number (its last
/// byte) is written, A is the record found (refused again for its fit: whole, not `crc`);
/// afterwards B is loaded. (The host test `firmware/tests/slots.rs` cuts at every byte.)
#[test]
fn a_save_cut_at_any_point_keeps_the_other_slot() {
    use ridge_core::{ArxModel, Offset};
    use ridge_pump_firmware::persist::{self, RECORD_LEN};
    use ridge_pump_firmware::slots::{self, SLOT_LEN, STORE_LEN, UNWRITTEN};

    let model = ArxModel::new(&[0.9f32], &[0.1], 3, Offset::Intercept, 0.0).expect("model");
    let a = persist::encode(&model, &default_blower_map(), 50.0);
    let (a_at, a_bytes) =
        slots::slot_bytes(&a, &slots::plan(&[0xFF; STORE_LEN])).expect("slot bytes");
    let mut cfg = BenchConfig::new(elf());
    cfg.eeprom = vec![(a_at, a_bytes.to_vec())];
    let mut bench = Bench::new(cfg.clone()).expect("bench");
    let end = bench.run_until(150.0, |l| l.text.starts_with("ACCEPT"));
    assert!(
        matches!(end, RunEnd::Line(_)),
        "no ACCEPT: {:?}",
        bench.lines.iter().map(|l| &l.text).collect::<Vec<_>>()
    );
    assert!(
        bench
            .lines
            .iter()
            .any(|l| l.text.starts_with("STORED-REJECTED fit=50.0<70.0")),
        "record A not refused for its fit"
    );
    // B goes to the slot A is not in.
    let b_at = SLOT_LEN - usize::from(a_at);
    let mut copies = Vec::new();
    for _ in 0..300 {
        bench.run_for(0.01);
        let e = bench.machine.eeprom();
        if copies.last() != Some(&e) {
            copies.push(e.clone());
        }
        if bench.lines.iter().any(|l| l.text == "PERSIST saved") {
            break;
        }
    }
    let last = copies.last().cloned().expect("EEPROM copies");
    assert_ne!(
        last[b_at + RECORD_LEN],
        UNWRITTEN,
        "B's sequence number never written"
    );
    assert_eq!(
        last[..STORE_LEN][usize::from(a_at)..][..SLOT_LEN],
        a_bytes[..],
        "A touched"
    );
    // Cuts: the first copy with B's first bytes, one in the middle, the last one before B's
    // sequence number, and the finished save.
    let before_seq: Vec<&Vec<u8>> = copies
        .iter()
        .filter(|e| e[b_at + RECORD_LEN] == UNWRITTEN)
        .collect();
    assert!(
        before_seq.len() >= 10,
        "{} copies before the sequence number",
        before_seq.len()
    );
    let cuts = [
        before_seq[0],
        before_seq[before_seq.len() / 2],
        before_seq[before_seq.len() - 1],
        &last,
    ];
    for (i, eeprom) in cuts.iter().enumerate() {
        let mut cfg = BenchConfig::new(elf());
        cfg.eeprom = vec![(0, eeprom[..STORE_LEN].to_vec())];
        let mut boot = Bench::new(cfg).expect("bench");
        boot.run_until(4.0, |l| {
            l.text.starts_with("LOADED") || l.text.starts_with("STORED-REJECTED")
        });
        let texts: Vec<&str> = boot.lines.iter().map(|l| l.text.as_str()).collect();
        if i + 1 < cuts.len() {
            assert!(
                texts
                    .iter()
                    .any(|l| l.starts_with("STORED-REJECTED fit=50.0<70.0")),
                "cut {i}: record A not found whole: {texts:?}"
            );
        } else {
            assert!(
                texts.iter().any(|l| l.starts_with("LOADED")),
                "finished save: B not loaded: {texts:?}"
            );
        }
    }
}

/// EEPROM through simavr: a record written with the firmware's own encoder into its slot
/// (the one a blank EEPROM's first save goes to) is loaded at boot (`LOADED`, no identification); the same record with one byte
/// flipped is rejected (`STORED-REJECTED`) and the firmware identifies anew (`SCAN`).
#[test]
fn persisted_record_is_loaded_and_a_corrupted_one_rejected() {
    use ridge_core::{ArxModel, Offset};
    use ridge_pump_firmware::{persist, slots};

    let model = ArxModel::new(&[0.9f32], &[0.1], 3, Offset::Intercept, 0.0).expect("model");
    let record = persist::encode(&model, &default_blower_map(), 88.5);
    let plan = slots::plan(&[0xFF; slots::STORE_LEN]);
    let boot = |bytes: &[u8]| {
        let (at, slot) = slots::slot_bytes(bytes, &plan).expect("slot");
        let mut cfg = BenchConfig::new(elf());
        cfg.eeprom = vec![(at, slot.to_vec())];
        let mut bench = Bench::new(cfg).expect("bench");
        bench.run_until(4.0, |l| {
            l.text.starts_with("LOADED") || l.text.starts_with("SCAN")
        });
        bench
            .lines
            .iter()
            .map(|l| l.text.clone())
            .collect::<Vec<_>>()
    };
    let intact = boot(&record);
    assert!(
        intact.iter().any(|l| l.starts_with("LOADED p=1 q=1 d=3")),
        "intact record not loaded: {intact:?}"
    );
    assert!(
        !intact
            .iter()
            .any(|l| l.starts_with("SCAN") || l.starts_with("STORED-REJECTED")),
        "{intact:?}"
    );
    for byte in [0, record.len() / 2, record.len() - 1] {
        let mut bad = record;
        bad[byte] ^= 0x04;
        let lines = boot(&bad);
        assert!(
            lines.iter().any(|l| l.starts_with("STORED-REJECTED")),
            "byte {byte} flipped: not rejected: {lines:?}"
        );
        assert!(
            !lines.iter().any(|l| l.starts_with("LOADED")),
            "byte {byte} flipped: loaded anyway: {lines:?}"
        );
        assert!(
            lines.iter().any(|l| l.starts_with("SCAN")),
            "byte {byte} flipped: no new identification: {lines:?}"
        );
    }
}

/// Identification, design and the demo program in run mode (steps, then breaths) on `blower`
/// with `outlet`, then the checks every run must pass; returns the scores.
///
/// Truth for the figures: the simulated plant's true flow (not the firmware's readings), scored
/// by `pump_sim`'s own metrics; the firmware's `TRACK` lines are recomputed from the frames the
/// bench served. Budgets: design ≤ 100 ms, control tick in run mode < 1.6 ms, no overruns.
fn tracking_run(
    blower: pump_sim::Blower,
    outlet: pump_sim::Outlet,
    seed: u64,
) -> pump_sim::baseline::experiment::Scores {
    let plant = pump_sim::PlantArgs::preset(blower, outlet);
    let what = plant.describe();
    let mut cfg = SessionConfig::new(elf());
    cfg.bench.pump = plant.pump();
    cfg.bench.lung = plant.lung().expect("lung preset");
    cfg.bench.seed = seed;
    cfg.max_s = 200.0;
    cfg.track_s = f64::from(pump_sim::baseline::experiment::run_ticks()) * 0.01 + 0.5;
    let o = session::run(&cfg).expect("simavr session");
    let mut bad = Vec::new();
    if o.accept.is_none() {
        bad.push("no ACCEPT line".to_string());
    }
    if !o.faults.is_empty() {
        bad.push(format!("FAULT lines: {:?}", o.faults));
    }
    if o.bench.find_lines("ALARM").next().is_some() {
        bad.push("a tracking ALARM on the demo program".into());
    }
    if o.timing.missed > 0 {
        bad.push(format!("{} tick overrun(s)", o.timing.missed));
    }
    let run = match run_trace(&o.bench) {
        Ok(r) => r,
        Err(e) => {
            bad.push(format!("no run mode: {e}"));
            assert_clean(&what, &o, bad);
            unreachable!()
        }
    };
    // The firmware's TRACK figures are those of the flow it was served.
    if let Err(e) = run.track_check() {
        bad.push(e);
    }
    match design_cycles(&o.bench) {
        Some(c) if c < session::DESIGN_BUDGET_CYCLES => {}
        c => bad.push(format!("design {c:?} cycles ≥ 100 ms")),
    }
    let control: Vec<u64> = o
        .bench
        .ticks()
        .iter()
        .filter(|t| t.start >= run.first_at)
        .filter_map(|t| t.control)
        .collect();
    if let Some(w) = control.iter().max() {
        println!(
            "{what}: run-mode control tick worst {w} cycles = {:.3} ms over {} ticks",
            *w as f64 / 16e3,
            control.len()
        );
    }
    match control.iter().max() {
        Some(&w) if w < TICK_BUDGET && control.len() > 1000 => {}
        w => bad.push(format!(
            "run-mode control tick worst {w:?} cycles over {} ticks (budget {TICK_BUDGET})",
            control.len()
        )),
    }
    let scores = run.scores();
    if scores.is_none() {
        bad.push("run mode too short to score".into());
    }
    assert_clean(&what, &o, bad);
    scores.unwrap()
}

/// Steady-state error within the sensor noise on every level (σ: the SFM3300 model's noise,
/// 3 % of the flow), and the largest overshoot and the breath RMS (% of the 60 slm peak) within
/// `overshoot_max` and `breath_max`.
fn assert_tracks(
    what: &str,
    sc: &pump_sim::baseline::experiment::Scores,
    overshoot_max: f64,
    breath_max: f64,
) {
    let over = sc
        .steps
        .iter()
        .flatten()
        .map(|m| m.overshoot_pct)
        .fold(0.0, f64::max);
    let ss = sc
        .steps
        .iter()
        .flatten()
        .map(|m| m.ss_error.abs())
        .fold(0.0, f64::max);
    println!(
        "{what}: largest overshoot {over:.1} %, largest |e_ss| {ss:.3} slm, breath RMS {:.2} slm ({:.2} % of peak), duty TV {:.0} %/s",
        sc.breath_rms,
        breath_pct(sc.breath_rms),
        100.0 * sc.duty_tv
    );
    let sensor = pump_sim::sfm3300::Sfm3300Params::default();
    let sigma = |level: f64| sensor.noise_std(level);
    for (m, level) in sc.steps.iter().zip(&sc.levels) {
        let m = m
            .as_ref()
            .unwrap_or_else(|| panic!("{what}: step to {level} not scored"));
        assert!(
            m.ss_error.abs() <= sigma(*level),
            "{what}: steady-state error {:.3} slm at {level} slm > σ {:.3}",
            m.ss_error,
            sigma(*level)
        );
        assert!(
            m.overshoot_pct <= overshoot_max,
            "{what}: overshoot {:.1} % at {level} slm > {overshoot_max} %",
            m.overshoot_pct
        );
    }
    let breath = breath_pct(sc.breath_rms);
    assert!(
        breath <= breath_max,
        "{what}: breath RMS {breath:.2} % of peak > {breath_max} %"
    );
}

#[test]
fn tracks_default_blower_adult_lung() {
    let sc = tracking_run(pump_sim::Blower::Default, pump_sim::Outlet::Adult, 1);
    assert_tracks("default blower, adult lung", &sc, 10.0, 5.0);
}

#[test]
fn tracks_default_blower_stiff_lung() {
    let sc = tracking_run(pump_sim::Blower::Default, pump_sim::Outlet::Stiff, 2);
    // The 10 % overshoot target is missed with the stiff lung (17 % measured here, 15–20 % in
    // docs/control.md): a regression bound, not the target.
    assert_tracks("default blower, stiff lung", &sc, 25.0, 5.0);
}

#[test]
fn tracks_small_blower_adult_lung() {
    let sc = tracking_run(pump_sim::Blower::Small, pump_sim::Outlet::Adult, 3);
    assert_tracks("small blower, adult lung", &sc, 10.0, 5.0);
}

#[test]
fn tracks_small_blower_stiff_lung() {
    let sc = tracking_run(pump_sim::Blower::Small, pump_sim::Outlet::Stiff, 4);
    // The 10 % overshoot target is missed with the stiff lung (26 % measured here, 19–23 % in
    // docs/control.md): a regression bound, not the target.
    assert_tracks("small blower, stiff lung", &sc, 40.0, 5.0);
}

#[test]
fn tracks_sluggish_blower_adult_lung() {
    let sc = tracking_run(pump_sim::Blower::Sluggish, pump_sim::Outlet::Adult, 5);
    assert_tracks("sluggish blower, adult lung", &sc, 10.0, 5.0);
}

#[test]
fn tracks_sluggish_blower_stiff_lung() {
    let sc = tracking_run(pump_sim::Blower::Sluggish, pump_sim::Outlet::Stiff, 6);
    // The 5 % breath target is missed by a hair with the stiff lung (5.1 % measured here,
    // 5.3 % in docs/control.md): a regression bound, not the target.
    assert_tracks("sluggish blower, stiff lung", &sc, 10.0, 6.0);
}

/// MCUSR, data-space address (ATmega2560 datasheet, register summary: I/O 0x34).
const MCUSR: u16 = 0x54;
/// MCUSR's watchdog reset flag (WDRF, bit 3) and power-on reset flag (PORF, bit 0).
const WDRF: u8 = 1 << 3;
const PORF: u8 = 1 << 0;

/// Resets the core the way simavr's watchdog does on a timeout (sets WDRF, then resets; the
/// flags survive the reset) or, with `PORF`, as a power-on. Returns the index of the first
/// line after the reset.
fn reset_with(bench: &mut Bench, flag: u8) -> usize {
    bench.machine.poke(MCUSR, flag);
    bench.machine.reset();
    bench.lines.len()
}

/// The reset count in the simulated EEPROM.
fn reset_count(bench: &Bench) -> ridge_pump_firmware::resets::Resets {
    use ridge_pump_firmware::resets::{Resets, COUNT_OFFSET};
    Resets::from_byte(bench.machine.eeprom()[usize::from(COUNT_OFFSET)])
}

/// Watchdog resets: one in the middle of the blocking structure search restarts the pump
/// safely (a new boot, the identification from the start, no fault); the third in a row keeps
/// the pump off with `FAULT resets watchdog=3 brownout=0`, in the same boot, and the count
/// stays in EEPROM; a power-on clears it and the pump identifies again.
#[test]
fn watchdog_resets_restart_safely_and_a_reset_loop_keeps_the_pump_off() {
    use ridge_pump_firmware::resets::Resets;

    let mut bench = Bench::new(BenchConfig::new(elf())).expect("bench");
    // Into the search: the only stretch after the excitation with kilobytes of stack in use
    // (the boot's `init` goes 1.5 KB deep too, with the console's buffers: hence after the
    // `EXCITE` line).
    let ramend = bench.machine.ramend();
    let mut in_search = false;
    while bench.time_s() < 90.0 {
        bench.run_for(0.005);
        let excited = bench.lines.iter().any(|l| l.text.starts_with("EXCITE"));
        if excited && bench.machine.sp() < ramend - 1500 {
            in_search = true;
            break;
        }
    }
    assert!(in_search, "no search within 90 s");
    assert!(
        !bench.lines.iter().any(|l| l.text.starts_with("SEARCH ")),
        "the search had already ended"
    );

    // First watchdog reset, mid-search: a clean restart.
    let from = reset_with(&mut bench, WDRF);
    bench.run_until(bench.time_s() + 12.0, |l| l.text.starts_with("EXCITE"));
    let after: Vec<&str> = bench.lines[from..]
        .iter()
        .map(|l| l.text.as_str())
        .collect();
    assert!(
        after
            .first()
            .is_some_and(|l| l.starts_with("BOOT board=atmega2560 reset=8 ")),
        "{after:?}"
    );
    assert!(after.iter().any(|l| l.starts_with("EXCITE")), "{after:?}");
    assert!(!after.iter().any(|l| l.starts_with("FAULT")), "{after:?}");
    assert_eq!(
        reset_count(&bench),
        Resets {
            watchdog: 1,
            brownout: 0
        }
    );

    // Second and third, a second after each boot: the third is a loop.
    reset_with(&mut bench, WDRF);
    bench.run_for(1.0);
    let third_at = bench.machine.cycle();
    let from = reset_with(&mut bench, WDRF);
    bench.run_for(5.0);
    let after: Vec<&str> = bench.lines[from..]
        .iter()
        .map(|l| l.text.as_str())
        .collect();
    assert!(
        after.contains(&"FAULT resets watchdog=3 brownout=0"),
        "{after:?}"
    );
    assert!(!after.iter().any(|l| l.starts_with("EXCITE")), "{after:?}");
    let driven: Vec<f64> = bench
        .duty_log
        .iter()
        .filter(|d| d.cycle > third_at)
        .map(|d| d.fraction)
        .collect();
    assert!(
        driven.iter().all(|&f| f == 0.0),
        "pump driven in a reset loop: {driven:?}"
    );
    assert_eq!(
        reset_count(&bench),
        Resets {
            watchdog: 3,
            brownout: 0
        }
    );

    // A power-on clears the count: the pump identifies again.
    let from = reset_with(&mut bench, PORF);
    bench.run_until(bench.time_s() + 12.0, |l| l.text.starts_with("EXCITE"));
    let after: Vec<&str> = bench.lines[from..]
        .iter()
        .map(|l| l.text.as_str())
        .collect();
    assert!(after.iter().any(|l| l.starts_with("EXCITE")), "{after:?}");
    assert!(!after.iter().any(|l| l.starts_with("FAULT")), "{after:?}");
    assert_eq!(reset_count(&bench), Resets::default());
}

/// A watchdog reset followed by a clean minute: the count is cleared in EEPROM, so that
/// resets far apart never add up to a loop.
#[test]
fn a_clean_minute_clears_the_reset_count() {
    use ridge_pump_firmware::resets::{Resets, CLEAN_TICKS, COUNT_OFFSET};

    let mut cfg = BenchConfig::new(elf());
    // Two watchdog resets already counted.
    let two = Resets {
        watchdog: 2,
        brownout: 0,
    };
    cfg.eeprom = vec![(COUNT_OFFSET, vec![two.to_byte()])];
    let mut bench = Bench::new(cfg).expect("bench");
    // simavr powers on with PORF: a power-on clears the count at boot.
    bench.run_for(0.5);
    assert_eq!(reset_count(&bench), Resets::default());
    // A watchdog reset now counts one; still counted just before the clean minute ends ...
    reset_with(&mut bench, WDRF);
    let clean_s = f64::from(CLEAN_TICKS) * 0.01;
    bench.run_for(clean_s - 1.0);
    assert_eq!(
        reset_count(&bench),
        Resets {
            watchdog: 1,
            brownout: 0
        }
    );
    // ... and cleared after it (the search's ticks do not count, hence the margin).
    bench.run_for(15.0);
    assert_eq!(reset_count(&bench), Resets::default());
    assert!(!bench.lines.iter().any(|l| l.text.starts_with("FAULT")));
}
