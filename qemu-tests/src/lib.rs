#![no_std]
// Small dense linear algebra reads best with the indices of its formulas.
#![allow(clippy::needless_range_loop)]
//! Helpers for the on-target tests of ridge-core (`tests/on_target.rs`), all written
//! independently of ridge-core so that they can serve as truth:
//!
//! - [`Rng`]: a deterministic integer PRNG (xorshift32);
//! - [`Record`] / [`Plant`]: a multilevel duty input and a known ARX plant simulated
//!   in `f32` on the target, producing integer PWM and SFM3300 counts;
//! - [`dense`]: brute-force normal equations from the stored record and a dense
//!   Gaussian-elimination solve in `f64`;
//! - [`clock`]: SysTick-based instruction counter (QEMU `-icount`).

pub mod clock;
pub mod dense;

/// Samples in a record: 30 s at 100 Hz.
pub const N: usize = 3000;

/// xorshift32 (Marsaglia): deterministic, integer only.
#[derive(Debug, Clone)]
pub struct Rng(u32);

impl Rng {
    /// A generator from a seed (any value; zero is mapped to a fixed non-zero state).
    pub fn new(seed: u32) -> Self {
        Rng(if seed == 0 { 0x9E37_79B9 } else { seed })
    }

    /// Next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        x
    }

    /// Uniform in `lo..=hi` (modulo bias is irrelevant here).
    pub fn range(&mut self, lo: i32, hi: i32) -> i32 {
        let span = (hi - lo) as u32 + 1;
        lo + (self.next_u32() % span) as i32
    }
}

use ridge_pump_firmware::units::SCALE;

/// Duty fraction per count (duty in 1/10 000 of full scale): the rig's `units::SCALE.u`.
pub const DUTY_PER_COUNT: f64 = SCALE.u;
/// Slm per SFM3300 count: the rig's `units::SCALE.y`.
pub const SLM_PER_COUNT: f64 = SCALE.y;

/// A known ARX plant `y_t = θ₁ y_{t-1} + θ₂ y_{t-2} + φ₀ u_{t-d} + φ₁ u_{t-d-1} + e_t`
/// in physical units (slm, duty fraction).
#[derive(Debug, Clone, Copy)]
pub struct Plant {
    /// `θ₁, θ₂`.
    pub theta: [f32; 2],
    /// `φ₀, φ₁` in slm per unit duty.
    pub phi: [f32; 2],
    /// Input delay in samples.
    pub d: usize,
    /// Equation noise: uniform integer in `±noise` SFM3300 counts.
    pub noise: i32,
}

impl Plant {
    /// True (p, q, d) = (2, 2, 3): θ = [1.5, −0.7], φ = 20 · [0.5, 0.3] slm per duty
    /// (static gain 80 slm per duty: 16..72 slm for duty 0.2..0.9), noise ±20 counts
    /// (±0.17 slm).
    pub const PUMP_223: Plant = Plant {
        theta: [1.5, -0.7],
        phi: [10.0, 6.0],
        d: 3,
        noise: 20,
    };
}

/// One input/output record in raw counts (PWM duty 2000..9000, SFM3300 `raw − 32768`).
pub struct Record {
    /// Input counts.
    pub u: [i32; N],
    /// Output counts.
    pub y: [i32; N],
}

impl Record {
    /// A multilevel input (levels uniform in 2000..=9000 counts, each held 1..=8
    /// samples) through `plant`, simulated in `f32`; the measurement is rounded to whole
    /// counts and fed back (equation-error form, zero history), so the record is exactly
    /// an ARX process whose noise is the uniform term plus rounding.
    pub fn simulate(plant: &Plant, seed: u32) -> Self {
        let mut rng = Rng::new(seed);
        let mut rec = Record {
            u: [0; N],
            y: [0; N],
        };
        // φ in counts: slm/duty · (duty/count) / (slm/count).
        let k = (DUTY_PER_COUNT / SLM_PER_COUNT) as f32;
        let b = [plant.phi[0] * k, plant.phi[1] * k];
        let mut t = 0;
        while t < N {
            let level = rng.range(2000, 9000);
            let hold = 1 + (rng.next_u32() % 8) as usize;
            for _ in 0..hold {
                if t < N {
                    rec.u[t] = level;
                    t += 1;
                }
            }
        }
        let at = |x: &[i32; N], t: usize, lag: usize| -> f32 {
            if t >= lag {
                x[t - lag] as f32
            } else {
                0.0
            }
        };
        for t in 0..N {
            let e = rng.range(-plant.noise, plant.noise) as f32;
            let v = plant.theta[0] * at(&rec.y, t, 1)
                + plant.theta[1] * at(&rec.y, t, 2)
                + b[0] * at(&rec.u, t, plant.d)
                + b[1] * at(&rec.u, t, plant.d + 1)
                + e;
            rec.y[t] = round(v);
        }
        rec
    }
}

/// Round half away from zero to `i32` (no libm needed).
pub fn round(v: f32) -> i32 {
    if v >= 0.0 {
        (v + 0.5) as i32
    } else {
        (v - 0.5) as i32
    }
}

/// `|a − b| / max(|b|, tiny)`.
pub fn rel(a: f64, b: f64) -> f64 {
    let d = if a > b { a - b } else { b - a };
    let m = if b < 0.0 { -b } else { b };
    d / if m > 1e-300 { m } else { 1e-300 }
}
