//! [`Guard`]: the fault checks every tick runs first (sensor errors, flow range, stall, frozen
//! sensor, missing flow), also used on their own while a blocking search keeps the state
//! machine from ticking.

use crate::event::{FaultReason, SensorFault};
use crate::units::DUTY_FULL_SCALE;

use super::{Config, LOSS_SHIFT};

/// The fault checks of every tick, with their counters: [`Config::sensor_fault_limit`]
/// consecutive sensor errors, a reading beyond [`Config::flow_limit`], a stall
/// ([`Config::stall_duty`] or more with a flow below [`Config::stall_flow`] for
/// [`Config::stall_ticks`] ticks), a frozen sensor ([`Config::frozen_ticks`] identical
/// readings at |flow| ≥ [`Config::frozen_flow`]) and a missing flow response (the flow below
/// a quarter of the expected one for [`Config::loss_ticks`] checked ticks, see [`Guard::expected`]).
/// [`SelfIdentification::tick`](super::SelfIdentification::tick) runs them first;
/// [`SelfIdentification::guard`](super::SelfIdentification::guard) hands out a copy for
/// stretches without ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Guard {
    sensor_fault_limit: u8,
    flow_limit: i16,
    stall_duty: u16,
    stall_flow: i16,
    stall_ticks: u16,
    frozen_ticks: u16,
    frozen_flow: i16,
    loss_ticks: u16,
    /// Consecutive sensor errors.
    errors: u8,
    /// Consecutive ticks meeting the stall condition.
    stall: u16,
    /// The previous good reading, counts.
    last: i16,
    /// Consecutive good readings equal to the previous one at |flow| ≥ `frozen_flow`.
    repeats: u16,
    /// Checked ticks with the flow below a quarter of the expected one (not reset by unchecked ticks).
    loss: u16,
    /// The expected flow, if known.
    expect: Option<Expect>,
    /// The flow expected at the next check only (run mode, [`Guard::expect_flow`]).
    given: Option<i16>,
}

/// The flow a healthy pump gives at a duty `u ≥ duty` (1/10 000), from the settled operating
/// point: `flow + slope · (u − duty) / 256` counts; nothing below `duty`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Expect {
    /// Reference duty (the operating point's), 1/10 000.
    duty: u16,
    /// Flow at the reference duty, counts (1/120 slm).
    flow: i16,
    /// Counts per 1/10 000 duty, times 256.
    slope: i16,
}

impl Guard {
    /// The checks of `cfg`, counters at zero, no flow expected yet.
    pub fn new(cfg: &Config) -> Self {
        Guard {
            sensor_fault_limit: cfg.sensor_fault_limit.max(1),
            flow_limit: cfg.flow_limit,
            stall_duty: cfg.stall_duty,
            stall_flow: cfg.stall_flow,
            stall_ticks: cfg.stall_ticks.max(1),
            frozen_ticks: cfg.frozen_ticks,
            frozen_flow: cfg.frozen_flow,
            loss_ticks: cfg.loss_ticks,
            errors: 0,
            stall: 0,
            last: 0,
            repeats: 0,
            loss: 0,
            expect: None,
            given: None,
        }
    }

    /// From now on expects, at a duty `u ≥ duty` (1/10 000), at least the flow
    /// `flow · u / duty` (counts): the settled operating point, before a model is in use.
    /// Nothing is expected below `duty`, nor anywhere if `duty` is 0 or `flow` not positive.
    pub fn expect_operating_point(&mut self, duty: u16, flow: i16) {
        self.expect = if duty == 0 || flow <= 0 {
            None
        } else {
            // ≤ 32 767 · 256 / 1, clamped to i16.
            let slope = (i32::from(flow) * 256 / i32::from(duty)).min(i32::from(i16::MAX));
            Some(Expect {
                duty,
                flow,
                slope: slope as i16,
            })
        };
        self.loss = 0;
    }

    /// Expects `flow` (counts) at the next check only, whatever its duty, instead of the
    /// operating point's law: run mode gives the model's steady state at the duty it has just
    /// written, every tick after the PWM write (so that the check itself costs no map
    /// evaluation). Outside run mode nobody gives it, and the law holds again from the check
    /// after.
    pub fn expect_flow(&mut self, flow: i16) {
        self.given = Some(flow);
    }

    /// The flow expected at the duty `applied` (1/10 000) by the next check, counts: the
    /// given one ([`expect_flow`](Self::expect_flow)), or the operating point's law
    /// ([`expect_operating_point`](Self::expect_operating_point)); `None` where nothing is
    /// expected. Saturates at the `i16` range.
    pub fn expected(&self, applied: u16) -> Option<i16> {
        if let Some(flow) = self.given {
            return Some(flow);
        }
        let Expect { duty, flow, slope } = self.expect?;
        let u = applied.min(DUTY_FULL_SCALE);
        if u < duty {
            return None;
        }
        // |slope · du| ≤ 32 767 · 10 000 < 2³¹.
        let du = i32::from(u) - i32::from(duty);
        let y = i32::from(flow) + ((i32::from(slope) * du) >> 8);
        Some(y.min(i32::from(i16::MAX)) as i16)
    }

    /// Takes over the counters of `watched`, a copy of this guard that checked the tick
    /// boundaries of a blocking job (the search, the design), so that a fault that started
    /// during the job is detected in the documented time after it; the limits and the
    /// expected flow stay this guard's.
    pub fn resume(&mut self, watched: &Guard) {
        self.errors = watched.errors;
        self.stall = watched.stall;
        self.last = watched.last;
        self.repeats = watched.repeats;
        self.loss = watched.loss;
    }

    /// Checks one tick's sensor result `flow` (counts, 1/120 slm), read after the pump ran at
    /// `applied` (1/10 000) for the tick. `Ok(Some(counts))`: a good reading; `Ok(None)`: a
    /// sensor error still within the limit (to be bridged); `Err`: the fault it completes.
    pub fn check(
        &mut self,
        applied: u16,
        flow: Result<i16, SensorFault>,
    ) -> Result<Option<i16>, FaultReason> {
        // Given for this check only, whatever its outcome.
        let given = self.given.take();
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
        // |c| ≤ flow_limit here: no overflow in abs.
        if c == self.last && c.abs() >= self.frozen_flow && self.frozen_ticks > 0 {
            self.repeats = self.repeats.saturating_add(1);
            // `repeats` equal pairs: `repeats + 1` identical readings.
            if self.repeats.saturating_add(1) >= self.frozen_ticks {
                return Err(FaultReason::Frozen { counts: c });
            }
        } else {
            self.repeats = 0;
        }
        self.last = c;
        let expected = given.or_else(|| self.expected(applied));
        if let Some(expected) = expected.filter(|_| self.loss_ticks > 0) {
            let part = expected >> LOSS_SHIFT;
            if part >= self.stall_flow {
                if c < part {
                    self.loss = self.loss.saturating_add(1);
                    if self.loss >= self.loss_ticks {
                        return Err(FaultReason::NoFlow {
                            duty: applied,
                            counts: c,
                            expected,
                        });
                    }
                } else {
                    self.loss = 0;
                }
            }
        }
        Ok(Some(c))
    }
}
