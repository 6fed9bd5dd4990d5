//! The least-squares lower bounds of the pruned structure search, a group of candidates at a
//! time.
//!
//! The pruned search ([`crate::Search`]) ranks every candidate by the criterion of its
//! least-squares RSS (`ρ²` of the factor of its augmented normal equations) before it runs
//! the estimator on the best-ranked ones. Factoring each candidate on its own costs one
//! Cholesky of up to 14 rows per candidate: 252 factorisations, most of the search's time on
//! a device without a floating-point unit.
//!
//! The candidates share most of that work. In the internal column order
//! `[y_{t-1}, (1), y_{t-2} … y_{t-p}, u_{t-d} … u_{t-d-q+1}, y_t]` (see [`crate::Normal`]),
//! Cholesky's row-oriented loop computes row `i` from the rows above it only, and each entry
//! as one sequence of subtractions over the columns in order. So:
//! - the rows of the *fixed block* `(1), y_{t-2} … y_{t-p}` are the same for every `q` and
//!   `d` of one `p`;
//! - the entries of an input lag's (or the target's) row under the fixed block depend on that
//!   lag and the fixed block only, so one elimination per `p` serves every `d`
//!   ([`Nested::eliminate`]), and what those subtractions leave of each pair of input lags is
//!   kept (`P`, the partial Schur complement);
//! - the candidates `(p, 1, d) … (p, q_max, d)` are the leading blocks of one another, and
//!   the target row is computed last: one small factorisation of `P`'s block for
//!   `u_{t-d} … u_{t-d-q_max+1}, y_t` gives `ρ²` of every `q` from the running sum of the
//!   target row's squares ([`Nested::group`]).
//!
//! Every value is computed by the same operations in the same order as the candidate's own
//! factorisation ([`crate::System::factor_into`] with `γ = 0`), so the bounds, and the
//! search's ranking and pick, are bit-identical to factoring each candidate on its own
//! (tested against it on every candidate of random records). The same holds for which
//! candidates are refused: a pivot at or below the tolerance, or a non-finite entry, refuses
//! the candidates whose leading block contains that row, exactly as their own factorisation
//! would.
//!
//! Cost on the default grid: 6 eliminations and 42 factorisations of 7 rows instead of 252 of
//! up to 14 (the ATmega2560's search: see README, "Measured figures"). Memory: the two factor
//! buffers the search owns anyway (`P` and the fixed block in one, the input lags' rows and
//! the small factor in the other), nothing more on the stack.

use crate::cholesky::{packed, packed_len};
use crate::normal::{others_index, pivot_tol, Col, Factor, Normal};
use crate::real::Real;
use crate::structure::{Grid, Offset, Structure};
use crate::{L_MAX, PARAMS_MAX, P_MAX, Q_MAX};

// The buffers hold what they must for the largest grid (checked at compile time):
// the input lags' rows under the fixed block, `(L_MAX + 1) × P_MAX`, and `P`, packed
// `(L_MAX + 1)²`, each in one factor's storage.
const STORAGE: usize = packed_len(PARAMS_MAX + 1);
const _: () = assert!((L_MAX + 1) * P_MAX <= STORAGE);
const _: () = assert!(packed_len(L_MAX + 1) <= STORAGE);
const _: () = assert!(packed_len(P_MAX) <= STORAGE);
const _: () = assert!(packed_len(Q_MAX) + Q_MAX <= STORAGE);
// One bit per input lag row and the target in `Nested::bad`.
const _: () = assert!(L_MAX < 32);

/// The shared elimination of one `p` and the least-squares RSS of its candidates.
///
/// `a` and `b` are the search's two factor buffers (their factors are invalidated).
pub(crate) struct Nested<'a, T: Real> {
    normal: &'a Normal<T>,
    offset: Offset,
    /// The grid's delays and input orders.
    grid: Grid,
    /// `c` of [`Normal::trailing`] for `γ = 0`.
    c: T,
    /// The current `p` (0: none eliminated yet, or its fixed block failed).
    p: u8,
    /// Columns of the fixed block: `1 + p − 1` with an intercept, `p − 1` without.
    f: usize,
    /// Bit `r` set: input lag row `r` (or the target, the last) has a non-finite entry under
    /// the fixed block.
    bad: u32,
    /// Holds the fixed block's factor, then `P` (packed over the input lags and the target).
    /// Arrays, not slices: with a slice's length in the frame the AVR build read it wrong
    /// (a bounds check failed on the ATmega2560 that holds on the host).
    a: &'a mut [T; STORAGE],
    /// Holds the input lags' rows under the fixed block, then each group's small factor.
    b: &'a mut [T; STORAGE],
}

impl<'a, T: Real> Nested<'a, T> {
    /// Storage for the groups of `grid` on `normal` (`Err` when the exact pivot `y_{t-1}`
    /// is not positive: no candidate can be factored).
    pub(crate) fn new(
        normal: &'a Normal<T>,
        offset: Offset,
        grid: Grid,
        a: &'a mut Factor<T>,
        b: &'a mut Factor<T>,
    ) -> crate::error::Result<Self> {
        let (_, c) = normal.pivot(T::ZERO)?;
        Ok(Nested {
            normal,
            offset,
            grid,
            c,
            p: 0,
            f: 0,
            bad: 0,
            a: a.storage(),
            b: b.storage(),
        })
    }

    /// Input lags `u_{t-lo} … u_{t-lo-len+1}` the grid's candidates use, then the target:
    /// `lo = d_min`, `len = d_max + q_max − d_min`.
    fn lags(&self) -> (u8, usize) {
        let g = &self.grid;
        let len = usize::from(g.d.max) + usize::from(g.q.max) - usize::from(g.d.min);
        (g.d.min, len)
    }

    /// Position in [`crate::normal`]'s column list of row `r` of the lag block (`r = len`:
    /// the target).
    fn lag_col(&self, r: usize) -> usize {
        let (lo, len) = self.lags();
        if r >= len {
            others_index(Col::Y(0))
        } else {
            others_index(Col::U(lo + r as u8))
        }
    }

    /// Position of fixed-block column `k`: the intercept first (if any), then `y_{t-2} …`.
    fn fixed_col(&self, k: usize) -> usize {
        match (self.offset, k) {
            (Offset::Intercept, 0) => others_index(Col::One),
            (Offset::Intercept, k) => others_index(Col::Y(k as u8 + 1)),
            (Offset::None, k) => others_index(Col::Y(k as u8 + 2)),
        }
    }

    /// Eliminates the fixed block of order `p` from the input lags and the target: factors
    /// the block (into `a`), computes each lag's row under it (into `b`), and what those
    /// subtractions leave of every pair (`P`, into `a`). `false` when no candidate of this
    /// `p` can be factored: the fixed block is not positive definite, or the target's row
    /// under it is not finite.
    // Out of line, as `group`: inlined into the firmware's search their loops took 9.6 KB of
    // the ATmega2560 image (every frame access through a pointer adjustment) instead of ~2 KB.
    #[inline(never)]
    pub(crate) fn eliminate(&mut self, p: u8) -> bool {
        self.p = 0;
        let f = usize::from(p) - 1 + self.offset.params();
        let tol = pivot_tol::<T>();
        // The fixed block's factor, as factor_in_place computes rows 1..=f.
        for i in 0..f {
            let ci = self.fixed_col(i);
            for j in 0..=i {
                let mut s = self.normal.trailing(ci, self.fixed_col(j), self.c);
                for k in 0..j {
                    s -= self.a[packed(i, k)] * self.a[packed(j, k)];
                }
                if i == j {
                    let diag = self.normal.trailing(ci, ci, self.c);
                    if !s.is_finite() || s <= tol * diag || s <= T::ZERO {
                        return false;
                    }
                    self.a[packed(i, i)] = s.sqrt();
                } else {
                    let v = s / self.a[packed(j, j)];
                    if !v.is_finite() {
                        return false;
                    }
                    self.a[packed(i, j)] = v;
                }
            }
        }
        // Each lag's row (and the target's) under the fixed block.
        let (_, len) = self.lags();
        let mut bad = 0u32;
        for r in 0..=len {
            let cr = self.lag_col(r);
            for j in 0..f {
                let mut s = self.normal.trailing(cr, self.fixed_col(j), self.c);
                for k in 0..j {
                    s -= self.b[r * f + k] * self.a[packed(j, k)];
                }
                let v = s / self.a[packed(j, j)];
                if !v.is_finite() {
                    bad |= 1 << r;
                }
                self.b[r * f + j] = v;
            }
        }
        if bad & (1 << len) != 0 {
            return false;
        }
        // P: every pair of lag rows less their products under the fixed block, in order.
        for r in 0..=len {
            let cr = self.lag_col(r);
            for r2 in 0..=r {
                let mut s = self.normal.trailing(cr, self.lag_col(r2), self.c);
                for k in 0..f {
                    s -= self.b[r * f + k] * self.b[r2 * f + k];
                }
                self.a[packed(r, r2)] = s;
            }
        }
        self.p = p;
        self.f = f;
        self.bad = bad;
        true
    }

    /// The least-squares RSS `rss_min` (as [`Factor::rss_min`] gives it) of the candidates
    /// `(p, q, d)` of the eliminated `p`, for `q = 1 ..= q_max` at index `q − 1`; `None` where
    /// the candidate's own factorisation would fail or the record is too short for it.
    #[inline(never)]
    pub(crate) fn group(&mut self, d: u8, out: &mut [Option<T>; Q_MAX]) {
        *out = [None; Q_MAX];
        if self.p == 0 {
            return;
        }
        let (lo, len) = self.lags();
        let q_max = usize::from(self.grid.q.max);
        let first = usize::from(d - lo);
        let tol = pivot_tol::<T>();
        // The input lags' rows of the small factor (packed, q_max rows), stopping at the
        // first row that fails: the candidates before it are unaffected.
        let mut valid = 0;
        'rows: for i in 0..q_max {
            let r = first + i;
            if self.bad & (1 << r) != 0 {
                break;
            }
            for j in 0..=i {
                let mut s = self.a[packed(r, first + j)];
                for k in 0..j {
                    s -= self.b[packed(i, k)] * self.b[packed(j, k)];
                }
                if i == j {
                    let cr = self.lag_col(r);
                    let diag = self.normal.trailing(cr, cr, self.c);
                    if !s.is_finite() || s <= tol * diag || s <= T::ZERO {
                        break 'rows;
                    }
                    self.b[packed(i, i)] = s.sqrt();
                } else {
                    let v = s / self.b[packed(j, j)];
                    if !v.is_finite() {
                        break 'rows;
                    }
                    self.b[packed(i, j)] = v;
                }
            }
            valid = i + 1;
        }
        // The target's row over those lags, and ρ² of each leading block from its running
        // sum of squares.
        let t0 = packed_len(q_max);
        let ptt = self.a[packed(len, len)];
        for q in 1..=valid {
            let j = q - 1;
            let mut s = self.a[packed(len, first + j)];
            for k in 0..j {
                s -= self.b[t0 + k] * self.b[packed(j, k)];
            }
            let v = s / self.b[packed(j, j)];
            if !v.is_finite() {
                break;
            }
            self.b[t0 + j] = v;
            // As the candidate's own factor computes its target pivot: P_tt less the squares
            // of the target row, in order; ρ² is the pivot (clamped at 0) squared.
            let mut t = ptt;
            for k in 0..q {
                t -= self.b[t0 + k] * self.b[t0 + k];
            }
            if !t.is_finite() {
                break;
            }
            let rho = if t > T::ZERO { t.sqrt() } else { T::ZERO };
            let s = Structure {
                p: self.p,
                q: q as u8,
                d,
            };
            let n = s.params(self.offset);
            if self.normal.samples() < (s.seed_len() + n + 1) as u32 {
                break;
            }
            let r2 = rho * rho;
            let floor = self.normal.rss_floor(n);
            if let Some(slot) = out.get_mut(j) {
                *slot = Some(if r2 > floor { r2 } else { floor });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gram::{FloatGram, Scale};

    /// A seeded generator (xorshift64*), uniform in [0, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            let mut x = self.0;
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            self.0 = x;
            (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A record of `n` samples of a stable ARX(2, 2, 2) plant at scale `sy` for `y`, `su` for
    /// `u`, driven by a multilevel input with `levels` distinct values held `hold` samples
    /// (one level: no excitation; a period of two samples: input lags two apart are equal),
    /// with noise `noise`.
    fn record(
        seed: u64,
        n: usize,
        levels: u32,
        hold: usize,
        noise: f64,
        su: f64,
        sy: f64,
    ) -> FloatGram {
        let mut rng = Lcg(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        let mut g = FloatGram::new();
        let (mut y1, mut y2, mut u1, mut u2, mut u3) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut u = 0.0;
        for t in 0..n {
            if t % hold == 0 {
                u = (rng.next() * f64::from(levels)).floor() / f64::from(levels.max(1));
            }
            let y = 1.3 * y1 - 0.45 * y2 + 0.8 * u2 + 0.3 * u3 + 0.2 + noise * (rng.next() - 0.5);
            g.push(u * su, y * sy).unwrap();
            (y2, y1) = (y1, y);
            (u3, u2, u1) = (u2, u1, u);
        }
        let _ = u1;
        g
    }

    /// A record whose input alternates between two values every sample: input lags two apart
    /// are the same column, so every candidate with `q ≥ 3` is singular.
    fn alternating(seed: u64, n: usize) -> FloatGram {
        let mut rng = Lcg(seed | 1);
        let mut g = FloatGram::new();
        let mut y1 = 0.0;
        for t in 0..n {
            let u = if t % 2 == 0 { 1.0 } else { -1.0 };
            let y = 0.7 * y1 + 0.5 * u + 0.1 * (rng.next() - 0.5);
            g.push(u, y).unwrap();
            y1 = y;
        }
        g
    }

    /// Every candidate of `grid`: the group's RSS equals the candidate's own factor's
    /// `rss_min` bit for bit, and is `None` exactly where the candidate cannot be factored.
    fn check<T: Real>(g: &FloatGram, grid: Grid, offset: Offset) -> (usize, usize) {
        let normal = match g.normal::<T>(Scale::UNIT) {
            Ok(n) => n,
            Err(_) => return (0, 0),
        };
        let (mut a, mut b) = (Factor::empty(), Factor::empty());
        let mut nested = Nested::new(&normal, offset, grid, &mut a, &mut b).unwrap();
        let (mut same, mut refused) = (0, 0);
        let mut out = [None; Q_MAX];
        for p in grid.p.min..=grid.p.max {
            let usable = nested.eliminate(p);
            for d in grid.d.min..=grid.d.max {
                if usable {
                    nested.group(d, &mut out);
                } else {
                    out = [None; Q_MAX];
                }
                for q in grid.q.min..=grid.q.max {
                    let s = Structure { p, q, d };
                    let own = normal
                        .system(s, offset)
                        .and_then(|sys| sys.factor(T::ZERO))
                        .map(|f| f.rss_min());
                    let got = out[usize::from(q) - 1];
                    match (own, got) {
                        (Ok(o), Some(x)) => {
                            assert_eq!(
                                o.to_f64().to_bits(),
                                x.to_f64().to_bits(),
                                "{s:?} {offset:?}: own {o:?}, group {x:?}"
                            );
                            same += 1;
                        }
                        (Err(_), None) => refused += 1,
                        (o, x) => panic!("{s:?} {offset:?}: own {o:?}, group {x:?}"),
                    }
                }
            }
        }
        (same, refused)
    }

    #[test]
    fn group_rss_is_the_candidates_own_bit_for_bit() {
        let grids = [
            Grid::PAPER,
            Grid {
                p: crate::structure::OrderRange::new(2, 4),
                q: crate::structure::OrderRange::new(2, 5),
                d: crate::structure::OrderRange::new(1, 3),
            },
            Grid::single(Structure { p: 3, q: 2, d: 4 }),
        ];
        let (mut same, mut refused) = (0, 0);
        for seed in 0..12u64 {
            // Rich input, few levels (singular input lags), short record (too short for
            // the large candidates), noise-free, other scales.
            let records = [
                record(seed, 3000, 1000, 7, 0.1, 1.0, 1.0),
                record(seed, 800, 2, 1, 0.05, 1.0, 1.0),
                record(seed, 20, 1000, 3, 0.1, 1.0, 1.0),
                record(seed, 1500, 50, 7, 0.0, 1.0, 1.0),
                record(seed, 2000, 1000, 7, 0.1, 1e-3, 1e3),
                record(seed, 500, 1, 7, 0.1, 1.0, 1.0),
                alternating(seed, 600),
            ];
            for g in &records {
                for grid in grids {
                    for offset in Offset::ALL {
                        let (s32, r32) = check::<f32>(g, grid, offset);
                        let (s64, r64) = check::<f64>(g, grid, offset);
                        same += s32 + s64;
                        refused += r32 + r64;
                    }
                }
            }
        }
        // Both outcomes occurred (the test exercises refusals as well as bounds).
        assert!(
            same > 10_000 && refused > 500,
            "same {same}, refused {refused}"
        );
    }
}
