//! The two-slot store against a simulated EEPROM: every write cut at every byte, with the
//! byte being written when power went left unchanged, zeroed, erased or garbled. The truth is
//! the simulation's own bookkeeping of which records were written completely.

use ridge_core::{ArxModel, InputMap, Offset, MAP_KNOTS};
use ridge_pump_firmware::persist::{self, RECORD_LEN};
use ridge_pump_firmware::slots::{self, Plan, SLOT_LEN, STORE_LEN};

/// A valid record, distinct for each `k`.
fn record(k: u32) -> [u8; RECORD_LEN] {
    let theta = 0.5 + (k % 97) as f32 * 1e-3;
    let m = ArxModel::new(&[theta], &[2.0 + k as f32], 1, Offset::Intercept, 0.25).unwrap();
    let mut knots = [0i16; MAP_KNOTS];
    for (i, v) in knots.iter_mut().enumerate() {
        *v = (100 * i + (k % 50) as usize) as i16;
    }
    persist::encode(&m, &InputMap::new(1_500, 533, knots).unwrap(), 80.0)
}

/// Writes `bytes` at `at` as the board does, stopping after `cut` bytes (`None`: all). The
/// byte being written when the power went gets `torn` (`None`: it keeps its old value).
fn write(store: &mut [u8; STORE_LEN], at: u16, bytes: &[u8], cut: Option<usize>, torn: Option<u8>) {
    let n = cut.unwrap_or(bytes.len()).min(bytes.len());
    let at = usize::from(at);
    store[at..at + n].copy_from_slice(&bytes[..n]);
    if let (Some(k), Some(g)) = (cut, torn) {
        if k < bytes.len() {
            store[at + k] = g;
        }
    }
}

/// The record the store hands to the state machine, if it decodes (a damaged one is
/// rejected there; see the bit-rot test).
fn loaded(store: &[u8; STORE_LEN]) -> Option<[u8; RECORD_LEN]> {
    let plan = slots::plan(store);
    let r = slots::record(store, &plan)?;
    persist::decode(r).ok()?;
    Some(r.try_into().unwrap())
}

/// Saves `rec` (or forgets, with all 0xFF) through the plan read from the store.
fn save(store: &mut [u8; STORE_LEN], rec: &[u8], cut: Option<usize>, torn: Option<u8>) -> Plan {
    let plan = slots::plan(store);
    let (at, bytes) = slots::slot_bytes(rec, &plan).unwrap();
    write(store, at, &bytes, cut, torn);
    plan
}

const TORN: [Option<u8>; 4] = [None, Some(0x00), Some(0xFF), Some(0x5A)];

#[test]
fn an_erased_store_loads_nothing_and_a_first_record_loads() {
    let mut store = [0xFF; STORE_LEN];
    assert_eq!(loaded(&store), None);
    save(&mut store, &record(1), None, None);
    assert_eq!(loaded(&store), Some(record(1)));
}

#[test]
fn a_first_write_cut_anywhere_loads_nothing_or_the_record() {
    for k in 0..=SLOT_LEN {
        for torn in TORN {
            let mut store = [0xFF; STORE_LEN];
            save(&mut store, &record(1), Some(k), torn);
            let got = loaded(&store);
            if k < RECORD_LEN {
                assert_eq!(got, None, "cut at {k}, torn {torn:?}");
            } else if k == SLOT_LEN {
                assert_eq!(got, Some(record(1)));
            } else {
                // Record complete, sequence number torn: nothing or the record, never junk.
                assert!(got.is_none() || got == Some(record(1)), "cut at {k}");
            }
        }
    }
}

#[test]
fn every_write_cut_at_every_byte_keeps_the_previous_record() {
    // 600 generations: the sequence numbers wrap (0..=254) twice.
    let mut store = [0xFF; STORE_LEN];
    save(&mut store, &record(0), None, None);
    for gen in 1..600u32 {
        let (old, new) = (record(gen - 1), record(gen));
        assert_eq!(loaded(&store), Some(old), "generation {gen}");
        for k in 0..SLOT_LEN {
            for torn in TORN {
                let mut cut = store;
                save(&mut cut, &new, Some(k), torn);
                let got = loaded(&cut);
                if k < RECORD_LEN {
                    assert_eq!(
                        got,
                        Some(old),
                        "generation {gen}, cut at {k}, torn {torn:?}"
                    );
                } else {
                    assert!(
                        got == Some(old) || got == Some(new),
                        "gen {gen}, cut at {k}"
                    );
                }
                // A later complete write after the cut lands, whatever the cut left.
                let mut again = cut;
                save(&mut again, &new, None, None);
                assert_eq!(loaded(&again), Some(new), "rewrite after cut at {k}");
            }
        }
        save(&mut store, &new, None, None);
    }
}

#[test]
fn forget_cut_anywhere_loads_the_old_record_or_nothing_and_stays_forgotten() {
    let mut store = [0xFF; STORE_LEN];
    save(&mut store, &record(1), None, None);
    save(&mut store, &record(2), None, None);
    let erase = [0xFF; RECORD_LEN];
    for k in 0..=SLOT_LEN {
        for torn in TORN {
            let mut cut = store;
            save(&mut cut, &erase, Some(k), torn);
            let got = loaded(&cut);
            if k == SLOT_LEN {
                assert_eq!(got, None);
            } else {
                assert!(got.is_none() || got == Some(record(2)), "cut at {k}");
            }
        }
    }
    save(&mut store, &erase, None, None);
    assert_eq!(loaded(&store), None);
    // A new record written after FORGET, cut anywhere: nothing, or the new record; the
    // forgotten one never comes back.
    for k in 0..=SLOT_LEN {
        for torn in TORN {
            let mut cut = store;
            save(&mut cut, &record(3), Some(k), torn);
            let got = loaded(&cut);
            assert!(
                got.is_none() || got == Some(record(3)),
                "cut at {k}, {torn:?}"
            );
            assert_ne!(got, Some(record(2)));
            assert_ne!(got, Some(record(1)));
        }
    }
}

#[test]
fn a_rotted_newest_record_falls_back_to_the_other_slot_and_is_overwritten_first() {
    let mut store = [0xFF; STORE_LEN];
    save(&mut store, &record(1), None, None);
    let plan = save(&mut store, &record(2), None, None);
    // Flip one bit in the newest record (not a tombstone): the older one loads.
    let at = usize::from(plan.target) * SLOT_LEN + 20;
    store[at] ^= 0x04;
    assert_eq!(loaded(&store), Some(record(1)));
    // The next write goes to the rotted slot, not over the record in use.
    let next = slots::plan(&store);
    assert_eq!(next.target, plan.target);
    for k in 0..RECORD_LEN {
        let mut cut = store;
        save(&mut cut, &record(3), Some(k), Some(0x00));
        assert_eq!(loaded(&cut), Some(record(1)), "cut at {k}");
    }
}

#[test]
fn a_rotted_record_with_nothing_to_fall_back_to_is_handed_on_and_fails_its_crc() {
    let mut store = [0xFF; STORE_LEN];
    let wrote = save(&mut store, &record(1), None, None);
    store[usize::from(wrote.target) * SLOT_LEN + 33] ^= 0x80;
    let plan = slots::plan(&store);
    let handed = slots::record(&store, &plan).expect("the damaged record is handed on");
    assert_eq!(persist::decode(handed), Err(persist::PersistError::Crc));
    // The next write goes to the other slot, and once whole it is the one loaded.
    save(&mut store, &record(2), None, None);
    assert_eq!(loaded(&store), Some(record(2)));
}

#[test]
fn after_write_agrees_with_reading_the_store_again() {
    let mut store = [0xFF; STORE_LEN];
    let mut plan = slots::plan(&store);
    for gen in 0..520u32 {
        let forget = gen % 7 == 3;
        let rec = if forget {
            [0xFF; RECORD_LEN]
        } else {
            record(gen)
        };
        let (at, bytes) = slots::slot_bytes(&rec, &plan).unwrap();
        write(&mut store, at, &bytes, None, None);
        plan = slots::after_write(&plan, forget);
        let fresh = slots::plan(&store);
        assert_eq!(plan.load, fresh.load, "generation {gen}");
        assert_eq!(plan.seq, fresh.seq, "generation {gen}");
        if plan.load.is_some() {
            assert_eq!(plan.target, fresh.target, "generation {gen}");
        }
    }
}

#[test]
fn records_of_another_length_are_refused() {
    let plan = slots::plan(&[0xFF; STORE_LEN]);
    assert!(slots::slot_bytes(&[0u8; RECORD_LEN - 1], &plan).is_none());
    assert!(slots::slot_bytes(&[0u8; RECORD_LEN + 1], &plan).is_none());
}
