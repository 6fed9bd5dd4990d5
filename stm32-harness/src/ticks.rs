//! The loop's ticks seen from the bus, with no marker in the firmware: the image waits for
//! each 10 ms tick by polling TIM5's counter, so
//! - the loop is **idle** while it reads `TIM5_CNT` over and over (the machine's poll
//!   detector: three equal reads of the register, at most [`POLL_GAP`] instructions apart,
//!   with no other access between);
//! - a **tick starts** at the last counter read before the loop leaves that wait (the read
//!   that saw the new 10 ms boundary; the next access is the watchdog's reload);
//! - its **control latency** ends with its first write of the pump's compare register
//!   (`TIM3_CCR1`): sensor read, state machine, PWM;
//! - it **ends** at the first read of the next idle wait.
//!
//! Instructions and emulated time are both recorded: the instructions are the CPU's work
//! (the waits for the I2C bus and the UART take time but, once the clock jump has skipped
//! them, few instructions); the time includes the bus transfers.

use crate::periph::Time;

/// Largest instruction gap between two reads of one register that still counts as polling.
pub const POLL_GAP: u64 = 64;
/// Equal reads in a row that make a poll.
pub const POLL_READS: u32 = 3;

/// One tick: from leaving the idle wait to coming back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tick {
    /// Emulated time and instruction count of the counter read that started it.
    pub start: Time,
    /// Instruction count at the start.
    pub start_instr: u64,
    /// Instructions from the start to the end of the first `TIM3_CCR1` write, if any.
    pub control_instr: Option<u64>,
    /// Emulated time from the start to that write, ps.
    pub control_ps: Option<Time>,
    /// Instructions from the start to the first read of the next idle wait.
    pub busy_instr: u64,
    /// Emulated time of the same, ps.
    pub busy_ps: Time,
}

/// An open tick: its start (time, instructions) and its first PWM write, once seen.
type Open = (Time, u64, Option<(Time, u64)>);

/// Tick detection state (fed by the machine's bus callbacks).
#[derive(Clone, Debug, Default)]
pub struct TickMeter {
    idle: bool,
    /// The last counter read while idle: (time, instructions).
    last_read: Option<(Time, u64)>,
    /// The open tick: start and control.
    open: Option<Open>,
    /// Ticks measured.
    pub ticks: Vec<Tick>,
}

impl TickMeter {
    /// A read of the tick counter at `(now, instr)`.
    pub fn counter_read(&mut self, now: Time, instr: u64) {
        if self.idle {
            self.last_read = Some((now, instr));
        }
    }

    /// The poll detector fired on the tick counter; its run's first read was at
    /// `(at, at_instr)`.
    pub fn idle(&mut self, at: Time, at_instr: u64) {
        if let Some((start, start_instr, control)) = self.open.take() {
            self.ticks.push(Tick {
                start,
                start_instr,
                control_instr: control.map(|(_, i)| i - start_instr),
                control_ps: control.map(|(t, _)| t - start),
                busy_instr: at_instr.saturating_sub(start_instr),
                busy_ps: at.saturating_sub(start),
            });
        }
        self.idle = true;
        self.last_read = Some((at, at_instr));
    }

    /// Any other bus access: leaving the idle wait starts a tick.
    pub fn other_access(&mut self) {
        if self.idle {
            self.idle = false;
            if let Some((t, i)) = self.last_read.take() {
                self.open = Some((t, i, None));
            }
        }
    }

    /// A write of the pump's compare register at `(now, instr)` (after the instruction).
    pub fn pwm_write(&mut self, now: Time, instr: u64) {
        if let Some((s, si, None)) = self.open {
            self.open = Some((s, si, Some((now, instr))));
        }
    }

    /// A reset: the open tick is dropped.
    pub fn reset(&mut self) {
        self.idle = false;
        self.last_read = None;
        self.open = None;
    }
}
