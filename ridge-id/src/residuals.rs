//! Residual analysis as MATLAB's `resid`: whiteness of the one-step residuals and their
//! independence of the input, from one streaming pass in constant memory ([`ResidualStats`])
//! (drawn by [`crate::plot::write_residuals_png`]).
//!
//! On the one-step residuals `e_t` of the scored samples (`t = m..N`, `N_s` of them) and the
//! input with its mean over those samples removed, `u′`:
//!
//! ```text
//! r_k = Σ e_t e_{t−k} / Σ e_t²                   k = 1..=25
//! c_k = Σ e_t u′_{t−k} / √(Σ e_t² · Σ u′_t²)     k = 0..=25
//! ```
//!
//! each numerator summed over the pairs with both samples scored; the 99 % bound of a white
//! sequence independent of the input is `2.576 / √N_s`. `white`: every `|r_k|` within it;
//! `independent`: every `|c_k|` within it.

/// Largest lag of the autocorrelation (`k = 1..=LAGS`) and the cross-correlation
/// (`k = 0..=LAGS`), MATLAB `resid`'s default.
pub const LAGS: usize = 25;

/// The 99 % point of the standard normal distribution (two-sided).
pub const Z99: f64 = 2.576;

/// The figures of a residual analysis (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Residuals {
    /// Samples analysed `N_s`.
    pub n: u32,
    /// `r_1 … r_25`, dimensionless.
    pub autocorr: [f64; LAGS],
    /// `c_0 … c_25`, dimensionless.
    pub crosscorr: [f64; LAGS + 1],
    /// `2.576 / √N_s`.
    pub bound: f64,
    /// Every `|r_k| ≤ bound`.
    pub white: bool,
    /// Every `|c_k| ≤ bound`.
    pub independent: bool,
}

/// One streaming pass of a residual analysis: [`ResidualStats::push`] each scored sample's
/// input and one-step residual, then [`ResidualStats::finish`]. Memory: the last 26 inputs and
/// 25 residuals.
#[derive(Debug, Clone)]
pub struct ResidualStats {
    n: u64,
    /// The first input, subtracted from every input: `u′` does not change, and the sums do
    /// not cancel when the input has a large mean.
    u_ref: f64,
    /// The last `LAGS + 1` residuals and inputs, each stored twice
    /// (`hist[pos + j] = hist[pos + j + LAGS + 1]`), so that `hist[pos..pos + LAGS + 1]` is
    /// newest first: `e_{t−k}` at `pos + k` after a push (no shift of 26 values a sample).
    e_hist: [f64; 2 * (LAGS + 1)],
    u_hist: [f64; 2 * (LAGS + 1)],
    pos: usize,
    see: f64,
    su: f64,
    suu: f64,
    /// `Σ e_t e_{t−k}`, `k = 1..=25` (index `k`).
    ee: [f64; LAGS + 1],
    /// `Σ e_t ũ_{t−k}` and `Σ e_t` over the pairs of lag `k`.
    eu: [f64; LAGS + 1],
    e_pairs: [f64; LAGS + 1],
}

impl Default for ResidualStats {
    fn default() -> Self {
        Self::new()
    }
}

impl ResidualStats {
    /// Empty.
    pub fn new() -> Self {
        ResidualStats {
            n: 0,
            u_ref: 0.0,
            e_hist: [0.0; 2 * (LAGS + 1)],
            u_hist: [0.0; 2 * (LAGS + 1)],
            pos: 0,
            see: 0.0,
            su: 0.0,
            suu: 0.0,
            ee: [0.0; LAGS + 1],
            eu: [0.0; LAGS + 1],
            e_pairs: [0.0; LAGS + 1],
        }
    }

    /// Adds the next scored sample: its input `u_t` and one-step residual `e_t = y_t − ŷ_t`.
    pub fn push(&mut self, u: f64, e: f64) {
        if self.n == 0 {
            self.u_ref = u;
        }
        let u = u - self.u_ref;
        const W: usize = LAGS + 1;
        self.pos = self.pos.checked_sub(1).unwrap_or(W - 1);
        let p = self.pos;
        self.e_hist[p] = e;
        self.e_hist[p + W] = e;
        self.u_hist[p] = u;
        self.u_hist[p + W] = u;
        self.n += 1;
        let (e_hist, u_hist) = (&self.e_hist[p..p + W], &self.u_hist[p..p + W]);
        // Lags up to n − 1 have a pair.
        let pairs = (self.n as usize).min(W);
        for k in 0..pairs {
            self.ee[k] += e * e_hist[k];
            self.eu[k] += e * u_hist[k];
            self.e_pairs[k] += e;
        }
        self.su += u;
        self.suu += u * u;
        self.see = self.ee[0];
    }

    /// The figures; `None` before 2 samples, or with zero residuals or a constant input.
    pub fn finish(&self) -> Option<Residuals> {
        if self.n < 2 {
            return None;
        }
        let n = self.n as f64;
        let mean = self.su / n;
        let su2 = self.suu - n * mean * mean;
        if !(self.see > 0.0 && su2 > 0.0) {
            return None;
        }
        let norm = (self.see * su2).sqrt();
        let mut autocorr = [0.0; LAGS];
        for (k, r) in autocorr.iter_mut().enumerate() {
            *r = self.ee[k + 1] / self.see;
        }
        let mut crosscorr = [0.0; LAGS + 1];
        for (k, c) in crosscorr.iter_mut().enumerate() {
            *c = (self.eu[k] - mean * self.e_pairs[k]) / norm;
        }
        let bound = Z99 / n.sqrt();
        Some(Residuals {
            n: u32::try_from(self.n).unwrap_or(u32::MAX),
            autocorr,
            crosscorr,
            bound,
            white: autocorr.iter().all(|r| r.abs() <= bound),
            independent: crosscorr.iter().all(|c| c.abs() <= bound),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The streaming sums against the definition written out over stored sequences.
    #[test]
    fn equals_the_explicit_sums() {
        let n = 300;
        let mut s = 12345u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let u: Vec<f64> = (0..n)
            .map(|t| 40.0 + ((t / 7) % 3) as f64 + rnd())
            .collect();
        let e: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let mut st = ResidualStats::new();
        for t in 0..n {
            st.push(u[t], e[t]);
        }
        let r = st.finish().unwrap();
        let ubar = u.iter().sum::<f64>() / n as f64;
        let up: Vec<f64> = u.iter().map(|v| v - ubar).collect();
        let see: f64 = e.iter().map(|v| v * v).sum();
        let suu: f64 = up.iter().map(|v| v * v).sum();
        for k in 1..=LAGS {
            let want = (k..n).map(|t| e[t] * e[t - k]).sum::<f64>() / see;
            assert!((r.autocorr[k - 1] - want).abs() < 1e-12, "r_{k}");
        }
        for k in 0..=LAGS {
            let want = (k..n).map(|t| e[t] * up[t - k]).sum::<f64>() / (see * suu).sqrt();
            assert!((r.crosscorr[k] - want).abs() < 1e-12, "c_{k}");
        }
        assert_eq!(r.bound, 2.576 / (n as f64).sqrt());
        assert_eq!(r.n, n as u32);
    }
}
