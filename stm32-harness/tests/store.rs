//! The STM32F411 image's persisted record in the emulated flash (`firmware/src/flash_store.rs`
//! over sectors 6 and 7; the board's `FlashStore`): written after `ACCEPT`, loaded after a
//! reset and checked at boot; a damaged or implausible record refused; a power cut at every
//! program access of a save, or during the erase that makes room, never loses the record; the
//! room is made at boot, before the pump runs (without a watchdog reset), and a save that would
//! need an erase while the pump runs is refused without a stall.
//!
//! Truths: the records the tests store (the firmware's encoder, `persist::encode`, of a known
//! model), the ID line of the run that saved, the flash contents and program accesses the
//! flash model logged (RM0383 §3.5 rules), the resets the machine went through. The
//! ATmega2560's counterparts: `persisted_record_is_loaded_and_a_corrupted_one_rejected`,
//! `a_save_cut_at_any_point_keeps_the_other_slot` (simavr-harness/tests/simavr.rs) and
//! `a_whole_record_of_an_implausible_model_is_refused` (record.rs).

mod common;

use common::{elf, run_to, texts, transcript};
use ridge_core::{ArxModel, InputMap, Offset};
use ridge_pump_firmware::flash_store::{
    self, slot_bytes, At, PROGRAMMED_LEN, RUN_SAVES, SECTORS, SECTOR_LEN, SLOTS, SLOT_LEN,
};
use ridge_pump_firmware::lines::PrintedModel;
use ridge_pump_firmware::persist::{self, RECORD_LEN};
use stm32_harness::bench::{ps, secs, Action, Bench, BenchConfig, RunEnd};
use stm32_harness::periph::flash::{EraseCut, Programmed, BASE};
use stm32_harness::periph::rcc::ResetCause;
use stm32_harness::periph::Time;
use stm32_harness::session::{self, SessionConfig};
use stm32_harness::transcript::Line;

/// Offset of θ₁ in a record, and of the first φ and of the CRC (`firmware/src/persist.rs`).
const THETA_AT: usize = 9;
const PHI_AT: usize = 33;
const CRC_AT: usize = 101;

/// The known model of the stored records: a blower-like map on the firmware's grid (15 % +
/// k · 5.33 % duty → 6.3 + 10.8 k slm, ~200 slm per unit duty) and dynamics from the map's
/// flow θ 0.9, φ 0.1, d 3, c −0.2 (static gain 1 slm/slm), fit `fit`.
fn known(fit: f32) -> [u8; RECORD_LEN] {
    let model = ArxModel::new(&[0.9f32], &[0.1], 3, Offset::Intercept, -0.2).expect("model");
    let knots = core::array::from_fn(|k| 759 + 1_300 * k as i16);
    let map = InputMap::new(1_500, 533, knots).expect("map");
    persist::encode(&model, &map, fit)
}

/// The freshly flashed image's memory (as `cargo flash-f411` leaves it).
fn image() -> Vec<u8> {
    Bench::new(BenchConfig::new(elf())).expect("bench").flash()
}

/// `mem` with the store's sectors replaced by `store`.
fn with_store(mut mem: Vec<u8>, store: &[Vec<u8>; 2]) -> Vec<u8> {
    for ((_, offset), s) in SECTORS.iter().zip(store) {
        mem[*offset as usize..*offset as usize + SECTOR_LEN].copy_from_slice(s);
    }
    mem
}

/// A store with `records` saved in order from an erased one, as the firmware's plan places
/// them (no erase needed: fewer than two sectors' worth).
fn store_of(records: &[[u8; RECORD_LEN]]) -> [Vec<u8>; 2] {
    let mut s = [vec![0xFF; SECTOR_LEN], vec![0xFF; SECTOR_LEN]];
    for r in records {
        let p = flash_store::plan([&s[0], &s[1]]);
        assert!(!p.erase);
        let at = usize::from(p.target.slot) * SLOT_LEN;
        s[usize::from(p.target.sector)][at..at + PROGRAMMED_LEN]
            .copy_from_slice(&slot_bytes(r, p.seq).expect("slot"));
    }
    s
}

/// Boots `mem` and runs until the stored model is loaded, refused, or an identification
/// starts (at most `limit_s`).
fn boot(mem: Vec<u8>, limit_s: f64) -> Bench {
    let mut cfg = BenchConfig::new(elf());
    cfg.flash = Some(mem);
    let mut b = Bench::new(cfg).expect("bench");
    b.run_until(limit_s, |l| {
        matches!(l.keyword(), "LOADED" | "STORED-REJECTED" | "SCAN" | "FAULT")
    })
    .expect("run");
    b
}

/// The model of the first `LOADED` line.
fn loaded(b: &Bench) -> Option<PrintedModel> {
    b.find("LOADED")
        .next()
        .and_then(|l| PrintedModel::from_line(&l.parsed()).ok())
}

/// The model a record holds, as a LOADED line prints it (6 decimals).
fn printed(record: &[u8]) -> PrintedModel {
    let (m, _, _) = persist::decode(record).expect("a whole record");
    let r6 = |v: f32| (f64::from(v) * 1e6).round() / 1e6;
    let s = m.structure();
    PrintedModel {
        p: s.p,
        q: s.q,
        d: s.d,
        offset: m.offset(),
        theta: m.theta().iter().map(|&v| r6(v)).collect(),
        phi: m.phi().iter().map(|&v| r6(v)).collect(),
        c: r6(m.intercept()),
    }
}

/// The same model (structure and coefficients as printed).
fn same_model(a: &PrintedModel, b: &PrintedModel) -> bool {
    (a.p, a.q, a.d) == (b.p, b.q, b.d)
        && a.theta.len() == b.theta.len()
        && a.phi.len() == b.phi.len()
        && a.theta
            .iter()
            .zip(&b.theta)
            .all(|(x, y)| (x - y).abs() < 1e-9)
        && a.phi.iter().zip(&b.phi).all(|(x, y)| (x - y).abs() < 1e-9)
}

/// Identification, persistence, a reset with flash kept: the record the first boot saved is
/// the ID line's model (the firmware's plan over the flash, decoded on the host), and the next
/// boot loads it (`record=stored`, `LOADED` with the ID line's coefficients) without
/// identifying again, and runs its controller.
#[test]
fn the_record_is_written_loaded_after_a_reset_and_checked() {
    let cfg = SessionConfig::new(elf());
    let first = session::run(&cfg).expect("session");
    assert!(first.bench.lines.iter().any(|l| l.text == "PERSIST saved"));
    let id = first.id.clone().expect("ID line").model;
    let store = first.bench.store();
    let plan = flash_store::plan([&store[0], &store[1]]);
    assert_eq!(plan.load, Some(At { sector: 0, slot: 0 }), "{plan:?}");
    let rec = flash_store::record([&store[0], &store[1]], &plan).expect("a record");
    let (model, _, fit) = persist::decode(rec).expect("the saved record decodes");
    for (a, b) in model
        .theta()
        .iter()
        .chain(model.phi())
        .zip(id.theta.iter().chain(&id.phi))
    {
        assert!((f64::from(*a) - b).abs() <= 0.5e-6 + 1e-9, "{a} vs ID {b}");
    }
    let accept = first.accept.as_ref().and_then(|a| a.num("fit"));
    assert!((f64::from(fit) - accept.expect("ACCEPT fit")).abs() <= 0.05 + 1e-9);

    let mut bc: BenchConfig = cfg.bench.clone();
    bc.flash = Some(first.bench.flash());
    let mut b = Bench::new(bc).expect("bench");
    b.run_until(30.0, |l| matches!(l.keyword(), "CTRL" | "FAULT"))
        .expect("run");
    let boot = b.find("BOOT").next().expect("BOOT");
    assert_eq!(boot.text, "BOOT board=stm32f411 reset=14 record=stored");
    let model = loaded(&b).expect("model on LOADED");
    assert!(same_model(&model, &id), "{model:?} vs {id:?}");
    assert!(
        b.find("SCAN").next().is_none(),
        "no identification with a stored model"
    );
    assert!(b.find("CTRL").next().is_some(), "{}", transcript(&b));
}

/// Runs a boot that must refuse its record: `STORED-REJECTED <reason>` before `SCAN` (the
/// identification's first line), no `LOADED`, no controller, no run mode. Returns the
/// refusal's text.
fn refused(mem: Vec<u8>, what: &str) -> String {
    let mut b = boot(mem, 5.0);
    if b.lines
        .last()
        .is_some_and(|l| l.keyword() == "STORED-REJECTED")
    {
        run_to(&mut b, 5.0, "SCAN");
    }
    let log = transcript(&b);
    let first = |kw: &str| b.lines.iter().position(|l| l.keyword() == kw);
    let rejected =
        first("STORED-REJECTED").unwrap_or_else(|| panic!("{what}: not refused:\n{log}"));
    let scan = first("SCAN").unwrap_or_else(|| panic!("{what}: no identification:\n{log}"));
    assert!(rejected < scan, "{what}:\n{log}");
    for kw in ["LOADED", "CTRL", "TRACK", "FAULT"] {
        assert!(first(kw).is_none(), "{what}: a {kw} line:\n{log}");
    }
    b.lines[rejected].text.clone()
}

/// The boot checks: a record of the known model in the store's first slot is loaded
/// (`LOADED p=1 q=1 d=3`, no identification); the same with one byte flipped (at its start,
/// middle and end) is refused and the pump identifies anew; a whole record (CRC recomputed) of
/// the model with φ negated is refused for its static gain, `−Σφ / (1 − Σθ)` = −1; the
/// store `ridge-id identify --stm32-store` writes is loaded.
#[test]
fn a_stored_record_is_loaded_and_a_damaged_or_implausible_one_refused() {
    let mem = image();
    let rec = known(88.5);
    let b = boot(with_store(mem.clone(), &store_of(&[rec])), 4.0);
    let log = transcript(&b);
    assert_eq!(
        b.lines.first().map(|l| l.text.as_str()),
        Some("BOOT board=stm32f411 reset=14 record=stored"),
        "{log}"
    );
    let m = loaded(&b).unwrap_or_else(|| panic!("not loaded:\n{log}"));
    assert!(same_model(&m, &printed(&rec)), "{m:?}\n{log}");
    assert!(
        !b.lines
            .iter()
            .any(|l| matches!(l.keyword(), "SCAN" | "STORED-REJECTED")),
        "{log}"
    );

    for byte in [0, THETA_AT + 3, RECORD_LEN - 1] {
        let mut bad = rec;
        bad[byte] ^= 0x04;
        let reason = refused(
            with_store(mem.clone(), &store_of(&[bad])),
            &format!("byte {byte} flipped"),
        );
        let want = if byte < 4 { "magic" } else { "crc" };
        assert_eq!(reason, format!("STORED-REJECTED {want}"), "byte {byte}");
    }

    let mut junk = rec;
    junk[PHI_AT + 3] ^= 0x80;
    let crc = persist::crc32(&junk[..CRC_AT]).to_le_bytes();
    junk[CRC_AT..CRC_AT + 4].copy_from_slice(&crc);
    assert!(persist::intact(&junk).is_ok(), "CRC-valid");
    let reason = refused(with_store(mem.clone(), &store_of(&[junk])), "φ negated");
    let gain: f64 = reason
        .strip_prefix("STORED-REJECTED gain=")
        .unwrap_or_else(|| panic!("not refused for its gain: {reason}"))
        .parse()
        .expect("a number");
    assert!((gain + 0.1 / (1.0 - 0.9)).abs() < 1e-3, "gain {gain}");

    let file = ridge_id::export::stm32_store(&rec);
    let at = (ridge_id::export::STM32_STORE_ADDRESS - BASE) as usize;
    let mut flashed = mem;
    flashed[at..at + file.len()].copy_from_slice(&file);
    let b = boot(flashed, 4.0);
    let m =
        loaded(&b).unwrap_or_else(|| panic!("ridge-id's store not loaded:\n{}", transcript(&b)));
    assert!(same_model(&m, &printed(&rec)));
}

/// `mem` after the program accesses `writes` (each clears bits: old AND new).
fn after(mut mem: Vec<u8>, writes: &[Programmed]) -> Vec<u8> {
    for w in writes {
        for k in 0..u32::from(w.size) {
            mem[(w.offset + k) as usize] &= (w.value >> (8 * k)) as u8;
        }
    }
    mem
}

/// A: the known model, stored. REID in run mode: the pump identifies anew and saves B after
/// `ACCEPT`. Runs that to `PERSIST`, or, with `cut`, cuts the power after that many program
/// accesses and powers up again (the bench's own cut). Returns the bench.
fn reid_and_save(mem: Vec<u8>, cut: Option<usize>) -> Bench {
    let mut b = boot(mem, 4.0);
    assert!(loaded(&b).is_some(), "{}", transcript(&b));
    run_to(&mut b, 2.0, "TRACK");
    // The save is the only flash programming of the run.
    assert!(b.machine.chip().flash.programmed.is_empty());
    if let Some(n) = cut {
        b.apply(Action::PowerCutAfterProgram(n)).expect("arm");
    }
    b.send_at(b.time_s(), b"REID\n");
    let accept = run_to(&mut b, 80.0, "ACCEPT");
    assert!(
        accept.is_some(),
        "no ACCEPT after REID:\n{}",
        transcript(&b)
    );
    if cut.is_some() {
        run_to(&mut b, 2.0, "BOOT");
        b.run_for(0.1).expect("run");
    } else {
        run_to(&mut b, 2.0, "PERSIST");
    }
    b
}

/// The power cut at every program access of a save (a loop over the cut point): A stored, the
/// pump identifies B and saves it (117 program accesses into the slot after A's). The flash a
/// cut after `k` accesses leaves is A's store and the first `k` accesses; booted from it, the
/// pump loads A for every `k` < 117 and B at 117: never a record it refuses, never none. The
/// bench's own power cut at three points leaves exactly that flash and that boot.
#[test]
fn a_power_cut_at_every_program_access_of_a_save_keeps_a_record() {
    let a = known(88.5);
    let mem = with_store(image(), &store_of(&[a]));
    let saved = reid_and_save(mem.clone(), None);
    assert!(
        saved.lines.iter().any(|l| l.text == "PERSIST saved"),
        "{}",
        transcript(&saved)
    );
    let writes = saved.machine.chip().flash.programmed.clone();
    let id = session::analyse(saved, 0.0).id.expect("ID line").model;
    assert_eq!(writes.len(), PROGRAMMED_LEN, "program accesses of the save");
    let slot1 = SECTORS[0].1 + SLOT_LEN as u32;
    for (k, w) in writes.iter().enumerate() {
        assert_eq!((w.offset, w.size), (slot1 + k as u32, 1), "access {k}");
    }
    let t0 = std::time::Instant::now();
    for k in 0..=writes.len() {
        let b = boot(after(mem.clone(), &writes[..k]), 4.0);
        let log = transcript(&b);
        assert_eq!(
            b.lines.first().map(|l| l.text.as_str()),
            Some("BOOT board=stm32f411 reset=14 record=stored"),
            "cut after {k}:\n{log}"
        );
        let m = loaded(&b).unwrap_or_else(|| panic!("cut after {k}: nothing loaded:\n{log}"));
        if k < writes.len() {
            assert!(same_model(&m, &printed(&a)), "cut after {k}: {m:?}");
        } else {
            assert!(same_model(&m, &id), "complete save: {m:?} vs ID {id:?}");
        }
    }
    println!(
        "{} boots from the cut points in {:.1} s wall",
        writes.len() + 1,
        t0.elapsed().as_secs_f64()
    );
    // The bench's own cuts: after the first byte, in the sequence number, before the mark's
    // last byte.
    for n in [1, RECORD_LEN + 1, PROGRAMMED_LEN - 1] {
        let b = reid_and_save(mem.clone(), Some(n));
        let resets: Vec<ResetCause> = b.machine.resets.iter().map(|r| r.cause).collect();
        assert_eq!(
            resets,
            [ResetCause::PowerOn, ResetCause::PowerOn],
            "cut after {n}"
        );
        assert_eq!(
            b.flash(),
            after(mem.clone(), &writes[..n]),
            "flash after a cut after {n}"
        );
        let boots: Vec<&Line> = b.find("BOOT").collect();
        assert_eq!(
            boots.last().map(|l| l.text.as_str()),
            Some("BOOT board=stm32f411 reset=14 record=stored")
        );
    }
}

/// Sector 6 full (1 365 slots, the newest holding A), sector 7 holding older records. The next
/// save needs room, so the boot makes it before the pump is driven: it erases sector 7 (2 s,
/// the CPU stalled, TIM3_CCR1 0 throughout) with the watchdog's timeout raised to 8 s and in
/// effect (the reload waits for IWDG_SR.RVU, RM0383 §15.4.4): no watchdog reset, A loaded
/// after it. A save while the pump runs (`FORGET`: the forgotten record) then goes to sector
/// 7's first slot without a stall: `PERSIST saved`, sector 6 untouched, the next boot has no
/// record. A power cut at several points of the boot's erase (its bits part way, see
/// `periph::flash`) leaves A loadable, and the boot after it erases again.
#[test]
fn a_full_sector_gets_its_room_at_boot_before_the_pump_runs_and_survives_a_cut() {
    let a = known(88.5);
    let older = known(77.0);
    let mut store = [vec![0xFF; SECTOR_LEN], vec![0xFF; SECTOR_LEN]];
    let mut put = |sector: usize, slot: usize, rec: &[u8; RECORD_LEN], seq: u32| {
        let at = slot * SLOT_LEN;
        store[sector][at..at + PROGRAMMED_LEN].copy_from_slice(&slot_bytes(rec, seq).unwrap());
    };
    for i in 0..10 {
        put(1, i, &older, i as u32);
    }
    for i in 0..SLOTS {
        put(
            0,
            i,
            if i + 1 == SLOTS { &a } else { &older },
            10 + i as u32,
        );
    }
    let plan = flash_store::plan([&store[0], &store[1]]);
    assert_eq!((plan.target, plan.erase), (At { sector: 1, slot: 0 }, true));
    let mem = with_store(image(), &store);

    let mut b = boot(mem.clone(), 6.0);
    let m = loaded(&b).unwrap_or_else(|| panic!("A not loaded:\n{}", transcript(&b)));
    assert!(same_model(&m, &printed(&a)));
    let core = b.machine.core();
    assert_eq!(core.erase_stalls.len(), 1, "{}", transcript(&b));
    assert_eq!(b.machine.chip().flash.erased.len(), 1);
    assert_eq!(b.machine.chip().flash.erased[0].1, SECTORS[1].0);
    let stall = core.erase_stalls[0];
    let stall_end = stall.at + stall.len;
    let watchdog = stall.watchdog.expect("the IWDG runs") - stall.at;
    println!(
        "boot erase: CPU stalled {:.3} s from {:.4} s, the IWDG's timeout at its start {:.3} s",
        secs(stall.len),
        secs(stall.at),
        secs(watchdog)
    );
    assert_eq!(stall.len, ps(2.0), "the whole 128 KB erase");
    assert!(watchdog > ps(7.9), "IWDG timeout {:.3} s", secs(watchdog));
    assert!(
        core.pwm_writes
            .iter()
            .all(|&(t, ccr)| ccr == 0 || t > stall_end),
        "the pump driven before the erase ended: {:?}",
        &core.pwm_writes[..core.pwm_writes.len().min(5)]
    );
    assert!(b.duty_log.iter().all(|d| d.at > stall_end || d.ccr == 0));
    let boot_line = b.find("BOOT").next().expect("BOOT");
    assert!(boot_line.start > stall_end, "BOOT before the erase ended");

    run_to(&mut b, 2.0, "TRACK").expect("TRACK");
    b.send_at(b.time_s(), b"FORGET\n");
    run_to(&mut b, 1.0, "PERSIST").expect("PERSIST");
    assert_eq!(
        b.lines.last().map(|l| l.text.as_str()),
        Some("PERSIST saved")
    );
    let m = &b.machine;
    assert_eq!(
        m.resets.len(),
        1,
        "a reset: {:?}\n{}",
        m.resets,
        transcript(&b)
    );
    assert_eq!(m.core().erase_stalls.len(), 1, "an erase while running");
    assert_eq!(m.chip().flash.erased.len(), 1);
    let after_store = b.store();
    assert_eq!(after_store[0], store[0], "sector 6 touched");
    assert_eq!(
        &after_store[1][..PROGRAMMED_LEN],
        &slot_bytes(&[0xFF; RECORD_LEN], 10 + SLOTS as u32).unwrap()[..]
    );
    assert!(after_store[1][PROGRAMMED_LEN..].iter().all(|&x| x == 0xFF));
    let reboot = boot(b.flash(), 3.0);
    assert_eq!(
        reboot.lines.first().map(|l| l.text.as_str()),
        Some("BOOT board=stm32f411 reset=14 record=none"),
        "{}",
        transcript(&reboot)
    );
    assert!(reboot.machine.core().erase_stalls.is_empty(), "room enough");

    for (i, fraction) in [0.0, 0.001, 0.1, 0.5, 0.999].into_iter().enumerate() {
        let cut = EraseCut {
            fraction,
            seed: 11 + i as u64,
        };
        let mut cfg = BenchConfig::new(elf());
        cfg.flash = Some(mem.clone());
        let mut b = Bench::new(cfg).expect("bench");
        b.apply(Action::PowerCutInErase(cut)).expect("arm");
        b.run_until(8.0, |l| l.keyword() == "LOADED").expect("run");
        assert_eq!(
            b.machine.resets.last().map(|r| r.cause),
            Some(ResetCause::PowerOn),
            "cut at {fraction}"
        );
        let boots: Vec<&str> = b
            .lines
            .iter()
            .filter(|l| l.keyword() == "BOOT")
            .map(|l| l.text.as_str())
            .collect();
        assert_eq!(
            boots,
            ["BOOT board=stm32f411 reset=14 record=stored"],
            "cut at {fraction}: {:?}",
            texts(&b.lines)
        );
        let m = loaded(&b)
            .unwrap_or_else(|| panic!("cut at {fraction}: A not loaded:\n{}", transcript(&b)));
        assert!(same_model(&m, &printed(&a)), "cut at {fraction}");
        let store_now = b.store();
        assert_eq!(
            store_now[0], store[0],
            "cut at {fraction}: sector 6 touched"
        );
        assert!(
            store_now[1].iter().all(|&x| x == 0xFF),
            "cut at {fraction}: sector 7 not erased at the next boot"
        );
    }
}

/// A run that has used up its saves ([`RUN_SAVES`]: the sector in use had that many erased
/// slots at boot, and the test fills them while the image runs, as that many saves would): the
/// next save would need sector 7 erased, 2 s with the CPU stalled while the pump runs. The
/// image refuses it (`PERSIST failed`): no erase, no stall, the store as it was, the control
/// ticks on (no `MISSED` line, `TRACK` lines go on). After a power cycle the boot makes the
/// room, the newest record (A) loads, and the same save succeeds.
#[test]
fn a_save_that_needs_an_erase_while_the_pump_runs_is_refused_without_a_stall() {
    let a = known(88.5);
    let older = known(77.0);
    let mut store = [vec![0xFF; SECTOR_LEN], vec![0xFF; SECTOR_LEN]];
    let put = |store: &mut [Vec<u8>; 2], sector: usize, slot: usize, seq: u32| {
        let at = slot * SLOT_LEN;
        store[sector][at..at + PROGRAMMED_LEN].copy_from_slice(&slot_bytes(&a, seq).unwrap());
    };
    for i in 0..10 {
        let at = i * SLOT_LEN;
        store[1][at..at + PROGRAMMED_LEN].copy_from_slice(&slot_bytes(&older, i as u32).unwrap());
    }
    let used = SLOTS - RUN_SAVES;
    for i in 0..used {
        put(&mut store, 0, i, 10 + i as u32);
    }
    assert_eq!(flash_store::boot_erase([&store[0], &store[1]]), None);
    let mut b = boot(with_store(image(), &store), 4.0);
    let m = loaded(&b).unwrap_or_else(|| panic!("A not loaded:\n{}", transcript(&b)));
    assert!(same_model(&m, &printed(&a)));
    run_to(&mut b, 2.0, "TRACK").expect("TRACK");
    // The run's saves: the rest of sector 6, each a committed copy of A.
    let mut full = store.clone();
    for i in used..SLOTS {
        put(&mut full, 0, i, 10 + i as u32);
    }
    let bytes = &full[0][used * SLOT_LEN..];
    b.machine
        .write_flash(SECTORS[0].1 + (used * SLOT_LEN) as u32, bytes)
        .expect("write");
    let plan = flash_store::plan([&full[0], &full[1]]);
    assert_eq!((plan.target, plan.erase), (At { sector: 1, slot: 0 }, true));

    let sent = b.send_at(b.time_s(), b"FORGET\n");
    run_to(&mut b, 1.0, "PERSIST").expect("PERSIST");
    assert_eq!(
        b.lines.last().map(|l| l.text.as_str()),
        Some("PERSIST failed"),
        "{}",
        transcript(&b)
    );
    b.run_for(2.0).expect("run");
    let core = b.machine.core();
    assert!(
        core.erase_stalls.is_empty(),
        "a stall: {:?}",
        core.erase_stalls
    );
    assert!(b.machine.chip().flash.erased.is_empty());
    assert!(b.machine.resets.len() == 1, "{:?}", b.machine.resets);
    assert_eq!(b.store(), full, "the store changed");
    let after = |kw: &'static str| b.find(kw).filter(move |l| l.start > sent);
    assert!(after("MISSED").next().is_none(), "{}", transcript(&b));
    let tracks: Vec<Time> = after("TRACK").map(|l| l.start).collect();
    assert!(tracks.len() >= 2, "{}", transcript(&b));
    // The pump ran on: the duty changes at least once a breath after the refusal.
    assert!(
        b.duty_log.iter().filter(|d| d.at > sent).count() > 10,
        "the duty froze"
    );

    // A power cycle: the boot erases sector 7, A loads, the save goes through.
    let mut b = boot(b.flash(), 6.0);
    assert_eq!(b.machine.core().erase_stalls.len(), 1, "no boot erase");
    let m = loaded(&b).unwrap_or_else(|| panic!("A not loaded:\n{}", transcript(&b)));
    assert!(same_model(&m, &printed(&a)));
    run_to(&mut b, 2.0, "TRACK").expect("TRACK");
    b.send_at(b.time_s(), b"FORGET\n");
    run_to(&mut b, 1.0, "PERSIST").expect("PERSIST");
    assert_eq!(
        b.lines.last().map(|l| l.text.as_str()),
        Some("PERSIST saved")
    );
    assert_eq!(b.machine.core().erase_stalls.len(), 1);
    assert_eq!(
        &b.store()[1][..PROGRAMMED_LEN],
        &slot_bytes(&[0xFF; RECORD_LEN], 10 + SLOTS as u32).unwrap()[..]
    );
}

/// At boot the image reads both sectors of the store: filled with zeros (no slot erased, none
/// committed) the reads are work, not a wait on a register: no clock jump may stretch them
/// (a loop reading the constant flash-size word once took 1.6 s of emulated time for
/// 0.09 M instructions).
#[test]
fn scanning_a_full_store_is_work_not_a_wait() {
    let zeros = [vec![0; SECTOR_LEN], vec![0; SECTOR_LEN]];
    let mut cfg = BenchConfig::new(elf());
    cfg.flash = Some(with_store(image(), &zeros));
    let mut b = Bench::new(cfg).expect("bench");
    let end = b.run_until(2.5, |l| l.keyword() == "BOOT").expect("run");
    assert!(matches!(end, RunEnd::Line(_)));
    let boot = b.find("BOOT").next().expect("BOOT");
    // Neither sector has room: the boot erases one (2 s, `flash_store::boot_erase`); the
    // rest is work.
    let stalls: Time = b.machine.core().erase_stalls.iter().map(|s| s.len).sum();
    assert_eq!(stalls, ps(2.0));
    assert!(
        boot.start - stalls < ps(0.01),
        "BOOT at {:.4} s, {:.4} s of it erasing",
        secs(boot.start),
        secs(stalls)
    );
    assert_eq!(boot.text, "BOOT board=stm32f411 reset=14 record=none");
}

/// A power cut in the middle of the first save (nothing stored before): the bytes before the
/// cut stay programmed, the slot has no commit mark, the next boot has no record.
#[test]
fn a_power_cut_in_the_middle_of_the_first_save_leaves_no_record() {
    let mut b = Bench::new(BenchConfig::new(elf())).expect("bench");
    b.apply(Action::PowerCutAfterProgram(40)).expect("arm");
    b.run_until(100.0, |l| l.keyword() == "BOOT" && l.start > ps(1.0))
        .expect("run");
    let m = &b.machine;
    assert_eq!(m.resets.len(), 2, "{:?}\n{}", m.resets, transcript(&b));
    assert_eq!(m.resets[1].cause, ResetCause::PowerOn);
    assert_eq!(m.chip().flash.programmed.len(), 40);
    assert!(b.store_used(), "the bytes before the cut stay programmed");
    let boot = b.find("BOOT").nth(1).expect("BOOT after the power cut");
    assert_eq!(boot.text, "BOOT board=stm32f411 reset=14 record=none");
}
