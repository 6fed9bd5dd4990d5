//! Independent reference: the explicit zero-padded regression matrix of eq. (6) summed
//! sample by sample in `f64` from the stored record, and a dense Gaussian-elimination
//! solve with partial pivoting. Shares no code with ridge-core.

use crate::{Record, DUTY_PER_COUNT, N, SLM_PER_COUNT};

/// Largest number of regressors handled (p + q ≤ 12).
pub const MAX: usize = 12;

/// `[XᵀX Xᵀy; yᵀX yᵀy]` of one structure in physical units, regressors in ARX order
/// `[y_{t-1} … y_{t-p}, u_{t-d} … u_{t-d-q+1}]`, target last.
#[derive(Debug, Clone)]
pub struct Normal {
    /// Number of regressors `p + q`.
    pub n: usize,
    /// Augmented matrix, `(n + 1) × (n + 1)` used.
    pub a: [[f64; MAX + 1]; MAX + 1],
}

/// Regressor `c` of row `t` (`c = n`: the target `y_t`).
fn column(rec: &Record, p: usize, d: usize, c: usize, n: usize, t: usize) -> f64 {
    let (x, lag, scale) = if c == n {
        (&rec.y, 0, SLM_PER_COUNT)
    } else if c < p {
        (&rec.y, c + 1, SLM_PER_COUNT)
    } else {
        (&rec.u, d + (c - p), DUTY_PER_COUNT)
    };
    if t >= lag {
        f64::from(x[t - lag]) * scale
    } else {
        0.0
    }
}

impl Normal {
    /// Brute force over all `N` rows.
    pub fn of(rec: &Record, p: usize, q: usize, d: usize) -> Self {
        let n = p + q;
        let mut a = [[0.0; MAX + 1]; MAX + 1];
        let mut row = [0.0; MAX + 1];
        for t in 0..N {
            for (c, r) in row.iter_mut().enumerate().take(n + 1) {
                *r = column(rec, p, d, c, n, t);
            }
            for i in 0..=n {
                for j in 0..=n {
                    a[i][j] += row[i] * row[j];
                }
            }
        }
        Normal { n, a }
    }

    /// `(XᵀX + γI)⁻¹ Xᵀy` by Gaussian elimination with partial pivoting
    /// (`None` if singular).
    pub fn solve(&self, gamma: f64) -> Option<[f64; MAX]> {
        let n = self.n;
        let mut m = [[0.0; MAX + 1]; MAX];
        for i in 0..n {
            for j in 0..n {
                m[i][j] = self.a[i][j] + if i == j { gamma } else { 0.0 };
            }
            m[i][n] = self.a[i][n];
        }
        for k in 0..n {
            let mut piv = k;
            for i in k + 1..n {
                if abs(m[i][k]) > abs(m[piv][k]) {
                    piv = i;
                }
            }
            if m[piv][k] == 0.0 {
                return None;
            }
            m.swap(k, piv);
            for i in k + 1..n {
                let f = m[i][k] / m[k][k];
                for j in k..=n {
                    m[i][j] -= f * m[k][j];
                }
            }
        }
        let mut w = [0.0; MAX];
        for i in (0..n).rev() {
            let mut s = m[i][n];
            for j in i + 1..n {
                s -= m[i][j] * w[j];
            }
            w[i] = s / m[i][i];
        }
        Some(w)
    }
}

/// `‖y − Xw‖²` summed row by row (physical units), `w` in ARX order.
pub fn rss(rec: &Record, p: usize, q: usize, d: usize, w: &[f64]) -> f64 {
    let n = p + q;
    let mut s = 0.0;
    for t in 0..N {
        let mut e = column(rec, p, d, n, n, t);
        for (c, wc) in w.iter().enumerate().take(n) {
            e -= wc * column(rec, p, d, c, n, t);
        }
        s += e * e;
    }
    s
}

fn abs(x: f64) -> f64 {
    if x < 0.0 {
        -x
    } else {
        x
    }
}
