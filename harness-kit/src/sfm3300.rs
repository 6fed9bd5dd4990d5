//! The Sensirion SFM3300 flow sensor's I2C side, for both harnesses' buses: 7-bit address
//! 0x40, 16-bit commands MSB first (0x1000 start continuous measurement, 0x2000 soft reset,
//! 0x31AE / 0x31AF serial number), 3-byte frames `[MSB, LSB, CRC]` with CRC-8 polynomial 0x31
//! and initial value 0x00, a new value every 0.5 ms, the read address NACKed while no new value
//! is ready, and the first frame after a start command invalid. The frames, the CRC and the
//! noise model are pump-sim's (`pump_sim::sfm3300`).
//!
//! Sources: Sensirion, *I2C Functional Description SFM3xxx* (address, commands, frame layout,
//! NACK before a new value, first frame after the start invalid); Sensirion's *SF05 sample
//! code* (CRC-8 polynomial 0x31 with initial value 0x00, which the SFM3300 uses; newer
//! Sensirion parts start from 0xFF); Sensirion, *Datasheet SFM3300-AW / SFM3300-D* (update time
//! 0.5 ms).
//!
//! [`SensorState`] is the part: each harness feeds it the bus conditions its emulator makes
//! (simavr's TWI packets, the STM32 I2C1 model's calls) with the time in its own unit, and the
//! bench sets the true flow at every plant step. Faults ([`Fault`]): an absent sensor, bursts
//! of NACKs, bad CRCs, a frozen or out-of-range reading. A slave holding SDA low is the bus's.

use pump_sim::sfm3300::{crc8, frame, CMD_SOFT_RESET, CMD_START_MEASUREMENT, I2C_ADDRESS};
use pump_sim::Sfm3300;

/// Serial number served by the simulated part.
pub const SERIAL: u32 = 0x1234_ABCD;

/// Injected sensor faults.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fault {
    /// Healthy.
    #[default]
    None,
    /// The part does not answer: every address is NACKed (unplugged, dead, vanished).
    Absent,
    /// The next `n` read addresses are NACKed, then healthy again.
    NackBurst(u32),
    /// Every frame has a wrong CRC.
    CrcCorrupt,
    /// The part repeats one raw word forever (a frozen reading), with a valid CRC.
    Stuck(u16),
    /// Serves this raw word instead of the measurement (e.g. out of range), valid CRC.
    Raw(u16),
}

/// What the part did, for the harness's records (times in the harness's unit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A measurement frame was handed to the master (its raw word, whether the CRC was valid,
    /// the true flow it measured).
    Frame {
        /// Time of the address phase.
        at: u64,
        /// Raw word.
        raw: u16,
        /// Whether the CRC byte was valid.
        crc_ok: bool,
        /// Whether this was the (invalid) first frame after a start command.
        first: bool,
        /// True flow at the sensor then, slm.
        flow: f64,
    },
    /// A read address NACKed (no new value, or a fault).
    Nack {
        /// Time.
        at: u64,
    },
    /// A complete 16-bit command.
    Command {
        /// Time.
        at: u64,
        /// The command.
        cmd: u16,
    },
}

/// The part's state, shared between the bus and the bench.
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
    /// Measurement update period (0.5 ms) in the harness's time unit.
    update: u64,
    measuring_since: Option<u64>,
    last_slot_read: Option<u64>,
    first_pending: bool,
    cmd: Vec<u8>,
    tx: Vec<u8>,
    tx_pos: usize,
    addressed: bool,
    reading: bool,
}

impl SensorState {
    /// A powered-up sensor (idle until a start command) with noise model `model`; `update`:
    /// 0.5 ms in the harness's time unit.
    pub fn new(model: Sfm3300, update: u64) -> Self {
        SensorState {
            flow_slm: 0.0,
            model,
            fault: Fault::None,
            first_frame_raw: 0xFFFF,
            events: Vec::new(),
            errors: Vec::new(),
            update: update.max(1),
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

    /// The frames served, without the invalid first one after each start: (time, raw word).
    pub fn served(&self) -> Vec<(u64, u16)> {
        self.served_with_flow()
            .into_iter()
            .map(|(at, raw, _)| (at, raw))
            .collect()
    }

    /// The frames served (as [`served`](Self::served)) with the true flow each measured:
    /// `(time, raw, flow_slm)`.
    pub fn served_with_flow(&self) -> Vec<(u64, u16, f64)> {
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

    /// A START (or repeated START) condition on the bus: a command cut short is an error.
    pub fn start(&mut self) {
        self.end_transfer();
    }

    /// The address phase: `addr` (7 bits) with the R/W bit `read`, at `now`. Returns the ACK.
    /// A read loads the next frame (or the serial number), or NACKs while no new value is
    /// ready.
    pub fn address(&mut self, addr: u8, read: bool, now: u64) -> bool {
        if addr != I2C_ADDRESS {
            self.addressed = false;
            return false;
        }
        self.cmd.clear();
        self.reading = read;
        let ack = if read {
            self.start_read(now)
        } else {
            self.fault != Fault::Absent
        };
        self.addressed = ack;
        ack
    }

    /// A byte the master writes; returns the ACK (a NACK for an unknown command).
    pub fn write(&mut self, byte: u8, now: u64) -> bool {
        if !self.addressed || self.reading {
            return false;
        }
        self.cmd.push(byte);
        if self.cmd.len() == 2 {
            let cmd = u16::from_be_bytes([self.cmd[0], self.cmd[1]]);
            self.cmd.clear();
            return self.command(cmd, now);
        }
        true
    }

    /// The next byte the master reads (0xFF past the frame).
    pub fn read(&mut self) -> u8 {
        let b = self.tx.get(self.tx_pos).copied().unwrap_or(0xFF);
        self.tx_pos += 1;
        b
    }

    /// A STOP condition: a command cut short is an error.
    pub fn stop(&mut self) {
        self.end_transfer();
    }

    /// Whether the part answered the last address (and is in the transfer).
    pub fn addressed(&self) -> bool {
        self.addressed
    }

    fn end_transfer(&mut self) {
        if self.addressed && !self.reading && !self.cmd.is_empty() {
            let n = self.cmd.len();
            self.errors
                .push(format!("incomplete command ({n} byte(s))"));
        }
        self.cmd.clear();
        self.addressed = false;
    }

    fn slot(&self, now: u64) -> Option<u64> {
        let since = self.measuring_since?;
        // The first value is ready one update period after the start command.
        let dt = now.checked_sub(since)?;
        (dt >= self.update).then_some(dt / self.update)
    }

    fn command(&mut self, cmd: u16, now: u64) -> bool {
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

    fn nack(&mut self, now: u64) -> bool {
        self.events.push(Event::Nack { at: now });
        false
    }

    /// Address phase of a read: ACK (and load the frame) or NACK.
    fn start_read(&mut self, now: u64) -> bool {
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
            // Serial-number reply (or nothing, if no command was sent).
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
