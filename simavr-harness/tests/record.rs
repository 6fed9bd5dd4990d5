//! Issue 11, item 5, end to end: `ridge-id identify … --eeprom PATH.hex` writes the model it
//! identified from logs of the simulated blower as an Intel HEX EEPROM image; the real
//! ATmega2560 image, booted in simavr with that EEPROM and wired to the same blower, loads it
//! (no identification of its own), designs its flow controller from it and tracks its demo
//! program; the same image with the record damaged is refused and the pump identifies anew.
//!
//! The chain, as a user runs it:
//! 1. Two logs `t,u,y` (duty 0..1, flow in slm) of the bench's plant — `pump_sim`'s default
//!    blower, open outlet, the default SFM3300 error model — written by `pump_sim::record`
//!    and `Log::write_csv`: an estimation record (A-Multistep, noise seed [`EST_SEED`]) and a
//!    validation record (B-Multistep, seed [`VAL_SEED`]).
//! 2. `ridge-id identify --input EST --validate VAL <device options> --json --eeprom HEX`
//!    through ridge-id's own command-line path (clap's `Cli::try_parse_from`,
//!    `IdentifyArgs::options`, `ridge_id::run`, the JSON `main` prints,
//!    `ridge_id::export::export`), as `ridge_id::cli::main` does. The options are the
//!    device's (`ridge_id::device_check::DEVICE_OPTIONS`, the list docs/real-logs.md names and
//!    ridge-id's tests check against the firmware's settings) with two changes a plain log
//!    needs: no `--phase excite --operating-point log` (they pick a segment of a pump's
//!    capture, which a `t,u,y` log has not) and `--offset intercept` instead of `none` (the
//!    pump fits no constant because it subtracts its operating point first and keeps that as
//!    the intercept of its stored model; on absolute samples the blower's dead zone needs the
//!    intercept). `--initial zero` stays: a `pump_sim` record starts from rest (zero duty,
//!    zero flow), so zero history is exact.
//! 3. The `.hex` file is read by the small Intel HEX reader below (every line's checksum,
//!    data records at their addresses, extended address records, the end-of-file record
//!    required and last) — not by ridge-id's writer — and its bytes are programmed into
//!    simavr's EEPROM at those addresses before reset.
//!
//! Truths: the JSON report of the same run (structure, `theta`, `phi`, `offset` as the
//! intercept, the validation fit) through the export's documented form (`ridge_id::export`:
//! the map is the model's steady flow `K u + c / A(1)` at the firmware's knots, the dynamics
//! `θ`, `φ / K` with no intercept left, `K = Σφ / (1 − Σθ)`), the firmware's documented line
//! format (`LOADED`: six decimals for coefficients, one for the fit, rounded from the stored
//! `f32`; so a printed value lies within half a unit of its last digit plus a few `f32`
//! roundings of the JSON's `f64`; `MAP`: the knots' counts as slm with 3 decimals), the Intel
//! HEX format (checksum = two's complement of the byte sum), the record layout documented in
//! `firmware/src/persist.rs` (magic `RPMD`, `φ` at 33, CRC-32 of IEEE 802.3 over bytes 0..101,
//! computed here by its own code), the documented controller
//! settings (`ControlConfig`: duty 15..95 %, at most 5 % per tick, base duty 30 %), and the
//! plant for the tracking tolerance: the true flow of the simulated blower (not the firmware's
//! readings) must settle on each demo level within the sensor's own error — its noise σ =
//! √((3 %·flow)² + 0.02²) slm plus its 0.1 slm zero offset, which the loop cannot see —
//! because the controller has integral action: on a stable loop the mean error at a constant
//! setpoint goes to zero and what remains is what the sensor feeds back. The step overshoot
//! must stay within the 10 % target. The `TRACK` lines must equal the figures
//! recomputed from the frames the bench served (`run_trace`, as in `tests/simavr.rs`).
//!
//! Refusals: the same image with one byte of the record flipped (θ₁'s sign/exponent byte)
//! and the Intel HEX checksum of its line fixed up — a valid file whose record fails its CRC
//! — and the same image with the sign of every `φ` flipped and the record's CRC recomputed — a
//! whole record of a model whose flow falls with the duty. Both must be refused at boot
//! (`STORED-REJECTED crc`, `STORED-REJECTED gain=-1.000`: the dynamics' static gain, 1 after
//! the export, negated), followed by a new identification (`SCAN`), with no `LOADED`, no
//! `CTRL`, no run mode and every duty on the pin, to the end of the run, one the firmware
//! drives without a model: 0, the base duty or a duty of its scan's ramps.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Instant;

use clap::Parser;
use pump_sim::baseline::metrics::step_metrics;
use pump_sim::{PumpParams, Sfm3300Params, TS_S};
use ridge_id::cli::{Cli, Command};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::lines::MapLine;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::{DEMO_HOLD_TICKS, DEMO_STEPS};
use ridge_pump_firmware::units::DUTY_FULL_SCALE;
use serde_json::Value;
use simavr_harness::bench::{Bench, BenchConfig, RunEnd};
use simavr_harness::firmware;
use simavr_harness::session::PWM_MAX;
use simavr_harness::tracking::run_trace;

/// Sensor noise seed of the estimation log.
const EST_SEED: u64 = 101;
/// Sensor noise seed of the validation log.
const VAL_SEED: u64 = 202;
/// Sensor noise seed of the simavr bench (another draw of the same sensor).
const BENCH_SEED: u64 = 303;
/// Estimation and validation excitations: two different presets.
const EST_RECORD: Record = Record::AMultistep;
const VAL_RECORD: Record = Record::BMultistep;

/// Ticks of the demo's steps.
const fn demo_steps_ticks() -> i64 {
    let (mut sum, mut i) = (0, 0);
    while i < DEMO_STEPS.len() {
        sum += DEMO_STEPS[i].ticks as i64;
        i += 1;
    }
    sum
}
/// Run-mode ticks to cover: the demo's hold and its steps, and one `TRACK` window more.
const RUN_TICKS: i64 = DEMO_HOLD_TICKS as i64 + demo_steps_ticks() + 100;
/// Simulated time limit of the loading boot, s (settle 1.5 s, design, then [`RUN_TICKS`]).
const LOAD_LIMIT_S: f64 = 16.0;
/// Simulated time limit before the `SCAN` of a refused record, s (settle 1.5 s).
const REFUSE_LIMIT_S: f64 = 5.0;
/// Simulated time run past `SCAN` in a refused boot, s.
const AFTER_SCAN_S: f64 = 1.0;
/// The overshoot target, percent of the step (3.6..5.7 % measured here).
const OVERSHOOT_MAX: f64 = 10.0;

/// Offset of `φ₀` in the record, bytes (firmware/src/persist.rs, layout table).
const PHI_AT: usize = 33;
/// Offset of `θ₁` in the record, bytes.
const THETA_AT: usize = 9;
/// Offset of the CRC-32 (of bytes `0..CRC_AT`) in the record.
const CRC_AT: usize = 101;
/// Length of the record: the CRC is its last 4 bytes.
const RECORD_LEN: usize = CRC_AT + 4;
/// The record's magic.
const MAGIC: &[u8; 4] = b"RPMD";

fn elf() -> PathBuf {
    firmware::ensure_elf().unwrap_or_else(|e| panic!("cannot build the ATmega2560 firmware: {e}"))
}

// ---------------------------------------------------------------------------------------
// Intel HEX, by the format's definition: `:LLAAAATT<data>CC`, CC the two's complement of the
// sum of the other bytes; type 00 data, 01 end of file, 02 extended segment address (× 16),
// 04 extended linear address (<< 16).

/// One record line's bytes (length, address, type, data, checksum), checksum verified.
fn hex_bytes(line: &str) -> Result<Vec<u8>, String> {
    let hex = line
        .strip_prefix(':')
        .ok_or_else(|| format!("no ':' at the start of {line:?}"))?;
    if hex.len() % 2 != 0 || hex.len() < 10 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!("not a record: {line:?}"));
    }
    let bytes: Vec<u8> = (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex digits"))
        .collect();
    if bytes.len() != usize::from(bytes[0]) + 5 {
        return Err(format!("length byte disagrees with the line: {line:?}"));
    }
    if bytes.iter().fold(0u8, |a, &b| a.wrapping_add(b)) != 0 {
        return Err(format!("checksum: {line:?}"));
    }
    Ok(bytes)
}

/// The bytes of an Intel HEX file by address. Errors: a bad line or checksum, a record type
/// other than 00/01/02/04, an address given twice, no end-of-file record, or anything after it.
fn read_hex(text: &str) -> Result<BTreeMap<u32, u8>, String> {
    let mut out = BTreeMap::new();
    let mut base = 0u32;
    let mut eof = false;
    for line in text.lines().map(str::trim_end) {
        if eof {
            return Err(format!("after the end-of-file record: {line:?}"));
        }
        let b = hex_bytes(line)?;
        let addr = u32::from(u16::from_be_bytes([b[1], b[2]]));
        let data = &b[4..b.len() - 1];
        match b[3] {
            0x00 => {
                for (k, &v) in data.iter().enumerate() {
                    let a = base + ((addr + k as u32) & 0xFFFF);
                    if out.insert(a, v).is_some() {
                        return Err(format!("address {a:#x} given twice"));
                    }
                }
            }
            0x01 if data.is_empty() => eof = true,
            0x02 if data.len() == 2 => {
                base = u32::from(u16::from_be_bytes([data[0], data[1]])) << 4
            }
            0x04 if data.len() == 2 => {
                base = u32::from(u16::from_be_bytes([data[0], data[1]])) << 16
            }
            t => return Err(format!("record type {t:02X} not expected here: {line:?}")),
        }
    }
    if !eof {
        return Err("no end-of-file record".into());
    }
    Ok(out)
}

/// `text` with the data bytes at the given addresses replaced, each changed line's checksum
/// recomputed (I8HEX: data records without extended addresses, as an EEPROM image is).
fn patch_hex(text: &str, patch: &BTreeMap<u32, u8>) -> String {
    let mut done = 0;
    let mut out = String::new();
    for line in text.lines() {
        let mut b = hex_bytes(line).expect("a valid line");
        let n = b.len();
        assert!(
            matches!(b[3], 0x00 | 0x01),
            "extended addresses not patched"
        );
        if b[3] == 0x00 {
            let addr = u32::from(u16::from_be_bytes([b[1], b[2]]));
            for k in 0..n - 5 {
                if let Some(&v) = patch.get(&(addr + k as u32)) {
                    b[4 + k] = v;
                    done += 1;
                }
            }
            let sum = b[..n - 1].iter().fold(0u8, |a, &x| a.wrapping_add(x));
            b[n - 1] = sum.wrapping_neg();
        }
        out.push(':');
        for x in &b {
            out.push_str(&format!("{x:02X}"));
        }
        out.push('\n');
    }
    assert_eq!(
        done,
        patch.len(),
        "not every patched address is in the file"
    );
    out
}

/// The contiguous runs of `bytes` as (EEPROM offset, bytes), for `BenchConfig::eeprom`.
fn eeprom_runs(bytes: &BTreeMap<u32, u8>) -> Vec<(u16, Vec<u8>)> {
    let mut runs: Vec<(u16, Vec<u8>)> = Vec::new();
    for (&a, &v) in bytes {
        assert!(
            a < 4096,
            "address {a:#x} beyond the ATmega2560's 4 KB EEPROM"
        );
        match runs.last_mut() {
            Some((start, run)) if u32::from(*start) + run.len() as u32 == a => run.push(v),
            _ => runs.push((a as u16, vec![v])),
        }
    }
    runs
}

/// CRC-32 of IEEE 802.3 (reflected 0xEDB88320, init and final XOR 0xFFFFFFFF), by table.
fn crc32(data: &[u8]) -> u32 {
    let table: Vec<u32> = (0..256u32)
        .map(|n| {
            (0..8).fold(n, |c, _| {
                if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                }
            })
        })
        .collect();
    !data.iter().fold(!0u32, |c, &b| {
        table[((c ^ u32::from(b)) & 0xFF) as usize] ^ (c >> 8)
    })
}

// ---------------------------------------------------------------------------------------
// ridge-id

/// What one `ridge-id identify … --json --eeprom` run left: its JSON report (parsed from the
/// text `main` prints), the `.hex` file's text, the notes `main` prints on stderr, and the
/// wall time of the run.
struct Identified {
    json: Value,
    hex: String,
    notes: Vec<String>,
    wall_s: f64,
}

/// The device's identification options for a plain `t,u,y` log (see the module docs).
fn device_options() -> Vec<String> {
    let words: Vec<&str> = ridge_id::device_check::DEVICE_OPTIONS
        .split_whitespace()
        .collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < words.len() {
        let (flag, value) = (words[i], words.get(i + 1).copied().unwrap_or(""));
        assert!(
            flag.starts_with("--") && !value.starts_with("--"),
            "{words:?}"
        );
        match flag {
            "--phase" | "--operating-point" => {}
            "--offset" => out.extend(["--offset".to_string(), "intercept".to_string()]),
            _ => out.extend([flag.to_string(), value.to_string()]),
        }
        i += 2;
    }
    assert!(out.iter().any(|w| w == "--offset"), "{out:?}");
    out
}

fn identified() -> &'static Identified {
    static ONCE: OnceLock<Identified> = OnceLock::new();
    ONCE.get_or_init(|| {
        let t0 = Instant::now();
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("simavr_record");
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).expect("test directory");
        let (est, val, hex) = (
            dir.join("est.csv"),
            dir.join("val.csv"),
            dir.join("model.hex"),
        );
        let pump = PumpParams::default();
        pump_sim::record(EST_RECORD, &pump, EST_SEED)
            .write_csv(&est)
            .expect("estimation log");
        pump_sim::record(VAL_RECORD, &pump, VAL_SEED)
            .write_csv(&val)
            .expect("validation log");
        let path = |p: &Path| p.to_str().expect("UTF-8 path").to_string();
        let mut argv: Vec<String> = ["ridge-id", "identify", "--input"].map(String::from).into();
        argv.extend([path(&est), "--validate".into(), path(&val)]);
        argv.extend(device_options());
        argv.extend(["--json".into(), "--eeprom".into(), path(&hex)]);

        // What `ridge_id::cli::main` does with these arguments.
        let cli = Cli::try_parse_from(&argv).unwrap_or_else(|e| panic!("{argv:?}: {e}"));
        let Command::Identify(args) = cli.command else {
            panic!("not parsed as identify: {argv:?}");
        };
        assert!(args.json && !args.strict && args.export.any());
        let opts = args.options().unwrap_or_else(|e| panic!("{argv:?}: {e}"));
        let report = ridge_id::run(&opts).unwrap_or_else(|e| panic!("{argv:?}: {e}"));
        let text = format!("{}\n", report.to_json_string());
        let refused = report
            .control
            .as_ref()
            .is_some_and(|c| c.refusal().is_some());
        assert!(!refused, "no --control was asked for");
        let notes = ridge_id::export::export(&args.export, &report)
            .unwrap_or_else(|e| panic!("export refused: {e}\nreport: {text}"));
        let json: Value = serde_json::from_str(&text).expect("the JSON main prints");
        let hex = std::fs::read_to_string(&hex).expect("the .hex file written");
        Identified {
            json,
            hex,
            notes,
            wall_s: t0.elapsed().as_secs_f64(),
        }
    })
}

/// The JSON's structure, `theta`, `phi`, intercept and validation fit.
struct JsonModel {
    pqd: (i64, i64, i64),
    theta: Vec<f64>,
    phi: Vec<f64>,
    c: f64,
    fit: f64,
}

impl JsonModel {
    /// The static gain `K = Σφ / (1 − Σθ)`, slm per unit duty.
    fn gain(&self) -> f64 {
        self.phi.iter().sum::<f64>() / (1.0 - self.theta.iter().sum::<f64>())
    }

    /// The steady flow at the duty fraction `u`: `K u + c / (1 − Σθ)`, slm.
    fn steady(&self, u: f64) -> f64 {
        self.gain() * u + self.c / (1.0 - self.theta.iter().sum::<f64>())
    }
}

fn json_model(j: &Value) -> JsonModel {
    let int = |k: &str| {
        j["structure"][k]
            .as_i64()
            .unwrap_or_else(|| panic!("{k}: {j}"))
    };
    let list = |k: &str| -> Vec<f64> {
        j[k].as_array()
            .unwrap_or_else(|| panic!("{k}: {j}"))
            .iter()
            .map(|v| v.as_f64().expect("a number"))
            .collect()
    };
    JsonModel {
        pqd: (int("p"), int("q"), int("d")),
        theta: list("theta"),
        phi: list("phi"),
        c: j["offset"].as_f64().expect("offset"),
        fit: j["validation"]["fit_free_run"]
            .as_f64()
            .expect("validation fit"),
    }
}

/// How far a printed decimal `s` may lie from the `f64` `want` whose `f32` rounding was
/// printed: half a unit of its last digit, one `f32` rounding (2⁻²⁴ relative), and the
/// decimal parse's own rounding.
fn printed_tolerance(s: &str, want: f64) -> f64 {
    let digits = s.split_once('.').map_or(0, |(_, f)| f.len()) as i32;
    0.5 * 10f64.powi(-digits) + want.abs() * 2f64.powi(-24) + 1e-12 * want.abs().max(1.0)
}

// ---------------------------------------------------------------------------------------
// simavr

/// The bench: the default blower, open outlet, default sensor (what the logs were made of),
/// the EEPROM programmed with `image`.
fn bench(image: &BTreeMap<u32, u8>) -> Bench {
    let mut cfg = BenchConfig::new(elf());
    cfg.pump = PumpParams::default();
    cfg.lung = None;
    cfg.sensor = Sfm3300Params::default();
    cfg.seed = BENCH_SEED;
    cfg.eeprom = eeprom_runs(image);
    Bench::new(cfg).expect("bench")
}

fn transcript(b: &Bench) -> String {
    b.transcript(&["RES "])
}

fn first(b: &Bench, kw: &str) -> Option<usize> {
    b.find_lines(kw).next().map(|(i, _)| i)
}

/// A duty fraction from the pin and a duty in 1/10 000 are the same, to the PWM's resolution
/// (1/[`PWM_MAX`]: the board rounds to a timer count).
fn same_duty(fraction: f64, duty: u16) -> bool {
    (fraction - f64::from(duty) / f64::from(DUTY_FULL_SCALE)).abs() <= 0.5 / f64::from(PWM_MAX)
}

/// The duties the firmware drives without a model before its first record: off, the base
/// duty, and the duties of its scan's ramps (`Records`: from the base duty up to the top,
/// down to the bottom, back up, each leg moving the scan rate a tick and ending on its bound).
fn modelless_duties() -> Vec<u16> {
    let (cfg, r) = (&DEFAULT_CONFIG, &DEFAULT_CONFIG.records);
    let mut d = vec![0, cfg.base_duty];
    let mut u = cfg.base_duty;
    while u < r.scan_high {
        u = (u + r.scan_rate).min(r.scan_high);
        d.push(u);
    }
    while u > r.scan_low {
        u = u.saturating_sub(r.scan_rate).max(r.scan_low);
        d.push(u);
    }
    while u < cfg.base_duty {
        u = (u + r.scan_rate).min(cfg.base_duty);
        d.push(u);
    }
    d.sort_unstable();
    d.dedup();
    d
}

/// The image as ridge-id wrote it loads: `LOADED` = the JSON's model, no identification, a
/// controller (`CTRL`), run mode tracking the demo's steps on the true flow within the
/// sensor's error, duties within the documented limits.
#[test]
fn a_ridge_id_record_is_loaded_and_the_pump_tracks_on_it() {
    let id = identified();
    let m = json_model(&id.json);
    assert!(
        id.notes.len() == 1 && id.notes[0].contains("Intel HEX"),
        "{:?}",
        id.notes
    );
    let image = read_hex(&id.hex).unwrap_or_else(|e| panic!("{e}:\n{}", id.hex));

    let t0 = Instant::now();
    let mut b = bench(&image);
    let end = b.run_until(LOAD_LIMIT_S, |l| {
        let p = l.parsed();
        (l.text.starts_with("TRACK") && p.int("tick").is_some_and(|n| n >= RUN_TICKS))
            || l.text.starts_with("SCAN")
            || l.text.starts_with("FAULT")
    });
    let (sim_s, wall_s) = (b.time_s(), t0.elapsed().as_secs_f64());
    let log = transcript(&b);
    assert!(matches!(end, RunEnd::Line(_)), "{end:?}:\n{log}");
    assert!(
        b.halted().is_none() && b.machine.resets().is_empty(),
        "{log}"
    );

    // Loaded, not identified.
    for kw in [
        "STORED-REJECTED",
        "SCAN",
        "EXCITE",
        "ID",
        "VALIDATE",
        "ACCEPT",
        "REJECT",
        "FAULT",
        "ALARM",
        "DRIFT",
    ] {
        assert!(first(&b, kw).is_none(), "a {kw} line:\n{log}");
    }
    let loaded: Vec<usize> = b.find_lines("LOADED").map(|(i, _)| i).collect();
    assert_eq!(loaded.len(), 1, "LOADED lines:\n{log}");
    let line = b.lines[loaded[0]].parsed();
    let pqd = (
        line.int("p").expect("p="),
        line.int("q").expect("q="),
        line.int("d").expect("d="),
    );
    assert_eq!(pqd, m.pqd, "structure: LOADED vs JSON\n{log}");
    assert_eq!(line.int("off"), Some(1), "an intercept was asked for");
    // Each printed number against the JSON's; returns the difference.
    let check = |what: &str, printed: &str, want: f64| -> f64 {
        let got: f64 = printed
            .parse()
            .unwrap_or_else(|_| panic!("{what}={printed}"));
        let tol = printed_tolerance(printed, want);
        assert!(
            (got - want).abs() <= tol,
            "{what}: LOADED {printed}, JSON {want} (tolerance {tol:e})\n{log}"
        );
        (got - want).abs()
    };
    // The dynamics: θ as identified, φ over the static gain (a few f32 roundings more than
    // the printed digit), no intercept left.
    let phi: Vec<f64> = m.phi.iter().map(|f| f / m.gain()).collect();
    let mut coef_worst = 0.0f64;
    for (key, want) in [("theta", &m.theta), ("phi", &phi)] {
        let printed: Vec<&str> = line.get(key).expect(key).split(',').collect();
        assert_eq!(printed.len(), want.len(), "{key}: {printed:?} vs {want:?}");
        for (k, (s, w)) in printed.iter().zip(want.iter()).enumerate() {
            coef_worst = coef_worst.max(check(&format!("{key}[{k}]"), s, *w));
        }
    }
    let c_diff = check("c", line.get("c").expect("c="), 0.0);
    check("fit", line.get("fit").expect("fit="), m.fit);
    // The map, on the MAP line before LOADED: the model's steady flow at the firmware's knots,
    // to the 1/120 slm the map holds.
    let map_at = first(&b, "MAP").unwrap_or_else(|| panic!("no MAP line:\n{log}"));
    assert!(map_at < loaded[0], "{log}");
    let map = MapLine::parse(&b.lines[map_at].text)
        .unwrap_or_else(|e| panic!("{e}:\n{log}"))
        .map;
    let r = &DEFAULT_CONFIG.records;
    assert_eq!((map.first(), map.step()), (r.map_first, r.map_step));
    for (k, &v) in map.knots().iter().enumerate() {
        let u = f64::from(r.map_first + k as u16 * r.map_step) / f64::from(DUTY_FULL_SCALE);
        let want = (m.steady(u) * 120.0).round();
        assert!(
            (f64::from(v) - want).abs() <= 1.0,
            "knot {k}: {v} vs {want}\n{log}"
        );
    }

    // The controller, after LOADED.
    let ctrl = first(&b, "CTRL").unwrap_or_else(|| panic!("no CTRL line:\n{log}"));
    assert!(ctrl > loaded[0], "{log}");

    // Run mode as the bench saw it; the TRACK lines are the served frames' figures.
    let run = run_trace(&b).unwrap_or_else(|e| panic!("{e}:\n{log}"));
    assert!(
        run.track_lines >= 10 && run.track_mismatch <= 0.002 && run.misaligned == 0,
        "TRACK lines {}, recomputed difference {:.4} slm, misaligned {}\n{log}",
        run.track_lines,
        run.track_mismatch,
        run.misaligned
    );
    let tr = &run.trace;
    let p = run.preview as usize;
    assert!(
        tr.flow.len() >= (RUN_TICKS - 100) as usize,
        "{}",
        tr.flow.len()
    );
    let sensor = Sfm3300Params::default();
    let bound = |level: f64| {
        (sensor.noise_rel * level).hypot(sensor.noise_floor_slm) + sensor.zero_offset_slm.abs()
    };
    let (mut prev_start, mut start) = (0usize, DEMO_HOLD_TICKS as usize);
    let mut figures = Vec::new();
    for l in DEMO_STEPS {
        let end = start + usize::from(l.ticks);
        let (from, to) = (tr.setpoint[start - 1], tr.setpoint[start]);
        assert_eq!(to, f64::from(l.slm));
        let s = step_metrics(
            &tr.flow[prev_start..end - p],
            start - prev_start,
            p,
            from,
            to,
            TS_S,
        )
        .unwrap_or_else(|| panic!("step to {to} slm not scored"));
        assert!(
            s.ss_error.abs() <= bound(to),
            "step to {to} slm: steady-state error {:.3} slm > {:.3}\n{log}",
            s.ss_error,
            bound(to)
        );
        assert!(
            s.overshoot_pct <= OVERSHOOT_MAX,
            "step {from:.2} -> {to} slm: overshoot {:.1} % > {OVERSHOOT_MAX} %\n{log}",
            s.overshoot_pct
        );
        figures.push(format!(
            "{from:.1}->{to}: e_ss {:+.3} (bound {:.3}) overshoot {:.1} %",
            s.ss_error,
            bound(to),
            s.overshoot_pct
        ));
        prev_start = start;
        start = end;
    }
    let track_rms: Vec<f64> = b
        .find_lines("TRACK")
        .filter_map(|(_, l)| l.parsed().num("rms"))
        .collect();

    // Duties: never above the documented maximum; before run mode only off or the base duty;
    // in run mode within the controller's limits and rate limit.
    let c = &DEFAULT_CONFIG.control;
    let frac = |d: u16| f64::from(d) / f64::from(DUTY_FULL_SCALE);
    let q = 1.0 / f64::from(PWM_MAX);
    let max_duty = b.duty_log.iter().map(|d| d.fraction).fold(0.0, f64::max);
    assert!(max_duty <= frac(c.duty_max) + q / 2.0, "duty {max_duty}");
    for d in b.duty_log.iter().filter(|d| d.cycle < run.first_at) {
        assert!(
            same_duty(d.fraction, 0) || same_duty(d.fraction, DEFAULT_CONFIG.base_duty),
            "duty {} before run mode\n{log}",
            d.fraction
        );
    }
    // (The trace's duties are the pin's, to one PWM count.)
    for &d in &tr.duty {
        assert!(
            frac(d) >= frac(c.duty_min) - q && frac(d) <= frac(c.duty_max) + q,
            "run-mode duty {d} outside {}..={}",
            c.duty_min,
            c.duty_max
        );
    }
    for w in tr.duty.windows(2) {
        assert!(
            frac(w[1].abs_diff(w[0])) <= frac(c.duty_step) + q,
            "run-mode duty step {} -> {} > {}",
            w[0],
            w[1],
            c.duty_step
        );
    }

    println!(
        "ridge-id: structure {:?}, validation fit {:.2} %, logs + identification + export {:.1} ms wall\n\
         LOADED: largest |theta, phi - JSON| {coef_worst:.2e}, |c - JSON| {c_diff:.2e}\n\
         steps: {}\n\
         TRACK rms per window (slm): {track_rms:?}\n\
         largest duty {:.4}; simavr: {sim_s:.2} s simulated in {wall_s:.1} s wall",
        m.pqd,
        m.fit,
        id.wall_s * 1e3,
        figures.join("; "),
        max_duty,
    );
}

/// Boots with `image`, runs to the `SCAN` of a new identification and [`AFTER_SCAN_S`] past
/// it; checks the refusal (`STORED-REJECTED <reason…>` before `SCAN`, no `LOADED`, no
/// controller, no run mode, only duties driven without a model). Returns the reason's text.
fn refused(image: &BTreeMap<u32, u8>, what: &str) -> String {
    let t0 = Instant::now();
    let mut b = bench(image);
    let end = b.run_until(REFUSE_LIMIT_S, |l| {
        l.text.starts_with("SCAN") || l.text.starts_with("LOADED") || l.text.starts_with("FAULT")
    });
    if let RunEnd::Line(i) = end {
        if b.lines[i].text.starts_with("SCAN") {
            b.run_for(AFTER_SCAN_S);
        }
    }
    let log = transcript(&b);
    assert!(
        b.halted().is_none() && b.machine.resets().is_empty(),
        "{what}:\n{log}"
    );
    let rejected =
        first(&b, "STORED-REJECTED").unwrap_or_else(|| panic!("{what}: not refused:\n{log}"));
    let scan = first(&b, "SCAN").unwrap_or_else(|| panic!("{what}: no new identification:\n{log}"));
    assert!(rejected < scan, "{what}:\n{log}");
    for kw in ["LOADED", "CTRL", "TRACK", "FAULT"] {
        assert!(first(&b, kw).is_none(), "{what}: a {kw} line:\n{log}");
    }
    let allowed = modelless_duties();
    for d in &b.duty_log {
        assert!(
            allowed.iter().any(|&a| same_duty(d.fraction, a)),
            "{what}: duty {} at {:.3} s is none the firmware drives without a model\n{log}",
            d.fraction,
            d.cycle as f64 / 16e6
        );
    }
    println!(
        "{what}: `{}`, SCAN at {:.2} s; simavr {:.2} s simulated in {:.1} s wall",
        b.lines[rejected].text,
        b.lines[scan].cycle as f64 / 16e6,
        b.time_s(),
        t0.elapsed().as_secs_f64()
    );
    b.lines[rejected].text.clone()
}

/// Where the record starts in the image: the one place its magic occurs.
fn record_at(image: &BTreeMap<u32, u8>) -> u32 {
    let at: Vec<u32> = image
        .keys()
        .copied()
        .filter(|&a| (0..4u32).all(|k| image.get(&(a + k)) == Some(&MAGIC[k as usize])))
        .collect();
    assert_eq!(at.len(), 1, "the record's magic at {at:?}");
    at[0]
}

/// One flipped byte of the record (θ₁'s most significant byte, bit 6: the top bit of its
/// exponent, θ₁ scaled by 2^±128), its Intel HEX line's checksum fixed: a valid file, a record
/// that fails its CRC.
#[test]
fn a_record_damaged_in_the_hex_is_refused_and_the_pump_identifies_anew() {
    let id = identified();
    let image = read_hex(&id.hex).expect("ridge-id's image");
    let at = record_at(&image) + THETA_AT as u32 + 3;
    let patch = BTreeMap::from([(at, image[&at] ^ 0x40)]);
    let hex = patch_hex(&id.hex, &patch);
    let bad = read_hex(&hex).unwrap_or_else(|e| panic!("the patched file is invalid: {e}"));
    let changed: Vec<u32> = image
        .keys()
        .filter(|a| image[a] != bad[a])
        .copied()
        .collect();
    assert_eq!(changed, vec![at]);
    assert_eq!(bad.len(), image.len());
    // The reader checks: the same byte changed without the checksum fixed is refused.
    let unfixed: String = id
        .hex
        .lines()
        .zip(hex.lines())
        .map(|(old, new)| format!("{}{}\n", &new[..new.len() - 2], &old[old.len() - 2..]))
        .collect();
    assert!(
        read_hex(&unfixed).is_err_and(|e| e.starts_with("checksum")),
        "{unfixed}"
    );
    let reason = refused(&bad, "θ₁ byte flipped");
    assert_eq!(reason, "STORED-REJECTED crc");
}

/// A whole record (CRC recomputed) of the model with every `φ` negated: the flow would fall
/// with the map's. The firmware's model check refuses it for its static gain, the dynamics'
/// `Σφ / (1 − Σθ)` after the export (1), negated.
#[test]
fn a_whole_record_of_an_implausible_model_is_refused() {
    let id = identified();
    let m = json_model(&id.json);
    let image = read_hex(&id.hex).expect("ridge-id's image");
    let base = record_at(&image);
    let mut record: Vec<u8> = (0..RECORD_LEN).map(|k| image[&(base + k as u32)]).collect();
    assert_eq!(
        crc32(&record[..CRC_AT]).to_le_bytes(),
        record[CRC_AT..CRC_AT + 4],
        "the record's CRC as documented"
    );
    for j in 0..m.phi.len() {
        record[PHI_AT + 4 * j + 3] ^= 0x80;
    }
    let crc = crc32(&record[..CRC_AT]).to_le_bytes();
    record[CRC_AT..CRC_AT + 4].copy_from_slice(&crc);
    let patch: BTreeMap<u32, u8> = record
        .iter()
        .enumerate()
        .map(|(k, &v)| (base + k as u32, v))
        .filter(|(a, v)| image[a] != *v)
        .collect();
    let bad = read_hex(&patch_hex(&id.hex, &patch)).expect("the patched file");
    let reason = refused(&bad, "φ negated, CRC fixed");
    let gain: f64 = reason
        .strip_prefix("STORED-REJECTED gain=")
        .unwrap_or_else(|| panic!("not refused for its gain: {reason}"))
        .parse()
        .expect("a number");
    let want =
        -m.phi.iter().map(|f| f / m.gain()).sum::<f64>() / (1.0 - m.theta.iter().sum::<f64>());
    assert!((want + 1.0).abs() < 1e-12, "{want}");
    // Printed with 3 decimals from the firmware's f32 arithmetic (a few roundings of a sum
    // of at most 12 terms of this size).
    assert!(
        (gain - want).abs() <= 5e-4 + 1e-5 * want.abs(),
        "gain {gain}, JSON model {want}"
    );
}
