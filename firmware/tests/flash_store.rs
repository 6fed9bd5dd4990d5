//! The flash record store (firmware/src/flash_store.rs) on a model of two flash sectors with
//! the rules of RM0383 §3.5: programming only clears bits (the result is old AND new), an
//! erase sets the whole sector to 0xFF, and an erase cut short leaves each bit part way (here:
//! every 0 bit rises with a given probability). A save is what the STM32F411 board does: read
//! the plan, erase the target sector if the plan says so, program the slot's bytes in order.
//!
//! Truths: the records saved (which one must load after a cut is known from the cut point),
//! never one the state machine has to refuse, never none while one was saved.

use ridge_core::{ArxModel, InputMap, Offset};
use ridge_pump_firmware::flash_store::{
    self, boot_erase, plan, slot_bytes, At, PROGRAMMED_LEN, RUN_SAVES, SECTOR_LEN, SLOTS, SLOT_LEN,
};
use ridge_pump_firmware::persist::{self, RECORD_LEN};

/// Two sectors, erased.
fn blank() -> [Vec<u8>; 2] {
    [vec![0xFF; SECTOR_LEN], vec![0xFF; SECTOR_LEN]]
}

fn view(m: &[Vec<u8>; 2]) -> [&[u8]; 2] {
    [&m[0], &m[1]]
}

/// The record loaded from `m`, if any.
fn loaded(m: &[Vec<u8>; 2]) -> Option<Vec<u8>> {
    let p = plan(view(m));
    flash_store::record(view(m), &p).map(<[u8]>::to_vec)
}

/// A distinct whole record (`k` in its fit).
fn record(k: u16) -> [u8; RECORD_LEN] {
    let model = ArxModel::new(&[0.9f32], &[12.0], 3, Offset::Intercept, -1.5).unwrap();
    let map = InputMap::new(1_500, 533, core::array::from_fn(|i| 100 * i as i16)).unwrap();
    persist::encode(&model, &map, 70.0 + f32::from(k) / 100.0)
}

/// Deterministic bit noise (xorshift64*).
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A byte whose bits are each 1 with probability `p`.
    fn byte(&mut self, p: f64) -> u8 {
        (0..8).fold(0, |b, i| {
            let u = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
            b | (u8::from(u < p) << i)
        })
    }
}

/// How a save ends.
#[derive(Clone, Copy, Debug)]
enum Cut {
    /// Not cut.
    None,
    /// Power lost after `n` program accesses (bytes).
    AfterBytes(usize),
    /// Power lost during the erase, each 0 bit of the sector having risen with this
    /// probability.
    InErase(f64, u64),
}

/// A save of `rec` as the board does it, cut as `cut` says. Returns the plan it followed.
fn save(m: &mut [Vec<u8>; 2], rec: &[u8], cut: Cut) -> flash_store::Plan {
    let p = plan(view(m));
    let sector = &mut m[usize::from(p.target.sector)];
    if p.erase {
        match cut {
            Cut::InErase(prob, seed) => {
                let mut noise = Noise(seed | 1);
                for b in sector.iter_mut() {
                    *b |= noise.byte(prob);
                }
                return p;
            }
            _ => sector.fill(0xFF),
        }
    }
    let bytes = slot_bytes(rec, p.seq).expect("slot bytes");
    let at = usize::from(p.target.slot) * SLOT_LEN;
    let n = match cut {
        Cut::AfterBytes(n) => n.min(bytes.len()),
        _ => bytes.len(),
    };
    for (k, &b) in bytes.iter().enumerate().take(n) {
        sector[at + k] &= b;
    }
    p
}

#[test]
fn layout() {
    assert_eq!(PROGRAMMED_LEN, RECORD_LEN + 12);
    assert_eq!(SLOT_LEN, 128);
    assert_eq!(SLOTS, 1024);
    assert_eq!(flash_store::SECTORS, [(6, 0x4_0000), (7, 0x6_0000)]);
    let b = slot_bytes(&record(1), 0x0102_0304).unwrap();
    assert_eq!(&b[..RECORD_LEN], &record(1));
    assert_eq!(&b[RECORD_LEN..RECORD_LEN + 4], &[4, 3, 2, 1]);
    assert_eq!(&b[RECORD_LEN + 4..RECORD_LEN + 8], &[!4, !3, !2, !1]);
    assert_eq!(&b[RECORD_LEN + 8..], b"RP\x69\x00");
    assert_eq!(slot_bytes(&[0; 3], 0), None);
}

#[test]
fn an_erased_store_has_no_record_and_saves_go_on_in_order() {
    let mut m = blank();
    let p = plan(view(&m));
    assert_eq!(p.load, None);
    assert_eq!(
        (p.target, p.erase, p.seq),
        (At { sector: 0, slot: 0 }, false, 0)
    );
    for k in 0..5u16 {
        save(&mut m, &record(k), Cut::None);
        assert_eq!(loaded(&m).as_deref(), Some(&record(k)[..]));
        let p = plan(view(&m));
        assert_eq!(p.target.slot, k + 1);
        assert_eq!(p.seq, u32::from(k) + 1);
    }
}

/// A cut after each program access of a save (0 ..= all of them): the previous record loads
/// until the mark's last byte is programmed, the new one from then on.
#[test]
fn a_save_cut_at_every_program_access_keeps_the_previous_record() {
    let mut base = blank();
    save(&mut base, &record(1), Cut::None);
    save(&mut base, &record(2), Cut::None);
    for n in 0..=PROGRAMMED_LEN {
        let mut m = base.clone();
        save(&mut m, &record(3), Cut::AfterBytes(n));
        let want = if n < PROGRAMMED_LEN { 2 } else { 3 };
        assert_eq!(
            loaded(&m).as_deref(),
            Some(&record(want)[..]),
            "cut after {n}"
        );
        // And the next save after the cut goes to a fresh slot, after the cut one.
        if n > 0 && n < PROGRAMMED_LEN {
            let p = save(&mut m, &record(4), Cut::None);
            assert_eq!(p.target.slot, 3);
            assert_eq!(loaded(&m).as_deref(), Some(&record(4)[..]));
        }
    }
    // Forgetting: the tombstone, cut the same way.
    for n in 0..=PROGRAMMED_LEN {
        let mut m = base.clone();
        save(&mut m, &[0xFF; RECORD_LEN], Cut::AfterBytes(n));
        let want = (n < PROGRAMMED_LEN).then(|| record(2).to_vec());
        assert_eq!(loaded(&m), want, "forget cut after {n}");
    }
}

/// Filling the first sector, then the switch: the other sector is erased first; the record
/// survives an erase cut anywhere (bits risen with probabilities from almost none to almost
/// all), and a completed switch goes on in the new sector.
#[test]
fn a_full_sector_switches_to_the_other_and_an_erase_cut_keeps_the_newest() {
    let mut full = blank();
    for k in 0..SLOTS as u16 {
        save(&mut full, &record(k % 50), Cut::None);
    }
    // The first switch finds the second sector blank: no erase.
    let p = plan(view(&full));
    assert_eq!((p.target, p.erase), (At { sector: 1, slot: 0 }, false));
    save(&mut full, &record(100), Cut::None);
    for k in 0..(SLOTS as u16 - 1) {
        save(&mut full, &record(k % 50), Cut::None);
    }
    // Now the second sector is full too, newest in its last slot; the next save erases the
    // first sector.
    let p = plan(view(&full));
    assert_eq!(
        (p.target, p.erase, p.seq),
        (At { sector: 0, slot: 0 }, true, 2 * SLOTS as u32)
    );
    let newest = loaded(&full).unwrap();
    assert_eq!(newest, record((SLOTS as u16 - 2) % 50));
    for (i, prob) in [0.0, 1e-4, 0.01, 0.1, 0.5, 0.9, 0.999, 1.0]
        .into_iter()
        .enumerate()
    {
        for seed in 1..4u64 {
            let mut cut = full.clone();
            save(
                &mut cut,
                &record(200),
                Cut::InErase(prob, seed * 7 + i as u64),
            );
            assert_eq!(
                loaded(&cut).as_ref(),
                Some(&newest),
                "erase cut at bit probability {prob}, seed {seed}"
            );
            // After the cut, the next save erases again (unless every bit rose) and lands in
            // the first slot.
            let all_risen = cut[0].iter().all(|&b| b == 0xFF);
            let p = save(&mut cut, &record(201), Cut::None);
            assert_eq!((p.target, p.erase), (At { sector: 0, slot: 0 }, !all_risen));
            assert_eq!(loaded(&cut).as_deref(), Some(&record(201)[..]));
        }
    }
    // Uncut: the new record in the first slot of the erased sector, the rest of it erased.
    let mut done = full.clone();
    save(&mut done, &record(300), Cut::None);
    assert_eq!(loaded(&done).as_deref(), Some(&record(300)[..]));
    assert!(done[0][SLOT_LEN..].iter().all(|&b| b == 0xFF));
}

/// A newest record damaged after it was written (bit rot: the mark is programmed last, so a
/// cut cannot do this) falls back to the one before it; with nothing whole before it, it is
/// handed on to be refused with its reason.
#[test]
fn a_damaged_newest_record_falls_back_or_is_refused() {
    let mut m = blank();
    save(&mut m, &record(1), Cut::None);
    save(&mut m, &record(2), Cut::None);
    m[0][SLOT_LEN + 10] ^= 0x04;
    assert_eq!(loaded(&m).as_deref(), Some(&record(1)[..]));
    let mut only = blank();
    save(&mut only, &record(1), Cut::None);
    only[0][10] ^= 0x04;
    let got = loaded(&only).expect("handed on");
    assert_eq!(persist::intact(&got), Err(persist::PersistError::Crc));
}

/// The erase at boot ([`boot_erase`]), walked through boots and runs as the board does them:
/// at each boot the named sector is erased; each run then saves a number of records (up to
/// [`RUN_SAVES`], varied). Truths: no save of a run needs an erase (the board would refuse
/// it), the newest saved record always loads, the boot erases come once per [`SLOTS`] saves
/// (as the erases did when a save made its own room), never of the sector holding the
/// newest record, and a run past [`RUN_SAVES`] saves meets an erase only after them.
#[test]
fn erasing_at_boot_leaves_every_run_its_saves_without_an_erase() {
    let mut m = blank();
    let mut noise = Noise(5);
    let (mut saves, mut erases, mut k) = (0usize, 0usize, 0u16);
    let mut newest: Option<Vec<u8>> = None;
    while saves < 3 * SLOTS + 100 {
        if let Some(index) = boot_erase(view(&m)) {
            let holds_newest = plan(view(&m)).load.map(|at| at.sector);
            assert_ne!(holds_newest, Some(index), "after {saves} saves");
            m[usize::from(index)].fill(0xFF);
            erases += 1;
            assert_eq!(boot_erase(view(&m)), None, "erased");
        }
        assert_eq!(loaded(&m), newest, "boot after {saves} saves");
        let run = (noise.next() % (RUN_SAVES as u64 + 1)) as usize;
        for _ in 0..run {
            k = k.wrapping_add(1);
            let rec = record(k % 60);
            let p = save(&mut m, &rec, Cut::None);
            assert!(!p.erase, "save {} of a run after {saves} saves", saves);
            saves += 1;
            newest = Some(rec.to_vec());
            assert_eq!(loaded(&m), newest);
        }
    }
    // Two sectors filled past the first: one erase per further sector's worth.
    assert_eq!(
        erases,
        (saves - SLOTS) / SLOTS,
        "{erases} erases in {saves} saves"
    );

    // A run that keeps saving: the first RUN_SAVES need no erase, one after them does.
    let mut m = blank();
    for i in 0..(2 * SLOTS - RUN_SAVES) {
        save(&mut m, &record((i % 60) as u16), Cut::None);
    }
    assert_eq!(boot_erase(view(&m)), None, "RUN_SAVES slots left");
    let mut first_erase = None;
    for i in 0..=RUN_SAVES {
        let p = save(&mut m, &record(7), Cut::None);
        if p.erase && first_erase.is_none() {
            first_erase = Some(i);
        }
    }
    assert_eq!(first_erase, Some(RUN_SAVES));
}
