//! `identify --eeprom / --record / --stm32-store`: the files hold the firmware's record of the
//! model the JSON report gives, at the addresses the boards read; refusals write nothing.
//!
//! Independent truths: the JSON of the same run (the model from the duty), its documented form
//! in the record (the map its steady flow `K u + c/A(1)` at the firmware's knots, the dynamics
//! `θ` and `φ / K`: the model's own free-run prediction computed here must equal the record's
//! Hammerstein model's), the firmware's own `persist::decode` and boot path
//! (`SelfIdentification::new` with the record, as the boards call it), the `ihex` crate and a
//! small hand-written Intel HEX parser (checksums), the board sources for the addresses.

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use pump_sim::arx::simulate_arx;
use ridge_core::{ArxModel, Evaluation, InputMap};
use ridge_pump_firmware::event::Event;
use ridge_pump_firmware::flash_store;
use ridge_pump_firmware::persist::{self, RECORD_LEN};
use ridge_pump_firmware::selfid::{SelfIdentification, DEFAULT_CONFIG};
use ridge_pump_firmware::slots::{self, EEPROM_BASE, SLOT_LEN, STORE_LEN};
use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_ridge-id");

/// A fresh, empty directory for one test.
fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("ridge_id_export")
        .join(name);
    fs::remove_dir_all(&d).ok();
    fs::create_dir_all(&d).unwrap();
    d
}

/// Duty steps in 0.2..0.6 (a fraction, as the pump's log), held 5..=60 samples.
fn duty_steps(n: usize, seed: u64) -> Vec<f64> {
    common::steps(n, seed ^ 0x9E37_79B9_7F4A_7C15, 0.2, 0.4, 5, 56.0)
}

/// A pump-like plant (slm per unit duty): poles 0.8 and 0.5, static gain 5 / 0.1 = 50 slm,
/// delay 3 samples, a flow offset of 2 slm.
const THETA: [f64; 2] = [1.3, -0.4];
const PHI: [f64; 2] = [3.0, 2.0];
const DELAY: usize = 3;
const OFFSET: f64 = 2.0;

/// A log `t,u,y` of the plant; `u_scale` 100 writes the duty in percent.
fn log(path: &Path, n: usize, seed: u64, u_scale: f64) {
    let u = duty_steps(n, seed);
    let y = simulate_arx(&THETA, &PHI, DELAY, &u, 0.02, seed);
    let mut text = String::from("t,u,y\n");
    for (i, (u, y)) in u.iter().zip(&y).enumerate() {
        text.push_str(&format!(
            "{:.2},{},{}\n",
            i as f64 * 0.01,
            u * u_scale,
            y + OFFSET
        ));
    }
    fs::write(path, text).unwrap();
}

fn identify(args: &[&str]) -> Output {
    Command::new(BIN)
        .arg("identify")
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn f32_close(got: f32, want: f64) -> bool {
    // One rounding to f32: within half an ulp, i.e. 2^-24 relative (plus subnormal slack).
    (f64::from(got) - want).abs() <= want.abs() * 2f64.powi(-24) + 1e-38
}

/// An independent Intel HEX reader: every line's checksum verified, data records (type 00)
/// placed at their address, the end-of-file record (01) required last; any other record type
/// is an error. Returns (address, byte) pairs.
fn parse_hex(text: &str) -> Vec<(u16, u8)> {
    let mut out = Vec::new();
    let mut eof = false;
    for line in text.lines() {
        assert!(!eof, "a line after the end-of-file record");
        let hex = line.strip_prefix(':').expect("a line without ':'");
        assert!(hex.len() % 2 == 0 && hex.len() >= 10, "line {line}");
        let bytes: Vec<u8> = (0..hex.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
            .collect();
        let sum = bytes.iter().fold(0u8, |a, &b| a.wrapping_add(b));
        assert_eq!(sum, 0, "checksum of {line}");
        let len = usize::from(bytes[0]);
        assert_eq!(bytes.len(), len + 5, "length of {line}");
        let addr = u16::from_be_bytes([bytes[1], bytes[2]]);
        match bytes[3] {
            0x00 => {
                for (k, &b) in bytes[4..4 + len].iter().enumerate() {
                    out.push((addr + k as u16, b));
                }
            }
            0x01 => eof = true,
            t => panic!("record type {t:02X} in an EEPROM image"),
        }
    }
    assert!(eof, "no end-of-file record");
    out
}

/// The ATmega2560's 4 KB EEPROM after avrdude wrote `hex` to an erased chip.
fn eeprom_after(hex: &str) -> Vec<u8> {
    let mut ee = vec![0xFFu8; 4096];
    for (a, b) in parse_hex(hex) {
        ee[usize::from(a)] = b;
    }
    ee
}

/// What the firmware's boot path makes of `stored` (the bytes the board's load returns):
/// the map (its `MAP` line, first), the `LOADED` model and fit, or the first other event.
fn boot(stored: &[u8]) -> Result<(ArxModel<f32>, InputMap, f32), String> {
    let mut sm = SelfIdentification::new(&DEFAULT_CONFIG, Some(stored));
    let mut map = None;
    // About 20 slm (2400 counts, dithered by one count as a real sensor's noise would: an
    // exactly constant reading is a frozen sensor) until the state machine has settled and
    // loads the model.
    for k in 0..2000 {
        if let Some(e) = sm.tick(Ok(2400 + k % 2)).event {
            match e {
                Event::Map(m) => map = Some(m),
                Event::Loaded { model, fit } => {
                    return Ok((model, map.ok_or("no MAP line before LOADED")?, fit))
                }
                other => return Err(format!("{other:?}")),
            }
        }
    }
    Err("no event".into())
}

/// The free-run predictions of the linear model `(theta, phi, d, c)` from the duty and of the
/// record's Hammerstein model (`map` to flow, then `dynamics`) on the same duty steps, from
/// the same measured start; their largest difference, slm.
fn largest_difference(linear: &ArxModel<f64>, map: &InputMap, dynamics: &ArxModel<f32>) -> f64 {
    let u = duty_steps(2_000, 77);
    let y = simulate_arx(
        linear.theta(),
        linear.phi(),
        linear.structure().d.into(),
        &u,
        0.0,
        1,
    );
    let mut a = Evaluation::new(*linear);
    let mut b = Evaluation::new(*dynamics);
    let mut worst = 0.0f64;
    for (&u, &y) in u.iter().zip(&y) {
        let y = y + linear.intercept() / (1.0 - linear.theta().iter().sum::<f64>());
        let v = f32::from(map.at((u * 10_000.0).round() as u16)) / 120.0;
        let (pa, pb) = (a.push(u, y), b.push(v, y as f32));
        if let (Some(pa), Some(pb)) = (pa, pb) {
            worst = worst.max((pa.1 - f64::from(pb.1)).abs());
        }
    }
    worst
}

#[test]
fn files_hold_the_json_model_at_the_boards_addresses() {
    let d = dir("json");
    let (est, val) = (d.join("est.csv"), d.join("val.csv"));
    log(&est, 3000, 1, 1.0);
    log(&val, 3000, 2, 1.0);
    let (hex, bin, stm) = (d.join("m.hex"), d.join("m.bin"), d.join("store.bin"));
    let out = identify(&[
        "--input",
        s(&est),
        "--validate",
        s(&val),
        "--offset",
        "intercept",
        "--json",
        "--eeprom",
        s(&hex),
        "--record",
        s(&bin),
        "--stm32-store",
        s(&stm),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();

    // The raw record decodes (the firmware's decoder) to the JSON's model: its θ, its φ over
    // the static gain, no intercept left; the map the model's steady flow.
    let record = fs::read(&bin).unwrap();
    assert_eq!(record.len(), RECORD_LEN);
    let (model, map, fit) = persist::decode(&record).unwrap();
    let st = model.structure();
    let js = &json["structure"];
    assert_eq!(
        (u64::from(st.p), u64::from(st.q), u64::from(st.d)),
        (
            js["p"].as_u64().unwrap(),
            js["q"].as_u64().unwrap(),
            js["d"].as_u64().unwrap()
        )
    );
    let list = |k: &str| -> Vec<f64> {
        json[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (theta, phi) = (list("theta"), list("phi"));
    let c = json["offset"].as_f64().unwrap();
    assert_eq!(model.theta().len(), theta.len());
    assert_eq!(model.phi().len(), phi.len());
    for (g, w) in model.theta().iter().zip(&theta) {
        assert!(f32_close(*g, *w), "{g} vs {w}");
    }
    let a1 = 1.0 - theta.iter().sum::<f64>();
    let gain = phi.iter().sum::<f64>() / a1;
    for (g, w) in model.phi().iter().zip(&phi) {
        // φ and the gain rounded to f32 before the division: a few roundings.
        assert!(
            (f64::from(*g) - w / gain).abs() <= 1e-6 * (w / gain).abs() + 1e-12,
            "{g} vs {w}"
        );
    }
    assert_eq!(model.offset(), ridge_core::Offset::Intercept);
    assert_eq!(model.intercept(), 0.0);
    let r = &DEFAULT_CONFIG.records;
    assert_eq!((map.first(), map.step()), (r.map_first, r.map_step));
    for (k, &v) in map.knots().iter().enumerate() {
        let u = f64::from(r.map_first + k as u16 * r.map_step) / 10_000.0;
        let want = ((gain * u + c / a1) * 120.0).round();
        assert!(
            (f64::from(v) - want).abs() <= 1.0,
            "knot {k}: {v} vs {want}"
        );
    }
    // The same model: its predictions from the duty and the record's from the map's flow
    // agree to the map's rounding (half a count, 0.004 slm, through the dynamics' gain 1).
    let linear =
        ridge_core::ArxModel::new(&theta, &phi, st.d, ridge_core::Offset::Intercept, c).unwrap();
    let worst = largest_difference(&linear, &map, &model);
    assert!(worst < 0.02, "largest difference {worst} slm");
    let val_fit = json["validation"]["fit_free_run"].as_f64().unwrap();
    assert!(f32_close(fit, val_fit), "{fit} vs {val_fit}");
    assert!(stderr.contains("validation free-run"), "{stderr}");

    // The EEPROM image: the ihex crate reads it (checksums verified), one end-of-file
    // record, the record's bytes at the address the ATmega2560 image reads.
    let hex_text = fs::read_to_string(&hex).unwrap();
    let mut placed = vec![None; 4096];
    let mut eofs = 0;
    for rec in ihex::Reader::new(&hex_text) {
        match rec.unwrap() {
            ihex::Record::Data { offset, value } => {
                for (k, b) in value.into_iter().enumerate() {
                    let a = usize::from(offset) + k;
                    assert!(placed[a].is_none(), "address {a} twice");
                    placed[a] = Some(b);
                }
            }
            ihex::Record::EndOfFile => eofs += 1,
            other => panic!("unexpected record {other:?}"),
        }
    }
    assert_eq!(eofs, 1);
    // The image is the whole two-slot store: the firmware's slot choice finds the record in
    // it, the sequence number is the first one (0) and the other slot is erased.
    let base = usize::from(EEPROM_BASE);
    let store: [u8; STORE_LEN] = placed[base..base + STORE_LEN]
        .iter()
        .map(|b| b.expect("a store byte missing from the image"))
        .collect::<Vec<u8>>()
        .try_into()
        .unwrap();
    assert_eq!(placed.iter().flatten().count(), STORE_LEN, "extra bytes");
    let plan = slots::plan(&store);
    assert_eq!(slots::record(&store, &plan), Some(&record[..]));
    let used = usize::from(plan.load.expect("a slot is loaded")) * SLOT_LEN;
    assert_eq!(store[used + RECORD_LEN], 0);
    let other = SLOT_LEN - used;
    assert!(store[other..other + SLOT_LEN].iter().all(|&b| b == 0xFF));
    // The same through the hand-written reader.
    assert_eq!(&eeprom_after(&hex_text)[base..base + STORE_LEN], &store[..]);

    // The STM32F411 store: both sectors (2 × 128 KB from 0x0804_0000); the firmware's plan
    // loads the record from the first slot; beyond it, only its sequence number (0), its
    // complement and the commit mark "RP" + length; every other byte erased.
    let store = fs::read(&stm).unwrap();
    assert_eq!(store.len(), 2 * flash_store::SECTOR_LEN);
    let (s6, s7) = store.split_at(flash_store::SECTOR_LEN);
    let plan = flash_store::plan([s6, s7]);
    assert_eq!(flash_store::record([s6, s7], &plan), Some(&record[..]));
    assert_eq!(&store[..RECORD_LEN], &record[..]);
    assert_eq!(
        &store[RECORD_LEN..RECORD_LEN + 12],
        &[
            0,
            0,
            0,
            0,
            0xFF,
            0xFF,
            0xFF,
            0xFF,
            b'R',
            b'P',
            RECORD_LEN as u8,
            0
        ]
    );
    assert!(store[RECORD_LEN + 12..].iter().all(|&b| b == 0xFF));

    // The firmware's boot path loads it.
    let (loaded, loaded_map, loaded_fit) = boot(&record).unwrap();
    assert_eq!(loaded, model);
    assert_eq!(loaded_map, map);
    assert_eq!(loaded_fit.to_bits(), fit.to_bits());
}

/// The firmware's own boot accepts an EEPROM image of a known model (the plant above, with
/// its intercept `c = offset · (1 − Σθ)`), read back from an erased 4 KB EEPROM written by
/// the image: the plant's dynamics over its static gain (50 slm per unit duty) after its
/// steady flow, `50 u + 2` slm.
#[test]
fn firmware_boot_accepts_an_image_of_a_known_model() {
    let c = OFFSET * (1.0 - THETA.iter().sum::<f64>());
    let model = ridge_core_host::ArxModel::new(
        &THETA,
        &PHI,
        DELAY as u8,
        ridge_core_host::Offset::Intercept,
        c,
    )
    .unwrap();
    let record = ridge_id::export::encode_record(&model, None, 91.25, "validation").unwrap();
    let hex = ridge_id::export::eeprom_image(&record);
    let ee = eeprom_after(&hex);
    let base = usize::from(EEPROM_BASE);
    let store: [u8; STORE_LEN] = ee[base..base + STORE_LEN].try_into().unwrap();
    let plan = slots::plan(&store);
    let (loaded, map, fit) = boot(slots::record(&store, &plan).expect("a record")).unwrap();
    let st = loaded.structure();
    assert_eq!((st.p, st.q, st.d), (2, 2, 3));
    for (g, w) in loaded.theta().iter().zip(&THETA) {
        assert!(f32_close(*g, *w));
    }
    for (g, w) in loaded.phi().iter().zip(&PHI) {
        assert!((f64::from(*g) - w / 50.0).abs() < 1e-7, "{g} vs {w}/50");
    }
    assert_eq!(loaded.intercept(), 0.0);
    for (k, &v) in map.knots().iter().enumerate() {
        let u = f64::from(map.first() + k as u16 * map.step()) / 10_000.0;
        assert_eq!(
            f64::from(v),
            ((50.0 * u + OFFSET) * 120.0).round(),
            "knot {k}"
        );
    }
    assert_eq!(fit, 91.25);
}

/// Every entry of `d` (no output, no temporary file left behind) besides the inputs.
fn outputs(d: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".csv"))
        .collect();
    names.sort();
    names
}

#[test]
fn too_large_orders_are_refused_and_nothing_is_written() {
    let d = dir("orders");
    let est = d.join("est.csv");
    log(&est, 3000, 3, 1.0);
    for (structure, what) in [
        ("7,2,3", "(7, 2, 3)"),
        ("2,7,3", "(2, 7, 3)"),
        ("2,2,9", "(2, 2, 9)"),
    ] {
        let out = identify(&[
            "--input",
            s(&est),
            "--structure",
            structure,
            "--offset",
            "intercept",
            "--eeprom",
            s(&d.join("m.hex")),
            "--record",
            s(&d.join("m.bin")),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{structure}: {stderr}");
        assert!(
            stderr.contains(what) && stderr.contains("does not fit"),
            "{stderr}"
        );
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(outputs(&d).is_empty(), "{:?}", outputs(&d));
    }
}

#[test]
fn a_model_the_firmware_would_reject_at_boot_is_refused() {
    let d = dir("boot-checks");
    let est = d.join("est.csv");
    // The duty in percent: the flow rises by 0.5 slm per percent, as if by 0.5 slm per unit
    // duty: a map outside the firmware's 20..=2000.
    log(&est, 3000, 4, 100.0);
    let hex = d.join("m.hex");
    let out = identify(&[
        "--input",
        s(&est),
        "--offset",
        "intercept",
        "--eeprom",
        s(&hex),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("slm per unit duty") && stderr.contains("outside"),
        "{stderr}"
    );
    assert!(outputs(&d).is_empty());

    // Library level: a fit below the firmware's 70 %, an unstable model, a coefficient beyond
    // f32, a model whose flow falls with the duty; a given map goes with the model as it is.
    let m = |theta: &[f64], phi: &[f64]| {
        ridge_core_host::ArxModel::new(theta, phi, 0, ridge_core_host::Offset::None, 0.0).unwrap()
    };
    use ridge_id::export::{encode_record, ExportError};
    let good = m(&[0.9], &[10.0]);
    assert!(encode_record(&good, None, 70.0, "validation").is_ok());
    assert!(matches!(
        encode_record(&good, None, 69.9, "validation"),
        Err(ExportError::Fit { .. })
    ));
    assert!(matches!(
        encode_record(&good, None, f64::NAN, "validation"),
        Err(ExportError::NonFinite { .. })
    ));
    assert!(matches!(
        encode_record(&m(&[1.01], &[5.0]), None, 90.0, "validation"),
        Err(ExportError::Model(_))
    ));
    assert!(matches!(
        encode_record(&m(&[0.9], &[1e39]), None, 90.0, "validation"),
        Err(ExportError::NonFinite { .. })
    ));
    assert!(matches!(
        encode_record(&m(&[0.9], &[-10.0]), None, 90.0, "validation"),
        Err(ExportError::Model(_))
    ));
    let record = encode_record(&m(&[0.9], &[10.0]), None, 90.0, "validation").unwrap();
    let (_, map, _) = persist::decode(&record).unwrap();
    let dynamics = m(&[0.8], &[0.2]);
    let with_map = encode_record(&dynamics, Some(map), 90.0, "validation").unwrap();
    let (d, back, _) = persist::decode(&with_map).unwrap();
    assert_eq!(
        (d.theta(), d.phi(), back),
        (&[0.8f32][..], &[0.2f32][..], map)
    );
}

#[test]
fn an_unwritable_output_leaves_no_file() {
    let d = dir("io");
    let est = d.join("est.csv");
    log(&est, 3000, 5, 1.0);
    let out = identify(&[
        "--input",
        s(&est),
        "--offset",
        "intercept",
        "--record",
        s(&d.join("m.bin")),
        "--eeprom",
        s(&d.join("missing-dir").join("m.hex")),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("cannot write"), "{stderr}");
    assert!(outputs(&d).is_empty(), "{:?}", outputs(&d));
    // Without --validate the record's fit is the estimation record's, and stderr says so.
    let out = identify(&[
        "--input",
        s(&est),
        "--offset",
        "intercept",
        "--record",
        s(&d.join("m.bin")),
    ]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("estimation free-run"));
}

/// The addresses and the slot layout used by ridge-id are the boards' (the board modules are
/// compiled for their targets only, so their sources are read).
#[test]
fn addresses_match_the_board_sources() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware/src/board");
    let avr = fs::read_to_string(root.join("arduino_mega2560/eeprom.rs")).unwrap();
    assert!(avr.contains("pub const BASE: u16 = ridge_pump_firmware::slots::EEPROM_BASE;"));
    // The STM32F411 board keeps its record with `flash_store` at its `SECTORS`, which the
    // linker's memory map (memory.x) leaves out of the image: sector 6 starts at 256 KB.
    let stm = fs::read_to_string(root.join("blackpill_f411.rs")).unwrap();
    assert!(stm.contains("flash_store::plan(sectors)"));
    assert!(stm.contains("SECTORS.map(|(_, offset)|"));
    assert_eq!(
        ridge_id::export::STM32_STORE_ADDRESS,
        0x0800_0000 + 0x4_0000
    );
    let map = fs::read_to_string(root.join("../../../memory.x")).unwrap();
    assert!(map.contains("FLASH : ORIGIN = 0x08000000, LENGTH = 256K"));
}
