//! The tick's fault checks (`selfid::Guard`) on their own: the frozen-sensor and the no-flow
//! checks, fed readings whose verdict follows from the documented thresholds.

use ridge_pump_firmware::event::{FaultReason, SensorFault};
use ridge_pump_firmware::selfid::{Config, Guard};

fn cfg() -> Config {
    Config::default()
}

/// Feeds `n` ticks of `(duty, reading)`; the first fault and the tick (1-based) it came at.
fn feed(g: &mut Guard, n: usize, duty: u16, reading: i16) -> Option<(usize, FaultReason)> {
    for k in 1..=n {
        if let Err(r) = g.check(duty, Ok(reading)) {
            return Some((k, r));
        }
    }
    None
}

#[test]
fn fifty_identical_readings_at_a_plausible_flow_are_a_frozen_sensor() {
    let c = cfg();
    assert_eq!((c.frozen_ticks, c.frozen_flow), (50, 240));
    for reading in [240i16, -240, 2_400, 30_000] {
        let mut g = Guard::new(&c);
        // Below the stall duty, nothing expected: only the frozen check can fire.
        assert_eq!(
            feed(&mut g, 100, 3_000, reading),
            Some((50, FaultReason::Frozen { counts: reading })),
            "{reading}"
        );
    }
}

#[test]
fn repeats_below_two_slm_and_a_one_count_noise_are_not_frozen() {
    let mut g = Guard::new(&cfg());
    assert_eq!(feed(&mut g, 10_000, 0, 0), None, "stopped pump, zero point");
    assert_eq!(feed(&mut g, 10_000, 3_000, 239), None, "just below 2 slm");
    assert_eq!(feed(&mut g, 10_000, 3_000, -239), None);
    for k in 0..10_000 {
        let reading = 2_400 + (k % 2) as i16;
        assert_eq!(g.check(3_000, Ok(reading)), Ok(Some(reading)));
    }
    // 49 identical, one different, 49 identical: never 50 in a row.
    for _ in 0..20 {
        assert_eq!(feed(&mut g, 48, 3_000, 1_000), None);
        assert_eq!(feed(&mut g, 1, 3_000, 1_001), None);
    }
}

#[test]
fn a_sensor_error_between_frozen_readings_neither_counts_nor_resets() {
    let mut g = Guard::new(&cfg());
    assert_eq!(feed(&mut g, 30, 3_000, 1_200), None);
    assert_eq!(g.check(3_000, Err(SensorFault::Crc)), Ok(None));
    assert_eq!(
        feed(&mut g, 30, 3_000, 1_200),
        Some((20, FaultReason::Frozen { counts: 1_200 }))
    );
}

#[test]
fn a_reading_stuck_at_full_scale_is_out_of_range_at_once() {
    let mut g = Guard::new(&cfg());
    assert_eq!(
        feed(&mut g, 5, 3_000, i16::MAX),
        Some((1, FaultReason::FlowRange { counts: i16::MAX }))
    );
    let mut g = Guard::new(&cfg());
    assert_eq!(
        feed(&mut g, 5, 3_000, i16::MIN),
        Some((1, FaultReason::FlowRange { counts: i16::MIN }))
    );
}

#[test]
fn zero_turns_the_new_checks_off() {
    let c = Config {
        frozen_ticks: 0,
        loss_ticks: 0,
        ..cfg()
    };
    let mut g = Guard::new(&c);
    g.expect_operating_point(3_000, 2_400);
    assert_eq!(feed(&mut g, 10_000, 3_000, 2_400), None);
    assert_eq!(feed(&mut g, 10_000, 3_000, 300), None);
}

#[test]
fn nothing_is_expected_before_an_operating_point() {
    let mut g = Guard::new(&cfg());
    assert_eq!(g.expected(3_000), None);
    // No flow at 30 %, below the 40 % stall duty: no fault without an expectation.
    let mut k = 0i16;
    for _ in 0..10_000 {
        k = (k + 7) % 5;
        assert!(g.check(3_900, Ok(k)).is_ok());
    }
    // An operating point without flow (a dead line from power-up) expects nothing either.
    g.expect_operating_point(3_000, 0);
    assert_eq!(g.expected(9_000), None);
    g.expect_operating_point(0, 2_400);
    assert_eq!(g.expected(9_000), None);
}

#[test]
fn the_operating_point_is_expected_in_proportion_above_it_and_nothing_below() {
    let mut g = Guard::new(&cfg());
    g.expect_operating_point(3_000, 2_400);
    assert_eq!(g.expected(2_999), None);
    assert_eq!(g.expected(0), None);
    // 2 400 · u / 3 000 (the slope 204.8 / 256 counts per 1/10 000 is floored to 204).
    for (u, exact) in [(3_000u16, 2_400.0f64), (4_500, 3_600.0), (9_500, 7_600.0)] {
        let e = f64::from(g.expected(u).unwrap());
        assert!(e <= exact && e > exact * 0.995, "{u}: {e} vs {exact}");
    }
    // Duties beyond full scale count as full scale.
    assert_eq!(g.expected(u16::MAX), g.expected(10_000));
}

#[test]
fn a_flow_below_a_quarter_of_the_expected_for_a_second_is_no_flow() {
    let c = cfg();
    assert_eq!(c.loss_ticks, 100);
    let mut g = Guard::new(&c);
    g.expect_operating_point(3_000, 2_400);
    // A quarter of 2 400 is 600: 600 is enough (dithered by a count so that the frozen check
    // stays out of it) ...
    for k in 0..1_000 {
        assert!(g.check(3_000, Ok(600 + (k % 2) as i16)).is_ok());
    }
    // ... 599 is not: the 100th tick below it is the fault.
    let mut k = 0i16;
    let fault = loop {
        k += 1;
        if let Err(r) = g.check(3_000, Ok(599 - k % 2)) {
            break r;
        }
    };
    assert_eq!(k, 100);
    assert_eq!(
        fault,
        FaultReason::NoFlow {
            duty: 3_000,
            counts: 599,
            expected: 2_400
        }
    );
}

#[test]
fn unchecked_ticks_hold_the_count_and_a_good_reading_resets_it() {
    let mut g = Guard::new(&cfg());
    g.expect_operating_point(3_000, 2_400);
    let bad = |g: &mut Guard, n: usize, duty: u16| {
        for k in 0..n {
            if let Err(r) = g.check(duty, Ok(300 + (k % 2) as i16)) {
                return Some((k + 1, r));
            }
        }
        None
    };
    assert_eq!(bad(&mut g, 60, 3_000), None);
    // Below the operating point's duty nothing is expected: no count, no reset.
    assert_eq!(bad(&mut g, 500, 2_000), None);
    let (k, r) = bad(&mut g, 60, 3_000).unwrap();
    assert_eq!(k, 40);
    assert!(matches!(r, FaultReason::NoFlow { duty: 3_000, .. }));
    // A good reading in between resets the count.
    let mut g = Guard::new(&cfg());
    g.expect_operating_point(3_000, 2_400);
    assert_eq!(bad(&mut g, 99, 3_000), None);
    assert_eq!(g.check(3_000, Ok(600)), Ok(Some(600)));
    assert_eq!(bad(&mut g, 99, 3_000), None);
}

#[test]
fn a_given_flow_is_expected_at_the_next_check_only() {
    // Run mode gives the model's steady state at the duty it wrote (here 10 slm, as at 25 %
    // on a 200 slm-per-unit-duty blower) before every check, whatever the duty the check sees.
    let mut g = Guard::new(&cfg());
    g.expect_operating_point(3_000, 2_400);
    g.expect_flow(1_200);
    for u in [5_000u16, 3_000, 2_500, 2_000, 0] {
        assert_eq!(g.expected(u), Some(1_200), "{u}");
    }
    // A quarter is 2.5 slm = 300 counts: 100 checked ticks below it are no flow.
    let mut k = 0;
    let r = loop {
        k += 1;
        g.expect_flow(1_200);
        if let Err(r) = g.check(2_500, Ok(280 + (k % 3) as i16)) {
            break r;
        }
    };
    assert_eq!(k, 100);
    assert!(
        matches!(
            r,
            FaultReason::NoFlow {
                duty: 2_500,
                expected: 1_200,
                ..
            }
        ),
        "{r:?}"
    );
    // Where the model expects almost nothing (a quarter below the stall flow's 2 slm), nothing
    // is checked, however long.
    let mut g = Guard::new(&cfg());
    g.expect_operating_point(3_000, 2_400);
    assert_eq!(
        (0..10_000).find(|k| {
            g.expect_flow(900);
            g.check(2_000, Ok((k % 3) as i16)).is_err()
        }),
        None
    );
    // Not given again (run mode left, e.g. stopped at duty 0): the operating point's law
    // from the next check on, which expects nothing below its duty.
    g.expect_flow(9_000);
    assert_eq!(g.check(2_000, Ok(300)), Ok(Some(300)));
    assert_eq!(g.expected(2_000), None);
    assert_eq!(g.expected(0), None);
    // 2 400 · 6 000 / 3 000 = 4 800, less the slope's rounding down to 204/256 count per step.
    assert_eq!(
        g.expected(6_000),
        Some(2_400 + (204i32 * 3_000 / 256) as i16)
    );
    // A sensor error uses up the given flow too.
    g.expect_flow(9_000);
    assert_eq!(g.check(2_000, Err(SensorFault::Nack)), Ok(None));
    assert_eq!(g.expected(2_000), None);
}

#[test]
fn resume_takes_over_the_counters_of_the_watched_copy() {
    let mut g = Guard::new(&cfg());
    g.expect_operating_point(3_000, 2_400);
    let mut watched = g;
    assert_eq!(feed(&mut watched, 30, 3_000, 1_500), None);
    g.resume(&watched);
    // 30 identical readings counted in the copy: 20 more complete the 50.
    assert_eq!(
        feed(&mut g, 30, 3_000, 1_500),
        Some((20, FaultReason::Frozen { counts: 1_500 }))
    );
}
