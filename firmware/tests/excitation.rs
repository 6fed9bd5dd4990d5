//! The pump's excitation presets (`ridge_pump_firmware::excitation`): lengths, levels within
//! the 20..90 % band, exact holds and slopes, the PRBS preset's m-sequence properties, names.

use ridge_core::excitation::{Excitation, Ramp};
use ridge_pump_firmware::excitation::{
    Record, A_MULTISTEP_STEPS, A_RAMP_SHAPE, B_MULTISTEP_STEPS, B_RAMP_SHAPE, PRBS_PRESET_ORDER,
    PRESET_DUTY_MAX, PRESET_DUTY_MIN,
};

/// Drains a generator into a fixed buffer, returning the count.
fn drain<I: Iterator<Item = u16>>(it: I, buf: &mut [u16]) -> usize {
    let mut n = 0;
    for (slot, d) in buf.iter_mut().zip(it) {
        *slot = d;
        n += 1;
    }
    n
}

const BUF: usize = 4096;

/// The ramp generator of a ramp preset.
fn ramp(r: Record) -> Ramp {
    match r.generator() {
        Excitation::Ramp(g) => g,
        other => panic!("{} is not a ramp: {other:?}", r.name()),
    }
}

#[test]
fn preset_lengths_are_about_30_s() {
    let expect = [3000u32, 3000, 3000, 3000, 3066];
    for (r, &n) in Record::ALL.iter().zip(expect.iter()) {
        assert_eq!(r.len_samples(), n, "{}", r.name());
        let mut g = r.generator();
        assert_eq!(g.size_hint(), (n as usize, Some(n as usize)));
        let mut count = 0u32;
        while g.next_duty().is_some() {
            count += 1;
            assert_eq!(g.remaining(), n - count);
        }
        assert_eq!(count, n, "{}", r.name());
        // Fused: stays exhausted.
        assert_eq!(g.next_duty(), None);
        assert_eq!(g.next(), None);
        // 30 s ± 1 s at 100 Hz.
        assert!((2900..=3100).contains(&n));
    }
}

#[test]
fn preset_levels_within_20_to_90_percent() {
    for r in Record::ALL {
        let mut lo = u16::MAX;
        let mut hi = 0;
        for d in r.generator() {
            lo = lo.min(d);
            hi = hi.max(d);
        }
        assert!(lo >= PRESET_DUTY_MIN, "{} min {}", r.name(), lo);
        assert!(hi <= PRESET_DUTY_MAX, "{} max {}", r.name(), hi);
        // Every preset actually spans a good part of the range.
        assert!(hi - lo >= 4_000, "{} span {}", r.name(), hi - lo);
    }
}

#[test]
fn reset_replays_the_same_sequence() {
    for r in Record::ALL {
        let mut a = [0u16; BUF];
        let mut b = [0u16; BUF];
        let mut g = r.generator();
        let na = drain(&mut g, &mut a);
        g.reset();
        let nb = drain(&mut g, &mut b);
        assert_eq!(na, nb);
        assert_eq!(a, b, "{}", r.name());
    }
}

#[test]
fn names_round_trip() {
    for r in Record::ALL {
        assert_eq!(r.name().parse::<Record>().ok(), Some(r));
    }
    assert_eq!("a-ramp".parse::<Record>().ok(), Some(Record::ARamp));
    assert_eq!("C-Ramp".parse::<Record>().ok(), None);
}

#[test]
fn multistep_holds_each_level() {
    for (steps, g) in [
        (A_MULTISTEP_STEPS, Record::AMultistep.generator()),
        (B_MULTISTEP_STEPS, Record::BMultistep.generator()),
    ] {
        let mut buf = [0u16; BUF];
        let n = drain(g, &mut buf);
        let mut pos = 0usize;
        for s in steps {
            let h = usize::from(s.hold);
            assert!(buf[pos..pos + h].iter().all(|&d| d == s.level));
            pos += h;
        }
        assert_eq!(pos, n);
    }
    // A and B really differ, in levels and in holds.
    assert_ne!(A_MULTISTEP_STEPS, B_MULTISTEP_STEPS);
    assert!(B_MULTISTEP_STEPS.iter().any(|s| s.hold != 200));
}

#[test]
fn ramp_slope_is_exact() {
    for (g, slope) in [(ramp(Record::ARamp), 14i32), (ramp(Record::BRamp), 30)] {
        let shape = g.shape();
        assert_eq!((shape.high - shape.low) % shape.slope, 0);
        let mut buf = [0u16; BUF];
        let n = drain(g.clone(), &mut buf);
        let v = &buf[..n];
        let mut ups = 0;
        let mut downs = 0;
        for w in v.windows(2) {
            let dv = i32::from(w[1]) - i32::from(w[0]);
            assert!(dv == 0 || dv.abs() == slope, "step {dv}");
            if dv > 0 {
                ups += 1;
            } else if dv < 0 {
                downs += 1;
            }
        }
        let per_ramp = (shape.high - shape.low) / shape.slope;
        assert_eq!(g.ramp_len(), u32::from(per_ramp));
        // Each cycle: `per_ramp` increments up and `per_ramp` decrements down.
        assert_eq!(ups, per_ramp * shape.cycles);
        assert_eq!(downs, per_ramp * shape.cycles);
        assert_eq!(v[0], shape.low);
        assert_eq!(*v.iter().max().unwrap(), shape.high);
        assert_eq!(*v.iter().min().unwrap(), shape.low);
        // duty_at agrees with iteration.
        for (i, &d) in v.iter().enumerate() {
            assert_eq!(g.duty_at(i as u32), Some(d));
        }
        assert_eq!(g.duty_at(n as u32), None);
    }
    // A and B have different slopes.
    assert_ne!(A_RAMP_SHAPE.slope, B_RAMP_SHAPE.slope);
}

#[test]
fn prbs_preset_period_balance_and_hold() {
    let Excitation::Prbs(g) = Record::Prbs.generator() else {
        panic!("PRBS preset is not a PRBS");
    };
    assert_eq!(g.initial_lfsr().order(), PRBS_PRESET_ORDER);
    assert_eq!(g.initial_lfsr().period(), 511);
    let hold = usize::from(g.hold());
    let mut buf = [0u16; BUF];
    let n = drain(g.clone(), &mut buf);
    assert_eq!(n, 511 * hold);
    let v = &buf[..n];
    // Constant within each bit.
    for bit in v.chunks(hold) {
        assert!(bit.iter().all(|&d| d == bit[0]));
        assert!(bit[0] == g.low() || bit[0] == g.high());
    }
    let highs = v.chunks(hold).filter(|b| b[0] == g.high()).count();
    let lows = v.chunks(hold).filter(|b| b[0] == g.low()).count();
    assert_eq!(highs, 256);
    assert_eq!(lows, 255);
    // Longest run of equal bits in an m-sequence of order n is n (ones) and n-1 (zeros).
    let mut longest = 0;
    let mut run = 0;
    let mut prev = None;
    for b in v.chunks(hold) {
        if Some(b[0]) == prev {
            run += 1;
        } else {
            run = 1;
            prev = Some(b[0]);
        }
        longest = longest.max(run);
    }
    assert_eq!(longest, usize::from(PRBS_PRESET_ORDER));
}
