//! The one name table of each enum: `name()` and `FromStr` agree on every variant, unknown
//! names are refused with the list of the accepted ones.

use core::str::FromStr;

use ridge_core::{Criterion, MethodKind, Offset, UnknownName};

fn round_trip<T>(all: &[T], name: fn(T) -> &'static str)
where
    T: Copy + PartialEq + core::fmt::Debug + FromStr<Err = UnknownName> + core::fmt::Display,
{
    let mut names: Vec<&str> = Vec::new();
    for &v in all {
        assert_eq!(name(v).parse::<T>(), Ok(v));
        assert_eq!(v.to_string(), name(v));
        assert!(!names.contains(&name(v)), "duplicate name {}", name(v));
        names.push(name(v));
    }
    let err = "no-such-name".parse::<T>().unwrap_err();
    assert_eq!(err.expected, names.as_slice());
}

#[test]
fn names_round_trip() {
    round_trip(&Criterion::ALL, Criterion::name);
    round_trip(&Offset::ALL, Offset::name);
    round_trip(&MethodKind::ALL, MethodKind::name);
}

#[test]
fn unknown_names_list_the_accepted_ones() {
    let e = "AIC".parse::<Criterion>().unwrap_err();
    assert_eq!(
        e.to_string(),
        "unknown criterion (expected paper, aic, bic or validation)"
    );
    assert_eq!(
        "x".parse::<Offset>().unwrap_err().to_string(),
        "unknown offset (expected none or intercept)"
    );
    assert_eq!(
        "".parse::<MethodKind>().unwrap_err().to_string(),
        "unknown method (expected ridge-m, ridge, ols, rls or alasso)"
    );
}

#[test]
fn criterion_values_follow_their_formulas() {
    use ridge_core::Structure;
    let s = Structure::new(2, 3, 4).unwrap();
    let (rss, n, alpha) = (50.0f64, 1000u32, 12.0);
    let fit = 1000.0 * (50.0f64 / 1000.0).ln();
    let v = |c: Criterion, o| c.value(alpha, rss, n, s, o);
    assert_eq!(v(Criterion::Aic, Offset::None), fit + 12.0 * 5.0);
    assert_eq!(v(Criterion::Aic, Offset::Intercept), fit + 12.0 * 6.0);
    assert_eq!(v(Criterion::Paper, Offset::None), fit + 12.0 * 9.0);
    assert_eq!(v(Criterion::Bic, Offset::None), fit + 1000f64.ln() * 5.0);
    assert_eq!(v(Criterion::Validation, Offset::Intercept), fit);
}

/// The grid's iterator visits exactly `Grid::get(0..len)`, in that order, for every grid of
/// the maxima (and none for an empty one).
#[test]
fn grid_iteration_is_the_indexed_order() {
    use ridge_core::{Grid, OrderRange, D_MAX, P_MAX, Q_MAX};
    let mut grids = 0;
    for (p0, p1) in [(1, 1), (1, 6), (2, 4), (6, 6), (3, 2)] {
        for (q0, q1) in [(1, 1), (1, 6), (3, 5)] {
            for (d0, d1) in [(0, 0), (0, 6), (2, 3), (5, 4)] {
                let g = Grid {
                    p: OrderRange::new(p0, p1),
                    q: OrderRange::new(q0, q1),
                    d: OrderRange::new(d0, d1),
                };
                let indexed: Vec<_> = (0..g.len()).map(|i| g.get(i).unwrap()).collect();
                let iterated: Vec<_> = g.iter().collect();
                assert_eq!(iterated, indexed, "{g:?}");
                grids += 1;
            }
        }
    }
    assert_eq!(grids, 60);
    assert_eq!(Grid::PAPER.iter().count(), P_MAX * Q_MAX * (D_MAX + 1));
}
