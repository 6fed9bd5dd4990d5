//! What the STM32F411 image does that the ATmega2560's does too (issue 30, item 4), on the
//! release image in the emulated chip: the reset-loop count kept across resets in a backup
//! register, I2C bus recovery when the sensor holds SDA low, and a record store that a power
//! cut at any program access (or during a sector erase) leaves loadable.
//!
//! Truths: the reset flags RM0383 §6.3.18 defines (the harness sets them as the chip would),
//! the backup register's content read from the model, the duty on the pump's pin, the bus
//! lines as the harness's pin-level model saw them, the flash contents.
//!
//! The ATmega2560's counterparts are `watchdog_resets_restart_safely_and_a_reset_loop_keeps_
//! the_pump_off`, `a_clean_minute_clears_the_reset_count`, `sda_held_low_*` and
//! `a_save_cut_at_any_point_keeps_the_other_slot` in `simavr-harness/tests/simavr.rs`.

mod common;

use common::{assert_stopped, elf, run_to, texts, transcript, TICK};
use ridge_pump_firmware::resets::{Resets, CLEAN_TICKS};
use ridge_pump_firmware::selfid::{Config, DEFAULT_CONFIG};
use stm32_harness::bench::{ps, secs, Action, Bench, BenchConfig, RunEnd};
use stm32_harness::bus::{BusEvent, Lines, SdaHold};
use stm32_harness::periph::rcc::ResetCause;
use stm32_harness::periph::Time;

/// The reset count in RTC_BKP0R as the image stores it (`ResetCount` in
/// `firmware/src/board/blackpill_f411.rs`): `"RPC"` in the top three bytes, the count byte of
/// `resets::Resets::to_byte` below; a register without the mark (0 after a power-on) is no
/// count.
fn reset_count(b: &Bench) -> Resets {
    let v = b.machine.chip().backup.bkp[0];
    if v >> 8 == 0x52_5043 {
        Resets::from_byte(v as u8)
    } else {
        assert_eq!(v, 0, "RTC_BKP0R holds {v:#010x}");
        Resets::default()
    }
}

/// Resets by `cause` now and returns the index of the first line after it.
fn reset_with(b: &mut Bench, cause: ResetCause) -> usize {
    b.apply(Action::Reset(cause)).expect("reset");
    b.lines.len()
}

/// Watchdog and brown-out resets: a watchdog reset in the middle of the structure search
/// restarts the pump safely (a new boot, the identification from the start, no fault); a
/// brown-out and another watchdog reset make three without a clean minute: the pump stays off
/// with `FAULT resets watchdog=2 brownout=1` in that boot, and the count stays in the backup
/// register; the reset button clears it and the pump identifies again.
#[test]
fn watchdog_resets_restart_safely_and_a_reset_loop_keeps_the_pump_off() {
    let mut b = Bench::new(BenchConfig::new(elf())).expect("bench");
    let search = b
        .machine
        .image()
        .symbols
        .iter()
        .find(|s| s.name.contains("App$LT$") && s.name.contains("$GT$6search17h"))
        .cloned()
        .expect("App::search in the ELF's symbols");
    // Into the search: the estimation record (`records.samples` ticks) completes, then the
    // search runs over a few ticks. Step 1 ms at a time until `App::search` is on the call
    // stack.
    run_to(&mut b, 10.0, "EXCITE");
    let excite = b.lines.last().expect("EXCITE").start;
    let record_s = f64::from(DEFAULT_CONFIG.records.samples) * 0.01;
    b.run_until(stm32_harness::bench::secs(excite) + record_s - 0.01, |_| {
        false
    })
    .expect("run");
    let mut in_search = false;
    for _ in 0..100 {
        b.run_for(0.001).expect("run");
        if b.machine.on_call_stack(&search) {
            in_search = true;
            break;
        }
    }
    assert!(in_search, "no search within 100 ms of the record's end");
    assert!(
        !b.lines.iter().any(|l| l.text.starts_with("ID ")),
        "the search had already ended"
    );
    assert_eq!(reset_count(&b), Resets::default(), "a power-on: no resets");

    // First watchdog reset, mid-search: a clean restart.
    let from = reset_with(&mut b, ResetCause::Watchdog);
    run_to(&mut b, 12.0, "EXCITE");
    let after = texts(&b.lines[from..]);
    assert_eq!(
        after.first().copied(),
        Some("BOOT board=stm32f411 reset=36 record=none"),
        "RCC_CSR: IWDGRSTF 0x20 with PINRSTF 0x04: {after:?}"
    );
    assert!(after.iter().any(|l| l.starts_with("EXCITE")), "{after:?}");
    assert!(!after.iter().any(|l| l.starts_with("FAULT")), "{after:?}");
    assert_eq!(
        reset_count(&b),
        Resets {
            watchdog: 1,
            brownout: 0
        }
    );

    // A brown-out a second later (BORRSTF with PINRSTF, no PORRSTF), then a watchdog reset a
    // second after that boot: the third abnormal reset is a loop.
    let from = reset_with(&mut b, ResetCause::BrownOut);
    b.run_for(1.0).expect("run");
    assert_eq!(
        b.lines.get(from).map(|l| l.text.as_str()),
        Some("BOOT board=stm32f411 reset=6 record=none")
    );
    assert_eq!(
        reset_count(&b),
        Resets {
            watchdog: 1,
            brownout: 1
        }
    );
    let third_at = b.machine.now();
    let from = reset_with(&mut b, ResetCause::Watchdog);
    b.run_for(5.0).expect("run");
    let after = texts(&b.lines[from..]);
    assert_eq!(
        after.get(..2),
        Some(
            &[
                "BOOT board=stm32f411 reset=36 record=none",
                "FAULT resets watchdog=2 brownout=1"
            ][..]
        ),
        "{after:?}"
    );
    assert!(!after.iter().any(|l| l.starts_with("EXCITE")), "{after:?}");
    let driven: Vec<f64> = b
        .duty_log
        .iter()
        .filter(|d| d.at > third_at)
        .map(|d| d.fraction)
        .collect();
    assert!(
        driven.iter().all(|&f| f == 0.0),
        "pump driven in a reset loop: {driven:?}"
    );
    assert_eq!(b.duty_now().fraction, 0.0);
    assert_eq!(
        reset_count(&b),
        Resets {
            watchdog: 2,
            brownout: 1
        }
    );

    // The reset button (PINRSTF alone) clears the count: the pump identifies again.
    let from = reset_with(&mut b, ResetCause::Pin);
    run_to(&mut b, 12.0, "EXCITE");
    let after = texts(&b.lines[from..]);
    assert_eq!(
        after.first().copied(),
        Some("BOOT board=stm32f411 reset=4 record=none")
    );
    assert!(after.iter().any(|l| l.starts_with("EXCITE")), "{after:?}");
    assert!(!after.iter().any(|l| l.starts_with("FAULT")), "{after:?}");
    assert_eq!(reset_count(&b), Resets::default());
    assert_eq!(
        b.machine.chip().backup.dropped,
        0,
        "a write to PWR or a backup register was dropped (clock or DBP off)"
    );
}

/// Two watchdog resets already counted are cleared by a power cycle (the backup domain loses
/// its supply); a watchdog reset then counts one, still counted just before a clean minute
/// ends and cleared after it, so that resets far apart never add up to a loop.
#[test]
fn a_clean_minute_clears_the_reset_count() {
    let mut b = Bench::new(BenchConfig::new(elf())).expect("bench");
    b.run_for(0.5).expect("run");
    reset_with(&mut b, ResetCause::Watchdog);
    b.run_for(0.5).expect("run");
    reset_with(&mut b, ResetCause::Watchdog);
    b.run_for(0.5).expect("run");
    assert_eq!(
        reset_count(&b),
        Resets {
            watchdog: 2,
            brownout: 0
        }
    );
    reset_with(&mut b, ResetCause::PowerOn);
    b.run_for(0.5).expect("run");
    assert_eq!(reset_count(&b), Resets::default());
    let boot = b.find("BOOT").last().expect("BOOT");
    assert_eq!(boot.text, "BOOT board=stm32f411 reset=14 record=none");

    reset_with(&mut b, ResetCause::Watchdog);
    let clean_s = f64::from(CLEAN_TICKS) * 0.01;
    b.run_for(clean_s - 1.0).expect("run");
    assert_eq!(
        reset_count(&b),
        Resets {
            watchdog: 1,
            brownout: 0
        }
    );
    // Ticks lost in the search's and the design's passes do not count: a margin.
    b.run_for(3.0).expect("run");
    assert_eq!(reset_count(&b), Resets::default());
    assert!(
        !b.lines.iter().any(|l| l.text.starts_with("FAULT")),
        "{:?}",
        texts(&b.lines)
    );
    assert!(b.machine.now() > ps(clean_s));
}

/// Fault injection starts at 5 s: the firmware is in the scan (after the 1.5 s settle), as in
/// the ATmega2560's tests.
const AT: f64 = 5.0;
/// Standard-mode I2C clock phases (NXP UM10204, Table 10): SCL low ≥ 4.7 µs ...
const I2C_LOW_MIN: Time = 4_700_000;
/// ... and SCL high ≥ 4.0 µs.
const I2C_HIGH_MIN: Time = 4_000_000;
/// SDA stuck low for good: the pump is off and the FAULT line has started within this long
/// after SDA went low (docs/boards.md, Faults; the ATmega2560's bound, which includes its
/// 2.5 ms timeout: here five 10 ms ticks and the tick's work).
const SDA_STUCK_BOUND_S: f64 = 0.055;
/// GPIOB_IDR (RM0383 §8.4.5; GPIOB at 0x4002_0400).
const GPIOB_IDR: u32 = 0x4002_0410;

/// Every SCL phase in `from..to` is as long as standard-mode I2C asks (a high phase longer
/// than 1 ms is the idle bus between two recoveries, not a phase).
fn check_clock(bus: &Lines, from: Time, to: Time, what: &str) {
    for (t0, high, len) in bus.scl_phases(from, to) {
        if high {
            assert!(
                len >= I2C_HIGH_MIN || len > ps(1e-3),
                "{what}: SCL high for {len} ps at {} s",
                secs(t0)
            );
        } else {
            assert!(
                len >= I2C_LOW_MIN,
                "{what}: SCL low for {len} ps at {} s",
                secs(t0)
            );
        }
    }
}

/// I2C bus stuck low, a sensor that lets go: after its next frame it keeps SDA low until it
/// has seen `k` clocks, as a slave stuck in a byte does. For k = 1, 5 and 9 (the most such a
/// slave needs) in one run in the excitation, on the harness's own view of the pins and of the
/// slave: exactly k clock pulses, each phase as long as standard-mode I2C asks, a STOP
/// condition on the pins after the release, no START request reaching I2C1 while the bus was
/// held (the firmware's guard sees the held bus first: the ATmega2560's TWI times out one
/// START instead), the frame read in the same pass after the STOP and then at every tick, no
/// FAULT, the pump running throughout.
#[test]
fn sda_held_low_by_the_sensor_is_clocked_free() {
    let mut b = Bench::new(BenchConfig::new(elf())).expect("bench");
    b.run_until(AT, |_| false).expect("run");
    for k in [1u8, 5, 9] {
        let armed = b.machine.now();
        b.apply(Action::HoldSda(SdaHold::ReleaseAfter(k)))
            .expect("hold");
        b.run_for(0.3).expect("run");
        let end = b.machine.now();
        let bus = b.bus.borrow();
        let what = format!("released after {k} clocks");
        let within = |t: &Time| (armed..end).contains(t);
        let holds = bus.times(|e| matches!(e, BusEvent::Hold(t) if within(t)));
        let releases = bus.times(|e| matches!(e, BusEvent::Release(t) if within(t)));
        assert!(
            holds.len() == 1 && releases.len() == 1,
            "{what}: holds {holds:?}, releases {releases:?}"
        );
        let (hold, release) = (holds[0], releases[0]);
        let pulses = bus.scl_pulses(hold, end);
        assert_eq!(pulses, usize::from(k), "{what}: clock pulses");
        check_clock(&bus, hold, end, &what);
        let blocked = bus.times(|e| matches!(e, BusEvent::BlockedStart(t) if within(t)));
        assert!(blocked.is_empty(), "{what}: START requests on the held bus");
        let stops = bus.times(|e| matches!(e, BusEvent::Stop(t) if within(t)));
        assert!(
            stops.len() == 1 && stops[0] > release,
            "{what}: STOP conditions on the pins {stops:?}, release at {release}"
        );
        let stop = stops[0];
        // The recovery starts at the next tick's read, within one tick of the hold.
        let first_edge = bus.times(|e| matches!(e, BusEvent::Scl(t, false) if *t > hold))[0];
        assert!(
            first_edge - hold < TICK,
            "{what}: first recovery clock {} ms after the hold",
            (first_edge - hold) as f64 / 1e9
        );
        let served: Vec<Time> = b
            .sensor
            .borrow()
            .served()
            .iter()
            .map(|&(t, _)| t)
            .filter(|t| (hold..end).contains(t))
            .collect();
        assert!(
            served
                .first()
                .is_some_and(|&t| t > stop && t < stop + ps(1e-3)),
            "{what}: first frame after the hold at {:?} s, STOP at {} s",
            served.first().map(|&t| secs(t)),
            secs(stop)
        );
        let scl: Vec<f64> = bus
            .times(|e| matches!(e, BusEvent::Scl(t, _) if (hold..end).contains(t)))
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 / 1e6)
            .collect();
        println!(
            "{what}: recovery {:.3} ms after the hold, SCL phases {scl:.2?} µs, STOP {:.1} µs \
             after the release, frame {:.1} µs after the STOP",
            (first_edge - hold) as f64 / 1e9,
            (stop - release) as f64 / 1e6,
            (served[0] - stop) as f64 / 1e6
        );
        let ticks = (end - stop) / TICK;
        assert!(
            served.len() as u64 >= ticks,
            "{what}: {} frames served in the {ticks} ticks after the STOP",
            served.len()
        );
    }
    assert!(
        !b.lines.iter().any(|l| l.text.starts_with("FAULT")),
        "a fault:\n{}",
        transcript(&b)
    );
    let since = ps(AT);
    assert!(
        b.duty_at(since).is_some_and(|d| d.fraction > 0.0)
            && b.duty_log
                .iter()
                .filter(|d| d.at >= since)
                .all(|d| d.fraction > 0.0),
        "the pump stopped: {:?}",
        b.duty_log
    );
}

/// I2C bus stuck low for good: the sensor never lets go of SDA. Every read finds the bus
/// held, clocks 9 pulses that free nothing (no STOP condition can happen) and fails; the fifth
/// failed read in a row is the fault, `FAULT sensor=bus n=5`, with the pump off (duty 0 on the
/// pin) and the line started within [`SDA_STUCK_BOUND_S`] of SDA going low, and the pump kept
/// off.
#[test]
fn sda_held_low_for_good_stops_the_pump_within_its_bound() {
    let mut b = Bench::new(BenchConfig::new(elf())).expect("bench");
    b.schedule(AT, Action::HoldSda(SdaHold::Forever));
    let end = b
        .run_until(AT + 1.0, |l| l.text.starts_with("FAULT"))
        .expect("run");
    let RunEnd::Line(idx) = end else {
        panic!("no FAULT line within 1 s:\n{}", transcript(&b));
    };
    b.run_for(0.03).expect("run");
    assert_eq!(b.lines[idx].text, "FAULT sensor=bus n=5");
    assert_stopped(&b, idx, "SDA held low");
    let bus = b.bus.borrow();
    let hold = bus.times(|e| matches!(e, BusEvent::Hold(_)));
    assert_eq!(hold.len(), 1, "holds");
    let hold = hold[0];
    let line = b.lines[idx].start;
    let off = b
        .duty_log
        .iter()
        .find(|d| d.at > hold && d.fraction == 0.0)
        .map_or(Time::MAX, |d| d.at);
    let bound = ps(SDA_STUCK_BOUND_S);
    println!(
        "SDA held for good: pump off {:.2} ms, FAULT line {:.2} ms after SDA went low",
        (off - hold) as f64 / 1e9,
        (line - hold) as f64 / 1e9
    );
    assert!(
        off - hold <= bound && line - hold <= bound,
        "pump off {} ms and FAULT line {} ms after SDA went low (bound {} ms)",
        (off - hold) as f64 / 1e9,
        (line - hold) as f64 / 1e9,
        SDA_STUCK_BOUND_S * 1e3
    );
    // One recovery per tick (its clocks within 0.2 ms), each the full 9 clocks; the fifth
    // failed read in a row faults.
    let falls = bus.times(|e| matches!(e, BusEvent::Scl(t, false) if *t > hold && *t < line));
    let mut bursts: Vec<Vec<Time>> = Vec::new();
    for t in falls {
        match bursts.last_mut() {
            Some(burst) if t - burst[0] < ps(2e-4) => burst.push(t),
            _ => bursts.push(vec![t]),
        }
    }
    assert_eq!(
        bursts.len(),
        usize::from(Config::default().sensor_fault_limit),
        "recoveries before the FAULT line: {bursts:?}"
    );
    for (i, burst) in bursts.iter().enumerate() {
        assert_eq!(burst.len(), 9, "clock pulses of recovery {i}");
    }
    check_clock(&bus, hold, line, "SDA held for good");
    let after = |t: &Time| *t > hold;
    assert!(
        bus.times(|e| matches!(e, BusEvent::Release(t) | BusEvent::Stop(t) if after(t)))
            .is_empty(),
        "SDA rose while held: {:?}",
        bus.events
    );
    assert!(
        bus.times(|e| matches!(e, BusEvent::BlockedStart(_)))
            .is_empty(),
        "a START requested on the held bus"
    );
    // The pins: GPIOB_IDR reads SDA (PB7) low and SCL (PB6) high.
    let now = b.machine.now();
    let idr = b.machine.chip_mut().read(GPIOB_IDR, 4, now);
    assert_eq!((idr >> 6) & 3, 0b01, "GPIOB_IDR {idr:#06x}");
}
