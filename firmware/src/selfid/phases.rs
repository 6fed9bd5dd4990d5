//! The tick's phase logic ([`SelfIdentification::advance`]): run mode's control step, and
//! every other phase's transitions (settling, the scan, the records and their ends, the
//! validation's verdict), which run mode's tick does not carry.

use ridge_core::{ArxModel, Evaluation, InputMap, Real};

use crate::event::{Event, RejectReason};
use crate::excitation::FlowSteps;
use crate::units::SLM_PER_COUNT;

use super::recording::SETTLE_MEAN_TICKS;
use super::scan::{Scan, Startup};
use super::{settle, Phase, SelfIdentification, Settings, Then};

impl<S: Settings> SelfIdentification<S> {
    /// The phase logic of one tick (faults already checked); its event into `event`. Run mode
    /// writes no event here (its events come after the PWM write,
    /// [`after_write`](Self::after_write)); the other phases return theirs from
    /// [`advance_other`](Self::advance_other).
    pub(super) fn advance(
        &mut self,
        applied: u16,
        reading: Option<i16>,
        event: &mut Option<Event>,
    ) {
        if let Phase::Run(run) = &mut self.phase {
            #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
            run.swap_at_boundary(&mut self.reid, reading, self.last_counts);
            self.duty = run.control(applied, reading, self.last_counts);
            return;
        }
        // Moved only when there is one (a 74-byte copy, ~550 cycles on the ATmega2560).
        if let Some(e) = self.advance_other(applied, reading) {
            *event = Some(e);
        }
    }

    /// [`advance`](Self::advance) in every phase but run mode.
    // Out of line: 542 B smaller ATmega2560 image (text 96 380 → 95 838), run mode's tick
    // (`advance` → `RunMode::control`) no longer carries the other phases' code.
    #[inline(never)]
    pub(super) fn advance_other(&mut self, applied: u16, reading: Option<i16>) -> Option<Event> {
        let y = reading.unwrap_or(self.last_counts);
        let cfg = self.settings.config();
        match &mut self.phase {
            Phase::Wait => {
                reading?;
                let load = self.model.is_some() && !self.identify;
                let then = if load { Then::Load } else { Then::Excite };
                self.phase = settle(cfg.settle_ticks, then);
                if let Phase::Settle { startup, .. } = &mut self.phase {
                    // The pump stood still: its start-up gives the lag.
                    *startup = (applied == 0).then(Startup::new);
                }
                self.duty = cfg.base_duty;
                let event = self.settle_step(applied, reading);
                // The stored model's map is reported before it is loaded.
                match (load, self.map) {
                    (true, Some(map)) => Some(Event::Map(map)),
                    _ => event,
                }
            }
            Phase::Settle { .. } => self.settle_step(applied, reading),
            Phase::Scan { scan, u0, gaps, .. } => {
                if reading.is_none() {
                    *gaps = gaps.saturating_add(1);
                    if *gaps > cfg.max_gaps {
                        let gaps = *gaps;
                        return Some(self.reject(RejectReason::SensorGaps { gaps }));
                    }
                }
                scan.credit(&cfg.records, reading);
                let (duty, _) = scan.duty(&cfg.records, scan.next).unwrap_or((*u0, true));
                // Past the lead-in the base duty holds until `judge` has made the map.
                scan.next = scan.next.saturating_add(1);
                self.duty = duty;
                None
            }
            Phase::Excite { lead: 1.., .. } => {
                let Phase::Excite { lead, start, .. } = &mut self.phase else {
                    return None;
                };
                *lead -= 1;
                if *lead > 0 {
                    self.duty = cfg.base_duty;
                    return None;
                }
                self.duty = *start;
                let (samples, u0, y0) = match &self.phase {
                    Phase::Excite { gen, .. } => (gen.len_samples(), cfg.base_duty, self.y0()),
                    _ => return None,
                };
                Some(Event::Excite {
                    samples,
                    u0,
                    y0,
                    attempt: self.attempt,
                    attempts: cfg.attempts.max(1),
                })
            }
            Phase::Excite { gen, rec, v, .. } => {
                if reading.is_none() {
                    rec.gaps = rec.gaps.saturating_add(1);
                    if rec.gaps > cfg.max_gaps {
                        let gaps = rec.gaps;
                        return Some(self.reject(RejectReason::SensorGaps { gaps }));
                    }
                }
                let dv = i32::from(*v) - i32::from(rec.v0);
                let dy = i32::from(y) - i32::from(rec.y0);
                if let Err(e) = rec.gram.push(dv, dy) {
                    return Some(self.reject(RejectReason::Search(e)));
                }
                let y64 = i64::from(y);
                rec.sum_y = rec.sum_y.saturating_add(y64);
                rec.sum_y2 = rec.sum_y2.saturating_add(y64 * y64);
                match gen.next_step() {
                    Some((duty, next)) => {
                        self.duty = duty;
                        *v = next;
                    }
                    None => self.end_excitation(),
                }
                None
            }
            Phase::SearchReady { .. }
            | Phase::Searching
            | Phase::SearchNormal { .. }
            | Phase::SearchRefused(..) => {
                self.duty = cfg.base_duty;
                None
            }
            Phase::Validate {
                gen,
                eval,
                v,
                gaps,
                started,
                complete,
                ..
            } => {
                if *complete {
                    // Waiting for `judge`: hold the base duty, score nothing.
                    self.duty = cfg.base_duty;
                    return None;
                }
                if !*started {
                    *started = true;
                    let samples = gen.len_samples();
                    return match gen.next_step() {
                        Some((duty, next)) => {
                            self.duty = duty;
                            *v = next;
                            Some(Event::Validate { samples })
                        }
                        None => {
                            *complete = true;
                            self.duty = cfg.base_duty;
                            Some(Event::Validate { samples })
                        }
                    };
                }
                if reading.is_none() {
                    *gaps = gaps.saturating_add(1);
                    if *gaps > cfg.max_gaps {
                        let gaps = *gaps;
                        return Some(self.reject(RejectReason::SensorGaps { gaps }));
                    }
                }
                eval.push(f32::from(*v) * SLM_PER_COUNT, f32::from(y) * SLM_PER_COUNT);
                match gen.next_step() {
                    Some((duty, next)) => {
                        self.duty = duty;
                        *v = next;
                    }
                    None => {
                        // Scoring (square roots, the model's move into run mode) is left to
                        // `judge`, outside the tick, so that the tick stays short.
                        *complete = true;
                        self.duty = cfg.base_duty;
                    }
                }
                None
            }
            Phase::Design { .. } => {
                self.duty = cfg.base_duty;
                None
            }
            // Run mode is `advance`'s; here it would stop the pump like the others.
            Phase::Run(_) | Phase::Stopped | Phase::Fault => {
                self.duty = 0;
                None
            }
        }
    }

    /// A record of random steps uniform in `map`'s flow (the settings' [`Records::shape`]).
    /// `None` when the map's flows leave no range for the levels.
    pub(super) fn record(
        &self,
        map: &InputMap,
        lag: u8,
        samples: u16,
        seed: u16,
    ) -> Option<FlowSteps> {
        let r = &self.settings.config().records;
        FlowSteps::new(map, &r.shape(lag, samples, seed))
    }

    /// The validation phase for `model` on `map`: a record like the estimation record, with
    /// the complement of its seed. `None` when the map's flows leave no range for the levels.
    pub(super) fn validation(&self, model: ArxModel<f32>, map: InputMap) -> Option<Phase> {
        let r = &self.settings.config().records;
        let lag = self.lag.unwrap_or(r.lag_default);
        Some(Phase::Validate {
            gen: self.record(&map, lag, r.validation, !r.seed)?,
            eval: Evaluation::new(model),
            model,
            map,
            v: 0,
            gaps: 0,
            started: false,
            complete: false,
        })
    }

    /// One settle tick: base duty; at the end, run mode or the scan.
    pub(super) fn settle_step(&mut self, applied: u16, reading: Option<i16>) -> Option<Event> {
        let cfg = self.settings.config();
        let Phase::Settle {
            left,
            then,
            sum,
            n,
            startup,
        } = &mut self.phase
        else {
            return None;
        };
        self.duty = cfg.base_duty;
        if let (Some(st), Some(c), true) = (startup.as_mut(), reading, applied != 0) {
            st.push(c);
        }
        if *left <= SETTLE_MEAN_TICKS && reading.is_some() {
            *sum = sum.saturating_add(i32::from(self.last_counts));
            *n = n.saturating_add(1);
        }
        *left = left.saturating_sub(1);
        if *left > 0 {
            return None;
        }
        // Rounded mean of the settled flow (the last reading if none was good).
        let y0 = if *n > 0 {
            let (s, k) = (*sum, i32::from(*n));
            let half = if s >= 0 { k / 2 } else { -(k / 2) };
            i16::try_from((s + half) / k).unwrap_or(self.last_counts)
        } else {
            self.last_counts
        };
        if let Some(lag) = startup.and_then(|st| st.lag(y0, cfg.records.lag_max)) {
            self.lag = Some(lag);
        }
        let u0 = cfg.base_duty;
        // The operating point is what the no-flow check expects from now on.
        self.guard.expect_operating_point(u0, y0);
        match (*then, self.model, self.map) {
            (Then::Load, Some(model), Some(map)) => {
                self.phase = Phase::Design { model, map };
                Some(Event::Loaded {
                    model,
                    fit: self.fit,
                })
            }
            (Then::Design, Some(model), Some(map)) => {
                self.phase = Phase::Design { model, map };
                None
            }
            _ => {
                self.attempt = self.attempt.saturating_add(1);
                let lag = self.lag.unwrap_or(cfg.records.lag_default);
                let mut scan = Scan::new(&cfg.records, u0, lag);
                let samples = scan.len(&cfg.records);
                if let Some((duty, _)) = scan.duty(&cfg.records, 0) {
                    scan.next = 1;
                    self.duty = duty;
                }
                self.phase = Phase::Scan {
                    scan,
                    u0,
                    y0,
                    gaps: 0,
                };
                Some(Event::Scan {
                    samples,
                    lag,
                    u0,
                    y0,
                    attempt: self.attempt,
                    attempts: cfg.attempts.max(1),
                })
            }
        }
    }

    /// The excitation record is complete: wait for the search at the base duty.
    pub(super) fn end_excitation(&mut self) {
        if let Phase::Excite { rec, .. } = core::mem::replace(&mut self.phase, Phase::Searching) {
            self.phase = Phase::SearchReady { rec };
        }
        self.duty = self.settings.config().base_duty;
    }

    /// The validation record is complete: accept (run mode) or reject.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    pub(super) fn end_validation(&mut self) -> Event {
        let Phase::Validate {
            eval, model, map, ..
        } = &self.phase
        else {
            return self.reject(RejectReason::NonFinite);
        };
        let (model, map) = (*model, *map);
        let (free, one) = match (eval.free_run(), eval.one_step()) {
            (Some(f), Some(o))
                if Real::is_finite(f.fit) && Real::is_finite(f.rmse) && Real::is_finite(o.rmse) =>
            {
                (f, o)
            }
            _ => return self.reject(RejectReason::NonFinite),
        };
        if free.fit < self.settings.config().min_fit {
            return self.reject(RejectReason::Fit {
                fit: free.fit,
                min: self.settings.config().min_fit,
            });
        }
        self.model = Some(model);
        self.map = Some(map);
        self.fit = free.fit;
        self.drift = false;
        // Settle at the base duty, then design: control starts from the settled operating point.
        self.phase = settle(self.settings.config().settle_ticks, Then::Design);
        self.duty = self.settings.config().base_duty;
        Event::Accepted {
            fit: free.fit,
            rmse: free.rmse,
            one_step: one.rmse,
            samples: free.n,
        }
    }
}
