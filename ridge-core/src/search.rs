//! Bounded structure search (the paper's eq. 13–15).
//!
//! Every candidate `(p, q, d)` of a [`Grid`] is scored by a [`Criterion`] of its
//! residual sum of squares. With `prune` on (the default) the search is exact but cheap:
//! least squares minimises the RSS, so the criterion of the least-squares RSS is a
//! lower bound of every estimator's criterion for that candidate. The bounds come a
//! group of candidates at a time, bit-identical to factoring each (`crate::bounds`: one
//! elimination per `p` and one small factorisation per `(p, d)` give every `q`); the
//! estimator then runs on candidates in ascending bound order and stops when the next
//! bound exceeds the best criterion found. The pick is identical to
//! the exhaustive grid: the same arithmetic produces every score, and every score is
//! `bound + (non-negative excess)`.
//!
//! Memory is bounded by a constant, not by the grid: each pass over the grid queues the 16
//! best-ranked bounds after those already queued, and another pass runs only when all of them
//! were evaluated and the search goes on (the bounds computed again in each pass; the
//! default search on the simulated pump needs one pass).

use crate::bounds::Nested;
use crate::error::{Error, Result};
use crate::estimate::{Estimator, Fit, Ols, Ridge, RidgeM};
#[cfg(feature = "alasso")]
use crate::lasso::AdaptiveLasso;
use crate::normal::{Factor, Normal, System};
use crate::real::Real;
use crate::structure::{Grid, Offset, Structure};
use crate::Q_MAX;

/// How candidates are ranked. All use `N ln(RSS/N)`; they differ in the penalty.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Criterion {
    /// The paper's eq. (14): `N ln(RSS/N) + α (p + q + d)`. Counts the delay as a
    /// parameter, so `(p, q + d, 0)`, which contains every regressor of `(p, q, d)`
    /// at the same penalty, always wins unless `q` is at its maximum. Kept to
    /// reproduce the paper.
    Paper,
    /// Delay-free AIC: `N ln(RSS/N) + α (p + q)`, as MATLAB `selstruc` and SIPPY count.
    /// The default: it is the paper's criterion and weight with the delay flaw removed,
    /// so it can find a true delay.
    #[default]
    Aic,
    /// BIC: `N ln(RSS/N) + ln(N) (p + q)`; ignores `α`.
    Bic,
    /// Validation loss: `N_v ln(RSS_v/N_v)` of the estimated model on a second record's
    /// statistics (like MATLAB `arxstruc`); no penalty.
    Validation,
}

impl Criterion {
    /// All criteria, in declaration order.
    pub const ALL: [Criterion; 4] = [
        Criterion::Paper,
        Criterion::Aic,
        Criterion::Bic,
        Criterion::Validation,
    ];

    /// The name used on command lines and in reports: `paper`, `aic`, `bic`, `validation`
    /// (the one name table; [`FromStr`](core::str::FromStr) reads the same names).
    pub const fn name(self) -> &'static str {
        match self {
            Criterion::Paper => "paper",
            Criterion::Aic => "aic",
            Criterion::Bic => "bic",
            Criterion::Validation => "validation",
        }
    }

    /// The criterion value of a candidate: `N ln(RSS/N) + penalty`, with `N = samples`,
    /// `k = p + q (+1 with an intercept)` and the penalty `α (k + d)` ([`Paper`]), `α k`
    /// ([`Aic`]), `ln(N) k` ([`Bic`]) or none ([`Validation`], whose `rss` and `samples` are
    /// the validation record's). Smaller is better. The one definition the search and every
    /// report use.
    ///
    /// [`Paper`]: Criterion::Paper
    /// [`Aic`]: Criterion::Aic
    /// [`Bic`]: Criterion::Bic
    /// [`Validation`]: Criterion::Validation
    pub fn value<T: Real>(self, alpha: T, rss: T, samples: u32, s: Structure, offset: Offset) -> T {
        let n = T::from_u32(samples);
        let k = T::from_u32(u32::from(s.p) + u32::from(s.q) + offset.params() as u32);
        let fit = n * (rss / n).ln();
        match self {
            Criterion::Paper => fit + alpha * (k + T::from_u32(u32::from(s.d))),
            Criterion::Aic => fit + alpha * k,
            Criterion::Bic => fit + n.ln() * k,
            Criterion::Validation => fit,
        }
    }
}

impl core::str::FromStr for Criterion {
    type Err = crate::error::UnknownName;
    fn from_str(s: &str) -> core::result::Result<Self, Self::Err> {
        const NAMES: [&str; 4] = [
            Criterion::Paper.name(),
            Criterion::Aic.name(),
            Criterion::Bic.name(),
            Criterion::Validation.name(),
        ];
        crate::error::parse_name(s, &Criterion::ALL, Criterion::name, "criterion", &NAMES)
    }
}

/// The estimators of the crate, by kind (without their hyper-parameters): what a command line
/// or a report names. [`Method`] carries the hyper-parameters of the ones the search can run;
/// [`MethodKind::Rls`] runs sample by sample ([`crate::Rls`]) on a chosen structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MethodKind {
    /// Ridge with momentum (the paper's method), [`RidgeM`].
    #[default]
    RidgeM,
    /// Plain Ridge, [`Ridge`] (one Ridge-M iterate).
    Ridge,
    /// Ordinary least squares, [`crate::Ols`].
    Ols,
    /// Recursive least squares, [`crate::Rls`].
    Rls,
    /// Adaptive LASSO (cargo feature `alasso`).
    AdaptiveLasso,
}

impl MethodKind {
    /// All kinds, in declaration order.
    pub const ALL: [MethodKind; 5] = [
        MethodKind::RidgeM,
        MethodKind::Ridge,
        MethodKind::Ols,
        MethodKind::Rls,
        MethodKind::AdaptiveLasso,
    ];

    /// The name used on command lines and in reports: `ridge-m`, `ridge`, `ols`, `rls`,
    /// `alasso` (the one name table; [`FromStr`](core::str::FromStr) reads the same names).
    pub const fn name(self) -> &'static str {
        match self {
            MethodKind::RidgeM => "ridge-m",
            MethodKind::Ridge => "ridge",
            MethodKind::Ols => "ols",
            MethodKind::Rls => "rls",
            MethodKind::AdaptiveLasso => "alasso",
        }
    }
}

impl core::str::FromStr for MethodKind {
    type Err = crate::error::UnknownName;
    fn from_str(s: &str) -> core::result::Result<Self, Self::Err> {
        const NAMES: [&str; 5] = [
            MethodKind::RidgeM.name(),
            MethodKind::Ridge.name(),
            MethodKind::Ols.name(),
            MethodKind::Rls.name(),
            MethodKind::AdaptiveLasso.name(),
        ];
        crate::error::parse_name(s, &MethodKind::ALL, MethodKind::name, "method", &NAMES)
    }
}

/// The estimator run on each candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method<T> {
    /// Ridge with momentum (the paper's method).
    RidgeM(RidgeM<T>),
    /// Plain Ridge.
    Ridge(Ridge<T>),
    /// Ordinary least squares.
    Ols,
    /// Adaptive LASSO (cargo feature `alasso`).
    #[cfg(feature = "alasso")]
    AdaptiveLasso(AdaptiveLasso<T>),
}

impl<T: Real> Method<T> {
    /// Which estimator this is.
    pub fn kind(&self) -> MethodKind {
        match self {
            Method::RidgeM(_) => MethodKind::RidgeM,
            Method::Ridge(_) => MethodKind::Ridge,
            Method::Ols => MethodKind::Ols,
            #[cfg(feature = "alasso")]
            Method::AdaptiveLasso(_) => MethodKind::AdaptiveLasso,
        }
    }
}

impl<T: Real> Default for Method<T> {
    fn default() -> Self {
        Method::RidgeM(RidgeM::default())
    }
}

impl<T: Real> Estimator<T> for Method<T> {
    fn fit_with(&self, system: &System<T>, ls: &Factor<T>) -> Result<Fit<T>> {
        match self {
            Method::RidgeM(m) => m.fit_with(system, ls),
            Method::Ridge(m) => m.fit_with(system, ls),
            Method::Ols => Ols.fit_with(system, ls),
            #[cfg(feature = "alasso")]
            Method::AdaptiveLasso(m) => m.fit_with(system, ls),
        }
    }
}

/// A structure search: grid, criterion, estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Search<T> {
    /// Candidate orders and delays (default: the paper's 252).
    pub grid: Grid,
    /// Constant term in every candidate.
    pub offset: Offset,
    /// Ranking criterion (default: delay-free AIC).
    pub criterion: Criterion,
    /// Penalty weight per parameter for [`Criterion::Paper`] and [`Criterion::Aic`]
    /// (paper: 12).
    pub alpha: T,
    /// Estimator (default: Ridge-M with the paper's hyper-parameters).
    pub method: Method<T>,
    /// Exact pruning by least-squares bounds (default on; the result is identical).
    pub prune: bool,
}

/// The paper's penalty weight `α` per parameter.
pub const PAPER_ALPHA: f64 = 12.0;

impl<T: Real> Default for Search<T> {
    fn default() -> Self {
        Search {
            grid: Grid::PAPER,
            offset: Offset::None,
            criterion: Criterion::Aic,
            alpha: T::from_f64(PAPER_ALPHA),
            method: Method::default(),
            prune: true,
        }
    }
}

impl Search<f32> {
    /// [`Search::default`] as a constant, in `f32` (for `static` settings on a device).
    pub const DEFAULT: Search<f32> = Search {
        grid: Grid::PAPER,
        offset: Offset::None,
        criterion: Criterion::Aic,
        alpha: PAPER_ALPHA as f32,
        method: Method::RidgeM(RidgeM::PAPER),
        prune: true,
    };
}

/// The winner of a search.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection<T: Real> {
    /// The chosen structure's fit (model, estimation RSS, iterations).
    pub fit: Fit<T>,
    /// Its criterion value.
    pub score: T,
    /// Candidates in the grid.
    pub candidates: u16,
    /// Candidates on which the estimator ran.
    pub evaluated: u16,
    /// Candidates skipped because their normal equations were not positive definite
    /// (the record does not excite that structure).
    pub skipped: u16,
}

impl<T: Real> Selection<T> {
    /// The chosen structure.
    pub fn structure(&self) -> Structure {
        self.fit.layout.structure
    }
}

impl<T: Real> Search<T> {
    fn check(&self, validation: Option<&Normal<T>>) -> Result<()> {
        self.grid.check()?;
        if !(self.alpha.is_finite() && self.alpha >= T::ZERO) {
            return Err(Error::InvalidParameter);
        }
        if self.criterion == Criterion::Validation && validation.is_none() {
            return Err(Error::InvalidParameter);
        }
        Ok(())
    }

    /// [`Criterion::value`] of a structure with this search's criterion, `α` and offset.
    fn criterion(&self, rss: T, samples: u32, s: Structure) -> T {
        self.criterion
            .value(self.alpha, rss, samples, s, self.offset)
    }

    /// Forms candidate `s`: its system (a view into `est`), its least-squares factor in
    /// `ls` (caller-owned storage, reused across candidates to keep the stack small on
    /// an 8-bit MCU) and the criterion of the least-squares RSS, a lower bound of its
    /// score.
    /// Sets up candidate `s`: its system, its least-squares factor in `ls`, and the lower
    /// bound of its score. `scratch` is overwritten (validation factor).
    fn prepare<'n>(
        &self,
        s: Structure,
        est: &'n Normal<T>,
        val: Option<&Normal<T>>,
        ls: &mut Factor<T>,
        scratch: &mut Factor<T>,
    ) -> Result<(System<'n, T>, T)> {
        let system = est.system(s, self.offset)?;
        system.factor_into(T::ZERO, ls)?;
        let bound = match (self.criterion, val) {
            (Criterion::Validation, Some(v)) => {
                let vs = v.system(s, self.offset)?;
                vs.factor_into(T::ZERO, scratch)?;
                self.criterion(scratch.rss_min(), vs.samples(), s)
            }
            _ => self.criterion(ls.rss_min(), system.samples(), s),
        };
        // A NaN or +∞ bound cannot be ordered: such a candidate is unusable.
        if !(bound.is_finite() || bound < T::ZERO) {
            return Err(Error::NonFinite);
        }
        Ok((system, bound))
    }

    /// Fits a prepared candidate and scores it. All factor storage comes from the caller
    /// (`ls`: the least-squares factor from [`prepare`](Self::prepare), which Ridge-M uses as
    /// work space and factors again; `scratch`: overwritten), so that the search's deepest
    /// stack frame holds no factor of its own.
    /// Never inlined: inside the caller's frame its locals would add to the deepest stack
    /// (ATmega2560: +236 B once the board's settings are compile-time constants).
    #[inline(never)]
    fn score(
        &self,
        system: &System<'_, T>,
        ls: &mut Factor<T>,
        scratch: &mut Factor<T>,
        val: Option<&Normal<T>>,
        progress: &mut impl FnMut(),
    ) -> Result<(Fit<T>, T)> {
        let fit = match &self.method {
            // Ridge-M is the long one: it reports progress as it goes.
            Method::RidgeM(m) => m.fit_in(system, ls, scratch, &mut *progress)?,
            Method::Ridge(m) => {
                let fit = m.fit_in(system, ls, scratch);
                progress();
                fit?
            }
            other => {
                let fit = other.fit_with(system, ls);
                progress();
                fit?
            }
        };
        let s = system.structure();
        let score = match (self.criterion, val) {
            (Criterion::Validation, Some(v)) => {
                let vs = v.system(s, self.offset)?;
                vs.factor_into(T::ZERO, scratch)?;
                self.criterion(scratch.rss(&fit.w[..vs.params()]), vs.samples(), s)
            }
            _ => self.criterion(fit.rss, system.samples(), s),
        };
        if score.is_finite() || score < T::ZERO {
            Ok((fit, score))
        } else {
            Err(Error::NonFinite)
        }
    }

    /// Prepares, fits and scores candidate `s`: `None` when it cannot be prepared (not
    /// evaluated), otherwise its fit and score or why they failed. Inlined: a frame of its
    /// own would hold the returned fit once more on the search's deepest path (AVR stack).
    #[inline(always)]
    fn evaluate(
        &self,
        s: Structure,
        est: &Normal<T>,
        val: Option<&Normal<T>>,
        ls: &mut Factor<T>,
        scratch: &mut Factor<T>,
        progress: &mut impl FnMut(),
    ) -> Option<Result<(Fit<T>, T)>> {
        let (system, _) = self.prepare(s, est, val, ls, scratch).ok()?;
        Some(self.score(&system, ls, scratch, val, progress))
    }

    /// Calls `visit(s, bound)` for every candidate `s` of the grid: the criterion of its
    /// least-squares RSS (a lower bound of its score), or `None` when the candidate cannot
    /// be prepared ([`Search::prepare`] fails: too short, not positive definite, a bound
    /// that is not finite). The bounds come a group at a time ([`crate::bounds`]),
    /// bit-identical to preparing each candidate, except for [`Criterion::Validation`],
    /// whose bounds are the validation record's and are prepared one by one. `ls` and
    /// `scratch` are overwritten.
    fn bounds(
        &self,
        est: &Normal<T>,
        val: Option<&Normal<T>>,
        ls: &mut Factor<T>,
        scratch: &mut Factor<T>,
        progress: &mut impl FnMut(),
        visit: &mut impl FnMut(Structure, Option<T>),
    ) {
        if self.criterion == Criterion::Validation {
            for s in self.grid.iter() {
                visit(
                    s,
                    self.prepare(s, est, val, ls, scratch).ok().map(|(_, b)| b),
                );
                progress();
            }
            return;
        }
        let g = self.grid;
        let mut nested = Nested::new(est, self.offset, g, ls, scratch).ok();
        let mut rss = [None; Q_MAX];
        for p in g.p.min..=g.p.max {
            let usable = nested.as_mut().is_some_and(|n| n.eliminate(p));
            progress();
            for d in g.d.min..=g.d.max {
                match nested.as_mut() {
                    Some(n) if usable => n.group(d, &mut rss),
                    _ => rss = [None; Q_MAX],
                }
                for q in g.q.min..=g.q.max {
                    let s = Structure { p, q, d };
                    let bound = rss
                        .get(usize::from(q) - 1)
                        .copied()
                        .flatten()
                        .map(|r| self.criterion(r, est.samples(), s))
                        // A NaN or +∞ bound cannot be ordered: such a candidate is unusable.
                        .filter(|b| b.is_finite() || *b < T::ZERO);
                    visit(s, bound);
                }
                progress();
            }
        }
    }

    /// Runs the search on the estimation statistics `est` (and, for
    /// [`Criterion::Validation`], the validation statistics `val`).
    ///
    /// Errors: [`Error::InvalidStructure`] / [`Error::InvalidParameter`] for a bad
    /// configuration, [`Error::NoCandidate`] when no candidate could be fitted (e.g. the
    /// record is too short for all of them or does not excite any).
    pub fn run(&self, est: &Normal<T>, val: Option<&Normal<T>>) -> Result<Selection<T>> {
        self.run_with_progress(est, val, &mut || {})
    }

    /// [`Search::run`], calling `progress()` after every group of bounds (one elimination
    /// per `p`, one small factorisation per `(p, d)`, `crate::bounds`; one bound with
    /// [`Criterion::Validation`]), every Ridge-M iterate and every other estimator fit, so
    /// that no stretch between two calls is longer than one factorisation or one iterate
    /// (≤ 14 rows): firmware feeds its watchdog there. The result is identical to
    /// [`Search::run`].
    pub fn run_with_progress(
        &self,
        est: &Normal<T>,
        val: Option<&Normal<T>>,
        progress: &mut impl FnMut(),
    ) -> Result<Selection<T>> {
        self.check(val)?;
        let mut tally = Tally {
            best: None,
            evaluated: 0,
            skipped: 0,
        };
        let (mut ls, mut scratch) = (Factor::empty(), Factor::empty());
        if self.prune {
            // Candidates are evaluated in ascending order of their lower bounds until a bound
            // exceeds the best score. The bounds are not all kept: each pass over the grid
            // computes them again and queues the `QUEUE` smallest that come after everything
            // queued before (`after`: the last one evaluated; `None` in the first pass); a
            // further pass is only needed when all of those were evaluated and the search
            // goes on (rare: most searches stop within the first few).
            let mut after: Option<(T, Structure)> = None;
            'passes: loop {
                let mut queue = Queue::<T>::default();
                let first_pass = after.is_none();
                let mut offer = |s: Structure, bound: Option<T>| match bound {
                    Some(b) => {
                        let done = after.is_some_and(|(ab, a)| !better(ab, a, b, s));
                        if !done {
                            queue.offer(b, s);
                        }
                    }
                    // Counted once, in the first pass.
                    None if first_pass => tally.skipped += 1,
                    None => {}
                };
                self.bounds(est, val, &mut ls, &mut scratch, progress, &mut offer);
                for (b, s) in queue.entries() {
                    if let Some((_, bs)) = &tally.best {
                        if b > *bs {
                            break 'passes;
                        }
                    }
                    after = Some((b, s));
                    tally.add(self.evaluate(s, est, val, &mut ls, &mut scratch, progress));
                }
                if queue.len < QUEUE {
                    break;
                }
            }
        } else {
            for s in self.grid.iter() {
                tally.add(self.evaluate(s, est, val, &mut ls, &mut scratch, progress));
            }
        }
        let (fit, score) = tally.best.ok_or(Error::NoCandidate)?;
        Ok(Selection {
            fit,
            score,
            candidates: self.grid.len() as u16,
            evaluated: tally.evaluated,
            skipped: tally.skipped,
        })
    }

    /// Scores every candidate (no pruning) and calls `visit(structure, fit, score)`
    /// for each one that could be fitted; for tables and diagnostics.
    pub fn for_each(
        &self,
        est: &Normal<T>,
        val: Option<&Normal<T>>,
        mut visit: impl FnMut(Structure, &Fit<T>, T),
    ) -> Result<()> {
        self.check(val)?;
        let (mut ls, mut scratch) = (Factor::empty(), Factor::empty());
        for s in self.grid.iter() {
            if let Some(Ok((fit, score))) =
                self.evaluate(s, est, val, &mut ls, &mut scratch, &mut || {})
            {
                visit(s, &fit, score);
            }
        }
        Ok(())
    }
}

/// `true` when `(sa, a)` ranks before `(sb, b)`: lower criterion; on a tie the smaller
/// model (`p + q`), then the larger delay, then the smaller `p`.
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

/// Candidates queued per pass of the pruned search.
const QUEUE: usize = 16;

/// The `QUEUE` best-ranked candidates offered so far, ascending: bounds and structures
/// (16 × 7 bytes with `f32`, against 4 bytes per grid candidate, 1 KB, for keeping every
/// bound). Two arrays, not one of `(bound, structure)` pairs: the AVR backend read the
/// structure of such a pair wrong (`scripts/avr-arith-check` picked another model).
struct Queue<T> {
    bounds: [T; QUEUE],
    structures: [Structure; QUEUE],
    len: usize,
}

impl<T: Real> Default for Queue<T> {
    fn default() -> Self {
        Queue {
            bounds: [T::ZERO; QUEUE],
            structures: [Structure { p: 0, q: 0, d: 0 }; QUEUE],
            len: 0,
        }
    }
}

impl<T: Real> Queue<T> {
    /// The queued entries, best first.
    fn entries(&self) -> impl Iterator<Item = (T, Structure)> + '_ {
        self.bounds
            .iter()
            .copied()
            .zip(self.structures.iter().copied())
            .take(self.len)
    }

    /// Inserts candidate `s` with bound `b` in rank order if it ranks among the `QUEUE`
    /// best; the worst one drops out of a full queue.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    fn offer(&mut self, b: T, s: Structure) {
        let at = self
            .entries()
            .position(|(qb, qs)| better(b, s, qb, qs))
            .unwrap_or(self.len);
        let end = (self.len + 1).min(QUEUE);
        // Shift [at, end) one place up (the last entry of a full queue falls off), then put
        // the new entry at `at`; nothing happens when it ranks after a full queue.
        if at >= end {
            return;
        }
        if let (Some(bw), Some(sw)) = (
            self.bounds.get_mut(at..end),
            self.structures.get_mut(at..end),
        ) {
            bw.rotate_right(1);
            sw.rotate_right(1);
            if let (Some(bs), Some(ss)) = (bw.first_mut(), sw.first_mut()) {
                *bs = b;
                *ss = s;
                self.len = end;
            }
        }
    }
}

/// The best candidate of a search so far, and the counts of its [`Selection`].
struct Tally<T: Real> {
    best: Option<(Fit<T>, T)>,
    evaluated: u16,
    skipped: u16,
}

impl<T: Real> Tally<T> {
    /// Counts the outcome of [`Search::evaluate`] and keeps the better of it and the best.
    fn add(&mut self, outcome: Option<Result<(Fit<T>, T)>>) {
        let (fit, score) = match outcome {
            None => {
                self.skipped += 1;
                return;
            }
            Some(Err(_)) => {
                self.evaluated += 1;
                self.skipped += 1;
                return;
            }
            Some(Ok(found)) => {
                self.evaluated += 1;
                found
            }
        };
        let wins = match &self.best {
            None => true,
            Some((b, bs)) => better(score, fit.layout.structure, *bs, b.layout.structure),
        };
        if wins {
            self.best = Some((fit, score));
        }
    }
}
