//! [`MeasuredGram`]: the statistics from measured initial conditions equal `XᵀX`, `Xᵀy`,
//! `yᵀy` of the explicit regression matrix whose rows are `t = m+1..N` with every lag read
//! from the record (no zero padding), for random records, every structure of the grid and
//! both accumulators; `m = 0` is the zero-history [`Gram`].
mod common;

use nalgebra::DMatrix;
use proptest::prelude::*;
use ridge_core::{
    Error, FloatGram, Grid, IntGram, MeasuredGram, Normal, Offset, Regressor, Scale, System,
};

/// Rows `t = m..N` (0-based) of the regression of `system`, lags read from the record.
fn measured_design(system: &System<f64>, u: &[f64], y: &[f64], m: usize) -> DMatrix<f64> {
    let n = system.params();
    DMatrix::from_fn(u.len() - m, n + 1, |r, col| {
        let t = r + m;
        match system.regressor(col).unwrap() {
            Regressor::Output(k) => y[t - k as usize],
            Regressor::Input(k) => u[t - k as usize],
            Regressor::Constant => 1.0,
        }
    })
}

fn check_all(normal: &Normal<f64>, u: &[f64], y: &[f64], m: usize) -> Result<(), TestCaseError> {
    prop_assert_eq!(normal.samples() as usize, u.len() - m);
    for s in Grid::default().iter() {
        for offset in [Offset::None, Offset::Intercept] {
            let Ok(sys) = normal.system(s, offset) else {
                prop_assert!(u.len() - m < s.seed_len() + s.params(offset) + 1);
                continue;
            };
            let x = measured_design(&sys, u, y, m);
            let reference = x.transpose() * &x;
            let n = sys.params();
            for i in 0..=n {
                for j in 0..=n {
                    let want = reference[(i, j)];
                    let got = sys.augmented(i, j);
                    let tol = 1e-9 * (reference[(i, i)] * reference[(j, j)]).sqrt().max(1.0);
                    prop_assert!(
                        (got - want).abs() <= tol,
                        "{:?} {:?} ({},{}): {} vs {}",
                        s,
                        offset,
                        i,
                        j,
                        got,
                        want
                    );
                }
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn integer_statistics_match_the_explicit_matrix(
        data in prop::collection::vec((-3000i32..3000, -30000i32..30000), 14..70),
        offset in -20000i32..20000,
    ) {
        let m = Grid::default().longest_lag();
        let mut g = MeasuredGram::<i64>::new(m as u32);
        for &(u, y) in &data {
            g.push(u, y.saturating_add(offset)).unwrap();
        }
        let u: Vec<f64> = data.iter().map(|d| d.0 as f64).collect();
        let y: Vec<f64> = data.iter().map(|d| d.1.saturating_add(offset) as f64).collect();
        match g.normal::<f64>(Scale::UNIT) {
            Ok(n) => check_all(&n, &u, &y, m)?,
            Err(Error::NotExcited) => {
                let const_u = u[m..].iter().all(|v| *v == u[m]);
                let const_y = y[m..].iter().all(|v| *v == y[m]);
                let zero_lag = y[m - 1..y.len() - 1].iter().all(|v| *v == 0.0);
                prop_assert!(const_u || const_y || zero_lag);
            }
            Err(e) => return Err(TestCaseError::fail(format!("{e}"))),
        }
    }

    #[test]
    fn float_statistics_match_the_explicit_matrix(
        data in prop::collection::vec((-5.0f64..5.0, -50.0f64..50.0), 14..70),
        m in 0usize..=12,
    ) {
        let mut g = MeasuredGram::<f64>::new(m as u32);
        for &(u, y) in &data {
            g.push(u, y + 100.0).unwrap();
        }
        let u: Vec<f64> = data.iter().map(|d| d.0).collect();
        let y: Vec<f64> = data.iter().map(|d| d.1 + 100.0).collect();
        let normal = g.normal::<f64>(Scale::UNIT).unwrap();
        // Structures whose lags reach before the record's start (lag > m) are not compared:
        // their first rows would read samples before t = 0.
        prop_assert_eq!(normal.samples() as usize, u.len() - m);
        for s in Grid::default().iter().filter(|s| s.seed_len() <= m) {
            let Ok(sys) = normal.system(s, Offset::Intercept) else { continue };
            let x = measured_design(&sys, &u, &y, m);
            let reference = x.transpose() * &x;
            for i in 0..=sys.params() {
                for j in 0..=sys.params() {
                    let want = reference[(i, j)];
                    let tol = 1e-9 * (reference[(i, i)] * reference[(j, j)]).sqrt().max(1.0);
                    prop_assert!((sys.augmented(i, j) - want).abs() <= tol);
                }
            }
        }
    }
}

#[test]
fn no_initial_samples_is_the_zero_history_gram() {
    let mut rng = common::Rng::new(3);
    let (mut a, mut b) = (IntGram::new(), MeasuredGram::<i64>::new(0));
    let (mut fa, mut fb) = (FloatGram::new(), MeasuredGram::<f64>::new(0));
    for _ in 0..500 {
        let (u, y) = (rng.range_i32(-900, 900), rng.range_i32(1000, 9000));
        a.push(u, y).unwrap();
        b.push(u, y).unwrap();
        fa.push(f64::from(u) * 0.1, f64::from(y) * 0.01).unwrap();
        fb.push(f64::from(u) * 0.1, f64::from(y) * 0.01).unwrap();
    }
    let scale = Scale { u: 0.1, y: 0.01 };
    assert_eq!(a.normal::<f64>(scale), b.normal::<f64>(scale));
    assert_eq!(a.normal::<f32>(scale), b.normal::<f32>(scale));
    assert_eq!(fa.normal::<f64>(Scale::UNIT), fb.normal::<f64>(Scale::UNIT));
}

#[test]
fn too_few_rows_and_constant_rows_are_errors() {
    let mut g = MeasuredGram::<i64>::new(11);
    for t in 0..12 {
        g.push(t, 3 * t).unwrap();
    }
    assert_eq!(g.rows(), 1);
    assert_eq!(g.len(), 12);
    assert!(matches!(
        g.normal::<f32>(Scale::UNIT),
        Err(Error::TooShort { needed: 2, have: 1 })
    ));
    // Varying only in the initial samples: constant over the rows.
    let mut g = MeasuredGram::<f64>::new(4);
    for t in 0..40 {
        let u = if t < 4 { f64::from(t) } else { 1.0 };
        g.push(u, f64::from(t)).unwrap();
    }
    assert_eq!(g.normal::<f64>(Scale::UNIT), Err(Error::NotExcited));
}
