//! What the plots' axes say ([`Axes`]): the quantity and unit of the record's output and
//! input and of time. ridge-id reads logs whose units it does not know: a plain CSV's axes are
//! its column names, in samples; a pump capture's are the pump's units.

use ridge_pump_firmware::units::SAMPLE_RATE_HZ;

/// The axis labels of a run's plots.
#[derive(Debug, Clone, PartialEq)]
pub struct Axes {
    /// The output's label (axis and legend), e.g. `y, units of the log` or `flow y, slm`.
    pub output: String,
    /// The input's label (axis and legend), e.g. `u` or `duty u, fraction of full scale`.
    pub input: String,
    /// The sample period, s, when the record's time base is known: the fit plot's time axis
    /// is then in seconds from the record's first sample; `None`: it counts samples.
    pub ts: Option<f64>,
}

impl Axes {
    /// A CSV log of unknown units: its columns' names `y` and `u`, in the log's units, time in
    /// samples.
    pub fn columns() -> Self {
        Axes {
            output: "y, units of the log".into(),
            input: "u, units of the log".into(),
            ts: None,
        }
    }

    /// The pump's log capture (`--phase`, `--device`): flow in slm, duty as a fraction of
    /// full scale (0..1), one sample per tick of the firmware's loop (100 Hz).
    pub fn pump() -> Self {
        Axes {
            output: "flow y, slm".into(),
            input: "duty u, fraction of full scale".into(),
            ts: Some(1.0 / f64::from(SAMPLE_RATE_HZ)),
        }
    }
}
