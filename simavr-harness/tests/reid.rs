//! Run mode's closed-loop re-identification on the opt-in ATmega2560 image (feature
//! `atmega2560-reid`, over the 96 KB flash budget: docs/boards.md) in simavr: ISO 80601-2-12
//! row 1's test lung that becomes C 10 mL/cmH₂O, R 50 cmH₂O/(L/s) as breath 10 starts, as
//! `stm32-harness/tests/reid.rs` runs the same code on the STM32F411 image. The image starts
//! from a stored model (the firmware's state machine identified on pump-sim's rig, seed 3, as
//! on the STM32F411).
//!
//! The image runs in the chip's 8 KB of SRAM (static RAM and `main`'s frame with the state
//! machine, 5.7 KB, and the deepest stack below it; `avr-stack` and docs/boards.md have the
//! figures); the RAM figures are printed, not asserted.
//!
//! What it checks (numbers printed with `--nocapture`):
//! - `REID` lines every other breath on the adult lung (a snapshot at a breath's start, the
//!   next breath held out), every one `kept` (no volume alarm: the default swap rule keeps the
//!   running controller), their static gain within the plant's response through the map over
//!   the inspiration against the closed valve (pump-sim, as on the STM32F411); on the stiff
//!   lung the estimates are refused by the model check and the power-up controller runs on;
//! - the host's replay of the firmware's code on what the bench observed (harness-kit) prints
//!   the same lines: same verdicts, gains to the printed digit (the AVR computes what the host
//!   computes; this backend has miscompiled ordinary Rust before);
//! - the control tick (tick interrupt → PWM written, simavr's cycle count) within 1.6 ms while
//!   the re-identification runs, no fault; every whole tick (to the main loop's idle wait) within
//!   the 10 ms period, the bench's tick detector finding no overrun and the firmware printing
//!   no `MISSED` line: the snapshot is taken in the two ticks after the breath boundary's, not
//!   beside the boundary's bookkeeping and a verdict (`ridge_pump_firmware::reid`).
//!
//! Truths: the simulated lung (its parameters, what it received), the breath timing the `VENT`
//! line sets (rate 20 /min: 300 ticks a breath), pump-sim's linearisation of the plant through
//! the model's map (an independent computation from the plant) for the re-estimated static
//! gain, the host's build of the same code, the bench's tick detector.

use harness_kit::run::v_rms_unit;
use pump_sim::baseline::experiment::identify_with;
use pump_sim::iso::iso_row;
use pump_sim::reid::{closed_valve_step, linearisation, secant_through_map, through_map};
use pump_sim::vent_bench::power_up_plant;
use pump_sim::{LungParams, Valve};
use ridge_pump_firmware::lines::ReidLine;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::Shape;
use simavr_harness::bench::{Bench, LungChange};
use simavr_harness::firmware;
use simavr_harness::session::SessionConfig;
use simavr_harness::tracking::run_trace_ventilated;
use simavr_harness::vent_bench::{stored_model, vent_line};
use simavr_harness::ventilation::{self, VentConfig};

/// Tick budget, cycles (1.6 ms at 16 MHz).
const TICK_BUDGET: u64 = 25_600;
/// The tick period, cycles (10 ms at 16 MHz).
const PERIOD: u64 = 160_000;
/// Ticks of row 1's breath (20 /min at 100 Hz).
const BREATH_TICKS: u64 = 300;
/// The sensor seed of the stored model's identification (the STM32F411 test's).
const MODEL_SEED: u64 = 3;
/// The breath whose start changes the lung.
const CHANGE: u32 = 10;

fn transcript(b: &Bench) -> String {
    b.transcript(&["RES ", "TRACK "])
}

fn reids(b: &Bench) -> Vec<ReidLine> {
    b.find_lines("REID")
        .map(|(_, l)| ReidLine::parse(&l.text).unwrap_or_else(|e| panic!("{}: {e:?}", l.text)))
        .collect()
}

#[test]
fn the_avr_re_identifies_as_the_host_does_with_every_tick_within_the_period() {
    let elf = firmware::ensure_reid_elf()
        .unwrap_or_else(|e| panic!("cannot build the opt-in ATmega2560 image: {e}"));
    let sizes = firmware::sizes(&elf).expect("sizes");
    let row = iso_row(1).expect("row 1");
    let lung = row.lung(&LungParams::adult());
    let mut session = SessionConfig::new(elf);
    session.bench.lung = Some(lung.clone());
    session.bench.eeprom = stored_model(&lung, MODEL_SEED).expect("stored model");
    session.max_s = 90.0;
    // Nine breaths on the adult lung, the change as breath 10 starts (its valve closes), ten on
    // the stiff lung.
    let stiff = LungChange {
        compliance: Some(10.0),
        resistance: Some(50.0),
        ..LungChange::default()
    };
    let cfg = VentConfig {
        session,
        command: vent_line(&row, Shape::Square),
        identify_peep: 0.0,
        peep: lung.peep,
        breaths: 2 * CHANGE,
        change: Some((CHANGE as usize, 0.0, stiff)),
    };
    let out = ventilation::run(&cfg).expect("ventilated session");
    let b = &out.outcome.bench;
    let all = reids(b);
    for r in &all {
        println!(
            "REID breath {:2}: {:11} gain {:.3} fit {:.1} / running {:.1}, v-rms {:.3}",
            r.breath, r.verdict, r.gain, r.fit, r.running, r.v_rms
        );
    }
    for r in &out.rows {
        if let Some(l) = &r.firmware {
            println!(
                "BREATH {:2}: lung {:6.1} mL, firmware vd {:6.1} of {:.1}",
                r.number, r.truth.delivered, l.delivered, l.tidal
            );
        }
    }
    assert_eq!(out.answer.as_deref(), Some("OK vent"), "{}", transcript(b));
    assert!(out.rows.len() >= 2 * CHANGE as usize, "{}", transcript(b));
    let faults: Vec<&str> = b
        .lines
        .iter()
        .filter(|l| l.text.starts_with("FAULT") || l.text == "PANIC")
        .map(|l| l.text.as_str())
        .collect();
    assert!(faults.is_empty(), "{faults:?}\n{}", transcript(b));

    // The ticks from `OK vent` on.
    let ok = b
        .lines
        .iter()
        .position(|l| l.text == "OK vent")
        .expect("OK vent");
    let from = b.line_starts[ok];
    let ticks: Vec<_> = b.ticks().iter().filter(|t| t.start >= from).collect();
    let control = ticks.iter().filter_map(|t| t.control).max().unwrap_or(0);
    let busy = ticks.iter().map(|t| t.busy).max().unwrap_or(0);
    // Ticks after the valve's last closing before them: the breath's phase.
    let phase = |start: u64| {
        b.valve_log
            .iter()
            .rfind(|(c, v)| *c <= start && *v == Valve::Closed)
            .map(|(c, _)| ((start - c) as f64 / (PERIOD as f64)).round() as u64)
    };
    let boundary = |start: u64| phase(start).is_some_and(|k| k % BREATH_TICKS <= 1);
    let slow: Vec<_> = ticks.iter().filter(|t| t.busy > PERIOD / 2).collect();
    for t in &slow {
        println!(
            "tick at {:7.3} s, {:?} ticks after the valve closed: {} cycles",
            t.start as f64 / 16e6,
            phase(t.start),
            t.busy
        );
    }
    let inside = ticks
        .iter()
        .filter(|t| !boundary(t.start))
        .map(|t| t.busy)
        .max()
        .unwrap_or(0);
    let missed: Vec<&str> = b
        .find_lines("MISSED")
        .map(|(_, l)| l.text.as_str())
        .collect();
    println!(
        "{} ticks ventilating: control worst {control} cycles ({:.3} ms), whole tick worst \
         {busy} cycles, away from the breath boundary {inside}; ticks over half the period {}; \
         bench overruns {}; {missed:?}",
        ticks.len(),
        control as f64 / 16e3,
        slow.len(),
        out.outcome.timing.missed,
    );
    println!(
        "flash {} B (text {} + data {}), static RAM {} B, stack high-water {:?} B",
        sizes.flash(),
        sizes.text,
        sizes.data,
        sizes.ram(),
        b.stack_used()
    );
    assert!(ticks.len() > 6000, "{} ticks", ticks.len());
    assert!(
        control > 0 && control <= TICK_BUDGET,
        "control tick {control} cycles"
    );
    // Every tick, the breath boundary's and the snapshot's included, ends within the period:
    // the bench sees no tick start while the previous one runs, and the firmware's own count
    // of late ticks stays silent.
    assert!(
        busy < PERIOD && inside < PERIOD,
        "a tick of {busy} cycles ({inside} away from the boundary)"
    );
    assert!(
        ticks.iter().all(|t| !t.interrupted_busy),
        "a tick found the previous one running"
    );
    assert_eq!(out.outcome.timing.missed, 0, "bench overruns");
    assert!(missed.is_empty(), "{missed:?}");

    // Adult lung: snapshot and held-out breath both before the change (breaths 1 to 9).
    let adult: Vec<&ReidLine> = all.iter().filter(|r| r.breath + 1 < CHANGE).collect();
    let snapshots: Vec<u32> = adult.iter().map(|r| r.breath).collect();
    assert!(
        adult.len() >= 4 && snapshots.windows(2).all(|w| w[1] == w[0] + 2),
        "REID lines before the change every other breath: {snapshots:?}\n{}",
        transcript(b)
    );
    assert!(
        b.find_lines("ALARM volume").next().is_none(),
        "{}",
        transcript(b)
    );
    assert!(
        adult.iter().all(|r| r.verdict == "kept"),
        "{}",
        transcript(b)
    );
    // Their static gain against the plant through the power-up model's map (the model the
    // image loaded): the inspiration against the closed valve, from the bias flow (5 slm) at
    // the duty of the breath's 30 slm, after 50 and 100 ticks (as stm32-harness/tests/reid.rs).
    let plant = power_up_plant(&lung);
    let (_, sm, _) = identify_with(&plant, MODEL_SEED, &DEFAULT_CONFIG).expect("identification");
    let table = sm.map().expect("map").table();
    let open = secant_through_map(
        &linearisation(&plant, &lung, 5.0),
        &linearisation(&plant, &lung, 30.0),
        &table,
    );
    let closed = through_map(&closed_valve_step(&plant, &lung, 5.0, 30.0, 100), &table);
    let (c50, c100) = (closed.step[49], closed.gain);
    println!(
        "closed valve through the map: {c50:.3} after 50 ticks, {c100:.3} after 100; open \
         valve secant {open:.3}"
    );
    for r in &adult {
        assert!(
            r.gain >= 0.95 * c100 && r.gain <= 1.05 * c50,
            "breath {}: gain {:.3} outside the closed-valve band {c100:.3}-{c50:.3}",
            r.breath,
            r.gain
        );
    }
    // The stiff lung: re-estimated every breath once `DRIFT` is raised, none swapped in.
    let changed: Vec<&ReidLine> = all.iter().filter(|r| r.breath > CHANGE).collect();
    assert!(changed.len() >= 4, "{}", transcript(b));
    assert!(
        all.iter().all(|r| r.verdict != "accepted"),
        "{}",
        transcript(b)
    );

    // The host's replay of the same code on what the bench observed: the same lines, within
    // what the replay cannot see (the duty read back from the pin, the LOADED line's 6
    // decimals; `RunTrace::reid_check`).
    let trace = run_trace_ventilated(b, out.breath).expect("replay");
    let top = b
        .duty_log
        .iter()
        .map(|d| d.top)
        .max()
        .expect("a duty written");
    let v_unit = v_rms_unit(&table, u32::from(top) + 1);
    println!(
        "v RMS tolerance {v_unit:.3} slm (half a step of TOP + 1 = {} through the map)",
        u32::from(top) + 1
    );
    if let Err(e) = trace.reid_check(&all, v_unit) {
        panic!("{e}");
    }
}
