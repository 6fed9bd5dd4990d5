//! The acceptance rule of the power-up before issue 31 and the one after it, on the same
//! healthy and changed plants: do the 3 s validation record and its rule still refuse what
//! the 30 s one refused?
//!
//! Both rules accept a model when its free-run fit on the validation record (seeded with the
//! first measured samples) is at least 70 %. Before: the model of the 30 s A-Multistep
//! ([`super::before`]) on the B-Multistep (30 s), after 2.6 s at the base duty (the search on
//! the ATmega2560 then). After: the firmware's own state machine, whose validation record is
//! 3 s of random steps uniform in the map's flow. A *change* of the plant happens when the
//! validation record starts, after the model was identified on the healthy one (the plant
//! the pump finds is not the one it identified): the model must then be refused.

use ridge_core::Evaluation;
use ridge_pump_firmware::event::{Event, LINE_MAX};
use ridge_pump_firmware::selfid::{Config, SelfIdentification, State};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::DUTY_FULL_SCALE;

use super::before::{
    model_before, BEFORE_BASE_DUTY, BEFORE_RECORD, BEFORE_SETTLE_TICKS, BEFORE_VALIDATION,
};
use crate::sfm3300::raw_to_flow;
use crate::{Lung, LungParams, PlantArgs, Pump, PumpParams, Rig, Sfm3300Params};

/// Ticks the pump held the base duty while the search ran before issue 31 (2.62 s on the
/// ATmega2560).
pub const BEFORE_SEARCH_TICKS: usize = 262;

/// How the plant changes when the validation record starts.
#[derive(Debug, Clone, PartialEq)]
pub enum Change {
    /// It does not.
    None,
    /// The blower's flow at every speed times this (a leak, a clogged filter).
    Flow(f64),
    /// The blower's time constants times this (a heavier rotor).
    Lag(f64),
    /// This many more samples of transport delay.
    Delay(usize),
    /// A test lung appears behind the blower (the patient circuit connected).
    Lung(LungParams),
}

impl Change {
    /// A short name for the table.
    pub fn name(&self) -> String {
        match self {
            Change::None => "healthy".into(),
            Change::Flow(x) => format!("flow x{x}"),
            Change::Lag(x) => format!("lag x{x}"),
            Change::Delay(k) => format!("delay +{k}"),
            Change::Lung(l) => format!("lung C {} R {}", l.compliance, l.resistance),
        }
    }

    /// Applies the change to `rig`, the blower already turning at `duty` (1/10 000).
    fn apply(&self, rig: &mut Rig, duty: u16) {
        let p = rig.pump.params().clone();
        let params = match self {
            Change::None => return,
            Change::Lung(l) => {
                rig.lung = Some(Lung::new(l.clone()));
                return;
            }
            Change::Flow(x) => PumpParams {
                max_flow_slm: p.max_flow_slm * x,
                ..p
            },
            Change::Lag(x) => PumpParams {
                tau_up_s: p.tau_up_s * x,
                tau_down_s: p.tau_down_s * x,
                ..p
            },
            Change::Delay(k) => PumpParams {
                delay_samples: p.delay_samples + k,
                ..p
            },
        };
        let mut pump = Pump::new(params);
        for _ in 0..500 {
            pump.step(f64::from(duty) / f64::from(DUTY_FULL_SCALE));
        }
        rig.pump = pump;
    }
}

/// A rule's verdict: the validation fit and whether the model was accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdict {
    /// Free-run fit on the validation record, percent (NaN when none was scored).
    pub fit: f32,
    /// Accepted.
    pub accepted: bool,
}

/// The rule before issue 31 on `plant` with noise `seed` and `change` at its validation.
pub fn verdict_before(
    plant: &PlantArgs,
    seed: u64,
    change: &Change,
    min_fit: f32,
) -> Result<Verdict, String> {
    let model = model_before(plant, seed)?;
    // The same noise stream and plant state as the identification: replay it.
    let mut rig = plant.rig(Sfm3300Params::default(), seed)?;
    rig.step(0);
    for _ in 1..BEFORE_SETTLE_TICKS {
        rig.step(BEFORE_BASE_DUTY);
    }
    for d in BEFORE_RECORD.generator() {
        rig.step(d);
    }
    for _ in 0..BEFORE_SEARCH_TICKS {
        rig.step(BEFORE_BASE_DUTY);
    }
    change.apply(&mut rig, BEFORE_BASE_DUTY);
    let mut ev = Evaluation::new(model);
    for d in BEFORE_VALIDATION.generator() {
        let y = raw_to_flow(rig.step(d));
        ev.push(f32::from(d) / f32::from(DUTY_FULL_SCALE), y as f32);
    }
    let fit = ev.free_run().map_or(f32::NAN, |s| s.fit);
    Ok(Verdict {
        fit,
        accepted: fit >= min_fit,
    })
}

/// The firmware's own rule (its state machine with `config`) on `plant` with noise `seed` and
/// `change` when its validation record starts: the first attempt's `ACCEPT` or `REJECT`.
pub fn verdict_now(
    plant: &PlantArgs,
    seed: u64,
    change: &Change,
    config: &'static Config,
) -> Result<Verdict, String> {
    let mut rig = plant.rig(Sfm3300Params::default(), seed)?;
    let mut sm = SelfIdentification::new(config, None);
    let mut duty = 0u16;
    let mut changed = false;
    for _ in 0..20_000 {
        let t = sm.tick(Ok(raw_to_counts(rig.step(duty))));
        duty = t.duty;
        let mut events: Vec<Event> = t.event.into_iter().collect();
        events.extend(sm.judge());
        events.extend(sm.search(|| {}));
        if sm.state() == State::Validate && !changed {
            change.apply(&mut rig, duty);
            changed = true;
        }
        for e in events {
            match e {
                Event::Accepted { fit, .. } => {
                    return Ok(Verdict {
                        fit,
                        accepted: true,
                    })
                }
                Event::Rejected { reason, .. } => {
                    let fit = match reason {
                        ridge_pump_firmware::event::RejectReason::Fit { fit, .. } => fit,
                        _ => f32::NAN,
                    };
                    return Ok(Verdict {
                        fit,
                        accepted: false,
                    });
                }
                Event::Fault(_) => {
                    return Err(format!("fault: {}", e.line::<LINE_MAX>().as_str()));
                }
                _ => {}
            }
        }
    }
    Err("no verdict".into())
}
