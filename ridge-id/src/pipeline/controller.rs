//! The pipeline's controller step (`--control`): the model as the device's, its checks and
//! design, and with `--plot` the designed loop's simulated setpoint step ([`control()`] →
//! [`Controlled`]).

use ridge_core_host::ArxModel;

use super::read::Records;
use crate::control::{self, ControlReport, LogSpan, StepResponse};
use crate::error::IdError;
use crate::options::Options;

/// What `--control` produced (all `None` without it).
#[derive(Debug)]
pub(super) struct Controlled {
    /// The design, or why it was refused.
    pub report: Option<ControlReport>,
    /// The designed controller's setpoint step simulated on the model (`--plot`, a designed
    /// controller, a model with a finite steady state).
    pub step: Option<StepResponse>,
}

/// Checks `model` and designs its controller as the firmware does, for the device's orders
/// (p, q, d ≤ 6); a refusal is in [`Controlled::report`], not an error. With `--plot`, also
/// simulates the designed loop's setpoint step.
///
/// Errors: a structure beyond the device's orders; empty input limits of the simulated loop
/// (checked even without `--plot`: bad ones are a usage error whatever is printed).
pub(super) fn control(
    opts: &Options,
    rec: &Records,
    model: &ArxModel<f64>,
) -> Result<Controlled, IdError> {
    let span = LogSpan {
        u: rec.est.u_range.1 - rec.est.u_range.0,
        y: rec.est.y_range.1 - rec.est.y_range.0,
    };
    let device = opts
        .control
        .as_ref()
        .map(|_| control::device_model(model))
        .transpose()?;
    let report = opts
        .control
        .as_ref()
        .zip(device.as_ref())
        .map(|(c, m)| control::control(m, c, span));
    let limits = opts
        .control
        .as_ref()
        .map(|c| c.limits(rec.est.u_range))
        .transpose()?;
    let step = match (&opts.plot, &report, limits, &device) {
        (Some(_), Some(r), Some(limits), Some(device)) => r
            .designed()
            .and_then(|d| control::simulate_step(device, &d.design, limits, r.options.ts)),
        _ => None,
    };
    Ok(Controlled { report, step })
}
