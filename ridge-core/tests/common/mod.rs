//! Independent test helpers: a seeded generator, an ARX simulator written from eq. (1),
//! the explicit zero-padded regression matrix of eq. (6) and dense reference solves
//! (nalgebra), none of which share code with the crate under test.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use ridge_core::{Regressor, System};

/// xorshift64* with Box–Muller normals.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    pub fn range_i32(&mut self, lo: i32, hi: i32) -> i32 {
        lo + (self.next_u64() % (hi - lo + 1) as u64) as i32
    }
}

/// A random multilevel input: levels uniform in [lo, hi], each held 1..=hold samples.
pub fn multilevel(rng: &mut Rng, n: usize, lo: f64, hi: f64, hold: usize) -> Vec<f64> {
    let mut u = Vec::with_capacity(n);
    while u.len() < n {
        let level = lo + (hi - lo) * rng.uniform();
        let len = 1 + (rng.next_u64() as usize) % hold;
        for _ in 0..len {
            if u.len() < n {
                u.push(level);
            }
        }
    }
    u
}

/// `y_t = Σ θ_i y_{t-i} + Σ φ_j u_{t-j-d} + c + e_t`, zero history, `e ~ N(0, σ²)`.
pub fn simulate(
    theta: &[f64],
    phi: &[f64],
    d: usize,
    c: f64,
    u: &[f64],
    sigma: f64,
    seed: u64,
) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let mut y: Vec<f64> = Vec::with_capacity(u.len());
    for t in 0..u.len() {
        let mut v = c;
        for (i, th) in theta.iter().enumerate() {
            if t > i {
                v += th * y[t - 1 - i];
            }
        }
        for (j, ph) in phi.iter().enumerate() {
            if t >= j + d {
                v += ph * u[t - j - d];
            }
        }
        y.push(v + sigma * rng.normal());
    }
    y
}

/// The explicit regression matrix of eq. (6) (zero-padded) for the columns of
/// `system` in its internal order, plus the target column last.
pub fn design(system: &System<f64>, u: &[f64], y: &[f64]) -> DMatrix<f64> {
    let n = system.params();
    let rows = u.len();
    DMatrix::from_fn(rows, n + 1, |t, col| match system.regressor(col).unwrap() {
        Regressor::Output(k) => {
            let k = k as usize;
            if t >= k {
                y[t - k]
            } else {
                0.0
            }
        }
        Regressor::Input(k) => {
            let k = k as usize;
            if t >= k {
                u[t - k]
            } else {
                0.0
            }
        }
        Regressor::Constant => 1.0,
    })
}

/// `[XᵀX Xᵀy; yᵀX yᵀy]` by brute force.
pub fn augmented(system: &System<f64>, u: &[f64], y: &[f64]) -> DMatrix<f64> {
    let x = design(system, u, y);
    x.transpose() * &x
}

/// Dense `(XᵀX + γI)⁻¹ Xᵀy` (no regularisation of a constant column), by LU.
pub fn ridge_reference(system: &System<f64>, u: &[f64], y: &[f64], gamma: f64) -> DVector<f64> {
    let n = system.params();
    let m = augmented(system, u, y);
    let mut a = m.view((0, 0), (n, n)).into_owned();
    for i in 0..n {
        if system.regressor(i) != Some(Regressor::Constant) {
            a[(i, i)] += gamma;
        }
    }
    let b = m.view((0, n), (n, 1)).into_owned();
    a.lu().solve(&b).unwrap().column(0).into_owned()
}

/// RSS of `w` by brute force on the explicit matrix.
pub fn rss_reference(system: &System<f64>, u: &[f64], y: &[f64], w: &[f64]) -> f64 {
    let x = design(system, u, y);
    let n = system.params();
    let mut s = 0.0;
    for t in 0..x.nrows() {
        let mut e = x[(t, n)];
        for i in 0..n {
            e -= x[(t, i)] * w[i];
        }
        s += e * e;
    }
    s
}

/// Internal-order coefficient vector of a model, for comparisons with dense solves.
pub fn internal(system: &System<f64>, model: &ridge_core::ArxModel<f64>) -> Vec<f64> {
    (0..system.params())
        .map(|i| match system.regressor(i).unwrap() {
            Regressor::Output(k) => model.theta()[k as usize - 1],
            Regressor::Input(k) => model.phi()[(k - model.structure().d) as usize],
            Regressor::Constant => model.intercept(),
        })
        .collect()
}
