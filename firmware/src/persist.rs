//! Fixed-size non-volatile record of an identified model (EEPROM on the ATmega2560, a flash
//! page on the STM32F411): the dynamics (ARX), its validation fit and the static map from duty
//! to flow its input goes through (`ridge_core::InputMap`, see [`crate::selfid`]).
//!
//! Layout (all multi-byte values little-endian), [`RECORD_LEN`] = 105 bytes:
//!
//! | Offset | Size | Field |
//! |---:|---:|---|
//! | 0 | 4 | magic [`MAGIC`] = `"RPMD"` |
//! | 4 | 1 | format version [`VERSION`] |
//! | 5 | 1 | `p` (1..=6) |
//! | 6 | 1 | `q` (1..=6) |
//! | 7 | 1 | `d` (0..=6), samples of 10 ms |
//! | 8 | 1 | offset flag: 0 = none, 1 = intercept |
//! | 9 | 24 | `θ_1 … θ_6` as `f32` (dimensionless); slots past `p` are `+0.0` |
//! | 33 | 24 | `φ_0 … φ_5` as `f32` (slm of measured flow per slm of the map's flow); slots past `q` are `+0.0` |
//! | 57 | 4 | `c` as `f32` (slm); `+0.0` without intercept |
//! | 61 | 4 | validation free-run fit as `f32` (percent) |
//! | 65 | 2 | the map's first knot, `u16` duty (1/10 000) |
//! | 67 | 2 | the map's knot spacing, `u16` duty (1/10 000, > 0) |
//! | 69 | 32 | the map's 16 knots, `i16` flow (SFM3300 counts, 1/120 slm), strictly increasing |
//! | 101 | 4 | CRC-32 (IEEE 802.3: reflected polynomial 0xEDB88320, init and final XOR 0xFFFFFFFF) of bytes 0..101 |
//!
//! [`decode`] accepts only what [`encode`] can produce: it rejects a wrong length, magic,
//! version or CRC, an invalid structure or offset flag, non-zero unused slots, non-finite
//! numbers and a map that is not one (knots not increasing, spacing 0 or past full range).
//! CRC-32 detects every single-bit and every burst error up to 32 bits. Version 1 (69 bytes,
//! a model from duty to flow without a map) is refused as [`PersistError::Version`].

use ridge_core::{ArxModel, InputMap, Offset, Real, MAP_KNOTS, P_MAX, Q_MAX};

/// Length of a record in bytes.
pub const RECORD_LEN: usize = 105;

/// The record's first four bytes ("Ridge-Pump Model Data").
pub const MAGIC: [u8; 4] = *b"RPMD";

/// Format version written by [`encode`] and the only one [`decode`] accepts.
pub const VERSION: u8 = 2;

/// Offset of the CRC in the record (the CRC covers bytes `0..CRC_AT`).
const CRC_AT: usize = RECORD_LEN - 4;
const THETA_AT: usize = 9;
const PHI_AT: usize = THETA_AT + 4 * P_MAX;
const C_AT: usize = PHI_AT + 4 * Q_MAX;
const FIT_AT: usize = C_AT + 4;
const MAP_AT: usize = FIT_AT + 4;
const KNOTS_AT: usize = MAP_AT + 4;
const _: () = assert!(KNOTS_AT + 2 * MAP_KNOTS == CRC_AT);

/// Why a stored record was not accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PersistError {
    /// Fewer than [`RECORD_LEN`] bytes.
    Length,
    /// The first four bytes are not [`MAGIC`] (e.g. erased memory, `0xFF…`).
    Magic,
    /// A format version other than [`VERSION`] (an older or newer firmware wrote it).
    Version,
    /// The CRC does not match: the record is corrupt.
    Crc,
    /// The structure is outside the supported range, the offset flag is not 0/1, or an
    /// unused coefficient slot is not zero.
    Structure,
    /// A coefficient or the fit is NaN or infinite.
    NonFinite,
    /// The map's knots are not strictly increasing, or its grid is invalid.
    Map,
}

impl PersistError {
    /// Short lower-case name used in report lines: `length`, `magic`, `version`, `crc`,
    /// `structure`, `nonfinite`, `map`.
    pub const fn name(self) -> &'static str {
        match self {
            PersistError::Length => "length",
            PersistError::Magic => "magic",
            PersistError::Version => "version",
            PersistError::Crc => "crc",
            PersistError::Structure => "structure",
            PersistError::NonFinite => "nonfinite",
            PersistError::Map => "map",
        }
    }
}

/// CRC-32 (IEEE 802.3, as zlib's `crc32`): reflected polynomial 0xEDB88320, initial value and
/// final XOR 0xFFFFFFFF. Bitwise, without a table (a table would cost 1 KB of AVR SRAM):
/// 20.6 k cycles per record on the ATmega2560, the same as the `crc` crate's `NoTable`
/// (figures in `docs/hand-written.md`).
///
/// ```
/// use ridge_pump_firmware::persist::crc32;
/// assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
/// ```
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in data {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// Encodes `model`, its validation `fit` (percent) and the `map` its input goes through into a
/// record (layout in the [module docs](self)).
pub fn encode(model: &ArxModel<f32>, map: &InputMap, fit: f32) -> [u8; RECORD_LEN] {
    let mut out = [0u8; RECORD_LEN];
    let s = model.structure();
    let mut w = Writer {
        buf: &mut out,
        at: 0,
    };
    w.bytes(&MAGIC);
    w.bytes(&[VERSION, s.p, s.q, s.d]);
    w.bytes(&[match model.offset() {
        Offset::None => 0,
        Offset::Intercept => 1,
    }]);
    let mut theta = [0.0f32; P_MAX];
    for (slot, v) in theta.iter_mut().zip(model.theta()) {
        *slot = *v;
    }
    let mut phi = [0.0f32; Q_MAX];
    for (slot, v) in phi.iter_mut().zip(model.phi()) {
        *slot = *v;
    }
    for v in theta.iter().chain(phi.iter()) {
        w.bytes(&v.to_le_bytes());
    }
    w.bytes(&model.intercept().to_le_bytes());
    w.bytes(&fit.to_le_bytes());
    w.bytes(&map.first().to_le_bytes());
    w.bytes(&map.step().to_le_bytes());
    for k in map.knots() {
        w.bytes(&k.to_le_bytes());
    }
    let crc = crc32(out.get(..CRC_AT).unwrap_or(&[]));
    if let Some(slot) = out.get_mut(CRC_AT..) {
        slot.copy_from_slice(&crc.to_le_bytes());
    }
    out
}

/// Decodes a record written by [`encode`]: the model, its map and its fit (percent).
///
/// Only the first [`RECORD_LEN`] bytes are read (a board may pass a whole EEPROM page).
/// Checks, in this order: length, magic, version, CRC, structure and layout, finiteness, the
/// map.
pub fn decode(bytes: &[u8]) -> Result<(ArxModel<f32>, InputMap, f32), PersistError> {
    let rec = intact(bytes)?;
    let [_, _, _, _, _, p, q, d, off, ..] = *rec;
    let offset = match off {
        0 => Offset::None,
        1 => Offset::Intercept,
        _ => return Err(PersistError::Structure),
    };
    let (pu, qu) = (usize::from(p), usize::from(q));
    if p == 0 || pu > P_MAX || q == 0 || qu > Q_MAX || usize::from(d) > ridge_core::D_MAX {
        return Err(PersistError::Structure);
    }
    let mut theta = [0.0f32; P_MAX];
    let mut phi = [0.0f32; Q_MAX];
    for (i, t) in theta.iter_mut().enumerate() {
        *t = read_f32(rec, THETA_AT + 4 * i);
    }
    for (j, f) in phi.iter_mut().enumerate() {
        *f = read_f32(rec, PHI_AT + 4 * j);
    }
    let c = read_f32(rec, C_AT);
    let fit = read_f32(rec, FIT_AT);
    // Unused slots (and c without an intercept) are exactly +0.0, as `encode` writes them.
    let unused_zero = theta.iter().skip(pu).all(|v| v.to_bits() == 0)
        && phi.iter().skip(qu).all(|v| v.to_bits() == 0)
        && (offset == Offset::Intercept || c.to_bits() == 0);
    if !unused_zero {
        return Err(PersistError::Structure);
    }
    if !Real::is_finite(fit) {
        return Err(PersistError::NonFinite);
    }
    let model = ArxModel::new(
        theta.get(..pu).unwrap_or(&[]),
        phi.get(..qu).unwrap_or(&[]),
        d,
        offset,
        c,
    )
    .map_err(|e| match e {
        ridge_core::Error::NonFinite => PersistError::NonFinite,
        _ => PersistError::Structure,
    })?;
    let half = |at: usize| (read_u32(rec, at) & 0xFFFF) as u16;
    let mut knots = [0i16; MAP_KNOTS];
    for (k, v) in knots.iter_mut().enumerate() {
        *v = half(KNOTS_AT + 2 * k) as i16;
    }
    let map =
        InputMap::new(half(MAP_AT), half(MAP_AT + 2), knots).map_err(|_| PersistError::Map)?;
    Ok((model, map, fit))
}

/// The first [`RECORD_LEN`] bytes of `bytes` if they are whole as [`encode`] wrote them:
/// length, magic, version and CRC (the first four checks of [`decode`], which a two-slot store
/// uses to pick the slot to load).
pub fn intact(bytes: &[u8]) -> Result<&[u8; RECORD_LEN], PersistError> {
    let rec: &[u8; RECORD_LEN] = bytes
        .get(..RECORD_LEN)
        .and_then(|b| b.try_into().ok())
        .ok_or(PersistError::Length)?;
    if rec.get(..4) != Some(&MAGIC[..]) {
        return Err(PersistError::Magic);
    }
    if rec.get(4) != Some(&VERSION) {
        return Err(PersistError::Version);
    }
    if crc32(rec.get(..CRC_AT).unwrap_or(&[])) != read_u32(rec, CRC_AT) {
        return Err(PersistError::Crc);
    }
    Ok(rec)
}

/// Sequential writer into the record buffer (never panics: writes past the end are dropped).
struct Writer<'a> {
    buf: &'a mut [u8; RECORD_LEN],
    at: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        let end = self.at.saturating_add(b.len());
        if let Some(slot) = self.buf.get_mut(self.at..end) {
            slot.copy_from_slice(b);
        }
        self.at = end;
    }
}

/// Little-endian `u32` at `at` (0 past the end, which the constant layout never reaches).
fn read_u32(rec: &[u8; RECORD_LEN], at: usize) -> u32 {
    rec.get(at..at.saturating_add(4))
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .map_or(0, u32::from_le_bytes)
}

/// Little-endian `f32` at `at`.
fn read_f32(rec: &[u8; RECORD_LEN], at: usize) -> f32 {
    f32::from_bits(read_u32(rec, at))
}
