//! Simulation-error refinement and structure choice by validation free-run error
//! (`--refine oe`, `--select free-run`).
//!
//! - [`output_error`]: the output-error fit of a structure, Gauss–Newton with
//!   Levenberg–Marquardt damping on the free-run (simulation) error of the estimation record,
//!   started from the ARX estimate (L. Ljung, *System Identification*, 2nd ed., §10.2: the
//!   prediction-error method for an output-error model). The free run is seeded with the
//!   first `m = max(p, d + q − 1)` measured outputs and its error summed over `m..N`, as the
//!   scores are. The sensitivities `ψ_t = ∂ŷ_t/∂w` follow `ψ_t = x̂_t + Σ θ_i ψ_{t−i}`, `x̂_t`
//!   the regressor of the simulated outputs.
//! - [`best_free_run`]: the candidate of a list with the lowest free-run RMSE on a record
//!   (ties within 1 % broken by the criterion).
//!
//! Both hold the record in memory (16 bytes a sample): they run only when asked for.

use ridge_core_host::{ArxModel, Evaluation, Offset};

use crate::error::IdError;
use crate::input::Input;

/// `(u, y)` of a whole record: the run's [`Input`], so that standard input, a pipe or a FIFO
/// (read once, into memory) and a `--phase` segment are the samples the run identified on,
/// not a file opened again.
pub fn load(input: &Input) -> Result<Vec<(f64, f64)>, IdError> {
    input.samples()?.map(|s| s.map(|s| (s.u, s.y))).collect()
}

/// Free-run RMSE of `model` on `data` (seeded with its first `m` measured outputs, scored on
/// `m..N`); `None` when nothing is scored or the run diverges.
pub fn free_run_rmse(model: &ArxModel<f64>, data: &[(f64, f64)]) -> Option<f64> {
    let mut ev = Evaluation::new(*model);
    for &(u, y) in data {
        ev.push(u, y);
    }
    ev.free_run().map(|m| m.rmse).filter(|r| r.is_finite())
}

/// Free-run RMSEs within this fraction of the lowest are a tie for [`best_free_run`]: a
/// validation record cannot tell them apart (the RMSE of `N` samples of white errors varies by
/// about `1/√(2N)`: 2.4 % at `N` = 900, 0.7 % at 10 000), and the lowest of them is often a
/// larger structure fitting the record's noise.
pub const FREE_RUN_TIE: f64 = 0.01;

/// The candidate whose free-run RMSE on `data` is lowest, with it, among `candidates`
/// (models with their criterion value): of those within [`FREE_RUN_TIE`] of the lowest RMSE,
/// the one the criterion ranks first (it penalises the number of coefficients).
pub fn best_free_run(
    candidates: &[(ArxModel<f64>, f64)],
    data: &[(f64, f64)],
) -> Option<(ArxModel<f64>, f64)> {
    let mut evs: Vec<Evaluation<f64>> = candidates.iter().map(|c| Evaluation::new(c.0)).collect();
    for &(u, y) in data {
        for ev in &mut evs {
            ev.push(u, y);
        }
    }
    let scored: Vec<(ArxModel<f64>, f64, f64)> = candidates
        .iter()
        .zip(&evs)
        .filter_map(|(&(m, score), ev)| ev.free_run().map(|f| (m, score, f.rmse)))
        .filter(|c| c.2.is_finite())
        .collect();
    let lowest = scored.iter().map(|c| c.2).min_by(f64::total_cmp)?;
    scored
        .into_iter()
        .filter(|c| c.2 <= lowest * (1.0 + FREE_RUN_TIE))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(m, _, rmse)| (m, rmse))
}

/// Parameters as a vector `[θ_1 … θ_p, φ_0 … φ_{q−1}, (c)]`.
fn params(m: &ArxModel<f64>) -> Vec<f64> {
    let mut w: Vec<f64> = m.theta().iter().chain(m.phi()).copied().collect();
    if m.offset() == Offset::Intercept {
        w.push(m.intercept());
    }
    w
}

fn model_of(like: &ArxModel<f64>, w: &[f64]) -> Option<ArxModel<f64>> {
    let s = like.structure();
    let (p, q) = (usize::from(s.p), usize::from(s.q));
    let c = w.get(p + q).copied().unwrap_or(0.0);
    ArxModel::new(&w[..p], &w[p..p + q], s.d, like.offset(), c).ok()
}

/// Free-run error sum of squares of `w` and, if `grad`, `JᵀJ` and `Jᵀe` (`J = ∂ŷ/∂w`).
fn simulate(
    like: &ArxModel<f64>,
    w: &[f64],
    data: &[(f64, f64)],
    grad: bool,
) -> (f64, Vec<f64>, Vec<f64>) {
    let s = like.structure();
    let (p, q, d) = (usize::from(s.p), usize::from(s.q), usize::from(s.d));
    let k = w.len();
    let m = s.seed_len();
    let n = data.len();
    let mut yh: Vec<f64> = data.iter().map(|v| v.1).collect();
    let mut psi = if grad { vec![0.0; n * k] } else { Vec::new() };
    let (mut jtj, mut jte) = (vec![0.0; k * k], vec![0.0; k]);
    let mut sse = 0.0;
    let mut x = vec![0.0; k];
    for t in m..n {
        for i in 0..p {
            x[i] = yh[t - 1 - i];
        }
        for j in 0..q {
            x[p + j] = data[t - d - j].0;
        }
        if k > p + q {
            x[p + q] = 1.0;
        }
        let v: f64 = w.iter().zip(&x).map(|(a, b)| a * b).sum();
        yh[t] = v;
        let e = data[t].1 - v;
        sse += e * e;
        if grad {
            for c in 0..k {
                let mut g = x[c];
                for i in 0..p {
                    if t >= m + 1 + i {
                        g += w[i] * psi[(t - 1 - i) * k + c];
                    }
                }
                psi[t * k + c] = g;
            }
            let row = &psi[t * k..t * k + k];
            for a in 0..k {
                jte[a] += row[a] * e;
                for b in 0..=a {
                    jtj[a * k + b] += row[a] * row[b];
                }
            }
        }
    }
    for a in 0..k {
        for b in 0..a {
            jtj[b * k + a] = jtj[a * k + b];
        }
    }
    (if sse.is_finite() { sse } else { f64::INFINITY }, jtj, jte)
}

/// Solves `A x = b` (`A` symmetric positive definite, `k × k`) by Cholesky; `None` if it is
/// not.
fn solve(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let k = b.len();
    let mut l = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..=i {
            let mut s = a[i * k + j];
            for r in 0..j {
                s -= l[i * k + r] * l[j * k + r];
            }
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * k + i] = s.sqrt();
            } else {
                l[i * k + j] = s / l[j * k + j];
            }
        }
    }
    let mut z = b.to_vec();
    for i in 0..k {
        for r in 0..i {
            z[i] -= l[i * k + r] * z[r];
        }
        z[i] /= l[i * k + i];
    }
    for i in (0..k).rev() {
        for r in i + 1..k {
            z[i] -= l[r * k + i] * z[r];
        }
        z[i] /= l[i * k + i];
    }
    Some(z)
}

/// The output-error fit of `start`'s structure on `data` (see the [module docs](self)):
/// the refined model and the Gauss–Newton steps taken. At most `max_iter` steps; stops when
/// a step improves the sum of squares by less than 1e-10 of it. Never worse than `start` on
/// `data`.
pub fn output_error(
    start: &ArxModel<f64>,
    data: &[(f64, f64)],
    max_iter: u32,
) -> (ArxModel<f64>, u32) {
    let mut w = params(start);
    let (mut cost, mut jtj, mut jte) = simulate(start, &w, data, true);
    let mut lambda = 1e-3;
    let mut steps = 0;
    'outer: for _ in 0..max_iter {
        loop {
            let mut a = jtj.clone();
            let k = w.len();
            for i in 0..k {
                a[i * k + i] += lambda * jtj[i * k + i].max(1e-12);
            }
            if let Some(step) = solve(&a, &jte) {
                let w2: Vec<f64> = w.iter().zip(&step).map(|(a, b)| a + b).collect();
                let (c2, _, _) = simulate(start, &w2, data, false);
                if c2 < cost {
                    let done = cost - c2 < 1e-10 * cost;
                    w = w2;
                    (cost, jtj, jte) = simulate(start, &w, data, true);
                    steps += 1;
                    lambda = (lambda / 10.0).max(1e-12);
                    if done {
                        break 'outer;
                    }
                    break;
                }
            }
            lambda *= 10.0;
            if lambda > 1e10 {
                break 'outer;
            }
        }
    }
    (model_of(start, &w).unwrap_or(*start), steps)
}

/// What `--refine oe` did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refinement {
    /// Gauss–Newton steps taken.
    pub steps: u32,
    /// Free-run RMSE on the estimation record before and after (output units).
    pub estimation: (f64, f64),
    /// Free-run RMSE on the validation record before and after, if one was given.
    pub validation: Option<(f64, f64)>,
    /// `true` when the refined model replaced the ARX one (always without a validation
    /// record, else when it lowered the validation free-run RMSE).
    pub kept: bool,
}

/// Applies [`Refine::Oe`] to `model` (estimation record `input`, validation record `val`).
///
/// [`Refine::Oe`]: crate::options::Refine::Oe
pub fn refine(
    model: ArxModel<f64>,
    input: &Input,
    val: Option<&[(f64, f64)]>,
) -> Result<(ArxModel<f64>, Refinement), IdError> {
    let est = load(input)?;
    let (oe, steps) = output_error(&model, &est, 200);
    let nan = f64::NAN;
    let estimation = (
        free_run_rmse(&model, &est).unwrap_or(nan),
        free_run_rmse(&oe, &est).unwrap_or(nan),
    );
    let validation = val.map(|v| {
        (
            free_run_rmse(&model, v).unwrap_or(nan),
            free_run_rmse(&oe, v).unwrap_or(nan),
        )
    });
    let kept = match validation {
        Some((before, after)) => after < before,
        None => steps > 0,
    };
    let r = Refinement {
        steps,
        estimation,
        validation,
        kept,
    };
    Ok((if kept { oe } else { model }, r))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An output-error plant `y = B/A u + white noise` (not an ARX one): least squares on the
    /// equation error is biased, the output-error fit recovers the plant.
    #[test]
    fn output_error_fit_recovers_an_output_error_plant() {
        let n = 3000;
        let mut s = 7u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut u = Vec::with_capacity(n);
        while u.len() < n {
            let level = 2.0 * rnd();
            let hold = 2 + (10.0 * (rnd() + 0.5)) as usize;
            u.extend(std::iter::repeat_n(level, hold));
        }
        u.truncate(n);
        // x_t = 1.2 x_{t-1} − 0.5 x_{t-2} + 0.8 u_{t-1}; y = x + e, e uniform, std ≈ 0.29.
        let mut x = vec![0.0; n];
        for t in 2..n {
            x[t] = 1.2 * x[t - 1] - 0.5 * x[t - 2] + 0.8 * u[t - 1];
        }
        let data: Vec<(f64, f64)> = u.iter().zip(&x).map(|(&u, &x)| (u, x + rnd())).collect();
        // A deliberately wrong start (what a biased ARX estimate looks like).
        let start = ArxModel::new(&[0.9, -0.2], &[1.0], 1, Offset::None, 0.0).unwrap();
        let (m, steps) = output_error(&start, &data, 100);
        assert!(steps > 0);
        for (got, want) in m.theta().iter().chain(m.phi()).zip([1.2, -0.5, 0.8]) {
            assert!((got - want).abs() < 0.03, "{got} vs {want}");
        }
        let clean: Vec<(f64, f64)> = u.iter().zip(&x).map(|(&u, &x)| (u, x)).collect();
        assert!(free_run_rmse(&m, &clean).unwrap() < free_run_rmse(&start, &clean).unwrap());
    }
}
