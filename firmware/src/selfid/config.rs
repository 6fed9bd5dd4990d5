//! [`Config`]: the settings of the self-identification state machine and their defaults.

use ridge_core::Search;

use crate::excitation::Record;
use crate::monitor::MonitorConfig;

/// Settings of the state machine. Duties in 1/10 000 of full scale, flows in SFM3300 counts
/// (1/120 slm), times in ticks of 10 ms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Duty while settling, searching and between attempts (default 3000 = 30 %).
    pub base_duty: u16,
    /// Ticks at the base duty before a record or before run mode (default 200 = 2 s).
    pub settle_ticks: u16,
    /// Estimation record (default A-Multistep, 3000 samples).
    pub excitation: Record,
    /// Validation record (default B-Multistep, 3000 samples).
    pub validation: Record,
    /// Structure search on the deviations from the operating point. Default: ridge-core's
    /// `Search::default()` (Ridge-M γ = 1000, β = 0.01, 200 iterates, delay-free AIC with
    /// α = 12, the 252-candidate grid, exact pruning, no offset).
    /// [`ridge_core::Criterion::Validation`] is not supported here.
    pub search: Search<f32>,
    /// Smallest accepted free-run fit on the validation record, percent (default 70).
    pub min_fit: f32,
    /// Smallest RMS deviation of the flow from its mean over the estimation record, slm
    /// (default 1.0): below it the record is "not excited".
    pub min_response: f32,
    /// Largest number of sensor errors bridged within one record (default 10).
    pub max_gaps: u16,
    /// Identification attempts before the fault state (default 3).
    pub attempts: u8,
    /// Consecutive sensor errors that raise a fault (default 5).
    pub sensor_fault_limit: u8,
    /// Largest |flow| accepted, counts (default 30 000 = 250 slm).
    pub flow_limit: i16,
    /// Stall detection: at a duty of at least `stall_duty` (default 4000 = 40 %) ...
    pub stall_duty: u16,
    /// ... a flow below `stall_flow` counts (default 240 = 2 slm) ...
    pub stall_flow: i16,
    /// ... for `stall_ticks` consecutive ticks (default 50 = 0.5 s) is a stall.
    pub stall_ticks: u16,
    /// Duty held in run mode (default 3000 = 30 %).
    pub run_duty: u16,
    /// Run-mode monitor.
    pub monitor: MonitorConfig,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            base_duty: 3_000,
            settle_ticks: 200,
            excitation: Record::AMultistep,
            validation: Record::BMultistep,
            search: Search::default(),
            min_fit: 70.0,
            min_response: 1.0,
            max_gaps: 10,
            attempts: 3,
            sensor_fault_limit: 5,
            flow_limit: 30_000,
            stall_duty: 4_000,
            stall_flow: 240,
            stall_ticks: 50,
            run_duty: 3_000,
            monitor: MonitorConfig::default(),
        }
    }
}
