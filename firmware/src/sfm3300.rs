//! Driver for the Sensirion SFM3300 mass-flow sensor over I2C.
//!
//! Protocol facts are from the Sensirion *SFM3xxx I2C functional description* and the Sensirion
//! *SF05 sample code* (CRC routine), and the *SFM3300 datasheet* (flow encoding):
//!
//! - 7-bit address `0x40`; commands are 16 bits, sent MSB first.
//! - After *start continuous measurement* (`0x1000`) every plain read returns 3 bytes:
//!   flow word MSB, flow word LSB, CRC-8 of the two data bytes.
//! - The first read after the start may be invalid and is discarded by this driver.
//! - A read issued before a new value is ready is NACKed; the driver retries a bounded number of
//!   times ([`Sfm3300::set_read_attempts`]) before reporting [`Error::NotReady`].
//! - Flow in slm = (raw − 32768) / 120, range ±250 slm.
//!
//! The driver never uses floating point: [`Sfm3300::read_counts`] gives signed integer counts
//! (1 count = 1/120 slm) for exact integer accumulation, and [`flow_millislm`] converts a raw word
//! to rounded milli-slm for reports.
//!
//! # Example
//!
//! ```
//! # use embedded_hal_mock::eh1::i2c::{Mock, Transaction};
//! use ridge_pump_firmware::sfm3300::{flow_millislm, Sfm3300};
//!
//! # let expectations = [
//! #     Transaction::write(0x40, vec![0x10, 0x00]),
//! #     Transaction::read(0x40, vec![0xFF, 0xFF, 0xFF]), // first read: discarded
//! #     Transaction::read(0x40, vec![0x80, 0x78, 0x62]), // 32768 + 120 = 1 slm
//! # ];
//! # let i2c = Mock::new(&expectations);
//! let mut sensor = Sfm3300::new(i2c);
//! sensor.start_continuous()?;
//! // Every 10 ms:
//! let raw = sensor.read_raw()?;
//! assert_eq!(flow_millislm(raw), 1_000); // 1.000 slm
//! # let mut i2c = sensor.release();
//! # i2c.done();
//! # Ok::<(), ridge_pump_firmware::sfm3300::Error<embedded_hal::i2c::ErrorKind>>(())
//! ```

use embedded_hal::i2c::{ErrorKind, I2c};

use crate::units::{FLOW_RANGE_SLM, FLOW_SCALE};

/// 7-bit I2C address of the SFM3300 (fixed; SFM3xxx I2C functional description).
pub const ADDRESS: u8 = 0x40;

/// Default number of read attempts per measurement (first try included) before a NACKed read
/// is reported as [`Error::NotReady`].
pub const DEFAULT_READ_ATTEMPTS: u8 = 3;

/// CRC-8 generator polynomial x⁸ + x⁵ + x⁴ + 1 (SFM3xxx I2C functional description; SF05 sample
/// code `POLYNOMIAL = 0x131`). No reflection, no final XOR.
const CRC_POLYNOMIAL: u8 = 0x31;

/// CRC-8 initial value for the SFM3300: **0x00** (SF05 sample code). Newer Sensirion parts use
/// 0xFF (e.g. the `sensirion-i2c` crate hard-codes it), which does not check SFM3300 frames.
const CRC_INIT: u8 = 0x00;

/// All errors this driver can return.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The I2C bus reported an error other than a NACK of a measurement read.
    I2c(E),
    /// The CRC byte received did not match the CRC-8 of the two data bytes.
    Crc,
    /// Every read attempt was NACKed: the sensor had no new value ready (or is absent).
    NotReady,
}

/// Commands of the SFM3300 (SFM3xxx I2C functional description).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Command {
    /// Start continuous measurement; each following read returns a new flow word.
    StartContinuous,
    /// Soft reset: the sensor restarts as after power-up.
    SoftReset,
    /// Read the serial number, bits 31..16.
    SerialNumberHigh,
    /// Read the serial number, bits 15..0.
    SerialNumberLow,
}

impl Command {
    /// The 16-bit command code.
    const fn code(self) -> u16 {
        match self {
            Command::StartContinuous => 0x1000,
            Command::SoftReset => 0x2000,
            Command::SerialNumberHigh => 0x31AE,
            Command::SerialNumberLow => 0x31AF,
        }
    }

    /// The two bytes on the wire, MSB first.
    const fn bytes(self) -> [u8; 2] {
        self.code().to_be_bytes()
    }
}

/// CRC-8 of `data` as the SFM3300 computes it: polynomial 0x31, init 0x00, no reflection, no
/// final XOR.
///
/// Public so that simulators and host tools can build valid frames.
///
/// Bitwise, as Sensirion's sample code: 441 cycles per frame on the ATmega2560, the same as the
/// `crc` crate's table-less `NoTable`; its 256-entry table would save 370 cycles per 10 ms tick
/// for 256 B of SRAM (figures in `docs/hand-written.md`).
///
/// ```
/// use ridge_pump_firmware::sfm3300::crc8;
/// assert_eq!(crc8(&[0xBE, 0xEF]), 0x13);
/// assert_eq!(crc8(&[0x80, 0x00]), 0x23);
/// ```
pub fn crc8(data: &[u8]) -> u8 {
    let mut crc = CRC_INIT;
    for &byte in data {
        crc ^= byte;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ CRC_POLYNOMIAL
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Converts a raw flow word to signed counts around zero flow: `raw − 32768`.
///
/// 1 count = 1/120 slm. Every `u16` maps exactly onto the whole `i16` range (0 → −32768,
/// 65535 → 32767), so no information is lost.
///
/// ```
/// use ridge_pump_firmware::sfm3300::raw_to_counts;
/// assert_eq!(raw_to_counts(32_768), 0);
/// assert_eq!(raw_to_counts(32_768 + 120), 120); // 1 slm
/// assert_eq!(raw_to_counts(0), -32_768);
/// ```
pub const fn raw_to_counts(raw: u16) -> i16 {
    // Flipping the top bit of an offset-binary word gives its two's-complement value:
    // raw − 32768 for every raw in 0..=65535.
    i16::from_be_bytes((raw ^ 0x8000).to_be_bytes())
}

/// Converts signed flow counts (1 count = 1/120 slm) to milli-slm, rounded to the nearest
/// integer (halves away from zero; with a scale of 120 no exact halves occur).
///
/// ```
/// use ridge_pump_firmware::sfm3300::counts_to_millislm;
/// assert_eq!(counts_to_millislm(120), 1_000);
/// assert_eq!(counts_to_millislm(1), 8); // 8.33… milli-slm
/// assert_eq!(counts_to_millislm(-2), -17); // −16.67 milli-slm
/// ```
pub const fn counts_to_millislm(counts: i16) -> i32 {
    let scale = FLOW_SCALE as i32;
    // |counts| ≤ 32768, so 2·|counts|·1000 + 120 ≤ 65 536 120: no i32 overflow.
    let magnitude = (2 * (counts as i32).abs() * 1000 + scale) / (2 * scale);
    if counts < 0 {
        -magnitude
    } else {
        magnitude
    }
}

/// Converts a raw flow word to flow in milli-slm, rounded to the nearest integer, without
/// floating point: `round((raw − 32768) · 1000 / 120)`.
///
/// ```
/// use ridge_pump_firmware::sfm3300::flow_millislm;
/// assert_eq!(flow_millislm(32_768), 0);
/// assert_eq!(flow_millislm(32_768 + 120), 1_000); // 1 slm
/// assert_eq!(flow_millislm(32_768 - 30_000), -250_000); // −250 slm, end of range
/// ```
pub const fn flow_millislm(raw: u16) -> i32 {
    counts_to_millislm(raw_to_counts(raw))
}

/// Whether a raw flow word lies inside the calibrated range of ±250 slm
/// (raw 2768..=62768). Words outside are still converted but are not specified by Sensirion.
///
/// ```
/// use ridge_pump_firmware::sfm3300::in_range;
/// assert!(in_range(32_768 + 30_000));
/// assert!(!in_range(32_768 + 30_001));
/// ```
pub const fn in_range(raw: u16) -> bool {
    let limit = FLOW_RANGE_SLM as i32 * FLOW_SCALE as i32;
    let counts = raw_to_counts(raw) as i32;
    -limit <= counts && counts <= limit
}

/// Whether an I2C error is a NACK, which the SFM3300 uses to say "no new value yet".
fn is_nack<E: embedded_hal::i2c::Error>(error: &E) -> bool {
    matches!(error.kind(), ErrorKind::NoAcknowledge(_))
}

/// SFM3300 flow sensor on an I2C bus implementing [`embedded_hal::i2c::I2c`].
///
/// Owns the bus (or a shared-bus proxy); [`release`](Sfm3300::release) gives it back.
#[derive(Debug)]
pub struct Sfm3300<I2C> {
    i2c: I2C,
    read_attempts: u8,
    discard_next: bool,
}

impl<I2C: I2c> Sfm3300<I2C> {
    /// Creates a driver on `i2c`. Sends nothing; call
    /// [`start_continuous`](Sfm3300::start_continuous) before reading flow.
    ///
    /// Reads try [`DEFAULT_READ_ATTEMPTS`] times before reporting [`Error::NotReady`].
    pub fn new(i2c: I2C) -> Self {
        Sfm3300 {
            i2c,
            read_attempts: DEFAULT_READ_ATTEMPTS,
            discard_next: false,
        }
    }

    /// Sets how many times a NACKed read is tried in all (first try included) before
    /// [`Error::NotReady`] is returned. `0` is treated as `1`.
    ///
    /// The retries are immediate (no delay): each NACKed attempt costs about one address byte on
    /// the bus (≈ 23 µs at 400 kHz, ≈ 90 µs at 100 kHz). The sensor updates every 0.5 ms, so on
    /// a fast bus more attempts are needed to bridge a whole update period.
    pub fn set_read_attempts(&mut self, attempts: u8) {
        self.read_attempts = attempts.max(1);
    }

    /// The number of read attempts per measurement (see
    /// [`set_read_attempts`](Sfm3300::set_read_attempts)).
    pub fn read_attempts(&self) -> u8 {
        self.read_attempts
    }

    /// Sends the soft-reset command (0x2000): the sensor restarts as after power-up and leaves
    /// continuous-measurement mode.
    ///
    /// The driver does not wait: give the sensor its start-up time (datasheet) before the next
    /// command, then call [`start_continuous`](Sfm3300::start_continuous) again.
    pub fn soft_reset(&mut self) -> Result<(), Error<I2C::Error>> {
        self.discard_next = false;
        self.write_command(Command::SoftReset)
    }

    /// Sends *start continuous measurement* (0x1000) and arms the first-read discard.
    ///
    /// Sensirion notes that the first read after starting may be invalid. This method does not
    /// read; instead the **next** [`read_raw`](Sfm3300::read_raw) (or
    /// [`read_counts`](Sfm3300::read_counts)) first reads one frame and throws it away (its CRC
    /// is not checked), then reads and returns a second one. If that second read is NACKed on
    /// every attempt, the call returns [`Error::NotReady`] and the following call reads normally.
    pub fn start_continuous(&mut self) -> Result<(), Error<I2C::Error>> {
        self.write_command(Command::StartContinuous)?;
        self.discard_next = true;
        Ok(())
    }

    /// Reads one raw flow word (offset binary: 32768 = zero flow, 120 counts per slm) with its
    /// CRC checked.
    ///
    /// NACKed reads are retried up to [`read_attempts`](Sfm3300::read_attempts) times in all,
    /// then [`Error::NotReady`] is returned. Any other bus error is returned at once as
    /// [`Error::I2c`]; a CRC mismatch is [`Error::Crc`]. The sensor must be in continuous
    /// measurement mode ([`start_continuous`](Sfm3300::start_continuous)).
    pub fn read_raw(&mut self) -> Result<u16, Error<I2C::Error>> {
        if self.discard_next {
            // The first frame after the start may be invalid (SFM3xxx I2C functional
            // description): read it, ignore its content.
            self.read_frame()?;
            self.discard_next = false;
        }
        let frame = self.read_frame()?;
        check_frame(frame)
    }

    /// Reads one flow value as signed counts around zero flow (`raw − 32768`;
    /// 1 count = 1/120 slm), CRC checked. Errors as for [`read_raw`](Sfm3300::read_raw).
    ///
    /// These integers are what the identification statistics accumulate exactly.
    pub fn read_counts(&mut self) -> Result<i16, Error<I2C::Error>> {
        self.read_raw().map(raw_to_counts)
    }

    /// Reads the 32-bit serial number: command 0x31AE then one read for bits 31..16, command
    /// 0x31AF then one read for bits 15..0, each word CRC checked.
    ///
    /// This leaves continuous-measurement mode: call
    /// [`start_continuous`](Sfm3300::start_continuous) afterwards to measure again.
    pub fn serial_number(&mut self) -> Result<u32, Error<I2C::Error>> {
        self.discard_next = false;
        self.write_command(Command::SerialNumberHigh)?;
        let high = check_frame(self.read_frame()?)?;
        self.write_command(Command::SerialNumberLow)?;
        let low = check_frame(self.read_frame()?)?;
        Ok((u32::from(high) << 16) | u32::from(low))
    }

    /// Gives back the I2C bus.
    pub fn release(self) -> I2C {
        self.i2c
    }

    /// Writes a 16-bit command, MSB first.
    fn write_command(&mut self, command: Command) -> Result<(), Error<I2C::Error>> {
        self.i2c
            .write(ADDRESS, &command.bytes())
            .map_err(Error::I2c)
    }

    /// Reads one 3-byte frame, retrying NACKs up to `read_attempts` times in all.
    fn read_frame(&mut self) -> Result<[u8; 3], Error<I2C::Error>> {
        let mut frame = [0u8; 3];
        for _ in 0..self.read_attempts.max(1) {
            match self.i2c.read(ADDRESS, &mut frame) {
                Ok(()) => return Ok(frame),
                Err(e) if is_nack(&e) => {}
                Err(e) => return Err(Error::I2c(e)),
            }
        }
        Err(Error::NotReady)
    }
}

/// Checks the CRC of a `[MSB, LSB, CRC]` frame and returns the data word.
fn check_frame<E>(frame: [u8; 3]) -> Result<u16, Error<E>> {
    let [msb, lsb, crc] = frame;
    if crc8(&[msb, lsb]) == crc {
        Ok(u16::from_be_bytes([msb, lsb]))
    } else {
        Err(Error::Crc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_codes_are_msb_first() {
        assert_eq!(Command::StartContinuous.bytes(), [0x10, 0x00]);
        assert_eq!(Command::SoftReset.bytes(), [0x20, 0x00]);
        assert_eq!(Command::SerialNumberHigh.bytes(), [0x31, 0xAE]);
        assert_eq!(Command::SerialNumberLow.bytes(), [0x31, 0xAF]);
    }

    #[test]
    fn crc_vectors_from_spec() {
        assert_eq!(crc8(&[0xBE, 0xEF]), 0x13);
        assert_eq!(crc8(&[0x80, 0x00]), 0x23);
        assert_eq!(crc8(&[]), 0x00);
    }

    #[test]
    fn check_frame_accepts_good_and_rejects_bad_crc() {
        assert_eq!(check_frame::<()>([0xBE, 0xEF, 0x13]), Ok(0xBEEF));
        assert_eq!(check_frame::<()>([0xBE, 0xEF, 0x14]), Err(Error::Crc));
    }

    #[test]
    fn raw_to_counts_is_exact_over_the_whole_range() {
        for raw in 0..=u16::MAX {
            assert_eq!(i32::from(raw_to_counts(raw)), i32::from(raw) - 32_768);
        }
    }
}
