//! Volume-controlled breaths: the `VENT` settings' ranges at their edges, the volume wave's
//! shapes against hand-computed values, its inspiration summed tick by tick against the set
//! volume, and the per-breath bookkeeping (delivered volume, `BREATH` and `ALARM volume`
//! events, trim) against a trapezoid sum, an alarm sequence and a proportional plant written
//! here.

use ridge_pump_firmware::command::{Milli, VentArgs};
use ridge_pump_firmware::event::Event;
use ridge_pump_firmware::setpoint::{value, Program, Setpoint, Shape, VolumeBreath, VolumeWave};
use ridge_pump_firmware::ventilation::{settings, within_band, Anchor, Ventilation, TRIM_PERCENT};

/// The default flow limit (30 000 counts = 250 slm).
const LIMIT: i16 = 30_000;

fn args(vt: Milli, rate: Milli) -> VentArgs {
    VentArgs::new(vt, rate)
}

fn check(a: VentArgs) -> Result<VolumeBreath, &'static str> {
    settings(&a, LIMIT)
}

/// ISO 80601-2-12 row 1 as typed: `VENT vt=500 rate=20` (I:E 1:2 by default): 300-tick
/// breaths, 100 ticks of inspiration, a 10-tick rise, 5 slm bias, PEEP 5, trim on.
#[test]
fn defaults_fill_the_keys_left_out() {
    let b = check(args(500_000, 20_000)).unwrap();
    assert_eq!(b.tidal, 500.0);
    assert_eq!(b.peep, 5.0);
    assert!(b.trim);
    assert_eq!(b.wave.period(), 300);
    assert_eq!(b.wave.inspiration(), 100);
    assert_eq!(b.wave.rise(), 10);
    assert_eq!(b.wave.shape(), Shape::Square);
    assert_eq!(b.wave.bias(), 5.0);
    // 500 mL = 3000 slm·ticks; the bias gives 500 of them, the square's 100 − 5 = 95 unit
    // ticks the rest: amp = 2500 / 95 slm.
    assert!((b.wave.amplitude() - 2500.0 / 95.0).abs() < 1e-4);
}

/// A change of the base arguments.
type Edit = dyn Fn(&mut VentArgs);

/// Every range at its edges, in thousandths: the edge passes, one thousandth beyond fails with
/// the setting's name.
#[test]
fn every_range_is_checked_exactly() {
    let base = args(500_000, 20_000);
    let with = |f: &dyn Fn(&mut VentArgs)| {
        let mut a = base;
        f(&mut a);
        check(a).map(|_| ())
    };
    let cases: &[(&Edit, Result<(), &str>)] = &[
        // (The default 5 slm of bias alone would deliver 83 mL in the 1 s inspiration.)
        (
            &|a| {
                a.vt = 20_000;
                a.bias = Some(0);
            },
            Ok(()),
        ),
        (
            &|a| {
                a.vt = 19_999;
                a.bias = Some(0);
            },
            Err("vt"),
        ),
        (&|a| a.vt = 2_000_000, Ok(())),
        (&|a| a.vt = 2_000_001, Err("vt")),
        // 1 /min at 1:2: 20 s of inspiration, too long for any bias.
        (
            &|a| {
                a.rate = 1_000;
                a.bias = Some(0);
            },
            Ok(()),
        ),
        (&|a| a.rate = 999, Err("rate")),
        (&|a| a.rate = 60_000, Ok(())),
        (&|a| a.rate = 60_001, Err("rate")),
        // 20 /min: half the period is 1.5 s.
        (&|a| a.ti = Some(1_500), Ok(())),
        (&|a| a.ti = Some(1_501), Err("ti")),
        // 0.1 s is 10 ticks: a 5-tick rise fits, and 50 mL needs a peak of 48 slm.
        (
            &|a| {
                a.vt = 50_000;
                a.ti = Some(100);
                a.rise = Some(50);
            },
            Ok(()),
        ),
        (
            &|a| {
                a.vt = 50_000;
                a.ti = Some(99);
                a.rise = Some(0);
            },
            Err("ti"),
        ),
        (&|a| a.ie = Some(1_000), Ok(())),
        (&|a| a.ie = Some(999), Err("ie")),
        (&|a| a.ie = Some(10_000), Ok(())),
        (&|a| a.ie = Some(10_001), Err("ie")),
        // 1 s of inspiration, 100 ticks: a rise of 50 ticks; 0.504 s rounds to 50, 0.505 to 51.
        (&|a| a.rise = Some(500), Ok(())),
        (&|a| a.rise = Some(504), Ok(())),
        (&|a| a.rise = Some(505), Err("rise")),
        (&|a| a.rise = Some(-1), Err("rise")),
        (&|a| a.rise = Some(0), Ok(())),
        (&|a| a.peep = Some(0), Ok(())),
        (&|a| a.peep = Some(30_000), Ok(())),
        (&|a| a.peep = Some(30_001), Err("peep")),
        (&|a| a.peep = Some(-1), Err("peep")),
        (&|a| a.bias = Some(0), Ok(())),
        (&|a| a.bias = Some(-1), Err("bias")),
        (&|a| a.bias = Some(250_001), Err("bias")),
        // The bias alone delivers 30 slm · 100 ticks = 3000 slm·ticks = 500 mL.
        (&|a| a.bias = Some(30_000), Ok(())),
        (
            &|a| {
                a.bias = Some(30_000);
                a.vt = 499_999;
            },
            Err("flow"),
        ),
        // 0.5 s (50 ticks, rise 10: S = 45) without bias: 1500 mL · 1.25 = 11 250 slm·ticks
        // need a peak of 250 slm, the limit.
        (
            &|a| {
                a.ti = Some(500);
                a.bias = Some(0);
                a.vt = 1_500_000;
            },
            Ok(()),
        ),
        (
            &|a| {
                a.ti = Some(500);
                a.bias = Some(0);
                a.vt = 1_500_001;
            },
            Err("flow"),
        ),
    ];
    for (i, (f, want)) in cases.iter().enumerate() {
        assert_eq!(with(f), *want, "case {i}");
    }
}

/// Times round to whole ticks: 12 /min at 1:4 is 500 ticks with 100 of inspiration; 7 /min is
/// 857.14… → 857 ticks, at 1:3 214.25 → 214; `ti=0.805` → 81 (halves up).
#[test]
fn times_round_to_ticks() {
    let b = check(VentArgs {
        ie: Some(4_000),
        ..args(500_000, 12_000)
    })
    .unwrap();
    assert_eq!((b.wave.period(), b.wave.inspiration()), (500, 100));
    let b = check(VentArgs {
        ie: Some(3_000),
        ..args(500_000, 7_000)
    })
    .unwrap();
    assert_eq!((b.wave.period(), b.wave.inspiration()), (857, 214));
    let b = check(VentArgs {
        ti: Some(805),
        ..args(500_000, 7_000)
    })
    .unwrap();
    assert_eq!(b.wave.inspiration(), 81);
}

/// The shapes against hand-computed values: square rise 10 ticks from bias + amp/11 to the
/// peak at phase 10, ramp falling from the peak at 10 to bias + amp/90 at phase 99 (100 ticks
/// of inspiration); the bias flow in the expiration.
#[test]
fn wave_shapes_follow_their_definition() {
    let sq = VolumeWave::new(300, 100, 10, Shape::Square, 5.0, 500.0);
    let a = sq.amplitude();
    let close = |x: f32, y: f32| (x - y).abs() < 1e-4;
    assert!(close(sq.at_phase(0), 5.0 + a / 11.0));
    assert!(close(sq.at_phase(9), 5.0 + a * 10.0 / 11.0));
    for k in 10..100 {
        assert!(close(sq.at_phase(k), 5.0 + a), "{k}");
    }
    for k in 100..300 {
        assert_eq!(sq.at_phase(k), 5.0);
    }
    let ramp = VolumeWave::new(300, 100, 10, Shape::Ramp, 2.0, 300.0);
    let a = ramp.amplitude();
    assert!(close(ramp.at_phase(0), 2.0 + a / 11.0));
    assert!(close(ramp.at_phase(10), 2.0 + a));
    assert!(close(ramp.at_phase(54), 2.0 + a * 46.0 / 90.0));
    assert!(close(ramp.at_phase(99), 2.0 + a / 90.0));
    assert_eq!(ramp.at_phase(100), 2.0);
    // No rise: the peak from the first tick.
    let step = VolumeWave::new(200, 60, 0, Shape::Square, 0.0, 200.0);
    assert!(close(step.at_phase(0), step.amplitude()));
}

/// For every shape, rise and bias, the inspiration's setpoints summed tick by tick (1/6 mL per
/// slm and tick) are the volume asked for.
#[test]
fn inspiration_sums_to_the_volume() {
    for shape in [Shape::Square, Shape::Ramp] {
        for (period, insp) in [
            (300u16, 100u16),
            (500, 100),
            (200, 67),
            (100, 10),
            (6000, 1200),
        ] {
            for rise in [0, 1, 5, insp / 4, insp / 2] {
                for (bias, volume) in [(0.0, 500.0), (5.0, 500.0), (2.0, 200.0), (10.0, 300.0)] {
                    let w = VolumeWave::new(period, insp, rise, shape, bias, volume);
                    let sum: f64 = (0..u32::from(insp)).map(|k| f64::from(w.at_phase(k))).sum();
                    let delivered = sum / 6.0;
                    assert!(
                        (delivered - f64::from(volume)).abs() < 2e-5 * f64::from(volume),
                        "{shape:?} {period}/{insp} rise {rise} bias {bias}: {delivered} vs {volume}"
                    );
                }
            }
        }
    }
}

/// Setpoint, program and bookkeeping driven as run mode drives them (phase read before the
/// program advances, the bookkeeping after), with the reading of each tick from `reading(tick,
/// ended setpoint)`, ticks counted from breath 1's first. The lead-in before it (one
/// expiration) is checked on the way: the bias flow with the valve open, the phases from the
/// inspiration's end, no event, the breath number 0. Returns the events and the readings.
fn ventilate(
    b: VolumeBreath,
    ticks: u32,
    mut reading: impl FnMut(u32, f32) -> i16,
) -> (Vec<(u32, Event)>, Vec<i16>) {
    let program = Program::Volume(b);
    let mut sp = Setpoint::new(program, 0.0);
    let mut vent = Ventilation::new(b.tidal);
    let (period, insp) = (u32::from(b.wave.period()), u32::from(b.wave.inspiration()));
    let mut ended = 0.0f32;
    for k in insp..period {
        assert_eq!(sp.volume_phase(), Some((false, k)));
        assert_eq!(sp.advance(), b.wave.bias());
        let mut event = None;
        vent.after_pwm(&mut sp, k, counts(ended), ended, &mut event);
        assert_eq!((event, vent.breath()), (None, 0), "lead-in tick {k}");
        ended = b.wave.bias();
    }
    let (mut events, mut ys) = (Vec::new(), Vec::new());
    for t in 0..ticks {
        let (_, phase) = sp.volume_phase().unwrap();
        let y = reading(t, ended);
        ys.push(y);
        let r = sp.advance();
        let mut event = None;
        vent.after_pwm(&mut sp, phase, y, ended, &mut event);
        if let Some(e) = event {
            events.push((t, e));
        }
        ended = r;
    }
    (events, ys)
}

fn counts(slm: f32) -> i16 {
    (slm * 120.0).round() as i16
}

fn breaths(events: &[(u32, Event)]) -> Vec<ridge_pump_firmware::event::BreathSummary> {
    events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Breath(b) => Some(*b),
            _ => None,
        })
        .collect()
}

/// The reading follows the setpoint one tick late: each breath's delivered volume is the
/// trapezoid sum of its readings from the tick that closed the valve to the one that opened
/// it (computed here in f64), the peak the largest inspiratory reading, the RMS that of
/// setpoint − reading over the breath; `BREATH n` comes at the tick that starts breath `n + 1`.
#[test]
fn bookkeeping_integrates_the_readings_of_the_inspiration() {
    let b = VolumeBreath {
        trim: false,
        ..check(args(500_000, 20_000)).unwrap()
    };
    let (events, ys) = ventilate(b, 300 * 4 + 1, |_, ended| counts(ended) + 3);
    let got = breaths(&events);
    assert_eq!(got.len(), 4);
    for (i, br) in got.iter().enumerate() {
        let from = 300 * i;
        assert_eq!(br.number, i as u32 + 1);
        assert_eq!(
            events
                .iter()
                .filter(|(t, _)| *t == from as u32 + 300)
                .count(),
            1
        );
        let y = |k: usize| f64::from(ys[from + k]) / 120.0;
        let trapezoid = (0..100).map(|k| 0.5 * (y(k) + y(k + 1))).sum::<f64>() / 6.0;
        assert!(
            (f64::from(br.delivered) - trapezoid).abs() < 1e-3,
            "breath {}: {} vs {trapezoid}",
            br.number,
            br.delivered
        );
        let peak = (1..=100).map(|k| ys[from + k]).max().unwrap();
        assert_eq!(br.peak, peak);
        assert_eq!(br.samples, 300);
        // 3 counts above the setpoint (rounded to counts) every tick, but the first (the
        // program's first setpoint).
        let rms = (f64::from(br.sum_sq) / 300.0).sqrt();
        assert!((rms - 3.0 / 120.0).abs() < 0.01, "rms {rms}");
        assert_eq!(br.tidal, 500.0);
        assert_eq!(br.command, 500.0);
    }
}

/// Trim off, readings at 70 % of the setpoint for breaths 1–3, then 100 %: out of the band
/// (±(4 mL + 15 %)) twice raises the alarm at the end of breath 2's inspiration (not breath
/// 1's), back in twice clears it at the end of breath 5's.
#[test]
fn volume_alarm_needs_two_breaths_out_and_two_back() {
    let b = VolumeBreath {
        trim: false,
        ..check(args(500_000, 20_000)).unwrap()
    };
    let scale = |t: u32| if t < 3 * 300 + 1 { 0.7 } else { 1.0 };
    let (events, _) = ventilate(b, 300 * 7, |t, ended| counts(ended * scale(t)));
    let alarms: Vec<(u32, bool)> = events
        .iter()
        .filter_map(|(t, e)| match e {
            Event::VolumeAlarm { on, delivered, .. } => {
                assert_eq!(within_band(*delivered, 500.0), !on);
                Some((*t, *on))
            }
            _ => None,
        })
        .collect();
    // The end of breath n's inspiration is tick 300 (n − 1) + 100.
    assert_eq!(alarms, vec![(400, true), (1300, false)]);
    let got = breaths(&events);
    assert!(!within_band(got[0].delivered, 500.0));
    assert!(within_band(got[3].delivered, 500.0));
}

/// A plant that delivers 85 % of the programmed flow: with the trim the delivered volume is
/// within ±(4 mL + 5 %) from breath 4 on (the error shrinks by 1 − 0.5 · 0.85 per breath),
/// the programmed volume within its bound; without it every breath delivers ~85 %. At 60 %
/// the trim stops at its bound and the volume stays short.
#[test]
fn trim_corrects_a_proportional_shortfall_within_its_bound() {
    let b = check(args(500_000, 20_000)).unwrap();
    let run = |trim: bool, gain: f32| {
        let b = VolumeBreath { trim, ..b };
        let (events, _) = ventilate(b, 300 * 10 + 1, |_, ended| counts(ended * gain));
        breaths(&events)
    };
    let with = run(true, 0.85);
    for br in &with {
        let bound = 500.0 * (1.0 + f32::from(TRIM_PERCENT) / 100.0);
        assert!(br.command <= bound && br.command >= 1000.0 - bound);
        if br.number >= 4 {
            assert!(
                (br.delivered - 500.0).abs() <= 4.0 + 0.05 * 500.0,
                "breath {}: {}",
                br.number,
                br.delivered
            );
        }
    }
    for br in run(false, 0.85) {
        assert!((br.delivered - 425.0).abs() < 3.0, "{}", br.delivered);
    }
    let short = run(true, 0.6);
    let last = short.last().unwrap();
    assert_eq!(last.command, 625.0);
    assert!((last.delivered - 375.0).abs() < 3.0, "{}", last.delivered);
}

/// `value` (the program's definition) and the running setpoint agree for a volume program
/// until the trim changes its amplitude.
#[test]
fn volume_program_setpoint_equals_value() {
    let b = check(VentArgs {
        wave: Some(Shape::Ramp),
        ie: Some(4_000),
        ..args(300_000, 12_000)
    })
    .unwrap();
    let program = Program::Volume(b);
    let mut sp = Setpoint::new(program, 3.0);
    for k in 0..1500 {
        assert_eq!(sp.ahead(9).to_bits(), value(program, 3.0, k + 9).to_bits());
        let (insp, phase) = sp.volume_phase().unwrap();
        // From the lead-in's phase 100 (the inspiration's end).
        assert_eq!(phase, (k + 100) % 500);
        assert_eq!(insp, phase < 100);
        assert_eq!(sp.advance().to_bits(), value(program, 3.0, k).to_bits());
    }
    // Other programs have no breath phase.
    assert_eq!(
        Setpoint::new(Program::Constant(3.0), 0.0).volume_phase(),
        None
    );
}

/// The fault checks' anchors: a pause at every tick of the lead-in (200 ticks) and breath 1's
/// first, then mid-expiration (phase 200 of 300, 100 of inspiration) `Hold` when the reading
/// is within 1 slm + 15 % of the bias flow, `Keep` when not; nothing on the other ticks (not
/// in the lead-in's middle: its lung is still filling).
#[test]
fn breath_boundaries_anchor_the_fault_checks() {
    let b = check(args(500_000, 20_000)).unwrap(); // bias 5 slm: band 1.75 slm
    for (bias_reading, want) in [
        (5.0f32, Anchor::Hold),
        (6.7, Anchor::Hold),
        (3.3, Anchor::Hold),
        (6.8, Anchor::Keep),
        (0.0, Anchor::Keep),
    ] {
        let mut sp = Setpoint::new(Program::Volume(b), 0.0);
        let mut v = Ventilation::new(500.0);
        let mut anchors = Vec::new();
        for t in 0..801u32 {
            let (_, phase) = sp.volume_phase().unwrap();
            sp.advance();
            let y = if phase == 200 {
                counts(bias_reading)
            } else {
                3_000
            };
            if let Some(a) = v.after_pwm(&mut sp, phase, y, 0.0, &mut None) {
                anchors.push((t, a));
            }
        }
        let mut expected: Vec<(u32, Anchor)> = (0..=200).map(|t| (t, Anchor::Pause)).collect();
        expected.extend([(400, want), (700, want)]);
        assert_eq!(anchors, expected, "{bias_reading}");
    }
}
