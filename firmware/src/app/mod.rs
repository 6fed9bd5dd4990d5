//! The 100 Hz main loop shared by both boards: wait for the tick, pet the watchdog, read the
//! SFM3300 (I2C in the main loop, never in an interrupt), step the self-identification state
//! machine ([`crate::selfid`]), apply its duty to the pump and its exhalation valve state,
//! finish the tick's work (run mode's controller memory, monitor and tracking, a volume breath's
//! bookkeeping), print its events, persist its record when an event asks for it, and — after
//! the PWM write — judge the scan's map or the validation record and run the structure search
//! or the controller design when they are due.
//!
//! | file | concern |
//! |---|---|
//! | `mod.rs` | the loop: [`App`], one pass ([`App::step`]), the tick's work, the tick accounting |
//! | `board.rs` | what the loop needs from a board: [`Board`] |
//! | `serve.rs` | the operator's console: its state ([`Console`]), bytes in, commands answered |
//! | `jobs.rs` | the blocking jobs between ticks: the structure search, the controller design |
//!
//! Report lines written by the loop (`\n`-terminated ASCII), besides the state machine's events
//! (see [`crate::event`]):
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

mod board;
mod jobs;
mod serve;

pub use board::Board;
pub use serve::{Console, ANSWER_ROOM};

use crate::console::{LogRow, LOG_ROW_MAX};
use crate::event::{Event, SensorFault};
use crate::numfmt::Int;
use crate::pump::Pump;
use crate::selfid::{Config, SelfIdentification, Settings};
use crate::sfm3300::Sfm3300;
use crate::ventilation::Valve;
use embedded_hal::i2c::I2c;
use embedded_hal::pwm::SetDutyCycle;
use jobs::Job;
use ufmt::{uWrite, uwriteln};

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

/// Loop state: peripherals, the state machine and counters.
pub struct App<I, P, W, S: Settings = &'static Config> {
    sensor: Sfm3300<I>,
    pump: Pump<P>,
    out: W,
    sid: SelfIdentification<S>,
    late: u16,
    lost: u16,
    /// A search or design ended in the last pass: the next pass's tick is not late.
    job_ended: bool,
    reported: (u16, u16),
    summary_in: u8,
    /// The last blocking job and its `(ticks, lost)`, for its line in the next pass.
    job_lines: Option<(Job, u16, u16)>,
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
            lost: 0,
            job_ended: false,
            reported: (0, 0),
            summary_in: SUMMARY_TICKS,
            job_lines: None,
        }
    }

    /// The state machine (for status lines and host tests).
    pub fn selfid(&self) -> &SelfIdentification<S> {
        &self.sid
    }

    /// The state machine, to change (a board's boot: a fault found before the loop starts).
    pub fn selfid_mut(&mut self) -> &mut SelfIdentification<S> {
        &mut self.sid
    }

    /// The pump driver (its applied and commanded duty).
    pub fn pump(&self) -> &Pump<P> {
        &self.pump
    }

    /// Starts continuous measurement, retrying once per tick for up to [`START_TICKS`] ticks
    /// (the state machine is not ticked meanwhile: the pump stays stopped). A sensor that never
    /// answers is left to the state machine, which reports the fault on its first ticks.
    #[cfg_attr(all(target_arch = "avr", feature = "atmega2560-reid"), inline(never))]
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
        let job_ended = core::mem::take(&mut self.job_ended);
        if late && !job_ended {
            self.late = self.late.saturating_add(1);
        }
        self.lost = self.lost.saturating_add(elapsed - 1);
        if let Some(c) = board.console() {
            c.clock = c.clock.wrapping_add(u32::from(elapsed) - 1);
        }
        self.tick(board);
        self.summary(board);
        self.print_job_lines(board);
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
            self.after_job(board, end);
        }
        if self.sid.needs_design() {
            let end = self.design(board);
            self.after_job(board, end);
        }
    }

    /// Makes the scan's map or scores the complete validation record (after the tick's PWM
    /// write, so that it does not delay it), stops the pump at once if that latched a fault,
    /// and reports the outcome.
    #[inline(never)]
    fn judge(&mut self, board: &mut impl Board) {
        if let Some(event) = self.sid.judge() {
            self.stop_on_fault(board);
            self.report(board, &event);
        }
    }

    /// Stops the pump and opens the exhalation valve now when the state machine holds a fault
    /// (its duty is then 0), instead of at the next tick.
    fn stop_on_fault(&mut self, board: &mut impl Board) {
        if self.sid.fault().is_some() {
            self.pump.stop().ok();
            board.set_valve(Valve::Open);
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
        let pumped = self.pump.set(duty).is_ok();
        // The valve follows the PWM write (the control tick ends with that write).
        board.set_valve(if pumped {
            self.sid.valve()
        } else {
            Valve::Open
        });
        if !pumped {
            self.pump.stop().ok();
            uwriteln!(self.out, "PUMP error").ok();
        }
        // The tick's work that does not set its duty (run mode: the controller's memory, the
        // monitor, the tracking, then a volume breath's bookkeeping), after the PWM write.
        self.sid.after_write(&mut event);
        self.sid.after_pwm(&mut event);
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

    /// [`wait_tick`], moving received console bytes into the console's line meanwhile
    /// ([`serve::listen`]): a `STOP` completed there stops the state machine and the pump at once
    /// (its answer comes with the next pass); any other line waits for the next pass's
    /// [`serve`](Self::serve).
    fn wait<B: Board>(&mut self, board: &mut B) -> (u16, bool) {
        wait_tick(board, |board| {
            if serve::listen(board) {
                self.halt(board);
            }
        })
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
