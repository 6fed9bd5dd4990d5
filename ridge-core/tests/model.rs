//! ARX models, streaming predictors and scores against direct computations.
mod common;

use ridge_core::{ArxModel, Evaluation, Mode, Offset, Predictor, Score, Structure};

#[test]
fn one_step_and_free_run_follow_their_definitions() {
    let mut rng = common::Rng::new(1);
    let u = common::multilevel(&mut rng, 500, 0.0, 1.0, 7);
    let y = common::simulate(&[1.1, -0.3], &[2.0, 1.0], 3, 0.5, &u, 0.1, 2);
    // A deliberately wrong model so that one-step and free-run differ.
    let m = ArxModel::new(&[1.0, -0.25], &[2.2, 0.8], 3, Offset::Intercept, 0.4).unwrap();
    let mdl = m.structure().seed_len();
    assert_eq!(mdl, 4, "m = max(p, d + q - 1)");
    let mut one = Predictor::new(m, Mode::OneStep);
    let mut free = Predictor::new(m, Mode::FreeRun);
    let mut yfree: Vec<f64> = Vec::new();
    for t in 0..u.len() {
        let a = one.step(u[t], y[t]);
        let b = free.step(u[t], y[t]);
        if t < mdl {
            assert_eq!((a, b), (None, None));
            yfree.push(y[t]);
            continue;
        }
        let direct =
            |ys: &[f64]| 0.4 + 1.0 * ys[t - 1] - 0.25 * ys[t - 2] + 2.2 * u[t - 3] + 0.8 * u[t - 4];
        let want_one = direct(&y);
        let want_free = direct(&yfree);
        yfree.push(want_free);
        assert!((a.unwrap() - want_one).abs() < 1e-12);
        assert!((b.unwrap() - want_free).abs() < 1e-9);
    }
}

#[test]
fn scores_match_eq_16_and_matlab_fit() {
    let mut rng = common::Rng::new(3);
    let y: Vec<f64> = (0..300).map(|_| 20.0 + 5.0 * rng.normal()).collect();
    let yhat: Vec<f64> = y.iter().map(|v| v + 0.5 * rng.normal()).collect();
    let mut s = Score::new();
    for (a, b) in y.iter().zip(&yhat) {
        s.add(*a, *b);
    }
    let m = s.metrics().unwrap();
    let n = y.len() as f64;
    let sse: f64 = y.iter().zip(&yhat).map(|(a, b)| (a - b).powi(2)).sum();
    let mean = y.iter().sum::<f64>() / n;
    let sst: f64 = y.iter().map(|a| (a - mean).powi(2)).sum();
    assert!((m.rmse - (sse / n).sqrt()).abs() < 1e-12);
    assert!((m.fit - 100.0 * (1.0 - (sse / sst).sqrt())).abs() < 1e-9);
    assert_eq!(m.n, 300);
    assert!(Score::<f32>::new().metrics().is_none());
}

#[test]
fn a_true_model_scores_the_noise_level() {
    let mut rng = common::Rng::new(5);
    let u = common::multilevel(&mut rng, 5000, -1.0, 1.0, 9);
    let sigma = 0.05;
    let y = common::simulate(&[0.7], &[1.0, 0.5], 2, 0.0, &u, sigma, 6);
    let m = ArxModel::new(&[0.7], &[1.0, 0.5], 2, Offset::None, 0.0).unwrap();
    let mut ev = Evaluation::new(m);
    for (a, b) in u.iter().zip(&y) {
        ev.push(*a, *b);
    }
    let one = ev.one_step().unwrap();
    assert_eq!(one.n as usize, 5000 - 3);
    assert!(
        (one.rmse - sigma).abs() < 0.005,
        "one-step RMSE {} ≈ σ",
        one.rmse
    );
    // Free run accumulates the noise through the dynamics: larger, but still a good fit.
    let free = ev.free_run().unwrap();
    assert!(free.rmse > one.rmse && free.fit > 90.0);
    assert!((m.static_gain() - 1.5 / 0.3).abs() < 1e-12);
    assert_eq!(m.structure(), Structure::new(1, 2, 2).unwrap());
}

#[test]
fn a_validation_gram_scores_a_model_without_the_data() {
    let mut rng = common::Rng::new(8);
    let u = common::multilevel(&mut rng, 2000, 0.0, 1.0, 7);
    let y = common::simulate(&[1.1, -0.3], &[2.0, 1.0], 3, 0.5, &u, 0.1, 9);
    let m = ArxModel::new(&[1.0, -0.25], &[2.2, 0.8], 3, Offset::Intercept, 0.4).unwrap();
    let mut g = ridge_core::FloatGram::new();
    for (a, b) in u.iter().zip(&y) {
        g.push(*a, *b).unwrap();
    }
    let rss = g
        .normal::<f64>(ridge_core::Scale::UNIT)
        .unwrap()
        .rss(&m)
        .unwrap();
    // Direct: one-step errors with zero history before the record.
    let at = |v: &[f64], i: isize| if i >= 0 { v[i as usize] } else { 0.0 };
    let mut want = 0.0;
    for t in 0..y.len() as isize {
        let yhat = 0.4 + 1.0 * at(&y, t - 1) - 0.25 * at(&y, t - 2)
            + 2.2 * at(&u, t - 3)
            + 0.8 * at(&u, t - 4);
        want += (y[t as usize] - yhat).powi(2);
    }
    assert!((rss - want).abs() < 1e-9 * want, "{rss} vs {want}");
}
