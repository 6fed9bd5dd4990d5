//! The persisted record in flash (the STM32F411's store): an append-only log of slots over two
//! erase sectors, so that a save cut at any program access, or during a sector erase, leaves
//! the previous record loadable. The EEPROM counterpart of the ATmega2560 is [`crate::slots`].
//!
//! Flash is programmed a byte at a time, a programmed bit only goes from 1 to 0, and only a
//! whole sector goes back to `0xFF` (erase: 2 s for 128 KB, the CPU stalled). So a record is
//! never rewritten in place: each save appends a slot, and a sector is erased only when the
//! log needs room. Layout, from the start of each sector ([`SECTORS`]: sectors 6 and 7 of the
//! STM32F411xE, RM0383 §3.3 Table 4, 128 KB each):
//!
//! | Offset in a slot | Size | Field |
//! |---:|---:|---|
//! | 0 | 105 | the record ([`crate::persist`]), or all `0xFF`: forgotten (a tombstone) |
//! | 105 | 4 | sequence number `n`, `u32` little-endian: one more than every slot before it |
//! | 109 | 4 | `!n`, its complement |
//! | 113 | 4 | commit mark: `"RP"`, the record length as `u16` little-endian |
//! | 117 | 11 | `0xFF` (unprogrammed), to [`SLOT_LEN`] = 128 bytes |
//!
//! A slot is **committed** when it holds the mark and a sequence number equal to the
//! complement of the word after it. A save programs its slot in address order: record,
//! sequence number, complement, mark last. So:
//! - a save cut before the last byte of the mark leaves a slot without the mark (bits only go
//!   from 1 to 0: a partly programmed byte differs from its target): it is skipped, and the
//!   newest committed slot before it is loaded;
//! - a committed slot has its record and its sequence number complete;
//! - an erase cut short leaves the sector's bits part way back to 1 (the chip makes no
//!   promise): a slot there keeps its mark and a valid pair only if none of the 56 zero bits
//!   of its mark and its pair moved (a bit that rose in `n` is 1 in `!n` already, so the pair
//!   no longer matches), i.e. with its own, older, sequence number. No slot of a sector cut
//!   in its erase can outrank the newest one.
//!
//! The next save goes to the first erased slot of the sector holding the newest committed
//! slot; when that sector is full, it goes to the first slot of the **other** sector (which
//! holds only older records), erased first unless it reads all `0xFF`. An erase cut by a reset
//! leaves the newest record, in the sector not being erased, loadable.
//!
//! An erase stalls the CPU for 2 s (up to 4 s): the sensor is not read and the PWM holds its
//! duty meanwhile, so it must not happen while the pump runs. The board erases at boot,
//! before the pump is driven ([`boot_erase`]): the other sector, once the sector in use has
//! fewer than [`RUN_SAVES`] erased slots left. A run can then make [`RUN_SAVES`] saves (all
//! of them, if it started with fewer left) before one would need an erase; the board refuses
//! that save instead (`PERSIST failed`), and the next boot makes the room. A sector is then
//! erased once every [`SLOTS`] saves, as without the boot erase, and the boot that does it is
//! 2 s longer.
//!
//! Loading ([`plan`]): the committed slot with the highest sequence number; a tombstone there
//! means no record; a newest slot whose record is not whole ([`persist::intact`]: only bit rot
//! can do that, since the mark is programmed last) falls back to the committed slot before
//! it if that one is whole, else it is handed on to be rejected with its reason, as
//! [`crate::slots`] does with its two slots. Sequence numbers do not wrap: 2³² saves.

use crate::persist::{self, RECORD_LEN};

/// Flash memory's start address on the STM32F411 (RM0383 §3.3).
pub const FLASH_BASE: u32 = 0x0800_0000;

/// The store's two sectors: (sector number, offset from [`FLASH_BASE`]) of sectors 6 and 7.
pub const SECTORS: [(u8, u32); 2] = [(6, 0x4_0000), (7, 0x6_0000)];

/// Bytes of one sector of the store.
pub const SECTOR_LEN: usize = 0x2_0000;

/// Where the sequence number sits in a slot.
const SEQ_AT: usize = RECORD_LEN;

/// Where the sequence number's complement sits in a slot.
const INV_AT: usize = SEQ_AT + 4;

/// Where the commit mark sits in a slot.
const MARK_AT: usize = INV_AT + 4;

/// Bytes a save programs: record, sequence number, its complement, commit mark.
pub const PROGRAMMED_LEN: usize = MARK_AT + 4;

/// Bytes of one slot: [`PROGRAMMED_LEN`] rounded up to a 16-byte flash row.
pub const SLOT_LEN: usize = PROGRAMMED_LEN.div_ceil(16) * 16;

/// Slots in one sector.
pub const SLOTS: usize = SECTOR_LEN / SLOT_LEN;

/// Saves a run can make without an erase: at boot the other sector is erased when the sector in
/// use has fewer erased slots left ([`boot_erase`]).
pub const RUN_SAVES: usize = SLOTS / 2;

/// The commit mark: `"RP"` and the record length.
pub const MARK: [u8; 4] = {
    let len = (RECORD_LEN as u16).to_le_bytes();
    [b'R', b'P', len[0], len[1]]
};

/// Where a slot lies: the sector (0 or 1, an index into [`SECTORS`]) and the slot in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct At {
    /// Index into [`SECTORS`].
    pub sector: u8,
    /// Slot index in the sector, `0..SLOTS`.
    pub slot: u16,
}

impl At {
    /// Offset of the slot from [`FLASH_BASE`].
    pub fn offset(self) -> u32 {
        let base = SECTORS.get(usize::from(self.sector)).map_or(0, |s| s.1);
        base + u32::from(self.slot) * SLOT_LEN as u32
    }
}

/// What the two sectors hold: the slot to load, and where the next save goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Plan {
    /// The slot whose record goes to the state machine (`None`: no record, or forgotten).
    pub load: Option<At>,
    /// The slot the next save programs.
    pub target: At,
    /// Whether the target's sector must be erased first (it is not blank): 2 s with the CPU
    /// stalled, done only at boot ([`boot_erase`]).
    pub erase: bool,
    /// The sequence number the next save gets.
    pub seq: u32,
}

/// Sector `index` of `sectors` (empty past the end).
fn sector(sectors: [&[u8]; 2], index: u8) -> &[u8] {
    sectors.get(usize::from(index)).copied().unwrap_or(&[])
}

/// The slot `index` of `sector` (empty past the end).
fn slot(sector: &[u8], index: usize) -> &[u8] {
    sector
        .get(index * SLOT_LEN..(index + 1) * SLOT_LEN)
        .unwrap_or(&[])
}

/// The little-endian `u32` at `at` in `slot`.
fn word(slot: &[u8], at: usize) -> Option<u32> {
    let b = slot.get(at..at + 4)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// The sequence number of a committed slot (the mark, and the number matching its
/// complement), `None` for any other.
fn committed(slot: &[u8]) -> Option<u32> {
    if slot.get(MARK_AT..MARK_AT + 4) != Some(&MARK[..]) {
        return None;
    }
    let seq = word(slot, SEQ_AT)?;
    (word(slot, INV_AT)? == !seq).then_some(seq)
}

/// The first erased slot of a sector ([`SLOTS`]: none). Saves fill a sector in order, so
/// this is one past the last save; after an erase cut short, any erased slot will do: a slot
/// is placed by its sequence number, not by its position.
fn first_free(sector: &[u8]) -> usize {
    (0..SLOTS)
        .find(|&i| {
            let s = slot(sector, i);
            s.len() == SLOT_LEN && s.iter().all(|&b| b == 0xFF)
        })
        .unwrap_or(SLOTS)
}

/// Whether every slot of a sector reads erased (`0xFF`).
fn blank(sector: &[u8]) -> bool {
    sector.len() == SECTOR_LEN && sector.iter().all(|&b| b == 0xFF)
}

/// The committed slot with the highest sequence number below `below` (all: `None`).
fn newest(sectors: [&[u8]; 2], below: Option<u32>) -> Option<(At, u32)> {
    let mut best: Option<(At, u32)> = None;
    for s in 0..2u8 {
        let sec = sector(sectors, s);
        for i in 0..SLOTS {
            let Some(seq) = committed(slot(sec, i)) else {
                continue;
            };
            if below.is_some_and(|b| seq >= b) || best.is_some_and(|(_, q)| q >= seq) {
                continue;
            }
            let at = At {
                sector: s,
                slot: i as u16,
            };
            best = Some((at, seq));
        }
    }
    best
}

/// The record bytes of the slot at `at`.
fn record_at(sectors: [&[u8]; 2], at: At) -> &[u8] {
    let s = slot(sector(sectors, at.sector), usize::from(at.slot));
    s.get(..RECORD_LEN).unwrap_or(&[])
}

/// Reads the two sectors (each [`SECTOR_LEN`] bytes, in [`SECTORS`] order).
pub fn plan(sectors: [&[u8]; 2]) -> Plan {
    let top = newest(sectors, None);
    let load = top.and_then(|(at, seq)| {
        let rec = record_at(sectors, at);
        if crate::slots::is_tombstone(rec) {
            return None;
        }
        if persist::intact(rec).is_ok() {
            return Some(at);
        }
        // Not whole: the slot before it, if that is whole, else this one (rejected with its
        // reason by the state machine).
        match newest(sectors, Some(seq)) {
            Some((before, _)) if persist::intact(record_at(sectors, before)).is_ok() => {
                Some(before)
            }
            _ => Some(at),
        }
    });
    let active = active(sectors, top);
    let free = first_free(sector(sectors, active));
    let (target, erase) = if free < SLOTS {
        let at = At {
            sector: active,
            slot: free as u16,
        };
        (at, false)
    } else {
        // Full: the other sector, erased first unless blank (it holds only older records).
        let at = At {
            sector: 1 - active,
            slot: 0,
        };
        (at, !blank(sector(sectors, 1 - active)))
    };
    Plan {
        load,
        target,
        erase,
        seq: top.map_or(0, |(_, seq)| seq.saturating_add(1)),
    }
}

/// The sector the log goes on in: the newest slot's; with none, the first with room.
fn active(sectors: [&[u8]; 2], top: Option<(At, u32)>) -> u8 {
    match top {
        Some((at, _)) => at.sector,
        None => u8::from(first_free(sector(sectors, 0)) >= SLOTS),
    }
}

/// The sector (index into [`SECTORS`]) to erase at boot, before the pump is driven: the one
/// not in use, when the one in use has fewer than [`RUN_SAVES`] erased slots left and the
/// other is not blank. `None`: no erase.
pub fn boot_erase(sectors: [&[u8]; 2]) -> Option<u8> {
    let active = active(sectors, newest(sectors, None));
    let other = 1 - active;
    (first_free(sector(sectors, active)) > SLOTS - RUN_SAVES && !blank(sector(sectors, other)))
        .then_some(other)
}

/// The record of the slot `plan` loads, if any.
pub fn record<'a>(sectors: [&'a [u8]; 2], plan: &Plan) -> Option<&'a [u8]> {
    plan.load.map(|at| record_at(sectors, at))
}

/// The [`PROGRAMMED_LEN`] bytes a save of `record` (a [`RECORD_LEN`]-byte record, or all
/// `0xFF` to forget) with sequence number `seq` programs, in this order. `None` for a record
/// of another length.
pub fn slot_bytes(record: &[u8], seq: u32) -> Option<[u8; PROGRAMMED_LEN]> {
    if record.len() != RECORD_LEN {
        return None;
    }
    let mut out = [0xFF; PROGRAMMED_LEN];
    out.get_mut(..RECORD_LEN)?.copy_from_slice(record);
    out.get_mut(SEQ_AT..INV_AT)?
        .copy_from_slice(&seq.to_le_bytes());
    out.get_mut(INV_AT..MARK_AT)?
        .copy_from_slice(&(!seq).to_le_bytes());
    out.get_mut(MARK_AT..)?.copy_from_slice(&MARK);
    Some(out)
}
