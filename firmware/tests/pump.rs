//! Pump driver against the fake PWM channel (`firmware-testkit`) that logs every write, and
//! against the `embedded-hal-mock` PWM mock. Expected counts are worked out by hand in the
//! comments.

use embedded_hal_mock::eh1::pwm::{Mock, Transaction};
use embedded_hal_mock::eh1::MockError;
use firmware_testkit::{FakePwm, PwmBroken};
use ridge_pump_firmware::pump::{duty_to_counts, Error, Pump, NO_RAMP_LIMIT};
use ridge_pump_firmware::units::DUTY_FULL_SCALE;

/// A pump whose channel has max duty 10 000, so counts equal duty units.
fn unit_pump() -> (Pump<FakePwm<()>>, FakePwm<()>) {
    let pwm = FakePwm::alone(DUTY_FULL_SCALE);
    let pump = Pump::new(pwm.clone()).unwrap();
    (pump, pwm)
}

#[test]
fn full_scale_is_10000() {
    assert_eq!(DUTY_FULL_SCALE, 10_000);
}

#[test]
fn mapping_rounds_to_nearest() {
    // 5000/10000 · 799 = 399.5 → 400.
    assert_eq!(duty_to_counts(5_000, 799), 400);
    // 2500/10000 · 799 = 199.75 → 200.
    assert_eq!(duty_to_counts(2_500, 799), 200);
    // 1234/10000 · 799 = 98.5966 → 99.
    assert_eq!(duty_to_counts(1_234, 799), 99);
    // 1/10000 · 255 = 0.0255 → 0; 2/10000 · 2500 = 0.5 → 1 (half up).
    assert_eq!(duty_to_counts(1, 255), 0);
    assert_eq!(duty_to_counts(2, 2_500), 1);
    assert_eq!(duty_to_counts(0, 799), 0);
    assert_eq!(duty_to_counts(10_000, 799), 799);
}

#[test]
fn mapping_does_not_overflow_at_max_duty_65535() {
    assert_eq!(duty_to_counts(10_000, u16::MAX), 65_535);
    // 9999/10000 · 65535 = 65528.4465 → 65528.
    assert_eq!(duty_to_counts(9_999, u16::MAX), 65_528);
    // 5000/10000 · 65535 = 32767.5 → 32768.
    assert_eq!(duty_to_counts(5_000, u16::MAX), 32_768);
    // Above full scale counts as full scale.
    assert_eq!(duty_to_counts(u16::MAX, u16::MAX), 65_535);
    assert_eq!(duty_to_counts(10_000, 0), 0);
}

#[test]
fn mapping_is_monotonic_and_bounded_for_any_max() {
    for max in [
        0u16, 1, 2, 3, 255, 799, 1_000, 9_999, 10_000, 10_001, 40_000, 65_535,
    ] {
        let mut previous = 0;
        for duty in 0..=DUTY_FULL_SCALE {
            let counts = duty_to_counts(duty, max);
            assert!(counts <= max);
            assert!(counts >= previous);
            // Within half a count of the exact value: |counts · 10000 − duty · max| ≤ 5000.
            let error = (i64::from(counts) * 10_000 - i64::from(duty) * i64::from(max)).abs();
            assert!(error <= 5_000, "duty {duty} max {max} counts {counts}");
            previous = counts;
        }
    }
}

#[test]
fn new_writes_zero() {
    let pwm = FakePwm::alone(799);
    let pump = Pump::new(pwm.clone()).unwrap();
    assert_eq!(pwm.writes(), vec![0]);
    assert_eq!(pump.applied(), 0);
    assert_eq!(pump.commanded(), 0);
    assert_eq!(pump.min_duty(), 0);
    assert_eq!(pump.max_duty(), DUTY_FULL_SCALE);
    assert_eq!(pump.ramp_limit(), NO_RAMP_LIMIT);
}

#[test]
fn set_maps_to_channel_counts() {
    let pwm = FakePwm::alone(799);
    let mut pump = Pump::new(pwm.clone()).unwrap();
    assert_eq!(pump.set(5_000), Ok(5_000));
    assert_eq!(pump.set(10_000), Ok(10_000));
    assert_eq!(pump.set(0), Ok(0));
    // 5000 → 399.5 → 400; 10000 → 799.
    assert_eq!(pwm.writes(), vec![0, 400, 799, 0]);
}

#[test]
fn clamping_to_limits_keeps_zero() {
    let (mut pump, pwm) = unit_pump();
    pump.set_limits(2_000, 8_000);
    assert_eq!(pump.set(9_000), Ok(8_000));
    assert_eq!(pump.commanded(), 8_000);
    assert_eq!(pump.set(500), Ok(2_000));
    assert_eq!(pump.commanded(), 2_000);
    assert_eq!(pump.set(0), Ok(0));
    assert_eq!(pump.commanded(), 0);
    assert_eq!(pump.set(u16::MAX), Ok(8_000));
    assert_eq!(pwm.writes(), vec![0, 8_000, 2_000, 0, 8_000]);
}

#[test]
fn limits_are_made_consistent() {
    let (mut pump, _pwm) = unit_pump();
    pump.set_limits(3_000, 20_000);
    assert_eq!((pump.min_duty(), pump.max_duty()), (3_000, 10_000));
    pump.set_limits(7_000, 5_000);
    assert_eq!((pump.min_duty(), pump.max_duty()), (5_000, 5_000));
    assert_eq!(pump.set(1), Ok(5_000));
    pump.set_limits(0, 0);
    assert_eq!(pump.commanded(), 0);
    assert_eq!(pump.set(4_000), Ok(0));
}

#[test]
fn lowering_max_reclamps_command_and_applies_without_ramp() {
    let (mut pump, pwm) = unit_pump();
    assert_eq!(pump.set(9_000), Ok(9_000));
    pump.set_ramp_limit(100);
    pump.set_limits(0, 6_000);
    assert_eq!(pump.commanded(), 6_000);
    assert_eq!(pump.applied(), 9_000); // nothing written yet
    assert_eq!(pump.tick(), Ok(6_000));
    assert_eq!(pwm.writes(), vec![0, 9_000, 6_000]);
}

#[test]
fn ramp_limits_each_step() {
    let (mut pump, pwm) = unit_pump();
    pump.set_ramp_limit(300);
    assert_eq!(pump.set(1_000), Ok(300));
    assert_eq!(pump.tick(), Ok(600));
    assert_eq!(pump.tick(), Ok(900));
    assert_eq!(pump.tick(), Ok(1_000));
    assert_eq!(pump.tick(), Ok(1_000));
    // Down again, and a new command mid-ramp.
    assert_eq!(pump.set(0), Ok(700));
    assert_eq!(pump.set(800), Ok(800));
    assert_eq!(pump.set(0), Ok(500));
    assert_eq!(pump.tick(), Ok(200));
    assert_eq!(pump.tick(), Ok(0));
    assert_eq!(pump.commanded(), 0);
    assert_eq!(
        pwm.writes(),
        vec![0, 300, 600, 900, 1_000, 1_000, 700, 800, 500, 200, 0]
    );
}

#[test]
fn ramp_jumps_over_the_band_below_min() {
    let (mut pump, pwm) = unit_pump();
    pump.set_limits(2_000, 10_000);
    pump.set_ramp_limit(500);
    // Start: 0 → min at once, then ramp.
    assert_eq!(pump.set(3_200), Ok(2_000));
    assert_eq!(pump.tick(), Ok(2_500));
    assert_eq!(pump.tick(), Ok(3_000));
    assert_eq!(pump.tick(), Ok(3_200));
    // Stop by command: ramp down to the last step at or above min, then 0.
    assert_eq!(pump.set(0), Ok(2_700));
    assert_eq!(pump.tick(), Ok(2_200));
    assert_eq!(pump.tick(), Ok(0));
    assert_eq!(
        pwm.writes(),
        vec![0, 2_000, 2_500, 3_000, 3_200, 2_700, 2_200, 0]
    );
}

#[test]
fn ramp_limit_zero_is_raised_to_one() {
    let (mut pump, _pwm) = unit_pump();
    pump.set_ramp_limit(0);
    assert_eq!(pump.ramp_limit(), 1);
    assert_eq!(pump.set(10), Ok(1));
    assert_eq!(pump.tick(), Ok(2));
}

#[test]
fn stop_bypasses_the_ramp() {
    let (mut pump, pwm) = unit_pump();
    pump.set_ramp_limit(1_000);
    for _ in 0..8 {
        pump.set(8_000).unwrap();
    }
    assert_eq!(pump.applied(), 8_000);
    pump.stop().unwrap();
    assert_eq!(pump.applied(), 0);
    assert_eq!(pump.commanded(), 0);
    assert_eq!(pump.tick(), Ok(0));
    let writes = pwm.writes();
    assert_eq!(&writes[writes.len() - 3..], &[8_000, 0, 0]);
}

#[test]
fn pwm_error_propagates_and_keeps_applied() {
    let (mut pump, pwm) = unit_pump();
    pump.set_ramp_limit(1_000);
    assert_eq!(pump.set(1_500), Ok(1_000));
    pwm.set_broken(true);
    assert_eq!(pump.tick(), Err(Error::Pwm(PwmBroken)));
    assert_eq!(pump.applied(), 1_000);
    assert_eq!(pump.commanded(), 1_500);
    assert_eq!(pump.stop(), Err(Error::Pwm(PwmBroken)));
    assert_eq!(pump.applied(), 1_000);
    assert_eq!(pump.commanded(), 0);
    pwm.set_broken(false);
    // The next tick writes again, ramping down towards the 0 command.
    assert_eq!(pump.tick(), Ok(0));
    assert_eq!(pwm.writes(), vec![0, 1_000, 0]);
}

#[test]
fn new_fails_if_pwm_fails() {
    let pwm = FakePwm::alone(799);
    pwm.set_broken(true);
    assert!(matches!(Pump::new(pwm), Err(Error::Pwm(PwmBroken))));
}

#[test]
fn works_with_embedded_hal_mock() {
    let expectations = [
        Transaction::max_duty_cycle(799),
        Transaction::set_duty_cycle(0),
        Transaction::max_duty_cycle(799),
        Transaction::set_duty_cycle(400),
        Transaction::max_duty_cycle(799),
        Transaction::set_duty_cycle(0).with_error(MockError::Io(std::io::ErrorKind::NotConnected)),
    ];
    let mut pump = Pump::new(Mock::new(&expectations)).unwrap();
    assert_eq!(pump.set(5_000), Ok(5_000));
    assert_eq!(
        pump.stop(),
        Err(Error::Pwm(MockError::Io(std::io::ErrorKind::NotConnected)))
    );
    pump.release().done();
}
