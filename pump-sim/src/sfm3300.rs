//! Sensirion SFM3300 flow-sensor model: true flow in slm → the raw 16-bit word and the 3-byte
//! I2C frame `[MSB, LSB, CRC]` the part sends. Conversion, frame and CRC follow Sensirion's
//! SFM3300 datasheet and SFM3xxx I2C functional description; the noise figures are the typical
//! ones the paper quotes for the SFM3300 (section 3: 3 % of the measured value, 0.1 slm
//! zero-point offset).
//!
//! - Conversion: `raw = round(flow · 120) + 32768`, clamped to `0..=65535`
//!   (`flow = (raw − 32768) / 120`, resolution 1/120 slm, range ±250 slm on the real part).
//! - Errors: a fixed zero-point offset (`zero_offset_slm`, 0.1 slm by default) and Gaussian
//!   noise with standard deviation `sqrt((noise_rel·|flow|)² + noise_floor_slm²)`
//!   (3 % of reading and a 0.02 slm floor by default), drawn from a seeded xoshiro256++ stream:
//!   the same seed gives the same words.
//! - CRC-8 of the frame: polynomial 0x31, init 0x00, no reflection, no final XOR. The bitwise
//!   implementation here is written independently of the firmware driver's on purpose.

use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use ridge_pump_firmware::units::{FLOW_OFFSET, FLOW_SCALE};

/// 7-bit I2C address.
pub const I2C_ADDRESS: u8 = 0x40;
/// Command: start continuous measurement.
pub const CMD_START_MEASUREMENT: u16 = 0x1000;
/// Command: soft reset.
pub const CMD_SOFT_RESET: u16 = 0x2000;
/// CRC-8 polynomial (x⁸ + x⁵ + x⁴ + 1).
pub const CRC_POLY: u8 = 0x31;
/// CRC-8 initial value for the SFM3300 (newer Sensirion parts use 0xFF).
pub const CRC_INIT: u8 = 0x00;

/// Ideal conversion of a flow (slm) to the raw word: `round(flow·120) + 32768`, clamped to
/// `0..=65535` (NaN → 32768, i.e. zero flow).
pub fn flow_to_raw(flow_slm: f64) -> u16 {
    if flow_slm.is_nan() {
        return FLOW_OFFSET;
    }
    let counts = (flow_slm * f64::from(FLOW_SCALE)).round() + f64::from(FLOW_OFFSET);
    // `as` saturates for floats; the clamp makes the range explicit.
    counts.clamp(0.0, f64::from(u16::MAX)) as u16
}

/// Raw word → flow in slm: `(raw − 32768) / 120`.
pub fn raw_to_flow(raw: u16) -> f64 {
    (f64::from(raw) - f64::from(FLOW_OFFSET)) / f64::from(FLOW_SCALE)
}

/// CRC-8 as the SFM3300 computes it: polynomial 0x31, init 0x00, MSB first, no final XOR.
pub fn crc8(data: &[u8]) -> u8 {
    let mut crc = CRC_INIT;
    for &byte in data {
        crc ^= byte;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ CRC_POLY
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// The 3-byte frame for a raw word: `[MSB, LSB, crc8([MSB, LSB])]`.
pub fn frame(raw: u16) -> [u8; 3] {
    let [msb, lsb] = raw.to_be_bytes();
    [msb, lsb, crc8(&[msb, lsb])]
}

/// Parses a frame: the raw word if the CRC matches, `None` otherwise.
pub fn parse_frame(frame: [u8; 3]) -> Option<u16> {
    let [msb, lsb, crc] = frame;
    (crc8(&[msb, lsb]) == crc).then(|| u16::from_be_bytes([msb, lsb]))
}

/// Error model of the sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct Sfm3300Params {
    /// Noise standard deviation relative to the reading (0.03 = 3 % of reading).
    pub noise_rel: f64,
    /// Noise standard deviation independent of the reading, slm.
    pub noise_floor_slm: f64,
    /// Constant zero-point offset added to every reading, slm.
    pub zero_offset_slm: f64,
}

impl Default for Sfm3300Params {
    /// 3 % of reading and +0.1 slm zero offset (the SFM3300's typical figures as the paper
    /// quotes them, section 3), and a 0.02 slm floor (this model's choice: some noise at zero
    /// flow).
    fn default() -> Self {
        Self {
            noise_rel: 0.03,
            noise_floor_slm: 0.02,
            zero_offset_slm: 0.1,
        }
    }
}

impl Sfm3300Params {
    /// An error-free sensor: only the 1/120 slm quantisation remains.
    pub fn ideal() -> Self {
        Self {
            noise_rel: 0.0,
            noise_floor_slm: 0.0,
            zero_offset_slm: 0.0,
        }
    }

    /// Noise standard deviation (slm) at a true flow of `flow_slm`.
    pub fn noise_std(&self, flow_slm: f64) -> f64 {
        (self.noise_rel * flow_slm).hypot(self.noise_floor_slm)
    }
}

/// A seeded SFM3300.
#[derive(Clone, Debug)]
pub struct Sfm3300 {
    params: Sfm3300Params,
    rng: Xoshiro256PlusPlus,
}

impl Sfm3300 {
    /// A sensor with error model `params` and noise stream `seed`.
    pub fn new(params: Sfm3300Params, seed: u64) -> Self {
        Self {
            params,
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
        }
    }

    /// The error model.
    pub fn params(&self) -> &Sfm3300Params {
        &self.params
    }

    /// One measurement of the true flow `flow_slm` as the raw word (offset, noise, quantised,
    /// clamped). Exactly one normal draw per call, whatever the parameters, so the noise
    /// stream stays aligned with the sample index.
    pub fn measure_raw(&mut self, flow_slm: f64) -> u16 {
        let z: f64 = self.rng.sample(StandardNormal);
        let reading = flow_slm + self.params.zero_offset_slm + z * self.params.noise_std(flow_slm);
        flow_to_raw(reading)
    }

    /// One measurement as the I2C frame `[MSB, LSB, CRC]`.
    pub fn measure_frame(&mut self, flow_slm: f64) -> [u8; 3] {
        frame(self.measure_raw(flow_slm))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_datasheet_vectors() {
        assert_eq!(crc8(&[0xBE, 0xEF]), 0x13);
        assert_eq!(crc8(&[0x80, 0x00]), 0x23);
        assert_eq!(crc8(&[]), 0x00);
        assert_eq!(frame(0xBEEF), [0xBE, 0xEF, 0x13]);
        assert_eq!(frame(0x8000), [0x80, 0x00, 0x23]);
    }

    #[test]
    fn crc_detects_every_single_bit_error() {
        for raw in [0u16, 0x8000, 0xBEEF, 0xFFFF, 12_345] {
            let f = frame(raw);
            assert_eq!(parse_frame(f), Some(raw));
            for bit in 0..24 {
                let mut g = f;
                g[bit / 8] ^= 1 << (bit % 8);
                assert_eq!(parse_frame(g), None, "raw {raw:#06x} bit {bit}");
            }
        }
    }

    #[test]
    fn conversion_round_trips_and_clamps() {
        assert_eq!(flow_to_raw(0.0), 32_768);
        assert_eq!(flow_to_raw(1.0), 32_888);
        assert_eq!(flow_to_raw(-1.0), 32_648);
        assert_eq!(flow_to_raw(1.0 / 240.0 + 1e-9), 32_769);
        assert_eq!(flow_to_raw(1e6), u16::MAX);
        assert_eq!(flow_to_raw(-1e6), 0);
        assert_eq!(flow_to_raw(f64::NAN), 32_768);
        for raw in [0u16, 1, 32_767, 32_768, 40_000, u16::MAX] {
            assert_eq!(flow_to_raw(raw_to_flow(raw)), raw);
        }
        assert!((raw_to_flow(32_768 + 120 * 150) - 150.0).abs() < 1e-12);
    }

    #[test]
    fn ideal_sensor_only_quantises() {
        let mut s = Sfm3300::new(Sfm3300Params::ideal(), 1);
        for q in [0.0, 0.004, 12.3456, 99.99, 150.0] {
            let raw = s.measure_raw(q);
            assert!((raw_to_flow(raw) - q).abs() <= 0.5 / f64::from(FLOW_SCALE) + 1e-12);
        }
    }

    #[test]
    fn zero_flow_reads_the_offset() {
        let mut s = Sfm3300::new(Sfm3300Params::default(), 7);
        let n = 5_000;
        let mean: f64 = (0..n).map(|_| raw_to_flow(s.measure_raw(0.0))).sum::<f64>() / n as f64;
        assert!((mean - 0.1).abs() < 0.005, "mean {mean}");
    }
}
