//! Baseline flow controllers on the same simulator, setpoints and noise as the firmware's
//! RST controller (issue 10, deliverable 5), and the comparison table.
//!
//! One file per concern:
//!
//! - [`stepped`]: the [`Plant`] the tuning experiments step (the rig's true flow, or a linear
//!   ARX plant for tests);
//! - [`pid`]: the discrete PID with the firmware's duty limits, rate limit, conditional
//!   integration and bumpless start;
//! - [`zn`]: Ziegler–Nichols tuning from the ultimate gain and period of the noise-free plant;
//! - [`simc`]: SIMC PI tuning from an FOPDT fit of the identified model;
//! - [`knobs`]: the firmware's design with its time constants chosen per plant in hindsight;
//! - [`metrics`]: step metrics, RMS tracking error, duty total variation;
//! - [`optimal`]: the open-loop optimum of a step, the least IAE of any duty sequence;
//! - [`experiment`]: one plant and seed, the three controllers from the same switch-over;
//! - [`table`]: the plant × lung × controller grid and its markdown (what `control-table`
//!   prints).

pub mod experiment;
pub mod knobs;
pub mod metrics;
pub mod optimal;
pub mod pid;
pub mod simc;
pub mod stepped;
pub mod table;
pub mod zn;

pub use experiment::{run_case, tune_zn, CaseRun, Controller, ExperimentError, Trace, ZnTuning};
pub use pid::{config_limits, firmware_limits, no_limits, Pid, PidGains};
pub use simc::{fit_fopdt, fit_model, simc_pi, Fopdt, Simc};
pub use stepped::{ArxPlant, Plant, UnroundedRig};
pub use zn::{ultimate, zn_pid, Ultimate, ZnSearch};
