//! A simulated Sensirion SFM3300 on the simulated TWI bus, as an `avr_tester` [`TwiSlave`]:
//! 7-bit address 0x40, 16-bit commands MSB first, soft reset 0x2000, start continuous
//! measurement 0x1000, serial number 0x31AE (high word, then low word) / 0x31AF (low word),
//! 3-byte frames `[MSB, LSB, CRC]` (CRC-8 poly 0x31 init 0x00), a new value every 0.5 ms of
//! simulated time, read address NACKed while no new value is ready, and the first frame after
//! a start command invalid.
//!
//! Sources: Sensirion, *I2C Functional Description SFM3xxx* (address, commands, frame layout,
//! NACK before a new value, first frame after the start invalid); Sensirion's *SF05 sample
//! code* (CRC-8 polynomial 0x31 with initial value 0x00, which the SFM3300 uses; newer
//! Sensirion parts start from 0xFF); Sensirion, *Datasheet SFM3300-AW / SFM3300-D* (update time
//! 0.5 ms).
//!
//! The slave only sees bus packets; time and the flow it measures come from the bench through
//! [`SensorState`], shared with the harness (`Rc<RefCell<_>>`): the machine stamps each packet
//! with the core cycle, the harness sets `flow_slm` at every 0.5 ms plant step.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use avr_tester::{TwiPacket, TwiSlave};

use pump_sim::sfm3300::{crc8, frame, CMD_SOFT_RESET, CMD_START_MEASUREMENT, I2C_ADDRESS};
use pump_sim::Sfm3300;

/// 7-bit address (the simulator's, not the firmware driver's: the slave checks the driver).
pub const ADDRESS: u8 = I2C_ADDRESS;
/// Serial number served by the simulated part.
pub const SERIAL: u32 = 0x1234_ABCD;
/// Measurement update period in CPU cycles at 16 MHz (0.5 ms).
pub const UPDATE_CYCLES_16MHZ: u64 = 8_000;

/// Injected sensor faults.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fault {
    /// Healthy.
    #[default]
    None,
    /// The part does not answer: every address is NACKed (unplugged, dead).
    Absent,
    /// Every frame has a wrong CRC.
    CrcCorrupt,
    /// The part repeats one raw word forever (a frozen reading), with a valid CRC.
    Stuck(u16),
    /// Serves this raw word instead of the measurement (e.g. out of range), valid CRC.
    Raw(u16),
}

/// What the slave did, for the harness's records.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A measurement frame was handed to the master (its raw word, whether the CRC was valid,
    /// the 0.5 ms slot it belongs to).
    Frame {
        /// Cycle of the address phase.
        cycle: u64,
        /// Raw word.
        raw: u16,
        /// Frame CRC valid.
        crc_ok: bool,
        /// Whether this was the (invalid) first frame after a start command.
        first: bool,
        /// True flow at the sensor when the frame was measured, slm.
        flow: f64,
    },
    /// Read address NACKed (no new value, or fault).
    Nack {
        /// Cycle.
        cycle: u64,
    },
    /// A complete command was received.
    Command {
        /// Cycle.
        cycle: u64,
        /// Command word.
        cmd: u16,
    },
}

/// State shared between the TWI slave and the harness.
#[derive(Debug)]
pub struct SensorState {
    /// Core cycle of the packet being handled (set by [`Machine::attach_twi`]).
    ///
    /// [`Machine::attach_twi`]: crate::machine::Machine::attach_twi
    pub clock: Rc<Cell<u64>>,
    now: u64,
    /// True flow at the sensor now, slm (updated by the harness at every plant step).
    pub flow_slm: f64,
    /// Noise/offset/quantisation model (seeded).
    pub model: Sfm3300,
    /// Injected fault.
    pub fault: Fault,
    /// Cycles per measurement update (8000 at 16 MHz).
    pub update_cycles: u64,
    /// Raw word of the invalid first frame after a start command.
    pub first_frame_raw: u16,
    /// Log of bus-level events (frames served, NACKs, commands).
    pub events: Vec<Event>,
    /// Protocol violations seen (unknown command, read without command, …).
    pub errors: Vec<String>,
    measuring_since: Option<u64>,
    last_slot_read: Option<u64>,
    first_pending: bool,
    cmd: Vec<u8>,
    tx: Vec<u8>,
    tx_pos: usize,
    addressed_read: bool,
    addressed: bool,
}

impl SensorState {
    /// A powered-up sensor (idle until a start command) with noise model `model`.
    pub fn new(model: Sfm3300, frequency: u32, clock: Rc<Cell<u64>>) -> Self {
        Self {
            clock,
            now: 0,
            flow_slm: 0.0,
            model,
            fault: Fault::None,
            update_cycles: u64::from(frequency) / 2_000,
            first_frame_raw: 0xFFFF,
            events: Vec::new(),
            errors: Vec::new(),
            measuring_since: None,
            last_slot_read: None,
            first_pending: false,
            cmd: Vec::new(),
            tx: Vec::new(),
            tx_pos: 0,
            addressed_read: false,
            addressed: false,
        }
    }

    /// Whether continuous measurement is running.
    pub fn measuring(&self) -> bool {
        self.measuring_since.is_some()
    }

    /// Raw words of the valid-looking frames served, in order (excluding the discarded first
    /// frame after each start command).
    pub fn served(&self) -> Vec<(u64, u16)> {
        self.events
            .iter()
            .filter_map(|e| match *e {
                Event::Frame {
                    cycle,
                    raw,
                    first: false,
                    ..
                } => Some((cycle, raw)),
                _ => None,
            })
            .collect()
    }

    /// The frames served (as [`served`](Self::served)) with the true flow each measured:
    /// `(cycle, raw, flow_slm)`.
    pub fn served_with_flow(&self) -> Vec<(u64, u16, f64)> {
        self.events
            .iter()
            .filter_map(|e| match *e {
                Event::Frame {
                    cycle,
                    raw,
                    first: false,
                    flow,
                    ..
                } => Some((cycle, raw, flow)),
                _ => None,
            })
            .collect()
    }

    fn slot(&self) -> Option<u64> {
        let since = self.measuring_since?;
        // The first value is ready one update period after the start command.
        let dt = self.now.checked_sub(since)?;
        (dt >= self.update_cycles).then(|| dt / self.update_cycles)
    }

    fn command(&mut self, cmd: u16) -> bool {
        self.events.push(Event::Command {
            cycle: self.now,
            cmd,
        });
        match cmd {
            CMD_START_MEASUREMENT => {
                self.measuring_since = Some(self.now);
                self.last_slot_read = None;
                self.first_pending = true;
                self.tx.clear();
            }
            CMD_SOFT_RESET => {
                self.measuring_since = None;
                self.last_slot_read = None;
                self.tx.clear();
            }
            0x31AE => {
                let [a, b, c, d] = SERIAL.to_be_bytes();
                self.measuring_since = None;
                self.tx = vec![a, b, crc8(&[a, b]), c, d, crc8(&[c, d])];
                self.tx_pos = 0;
            }
            0x31AF => {
                let [_, _, c, d] = SERIAL.to_be_bytes();
                self.measuring_since = None;
                self.tx = vec![c, d, crc8(&[c, d])];
                self.tx_pos = 0;
            }
            other => {
                self.errors.push(format!("unknown command {other:#06x}"));
                return false;
            }
        }
        true
    }

    /// Address phase of a read: ACK (and load the frame) or NACK.
    fn start_read(&mut self) -> bool {
        if self.fault == Fault::Absent {
            self.events.push(Event::Nack { cycle: self.now });
            return false;
        }
        if self.measuring_since.is_none() {
            // Serial-number reply (or nothing, if no command was sent).
            if self.tx.is_empty() {
                self.events.push(Event::Nack { cycle: self.now });
                return false;
            }
            self.tx_pos = 0;
            return true;
        }
        let Some(slot) = self.slot() else {
            self.events.push(Event::Nack { cycle: self.now });
            return false;
        };
        if self.last_slot_read == Some(slot) {
            self.events.push(Event::Nack { cycle: self.now });
            return false;
        }
        self.last_slot_read = Some(slot);
        // One noise draw per frame served, whatever is served (keeps the stream aligned).
        let measured = self.model.measure_raw(self.flow_slm);
        let first = std::mem::take(&mut self.first_pending);
        let raw = if first {
            self.first_frame_raw
        } else {
            match self.fault {
                Fault::Stuck(r) | Fault::Raw(r) => r,
                _ => measured,
            }
        };
        let mut f = frame(raw);
        let crc_ok = self.fault != Fault::CrcCorrupt;
        if !crc_ok {
            f[2] ^= 0x5A;
        }
        self.events.push(Event::Frame {
            cycle: self.now,
            raw,
            crc_ok,
            first,
            flow: self.flow_slm,
        });
        self.tx = f.to_vec();
        self.tx_pos = 0;
        true
    }

    fn next_byte(&mut self) -> u8 {
        let b = self.tx.get(self.tx_pos).copied().unwrap_or(0xFF);
        self.tx_pos += 1;
        b
    }
}

/// The TWI slave: a handle on the shared [`SensorState`].
#[derive(Debug, Clone)]
pub struct Sfm3300Slave {
    /// Shared state.
    pub state: Rc<RefCell<SensorState>>,
}

impl TwiSlave for Sfm3300Slave {
    fn recv(&mut self, p: TwiPacket) -> Option<TwiPacket> {
        let mut s = self.state.borrow_mut();
        s.now = s.clock.get();
        // simavr's master sends START with the 8-bit address (SLA+R/W) once the address byte
        // is clocked out; STOP carries the address too.
        if p.addr >> 1 != ADDRESS {
            if p.is_start() {
                s.addressed = false;
            }
            return None;
        }
        if p.is_stop() {
            if s.addressed && !s.addressed_read && !s.cmd.is_empty() {
                let n = s.cmd.len();
                s.errors.push(format!("incomplete command ({n} byte(s))"));
            }
            s.cmd.clear();
            s.addressed = false;
            return Some(p.respond_ack());
        }
        if p.is_start() {
            s.cmd.clear();
            s.addressed_read = p.addr & 1 == 1;
            let ack = if s.addressed_read {
                s.start_read()
            } else {
                s.fault != Fault::Absent
            };
            s.addressed = ack;
            return Some(TwiPacket {
                data: u8::from(ack),
                ..p.respond_ack()
            });
        }
        if !s.addressed {
            return None;
        }
        if p.is_write() {
            s.cmd.push(p.data);
            let mut ack = true;
            if s.cmd.len() == 2 {
                let cmd = u16::from_be_bytes([s.cmd[0], s.cmd[1]]);
                ack = s.command(cmd);
                s.cmd.clear();
            }
            return Some(TwiPacket {
                data: u8::from(ack),
                ..p.respond_ack()
            });
        }
        if p.is_read() {
            let b = s.next_byte();
            return Some(p.respond_data(b));
        }
        None
    }
}
