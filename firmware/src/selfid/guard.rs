//! [`Guard`]: the fault checks every tick runs first (sensor errors, flow range, stall), also
//! used on their own while a blocking search keeps the state machine from ticking.

use crate::event::{FaultReason, SensorFault};

use super::Config;

/// The fault checks of every tick, with their counters: [`Config::sensor_fault_limit`]
/// consecutive sensor errors, a reading beyond [`Config::flow_limit`], and a stall
/// ([`Config::stall_duty`] or more with a flow below [`Config::stall_flow`] for
/// [`Config::stall_ticks`] ticks). [`SelfIdentification::tick`](super::SelfIdentification::tick) runs them first;
/// [`SelfIdentification::guard`](super::SelfIdentification::guard) hands out a copy for stretches without ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Guard {
    sensor_fault_limit: u8,
    flow_limit: i16,
    stall_duty: u16,
    stall_flow: i16,
    stall_ticks: u16,
    /// Consecutive sensor errors.
    errors: u8,
    /// Consecutive ticks meeting the stall condition.
    stall: u16,
}

impl Guard {
    /// The checks of `cfg`, counters at zero.
    pub fn new(cfg: &Config) -> Self {
        Guard {
            sensor_fault_limit: cfg.sensor_fault_limit.max(1),
            flow_limit: cfg.flow_limit,
            stall_duty: cfg.stall_duty,
            stall_flow: cfg.stall_flow,
            stall_ticks: cfg.stall_ticks.max(1),
            errors: 0,
            stall: 0,
        }
    }

    /// Checks one tick's sensor result `flow` (counts, 1/120 slm), read after the pump ran at
    /// `applied` (1/10 000) for the tick. `Ok(Some(counts))`: a good reading; `Ok(None)`: a
    /// sensor error still within the limit (to be bridged); `Err`: the fault it completes.
    pub fn check(
        &mut self,
        applied: u16,
        flow: Result<i16, SensorFault>,
    ) -> Result<Option<i16>, FaultReason> {
        let c = match flow {
            Ok(c) => {
                self.errors = 0;
                c
            }
            Err(error) => {
                self.errors = self.errors.saturating_add(1);
                if self.errors >= self.sensor_fault_limit {
                    return Err(FaultReason::Sensor {
                        error,
                        count: self.errors,
                    });
                }
                return Ok(None);
            }
        };
        if i32::from(c).abs() > i32::from(self.flow_limit) {
            return Err(FaultReason::FlowRange { counts: c });
        }
        if applied >= self.stall_duty && c < self.stall_flow {
            self.stall = self.stall.saturating_add(1);
            if self.stall >= self.stall_ticks {
                return Err(FaultReason::Stall {
                    duty: applied,
                    counts: c,
                });
            }
        } else {
            self.stall = 0;
        }
        Ok(Some(c))
    }
}
