//! A fixed computation through ridge-core's statistics path, printed value by value, for
//! comparing a board's arithmetic with the host's (`src/bin/avr-arith.rs`,
//! `scripts/avr-arith-check`, whose diff must stay empty). It caught the AVR backend's
//! miscompilations (README, "Known limits").
use ridge_core::{
    Fit, Grid, IntGram, Method, Offset, OrderRange, Real, RidgeM, Scale, Search, Structure,
};

/// A fit's iteration count and coefficients (θ, φ, intercept) as bit patterns.
fn fit_lines<W: ufmt::uWrite>(w: &mut W, fit: &Fit<f32>) {
    let m = fit.model();
    let _ = ufmt::uwriteln!(w, "iterations {}", fit.iterations);
    for v in m.theta().iter().chain(m.phi()) {
        let _ = ufmt::uwriteln!(w, "coef {}", v.to_bits());
    }
    let _ = ufmt::uwriteln!(w, "intercept {}", m.intercept().to_bits());
}

fn record() -> (IntGram, i64, i64, i64) {
    let mut g = IntGram::new();
    let (mut sy, mut syy, mut sy1) = (0i64, 0i64, 0i64);
    let mut x: u32 = 12345;
    let (mut y1, mut y2) = (0i32, 0i32);
    for t in 0..600i32 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        let u = 2000 + ((t / 15) % 7) * 1000;
        let y = (12 * y1 - 4 * y2) / 10 + u / 3 + (x % 41) as i32 - 20;
        let _ = g.push(u, y);
        sy += i64::from(y);
        syy += i64::from(y) * i64::from(y);
        sy1 += i64::from(y) * i64::from(y1);
        y2 = y1;
        y1 = y;
    }
    (g, sy, syy, sy1)
}

/// Writes `name value` lines (f32 values as their bit patterns in decimal).
pub fn write<W: ufmt::uWrite>(w: &mut W) {
    for (a, b, c, d) in [
        (600i64, 45268477322i64, 4852116i64, 4852116i64),
        (3, 5, 2, 7),
        (1 << 40, 1 << 30, 1, 1),
        (45168016793, 45268477322, 45163815969, 45163815969),
        // Signs (the magnitudes and the negations of the exact products), zero products, a
        // second product alone: the byte form passed its second pair on the stack once.
        (-3, 5, 2, -7),
        (0, 0, 2, 7),
        (0, 0, -2, 7),
        (1, 1, 1, 1),
        (256, 1, 0, 0),
        (-(1 << 40), 1 << 30, -5, -7),
        (-45168016793, -45268477322, 45163815969, -45163815969),
        (-i64::MAX, i64::MAX, i64::MAX, -i64::MAX),
    ] {
        let (hi, lo, f) = ridge_core::wide::probe(&a, &b, &c, &d);
        let _ = ufmt::uwriteln!(
            w,
            "wide {} {} {} {} f {}",
            (hi >> 32) as u32,
            hi as u32,
            (lo >> 32) as u32,
            lo as u32,
            f.to_bits()
        );
    }
    let (g, sy, syy, sy1) = record();
    let _ = ufmt::uwriteln!(w, "n {} sy {} syy {} sy1 {}", g.len(), sy, syy, sy1);
    let _ = ufmt::uwriteln!(
        w,
        "raw yy00 {} yy11 {} yy01 {} yy22 {}",
        g.output_lag_entry(0, 0),
        g.output_lag_entry(1, 1),
        g.output_lag_entry(0, 1),
        g.output_lag_entry(2, 2)
    );
    let _ = ufmt::uwriteln!(
        w,
        "raw u0y1 {} u0y0 {} u1y1 {} u3y0 {}",
        g.input_output_entry(0, 1),
        g.input_output_entry(0, 0),
        g.input_output_entry(1, 1),
        g.input_output_entry(3, 0)
    );
    {
        let mut e = ridge_core::Normal::<f32>::empty();
        let _ = ufmt::uwriteln!(
            w,
            "size {} empty {}",
            core::mem::size_of::<ridge_core::Normal<f32>>() as u32,
            e.samples()
        );
        let r = g.normal_into(&Scale::UNIT, &mut e);
        let code: u8 = match r {
            Ok(()) => 0,
            Err(ridge_core::Error::NonFinite) => 1,
            Err(ridge_core::Error::Overflow) => 2,
            Err(ridge_core::Error::TooShort { .. }) => 3,
            Err(ridge_core::Error::NotExcited) => 4,
            Err(_) => 5,
        };
        let _ = ufmt::uwriteln!(w, "into code {} samples {}", code, e.samples());
    }
    let r = g.normal::<f32>(Scale::UNIT);
    let _ = ufmt::uwriteln!(w, "unit ok {}", r.is_ok());
    if let Ok(f) = r {
        let _ = ufmt::uwriteln!(w, "samples {}", f.samples());
        match f.system(Structure { p: 1, q: 1, d: 0 }, Offset::None) {
            Err(ridge_core::Error::TooShort { needed, have }) => {
                let _ = ufmt::uwriteln!(w, "tooshort {} {}", needed, have);
            }
            Err(ridge_core::Error::InvalidStructure) => {
                let _ = ufmt::uwriteln!(w, "invalid");
            }
            Err(_) => {
                let _ = ufmt::uwriteln!(w, "other");
            }
            Ok(_) => {}
        }
        if let Ok(sys) = f.system(Structure { p: 1, q: 1, d: 0 }, Offset::None) {
            // Exact in f32 only up to 2^24, so print as integers via i64 casts.
            let _ = ufmt::uwriteln!(
                w,
                "s11 {} s10 {} s00 {}",
                sys.augmented(0, 0) as i64,
                sys.augmented(0, 2) as i64,
                sys.augmented(2, 2) as i64
            );
        }
    }
    let Ok(mut nn) = g.normal::<f32>(ridge_pump_firmware::units::SCALE) else {
        let _ = ufmt::uwriteln!(w, "normal error");
        return;
    };
    let normal = &mut nn;
    let s = Structure { p: 2, q: 2, d: 1 };
    if let Ok(sys) = normal.system(s, Offset::None) {
        for i in 0..=sys.params() {
            for j in 0..=i {
                let _ = ufmt::uwriteln!(w, "aug {} {} {}", i, j, sys.augmented(i, j).to_bits());
            }
        }
        match sys.factor(0.0) {
            Ok(f) => {
                let _ = ufmt::uwriteln!(w, "rss {}", f.rss_min().to_bits());
            }
            Err(_) => {
                let _ = ufmt::uwriteln!(w, "factor error");
            }
        }
    }
    match Search::<f32>::default().run(normal, None) {
        Ok(sel) => {
            let st = sel.structure();
            let _ = ufmt::uwriteln!(w, "pick {} {} {} skip {}", st.p, st.q, st.d, sel.skipped);
            fit_lines(w, &sel.fit);
        }
        Err(_) => {
            let _ = ufmt::uwriteln!(w, "search error");
        }
    }
    // Ridge-M in the eigenbasis on single candidates with an intercept: the largest structure
    // (12 columns, 4 of them past the scratch factor; 200 iterates), and one that stops on
    // its step (69 iterates: the stopping rule's step-by-step part).
    for (p, q, d, gamma, tol) in [(6u8, 6u8, 0u8, 1000.0f32, 1e-6f32), (2, 2, 1, 1.0, 1e-4)] {
        let one = |v| OrderRange::new(v, v);
        let search = Search::<f32> {
            grid: Grid {
                p: one(p),
                q: one(q),
                d: one(d),
            },
            offset: Offset::Intercept,
            method: Method::RidgeM(RidgeM {
                gamma,
                tol,
                ..RidgeM::PAPER
            }),
            ..Search::DEFAULT
        };
        match search.run(normal, None) {
            Ok(sel) => fit_lines(w, &sel.fit),
            Err(_) => {
                let _ = ufmt::uwriteln!(w, "ridge-m error");
            }
        }
    }
    for x in [2.0f32, 0.3, 1.0e-40, 3.4e38, 12_345.678, 1.000_000_1, 0.25] {
        let _ = ufmt::uwriteln!(w, "sqrt {}", Real::sqrt(x).to_bits());
    }
    // The board's √ and ln against independent references on 2048 pseudo-random positive
    // finite f32 (every exponent): √ against the digit-by-digit `sqrt_f32` (correctly rounded,
    // tested against libm on the host), ln against the f64 log rounded to f32.
    let (mut sqrt_bad, mut ln_worst) = (0u16, 0u32);
    let mut z: u32 = 0x9E37_79B9;
    for _ in 0..2048 {
        z ^= z << 13;
        z ^= z >> 17;
        z ^= z << 5;
        let x = f32::from_bits(z % 0x7F80_0000);
        if x == 0.0 {
            continue;
        }
        if Real::sqrt(x).to_bits() != ridge_core::real::sqrt_f32(x).to_bits() {
            sqrt_bad += 1;
        }
        let want = libm::log(f64::from(x)) as f32;
        let got = Real::ln(x);
        let ulps = if (want < 0.0) == (got < 0.0) {
            want.to_bits().abs_diff(got.to_bits())
        } else {
            u32::MAX
        };
        ln_worst = ln_worst.max(ulps);
    }
    let _ = ufmt::uwriteln!(w, "sqrt-mismatch {}", sqrt_bad);
    // avr-libc's `log` measured 2 ulp at worst here, libm's `logf` 1.
    let _ = ufmt::uwriteln!(w, "ln-within-2-ulp {}", ln_worst <= 2);
    let _ = ufmt::uwriteln!(w, "i64f32 {}", (123_456_789_012i64 as f32).to_bits());
    let _ = ufmt::uwriteln!(
        w,
        "u64f32 {}",
        (18_000_000_000_000_000_000u64 as f32).to_bits()
    );
    let a: u64 = 0x1_2345_6789;
    let b: u64 = 0x9_8765_4321;
    let p = a.wrapping_mul(b);
    let _ = ufmt::uwriteln!(w, "u64mul {} {}", (p >> 32) as u32, p as u32);
    let _ = ufmt::uwriteln!(w, "end");
}

/// The structure of the re-identification check and benchmark: `p + q` + intercept = 9
/// coefficients, the largest window of `docs/control.md` (10 columns with the target).
pub const REID_STRUCTURE: Structure = Structure { p: 5, q: 3, d: 2 };

/// Sample `t` of the re-identification record, counts: a staircase input (`u`, 7 levels
/// held 43 ticks) and a second-order response with pseudo-random noise (`y`), in integers so
/// that the board and the host see the same samples.
pub fn reid_sample(t: u32, y1: i16, y2: i16) -> (i16, i16) {
    let u = 600 + ((t / 43) % 7) as i32 * 500 - 1500;
    let mut x = t.wrapping_mul(2_654_435_761) ^ 0x5bd1_e995;
    x ^= x >> 15;
    let noise = (x % 61) as i32 - 30;
    let y = (14 * i32::from(y1) - 5 * i32::from(y2)) / 10 + u / 4 + 200 + noise;
    (u as i16, y.clamp(-32_000, 32_000) as i16)
}

/// Fills `window` with `ticks` samples of [`reid_sample`], a breath boundary every 250.
pub fn reid_fill(window: &mut ridge_core::reid::Window<'_>, ticks: u32) {
    let (mut y1, mut y2) = (0i16, 0i16);
    for t in 0..ticks {
        let (u, y) = reid_sample(t, y1, y2);
        let _ = window.push(u, y);
        if t % 250 == 249 {
            window.end_breath();
        }
        y2 = y1;
        y1 = y;
    }
}

/// Re-identification (`ridge_core::reid`): the window's statistics and the sliced fit (one
/// unit per call, as a tick would run it), printed as integers and bit patterns, then `end`.
/// A part of its own (the `AVR_ARITH=reid` image): with [`write()`] the image would pass 64 KB
/// of flash (71 KB measured), where this check's `.data` copy is not yet shown to work.
pub fn write_reid<W: ufmt::uWrite>(w: &mut W) {
    reid_lines(w);
    let _ = ufmt::uwriteln!(w, "end");
}

fn reid_lines<W: ufmt::uWrite>(w: &mut W) {
    use ridge_core::reid::{window_len, Refit, RefitStep, Window};
    let mut store = [0i64; window_len(9)];
    let Ok(mut win) = Window::new(REID_STRUCTURE, Offset::Intercept, 2, &mut store) else {
        let _ = ufmt::uwriteln!(w, "reid window error");
        return;
    };
    reid_fill(&mut win, 1500);
    let _ = ufmt::uwriteln!(w, "reid rows {} weight {}", win.rows(), win.weight());
    for i in 0..=win.params() {
        let (a, b) = (win.entry(i, 0), win.entry(i, i));
        let _ = ufmt::uwriteln!(
            w,
            "reid g {} {} {} {} {}",
            i,
            (a >> 32) as u32,
            a as u32,
            (b >> 32) as u32,
            b as u32
        );
    }
    let scale = ridge_pump_firmware::units::SCALE;
    let Ok(mut refit) = Refit::start(&win, RidgeM::PAPER, &scale) else {
        let _ = ufmt::uwriteln!(w, "reid start error");
        return;
    };
    let _ = ufmt::uwriteln!(w, "reid response {}", refit.response().to_bits());
    let mut calls = 0u32;
    loop {
        calls += 1;
        match refit.step(1) {
            RefitStep::Working => {}
            RefitStep::Done(m, k) => {
                let _ = ufmt::uwriteln!(w, "reid calls {} iterations {}", calls, k);
                for v in m.theta().iter().chain(m.phi()) {
                    let _ = ufmt::uwriteln!(w, "reid coef {}", v.to_bits());
                }
                let _ = ufmt::uwriteln!(w, "reid intercept {}", m.intercept().to_bits());
                break;
            }
            RefitStep::Refused(_) => {
                let _ = ufmt::uwriteln!(w, "reid refused");
                break;
            }
        }
    }
}
