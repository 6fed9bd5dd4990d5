//! Setpoint programs: breath shapes against hand-computed values, the prepared wave against
//! the definition in seconds, and the incremental `Setpoint` (with preview) against `value`.

use ridge_pump_firmware::setpoint::{
    value, Breath, BreathWave, Program, Setpoint, Shape, DEMO_BREATH, DEMO_HOLD_TICKS, DEMO_STEPS,
};

const SQUARE: Breath = Breath {
    shape: Shape::Square,
    rate: 20.0,
    ie: 2.0,
    peak: 60.0,
    bias: 10.0,
    rise: 0.3,
};

const RAMP: Breath = Breath {
    shape: Shape::Ramp,
    rate: 15.0,
    ie: 1.0,
    peak: 50.0,
    bias: 5.0,
    rise: 0.2,
};

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

/// 20/min, I:E 1:2: period 3 s, inspiration 1 s. Square, rise 0.3 s: linear from 10 to 60
/// slm over 0.3 s, 60 until 1 s, linear back to 10 over 0.3 s, then 10.
#[test]
fn square_breath_follows_its_definition() {
    assert_eq!(SQUARE.period(), 3.0);
    assert!(close(SQUARE.inspiration(), 1.0, 1e-6));
    for (t, want) in [
        (0.0, 10.0),
        (0.15, 35.0),
        (0.3, 60.0),
        (0.5, 60.0),
        (0.99, 60.0),
        (1.15, 35.0),
        (1.3, 10.0),
        (2.0, 10.0),
        (2.99, 10.0),
    ] {
        assert!(close(SQUARE.at(t), want, 1e-3), "t {t}: {}", SQUARE.at(t));
    }
}

/// 15/min, I:E 1:1: period 4 s, inspiration 2 s. Decelerating ramp, rise 0.2 s: 5 → 50 slm in
/// 0.2 s, then linearly down to 5 slm at 2 s (halfway, 1.1 s: 27.5 slm), then 5.
#[test]
fn ramp_breath_follows_its_definition() {
    for (t, want) in [
        (0.0, 5.0),
        (0.1, 27.5),
        (0.2, 50.0),
        (1.1, 27.5),
        (1.99, 5.0 + 45.0 * 0.01 / 1.8),
        (2.0, 5.0),
        (3.5, 5.0),
    ] {
        assert!(close(RAMP.at(t), want, 1e-3), "t {t}: {}", RAMP.at(t));
    }
}

#[test]
fn breath_settings_are_checked() {
    assert_eq!(SQUARE.check(), Ok(()));
    assert_eq!(RAMP.check(), Ok(()));
    assert_eq!(DEMO_BREATH.check(), Ok(()));
    let bad = |f: fn(&mut Breath)| {
        let mut b = SQUARE;
        f(&mut b);
        b.check()
    };
    assert_eq!(bad(|b| b.rate = 0.0), Err("rate"));
    assert_eq!(bad(|b| b.rate = f32::NAN), Err("rate"));
    assert_eq!(bad(|b| b.ie = -1.0), Err("ie"));
    assert_eq!(bad(|b| b.peak = f32::INFINITY), Err("flow"));
    assert_eq!(bad(|b| b.rise = 0.6), Err("rise"));
    assert_eq!(bad(|b| b.rise = -0.1), Err("rise"));
}

/// The prepared wave (reciprocals, whole-tick period) against the definition in seconds.
#[test]
fn wave_matches_the_definition_at_every_tick() {
    for b in [
        SQUARE,
        RAMP,
        DEMO_BREATH,
        Breath {
            rise: 0.0,
            ..SQUARE
        },
    ] {
        let w = BreathWave::new(&b);
        assert_eq!(w.period(), (b.period() * 100.0).round() as u32);
        for p in 0..w.period() {
            let t = p as f32 * 0.01;
            assert!(
                close(w.at_phase(p), b.at(t), 1e-3),
                "{b:?} phase {p}: {} vs {}",
                w.at_phase(p),
                b.at(t)
            );
        }
    }
}

/// `Setpoint` (incremental, with the preview of `ahead`) gives exactly `value` at every tick
/// for every kind of program, across the demo's hold → steps → breaths boundaries.
#[test]
fn setpoint_equals_value_at_every_tick_and_ahead() {
    let programs = [
        Program::Demo,
        Program::Breath(BreathWave::new(&SQUARE)),
        Program::Breath(BreathWave::new(&RAMP)),
        Program::Constant(33.0),
        Program::Hold,
    ];
    let steps: u32 = DEMO_STEPS.iter().map(|l| u32::from(l.ticks)).sum();
    let n = DEMO_HOLD_TICKS + steps + 5 * 300;
    for program in programs {
        let start = 21.25;
        let mut sp = Setpoint::new(program, start);
        for k in 0..n {
            for ahead in [1u32, 7, 17, 255] {
                assert_eq!(
                    sp.ahead(ahead).to_bits(),
                    value(program, start, k + ahead).to_bits(),
                    "{program:?} tick {k} ahead {ahead}"
                );
            }
            assert_eq!(
                sp.advance().to_bits(),
                value(program, start, k).to_bits(),
                "{program:?} tick {k}"
            );
        }
        assert_eq!(sp.ticks(), n);
    }
}

/// The demo: the start flow for the hold, each level for its ticks, then the square breaths.
#[test]
fn demo_program_is_hold_steps_breaths() {
    let start = 17.5;
    let v = |k| value(Program::Demo, start, k);
    assert_eq!(v(0), start);
    assert_eq!(v(DEMO_HOLD_TICKS - 1), start);
    let mut k = DEMO_HOLD_TICKS;
    for l in DEMO_STEPS {
        assert_eq!(v(k), l.slm);
        assert_eq!(v(k + u32::from(l.ticks) - 1), l.slm);
        k += u32::from(l.ticks);
    }
    // The first breath starts at the bias flow and is periodic.
    assert_eq!(v(k), DEMO_BREATH.bias);
    for j in 0..600 {
        assert_eq!(v(k + j), v(k + j + 300));
    }
}
