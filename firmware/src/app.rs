//! The 100 Hz main loop shared by both boards: wait for the tick, pet the watchdog, read the
//! SFM3300 (I2C in the main loop, never in an interrupt), step the self-identification state
//! machine ([`crate::selfid`]), apply its duty to the pump, print its events,
//! persist its record when an event asks for it, and — after the PWM write — judge the
//! validation record and run the structure search or the controller design when they are due.
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
//!   recorded. Afterwards the state machine's checks continue from the watch's counters
//!   (`SelfIdentification::resume_guard`).
//!
//! Either way the search's ticks are counted on the `SEARCH` line, not in `MISSED`. The
//! controller design (tens of milliseconds) always runs the blocking way, with the same guard,
//! and its ticks are counted on the `DESIGN` line.
//!
//! Report lines written here (`\n`-terminated ASCII), besides the state machine's events (see
//! [`crate::event`]):
//!
//! | line | when |
//! |---|---|
//! | `SENSOR ready tries=<n>` / `SENSOR start failed` | at start: continuous measurement started (retried every tick for 1 s) |
//! | `MISSED late=<n> lost=<n>` | at most once a second, when a total changed: `late` = loop passes that came back after the next tick had already fired, `lost` = ticks skipped entirely (no sample) |
//! | `SEARCH ticks=<n> lost=<n>` | after a search: tick boundaries handled (ticked, or sensor read and fault checks on the ATmega2560) and skipped while it ran |
//! | `DESIGN ticks=<n> lost=<n>` | after the controller design: tick boundaries handled (sensor read and fault checks) and skipped while it ran |
//! | `STACK used=<bytes> free=<bytes>` | after each search (boards that measure the stack) |
//! | `PERSIST saved` / `PERSIST failed` | a record write finished |
//! | `PUMP error` | the PWM channel refused a duty: the pump is stopped |
//! | `LOG dropped=<n>` | at most once a second, when the count changed: log rows that did not fit in the transmit queue |
//! | `OK <command>` / `ERR <why>` | the answer to a console command ([`crate::command`]) |
//!
//! # Console
//! While the loop waits for a tick it moves received bytes into the console's line (no
//! parsing there): a completed `STOP` stops the state machine and writes duty 0 to the PWM at
//! once, within microseconds of its last byte when the loop is idle and at the end of the
//! pass otherwise. Any other line is held (further bytes wait in the receive queue) and
//! executed after the next tick's PWM write, at most one command per pass, once the transmit
//! queue has [`ANSWER_ROOM`] bytes free ([`crate::command`], answers in [`crate::console`]).
//! While a blocking search or design runs, the watch keeps collecting bytes at every tick
//! boundary: a `STOP` stops the pump there and then (the state machine follows after the
//! search); any other command waits for the end of the search. With the log on, each tick
//! appends its [`LogRow`] after the PWM write.

use crate::command::{Command, CommandError, Line};
use crate::console::{LogRow, ModelLine, Poly, RstLine, Status, LOG_HEADER, LOG_ROW_MAX};
use crate::event::{Event, FaultReason, SensorFault};
use crate::persist::RECORD_LEN;
use crate::pump::Pump;
use crate::report::Int;
use crate::selfid::{Config, Guard, SelfIdentification, Settings, State};
use crate::sfm3300::Sfm3300;
use embedded_hal::i2c::I2c;
use embedded_hal::pwm::SetDutyCycle;
use ufmt::{uWrite, uwriteln};

/// Free bytes the transmit queue must have before the console answers a command, so that the
/// answer goes out without the loop waiting for the line: more than the answer lines of a
/// model of orders p, q ≤ 6 take with coefficients of up to 9 characters (`MODEL` ≤ 180
/// bytes; its `RST` lines, one per polynomial and pass after it under the same condition,
/// ≤ 137). A longer line waits for the rest at 11.5 bytes per ms.
pub const ANSWER_ROOM: usize = 200;

/// Ticks over which [`App::start`] retries *start continuous measurement* (1 s: covers the
/// sensor's power-up time when the MCU starts faster than the sensor).
pub const START_TICKS: u8 = 100;

/// Read attempts per sample for an I2C clock of `i2c_hz` Hz: NACKed reads are retried at once,
/// each costing one address byte plus START/STOP (≈ 10 SCL periods: 100 µs at 100 kHz, 25 µs at
/// 400 kHz), and the attempts must bridge the sensor's 0.5 ms update period (needed right after
/// the discarded first frame) with margin: `ceil(0.75 ms / attempt)`, at least 2.
///
/// `read_attempts(100_000) == 8`, `read_attempts(400_000) == 30` (checked at compile time).
pub const fn read_attempts(i2c_hz: u32) -> u8 {
    // 0.75 ms / (10 / f) = f · 75 / 1e6 attempts, rounded up.
    let n = (i2c_hz as u64 * 75).div_ceil(1_000_000);
    if n < 2 {
        2
    } else if n > 255 {
        255
    } else {
        n as u8
    }
}

const _: () = assert!(read_attempts(100_000) == 8 && read_attempts(400_000) == 30);

/// Ticks per `MISSED` summary check (1 s).
const SUMMARY_TICKS: u8 = 100;

/// What the loop needs from a board besides sensor, pump and UART.
pub trait Board {
    /// Whether the loop keeps ticking (sensor, state machine, pump, events) from the search's
    /// `pet` calls, through [`SelfIdentification::take_search`]. That costs a copy of the
    /// estimation statistics and the tick's stack on top of the search's deepest frame, which
    /// the ATmega2560's 8 KB do not have; without it the blocking
    /// [`SelfIdentification::search`] runs and the PWM holds the base duty meanwhile, with
    /// the sensor read and the fault checks ([`SelfIdentification::guard`]) at every tick
    /// boundary.
    const TICK_DURING_SEARCH: bool;
    /// Non-blocking: the number of 10 ms tick boundaries that passed since the last call that
    /// returned `Some` (≥ 1), or `None` if none did.
    fn poll_tick(&mut self) -> Option<u16>;
    /// Restarts the watchdog's timeout.
    fn pet(&mut self);
    /// Stores `record` (the board may finish the write later, see [`poll_store`]).
    ///
    /// [`poll_store`]: Board::poll_store
    fn save(&mut self, record: &[u8]);
    /// Advances a pending write; `Some(ok)` once when a write finished.
    fn poll_store(&mut self) -> Option<bool>;
    /// Stack high-water mark `(used, free)` in bytes, if the board measures it.
    fn stack(&self) -> Option<(u16, u16)>;
    /// Non-blocking: the next received console byte, if any.
    fn receive(&mut self) -> Option<u8> {
        None
    }
    /// Whether received bytes were lost since the last call (the receive queue was full). A
    /// board that marks the place in its queue instead ([`crate::command::LOST`], the
    /// ATmega2560) keeps the default `false`.
    fn receive_overrun(&mut self) -> bool {
        false
    }
    /// Free bytes in the transmit queue: a log row is sent only if it fits whole.
    fn tx_room(&self) -> usize {
        usize::MAX
    }
    /// The console's state, if the board has a console (receives commands). `None` leaves
    /// the console code out of the image.
    fn console(&mut self) -> Option<&mut Console> {
        None
    }
}

/// The console's state (kept by the board, see [`Board::console`]): the line being received,
/// a command waiting for the end of a blocking search, and the log.
#[derive(Debug, Clone, Default)]
pub struct Console {
    /// The line being received.
    line: Line,
    /// `MODEL` was answered and this `RST` line (if a controller is in use then), and those of
    /// the polynomials after it, wait for room in the transmit queue.
    rst_due: Option<Poly>,
    /// Tick boundaries since the start (the log's time base).
    clock: u32,
    /// Whether the CSV log is on.
    log: bool,
    /// Log rows dropped (transmit queue full), and the count last reported.
    dropped: u16,
    dropped_reported: u16,
}

impl Console {
    /// No line, log off, clock at 0.
    pub const fn new() -> Self {
        Console {
            line: Line::new(),
            rst_due: None,
            clock: 0,
            log: false,
            dropped: 0,
            dropped_reported: 0,
        }
    }

    /// Whether the CSV log is on.
    pub fn log(&self) -> bool {
        self.log
    }

    /// Log rows dropped so far.
    pub fn dropped(&self) -> u16 {
        self.dropped
    }
}

/// Loop state: peripherals, the state machine and counters.
pub struct App<I, P, W, S: Settings = &'static Config> {
    sensor: Sfm3300<I>,
    pump: Pump<P>,
    out: W,
    sid: SelfIdentification<S>,
    late: u16,
    lost: u16,
    /// A search or design ended in the last pass: the next pass's tick is not late.
    after_job: bool,
    reported: (u16, u16),
    summary_in: u8,
    /// The last blocking job and its `(ticks, lost)`, for its line in the next pass.
    search_lines: Option<(Job, u16, u16)>,
}

impl<I: I2c, P: SetDutyCycle, W: uWrite, S: Settings> App<I, P, W, S> {
    /// Puts the parts together; nothing is sent yet. `i2c_hz` is the sensor bus clock (Hz),
    /// which sets the read attempts per sample ([`read_attempts`]).
    pub fn new(
        mut sensor: Sfm3300<I>,
        pump: Pump<P>,
        out: W,
        sid: SelfIdentification<S>,
        i2c_hz: u32,
    ) -> Self {
        sensor.set_read_attempts(read_attempts(i2c_hz));
        App {
            sensor,
            pump,
            out,
            sid,
            late: 0,
            after_job: false,
            lost: 0,
            reported: (0, 0),
            summary_in: SUMMARY_TICKS,
            search_lines: None,
        }
    }

    /// The state machine (for status lines and host tests).
    pub fn selfid(&self) -> &SelfIdentification<S> {
        &self.sid
    }

    /// The pump driver (its applied and commanded duty).
    pub fn pump(&self) -> &Pump<P> {
        &self.pump
    }

    /// Starts continuous measurement, retrying once per tick for up to [`START_TICKS`] ticks
    /// (the state machine is not ticked meanwhile: the pump stays stopped). A sensor that never
    /// answers is left to the state machine, which reports the fault on its first ticks.
    pub fn start(&mut self, board: &mut impl Board) {
        for tries in 1..=START_TICKS {
            wait_tick(board, |_| {});
            board.pet();
            if self.sensor.start_continuous().is_ok() {
                uwriteln!(self.out, "SENSOR ready tries={}", Int::from(tries)).ok();
                return;
            }
        }
        uwriteln!(self.out, "SENSOR start failed").ok();
    }

    /// Runs the loop forever.
    pub fn run(&mut self, board: &mut impl Board) -> ! {
        self.start(board);
        loop {
            self.step(board);
        }
    }

    /// One pass: wait for the tick, then do that tick's work (and the search if due).
    #[inline(never)]
    pub fn step<B: Board>(&mut self, board: &mut B) {
        let (elapsed, late) = self.wait(board);
        board.pet();
        let after_job = core::mem::take(&mut self.after_job);
        if late && !after_job {
            self.late = self.late.saturating_add(1);
        }
        self.lost = self.lost.saturating_add(elapsed - 1);
        if let Some(c) = board.console() {
            c.clock = c.clock.wrapping_add(u32::from(elapsed) - 1);
        }
        self.tick(board);
        self.summary(board);
        self.print_search_lines(board);
        self.serve(board);
        if self.sid.needs_judgement() {
            self.judge(board);
        }
        if self.sid.needs_search() {
            // A blocking search's normal equations are built first, in a frame of their own
            // that is gone before the search's is built (ATmega2560 stack).
            if !B::TICK_DURING_SEARCH {
                self.sid.prepare_search();
            }
            let end = self.search(board);
            self.after_search(board, end);
        }
        if self.sid.needs_design() {
            let end = self.design(board);
            self.after_search(board, end);
        }
    }

    /// Scores the complete validation record (after the tick's PWM write, so that it does not
    /// delay it), stops the pump at once if that latched a fault, and reports the outcome.
    #[inline(never)]
    fn judge(&mut self, board: &mut impl Board) {
        if let Some(event) = self.sid.judge() {
            self.stop_on_fault();
            self.report(board, &event);
        }
    }

    /// Stops the pump now when the state machine holds a fault (its duty is then 0), instead
    /// of at the next tick.
    fn stop_on_fault(&mut self) {
        if self.sid.fault().is_some() {
            self.pump.stop().ok();
        }
    }

    /// One tick's work: sensor, state machine, pump, event, persistence. Never inlined: it is
    /// called from the loop and from inside the search's pet closure, and one copy is enough.
    #[inline(never)]
    fn tick<B: Board>(&mut self, board: &mut B) {
        if let Some(c) = board.console() {
            c.clock = c.clock.wrapping_add(1);
        }
        let before = (self.sid.state(), self.sid.duty(), self.sid.setpoint());
        let flow = self.sensor.read_counts().map_err(SensorFault::from);
        let mut event = None;
        let duty = self.sid.tick_into(flow, &mut event);
        if self.pump.set(duty).is_err() {
            self.pump.stop().ok();
            uwriteln!(self.out, "PUMP error").ok();
        }
        if let Some(event) = &event {
            self.report(board, event);
        }
        if let Some(ok) = board.poll_store() {
            let line = if ok {
                "PERSIST saved"
            } else {
                "PERSIST failed"
            };
            uwriteln!(self.out, "{}", line).ok();
        }
        let room = board.tx_room();
        if let Some(c) = board.console().filter(|c| c.log) {
            let (state, duty, setpoint) = before;
            let row = LogRow {
                tick: c.clock,
                duty,
                counts: self.sid.reading(),
                setpoint,
                state,
            };
            if room >= LOG_ROW_MAX {
                uwriteln!(self.out, "{}", row).ok();
            } else {
                c.dropped = c.dropped.wrapping_add(1);
            }
        }
    }

    /// Answers the console, once the transmit queue has [`ANSWER_ROOM`] bytes free: the `RST`
    /// line of a `MODEL` answered before, else the command of the line the wait completed,
    /// executed at once.
    #[inline(never)]
    fn serve(&mut self, board: &mut impl Board) {
        if board.console().is_none() || board.tx_room() < ANSWER_ROOM {
            return;
        }
        if let Some(c) = board.console() {
            if let Some(poly) = c.rst_due {
                c.rst_due = poly.next();
                if let Some(ctrl) = self.sid.controller() {
                    uwriteln!(self.out, "{}", RstLine(ctrl.rst(), poly)).ok();
                }
                return;
            }
        }
        if let Some(c) = board.console().filter(|c| c.line.is_complete()) {
            let command = c.line.take();
            self.execute(board, command);
        }
    }

    /// `STOP`: the state machine stops (latched until `START`) and the pump's PWM goes to 0.
    #[inline(never)]
    fn halt(&mut self) {
        self.sid.stop();
        self.pump.stop().ok();
    }

    /// [`wait_tick`], moving received console bytes into the console's line meanwhile
    /// ([`listen`]): a `STOP` completed there stops the state machine and the pump at once
    /// (its answer comes with the next pass); any other line waits for the next pass's
    /// [`serve`](Self::serve).
    fn wait<B: Board>(&mut self, board: &mut B) -> (u16, bool) {
        wait_tick(board, |board| {
            if listen(board) {
                self.halt();
            }
        })
    }

    /// Executes a console command and answers it (one line, `MODEL` two in run mode).
    fn execute(&mut self, board: &mut impl Board, command: Result<Command, CommandError>) {
        let answer = match command {
            Err(e) => Err(e),
            Ok(Command::Status) => {
                let status = Status {
                    state: self.sid.state(),
                    duty: self.pump.applied(),
                    counts: self.sid.reading(),
                    setpoint: self.sid.setpoint(),
                    log: board.console().is_some_and(|c| c.log),
                    fault: self.sid.fault(),
                };
                uwriteln!(self.out, "{}", status).ok();
                return;
            }
            Ok(Command::Stop) => {
                self.halt();
                if self.sid.state() == State::Fault {
                    Err(CommandError::State)
                } else {
                    Ok("stop")
                }
            }
            Ok(Command::Start) => match self.sid.start() {
                true => Ok("start"),
                false => Err(CommandError::State),
            },
            Ok(Command::Set(milli)) => self
                .sid
                .set_flow(milli as f32 / 1000.0)
                .map(|()| "set")
                .map_err(CommandError::Range),
            Ok(Command::Profile(args)) => self
                .sid
                .set_profile(&args)
                .map(|()| "profile")
                .map_err(CommandError::Range),
            Ok(Command::Reid) => match self.sid.state() {
                State::Fault | State::Stopped => Err(CommandError::State),
                _ => {
                    self.sid.request_reidentification();
                    Ok("reid")
                }
            },
            Ok(Command::Model) => {
                let model = ModelLine {
                    model: self.sid.model().zip(self.sid.fit()),
                };
                uwriteln!(self.out, "{}", model).ok();
                if let Some(c) = board.console() {
                    c.rst_due = Some(Poly::R);
                }
                return;
            }
            Ok(Command::Forget) => {
                // An erased record (all 0xFF) reads back as no record. Filled at run time: a
                // constant array would be kept in the ATmega2560's RAM.
                board.save(&[core::hint::black_box(0xFF); RECORD_LEN]);
                Ok("forget")
            }
            Ok(Command::Log(on)) => {
                if let Some(c) = board.console() {
                    c.log = on;
                }
                uwriteln!(self.out, "OK log").ok();
                if on {
                    uwriteln!(self.out, "{}", LOG_HEADER).ok();
                }
                return;
            }
        };
        match answer {
            Ok(name) => {
                uwriteln!(self.out, "OK {}", name).ok();
            }
            Err(CommandError::Range(what)) => {
                uwriteln!(self.out, "ERR range {}", what).ok();
            }
            Err(e) => {
                uwriteln!(self.out, "ERR {}", e.name()).ok();
            }
        }
    }

    /// Prints an event and persists the record if the event asks for it.
    #[inline(never)]
    fn report(&mut self, board: &mut impl Board, event: &Event) {
        uwriteln!(self.out, "{}", event).ok();
        if event.persist() {
            if let Some(record) = self.sid.persist_bytes() {
                board.save(&record);
            }
        }
    }

    /// Runs the search (ticking from its `pet` calls if the board does).
    ///
    /// Never inlined: the search's locals (the job with its statistics, the normal equations,
    /// the candidate systems: several KB on the ATmega2560) must only be on the stack while it
    /// runs, not in the frame of the endless loop, nor under the catch-up tick that follows.
    #[inline(never)]
    fn search<B: Board>(&mut self, board: &mut B) -> SearchEnd {
        let (mut ticks, mut lost) = (0u16, 0u16);
        let mut fault = None;
        let job = Job::Search;
        let event = if B::TICK_DURING_SEARCH {
            let Some(job) = self.sid.take_search() else {
                return SearchEnd {
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
            let mut watch = Watch::new(&self.sid, &mut self.sensor, &mut self.pump, board);
            let event = self.sid.run_search(|| watch.pet());
            self.sid.resume_guard(&watch.guard);
            (ticks, lost, fault) = (watch.ticks, watch.lost, watch.fault);
            event
        };
        SearchEnd {
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
    fn design<B: Board>(&mut self, board: &mut B) -> SearchEnd {
        let mut watch = Watch::new(&self.sid, &mut self.sensor, &mut self.pump, board);
        let event = self.sid.design(|| watch.pet());
        self.sid.resume_guard(&watch.guard);
        SearchEnd {
            job: Job::Design,
            event,
            fault: watch.fault,
            ticks: watch.ticks,
            lost: watch.lost,
        }
    }

    /// After a search (its frame is gone): its event (and a fault the guard found). The next
    /// pass ticks at once if a boundary passed meanwhile, and is not counted late for it (the
    /// job's time is on its `SEARCH` / `DESIGN` line). The `SEARCH` / `STACK` lines wait for
    /// that pass, right after its tick, so that printing them cannot run into the next tick
    /// boundary.
    fn after_search<B: Board>(&mut self, board: &mut B, end: SearchEnd) {
        let SearchEnd {
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
            // The log's clock: boundaries skipped, and those the watch handled (a ticking
            // search clocked its ticks already).
            let watched = if job == Job::Search && B::TICK_DURING_SEARCH {
                0
            } else {
                ticks
            };
            c.clock = c.clock.wrapping_add(u32::from(watched) + u32::from(lost));
            if c.line.is_stop() {
                // The watch stopped the pump; the state machine follows now (the answer in
                // the next pass).
                self.sid.stop();
            }
        }
        // The boundary that passes while the job ends is the next pass's tick, not a late one.
        self.after_job = true;
        self.search_lines = Some((job, ticks, lost));
    }

    /// The `SEARCH` / `STACK` lines of the last search, once.
    fn print_search_lines(&mut self, board: &impl Board) {
        if let Some((job, ticks, lost)) = self.search_lines.take() {
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

    /// Prints `MISSED` and `LOG dropped` once a second when the totals changed.
    fn summary(&mut self, board: &mut impl Board) {
        self.summary_in -= 1;
        if self.summary_in == 0 {
            self.summary_in = SUMMARY_TICKS;
            if let Some(c) = board.console().filter(|c| c.dropped != c.dropped_reported) {
                c.dropped_reported = c.dropped;
                uwriteln!(self.out, "LOG dropped={}", Int::from(c.dropped)).ok();
            }
            if (self.late, self.lost) != self.reported {
                self.reported = (self.late, self.lost);
                uwriteln!(
                    self.out,
                    "MISSED late={} lost={}",
                    Int::from(self.late),
                    Int::from(self.lost)
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
struct Watch<'a, I, P, B> {
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

impl<'a, I: I2c, P: SetDutyCycle, B: Board> Watch<'a, I, P, B> {
    /// The guard of `sid` at the pump's applied duty, counters at zero.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    fn new(
        sid: &SelfIdentification<impl Settings>,
        sensor: &'a mut Sfm3300<I>,
        pump: &'a mut Pump<P>,
        board: &'a mut B,
    ) -> Self {
        Watch {
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

impl<I: I2c, P: SetDutyCycle, B: Board> Watch<'_, I, P, B> {
    /// The console during a blocking search: received bytes go into the console's line, which
    /// is held for after it; a `STOP` stops the pump now.
    fn console(&mut self) {
        if listen(self.board) {
            self.pump.stop().ok();
            self.applied = 0;
        }
    }
}

/// Moves received bytes into the console's line until it holds a complete line (then they
/// wait in the receive queue); `true` when the line completed now is `STOP`. No parsing: a
/// few dozen cycles per byte. Inlined up to the first byte: in the loop's idle wait, where it
/// runs between polls of the tick, an empty queue costs a dozen instructions.
#[inline(always)]
fn listen(board: &mut impl Board) -> bool {
    if board.console().is_none_or(|c| c.line.is_complete()) {
        return false;
    }
    match board.receive() {
        Some(byte) => listen_from(board, byte),
        None => {
            lost(board);
            false
        }
    }
}

/// [`listen`] from the received `byte` on.
#[inline(never)]
fn listen_from(board: &mut impl Board, mut byte: u8) -> bool {
    loop {
        let Some(c) = board.console() else {
            return false;
        };
        if c.line.feed(byte) {
            return c.line.is_stop();
        }
        match board.receive() {
            Some(b) => byte = b,
            None => {
                lost(board);
                return false;
            }
        }
    }
}

/// With the receive queue read empty: a loss the board reports by flag
/// ([`Board::receive_overrun`], once the bytes before it are read) damages the line in
/// progress. Nothing on a board that marks losses in its queue.
#[inline(always)]
fn lost(board: &mut impl Board) {
    if board.receive_overrun() {
        if let Some(c) = board.console() {
            c.line.overrun();
        }
    }
}

/// The blocking work the loop runs between ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Job {
    /// The structure search.
    Search,
    /// The controller design.
    Design,
}

/// How a search (or design) ended, for [`App::after_search`].
struct SearchEnd {
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

/// Waits for the next tick boundary: `(boundaries passed, already passed on entry)`;
/// `idle` runs between the polls.
#[inline(always)]
fn wait_tick<B: Board>(board: &mut B, mut idle: impl FnMut(&mut B)) -> (u16, bool) {
    if let Some(elapsed) = board.poll_tick() {
        return (elapsed, true);
    }
    loop {
        if let Some(elapsed) = board.poll_tick() {
            return (elapsed, false);
        }
        idle(board);
    }
}
