//! Ridge-M, Ridge, OLS, RLS and the adaptive LASSO against dense references built from
//! the explicit regression matrix.
mod common;

use common::{multilevel, ridge_reference, simulate, Rng};
use nalgebra::{DMatrix, DVector};
use ridge_core::{
    AdaptiveLasso, Error, Estimator, FloatGram, Lambda, Normal, Offset, Ols, Ridge, RidgeM, Rls,
    Scale, Structure, System,
};

fn plant_record(seed: u64, n: usize, sigma: f64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let u = multilevel(&mut rng, n, 0.2, 0.9, 12);
    // A pump-like plant: slow, with delay 2, in slm per duty fraction.
    let y = simulate(&[1.3, -0.42], &[6.0, 3.0], 2, 0.0, &u, sigma, seed + 1);
    (u, y)
}

fn normal(u: &[f64], y: &[f64]) -> Normal<f64> {
    let mut g = FloatGram::new();
    for (&a, &b) in u.iter().zip(y) {
        g.push(a, b).unwrap();
    }
    g.normal(Scale::UNIT).unwrap()
}

fn internal(sys: &System<f64>, fit: &ridge_core::Fit<f64>) -> Vec<f64> {
    common::internal(sys, &fit.model())
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn ridge_is_the_first_ridge_m_iterate_and_matches_dense_solve() {
    let (u, y) = plant_record(1, 2000, 0.3);
    let nrm = normal(&u, &y);
    let sys = nrm
        .system(Structure::new(3, 3, 1).unwrap(), Offset::None)
        .unwrap();
    for gamma in [1.0, 1000.0, 1e5] {
        let ridge = Ridge { gamma }.fit(&sys).unwrap();
        let first = RidgeM {
            gamma,
            max_iter: 1,
            ..RidgeM::default()
        }
        .fit(&sys)
        .unwrap();
        assert_eq!(ridge.model(), first.model());
        assert_eq!(first.iterations, 1);
        let reference = ridge_reference(&sys, &u, &y, gamma);
        let got = internal(&sys, &ridge);
        assert!(
            max_diff(&got, reference.as_slice()) < 1e-8,
            "{got:?} vs {reference}"
        );
        // RSS of the ridge estimate against the explicit residuals.
        let rss = common::rss_reference(&sys, &u, &y, &got);
        assert!((ridge.rss - rss).abs() < 1e-9 * rss);
    }
}

#[test]
fn ridge_m_converges_to_least_squares() {
    let (u, y) = plant_record(2, 2000, 0.3);
    let nrm = normal(&u, &y);
    let sys = nrm
        .system(Structure::new(2, 2, 2).unwrap(), Offset::None)
        .unwrap();
    let ols = ridge_reference(&sys, &u, &y, 0.0);
    // γ small: one iterate is already least squares.
    let small = RidgeM {
        gamma: 1e-6,
        ..RidgeM::default()
    }
    .fit(&sys)
    .unwrap();
    assert!(max_diff(&internal(&sys, &small), ols.as_slice()) < 1e-6);
    // γ large, many iterates: the momentum walks to the least-squares fixed point.
    let many = RidgeM {
        gamma: 1000.0,
        tol: 1e-13,
        max_iter: 100_000,
        ..RidgeM::default()
    }
    .fit(&sys)
    .unwrap();
    assert!(many.iterations < 100_000);
    assert!(max_diff(&internal(&sys, &many), ols.as_slice()) < 1e-8);
    // ... whereas plain Ridge with the same γ stays shrunk.
    let ridge = Ridge { gamma: 1000.0 }.fit(&sys).unwrap();
    assert!(max_diff(&internal(&sys, &ridge), ols.as_slice()) > 1e-3);
    // RSS ordering: least squares is the minimum.
    let ls = Ols.fit(&sys).unwrap();
    assert!(ls.rss <= many.rss + 1e-9 * ls.rss && ls.rss < ridge.rss);
}

#[test]
fn ridge_m_iterates_and_stopping_rule_follow_eq_12() {
    let (u, y) = plant_record(3, 1500, 0.3);
    let nrm = normal(&u, &y);
    let sys = nrm
        .system(Structure::new(2, 3, 1).unwrap(), Offset::None)
        .unwrap();
    let n = sys.params();
    let m = common::augmented(&sys, &u, &y);
    let (gamma, beta) = (1000.0, 0.01);
    let a = m.view((0, 0), (n, n)).into_owned() + DMatrix::identity(n, n) * gamma;
    let b: DVector<f64> = m.view((0, n), (n, 1)).column(0).into_owned();
    let lu = a.lu();
    // Reference: Algorithm 1 written directly with a dense solve.
    let mut v = DVector::zeros(n);
    let mut w_prev = DVector::zeros(n);
    let mut iterates = Vec::new();
    let mut steps = Vec::new();
    for _ in 0..400 {
        let w = lu.solve(&(&b + &v * gamma)).unwrap();
        steps.push((&w - &w_prev).norm());
        v = &v * beta + &w * (1.0 - beta);
        iterates.push(w.clone());
        w_prev = w;
    }
    // Every iterate matches.
    let mut k_seen = 0;
    let (_, used) = RidgeM {
        gamma,
        beta,
        tol: 0.0,
        max_iter: 60,
    }
    .iterate(&sys, |k, w| {
        k_seen = k;
        let got: Vec<f64> = w.to_vec();
        let want = &iterates[k as usize - 1];
        let want: Vec<f64> = want.iter().copied().collect();
        assert!(max_diff(&got, &want) < 1e-9, "iterate {k}");
    })
    .unwrap();
    assert_eq!((used, k_seen), (60, 60), "tol = 0 runs to max_iter");
    // A tolerance between two consecutive reference steps stops exactly there.
    let k = 37;
    assert!(steps[k - 1] > steps[k] * 1.01);
    let tol = (steps[k - 1] * steps[k]).sqrt();
    let fit = RidgeM {
        gamma,
        beta,
        tol,
        max_iter: 400,
    }
    .fit(&sys)
    .unwrap();
    assert_eq!(fit.iterations, k as u32 + 1);
    // A huge tolerance stops after the first iterate (plain Ridge).
    let one = RidgeM {
        gamma,
        beta,
        tol: 1e12,
        max_iter: 400,
    }
    .fit(&sys)
    .unwrap();
    assert_eq!(one.iterations, 1);
}

#[test]
fn ridge_m_rejects_bad_hyper_parameters() {
    let (u, y) = plant_record(4, 500, 0.3);
    let nrm = normal(&u, &y);
    let sys = nrm
        .system(Structure::new(1, 1, 0).unwrap(), Offset::None)
        .unwrap();
    for bad in [
        RidgeM {
            gamma: 0.0,
            ..RidgeM::default()
        },
        RidgeM {
            gamma: -1.0,
            ..RidgeM::default()
        },
        RidgeM {
            gamma: f64::NAN,
            ..RidgeM::default()
        },
        RidgeM {
            beta: 1.0,
            ..RidgeM::default()
        },
        RidgeM {
            beta: -0.1,
            ..RidgeM::default()
        },
        RidgeM {
            tol: f64::INFINITY,
            ..RidgeM::default()
        },
        RidgeM {
            max_iter: 0,
            ..RidgeM::default()
        },
    ] {
        assert_eq!(bad.fit(&sys), Err(Error::InvalidParameter), "{bad:?}");
    }
    assert_eq!(Ridge { gamma: 0.0 }.fit(&sys), Err(Error::InvalidParameter));
}

#[test]
fn rls_without_forgetting_converges_to_least_squares() {
    let (u, y) = plant_record(5, 3000, 0.3);
    let s = Structure::new(2, 2, 2).unwrap();
    for offset in [Offset::None, Offset::Intercept] {
        let nrm = normal(&u, &y);
        let sys = nrm.system(s, offset).unwrap();
        let ols = ridge_reference(&sys, &u, &y, 0.0);
        let mut rls = Rls::new(s, offset, 1.0, 1e8).unwrap();
        for (&a, &b) in u.iter().zip(&y) {
            rls.update(a, b).unwrap();
        }
        let got = common::internal(&sys, &rls.model());
        // P₀ = δI is a prior of weight 1/δ: the gap to least squares is O(1/δ).
        assert!(
            max_diff(&got, ols.as_slice()) < 1e-4,
            "{offset:?} {got:?} vs {ols}"
        );
    }
}

#[test]
fn rls_with_forgetting_tracks_a_changed_plant() {
    let mut rng = Rng::new(6);
    let u = multilevel(&mut rng, 4000, -1.0, 1.0, 5);
    let y1 = simulate(&[0.5], &[1.0], 0, 0.0, &u[..2000], 0.01, 7);
    let y2 = simulate(&[0.5], &[2.0], 0, 0.0, &u[2000..], 0.01, 8);
    let s = Structure::new(1, 1, 0).unwrap();
    let mut forget = Rls::new(s, Offset::None, 0.98, 1e3).unwrap();
    let mut plain = Rls::new(s, Offset::None, 1.0, 1e3).unwrap();
    for (&a, &b) in u.iter().zip(y1.iter().chain(&y2)) {
        forget.update(a, b).unwrap();
        plain.update(a, b).unwrap();
    }
    assert!((forget.model().phi()[0] - 2.0).abs() < 0.05);
    assert!(
        (plain.model().phi()[0] - 2.0).abs() > 0.2,
        "no forgetting averages both"
    );
    assert_eq!(forget.update(f64::NAN, 1.0), Err(Error::NonFinite));
    assert_eq!(forget.samples(), 4000);
    assert_eq!(
        Rls::new(s, Offset::None, 0.0, 1.0).err(),
        Some(Error::InvalidParameter)
    );
    assert_eq!(
        Rls::new(s, Offset::None, 1.0, 0.0).err(),
        Some(Error::InvalidParameter)
    );
}

#[test]
fn adaptive_lasso_zeroes_irrelevant_lags() {
    let mut rng = Rng::new(9);
    let u = multilevel(&mut rng, 3000, -1.0, 1.0, 6);
    let y = simulate(&[0.7], &[1.0, 0.5], 0, 0.0, &u, 0.05, 10);
    let nrm = normal(&u, &y);
    let sys = nrm
        .system(Structure::new(4, 5, 0).unwrap(), Offset::None)
        .unwrap();
    let fit = AdaptiveLasso::<f64>::default().fit(&sys).unwrap();
    let m = fit.model();
    assert!((m.theta()[0] - 0.7).abs() < 0.02, "{:?}", m.theta());
    assert!((m.phi()[0] - 1.0).abs() < 0.02 && (m.phi()[1] - 0.5).abs() < 0.03);
    assert_eq!(
        &m.theta()[1..],
        &[0.0; 3],
        "irrelevant output lags are exactly zero"
    );
    assert_eq!(
        &m.phi()[2..],
        &[0.0; 3],
        "irrelevant input lags are exactly zero"
    );
    // With λ = 0 it is least squares (no zeros).
    let free = AdaptiveLasso {
        lambda: Lambda::Fixed(0.0),
        ..AdaptiveLasso::default()
    }
    .fit(&sys)
    .unwrap();
    let ols = Ols.fit(&sys).unwrap();
    let (a, b) = (
        common::internal(&sys, &free.model()),
        common::internal(&sys, &ols.model()),
    );
    assert!(max_diff(&a, &b) < 1e-5, "{a:?} vs {b:?}");
    let bad = AdaptiveLasso {
        lambda: Lambda::Fixed(-1.0),
        ..AdaptiveLasso::<f64>::default()
    };
    assert_eq!(bad.fit(&sys), Err(Error::InvalidParameter));
}

#[test]
fn intercept_absorbs_an_offset() {
    let mut rng = Rng::new(11);
    let u = multilevel(&mut rng, 3000, 0.2, 0.9, 10);
    let y = simulate(&[0.6], &[10.0], 1, -2.5, &u, 0.05, 12);
    let n = normal(&u, &y);
    let s = Structure::new(1, 1, 1).unwrap();
    let with = Ols.fit(&n.system(s, Offset::Intercept).unwrap()).unwrap();
    let without = Ols.fit(&n.system(s, Offset::None).unwrap()).unwrap();
    assert!((with.model().intercept() + 2.5).abs() < 0.05);
    assert!((with.model().phi()[0] - 10.0).abs() < 0.1);
    assert_eq!(without.model().intercept(), 0.0);
    assert!(with.rss < 0.5 * without.rss);
    // Ridge does not shrink the intercept: with huge γ the model is the mean.
    let flat = Ridge { gamma: 1e12 }
        .fit(&n.system(s, Offset::Intercept).unwrap())
        .unwrap();
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    assert!((flat.model().intercept() - mean).abs() < 1e-3 * mean.abs());
}

/// Algorithm 1 (eq. 9–12) as written, in `f64` with a dense LU solve on the explicit regression
/// matrix (no intercept regularised): the last iterate, the number of iterates and every step.
fn algorithm_1(
    sys: &System<f64>,
    u: &[f64],
    y: &[f64],
    rm: &RidgeM<f64>,
) -> (Vec<f64>, u32, Vec<f64>) {
    let n = sys.params();
    let m = common::augmented(sys, u, y);
    let d = DVector::from_fn(n, |i, _| {
        if sys.regressor(i) == Some(ridge_core::Regressor::Constant) {
            0.0
        } else {
            1.0
        }
    });
    let a = m.view((0, 0), (n, n)).into_owned() + DMatrix::from_diagonal(&d) * rm.gamma;
    let b: DVector<f64> = m.view((0, n), (n, 1)).column(0).into_owned();
    let lu = a.lu();
    let (mut v, mut w_prev) = (DVector::zeros(n), DVector::zeros(n));
    let mut steps = Vec::new();
    for k in 1..=rm.max_iter {
        let w = lu.solve(&(&b + d.component_mul(&v) * rm.gamma)).unwrap();
        steps.push((&w - &w_prev).norm());
        v = &v * rm.beta + &w * (1.0 - rm.beta);
        if steps[k as usize - 1] < rm.tol || k == rm.max_iter {
            return (w.iter().copied().collect(), k, steps);
        }
        w_prev = w;
    }
    unreachable!()
}

/// The largest `|a − b| / max(1, |b|)`.
fn coef_error(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / y.abs().max(1.0))
        .fold(0.0, f64::max)
}

#[test]
fn ridge_m_fit_is_algorithm_1_with_and_without_intercept() {
    // A known plant with an offset; structures from the smallest to the largest (12 columns).
    let mut rng = Rng::new(21);
    let u = multilevel(&mut rng, 2500, 0.2, 0.9, 12);
    let y = simulate(&[1.3, -0.42], &[6.0, 3.0], 2, 2.5, &u, 0.3, 22);
    let n64 = normal(&u, &y);
    let mut g32 = FloatGram::new();
    for (&a, &b) in u.iter().zip(&y) {
        g32.push(a, b).unwrap();
    }
    let n32 = g32.normal::<f32>(Scale::UNIT).unwrap();
    let mut worst32 = 0.0f64;
    for offset in [Offset::None, Offset::Intercept] {
        for (p, q, d) in [(1, 1, 2), (2, 3, 1), (4, 6, 3), (6, 6, 0)] {
            let s = Structure::new(p, q, d).unwrap();
            let sys = n64.system(s, offset).unwrap();
            let default = RidgeM::default();
            let (_, _, steps) = algorithm_1(
                &sys,
                &u,
                &y,
                &RidgeM {
                    tol: 0.0,
                    ..default
                },
            );
            // The default tolerance, and two between consecutive steps of the reference.
            let mut tols = vec![default.tol];
            for k in [20, 60] {
                tols.push((steps[k - 1] * steps[k]).sqrt());
            }
            for tol in tols {
                let rm = RidgeM { tol, ..default };
                let (want, k, _) = algorithm_1(&sys, &u, &y, &rm);
                let fit = rm.fit(&sys).unwrap();
                let label = format!("{s:?} {offset:?} ε {tol:e}");
                assert_eq!(fit.iterations, k, "{label}");
                let got = common::internal(&sys, &fit.model());
                assert!(
                    coef_error(&got, &want) < 1e-9,
                    "{label}: {got:?} vs {want:?}"
                );
                // f32: the same count, coefficients close (float statistics of unit-scale
                // signals, the hardest case for f32).
                let rm32 = RidgeM {
                    tol: tol as f32,
                    ..RidgeM::default()
                };
                let sys32 = n32.system(s, offset).unwrap();
                let fit32 = rm32.fit(&sys32).unwrap();
                assert_eq!(fit32.iterations, k, "f32 {label}");
                let m32 = fit32.model();
                let got32: Vec<f64> = (0..sys.params())
                    .map(|i| match sys.regressor(i).unwrap() {
                        ridge_core::Regressor::Output(k) => f64::from(m32.theta()[k as usize - 1]),
                        ridge_core::Regressor::Input(k) => f64::from(m32.phi()[(k - d) as usize]),
                        ridge_core::Regressor::Constant => f64::from(m32.intercept()),
                    })
                    .collect();
                worst32 = worst32.max(coef_error(&got32, &want));
            }
        }
    }
    // Measured 3.4e-5: within the devices' 1e-4 (simavr tests' host rerun tolerance).
    assert!(worst32 < 1e-4, "f32 against Algorithm 1: {worst32:.1e}");
}

#[test]
fn ridge_m_fit_in_gives_back_the_least_squares_factor_and_reports_progress() {
    let (u, y) = plant_record(23, 1500, 0.3);
    let nrm = normal(&u, &y);
    for offset in [Offset::None, Offset::Intercept] {
        let sys = nrm
            .system(Structure::new(6, 6, 1).unwrap(), offset)
            .unwrap();
        let fresh = sys.factor(0.0).unwrap();
        let mut ls = fresh.clone();
        let mut scratch = ridge_core::Factor::empty();
        let mut calls = 0u32;
        let rm = RidgeM::default();
        let fit = rm
            .fit_in(&sys, &mut ls, &mut scratch, || calls += 1)
            .unwrap();
        // Factored again (what the factors say; storage past them is work space).
        let ridge = sys.factor(rm.gamma).unwrap();
        for (got, want) in [(&ls, &fresh), (&scratch, &ridge)] {
            assert_eq!(got.params(), want.params());
            assert_eq!(got.solution(), want.solution());
            assert_eq!(got.rss_min(), want.rss_min());
            let w = [0.5; 13];
            assert_eq!(got.excess(&w), want.excess(&w));
        }
        assert_eq!(fit, rm.fit(&sys).unwrap());
        // Factorisations, rotations and one call per iterate.
        assert!(calls > fit.iterations + 3, "{calls}");
    }
}
