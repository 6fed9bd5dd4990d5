//! `identify --eeprom PATH.hex`, `--record PATH.bin`, `--stm32-store PATH.bin`: the identified
//! model as the firmware's persisted record, ready to be flashed into the pump.
//!
//! The record's bytes are the firmware's own [`persist::encode`] (105 bytes, layout in
//! `firmware/src/persist.rs`); nothing here re-implements that layout. The pump's model is a
//! static map from duty to flow and the dynamics from the map's flow (`firmware/src/selfid/`):
//! a model identified through a pump's map (`--phase` on a capture with a `# MAP` line) is
//! written with that map; any other, a model from the duty, with its own steady flow as the
//! map ([`through_steady_map`]: the same model, up to the map's 1/120 slm). The model of
//! `ridge-id` is `f64` with `p, q, d ≤ 12`; the record holds `p, q ∈ 1..=6`, `d ∈ 0..=6` and
//! `f32` numbers. A model that does not fit is refused ([`ExportError`]), and so is one the
//! firmware would reject when it loads the record at boot (the same checks, the firmware's
//! `selfid::check_stored` on the encoded record: it decodes, the dynamics pass
//! `check_model` with the firmware's default limits, the map's slope is plausible, the fit is
//! at least `Config::min_fit`), since it would be discarded and the pump would identify anew.
//!
//! What goes where:
//! - `--eeprom PATH.hex`: Intel HEX (I8HEX: 16 data bytes a line, an end-of-file record) of
//!   the ATmega2560's two-slot store ([`slots`], 212 bytes at EEPROM byte address
//!   [`slots::EEPROM_BASE`] = 0, where the image reads it: `board/arduino_mega2560/eeprom.rs`,
//!   `BASE` is that constant) holding the record alone ([`slots::store_with`]: as a first save
//!   leaves it, the other slot erased), for
//!   `avrdude -p m2560 -c wiring -P /dev/ttyACM0 -b 115200 -D -U eeprom:w:PATH.hex:i`.
//! - `--record PATH.bin`: the raw 105 record bytes.
//! - `--stm32-store PATH.bin`: what the STM32F411 image loads: its record store
//!   ([`flash_store`], a log of slots over flash sectors 6 and 7) holding the record alone
//!   ([`stm32_store`]: in the first slot with sequence number 0, as a first save leaves it,
//!   every other byte erased, so that no older record on the board outranks it), both
//!   sectors, 256 KB, for [`STM32_STORE_ADDRESS`] (0x0804_0000):
//!   `probe-rs download --chip STM32F411CEUx --binary-format bin --base-address 0x08040000
//!   PATH.bin` (a flasher erases the sectors it writes).
//!
//! The fit field (percent, `f32`) holds the free-run fit of the `--validate` record as
//! `ridge-id` reports it (`validation.fit_free_run`), the figure the firmware stores after
//! its own validation record (`flow-steps`); without `--validate`, the estimation record's
//! free-run fit (`estimation.fit_free_run`), which is optimistic: say `--validate`.
//!
//! Files are written only when the whole run succeeds (exit 0), each to a temporary file in
//! the same directory that is renamed into place once every output is complete: a refusal or
//! an I/O error leaves no output file and no partial one.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;
use ridge_core::control::ModelFault;
use ridge_pump_firmware::event::StoredReason;
use ridge_pump_firmware::flash_store::{self, FLASH_BASE, SECTORS, SECTOR_LEN};
use ridge_pump_firmware::persist::{self, PersistError, RECORD_LEN};
use ridge_pump_firmware::selfid::{check_stored, DEFAULT_CONFIG};
use ridge_pump_firmware::slots::{self, EEPROM_BASE, STORE_LEN};
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_SCALE};

use crate::outcome::Report;

/// Size of the ATmega2560's EEPROM in bytes: an image must end within it.
pub const AVR_EEPROM_SIZE: usize = 4096;

/// Address of the STM32F411's record store: flash sector 6, the first of its two sectors.
pub const STM32_STORE_ADDRESS: u32 = FLASH_BASE + SECTORS[0].1;

/// Bytes of the STM32F411's record store: its two sectors, one after the other.
pub const STM32_STORE_LEN: usize = 2 * SECTOR_LEN;

/// The options of `identify` that write the model for the pump.
#[derive(Debug, Clone, Default, Args)]
pub struct ExportArgs {
    /// Write the model as the firmware's persisted record in an Intel HEX EEPROM image for
    /// the ATmega2560 (record at EEPROM address 0), for avrdude -U eeprom:w:PATH.hex:i.
    /// Refused (exit 1, nothing written) if the model does not fit the record (p, q in
    /// 1..=6, d in 0..=6, f32 numbers) or the firmware's boot checks would reject it.
    #[arg(long, value_name = "PATH.hex")]
    pub eeprom: Option<PathBuf>,
    /// Write the raw 105-byte record (same model, same checks as --eeprom).
    #[arg(long, value_name = "PATH.bin")]
    pub record: Option<PathBuf>,
    /// Write the STM32F411's record store holding the record (flash sectors 6 and 7, 256 KB,
    /// the record in the first slot) for address 0x08040000, e.g. probe-rs download --chip
    /// STM32F411CEUx --binary-format bin --base-address 0x08040000 PATH.bin.
    #[arg(long, value_name = "PATH.bin")]
    pub stm32_store: Option<PathBuf>,
}

impl ExportArgs {
    /// Whether any output was asked for.
    pub fn any(&self) -> bool {
        self.eeprom.is_some() || self.record.is_some() || self.stm32_store.is_some()
    }
}

/// Why a model was not written.
#[derive(Debug, Clone, PartialEq)]
pub enum ExportError {
    /// An order or the delay is beyond the record's range.
    Structure {
        /// The model's structure `(p, q, d)`.
        pqd: (u8, u8, u8),
    },
    /// A number is not finite in `f32` (NaN, infinite, or beyond ±3.4e38).
    NonFinite {
        /// Which number (`theta_2`, `phi_0`, `c`, `fit`).
        what: String,
        /// Its `f64` value.
        value: f64,
    },
    /// The encoded record does not decode (cannot happen for a model that passed the checks
    /// above; kept so that a firmware change shows as an error, not a bad file).
    Decode(PersistError),
    /// The firmware's model check at boot would reject it (unstable, static gain outside the
    /// firmware's limits, non-finite).
    Model(String),
    /// The map's mean slope over the firmware's records' duty range is outside its limits:
    /// it would refuse the record at boot.
    MapSlope {
        /// The slope, slm per unit duty.
        slope: f32,
        /// The firmware's limits.
        min: f32,
        /// The firmware's limits.
        max: f32,
    },
    /// The model's steady flow at a knot of the firmware's map is beyond what the map holds
    /// (±273 slm, `i16` counts of 1/120 slm).
    Map {
        /// The knot's duty, percent.
        duty: f64,
        /// The steady flow there, slm.
        flow: f64,
    },
    /// The fit is below the firmware's minimum: it would reject the record at boot.
    Fit {
        /// The fit written, percent.
        fit: f32,
        /// The firmware's minimum, percent.
        min: f32,
        /// Which record the fit is from.
        source: &'static str,
    },
    /// Writing a file failed.
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        message: String,
    },
}

impl fmt::Display for ExportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ExportError::Structure { pqd: (p, q, d) } => write!(
                f,
                "the model (p, q, d) = ({p}, {q}, {d}) does not fit the firmware's record \
                 (p and q in 1..={}, d in 0..={}); identify with --p 1..=6 --q 1..=6 --d 0..=6",
                ridge_core::P_MAX,
                ridge_core::D_MAX
            ),
            ExportError::NonFinite { what, value } => write!(
                f,
                "{what} = {value:e} is not a finite f32, as the firmware's record stores it"
            ),
            ExportError::Decode(e) => write!(
                f,
                "the encoded record does not decode ({}): firmware and ridge-id disagree",
                e.name()
            ),
            ExportError::Model(why) => {
                write!(f, "the firmware would reject this model at boot: {why}")
            }
            ExportError::MapSlope { slope, min, max } => write!(
                f,
                "the flow rises by {slope:.3} slm per unit duty over the pump's records' duty \
                 range, outside the firmware's {min}..={max}: it would reject the record at boot \
                 (is u the duty as a fraction 0..1 and y the flow in slm, as in the pump's log?)"
            ),
            ExportError::Map { duty, flow } => write!(
                f,
                "the model's steady flow at {duty:.2} % duty is {flow:.1} slm, beyond the \
                 ±273 slm the firmware's map holds (is y the flow in slm?)"
            ),
            ExportError::Fit { fit, min, source } => write!(
                f,
                "the {source} free-run fit {fit:.1} % is below the firmware's minimum {min:.1} %: \
                 it would reject the record at boot"
            ),
            ExportError::Io { path, message } => {
                write!(f, "cannot write {}: {message}", path.display())
            }
        }
    }
}

impl std::error::Error for ExportError {}

/// The fit that goes into the record (percent) and which record it is from: the validation
/// record's free-run fit, or without one the estimation record's.
pub fn record_fit(report: &Report) -> (f64, &'static str) {
    match &report.validation {
        Some(v) => (v.fit_free_run, "validation"),
        None => (report.estimation.fit_free_run, "estimation"),
    }
}

/// `value` as a finite `f32`, or the error naming it.
fn to_f32(what: &str, value: f64) -> Result<f32, ExportError> {
    let v = value as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ExportError::NonFinite {
            what: what.to_string(),
            value,
        })
    }
}

/// The firmware's record of `model` with fit `fit` (percent; `source` names its record in
/// messages), after the checks the firmware applies when it loads a record at boot. With
/// `map`, the model is the dynamics from that map's flow (a pump's capture) and goes with it;
/// without, it is a model from the duty and goes through its own steady flow
/// ([`through_steady_map`]).
pub fn encode_record(
    model: &ridge_core_host::ArxModel<f64>,
    map: Option<ridge_core::InputMap>,
    fit: f64,
    source: &'static str,
) -> Result<[u8; RECORD_LEN], ExportError> {
    let s = model.structure();
    let fits = (1..=ridge_core::P_MAX).contains(&usize::from(s.p))
        && (1..=ridge_core::Q_MAX).contains(&usize::from(s.q))
        && usize::from(s.d) <= ridge_core::D_MAX;
    if !fits {
        return Err(ExportError::Structure {
            pqd: (s.p, s.q, s.d),
        });
    }
    let theta = model
        .theta()
        .iter()
        .enumerate()
        .map(|(i, &v)| to_f32(&format!("theta_{}", i + 1), v))
        .collect::<Result<Vec<_>, _>>()?;
    let phi = model
        .phi()
        .iter()
        .enumerate()
        .map(|(j, &v)| to_f32(&format!("phi_{j}"), v))
        .collect::<Result<Vec<_>, _>>()?;
    let offset = match model.offset() {
        ridge_core_host::Offset::None => ridge_core::Offset::None,
        ridge_core_host::Offset::Intercept => ridge_core::Offset::Intercept,
    };
    let c = match offset {
        ridge_core::Offset::Intercept => to_f32("c", model.intercept())?,
        ridge_core::Offset::None => 0.0,
    };
    let fit32 = to_f32("fit", fit)?;
    let m32 = ridge_core::ArxModel::new(&theta, &phi, s.d, offset, c).map_err(|e| match e {
        ridge_core::Error::NonFinite => ExportError::NonFinite {
            what: "a coefficient".into(),
            value: f64::NAN,
        },
        _ => ExportError::Structure {
            pqd: (s.p, s.q, s.d),
        },
    })?;
    let (m32, map) = match map {
        Some(map) => (m32, map),
        None => through_steady_map(&m32)?,
    };
    let bytes = persist::encode(&m32, &map, fit32);
    // The firmware's boot checks, on what it will read (`SelfIdentification::new`).
    // The firmware's boot checks, on what it will read (`SelfIdentification::new`).
    let limits = &DEFAULT_CONFIG.control.model;
    check_stored(&bytes, &DEFAULT_CONFIG).map_err(|e| match e {
        StoredReason::Record(e) => ExportError::Decode(e),
        StoredReason::Model(ModelFault::NonFinite) => {
            ExportError::Model("a coefficient is not finite".into())
        }
        StoredReason::Model(ModelFault::Unstable) => ExportError::Model(format!(
            "a pole of the model lies outside the radius {} (unstable or nearly)",
            limits.stable_radius
        )),
        StoredReason::Model(ModelFault::Gain { gain }) => ExportError::Model(format!(
            "the static gain of its dynamics from the map's flow, B(1)/A(1) = {gain}, is \
             outside the firmware's {}..={} (is y the flow in slm, as in the pump's log?)",
            limits.gain_min, limits.gain_max
        )),
        StoredReason::MapSlope { slope } => {
            let [min, max] = DEFAULT_CONFIG.control.map_slope;
            ExportError::MapSlope { slope, min, max }
        }
        StoredReason::Fit { fit, min } => ExportError::Fit { fit, min, source },
    })?;
    Ok(bytes)
}

/// The firmware's form of a model `u → y` (duty fraction to slm): a static map and the
/// dynamics after it (`firmware/src/selfid/`). A linear model is that with the map its own
/// steady state, `v = K u + c / A(1)` (slm, `K = B(1)/A(1)` its static gain), sampled at the
/// firmware's knots (`DEFAULT_CONFIG.records`: 16 knots from 15 % every 5.33 %, rounded to
/// the SFM3300's 1/120 slm), and the dynamics `A y = (B / K) v`: the same model (up to that
/// rounding), with a static gain of 1 and no intercept left.
///
/// Errors: a static gain that is not positive and finite (the firmware's check would refuse
/// the model: [`ExportError::Model`]), or a steady flow beyond ±273 slm at a knot
/// ([`ExportError::Map`]).
pub fn through_steady_map(
    model: &ridge_core::ArxModel<f32>,
) -> Result<(ridge_core::ArxModel<f32>, ridge_core::InputMap), ExportError> {
    let a1 = 1.0 - model.theta().iter().map(|&t| f64::from(t)).sum::<f64>();
    let b1: f64 = model.phi().iter().map(|&f| f64::from(f)).sum();
    let gain = b1 / a1;
    if !(gain.is_finite() && gain > 0.0) {
        return Err(ExportError::Model(format!(
            "its static gain B(1)/A(1) = {gain} is not positive (more duty must give more \
             flow; is u the duty as a fraction 0..1 and y the flow in slm, as in the pump's \
             log?)"
        )));
    }
    let steady = f64::from(model.intercept()) / a1;
    let r = &DEFAULT_CONFIG.records;
    let mut knots = [0i16; ridge_core::MAP_KNOTS];
    for (k, v) in knots.iter_mut().enumerate() {
        let duty = f64::from(r.map_first) + k as f64 * f64::from(r.map_step);
        let flow = gain * duty / f64::from(DUTY_FULL_SCALE) + steady;
        let counts = (flow * f64::from(FLOW_SCALE)).round();
        if !(f64::from(i16::MIN)..=f64::from(i16::MAX)).contains(&counts) {
            return Err(ExportError::Map {
                duty: duty / 100.0,
                flow,
            });
        }
        *v = counts as i16;
    }
    let map = ridge_core::InputMap::new(r.map_first, r.map_step, knots).map_err(|_| {
        ExportError::Model(format!(
            "its static gain {gain} slm per unit duty is too small for the map's 1/120 slm"
        ))
    })?;
    let phi: Vec<f32> = model
        .phi()
        .iter()
        .map(|&f| (f64::from(f) / gain) as f32)
        .collect();
    let dynamics = ridge_core::ArxModel::new(
        model.theta(),
        &phi,
        model.structure().d,
        model.offset(),
        0.0,
    )
    .map_err(|_| ExportError::NonFinite {
        what: "a coefficient divided by the static gain".into(),
        value: gain,
    })?;
    Ok((dynamics, map))
}

/// One Intel HEX record line (without its line end): `:LLAAAATT<data>CC`.
fn hex_line(kind: u8, address: u16, data: &[u8]) -> String {
    let mut line = String::with_capacity(11 + 2 * data.len());
    let [hi, lo] = address.to_be_bytes();
    // Data records are at most 16 bytes here, so the length fits a byte.
    let len = data.len() as u8;
    let mut sum = len.wrapping_add(hi).wrapping_add(lo).wrapping_add(kind);
    line.push_str(&format!(":{len:02X}{address:04X}{kind:02X}"));
    for &b in data {
        sum = sum.wrapping_add(b);
        line.push_str(&format!("{b:02X}"));
    }
    line.push_str(&format!("{:02X}", sum.wrapping_neg()));
    line
}

/// `data` at `address` as an Intel HEX file (I8HEX: data records of at most 16 bytes, then
/// the end-of-file record; lines end in `\n`). `None` if the data would end past 64 KiB.
pub fn intel_hex(data: &[u8], address: u16) -> Option<String> {
    if usize::from(address) + data.len() > 0x1_0000 {
        return None;
    }
    let mut out = String::new();
    for (i, chunk) in data.chunks(16).enumerate() {
        out.push_str(&hex_line(0x00, address + (i * 16) as u16, chunk));
        out.push('\n');
    }
    out.push_str(&hex_line(0x01, 0, &[]));
    out.push('\n');
    Some(out)
}

/// The STM32F411's record store holding `record` ([`STM32_STORE_LEN`] bytes from
/// [`STM32_STORE_ADDRESS`], see the [module docs](self)): the slot a first save into an
/// erased store writes, the rest erased.
pub fn stm32_store(record: &[u8; RECORD_LEN]) -> Vec<u8> {
    let mut store = vec![0xFF; STM32_STORE_LEN];
    let empty = vec![0xFF; SECTOR_LEN];
    let plan = flash_store::plan([&empty, &empty]);
    // A record of RECORD_LEN bytes always makes a slot.
    if let Some(bytes) = flash_store::slot_bytes(record, plan.seq) {
        let at = (plan.target.offset() - SECTORS[0].1) as usize;
        store[at..at + bytes.len()].copy_from_slice(&bytes);
    }
    store
}

/// The EEPROM image of `record`: the two-slot store holding it ([`slots::store_with`]) as
/// Intel HEX at [`EEPROM_BASE`].
pub fn eeprom_image(record: &[u8; RECORD_LEN]) -> String {
    const _: () = assert!(EEPROM_BASE as usize + STORE_LEN <= AVR_EEPROM_SIZE);
    // A record of RECORD_LEN bytes always fits a slot; within 64 KiB by the assertion above.
    slots::store_with(record)
        .and_then(|store| intel_hex(&store, EEPROM_BASE))
        .unwrap_or_default()
}

/// A temporary name next to `path` (same directory, so that the rename is atomic).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

fn io_error(path: &Path, e: std::io::Error) -> ExportError {
    ExportError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Writes every `(path, bytes)` all or nothing: each to a temporary file first (synced), then
/// all renamed into place. On an error the temporary files are removed and no output exists
/// that was not there before (a rename failing part-way can leave the earlier ones renamed;
/// renames within a directory do not fail short of a vanished directory).
pub fn write_all_or_nothing(files: &[(PathBuf, Vec<u8>)]) -> Result<(), ExportError> {
    let mut temps: Vec<PathBuf> = Vec::new();
    let cleanup = |temps: &[PathBuf]| {
        for t in temps {
            std::fs::remove_file(t).ok();
        }
    };
    for (path, bytes) in files {
        let tmp = temp_path(path);
        let written = std::fs::File::create(&tmp).and_then(|mut f| {
            f.write_all(bytes)?;
            f.sync_all()
        });
        if let Err(e) = written {
            std::fs::remove_file(&tmp).ok();
            cleanup(&temps);
            return Err(io_error(path, e));
        }
        temps.push(tmp);
    }
    for (i, (path, _)) in files.iter().enumerate() {
        if let Err(e) = std::fs::rename(&temps[i], path) {
            cleanup(&temps[i..]);
            return Err(io_error(path, e));
        }
    }
    Ok(())
}

/// Builds and writes the outputs `args` asks for, from `report`; returns one line per file
/// for stderr. Nothing is written on an error.
pub fn export(args: &ExportArgs, report: &Report) -> Result<Vec<String>, ExportError> {
    let (fit, source) = record_fit(report);
    // A model identified through a pump's map (`--phase` on a capture with a `# MAP` line)
    // goes with that map; any other through its own steady flow.
    let map = report
        .segment
        .as_ref()
        .and_then(|s| s.map.as_ref())
        .map(|m| m.map);
    let record = encode_record(&report.model, map, fit, source)?;
    let s = report.model.structure();
    let what = format!(
        "(p, q, d) = ({}, {}, {}), fit {:.1} % ({source} free-run)",
        s.p, s.q, s.d, fit
    );
    let mut files = Vec::new();
    let mut notes = Vec::new();
    if let Some(path) = &args.eeprom {
        files.push((path.clone(), eeprom_image(&record).into_bytes()));
        notes.push(format!(
            "wrote {}: Intel HEX, the {STORE_LEN}-byte two-slot store at EEPROM address {EEPROM_BASE:#06x} with the record of {RECORD_LEN} bytes, {what}",
            path.display()
        ));
    }
    if let Some(path) = &args.record {
        files.push((path.clone(), record.to_vec()));
        notes.push(format!(
            "wrote {}: raw record, {RECORD_LEN} bytes, {what}",
            path.display()
        ));
    }
    if let Some(path) = &args.stm32_store {
        files.push((path.clone(), stm32_store(&record)));
        notes.push(format!(
            "wrote {}: STM32F411 record store (flash sectors 6 and 7), {STM32_STORE_LEN} bytes for address {STM32_STORE_ADDRESS:#010x}, {what}",
            path.display()
        ));
    }
    write_all_or_nothing(&files)?;
    Ok(notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_lines_have_valid_checksums() {
        // The example of the Intel HEX specification's data record.
        assert_eq!(
            hex_line(
                0,
                0x0010,
                &[0x61, 0x64, 0x64, 0x72, 0x65, 0x73, 0x73, 0x20, 0x67, 0x61, 0x70]
            ),
            ":0B0010006164647265737320676170A7"
        );
        assert_eq!(hex_line(1, 0, &[]), ":00000001FF");
        assert_eq!(intel_hex(&[0; 2], 0xFFFF), None);
    }

    #[test]
    fn store_layout() {
        assert_eq!(STM32_STORE_ADDRESS, 0x0804_0000);
        assert_eq!(STM32_STORE_LEN, 256 * 1024);
        let store = stm32_store(&[7; RECORD_LEN]);
        assert_eq!(store.len(), STM32_STORE_LEN);
        assert!(store[..RECORD_LEN].iter().all(|&b| b == 7));
        let programmed = flash_store::PROGRAMMED_LEN;
        assert!(store[programmed..].iter().all(|&b| b == 0xFF));
    }
}
