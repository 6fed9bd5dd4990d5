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

use ridge_pump_firmware::resets::{Resets, CLEAN_TICKS};
use stm32_harness::bench::{ps, Action, Bench, BenchConfig};
use stm32_harness::firmware;
use stm32_harness::lines::Line;
use stm32_harness::periph::rcc::ResetCause;

fn elf() -> std::path::PathBuf {
    firmware::ensure_elf().expect("STM32F411 image")
}

fn texts(lines: &[Line]) -> Vec<&str> {
    lines.iter().map(|l| l.text.as_str()).collect()
}

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

/// Runs for at most `within_s` more, until a line starting with `prefix`.
fn run_to(b: &mut Bench, within_s: f64, prefix: &str) {
    let until = b.time_s() + within_s;
    b.run_until(until, |l| l.text.starts_with(prefix))
        .expect("run");
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
    // Into the search: the excitation record (30 s) completes, then the search runs over a
    // few ticks. Step 1 ms at a time until `App::search` is on the call stack.
    run_to(&mut b, 10.0, "EXCITE");
    let excite = b.lines.last().expect("EXCITE").start;
    b.run_until(stm32_harness::bench::secs(excite) + 29.99, |_| false)
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
