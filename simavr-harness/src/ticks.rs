//! Tick timing on the bench ([`crate::bench::Bench`]), measured from the core's cycle counter,
//! with no help from the firmware:
//! - **tick start**: entry into the tick interrupt (TIMER3_COMPA, vector 32, by default);
//! - **tick end**: the tick ISR's return, and — for boards that do the tick's work in the main
//!   loop after the ISR released it — the first instruction back in the main loop's idle
//!   wait. The idle loop is learned from the addresses the tick ISR interrupts (the most
//!   frequent one and its neighbours within 16 bytes), so no marker pin is needed;
//! - a tick is **missed** when the ISR finds the main loop outside its idle wait (the previous
//!   tick's work was still running);
//! - **control latency** of a tick: from the tick ISR's entry to the end of the first
//!   instruction in that tick that writes the pump channel's compare register (`OCRnX` low
//!   byte, which completes the 16-bit update) or its `TCCRnA` (output connected/disconnected).
//!   Those `STS` instructions are found by scanning the flash at load, so this too needs no
//!   marker in the firmware. It covers the sensor read, the state machine with the statistics
//!   update, and the PWM write; report lines and persistence that follow are in `busy` only.

use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

use crate::machine::IrqEvent;

/// Timing of one tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickTiming {
    /// ISR entry cycle.
    pub start: u64,
    /// Cycles from ISR entry to the end of the tick's work: back in the idle wait when the ISR
    /// found the main loop idle; otherwise up to the ISR's return (or to the next tick's ISR).
    pub busy: u64,
    /// The tick did not end in the idle wait: the ISR found the main loop busy (a blocking job
    /// such as the search, or the previous tick overrunning), or the next tick fired first.
    pub interrupted_busy: bool,
    /// Cycles from ISR entry to the end of the tick's first write of the pump PWM registers
    /// (see the module docs); `None` if the tick wrote none (or the ISR found the loop busy).
    pub control: Option<u64>,
}

/// The meter the bench steps after every instruction batch and feeds the tick vector's
/// interrupt events (see the module docs).
#[derive(Debug, Default)]
pub(crate) struct TickMeter {
    vector: Option<u8>,
    events: Option<Rc<RefCell<Vec<IrqEvent>>>>,
    seen: usize,
    /// Last (program counter, stack pointer) pairs (ring), to learn the idle loop.
    ring: Vec<(u32, u16)>,
    ring_pos: usize,
    /// For each learning tick: the distinct (PC, SP) executed just before the ISR fired.
    learning: Vec<Vec<(u32, u16)>>,
    /// The idle wait's (instruction address, stack pointer) pairs (sorted), once learned. The
    /// stack pointer tells the wait loop from the same code called deeper (e.g. the tick poll
    /// inside a long job).
    idle: Option<Vec<(u32, u16)>>,
    /// Open tick: (start, isr_end, what it waits for).
    open: Option<(u64, Option<u64>, Wait)>,
    /// Control latency of the open tick, once its first PWM write executed.
    open_control: Option<u64>,
    /// Flash byte addresses of the instructions that write the pump PWM registers (sorted).
    pwm_sites: Vec<u32>,
    ticks: Vec<TickTiming>,
    idle_cycles: u64,
    last_cycle: u64,
    last_idle: bool,
}

/// Learn the idle loop from this many tick-ISR entries.
const LEARN_TICKS: usize = 32;
/// PCs remembered before each ISR entry (the idle loop must be shorter).
const RING: usize = 64;

impl TickMeter {
    /// A meter for the tick interrupt `vector` (its entry/return `events`, `None` without
    /// one) and the flash addresses of the instructions that write the pump PWM registers.
    pub(crate) fn new(
        vector: Option<u8>,
        events: Option<Rc<RefCell<Vec<IrqEvent>>>>,
        mut pwm_sites: Vec<u32>,
    ) -> Self {
        pwm_sites.sort_unstable();
        TickMeter {
            ring: vec![(0, 0); RING],
            pwm_sites,
            vector,
            events,
            ..TickMeter::default()
        }
    }

    /// The ticks measured so far.
    pub(crate) fn ticks(&self) -> &[TickTiming] {
        &self.ticks
    }

    /// The idle wait's (instruction address, stack pointer) pairs, once learned.
    pub(crate) fn idle(&self) -> Option<&[(u32, u16)]> {
        self.idle.as_deref()
    }

    /// Cycles spent in the idle wait.
    pub(crate) fn idle_cycles(&self) -> u64 {
        self.idle_cycles
    }

    /// The tick interrupt's vector.
    pub(crate) fn vector(&self) -> Option<u8> {
        self.vector
    }

    fn is_idle(&self, pc: u32, sp: u16) -> bool {
        self.idle
            .as_ref()
            .is_some_and(|v| v.binary_search(&(pc, sp)).is_ok())
    }

    /// The idle loop = the PCs found right before (at least 90 % of) the learning ISR entries.
    fn learn(&mut self) {
        let mut count: HashMap<(u32, u16), usize> = HashMap::new();
        for set in &self.learning {
            for &p in set {
                *count.entry(p).or_default() += 1;
            }
        }
        let need = self.learning.len() * 9 / 10;
        let mut idle: Vec<(u32, u16)> = count
            .into_iter()
            .filter(|&(_, n)| n >= need)
            .map(|(p, _)| p)
            .collect();
        idle.sort_unstable();
        self.idle = Some(idle);
    }

    /// Called after every instruction with the cycle, PC and SP after it, SREG.I, and the
    /// address of the instruction just executed.
    pub(crate) fn after_step(
        &mut self,
        cycle: u64,
        pc: u32,
        sp: u16,
        int_enabled: bool,
        executed: u32,
    ) {
        if self.last_idle {
            self.idle_cycles += cycle - self.last_cycle;
        }
        self.last_cycle = cycle;
        self.ring[self.ring_pos] = (pc, sp);
        self.ring_pos = (self.ring_pos + 1) % RING;
        if let Some(ev) = &self.events {
            let n = ev.borrow().len();
            if n != self.seen {
                let new: Vec<IrqEvent> = ev.borrow()[self.seen..].to_vec();
                self.seen = n;
                for e in new {
                    self.on_event(e);
                }
            }
        }
        if let Some((start, _, wait)) = self.open {
            if wait != Wait::Busy
                && self.open_control.is_none()
                && self.pwm_sites.binary_search(&executed).is_ok()
            {
                self.open_control = Some(cycle - start);
            }
        }
        let idle_now = self.is_idle(pc, sp);
        self.last_idle = idle_now;
        match self.open {
            // ISR returned into the idle wait: the tick's work starts when the main loop
            // leaves it (an instruction outside the wait with interrupts enabled, i.e. not
            // another ISR such as the UART's) ...
            Some((start, Some(ret), Wait::Leave)) if !idle_now && int_enabled => {
                self.open = Some((start, Some(ret), Wait::Return));
            }
            // ... and ends when it is back: tentatively at the first instruction back in the
            // wait, confirmed once the loop has stayed there for `CONFIRM` cycles (the tick poll
            // shares its tail with the path that detects the tick) ...
            Some((start, Some(ret), Wait::Return)) if idle_now => {
                self.open = Some((start, Some(ret), Wait::Confirm(cycle)));
            }
            Some((start, Some(ret), Wait::Confirm(_))) if !idle_now && int_enabled => {
                self.open = Some((start, Some(ret), Wait::Return));
            }
            Some((start, Some(_), Wait::Confirm(end))) if cycle - end >= CONFIRM => {
                self.close(start, end);
            }
            _ => {}
        }
    }

    fn close(&mut self, start: u64, end: u64) {
        self.open = None;
        self.ticks.push(TickTiming {
            start,
            busy: end - start,
            interrupted_busy: false,
            control: self.open_control.take(),
        });
    }

    fn on_event(&mut self, e: IrqEvent) {
        if e.running {
            if self.idle.is_none() {
                // The newest ring entry is the vector itself: skip it.
                let mut set: Vec<(u32, u16)> = (1..RING)
                    .map(|k| self.ring[(self.ring_pos + RING - 1 - k) % RING])
                    .collect();
                set.push((e.ret_pc, e.ret_sp));
                set.sort_unstable();
                set.dedup();
                self.learning.push(set);
                if self.learning.len() >= LEARN_TICKS {
                    self.learn();
                }
                return;
            }
            let was_idle = self.is_idle(e.ret_pc, e.ret_sp);
            if let Some((start, Some(_), Wait::Confirm(end))) = self.open {
                self.close(start, end);
            }
            if let Some((start, _, _)) = self.open.take() {
                // The previous tick never got back to idle before this one fired.
                self.ticks.push(TickTiming {
                    start,
                    busy: e.cycle - start,
                    interrupted_busy: true,
                    control: self.open_control.take(),
                });
            }
            let wait = if was_idle { Wait::Leave } else { Wait::Busy };
            self.open = Some((e.cycle, None, wait));
            self.open_control = None;
        } else if let Some((start, None, wait)) = self.open {
            if wait == Wait::Busy {
                // The ISR interrupted a busy main loop (the search, or an overrun): the tick
                // itself is only the ISR.
                self.open = None;
                self.ticks.push(TickTiming {
                    start,
                    busy: e.cycle - start,
                    interrupted_busy: true,
                    control: None,
                });
            } else {
                self.open = Some((start, Some(e.cycle), wait));
            }
        }
    }
}

/// What an open tick waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Wait {
    /// The main loop to leave the idle wait (after the ISR).
    Leave,
    /// The main loop to return to the idle wait.
    Return,
    /// Nothing: the ISR found the main loop busy.
    Busy,
    /// Back in the wait since this cycle; confirming.
    Confirm(u64),
}

/// Cycles the main loop must stay in its idle wait for a tick to count as finished.
const CONFIRM: u64 = 2_000;
