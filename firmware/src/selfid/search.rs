//! The ridge-core structure search ([`ridge_core::Search::run`]) with a watchdog hook.
//!
//! `Search::run` has no progress callback, and on the ATmega2560 it runs for seconds: the
//! least-squares bounds of 252 candidates (one Cholesky each, up to 11 ms) and then Ridge-M on
//! the candidates that survive pruning (each up to 200 iterates of two triangular solves,
//! about 1 s for 12 parameters). [`run`] performs **the same arithmetic in the same order**
//! from ridge-core's public pieces ([`Normal::system`], [`System::factor`],
//! [`RidgeM::iterate`], [`Factor::rss`]) and calls `pet` after every bound, after every
//! Ridge-M iterate and after every other estimator fit, so that no stretch without a `pet`
//! is longer than one factorisation (≤ 13 × 13).
//!
//! The result is identical, bit for bit, to `Search::run(est, None)`: the tests compare the
//! structure, score, coefficients and counters on `f32` and `f64`.
//!
//! [`RidgeM::iterate`]: ridge_core::RidgeM::iterate

use ridge_core::{
    ArxModel, Criterion, Error, Estimator, Factor, Method, Normal, Real, Regressor, Search,
    Structure, System, GRID_MAX, PARAMS_MAX, P_MAX, Q_MAX,
};

/// The winner of a [`run`], as [`ridge_core::Selection`] reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found<T: Real> {
    /// The chosen model (physical units).
    pub model: ArxModel<T>,
    /// Its criterion value.
    pub score: T,
    /// Its residual sum of squares on the estimation record, output units squared.
    pub rss: T,
    /// Estimator iterations of the chosen structure.
    pub iterations: u32,
    /// Candidates in the grid.
    pub candidates: u16,
    /// Candidates on which the estimator ran.
    pub evaluated: u16,
    /// Candidates that could not be fitted.
    pub skipped: u16,
}

/// Runs `search` on the estimation statistics `est`, calling `pet` between bounded steps
/// (see the [module docs](self)). Same result as `search.run(est, None)`.
///
/// Errors: as [`ridge_core::Search::run`] without validation statistics
/// ([`Criterion::Validation`] is [`Error::InvalidParameter`]).
pub fn run<T: Real>(
    search: &Search<T>,
    est: &Normal<T>,
    pet: &mut impl FnMut(),
) -> Result<Found<T>, Error> {
    search.grid.check()?;
    if !(search.alpha.is_finite() && search.alpha >= T::ZERO)
        || search.criterion == Criterion::Validation
    {
        return Err(Error::InvalidParameter);
    }
    let grid = search.grid;
    let candidates = grid.len();
    let mut best: Option<Best<T>> = None;
    let mut evaluated = 0u16;
    let mut skipped = 0u16;
    if search.prune {
        // Phase 1: least-squares bounds of every candidate.
        let mut bound = [T::ZERO; GRID_MAX];
        let mut pending = Bits::default();
        for (i, s) in grid.iter().enumerate().take(GRID_MAX) {
            match prepare(search, s, est) {
                Ok((_, _, b)) => {
                    if let Some(slot) = bound.get_mut(i) {
                        *slot = b;
                    }
                    pending.set(i, true);
                }
                Err(_) => skipped = skipped.saturating_add(1),
            }
            pet();
        }
        // Phase 2: ascending bounds until no bound can beat the best score.
        loop {
            let mut next: Option<usize> = None;
            for i in 0..candidates.min(GRID_MAX) {
                if !pending.get(i) {
                    continue;
                }
                next = match next {
                    None => Some(i),
                    Some(j) => match (grid.get(i), grid.get(j), bound.get(i), bound.get(j)) {
                        (Some(si), Some(sj), Some(&bi), Some(&bj)) if better(bi, si, bj, sj) => {
                            Some(i)
                        }
                        _ => Some(j),
                    },
                };
            }
            let Some(i) = next else { break };
            pending.set(i, false);
            let (Some(s), Some(&b)) = (grid.get(i), bound.get(i)) else {
                break;
            };
            if let Some(best) = &best {
                if b > best.score {
                    break;
                }
            }
            let Ok((system, ls, _)) = prepare(search, s, est) else {
                skipped = skipped.saturating_add(1);
                continue;
            };
            evaluated = evaluated.saturating_add(1);
            match score(search, &system, &ls, pet) {
                Ok(c) => consider(c, &mut best),
                Err(_) => skipped = skipped.saturating_add(1),
            }
            pet();
        }
    } else {
        for s in grid.iter() {
            let Ok((system, ls, _)) = prepare(search, s, est) else {
                skipped = skipped.saturating_add(1);
                pet();
                continue;
            };
            evaluated = evaluated.saturating_add(1);
            match score(search, &system, &ls, pet) {
                Ok(c) => consider(c, &mut best),
                Err(_) => skipped = skipped.saturating_add(1),
            }
            pet();
        }
    }
    let best = best.ok_or(Error::NoCandidate)?;
    Ok(Found {
        model: best.model,
        score: best.score,
        rss: best.rss,
        iterations: best.iterations,
        candidates: u16::try_from(candidates).unwrap_or(u16::MAX),
        evaluated,
        skipped,
    })
}

/// The best candidate so far.
struct Best<T: Real> {
    model: ArxModel<T>,
    structure: Structure,
    score: T,
    rss: T,
    iterations: u32,
}

fn consider<T: Real>(c: Best<T>, best: &mut Option<Best<T>>) {
    let take = match best {
        None => true,
        Some(b) => better(c.score, c.structure, b.score, b.structure),
    };
    if take {
        *best = Some(c);
    }
}

/// `N ln(RSS/N) + penalty`, exactly as ridge-core's `Search` computes it.
fn criterion<T: Real>(search: &Search<T>, rss: T, samples: u32, s: Structure) -> T {
    let n = T::from_u32(samples);
    let k = T::from_u32(u32::from(s.p) + u32::from(s.q) + search.offset.params() as u32);
    let fit = n * (rss / n).ln();
    match search.criterion {
        Criterion::Paper => fit + search.alpha * (k + T::from_u32(u32::from(s.d))),
        Criterion::Aic => fit + search.alpha * k,
        Criterion::Bic => fit + n.ln() * k,
        Criterion::Validation => fit,
    }
}

/// The candidate's system, least-squares factor and criterion bound.
fn prepare<T: Real>(
    search: &Search<T>,
    s: Structure,
    est: &Normal<T>,
) -> Result<(System<T>, Factor<T>, T), Error> {
    let system = est.system(s, search.offset)?;
    let ls = system.factor(T::ZERO)?;
    let bound = criterion(search, ls.rss_min(), system.samples(), s);
    // A NaN or +∞ bound cannot be ordered: such a candidate is unusable.
    if !(bound.is_finite() || bound < T::ZERO) {
        return Err(Error::NonFinite);
    }
    Ok((system, ls, bound))
}

/// Fits one candidate and scores it.
fn score<T: Real>(
    search: &Search<T>,
    system: &System<T>,
    ls: &Factor<T>,
    pet: &mut impl FnMut(),
) -> Result<Best<T>, Error> {
    let s = system.structure();
    match &search.method {
        Method::RidgeM(m) => {
            let (w, used) = m.iterate(system, |_, _| pet())?;
            let rss = ls.rss(w.get(..system.params()).unwrap_or(&w));
            let score = checked(criterion(search, rss, system.samples(), s))?;
            Ok(Best {
                model: model_from(system, &w)?,
                structure: s,
                score,
                rss,
                iterations: used,
            })
        }
        other => {
            let fit = other.fit_with(system, ls)?;
            pet();
            let score = checked(criterion(search, fit.rss, system.samples(), s))?;
            Ok(Best {
                model: fit.model(),
                structure: s,
                score,
                rss: fit.rss,
                iterations: fit.iterations,
            })
        }
    }
}

/// A score that can be ranked (finite or −∞), as ridge-core accepts it.
fn checked<T: Real>(score: T) -> Result<T, Error> {
    if score.is_finite() || score < T::ZERO {
        Ok(score)
    } else {
        Err(Error::NonFinite)
    }
}

/// The ARX model of coefficients `w` in the system's internal order.
fn model_from<T: Real>(system: &System<T>, w: &[T; PARAMS_MAX]) -> Result<ArxModel<T>, Error> {
    let s = system.structure();
    let mut theta = [T::ZERO; P_MAX];
    let mut phi = [T::ZERO; Q_MAX];
    let mut c = T::ZERO;
    for (i, &v) in w.iter().enumerate().take(system.params()) {
        match system.regressor(i) {
            Some(Regressor::Output(k)) => {
                if let Some(t) = theta.get_mut(usize::from(k).wrapping_sub(1)) {
                    *t = v;
                }
            }
            Some(Regressor::Input(k)) => {
                if let Some(f) = phi.get_mut(usize::from(k.wrapping_sub(s.d))) {
                    *f = v;
                }
            }
            Some(Regressor::Constant) => c = v,
            None => {}
        }
    }
    ArxModel::new(
        theta.get(..usize::from(s.p)).unwrap_or(&[]),
        phi.get(..usize::from(s.q)).unwrap_or(&[]),
        s.d,
        system.offset(),
        c,
    )
}

/// `true` when `(sa, a)` ranks before `(sb, b)`: ridge-core's order (lower criterion; on a
/// tie the smaller model, then the larger delay, then the smaller `p`).
fn better<T: Real>(sa: T, a: Structure, sb: T, b: Structure) -> bool {
    if sa < sb {
        return true;
    }
    if sa > sb {
        return false;
    }
    let ka = u16::from(a.p) + u16::from(a.q);
    let kb = u16::from(b.p) + u16::from(b.q);
    (ka, core::cmp::Reverse(a.d), a.p) < (kb, core::cmp::Reverse(b.d), b.p)
}

/// One bit per grid candidate.
#[derive(Default)]
struct Bits([u8; GRID_MAX.div_ceil(8)]);

impl Bits {
    fn get(&self, i: usize) -> bool {
        self.0.get(i / 8).is_some_and(|b| b & (1 << (i % 8)) != 0)
    }
    fn set(&mut self, i: usize, on: bool) {
        if let Some(b) = self.0.get_mut(i / 8) {
            if on {
                *b |= 1 << (i % 8);
            } else {
                *b &= !(1 << (i % 8));
            }
        }
    }
}
