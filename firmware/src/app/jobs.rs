//! The blocking jobs the loop runs between ticks, after the tick's PWM write: the structure
//! search and the controller design, with what keeps the board alive meanwhile
//! ([`Keepalive`]).
//!
//! The search runs in one of two ways ([`Board::TICK_DURING_SEARCH`]):
//! - ticking (STM32F411): as a `SearchJob` whose `pet` closure also keeps the loop going: at
//!   every pet it pets the watchdog and, if a 10 ms boundary has passed, reads the sensor and
//!   calls `tick` (the state machine holds the base duty and keeps detecting faults). Those
//!   ticks come as late as the longest stretch between two pets (one factorisation);
//! - blocking (ATmega2560, for stack): `SelfIdentification::search`; its `pet` closure pets the
//!   watchdog and, at every 10 ms boundary, reads the sensor and runs the tick's fault checks
//!   (`SelfIdentification::guard`: sensor errors, flow range, stall, frozen sensor, no flow),
//!   stopping the pump at once on a fault; the PWM holds the base duty, the readings are not
//!   recorded. Afterwards the state machine's checks continue from the keepalive's counters
//!   (`SelfIdentification::resume_guard`).
//!
//! Either way the search's ticks are counted on the `SEARCH` line, not in `MISSED`. The
//! controller design (tens of milliseconds) always runs the blocking way, with the same guard,
//! and its ticks are counted on the `DESIGN` line.

use super::{serve, App, Board};
use crate::event::{Event, FaultReason, SensorFault};
use crate::numfmt::Int;
use crate::pump::Pump;
use crate::selfid::{Guard, SelfIdentification, Settings};
use crate::sfm3300::Sfm3300;
use embedded_hal::i2c::I2c;
use embedded_hal::pwm::SetDutyCycle;
use ufmt::{uWrite, uwriteln};

impl<I: I2c, P: SetDutyCycle, W: uWrite, S: Settings> App<I, P, W, S> {
    /// Runs the search (ticking from its `pet` calls if the board does).
    ///
    /// Never inlined: the search's locals (the job with its statistics, the normal equations,
    /// the candidate systems: several KB on the ATmega2560) must only be on the stack while it
    /// runs, not in the frame of the endless loop, nor under the catch-up tick that follows.
    #[inline(never)]
    pub(super) fn search<B: Board>(&mut self, board: &mut B) -> JobEnd {
        let (mut ticks, mut lost) = (0u16, 0u16);
        let mut fault = None;
        let job = Job::Search;
        let event = if B::TICK_DURING_SEARCH {
            let Some(job) = self.sid.take_search() else {
                return JobEnd {
                    job,
                    event: None,
                    fault,
                    ticks,
                    lost,
                };
            };
            let outcome = job.run(|| {
                board.pet();
                if let Some(elapsed) = board.poll_tick() {
                    ticks = ticks.saturating_add(1);
                    lost = lost.saturating_add(elapsed - 1);
                    self.tick(board);
                }
            });
            self.sid.finish_search(outcome)
        } else {
            // The state machine cannot tick meanwhile (its statistics are in use, and the stack
            // has no room for a tick on top of the search): the PWM holds the base duty, and a
            // copy of the tick's fault checks reads the sensor at every tick boundary. A fault
            // stops the pump at once; the state machine takes it over after the search.
            let mut keepalive = Keepalive::new(&self.sid, &mut self.sensor, &mut self.pump, board);
            let event = self.sid.run_search(|| keepalive.pet());
            self.sid.resume_guard(&keepalive.guard);
            (ticks, lost, fault) = (keepalive.ticks, keepalive.lost, keepalive.fault);
            event
        };
        JobEnd {
            job,
            event,
            fault,
            ticks,
            lost,
        }
    }

    /// Runs the controller design, blocking, with the guard (tens of milliseconds on the
    /// ATmega2560). Never inlined, for the same reason as [`search`](Self::search): its frame
    /// is only on the stack while it runs, beside the search's, not on top of it.
    #[inline(never)]
    pub(super) fn design<B: Board>(&mut self, board: &mut B) -> JobEnd {
        let mut keepalive = Keepalive::new(&self.sid, &mut self.sensor, &mut self.pump, board);
        let event = self.sid.design(|| keepalive.pet());
        self.sid.resume_guard(&keepalive.guard);
        JobEnd {
            job: Job::Design,
            event,
            fault: keepalive.fault,
            ticks: keepalive.ticks,
            lost: keepalive.lost,
        }
    }

    /// After a search or design (its frame is gone): its event (and a fault the guard found).
    /// The next pass ticks at once if a boundary passed meanwhile, and is not counted late for
    /// it (the job's time is on its `SEARCH` / `DESIGN` line). The `SEARCH` / `DESIGN` and
    /// `STACK` lines wait for that pass, right after its tick, so that printing them cannot run
    /// into the next tick boundary.
    pub(super) fn after_job<B: Board>(&mut self, board: &mut B, end: JobEnd) {
        let JobEnd {
            job,
            event,
            fault,
            ticks,
            lost,
        } = end;
        if let Some(event) = event {
            self.stop_on_fault();
            self.report(board, &event);
        }
        if let Some(reason) = fault {
            let event = self.sid.fault_detected(reason);
            self.report(board, &event);
        }
        if let Some(c) = board.console() {
            // The log's clock: boundaries skipped, and those the keepalive handled (a ticking
            // search clocked its ticks already).
            let watched = if job == Job::Search && B::TICK_DURING_SEARCH {
                0
            } else {
                ticks
            };
            c.clock = c.clock.wrapping_add(u32::from(watched) + u32::from(lost));
            if c.line.is_stop() {
                // The keepalive stopped the pump; the state machine follows now (the answer in
                // the next pass).
                self.sid.stop();
            }
        }
        // The boundary that passes while the job ends is the next pass's tick, not a late one.
        self.job_ended = true;
        self.job_lines = Some((job, ticks, lost));
    }

    /// The `SEARCH` / `STACK` lines of the last search, once.
    pub(super) fn print_job_lines(&mut self, board: &impl Board) {
        if let Some((job, ticks, lost)) = self.job_lines.take() {
            let name = match job {
                Job::Search => "SEARCH",
                Job::Design => "DESIGN",
            };
            uwriteln!(
                self.out,
                "{} ticks={} lost={}",
                name,
                Int::from(ticks),
                Int::from(lost)
            )
            .ok();
            if let Some((used, free)) = board.stack() {
                uwriteln!(
                    self.out,
                    "STACK used={} free={}",
                    Int::from(used),
                    Int::from(free)
                )
                .ok();
            }
        }
    }
}

/// What a blocking search or design calls between its steps: pets the watchdog and, at every
/// tick boundary, reads the sensor and runs the tick's fault checks, stopping the pump at once
/// on a fault. One non-inlined function, so that each of the many call sites in the search and
/// the design costs a call, not a copy.
struct Keepalive<'a, I, P, B> {
    guard: Guard,
    /// The duty the pump holds meanwhile, 1/10 000.
    applied: u16,
    sensor: &'a mut Sfm3300<I>,
    pump: &'a mut Pump<P>,
    board: &'a mut B,
    fault: Option<FaultReason>,
    ticks: u16,
    lost: u16,
}

impl<'a, I: I2c, P: SetDutyCycle, B: Board> Keepalive<'a, I, P, B> {
    /// The guard of `sid` at the pump's applied duty, counters at zero.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    fn new(
        sid: &SelfIdentification<impl Settings>,
        sensor: &'a mut Sfm3300<I>,
        pump: &'a mut Pump<P>,
        board: &'a mut B,
    ) -> Self {
        Keepalive {
            guard: sid.guard(),
            applied: pump.applied(),
            sensor,
            pump,
            board,
            fault: None,
            ticks: 0,
            lost: 0,
        }
    }

    #[inline(never)]
    fn pet(&mut self) {
        self.board.pet();
        if let Some(elapsed) = self.board.poll_tick() {
            self.ticks = self.ticks.saturating_add(1);
            self.lost = self.lost.saturating_add(elapsed - 1);
            if self.fault.is_none() {
                let flow = self.sensor.read_counts().map_err(SensorFault::from);
                if let Err(reason) = self.guard.check(self.applied, flow) {
                    self.pump.stop().ok();
                    self.fault = Some(reason);
                }
            }
            self.console();
        }
    }
}

impl<I: I2c, P: SetDutyCycle, B: Board> Keepalive<'_, I, P, B> {
    /// The console during a blocking search: received bytes go into the console's line, which
    /// is held for after it; a `STOP` stops the pump now.
    fn console(&mut self) {
        if serve::listen(self.board) {
            self.pump.stop().ok();
            self.applied = 0;
        }
    }
}

/// The blocking work the loop runs between ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Job {
    /// The structure search.
    Search,
    /// The controller design.
    Design,
}

/// How a blocking job (search or design) ended, for [`App::after_job`].
pub(super) struct JobEnd {
    /// Which one it was.
    job: Job,
    /// The search's event (`ID` or `REJECT`), if it was not stale.
    event: Option<Event>,
    /// A fault the guard found while the search blocked the state machine.
    fault: Option<FaultReason>,
    /// Tick boundaries handled meanwhile.
    ticks: u16,
    /// Tick boundaries skipped meanwhile.
    lost: u16,
}
