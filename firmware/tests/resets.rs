//! The reset-loop count (firmware/src/resets.rs) against the MCUSR bits of the ATmega2560
//! datasheet (section 12.5.1: PORF bit 0, EXTRF 1, BORF 2, WDRF 3, JTRF 4), and the
//! STM32F411's reset flags (RM0383 §6.3.18, RCC_CSR bits 31..24) translated into them.

use ridge_pump_firmware::resets::{cause_from_rcc_csr, Resets, LIMIT};

const PORF: u8 = 0x01;
const EXTRF: u8 = 0x02;
const BORF: u8 = 0x04;
const WDRF: u8 = 0x08;
const JTRF: u8 = 0x10;

#[test]
fn an_erased_byte_is_no_resets_and_every_count_round_trips() {
    assert_eq!(Resets::from_byte(0xFF), Resets::default());
    for watchdog in 0..16 {
        for brownout in 0..16 {
            let r = Resets { watchdog, brownout };
            assert_eq!(Resets::from_byte(r.to_byte()), r);
        }
    }
}

#[test]
fn watchdog_and_brownout_resets_count_power_on_and_the_reset_pin_clear() {
    let none = Resets::default();
    let w = none.after_boot(WDRF);
    assert_eq!(
        w,
        Resets {
            watchdog: 1,
            brownout: 0
        }
    );
    let wb = w.after_boot(BORF);
    assert_eq!(
        wb,
        Resets {
            watchdog: 1,
            brownout: 1
        }
    );
    // Both flags at once count both.
    assert_eq!(
        none.after_boot(WDRF | BORF),
        Resets {
            watchdog: 1,
            brownout: 1
        }
    );
    // A power-on or the reset pin clears, whatever else is set.
    for cause in [PORF, EXTRF, PORF | BORF, EXTRF | WDRF] {
        assert_eq!(wb.after_boot(cause), none, "{cause:#x}");
    }
    // JTAG reset, or MCUSR already cleared by a bootloader: unchanged.
    for cause in [0, JTRF] {
        assert_eq!(wb.after_boot(cause), wb, "{cause:#x}");
    }
}

#[test]
fn the_third_abnormal_reset_is_a_loop_and_counts_saturate() {
    let mut r = Resets::default();
    let mut boots = 0;
    while !r.is_loop() {
        r = r.after_boot(if boots % 2 == 0 { WDRF } else { BORF });
        boots += 1;
    }
    assert_eq!(boots, usize::from(LIMIT));
    assert_eq!(LIMIT, 3);
    for _ in 0..40 {
        r = r.after_boot(WDRF);
    }
    assert_eq!(r.watchdog, 15);
    assert!(Resets::from_byte(r.to_byte()).is_loop());
}

/// RCC_CSR >> 24 (RM0383 §6.3.18): BORRSTF bit 1, PINRSTF 2, PORRSTF 3, SFTRSTF 4, IWDGRSTF 5,
/// WWDGRSTF 6, LPWRRSTF 7; the register's reset value after a power-on is 0x0E (POR, PIN, BOR).
#[test]
fn stm32_reset_flags_count_like_their_atmega2560_counterparts() {
    const BOR: u8 = 1 << 1;
    const PIN: u8 = 1 << 2;
    const POR: u8 = 1 << 3;
    const SFT: u8 = 1 << 4;
    const IWDG: u8 = 1 << 5;
    const WWDG: u8 = 1 << 6;
    const LPWR: u8 = 1 << 7;
    let one = Resets {
        watchdog: 1,
        brownout: 1,
    };
    let after = |flags: u8| one.after_boot(cause_from_rcc_csr(flags));
    // Power-on (the documented reset value), the reset button, a debugger's software reset:
    // cleared.
    for flags in [POR | PIN | BOR, POR, PIN, SFT | PIN, POR | IWDG | PIN] {
        assert_eq!(after(flags), Resets::default(), "{flags:#04x}");
    }
    // Watchdogs (an internal reset pulls NRST: PINRSTF comes with it).
    for flags in [IWDG | PIN, WWDG | PIN, IWDG] {
        assert_eq!(
            after(flags),
            Resets {
                watchdog: 2,
                brownout: 1
            },
            "{flags:#04x}"
        );
    }
    // A brown-out without a power-on (BOR enabled in the option bytes).
    for flags in [BOR, BOR | PIN] {
        assert_eq!(
            after(flags),
            Resets {
                watchdog: 1,
                brownout: 2
            },
            "{flags:#04x}"
        );
    }
    assert_eq!(
        after(IWDG | BOR | PIN),
        Resets {
            watchdog: 2,
            brownout: 2
        }
    );
    // Low-power reset, or flags already cleared: unchanged.
    for flags in [0, LPWR, LPWR | PIN] {
        assert_eq!(after(flags), one, "{flags:#04x}");
    }
}
