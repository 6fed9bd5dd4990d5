//! The exhalation valve of the STM32F411 release image (PB0, high = closed, docs/boards.md),
//! closed loop with ISO 80601-2-12 row 1's test lung, as
//! `simavr-harness/tests/ventilation.rs` checks the ATmega2560's D22: volume-controlled
//! breaths (`VENT` over the console) close it for each inspiration, after a lead-in of one
//! expiration, and a fault opens it
//! within two ticks of the `FAULT` line, with the pump off, for good.
//!
//! Truths: the level PB0 drives (GPIOB's MODER and ODR at every plant step, the bench's
//! `valve_log`), the breath timing the `VENT` line sets (rate 20 /min, Ti 1 s), the fault the
//! bench injects, the duty on PA6 and the simulated lung (closed, it keeps every millilitre the
//! blower delivers).

mod common;

use common::{assert_stopped, row1_in_run_mode, run_to, start_vent_row1, transcript, TICK};
use pump_sim::iso::iso_row;
use pump_sim::Valve;
use stm32_harness::bench::{ps, secs, Action, Bench};
use stm32_harness::sensor::Fault;

/// The times PB0 closed the valve (ps) and how long each closure lasted (ps; the last one up
/// to now if still closed).
fn closures(b: &Bench) -> Vec<(u64, u64)> {
    let log = &b.valve_log;
    log.iter()
        .enumerate()
        .filter(|(_, (_, v))| *v == Valve::Closed)
        .map(|(i, &(t, _))| {
            let end = log.get(i + 1).map_or(b.machine.now(), |&(e, _)| e);
            (t, end - t)
        })
        .collect()
}

#[test]
fn valve_closes_in_inspiration_and_opens_on_a_sensor_fault() {
    let mut b = row1_in_run_mode();
    assert_eq!(b.valve_now(), Valve::Open, "open until ventilation starts");
    assert!(b.valve_log.is_empty(), "closed before VENT");

    let r = iso_row(1).expect("row 1");
    let ok = start_vent_row1(&mut b);
    let ok_at = b.lines[ok].start;
    // Three breaths of 3 s; stop 0.3 s into the fourth inspiration.
    let t0 = b.time_s();
    while closures(&b).len() < 4 && b.time_s() < t0 + 12.0 {
        b.run_for(0.01).expect("run");
    }
    b.run_for(0.3).expect("run");
    let c = closures(&b);
    assert_eq!(c.len(), 4, "{:?}\n{}", c, transcript(&b));
    // The lead-in: one expiration (3 s − 1 s = 2 s) with the valve open before breath 1, from
    // the tick that answered the command (its line starts within that tick), a tick either way.
    assert!(
        (c[0].0 - ok_at).abs_diff(ps(2.0)) <= 2 * TICK,
        "first closing {} s after OK vent",
        secs(c[0].0 - ok_at)
    );
    for (i, &(at, len)) in c.iter().take(3).enumerate() {
        // Inspiration 1 s, one tick either way; breaths 3 s apart, one tick either way.
        assert!(
            len.abs_diff(ps(1.0)) <= TICK,
            "breath {}: closed {} s",
            i + 1,
            secs(len)
        );
        if let Some(&(next, _)) = c.get(i + 1) {
            assert!(
                (next - at).abs_diff(ps(3.0)) <= TICK,
                "breath {}: period {} s",
                i + 1,
                secs(next - at)
            );
        }
    }
    assert_eq!(b.valve_now(), Valve::Closed, "0.3 s into an inspiration");
    // Closed: the lung holds what the blower delivered (above the relaxed lung's PEEP volume).
    let lung = b.lung.as_ref().expect("lung");
    assert!(
        lung.pressure() > r.peep + 2.0,
        "lung at {} cmH2O 0.3 s into a closed inspiration",
        lung.pressure()
    );

    b.apply(Action::Sensor(Fault::Absent)).expect("fault");
    let i = run_to(&mut b, 0.5, "FAULT sensor=nack")
        .unwrap_or_else(|| panic!("no FAULT:\n{}", transcript(&b)));
    b.run_for(3.0).expect("run");
    let line = b.lines[i].start;
    let &(opened, v) = b.valve_log.last().expect("valve log");
    assert_eq!(v, Valve::Open, "closed again after the fault");
    assert!(
        opened <= line + 2 * TICK,
        "valve opened {} s after the FAULT line",
        secs(opened) - secs(line)
    );
    assert_eq!(b.valve_now(), Valve::Open);
    assert_stopped(&b, i, "sensor fault while ventilating");
}
