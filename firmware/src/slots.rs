//! Two slots for the persisted record, so that a write cut at any byte (reset, power loss)
//! never loses the previous valid model: the EEPROM of the ATmega2560 is written a byte per
//! tick (~3.4 ms each), and a record takes 106 ticks to write.
//!
//! Layout, [`STORE_LEN`] = 212 bytes from the board's base address:
//!
//! | Offset | Size | Field |
//! |---:|---:|---|
//! | 0 | 105 | slot 0: the record ([`crate::persist`]) |
//! | 105 | 1 | slot 0: sequence number, 0..=254; 255 (erased) = never written |
//! | 106 | 105 | slot 1: the record |
//! | 211 | 1 | slot 1: sequence number |
//!
//! A slot is written in address order, record first and sequence number last, into the slot
//! that does not hold the record in use, with the sequence number after the newest one
//! (0..=254, wrapping). So:
//! - a write cut inside the record leaves that slot with a record that fails its CRC and its
//!   old, older sequence number: the other slot's record still loads;
//! - a write cut at the sequence number leaves a complete record with a new or a garbled
//!   number: whichever of the two records is taken, it is whole and valid.
//!
//! `FORGET` writes a *tombstone* the same way: an all-`0xFF` record with a new sequence
//! number. A newest slot holding a tombstone means "no record"; any other newest slot whose
//! record is not whole (only bit rot can do that, since the number is written last) falls back
//! to the other slot, or, with no whole record left, is handed on to be rejected with its
//! reason.

use crate::persist::{self, RECORD_LEN};

/// EEPROM byte address of the store on the ATmega2560 (the board's `eeprom::BASE` is this
/// constant; `ridge-id identify --eeprom` places its image here).
pub const EEPROM_BASE: u16 = 0;

/// Bytes of one slot: the record and its sequence number.
pub const SLOT_LEN: usize = RECORD_LEN + 1;

/// Bytes of both slots.
pub const STORE_LEN: usize = 2 * SLOT_LEN;

/// The sequence number of a slot never written (erased EEPROM).
pub const UNWRITTEN: u8 = 0xFF;

/// What the two slots hold: the slot to load, and where the next write goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Plan {
    /// The slot whose record goes to the state machine (`None`: no record, or forgotten): the
    /// newest written one if it is whole, else the other one if that is whole, else the newest
    /// (damaged by bit rot: the state machine rejects it with its reason).
    pub load: Option<u8>,
    /// The slot the next write goes to: never the one in `load`.
    pub target: u8,
    /// The sequence number the next write gets: after every written slot's.
    pub seq: u8,
}

/// `a` was written after `b`: sequence numbers count 0..=254 and wrap, and two slots are
/// never more than 127 apart, so the difference modulo 256 decides (across the wrap it is 2,
/// not 1: 255 is skipped).
fn newer(a: u8, b: u8) -> bool {
    (a.wrapping_sub(b) as i8) > 0
}

/// The next sequence number after `seq` (0..=254, wrapping).
fn after(seq: u8) -> u8 {
    if seq >= UNWRITTEN - 1 {
        0
    } else {
        seq + 1
    }
}

/// Reads the two slots of `store` (the [`STORE_LEN`] bytes at the board's base address).
pub fn plan(store: &[u8; STORE_LEN]) -> Plan {
    let (s0, s1) = store.split_at(SLOT_LEN);
    let seq = |s: &[u8]| s.get(RECORD_LEN).copied().unwrap_or(UNWRITTEN);
    let (q0, q1) = (seq(s0), seq(s1));
    // (index, slot, sequence number) of the newest written slot first; slot 0 first when
    // neither is written.
    let slot1_newest = q1 != UNWRITTEN && (q0 == UNWRITTEN || newer(q1, q0));
    let ((first, s_first, newest), (second, s_second, q_second)) = if slot1_newest {
        ((1, s1, q1), (0, s0, q0))
    } else {
        ((0, s0, q0), (1, s1, q1))
    };
    let load = if newest == UNWRITTEN || is_tombstone(s_first) {
        None
    } else if !valid(s_first) && q_second != UNWRITTEN && valid(s_second) {
        Some(second)
    } else {
        // Whole, or damaged with nothing to fall back to: the state machine's decoder then
        // rejects it and says why (`STORED-REJECTED crc`).
        Some(first)
    };
    Plan {
        load,
        target: match load {
            Some(i) => 1 - i,
            None => second,
        },
        seq: if newest == UNWRITTEN {
            0
        } else {
            after(newest)
        },
    }
}

/// The record of the slot `plan` loads, if any.
pub fn record<'a>(store: &'a [u8; STORE_LEN], plan: &Plan) -> Option<&'a [u8]> {
    let at = usize::from(plan.load?) * SLOT_LEN;
    store.get(at..at + RECORD_LEN)
}

/// The slot's record is whole ([`persist::intact`]: magic, version, CRC). Whether its model
/// is usable is the state machine's check at load.
fn valid(slot: &[u8]) -> bool {
    persist::intact(slot).is_ok()
}

/// A forgotten record (what `FORGET` saves): all `0xFF`. Takes a record or a whole slot.
pub fn is_tombstone(slot: &[u8]) -> bool {
    slot.get(..RECORD_LEN)
        .is_some_and(|r| r.iter().all(|&b| b == 0xFF))
}

/// The store holding `record` alone, as a first save into an erased store leaves it: the
/// record in the slot [`plan`] picks for that save, with sequence number 0, the other slot
/// erased (so that no older record of the EEPROM survives a write of this image). `None` for
/// a record of another length.
pub fn store_with(record: &[u8]) -> Option<[u8; STORE_LEN]> {
    let mut store = [0xFF; STORE_LEN];
    let (at, bytes) = slot_bytes(record, &plan(&store))?;
    store
        .get_mut(usize::from(at)..usize::from(at) + SLOT_LEN)?
        .copy_from_slice(&bytes);
    Some(store)
}

/// Offset from the board's base address of the slot the next write goes to under `plan`.
pub fn target_offset(plan: &Plan) -> u16 {
    u16::from(plan.target) * SLOT_LEN as u16
}

/// The bytes to write for `record` (a [`RECORD_LEN`]-byte record, or all `0xFF` to forget)
/// under `plan`: [`target_offset`] and the slot's [`SLOT_LEN`] bytes (the record, then
/// `plan.seq`), to be written in order. `None` for a record of another length.
pub fn slot_bytes(record: &[u8], plan: &Plan) -> Option<(u16, [u8; SLOT_LEN])> {
    if record.len() != RECORD_LEN {
        return None;
    }
    let mut out = [plan.seq; SLOT_LEN];
    out.get_mut(..RECORD_LEN)?.copy_from_slice(record);
    Some((target_offset(plan), out))
}

/// The plan after a write under `plan` completed: the written slot is in use (or, for a
/// tombstone, no slot).
pub fn after_write(plan: &Plan, forgot: bool) -> Plan {
    Plan {
        load: if forgot { None } else { Some(plan.target) },
        target: 1 - plan.target,
        seq: after(plan.seq),
    }
}
