//! Model structures `(p, q, d)`, the optional offset, and search grids.

use crate::error::{Error, Result};
use crate::{D_MAX, P_MAX, Q_MAX};

/// The orders and delay of an ARX model
/// `y_t = Σ_{i=1..p} θ_i y_{t-i} + Σ_{j=0..q-1} φ_j u_{t-j-d} (+ c)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Structure {
    /// Autoregressive order, `1..=P_MAX` (number of past outputs).
    pub p: u8,
    /// Number of input coefficients, `1..=Q_MAX`.
    pub q: u8,
    /// Input delay in samples, `0..=D_MAX`.
    pub d: u8,
}

impl Structure {
    /// A structure, checked against the compile-time maxima.
    pub fn new(p: u8, q: u8, d: u8) -> Result<Self> {
        let s = Structure { p, q, d };
        s.check()?;
        Ok(s)
    }

    /// `Ok` when `1 ≤ p ≤ P_MAX`, `1 ≤ q ≤ Q_MAX`, `d ≤ D_MAX`.
    pub fn check(&self) -> Result<()> {
        if self.p == 0
            || usize::from(self.p) > P_MAX
            || self.q == 0
            || usize::from(self.q) > Q_MAX
            || usize::from(self.d) > D_MAX
        {
            return Err(Error::InvalidStructure);
        }
        Ok(())
    }

    /// Number of coefficients `p + q` (plus one with an intercept).
    pub fn params(&self, offset: Offset) -> usize {
        usize::from(self.p) + usize::from(self.q) + offset.params()
    }

    /// Samples a predictor must be seeded with before it can predict from measured
    /// history: `m = max(p, d + q − 1)`.
    pub fn seed_len(&self) -> usize {
        let p = usize::from(self.p);
        let lag = usize::from(self.d) + usize::from(self.q) - 1;
        if p > lag {
            p
        } else {
            lag
        }
    }
}

/// Whether the model carries a constant term (a pump dead zone, a sensor zero offset).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Offset {
    /// No constant term: the paper's model.
    #[default]
    None,
    /// A constant `c` is added to the regression (not regularised by Ridge/Ridge-M,
    /// not penalised by the adaptive LASSO). Absorbs a pump dead zone and a sensor zero
    /// offset.
    Intercept,
}

impl Offset {
    /// Both choices, in declaration order.
    pub const ALL: [Offset; 2] = [Offset::None, Offset::Intercept];

    /// The name used on command lines and in reports: `none`, `intercept` (the one name table;
    /// [`FromStr`](core::str::FromStr) reads the same names).
    pub const fn name(self) -> &'static str {
        match self {
            Offset::None => "none",
            Offset::Intercept => "intercept",
        }
    }

    /// 1 with an intercept, else 0.
    pub fn params(self) -> usize {
        match self {
            Offset::None => 0,
            Offset::Intercept => 1,
        }
    }
}

impl core::str::FromStr for Offset {
    type Err = crate::error::UnknownName;
    fn from_str(s: &str) -> core::result::Result<Self, Self::Err> {
        const NAMES: [&str; 2] = [Offset::None.name(), Offset::Intercept.name()];
        crate::error::parse_name(s, &Offset::ALL, Offset::name, "offset", &NAMES)
    }
}

/// An inclusive range of one order, e.g. `p ∈ 1..=6`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OrderRange {
    /// Smallest value (inclusive).
    pub min: u8,
    /// Largest value (inclusive).
    pub max: u8,
}

impl OrderRange {
    /// `min..=max`.
    pub const fn new(min: u8, max: u8) -> Self {
        OrderRange { min, max }
    }
    fn len(&self) -> usize {
        usize::from(self.max.saturating_sub(self.min)) + 1
    }
}

/// The search grid `P × Q × D` of the structure search (eq. 13).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Grid {
    /// Autoregressive orders.
    pub p: OrderRange,
    /// Input orders.
    pub q: OrderRange,
    /// Delays in samples.
    pub d: OrderRange,
}

impl Default for Grid {
    /// The paper's grid: p ∈ 1..=6, q ∈ 1..=6, d ∈ 0..=6 (252 candidates).
    fn default() -> Self {
        Grid::PAPER
    }
}

impl Grid {
    /// The paper's grid: p ∈ 1..=6, q ∈ 1..=6, d ∈ 0..=6 (252 candidates).
    pub const PAPER: Grid = Grid {
        p: OrderRange::new(1, 6),
        q: OrderRange::new(1, 6),
        d: OrderRange::new(0, 6),
    };
}

impl Grid {
    /// A grid containing exactly one structure.
    pub fn single(s: Structure) -> Self {
        Grid {
            p: OrderRange::new(s.p, s.p),
            q: OrderRange::new(s.q, s.q),
            d: OrderRange::new(s.d, s.d),
        }
    }

    /// `Ok` when every range is non-empty and within the compile-time maxima.
    pub fn check(&self) -> Result<()> {
        if self.p.min > self.p.max || self.q.min > self.q.max || self.d.min > self.d.max {
            return Err(Error::InvalidStructure);
        }
        Structure::new(self.p.min, self.q.min, self.d.min)?;
        Structure::new(self.p.max, self.q.max, self.d.max)?;
        Ok(())
    }

    /// The longest lag of any candidate, `max(p_max, d_max + q_max − 1)`: the number of
    /// initial samples that give every candidate a measured history
    /// ([`crate::MeasuredGram`]).
    pub fn longest_lag(&self) -> usize {
        let p = usize::from(self.p.max);
        let lag = (usize::from(self.d.max) + usize::from(self.q.max)).saturating_sub(1);
        if p > lag {
            p
        } else {
            lag
        }
    }

    /// Number of candidate structures.
    pub fn len(&self) -> usize {
        self.p.len() * self.q.len() * self.d.len()
    }

    /// `true` if the grid has no candidate (never, once [`Grid::check`] passed).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `index`-th candidate (p slowest, d fastest), `None` past the end.
    pub fn get(&self, index: usize) -> Option<Structure> {
        let nd = self.d.len();
        let nq = self.q.len();
        if index >= self.len() {
            return None;
        }
        let d = index % nd;
        let q = (index / nd) % nq;
        let p = index / (nd * nq);
        Some(Structure {
            p: self.p.min + p as u8,
            q: self.q.min + q as u8,
            d: self.d.min + d as u8,
        })
    }

    /// Iterates over all candidates in grid order (p slowest, d fastest: [`Grid::get`]'s).
    pub fn iter(&self) -> GridIter {
        let start = Structure {
            p: self.p.min,
            q: self.q.min,
            d: self.d.min,
        };
        GridIter {
            grid: *self,
            next: (!self.is_empty()).then_some(start),
        }
    }
}

/// The candidates of a [`Grid`] in order, by counting `d`, then `q`, then `p` up (no division
/// per candidate; on the ATmega2560 the index form cost 0.7 KB).
#[derive(Debug, Clone)]
pub struct GridIter {
    grid: Grid,
    next: Option<Structure>,
}

impl Iterator for GridIter {
    type Item = Structure;
    fn next(&mut self) -> Option<Structure> {
        let s = self.next?;
        let g = &self.grid;
        let mut n = s;
        self.next = if n.d < g.d.max {
            n.d += 1;
            Some(n)
        } else if n.q < g.q.max {
            n.d = g.d.min;
            n.q += 1;
            Some(n)
        } else if n.p < g.p.max {
            n.d = g.d.min;
            n.q = g.q.min;
            n.p += 1;
            Some(n)
        } else {
            None
        };
        Some(s)
    }
}

/// Maximum number of candidates of any grid: `P_MAX · Q_MAX · (D_MAX + 1)`.
pub const GRID_MAX: usize = P_MAX * Q_MAX * (D_MAX + 1);
