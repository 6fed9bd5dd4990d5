//! The operator's console as the loop serves it: its state ([`Console`], kept by the board),
//! received bytes moved into its line, commands executed and answered.
//!
//! While the loop waits for a tick it moves received bytes into the console's line (no
//! parsing there): a completed `STOP` stops the state machine and writes duty 0 to the PWM at
//! once, within microseconds of its last byte when the loop is idle and at the end of the
//! pass otherwise. Any other line is held (further bytes wait in the receive queue) and
//! executed after the next tick's PWM write, at most one command per pass, once the transmit
//! queue has [`ANSWER_ROOM`] bytes free ([`crate::command`], answers in [`crate::console`]).
//! While a blocking search or design runs, the keepalive (`jobs.rs`) keeps collecting bytes
//! at every tick boundary: a `STOP` stops the pump there and then (the state machine follows
//! after the search); any other command waits for the end of the search. With the log on,
//! each tick appends its [`LogRow`](crate::console::LogRow) after the PWM write.

use super::{App, Board};
use crate::command::{Command, CommandError, Line};
use crate::console::{ModelLine, Poly, RstLine, Status, LOG_HEADER};
use crate::event::Event;
use crate::persist::RECORD_LEN;
use crate::selfid::{Settings, State};
use embedded_hal::i2c::I2c;
use embedded_hal::pwm::SetDutyCycle;
use ufmt::{uWrite, uwriteln};

/// Free bytes the transmit queue must have before the console answers a command, so that the
/// answer goes out without the loop waiting for the line: more than the answer lines of a
/// model of orders p, q ≤ 6 take with coefficients of up to 9 characters (`MODEL` ≤ 180
/// bytes; its `RST` lines, one per polynomial and pass after it under the same condition,
/// ≤ 137). A longer line waits for the rest at 11.5 bytes per ms.
pub const ANSWER_ROOM: usize = 200;

/// The console's state (kept by the board, see [`Board::console`]): the line being received,
/// a command waiting for the end of a blocking search, and the log.
#[derive(Debug, Clone, Default)]
pub struct Console {
    /// The line being received.
    pub(super) line: Line,
    /// `MODEL` was answered and its `MAP` line waits for room in the transmit queue.
    pub(super) map_due: bool,
    /// `MODEL` was answered and this `RST` line (if a controller is in use then), and those of
    /// the polynomials after it, wait for room in the transmit queue.
    pub(super) rst_due: Option<Poly>,
    /// Tick boundaries since the start (the log's time base).
    pub(super) clock: u32,
    /// Whether the CSV log is on.
    pub(super) log: bool,
    /// Log rows dropped (transmit queue full), and the count last reported.
    pub(super) dropped: u16,
    pub(super) dropped_reported: u16,
}

impl Console {
    /// No line, log off, clock at 0.
    pub const fn new() -> Self {
        Console {
            line: Line::new(),
            map_due: false,
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

impl<I: I2c, P: SetDutyCycle, W: uWrite, S: Settings> App<I, P, W, S> {
    /// Answers the console, once the transmit queue has [`ANSWER_ROOM`] bytes free: the `MAP`
    /// or `RST` line of a `MODEL` answered before, else the command of the line the wait
    /// completed, executed at once.
    #[inline(never)]
    pub(super) fn serve(&mut self, board: &mut impl Board) {
        if board.console().is_none() || board.tx_room() < ANSWER_ROOM {
            return;
        }
        if let Some(c) = board.console() {
            if c.map_due {
                c.map_due = false;
                if let Some(map) = self.sid.map() {
                    uwriteln!(self.out, "{}", Event::Map(*map)).ok();
                }
                return;
            }
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
    pub(super) fn halt(&mut self) {
        self.sid.stop();
        self.pump.stop().ok();
    }

    /// Executes a console command and answers it (one line; `MODEL` is followed by its `MAP`
    /// line and in run mode the `RST` lines, one per pass).
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
                    c.map_due = true;
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
}

/// Moves received bytes into the console's line until it holds a complete line (then they
/// wait in the receive queue); `true` when the line completed now is `STOP`. No parsing: a
/// few dozen cycles per byte. Inlined up to the first byte: in the loop's idle wait, where it
/// runs between polls of the tick, an empty queue costs a dozen instructions.
#[inline(always)]
pub(super) fn listen(board: &mut impl Board) -> bool {
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
