//! The Sensirion SFM3300 flow sensor as a slave on the emulated I2C1 bus
//! ([`crate::periph::i2c::Device`]): 7-bit address 0x40, 16-bit commands MSB first (0x1000
//! start continuous measurement, 0x2000 soft reset, 0x31AE / 0x31AF serial number), 3-byte
//! frames `[MSB, LSB, CRC]` with CRC-8 polynomial 0x31 and initial value 0x00, a new value
//! every 0.5 ms, the read address NACKed while no new value is ready, and the first frame
//! after a start command invalid. The frames, the CRC and the noise model are pump-sim's
//! (`pump_sim::sfm3300`), as `simavr-harness`'s sensor uses them.
//!
//! Sources: Sensirion, *I2C Functional Description SFM3xxx* (address, commands, frame layout,
//! NACK before a new value, first frame after the start invalid); Sensirion, *SF05 sample
//! code* (CRC-8 0x31, init 0x00); *Datasheet SFM3300* (update time 0.5 ms).
//!
//! Faults ([`Fault`]): an absent sensor, bursts of NACKs, bad CRCs, a frozen or out-of-range
//! reading. A slave holding SDA low is the bus's ([`crate::bus`]).

use std::cell::RefCell;
use std::rc::Rc;

use pump_sim::sfm3300::{crc8, frame, CMD_SOFT_RESET, CMD_START_MEASUREMENT, I2C_ADDRESS};
use pump_sim::Sfm3300;

use crate::periph::i2c::Device;
use crate::periph::Time;

/// Serial number served by the simulated part.
pub const SERIAL: u32 = 0x1234_ABCD;
/// Measurement update period, ps (0.5 ms).
pub const UPDATE_PS: Time = 500_000_000;

/// Injected sensor faults.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fault {
    /// Healthy.
    #[default]
    None,
    /// The part does not answer: every address NACKed (unplugged, dead, vanished).
    Absent,
    /// The next `n` read addresses are NACKed, then healthy again.
    NackBurst(u32),
    /// Every frame has a wrong CRC.
    CrcCorrupt,
    /// The part repeats one raw word forever (a frozen reading), valid CRC.
    Stuck(u16),
    /// Serves this raw word instead of the measurement, valid CRC.
    Raw(u16),
}

/// What the slave did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A measurement frame was handed to the master.
    Frame {
        /// Time of the address phase.
        at: Time,
        /// Raw word.
        raw: u16,
        /// Frame CRC valid.
        crc_ok: bool,
        /// The invalid first frame after a start command.
        first: bool,
        /// True flow at the sensor when the frame was measured, slm.
        flow: f64,
    },
    /// A read address NACKed (no new value, or fault).
    Nack {
        /// Time.
        at: Time,
    },
    /// A complete command was received.
    Command {
        /// Time.
        at: Time,
        /// Command word.
        cmd: u16,
    },
}

/// The sensor's state, shared between the bus and the bench.
#[derive(Debug)]
pub struct SensorState {
    /// True flow at the sensor now, slm (set by the bench at every plant step).
    pub flow_slm: f64,
    /// Noise, offset and quantisation model (seeded).
    pub model: Sfm3300,
    /// Injected fault.
    pub fault: Fault,
    /// Raw word of the invalid first frame after a start command.
    pub first_frame_raw: u16,
    /// Bus-level events.
    pub events: Vec<Event>,
    /// Protocol violations seen (unknown command, incomplete command, …).
    pub errors: Vec<String>,
    measuring_since: Option<Time>,
    last_slot_read: Option<u64>,
    first_pending: bool,
    cmd: Vec<u8>,
    tx: Vec<u8>,
    tx_pos: usize,
    addressed: bool,
    reading: bool,
}

impl SensorState {
    /// A powered-up sensor, idle until a start command.
    pub fn new(model: Sfm3300) -> Self {
        SensorState {
            flow_slm: 0.0,
            model,
            fault: Fault::None,
            first_frame_raw: 0xFFFF,
            events: Vec::new(),
            errors: Vec::new(),
            measuring_since: None,
            last_slot_read: None,
            first_pending: false,
            cmd: Vec::new(),
            tx: Vec::new(),
            tx_pos: 0,
            addressed: false,
            reading: false,
        }
    }

    /// Whether continuous measurement runs.
    pub fn measuring(&self) -> bool {
        self.measuring_since.is_some()
    }

    /// The frames served (without the invalid first one after each start): (time, raw, true
    /// flow in slm).
    pub fn served(&self) -> Vec<(Time, u16, f64)> {
        self.events
            .iter()
            .filter_map(|e| match *e {
                Event::Frame {
                    at,
                    raw,
                    first: false,
                    flow,
                    ..
                } => Some((at, raw, flow)),
                _ => None,
            })
            .collect()
    }

    /// Read addresses NACKed so far.
    pub fn nacks(&self) -> usize {
        self.events
            .iter()
            .filter(|e| matches!(e, Event::Nack { .. }))
            .count()
    }

    fn slot(&self, now: Time) -> Option<u64> {
        let since = self.measuring_since?;
        let dt = now.checked_sub(since)?;
        (dt >= UPDATE_PS).then_some(dt / UPDATE_PS)
    }

    fn command(&mut self, cmd: u16, now: Time) -> bool {
        self.events.push(Event::Command { at: now, cmd });
        match cmd {
            CMD_START_MEASUREMENT => {
                self.measuring_since = Some(now);
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
            }
            0x31AF => {
                let [_, _, c, d] = SERIAL.to_be_bytes();
                self.measuring_since = None;
                self.tx = vec![c, d, crc8(&[c, d])];
            }
            other => {
                self.errors.push(format!("unknown command {other:#06x}"));
                return false;
            }
        }
        true
    }

    fn nack(&mut self, now: Time) -> bool {
        self.events.push(Event::Nack { at: now });
        false
    }

    /// Address phase of a read: ACK (and load the frame) or NACK.
    fn start_read(&mut self, now: Time) -> bool {
        match self.fault {
            Fault::Absent => return self.nack(now),
            Fault::NackBurst(n) => {
                self.fault = if n > 1 {
                    Fault::NackBurst(n - 1)
                } else {
                    Fault::None
                };
                return self.nack(now);
            }
            _ => {}
        }
        if self.measuring_since.is_none() {
            if self.tx.is_empty() {
                return self.nack(now);
            }
            self.tx_pos = 0;
            return true;
        }
        let Some(slot) = self.slot(now) else {
            return self.nack(now);
        };
        if self.last_slot_read == Some(slot) {
            return self.nack(now);
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
            at: now,
            raw,
            crc_ok,
            first,
            flow: self.flow_slm,
        });
        self.tx = f.to_vec();
        self.tx_pos = 0;
        true
    }
}

/// The bus's handle on the shared [`SensorState`].
#[derive(Debug, Clone)]
pub struct Sfm3300Slave {
    /// Shared state.
    pub state: Rc<RefCell<SensorState>>,
}

impl Device for Sfm3300Slave {
    fn start(&mut self, _now: Time) {
        let mut s = self.state.borrow_mut();
        if s.addressed && !s.reading && !s.cmd.is_empty() {
            let n = s.cmd.len();
            s.errors.push(format!("incomplete command ({n} byte(s))"));
        }
        s.cmd.clear();
        s.addressed = false;
    }

    fn address(&mut self, addr: u8, read: bool, now: Time) -> bool {
        let mut s = self.state.borrow_mut();
        if addr != I2C_ADDRESS {
            s.addressed = false;
            return false;
        }
        s.reading = read;
        let ack = if read {
            s.start_read(now)
        } else {
            !matches!(s.fault, Fault::Absent)
        };
        s.addressed = ack;
        ack
    }

    fn write(&mut self, byte: u8, now: Time) -> bool {
        let mut s = self.state.borrow_mut();
        if !s.addressed || s.reading {
            return false;
        }
        s.cmd.push(byte);
        if s.cmd.len() == 2 {
            let cmd = u16::from_be_bytes([s.cmd[0], s.cmd[1]]);
            s.cmd.clear();
            return s.command(cmd, now);
        }
        true
    }

    fn read(&mut self, _now: Time) -> u8 {
        let mut s = self.state.borrow_mut();
        let b = s.tx.get(s.tx_pos).copied().unwrap_or(0xFF);
        s.tx_pos += 1;
        b
    }

    fn read_ack(&mut self, _ack: bool, _now: Time) {}

    fn stop(&mut self, _now: Time) {
        let mut s = self.state.borrow_mut();
        if s.addressed && !s.reading && !s.cmd.is_empty() {
            let n = s.cmd.len();
            s.errors.push(format!("incomplete command ({n} byte(s))"));
        }
        s.cmd.clear();
        s.addressed = false;
    }

    fn holds_sda(&self, _now: Time) -> bool {
        false
    }
}
