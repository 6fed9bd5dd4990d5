//! Scores of a model on a simulated log: one-step-ahead and free-run RMSE.

use ridge_core::{ArxModel, Error, Evaluation, Result};

use crate::Log;

/// One-step and free-run RMSE of a model on one record (slm), seeded with measured samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rmse {
    /// Free-run simulation RMSE (the model feeds back its own outputs).
    pub free_run: f64,
    /// One-step-ahead RMSE (measured past outputs).
    pub one_step: f64,
    /// Samples scored (`N − m`).
    pub scored: u32,
}

impl Rmse {
    /// The RMSE of `model` on `log`, scored by [`Evaluation`]: both predictors seeded with the
    /// first `m = max(p, d + q − 1)` measured samples, samples `m..N` scored.
    pub fn of(model: &ArxModel<f64>, log: &Log) -> Result<Rmse> {
        let mut ev = Evaluation::new(*model);
        for (&u, &y) in log.u.iter().zip(&log.y) {
            ev.push(u, y);
        }
        match (ev.free_run(), ev.one_step()) {
            (Some(f), Some(o)) => Ok(Rmse {
                free_run: f.rmse,
                one_step: o.rmse,
                scored: f.n,
            }),
            _ => Err(Error::TooShort {
                needed: model.structure().seed_len() as u32 + 1,
                have: log.len() as u32,
            }),
        }
    }

    /// Mean of a set of RMSE figures (`scored`: their total).
    pub fn mean(v: &[Rmse]) -> Rmse {
        let n = v.len().max(1) as f64;
        Rmse {
            free_run: v.iter().map(|r| r.free_run).sum::<f64>() / n,
            one_step: v.iter().map(|r| r.one_step).sum::<f64>() / n,
            scored: v.iter().map(|r| r.scored).sum(),
        }
    }
}
