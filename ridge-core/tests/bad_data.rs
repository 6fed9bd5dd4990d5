//! Bad data gives errors, never panics, and never corrupts the statistics.
mod common;

use ridge_core::{
    ArxModel, Error, Estimator, FloatGram, Grid, IntGram, Offset, OrderRange, RidgeM, Scale,
    Search, Structure,
};

fn excited_int(n: usize) -> IntGram {
    let mut rng = common::Rng::new(1);
    let mut g = IntGram::new();
    for _ in 0..n {
        g.push(rng.range_i32(1000, 9000), rng.range_i32(-500, 9000))
            .unwrap();
    }
    g
}

#[test]
fn empty_and_short_records() {
    let g = IntGram::new();
    assert!(g.is_empty());
    assert!(matches!(
        g.normal::<f32>(Scale::UNIT),
        Err(Error::TooShort { needed: 2, have: 0 })
    ));
    let g = excited_int(12);
    let n = g.normal::<f32>(Scale::UNIT).unwrap();
    // (6,6,6) needs m = 11 seed samples + 12 parameters + 1.
    let s = Structure::new(6, 6, 6).unwrap();
    assert_eq!(
        n.system(s, Offset::None).err(),
        Some(Error::TooShort {
            needed: 24,
            have: 12
        })
    );
    // A small structure fits in the same record ...
    assert!(n
        .system(Structure::new(1, 1, 0).unwrap(), Offset::None)
        .is_ok());
    // ... but with two samples nothing does: (1,1,0) needs 3.
    let two = excited_int(2).normal::<f32>(Scale::UNIT).unwrap();
    assert_eq!(
        Search::<f32>::default().run(&two, None).err(),
        Some(Error::NoCandidate)
    );
}

#[test]
fn constant_input_or_output_is_not_excited() {
    let mut g = IntGram::new();
    let mut rng = common::Rng::new(2);
    for _ in 0..500 {
        g.push(5000, rng.range_i32(0, 100)).unwrap();
    }
    assert_eq!(g.normal::<f32>(Scale::UNIT).err(), Some(Error::NotExcited));
    let mut g = FloatGram::new();
    for t in 0..500 {
        g.push((t % 7) as f64, 3.25).unwrap();
    }
    assert_eq!(g.normal::<f64>(Scale::UNIT).err(), Some(Error::NotExcited));
    let mut g = FloatGram::new();
    for t in 0..500 {
        g.push((t % 7) as f64, 0.0).unwrap();
    }
    assert_eq!(g.normal::<f64>(Scale::UNIT).err(), Some(Error::NotExcited));
}

#[test]
fn linearly_dependent_regressors_are_not_positive_definite() {
    // Noise-free ARX(1,1,0) data: in the structure (2,2,0), y_{t-1} = 0.5 y_{t-2} + u_{t-1}
    // holds on every row (zero padding included), so XᵀX is singular.
    let mut rng = common::Rng::new(4);
    let u = common::multilevel(&mut rng, 400, -1.0, 1.0, 5);
    let y = common::simulate(&[0.5], &[1.0], 0, 0.0, &u, 0.0, 0);
    let mut g = FloatGram::new();
    for (&a, &b) in u.iter().zip(&y) {
        g.push(a, b).unwrap();
    }
    let n = g.normal::<f64>(Scale::UNIT).unwrap();
    let sys = n
        .system(Structure::new(2, 2, 0).unwrap(), Offset::None)
        .unwrap();
    assert_eq!(sys.factor(0.0).err(), Some(Error::NotPositiveDefinite));
    // Ridge-M still iterates (γ > 0 makes the system definite), but a fit needs the
    // least-squares factor for its RSS and reports the dependency; the search skips it.
    assert!(RidgeM::<f64>::default().iterate(&sys, |_, _| {}).is_ok());
    assert_eq!(
        RidgeM::<f64>::default().fit(&sys).err(),
        Some(Error::NotPositiveDefinite)
    );
    let sel = Search::<f64>::default().run(&n, None).unwrap();
    assert_eq!(sel.structure(), Structure::new(1, 1, 0).unwrap());
    assert!(sel.skipped > 0);
}

#[test]
fn non_finite_samples_are_rejected_and_leave_the_statistics_unchanged() {
    let mut g = FloatGram::new();
    g.push(1.0, 2.0).unwrap();
    let before = g.clone();
    for (u, y) in [
        (f64::NAN, 1.0),
        (1.0, f64::INFINITY),
        (f64::NEG_INFINITY, 0.0),
    ] {
        assert_eq!(g.push(u, y), Err(Error::NonFinite));
        assert_eq!(g, before);
    }
    assert_eq!(g.len(), 1);
}

#[test]
fn overflow_is_reported_before_it_happens() {
    let mut g = IntGram::new();
    let mut pushed = 0u32;
    let err = loop {
        match g.push(i32::MAX, i32::MIN) {
            Ok(()) => pushed += 1,
            Err(e) => break e,
        }
        assert!(
            pushed < 10,
            "i32 extremes must overflow i64 sums within a few samples"
        );
    };
    assert_eq!(err, Error::Overflow);
    let before = g.clone();
    assert_eq!(g.push(i32::MAX, 0), Err(Error::Overflow));
    assert_eq!(g, before);
    assert_eq!(g.len(), pushed);
    // 16-bit counts (SFM3300, PWM) have room for 2^31 samples: far beyond any record.
    let mut g = IntGram::new();
    for _ in 0..100_000 {
        g.push(i32::from(i16::MAX), i32::from(i16::MIN)).unwrap();
    }
    // Float statistics: huge values are reported, not turned into ∞.
    let mut f = FloatGram::new();
    assert_eq!(f.push(1e200, 1e200), Err(Error::Overflow));
    assert!(f.is_empty());
}

#[test]
fn bad_scales_structures_grids_and_models() {
    let g = excited_int(300);
    for bad in [
        Scale {
            u: f64::NAN,
            y: 1.0,
        },
        Scale { u: 1.0, y: 0.0 },
        Scale {
            u: f64::INFINITY,
            y: 1.0,
        },
    ] {
        assert_eq!(g.normal::<f32>(bad).err(), Some(Error::NonFinite));
    }
    assert_eq!(Structure::new(0, 1, 0).err(), Some(Error::InvalidStructure));
    assert_eq!(Structure::new(1, 0, 0).err(), Some(Error::InvalidStructure));
    assert_eq!(Structure::new(7, 1, 0).err(), Some(Error::InvalidStructure));
    assert_eq!(Structure::new(1, 1, 7).err(), Some(Error::InvalidStructure));
    let n = g.normal::<f32>(Scale::UNIT).unwrap();
    let bad_struct = Structure { p: 9, q: 1, d: 0 };
    assert_eq!(
        n.system(bad_struct, Offset::None).err(),
        Some(Error::InvalidStructure)
    );
    let inverted = Grid {
        p: OrderRange::new(3, 2),
        ..Grid::default()
    };
    let s = Search::<f32> {
        grid: inverted,
        ..Search::default()
    };
    assert_eq!(s.run(&n, None).err(), Some(Error::InvalidStructure));
    let too_big = Grid {
        d: OrderRange::new(0, 9),
        ..Grid::default()
    };
    let s = Search::<f32> {
        grid: too_big,
        ..Search::default()
    };
    assert_eq!(s.run(&n, None).err(), Some(Error::InvalidStructure));
    let s = Search::<f32> {
        criterion: ridge_core::Criterion::Validation,
        ..Search::default()
    };
    assert_eq!(s.run(&n, None).err(), Some(Error::InvalidParameter));
    let s = Search::<f32> {
        alpha: f32::NAN,
        ..Search::default()
    };
    assert_eq!(s.run(&n, None).err(), Some(Error::InvalidParameter));
    assert_eq!(
        ArxModel::new(&[f64::NAN], &[1.0], 0, Offset::None, 0.0).err(),
        Some(Error::NonFinite)
    );
    assert_eq!(
        ArxModel::<f64>::new(&[], &[1.0], 0, Offset::None, 0.0).err(),
        Some(Error::InvalidStructure)
    );
    assert_eq!(
        ArxModel::new(&[0.5; 7], &[1.0], 0, Offset::None, 0.0).err(),
        Some(Error::InvalidStructure)
    );
}

#[test]
fn random_garbage_never_panics() {
    let mut rng = common::Rng::new(3);
    for case in 0..300 {
        let n = (rng.next_u64() % 80) as usize;
        let mut g = IntGram::new();
        let mut f = FloatGram::new();
        for _ in 0..n {
            let a = (rng.next_u64() as i64 >> (rng.next_u64() % 60)) as i32;
            let b = (rng.next_u64() as i64 >> (rng.next_u64() % 60)) as i32;
            let _ = g.push(a, b);
            let x = f64::from_bits(rng.next_u64());
            let _ = f.push(x, f64::from(b));
        }
        for normal in [
            g.normal::<f32>(Scale::UNIT).ok(),
            f.normal::<f32>(Scale::UNIT).ok(),
        ]
        .into_iter()
        .flatten()
        {
            let _ = Search::<f32>::default().run(&normal, Some(&normal));
            let _ = Search::<f32> {
                criterion: ridge_core::Criterion::Validation,
                ..Search::default()
            }
            .run(&normal, Some(&normal));
        }
        let _ = case;
    }
}
