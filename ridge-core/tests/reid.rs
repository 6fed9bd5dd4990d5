//! Closed-loop re-identification (`ridge_core::reid`): the window's statistics against a
//! brute-force weighted sum, the sliced fit against its one-shot run (bit for bit) and against
//! the crate's Ridge-M on the exact statistics of `MeasuredGram`, recovery of known ARX systems
//! (before and after a change of the system) and the acceptance rules.

use ridge_core::control::ModelLimits;
use ridge_core::reid::{
    window_len, Acceptance, Holdout, Refit, RefitStep, Rejection, Window, WINDOW_LEN_MAX,
};
use ridge_core::{ArxModel, Error, MeasuredGram, Offset, Regressor, RidgeM, Scale, Structure};

/// xorshift64*: deterministic pseudo-random numbers for the records.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in `[-1, 1)`.
    fn uniform(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// A known ARX system `y_t = c + Σ θ_i y_{t−i} + Σ φ_j u_{t−d−j} + e_t`, driven by random
/// steps (holds of 20..80 samples), in integer counts; the output is rounded to counts.
fn known_record(
    theta: &[f64],
    phi: &[f64],
    d: usize,
    c: f64,
    noise: f64,
    len: usize,
    seed: u64,
) -> (Vec<i16>, Vec<i16>) {
    let mut rng = Rng(seed);
    let (mut u, mut y) = (Vec::new(), Vec::new());
    let (mut yf, mut level, mut hold) = (Vec::<f64>::new(), 0.0, 0usize);
    for t in 0..len {
        if hold == 0 {
            level = (rng.uniform() * 2000.0).round();
            hold = 20 + (rng.next() % 60) as usize;
        }
        hold -= 1;
        u.push(level as i16);
        let mut v = c + noise * rng.uniform() * 3f64.sqrt();
        for (i, th) in theta.iter().enumerate() {
            v += th * if t > i { yf[t - 1 - i] } else { 0.0 };
        }
        for (j, ph) in phi.iter().enumerate() {
            v += ph
                * if t >= d + j {
                    f64::from(u[t - d - j])
                } else {
                    0.0
                };
        }
        yf.push(v);
        y.push(v.round().clamp(-32768.0, 32767.0) as i16);
    }
    (u, y)
}

/// The regressor row of `structure` at `t` in the window's internal order, target last.
fn row(s: Structure, offset: Offset, u: &[i16], y: &[i16], t: usize) -> Vec<f64> {
    let mut z = vec![f64::from(y[t - 1])];
    if offset == Offset::Intercept {
        z.push(1.0);
    }
    for i in 2..=usize::from(s.p) {
        z.push(f64::from(y[t - i]));
    }
    for j in 0..usize::from(s.q) {
        z.push(f64::from(u[t - usize::from(s.d) - j]));
    }
    z.push(f64::from(y[t]));
    z
}

#[test]
fn window_matches_a_brute_force_weighted_sum() {
    let s = Structure::new(3, 2, 1).unwrap();
    let (u, y) = known_record(&[1.2, -0.5, 0.1], &[0.3, 0.2], 1, 40.0, 30.0, 1500, 7);
    for shift in [0u8, 1, 2, 3] {
        let mut store = [0i64; WINDOW_LEN_MAX];
        let mut w = Window::new(s, Offset::Intercept, shift, &mut store).unwrap();
        let n = w.params();
        let m = s.seed_len();
        let lambda = 1.0 - 0.5f64.powi(i32::from(shift));
        let lambda = if shift == 0 { 1.0 } else { lambda };
        let mut brute = vec![vec![0.0f64; n + 1]; n + 1];
        let mut breaths = 0u32;
        for t in 0..u.len() {
            w.push(u[t], y[t]).unwrap();
            if t >= m {
                let z = row(s, Offset::Intercept, &u, &y, t);
                for (r, zi) in brute.iter_mut().zip(&z) {
                    for (x, zj) in r.iter_mut().zip(&z) {
                        *x += zi * zj;
                    }
                }
            }
            if t % 137 == 136 {
                w.end_breath();
                breaths += 1;
                for r in brute.iter_mut() {
                    for x in r.iter_mut() {
                        *x *= lambda;
                    }
                }
            }
        }
        assert_eq!(w.rows() as usize, u.len() - m);
        for (i, r) in brute.iter().enumerate() {
            for (j, &want) in r.iter().enumerate() {
                let got = w.entry(i, j) as f64;
                // The shift truncates by less than 1 count² per entry per breath.
                let tol = f64::from(breaths) + 1e-12 * want.abs();
                assert!(
                    (got - want).abs() <= tol,
                    "shift {shift} ({i}, {j}): {got} vs {want}"
                );
            }
        }
    }
}

/// A window fed with segments of a record only (each breath's inspiration, say), its lag
/// history restarted before each segment: the statistics are exactly the sum over the rows
/// whose samples all lie in one segment (the first `m` of each segment only seed the lags),
/// forgotten at each segment's end; a segment shorter than `m + 1` adds nothing. The samples
/// between segments are never pushed.
#[test]
fn a_window_restarted_at_each_segment_sums_only_rows_within_a_segment() {
    let s = Structure::new(3, 2, 2).unwrap();
    let (u, y) = known_record(&[1.2, -0.5, 0.1], &[0.3, 0.2], 2, 40.0, 30.0, 2000, 11);
    let m = s.seed_len();
    // Segments [start, end): lengths from 2 (shorter than m + 1) to 120, gaps of 0 to 90.
    let mut rng = Rng(5);
    let mut segments = Vec::new();
    let mut t = 3;
    while t < u.len() {
        let len = if segments.len() % 5 == 4 {
            2
        } else {
            2 + (rng.next() % 119) as usize
        };
        let end = (t + len).min(u.len());
        segments.push((t, end));
        t = end + (rng.next() % 91) as usize;
    }
    assert!(segments.iter().any(|&(a, b)| b - a <= m));
    for shift in [0u8, 2] {
        let mut store = [0i64; WINDOW_LEN_MAX];
        let mut w = Window::new(s, Offset::Intercept, shift, &mut store).unwrap();
        let n = w.params();
        let lambda = if shift == 0 {
            1.0
        } else {
            1.0 - 0.5f64.powi(i32::from(shift))
        };
        let mut brute = vec![vec![0.0f64; n + 1]; n + 1];
        let mut rows = 0usize;
        for (k, &(a, b)) in segments.iter().enumerate() {
            w.restart_lags();
            for t in a..b {
                w.push(u[t], y[t]).unwrap();
            }
            for t in (a + m)..b {
                let z = row(s, Offset::Intercept, &u, &y, t);
                for (r, zi) in brute.iter_mut().zip(&z) {
                    for (x, zj) in r.iter_mut().zip(&z) {
                        *x += zi * zj;
                    }
                }
                rows += 1;
            }
            w.end_breath();
            for r in brute.iter_mut() {
                for x in r.iter_mut() {
                    *x *= lambda;
                }
            }
            assert_eq!(w.rows() as usize, rows, "segment {k}");
        }
        for (i, r) in brute.iter().enumerate() {
            for (j, &want) in r.iter().enumerate() {
                let got = w.entry(i, j) as f64;
                let tol = segments.len() as f64 + 1e-12 * want.abs();
                assert!(
                    (got - want).abs() <= tol,
                    "shift {shift} ({i}, {j}): {got} vs {want}"
                );
            }
        }
    }
    // Without the restart the rows that span a gap are summed too: the statistics differ.
    let mut store = [0i64; WINDOW_LEN_MAX];
    let mut w = Window::new(s, Offset::Intercept, 0, &mut store).unwrap();
    for &(a, b) in &segments {
        for t in a..b {
            w.push(u[t], y[t]).unwrap();
        }
    }
    let within: usize = segments
        .iter()
        .map(|&(a, b)| (b - a).saturating_sub(m))
        .sum();
    assert!(w.rows() as usize > within);
}

/// A window kept apart from its storage between ticks (detached after each tick, attached for
/// the next, as the firmware's run mode keeps it) sums what the brute force sums.
#[test]
fn a_window_detached_between_ticks_matches_a_brute_force_weighted_sum() {
    let s = Structure::new(2, 3, 2).unwrap();
    let (u, y) = known_record(&[0.9, -0.2], &[0.3, 0.2, 0.1], 2, 40.0, 30.0, 1200, 11);
    let mut store = [0i64; WINDOW_LEN_MAX];
    let mut state = Window::new(s, Offset::Intercept, 2, &mut store)
        .unwrap()
        .detach();
    let n = s.params(Offset::Intercept);
    let m = s.seed_len();
    let mut brute = vec![vec![0.0f64; n + 1]; n + 1];
    let mut breaths = 0u32;
    for t in 0..u.len() {
        let mut w = Window::attach(state, &mut store).unwrap();
        w.push(u[t], y[t]).unwrap();
        if t >= m {
            let z = row(s, Offset::Intercept, &u, &y, t);
            for (r, zi) in brute.iter_mut().zip(&z) {
                for (x, zj) in r.iter_mut().zip(&z) {
                    *x += zi * zj;
                }
            }
        }
        if t % 150 == 149 {
            w.end_breath();
            breaths += 1;
            for x in brute.iter_mut().flatten() {
                *x *= 0.75;
            }
        }
        state = w.detach();
    }
    let w = Window::attach(state, &mut store).unwrap();
    assert_eq!(w.rows() as usize, u.len() - m);
    for (i, r) in brute.iter().enumerate() {
        for (j, &want) in r.iter().enumerate() {
            let got = w.entry(i, j) as f64;
            let tol = f64::from(breaths) + 1e-12 * want.abs();
            assert!((got - want).abs() <= tol, "({i}, {j}): {got} vs {want}");
        }
    }
    // Storage too short for the structure is refused.
    let state = w.detach();
    let mut small = [0i64; 8];
    assert!(matches!(
        Window::attach(state, &mut small),
        Err(Error::InvalidStructure)
    ));
}

#[test]
fn window_refuses_small_storage_and_bad_shift() {
    let s = Structure::new(2, 2, 0).unwrap();
    let mut small = [0i64; 8];
    assert_eq!(window_len(5), 21);
    assert!(matches!(
        Window::new(s, Offset::Intercept, 2, &mut small),
        Err(Error::InvalidStructure)
    ));
    let mut store = [0i64; 21];
    assert!(Window::new(s, Offset::Intercept, 2, &mut store).is_ok());
    assert!(matches!(
        Window::new(s, Offset::Intercept, 17, &mut store),
        Err(Error::InvalidParameter)
    ));
}

/// Fits the window with the sliced fit, `units` per call; returns the model, the iterates
/// and the number of calls.
fn sliced<T: ridge_core::Real>(refit: &mut Refit<T>, units: u32) -> (ArxModel<T>, u32, u32) {
    let mut calls = 0;
    loop {
        calls += 1;
        match refit.step(units) {
            RefitStep::Working => {}
            RefitStep::Done(m, k) => return (m, k, calls),
            RefitStep::Refused(e) => panic!("refused: {e:?}"),
        }
    }
}

fn bits(m: &ArxModel<f32>) -> Vec<u32> {
    m.theta()
        .iter()
        .chain(m.phi())
        .chain(core::iter::once(&m.intercept()))
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn sliced_fit_is_bit_identical_to_the_one_shot_fit() {
    let s = Structure::new(2, 3, 1).unwrap();
    let (u, y) = known_record(&[1.3, -0.45], &[0.05, 0.08, 0.02], 1, 25.0, 20.0, 3000, 11);
    let mut store = [0i64; WINDOW_LEN_MAX];
    let mut w = Window::new(s, Offset::Intercept, 2, &mut store).unwrap();
    for (t, (&ui, &yi)) in u.iter().zip(&y).enumerate() {
        w.push(ui, yi).unwrap();
        if t % 300 == 299 {
            w.end_breath();
        }
    }
    let scale = Scale {
        u: 1e-3,
        y: 1.0 / 120.0,
    };
    let method = RidgeM::<f32>::PAPER;
    let mut one = Refit::start(&w, method, &scale).unwrap();
    let RefitStep::Done(reference, iters) = one.finish() else {
        panic!("one-shot fit refused")
    };
    assert!(iters >= 2);
    for units in [1u32, 2, 3, 5, 17] {
        let mut r = Refit::start(&w, method, &scale).unwrap();
        let (m, k, calls) = sliced(&mut r, units);
        assert_eq!(k, iters, "units {units}");
        assert_eq!(bits(&m), bits(&reference), "units {units}");
        // Units: n + 1 factor rows, the solution, the iterates.
        let total = (w.params() as u32 + 1) + 1 + iters;
        assert_eq!(calls, total.div_ceil(units), "units {units}");
        // Further calls return the same result.
        assert_eq!(r.step(3), RefitStep::Done(m, k));
    }
}

#[test]
fn a_snapshot_taken_in_parts_with_the_window_held_back_is_the_one_shot_fit() {
    // As the firmware spreads it: `begin` at the boundary, the rows and the fit's first units
    // a tick later, the responses the tick after, the window's samples of those ticks held
    // back and pushed afterwards.
    let s = Structure::new(2, 3, 1).unwrap();
    let (u, y) = known_record(&[1.3, -0.45], &[0.05, 0.08, 0.02], 1, 25.0, 20.0, 3000, 11);
    let scale = Scale {
        u: 1e-3,
        y: 1.0 / 120.0,
    };
    let method = RidgeM::<f32>::PAPER;
    let boundary = 2399;
    let mut store = [0i64; WINDOW_LEN_MAX];
    let mut w = Window::new(s, Offset::Intercept, 2, &mut store).unwrap();
    for (t, (&ui, &yi)) in u.iter().zip(&y).enumerate().take(boundary + 1) {
        w.push(ui, yi).unwrap();
        if t % 300 == 299 {
            w.end_breath();
        }
    }
    let mut one = Refit::start(&w, method, &scale).unwrap();
    let RefitStep::Done(reference, iters) = one.finish() else {
        panic!("one-shot fit refused")
    };
    let mut parts = Refit::begin(&w, method).unwrap();
    // Nothing to step before the rows are taken.
    assert_eq!(parts.step(5), RefitStep::Working);
    parts.take_rows(&w, &scale).unwrap();
    assert_eq!(parts.step(2), RefitStep::Working);
    parts.take_responses(&w, &scale).unwrap();
    assert_eq!(parts.response().to_bits(), one.response().to_bits());
    assert_eq!(
        parts.input_response().to_bits(),
        one.input_response().to_bits()
    );
    // The held-back samples go in now; a window that moved on is refused for a snapshot.
    for (&ui, &yi) in u[boundary + 1..boundary + 4]
        .iter()
        .zip(&y[boundary + 1..boundary + 4])
    {
        w.push(ui, yi).unwrap();
    }
    assert_eq!(
        parts.take_responses(&w, &scale),
        Err(Error::InvalidStructure)
    );
    let (m, k, _) = sliced(&mut parts, 1);
    assert_eq!((k, bits(&m)), (iters, bits(&reference)));
}

/// The crate's Ridge-M iteration ([`RidgeM::iterate`]) on `MeasuredGram`'s exact statistics
/// of the same rows, as an ARX model (θ, φ, c).
fn reference_fit(
    s: Structure,
    u: &[i16],
    y: &[i16],
    scale: Scale,
    method: &RidgeM<f64>,
) -> (Vec<f64>, Vec<f64>, f64, u32) {
    let mut g = MeasuredGram::<i64>::new(s.seed_len() as u32);
    for (&ui, &yi) in u.iter().zip(y) {
        g.push(i32::from(ui), i32::from(yi)).unwrap();
    }
    let normal = g.normal::<f64>(scale).unwrap();
    let sys = normal.system(s, Offset::Intercept).unwrap();
    let (w, k) = method.iterate(&sys, |_, _| {}).unwrap();
    let (mut theta, mut phi, mut c) = (
        vec![0.0; usize::from(s.p)],
        vec![0.0; usize::from(s.q)],
        0.0,
    );
    for (i, wi) in w.iter().enumerate().take(sys.params()) {
        match sys.regressor(i).unwrap() {
            Regressor::Output(k) => theta[usize::from(k) - 1] = *wi,
            Regressor::Input(k) => phi[usize::from(k - s.d)] = *wi,
            Regressor::Constant => c = *wi,
        }
    }
    (theta, phi, c, k)
}

#[test]
fn fit_agrees_with_the_crates_ridge_m_on_exact_statistics() {
    for (k, s) in [(2u8, 2u8, 1u8), (3, 2, 3), (1, 4, 0)]
        .into_iter()
        .enumerate()
    {
        let s = Structure::new(s.0, s.1, s.2).unwrap();
        let (u, y) = known_record(
            &[1.1, -0.3],
            &[0.1, 0.05],
            2,
            30.0,
            15.0,
            2500,
            3 + k as u64,
        );
        let scale = Scale {
            u: 1e-3,
            y: 1.0 / 120.0,
        };
        let method = RidgeM::<f64>::default();
        let (theta, phi, c, iters) = reference_fit(s, &u, &y, scale, &method);
        let mut store = [0i64; WINDOW_LEN_MAX];
        let mut w = Window::new(s, Offset::Intercept, 0, &mut store).unwrap();
        for (&ui, &yi) in u.iter().zip(&y) {
            w.push(ui, yi).unwrap();
        }
        let mut r = Refit::start(&w, method, &scale).unwrap();
        // The window's spreads against the rows' own: y_t and u_{t−d}, t = m … N − 1.
        let m0 = s.seed_len();
        let rms = |v: Vec<f64>| {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
        };
        let ry = rms((m0..y.len()).map(|t| f64::from(y[t]) * scale.y).collect());
        let d = usize::from(s.d);
        let ru = rms((m0..u.len())
            .map(|t| f64::from(u[t - d]) * scale.u)
            .collect());
        assert!(
            (r.response() - ry).abs() < 1e-9 * ry,
            "{} vs {ry}",
            r.response()
        );
        assert!(
            (r.input_response() - ru).abs() < 1e-9 * ru,
            "{} vs {ru}",
            r.input_response()
        );
        let RefitStep::Done(m, k) = r.finish() else {
            panic!("refused")
        };
        assert_eq!(k, iters, "{s:?}");
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-8 * (1.0 + b.abs());
        for (a, b) in m.theta().iter().zip(&theta).chain(m.phi().iter().zip(&phi)) {
            assert!(close(*a, *b), "{s:?}: {a} vs {b}");
        }
        assert!(close(m.intercept(), c), "{s:?}: {} vs {c}", m.intercept());
    }
}

#[test]
fn fit_recovers_a_known_system_and_follows_a_change_through_forgetting() {
    // y in counts of 1/120, u in counts of 1e-3: the physical model has θ, φ·(1e-3·120)⁻¹…
    // compare in counts (scale 1) to keep the truth plain.
    let s = Structure::new(2, 2, 1).unwrap();
    let before = ([1.2, -0.36], [0.10, 0.06], 50.0);
    let after = ([1.5, -0.5625], [0.02, 0.01], 20.0);
    let (u1, y1) = known_record(&before.0, &before.1, 1, before.2, 4.0, 3000, 21);
    let (u2, y2) = known_record(&after.0, &after.1, 1, after.2, 4.0, 3000, 22);
    let mut store = [0i64; WINDOW_LEN_MAX];
    let mut w = Window::new(s, Offset::Intercept, 1, &mut store).unwrap();
    let fit = |w: &Window<'_>| {
        let mut r = Refit::start(
            w,
            RidgeM::<f32> {
                max_iter: 2000,
                ..RidgeM::PAPER
            },
            &Scale::UNIT,
        )
        .unwrap();
        match r.finish() {
            RefitStep::Done(m, _) => m,
            other => panic!("{other:?}"),
        }
    };
    let gain = |theta: [f64; 2], phi: [f64; 2]| (phi[0] + phi[1]) / (1.0 - theta[0] - theta[1]);
    let feed = |w: &mut Window<'_>, u: &[i16], y: &[i16]| {
        for (t, (&ui, &yi)) in u.iter().zip(y).enumerate() {
            w.push(ui, yi).unwrap();
            if t % 300 == 299 {
                w.end_breath();
            }
        }
    };
    feed(&mut w, &u1, &y1);
    let m = fit(&w);
    let g1 = gain(before.0, before.1);
    assert!(
        (f64::from(m.static_gain()) - g1).abs() < 0.03 * g1,
        "before: {} vs {g1}",
        m.static_gain()
    );
    for (a, b) in m.theta().iter().zip(before.0) {
        assert!((f64::from(*a) - b).abs() < 0.03, "θ {a} vs {b}");
    }
    // After the change: 10 "breaths" with λ = 1/2 leave 2⁻¹⁰ of the old data.
    feed(&mut w, &u2, &y2);
    let m = fit(&w);
    let g2 = gain(after.0, after.1);
    assert!(
        (f64::from(m.static_gain()) - g2).abs() < 0.05 * g2,
        "after: {} vs {g2}",
        m.static_gain()
    );
}

fn limits() -> ModelLimits<f64> {
    ModelLimits {
        stable_radius: 0.995,
        gain_min: 0.5,
        gain_max: 2.0,
    }
}

#[test]
fn acceptance_refuses_unexcited_unstable_and_worse_than_running() {
    let acc = Acceptance {
        model: limits(),
        min_response: 1.0,
        min_input_response: 0.1,
        min_fit: 70.0,
        holdout_min: 100,
    };
    let good = ArxModel::new(&[0.8], &[0.2], 1, Offset::Intercept, 0.0).unwrap();
    assert!(acc.check_estimate(&good, 5.0, 1.0).is_ok());
    assert!(matches!(
        acc.check_estimate(&good, 0.5, 1.0),
        Err(Rejection::NotExcited { .. })
    ));
    assert!(matches!(
        acc.check_estimate(&good, f64::NAN, 1.0),
        Err(Rejection::NotExcited { .. })
    ));
    // Output moving, input not (the closed loop's noise fed back).
    assert!(matches!(
        acc.check_estimate(&good, 5.0, 0.05),
        Err(Rejection::NotExcited { .. })
    ));
    let unstable = ArxModel::new(&[1.01], &[0.2], 1, Offset::Intercept, 0.0).unwrap();
    assert!(matches!(
        acc.check_estimate(&unstable, 5.0, 1.0),
        Err(Rejection::Model(_))
    ));
    let weak = ArxModel::new(&[0.8], &[0.02], 1, Offset::Intercept, 0.0).unwrap();
    assert!(matches!(
        acc.check_estimate(&weak, 5.0, 1.0),
        Err(Rejection::Model(_))
    ));
    // Held out: data from `good`; a wrong candidate against the right running model is
    // refused, the right one against a wrong running model accepted.
    let wrong = ArxModel::new(&[0.5], &[0.5], 1, Offset::Intercept, 0.0).unwrap();
    let mut rng = Rng(5);
    let (mut y, mut up, mut u) = (0.0, 0.0, 0.0);
    let mut a = Holdout::new(wrong, good);
    let mut b = Holdout::new(good, wrong);
    for t in 0..400 {
        if t % 40 == 0 {
            u = 10.0 * rng.uniform();
        }
        y = 0.8 * y + 0.2 * up + 0.05 * rng.uniform();
        up = u;
        a.push(u, y);
        b.push(u, y);
        if t == 50 {
            assert!(matches!(
                acc.judge(&a),
                Err(Rejection::TooFewHeldOut { .. })
            ));
        }
    }
    assert!(matches!(acc.judge(&a), Err(Rejection::Fit { .. })));
    let v = acc.judge(&b).unwrap();
    assert!(
        v.candidate.fit > 90.0 && v.running.fit < v.candidate.fit,
        "{v:?}"
    );
}
