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

fn sub_grid() -> impl Strategy<Value = Grid> {
    let range = |lo: u8| {
        (lo..=6u8, lo..=6u8).prop_map(|(a, b)| ridge_core::OrderRange::new(a.min(b), a.max(b)))
    };
    (range(1), range(1), range(0)).prop_map(|(p, q, d)| Grid { p, q, d })
}

/// The statistics of `for_grid` against those of `new` on the same samples: every entry of
/// every structure of `grid` bit for bit, and a structure using a lag outside it not fitted.
fn same_on_grid<A: ridge_core::Accumulator>(
    full: &MeasuredGram<A>,
    window: &MeasuredGram<A>,
    grid: &Grid,
) -> Result<(), TestCaseError> {
    let (full, window) = match (
        full.normal::<f64>(Scale::UNIT),
        window.normal::<f64>(Scale::UNIT),
    ) {
        (Ok(f), Ok(w)) => (f, w),
        (f, w) => {
            prop_assert_eq!(f.err(), w.err());
            return Ok(());
        }
    };
    for s in grid.iter() {
        for offset in [Offset::None, Offset::Intercept] {
            let (f, w) = match (full.system(s, offset), window.system(s, offset)) {
                (Ok(f), Ok(w)) => (f, w),
                (f, w) => {
                    prop_assert_eq!(f.err(), w.err());
                    continue;
                }
            };
            for i in 0..=f.params() {
                for j in 0..=f.params() {
                    prop_assert_eq!(f.augmented(i, j).to_bits(), w.augmented(i, j).to_bits());
                }
            }
        }
    }
    if grid.p.max < 6 {
        let s = ridge_core::Structure::new(grid.p.max + 1, grid.q.max, grid.d.max).unwrap();
        if let Ok(sys) = window.system(s, Offset::None) {
            prop_assert_eq!(sys.factor(0.0).err(), Some(Error::NotPositiveDefinite));
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// `MeasuredGram::for_grid` (only the grid's lags) gives the statistics of `new` for
    /// every structure of the grid, exactly.
    #[test]
    fn grid_statistics_are_the_full_statistics_on_the_grid(
        data in prop::collection::vec((-3000i32..3000, -30000i32..30000), 14..90),
        grid in sub_grid(),
    ) {
        let m = grid.longest_lag() as u32;
        let (mut fi, mut wi) = (MeasuredGram::<i64>::new(m), MeasuredGram::<i64>::for_grid(m, &grid));
        let (mut ff, mut wf) = (MeasuredGram::<f64>::new(m), MeasuredGram::<f64>::for_grid(m, &grid));
        for &(u, y) in &data {
            fi.push(u, y).unwrap();
            wi.push(u, y).unwrap();
            let (u, y) = (f64::from(u) * 1e-3, f64::from(y) * 0.01 + 20.0);
            ff.push(u, y).unwrap();
            wf.push(u, y).unwrap();
        }
        same_on_grid(&fi, &wi, &grid)?;
        same_on_grid(&ff, &wf, &grid)?;
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
