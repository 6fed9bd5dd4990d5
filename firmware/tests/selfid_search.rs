//! The watchdog hook of the structure search the state machine runs
//! (`ridge_core::Search::run_with_progress`): identical results to `Search::run`, bit for bit,
//! and bounded work between two `pet` calls (operation counts for the ATmega2560 estimate).

use std::cell::Cell;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use ridge_core::{
    AdaptiveLasso, Criterion, Error, Grid, IntGram, Method, Normal, Offset, OrderRange, Real,
    Ridge, RidgeM, Search,
};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::SCALE;

/// What the tests compare of a search result.
#[derive(Debug)]
struct Found<T: Real> {
    model: ridge_core::ArxModel<T>,
    score: T,
    rss: T,
    iterations: u32,
    candidates: u16,
    evaluated: u16,
    skipped: u16,
}

/// The search as the state machine runs it, with `pet` as the progress hook.
fn search_with_pet<T: Real>(
    search: &Search<T>,
    est: &Normal<T>,
    pet: &mut impl FnMut(),
) -> Result<Found<T>, Error> {
    let s = search.run_with_progress(est, None, pet)?;
    Ok(Found {
        model: s.fit.model(),
        score: s.score,
        rss: s.fit.rss,
        iterations: s.fit.iterations,
        candidates: s.candidates,
        evaluated: s.evaluated,
        skipped: s.skipped,
    })
}

/// A record of an ARX plant with white equation noise, as deviations in integer counts
/// (duty 1/10 000 around 30 %, flow 1/120 slm).
fn record(theta: &[f64], phi: &[f64], d: usize, noise: f64, seed: u64, rec: Record) -> IntGram {
    let mut rng = seed | 1;
    let mut next = || {
        // Sum of 4 uniforms: roughly normal, σ = 1.
        let mut s = 0.0;
        for _ in 0..4 {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            s += (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        }
        s * 3f64.sqrt()
    };
    let u: Vec<f64> = rec
        .generator()
        .map(|d| (f64::from(d) - 3000.0) / 10_000.0)
        .collect();
    let mut y: Vec<f64> = Vec::new();
    let mut gram = IntGram::new();
    for t in 0..u.len() {
        let mut v = noise * next();
        for (i, th) in theta.iter().enumerate() {
            if t > i {
                v += th * y[t - 1 - i];
            }
        }
        for (j, ph) in phi.iter().enumerate() {
            if t >= d + j {
                v += ph * u[t - d - j];
            }
        }
        y.push(v);
        let counts = (v * 120.0).round() as i32;
        let duty = (u[t] * 10_000.0).round() as i32;
        gram.push(duty, counts).unwrap();
    }
    gram
}

fn records() -> Vec<IntGram> {
    vec![
        record(&[0.9], &[10.0], 3, 0.05, 1, Record::AMultistep),
        record(&[1.5, -0.56], &[4.0, 2.0], 2, 0.3, 2, Record::AMultistep),
        record(&[0.8, 0.1], &[2.0, 3.0, 1.0], 5, 1.0, 3, Record::Prbs),
        record(&[0.95], &[5.0], 0, 2.0, 4, Record::ARamp),
        record(&[0.6, 0.2, 0.1], &[8.0], 1, 0.5, 5, Record::BMultistep),
    ]
}

fn searches<T: Real>() -> Vec<Search<T>> {
    let mut out = Vec::new();
    for criterion in [Criterion::Aic, Criterion::Paper, Criterion::Bic] {
        for offset in [Offset::None, Offset::Intercept] {
            for prune in [true, false] {
                out.push(Search {
                    criterion,
                    offset,
                    prune,
                    ..Search::default()
                });
            }
        }
    }
    for method in [
        Method::Ols,
        Method::Ridge(Ridge::default()),
        Method::AdaptiveLasso(AdaptiveLasso::default()),
        Method::RidgeM(RidgeM {
            max_iter: 50,
            ..RidgeM::default()
        }),
    ] {
        out.push(Search {
            method,
            ..Search::default()
        });
    }
    out.push(Search {
        grid: Grid {
            p: OrderRange::new(2, 3),
            q: OrderRange::new(1, 4),
            d: OrderRange::new(1, 5),
        },
        alpha: T::from_f64(2.0),
        ..Search::default()
    });
    out
}

fn check_same<T: Real>(normal: &Normal<T>, search: &Search<T>) {
    let mut pets = 0usize;
    let mine = search_with_pet(search, normal, &mut || pets += 1);
    let core = search.run(normal, None);
    match (mine, core) {
        (Ok(m), Ok(c)) => {
            assert_eq!(m.model, c.fit.model(), "{search:?}");
            assert_eq!(m.model.structure(), c.structure());
            assert_eq!(m.score.to_f64().to_bits(), c.score.to_f64().to_bits());
            assert_eq!(m.rss.to_f64().to_bits(), c.fit.rss.to_f64().to_bits());
            assert_eq!(m.iterations, c.fit.iterations);
            assert_eq!(
                (m.candidates, m.evaluated, m.skipped),
                (c.candidates, c.evaluated, c.skipped),
                "{search:?}"
            );
            // The watchdog is fed at least once per group of bounds (one elimination per p,
            // one small factorisation per (p, d); one bound per candidate for the validation
            // criterion).
            let g = search.grid;
            let (np, nd) = (
                usize::from(g.p.max - g.p.min) + 1,
                usize::from(g.d.max - g.d.min) + 1,
            );
            let groups = match search.criterion {
                Criterion::Validation => usize::from(m.candidates),
                _ => np * (nd + 1),
            };
            assert!(pets >= groups, "{pets}");
        }
        (Err(a), Err(b)) => assert_eq!(a, b),
        (a, b) => panic!("{a:?} vs {b:?}"),
    }
}

#[test]
fn identical_to_ridge_core_search_in_f32_and_f64() {
    for gram in records() {
        let n32 = gram.normal::<f32>(SCALE).unwrap();
        let n64 = gram.normal::<f64>(SCALE).unwrap();
        for s in searches::<f32>() {
            check_same(&n32, &s);
        }
        for s in searches::<f64>() {
            check_same(&n64, &s);
        }
    }
}

#[test]
fn bad_configurations_fail_like_ridge_core() {
    let gram = &records()[0];
    let n = gram.normal::<f32>(SCALE).unwrap();
    let bad = [
        Search {
            criterion: Criterion::Validation,
            ..Search::default()
        },
        Search {
            alpha: f32::NAN,
            ..Search::default()
        },
        Search {
            grid: Grid {
                p: OrderRange::new(0, 3),
                ..Grid::default()
            },
            ..Search::default()
        },
        Search {
            method: Method::RidgeM(RidgeM {
                beta: 1.5,
                ..RidgeM::default()
            }),
            ..Search::default()
        },
    ];
    for s in bad {
        let mine = search_with_pet(&s, &n, &mut || {});
        assert!(mine.is_err(), "{s:?}");
        assert_eq!(mine.err(), s.run(&n, None).err(), "{s:?}");
    }
    // A record too short for every candidate (the smallest needs 4 samples).
    let mut short = IntGram::new();
    for t in 0..3 {
        short.push(t * 100, (t * t) % 7).unwrap();
    }
    let n = short.normal::<f32>(SCALE).unwrap();
    let s = Search::<f32>::default();
    assert_eq!(
        search_with_pet(&s, &n, &mut || {}).err(),
        Some(Error::NoCandidate)
    );
    assert_eq!(s.run(&n, None).err(), Some(Error::NoCandidate));
}

// ---------------------------------------------------------------------------------------
// Operation counts between two pets (for the ATmega2560 time estimate).
// ---------------------------------------------------------------------------------------

thread_local! {
    static OPS: Cell<[u64; 5]> = const { Cell::new([0; 5]) };
}
const ADD: usize = 0;
const MUL: usize = 1;
const DIV: usize = 2;
const SQRT: usize = 3;
const LN: usize = 4;

fn count(kind: usize) {
    OPS.with(|c| {
        let mut v = c.get();
        v[kind] += 1;
        c.set(v);
    });
}

fn ops() -> [u64; 5] {
    OPS.with(Cell::get)
}

/// avr-libc cycle costs per operation (add/sub ~100, mul ~130, div ~480, sqrt ~490,
/// log ~3000); a multiply-add is ~230, the ~200 the team uses.
fn cycles(o: [u64; 5]) -> u64 {
    o[ADD] * 100 + o[MUL] * 130 + o[DIV] * 480 + o[SQRT] * 490 + o[LN] * 3000
}

/// An `f32` that counts its arithmetic.
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
struct C(f32);

macro_rules! op {
    ($tr:ident, $f:ident, $kind:expr, $o:tt) => {
        impl $tr for C {
            type Output = C;
            fn $f(self, r: C) -> C {
                count($kind);
                C(self.0 $o r.0)
            }
        }
    };
}
op!(Add, add, ADD, +);
op!(Sub, sub, ADD, -);
op!(Mul, mul, MUL, *);
op!(Div, div, DIV, /);
impl Neg for C {
    type Output = C;
    fn neg(self) -> C {
        C(-self.0)
    }
}
impl AddAssign for C {
    fn add_assign(&mut self, r: C) {
        *self = *self + r;
    }
}
impl SubAssign for C {
    fn sub_assign(&mut self, r: C) {
        *self = *self - r;
    }
}
impl MulAssign for C {
    fn mul_assign(&mut self, r: C) {
        *self = *self * r;
    }
}
impl Real for C {
    const ZERO: C = C(0.0);
    const ONE: C = C(1.0);
    const EPSILON: C = C(f32::EPSILON);
    const MAX: C = C(f32::MAX);
    fn from_f64(x: f64) -> C {
        C(x as f32)
    }
    fn from_i64(x: i64) -> C {
        C(x as f32)
    }
    fn from_u64(x: u64) -> C {
        C(x as f32)
    }
    fn to_f64(self) -> f64 {
        f64::from(self.0)
    }
    fn sqrt(self) -> C {
        count(SQRT);
        C(self.0.sqrt())
    }
    fn ln(self) -> C {
        count(LN);
        C(self.0.ln())
    }
    fn abs(self) -> C {
        C(self.0.abs())
    }
    fn is_finite(self) -> bool {
        self.0.is_finite()
    }
    fn from_u32(x: u32) -> C {
        C(x as f32)
    }
}

/// Runs `search` counting operations; returns (total cycles, largest cycles between two
/// pets, pets).
fn measure(normal: &Normal<C>, search: &Search<C>) -> (u64, u64, u64, u16) {
    let start = ops();
    let mut last = start;
    let mut worst = 0;
    let mut pets = 0;
    let found = search_with_pet(search, normal, &mut || {
        let now = ops();
        let gap: [u64; 5] = std::array::from_fn(|k| now[k] - last[k]);
        worst = worst.max(cycles(gap));
        last = now;
        pets += 1;
    })
    .unwrap();
    let end = ops();
    let total: [u64; 5] = std::array::from_fn(|k| end[k] - start[k]);
    (cycles(total), worst, pets, found.evaluated)
}

#[test]
fn work_between_two_pets_is_bounded() {
    const WATCHDOG_CYCLES: u64 = 16_000_000 / 4; // 250 ms at 16 MHz
    let mut worst_gap = 0;
    for (i, gram) in records().iter().enumerate() {
        let n = gram.normal::<C>(SCALE).unwrap();
        for (name, search) in [
            ("default", Search::<C>::default()),
            (
                "exhaustive+intercept",
                Search {
                    prune: false,
                    offset: Offset::Intercept,
                    ..Search::default()
                },
            ),
        ] {
            let (total, worst, pets, evaluated) = measure(&n, &search);
            println!(
                "record {i} {name}: evaluated {evaluated}, {pets} pets, total ≈ {:.2} s, \
                 worst gap ≈ {:.1} ms at 16 MHz",
                total as f64 / 16e6,
                worst as f64 / 16e3
            );
            worst_gap = worst_gap.max(worst);
        }
    }
    // The largest step is one 13-parameter candidate's factorisation and Ridge solution
    // (~27 ms by these costs), an order of magnitude below 250 ms.
    assert!(worst_gap < WATCHDOG_CYCLES / 4, "{worst_gap}");
}
