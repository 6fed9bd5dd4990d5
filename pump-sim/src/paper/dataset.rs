//! The simulated records of the paper's experiments and their exact statistics.
//!
//! Every record is simulated by [`crate::record`] on the reference blower
//! ([`PumpParams::default`]) and fed to the statistics exactly as the firmware feeds them:
//! an [`IntGram`] of `(raw_u, raw_y − 32768)`, converted with [`SCALE`] at solve time, so
//! models are in duty fraction (0..1) and slm.

use ridge_core::{Error, IntGram, Normal, Real, Result};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::SCALE;

use super::RECORDS;
use crate::{record, Log, PumpParams, Sfm3300Params};

/// The four simulated records and their exact integer statistics.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Sensor-noise seed of every record.
    pub seed: u64,
    /// Logs in [`RECORDS`] order.
    pub logs: Vec<Log>,
    /// Integer statistics of each log, in [`RECORDS`] order.
    pub grams: Vec<IntGram>,
}

/// Exact statistics of a log, fed as the firmware feeds them:
/// `push(raw_u, raw_y − 32768)`.
pub fn int_gram(log: &Log) -> Result<IntGram> {
    let mut g = IntGram::new();
    for (&u, &y) in log.raw_u.iter().zip(&log.raw_y) {
        g.push(i32::from(u), i32::from(y) - 32_768)?;
    }
    Ok(g)
}

/// Index of a record in [`RECORDS`].
pub fn record_index(r: Record) -> Option<usize> {
    RECORDS.iter().position(|&x| x == r)
}

impl Dataset {
    /// Simulates the four records on the reference pump with sensor-noise seed `seed`.
    pub fn simulate(seed: u64) -> Result<Self> {
        let params = PumpParams::default();
        let logs: Vec<Log> = RECORDS.iter().map(|&r| record(r, &params, seed)).collect();
        let grams = logs.iter().map(int_gram).collect::<Result<Vec<_>>>()?;
        Ok(Dataset { seed, logs, grams })
    }

    /// The log of record `r` (one of [`RECORDS`]).
    pub fn log(&self, r: Record) -> Result<&Log> {
        record_index(r)
            .and_then(|i| self.logs.get(i))
            .ok_or(Error::InvalidParameter)
    }

    /// The solve-time statistics of record `r` in scalar `T`.
    pub fn normal<T: Real>(&self, r: Record) -> Result<Normal<T>> {
        record_index(r)
            .and_then(|i| self.grams.get(i))
            .ok_or(Error::InvalidParameter)?
            .normal(SCALE)
    }
}

/// Summary of one simulated record (for the scale of the RMSE figures).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordSummary {
    /// Record.
    pub record: Record,
    /// Samples.
    pub samples: usize,
    /// Duty range, fraction 0..1.
    pub u_range: (f64, f64),
    /// Samples where the duty changes (`u_t ≠ u_{t−1}`): the only samples at which a
    /// delay `d` and a delay `d + 1` give different regressors.
    pub u_changes: usize,
    /// Flow mean, slm.
    pub y_mean: f64,
    /// Flow standard deviation, slm.
    pub y_std: f64,
    /// Flow range, slm.
    pub y_range: (f64, f64),
    /// RMS of the simulated sensor's noise standard deviation over the record
    /// (`Sfm3300Params::default().noise_std` at the measured flows), slm: the floor of any
    /// one-step RMSE.
    pub noise_rms: f64,
}

impl RecordSummary {
    /// Summarises `log`, a simulation of record `r`.
    pub fn of(r: Record, log: &Log) -> RecordSummary {
        let n = log.len().max(1) as f64;
        let sensor = Sfm3300Params::default();
        let mean = log.y.iter().sum::<f64>() / n;
        let var = log.y.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / n;
        let range = |v: &[f64]| {
            v.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                })
        };
        RecordSummary {
            record: r,
            samples: log.len(),
            u_range: range(&log.u),
            u_changes: log.raw_u.windows(2).filter(|w| w[0] != w[1]).count(),
            y_mean: mean,
            y_std: var.sqrt(),
            y_range: range(&log.y),
            noise_rms: (log
                .y
                .iter()
                .map(|&y| sensor.noise_std(y).powi(2))
                .sum::<f64>()
                / n)
                .sqrt(),
        }
    }
}
