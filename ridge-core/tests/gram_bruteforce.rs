//! The Gram's sub-blocks equal XᵀX, Xᵀy, yᵀy of the explicit zero-padded matrix of
//! eq. (6), for random records and every structure of the grid (property test).
mod common;

use proptest::prelude::*;
use ridge_core::{Error, FloatGram, Grid, IntGram, Normal, Offset, Scale};

fn check_all(normal: &Normal<f64>, u: &[f64], y: &[f64]) -> Result<(), TestCaseError> {
    for s in Grid::default().iter() {
        for offset in [Offset::None, Offset::Intercept] {
            let needed = s.seed_len() + s.params(offset) + 1;
            match normal.system(s, offset) {
                Err(Error::TooShort { needed: nd, have }) => {
                    prop_assert_eq!(nd as usize, needed);
                    prop_assert_eq!(have as usize, u.len());
                    prop_assert!(u.len() < needed);
                }
                Err(e) => return Err(TestCaseError::fail(format!("{s:?}: {e}"))),
                Ok(sys) => {
                    prop_assert!(u.len() >= needed);
                    let reference = common::augmented(&sys, u, y);
                    let n = sys.params();
                    for i in 0..=n {
                        for j in 0..=n {
                            let want = reference[(i, j)];
                            let got = sys.augmented(i, j);
                            let tol =
                                1e-9 * (reference[(i, i)] * reference[(j, j)]).sqrt().max(1.0);
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
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn integer_gram_matches_explicit_matrix(
        data in prop::collection::vec((-3000i32..3000, -30000i32..30000), 2..70),
        su in 1e-4f64..1.0,
        sy in 1e-3f64..1.0,
    ) {
        let mut g = IntGram::new();
        for &(u, y) in &data {
            g.push(u, y).unwrap();
        }
        let u: Vec<f64> = data.iter().map(|d| d.0 as f64 * su).collect();
        let y: Vec<f64> = data.iter().map(|d| d.1 as f64 * sy).collect();
        match g.normal::<f64>(Scale { u: su, y: sy }) {
            Ok(n) => check_all(&n, &u, &y)?,
            // Constant columns: the only other legitimate outcome.
            Err(Error::NotExcited) => {
                let const_u = data.iter().all(|d| d.0 == data[0].0);
                let const_y = data.iter().all(|d| d.1 == data[0].1);
                let zero_lag = data[..data.len() - 1].iter().all(|d| d.1 == 0);
                prop_assert!(const_u || const_y || zero_lag);
            }
            Err(e) => return Err(TestCaseError::fail(format!("{e}"))),
        }
    }

    #[test]
    fn float_gram_matches_explicit_matrix(
        data in prop::collection::vec((-5.0f64..5.0, -50.0f64..50.0), 2..70),
    ) {
        let mut g = FloatGram::new();
        for &(u, y) in &data {
            g.push(u, y).unwrap();
        }
        let u: Vec<f64> = data.iter().map(|d| d.0).collect();
        let y: Vec<f64> = data.iter().map(|d| d.1).collect();
        let n = g.normal::<f64>(Scale::UNIT).unwrap();
        check_all(&n, &u, &y)?;
    }
}

#[test]
fn long_record_with_large_offsets_is_exact() {
    // SFM3300-like counts with a large mean: the regime where float accumulation fails.
    let mut rng = common::Rng::new(7);
    let mut g = IntGram::new();
    let (mut u, mut y) = (Vec::new(), Vec::new());
    for _ in 0..5000 {
        let ui = rng.range_i32(2000, 9000);
        let yi = rng.range_i32(3000, 12000);
        g.push(ui, yi).unwrap();
        u.push(ui as f64);
        y.push(yi as f64);
    }
    let normal = g.normal::<f64>(Scale::UNIT).unwrap();
    for s in [
        ridge_core::Structure::new(6, 6, 6).unwrap(),
        ridge_core::Structure::new(1, 1, 0).unwrap(),
        ridge_core::Structure::new(3, 2, 4).unwrap(),
    ] {
        let sys = normal.system(s, Offset::Intercept).unwrap();
        let reference = common::augmented(&sys, &u, &y);
        for i in 0..=sys.params() {
            for j in 0..=sys.params() {
                let want = reference[(i, j)];
                assert!((sys.augmented(i, j) - want).abs() <= 1e-12 * want.abs().max(1.0));
            }
        }
    }
}
