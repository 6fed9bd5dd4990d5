//! Number formatting for machine-readable report lines, with [`ufmt`] and without `core::fmt`.
//!
//! `core::fmt` float formatting is large and slow on AVR, and `ufmt` has no float support. The
//! wrappers here print fixed-point decimals using integer arithmetic only. (Measured on the
//! ATmega2560, `docs/hand-written.md`: `core::fmt`'s `{:.4}` adds 33 KB of flash; the
//! `ufmt_float` crate is 3.7 KB smaller than [`Fixed`] but prints −1.9472 as `-1.0000` and
//! −0.5 as `0.0000`, and truncates.)
//!
//! - [`Fixed`]: an `f32` with a chosen number of fractional digits, e.g. `-1.9472`. The exact
//!   binary value of the float is scaled and rounded (halves away from zero) with integer math
//!   on its bits; no floating-point operation is executed.
//! - [`Milli`]: an integer count of thousandths, e.g. milli-slm `12345` → `12.345`.
//! - [`Decimal`]: any `i32` with an implied number of decimals, e.g. duty units (1/100 %) with 2
//!   decimals → percent.
//! - [`Int`]: an unsigned integer (counts, orders).
//!
//! Output format (stable, for host-side parsers; `lines::number` reads it): an optional `-`,
//! the integer part without leading zeros (at least one digit), then `.` and the fractional
//! digits when there are any. No `+`, no exponent, no negative zero (a value that rounds to
//! zero prints unsigned). Special values of [`Fixed`] print as `nan`, `inf`, `-inf` and `ovf`
//! (see there).
//!
//! All arithmetic is 32-bit at most where it divides: a printed number, without its point, is
//! below 2³² ([`FIXED_LIMIT`]). A [`Fixed`] that would need more prints with fewer fractional
//! digits (as many as fit). On the ATmega2560 this keeps 64-bit division (2.8 KB of flash)
//! out of the image.
//!
//! # Example
//!
//! ```
//! use ridge_pump_firmware::numfmt::{Fixed, Milli};
//! # let mut line = heapless::String::<64>::new();
//! // `line` is any `ufmt::uWrite`, e.g. a UART writer or a `heapless::String`.
//! ufmt::uwrite!(line, "y,{},{}", Milli(-273_067), Fixed::new(-1.9472, 4)).ok();
//! assert_eq!(line.as_str(), "y,-273.067,-1.9472");
//! ```

use ufmt::{uDisplay, uWrite, Formatter};

/// Largest number of fractional digits [`Fixed`] and [`Decimal`] print; larger requests are
/// reduced to this. (An `f32` carries about 7 significant decimal digits.)
pub const MAX_DIGITS: u8 = 9;

/// Magnitude limit of a printed number without its point: `|x|·10^digits`, rounded, stays
/// below 2³² (4 294 967 296). A [`Fixed`] above it with `digits` prints with the most
/// fractional digits below it; one above it with no fractional digit prints as `ovf`.
pub const FIXED_LIMIT: u64 = 1 << 32;

/// An `f32` printed as a fixed-point decimal with `digits` fractional digits.
///
/// - Rounding is to nearest, halves away from zero, applied to the **exact** binary value of
///   the float (so `1.005_f32`, which is 1.00499999523…, prints `1.00` with 2 digits).
/// - NaN prints `nan`; infinities print `inf` / `-inf`.
/// - A finite value with rounded `|x|·10^digits` ≥ 2³² ([`FIXED_LIMIT`]) prints with the
///   largest number of fractional digits below that limit (`4294.96729` for 4294.967296 with
///   6 digits); at or above 2³² with 0 digits it prints `ovf`.
/// - `digits` above [`MAX_DIGITS`] is reduced to [`MAX_DIGITS`].
///
/// ```
/// use ridge_pump_firmware::numfmt::Fixed;
/// # fn show(x: Fixed) -> heapless::String<32> {
/// #     let mut s = heapless::String::new();
/// #     ufmt::uwrite!(s, "{}", x).ok();
/// #     s
/// # }
/// assert_eq!(show(Fixed::new(-1.9472, 4)), "-1.9472");
/// assert_eq!(show(Fixed::new(0.125, 2)), "0.13");
/// assert_eq!(show(Fixed::new(2.5, 0)), "3");
/// assert_eq!(show(Fixed::new(f32::NAN, 3)), "nan");
/// assert_eq!(show(Fixed::new(1e30, 0)), "ovf");
/// assert_eq!(show(Fixed::new(12_345.5, 6)), "12345.50000");
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fixed {
    value: f32,
    digits: u8,
}

impl Fixed {
    /// Wraps `value` for printing with `digits` fractional digits (at most [`MAX_DIGITS`]).
    pub const fn new(value: f32, digits: u8) -> Self {
        Fixed {
            value,
            digits: if digits > MAX_DIGITS {
                MAX_DIGITS
            } else {
                digits
            },
        }
    }

    /// The wrapped value.
    pub const fn value(&self) -> f32 {
        self.value
    }

    /// The number of fractional digits that will be printed.
    pub const fn digits(&self) -> u8 {
        self.digits
    }

    /// The printed number as an integer and its fractional digits: `round(value · 10^d)`,
    /// halves away from zero, with `d` the requested digits or fewer (see [`FIXED_LIMIT`]).
    ///
    /// `None` for NaN, infinities, and magnitudes at or above [`FIXED_LIMIT`] with 0 digits.
    ///
    /// ```
    /// use ridge_pump_firmware::numfmt::Fixed;
    /// assert_eq!(Fixed::new(-1.9472, 4).scaled(), Some((-19_472, 4)));
    /// assert_eq!(Fixed::new(f32::INFINITY, 0).scaled(), None);
    /// ```
    pub fn scaled(&self) -> Option<(i64, u8)> {
        match fit(self.value, self.digits) {
            (
                Scaled::Finite {
                    negative,
                    magnitude,
                },
                d,
            ) => {
                let magnitude = i64::from(magnitude);
                Some((if negative { -magnitude } else { magnitude }, d))
            }
            _ => None,
        }
    }
}

impl uDisplay for Fixed {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        match fit(self.value, self.digits) {
            (
                Scaled::Finite {
                    negative,
                    magnitude,
                },
                d,
            ) => write_decimal(f, negative, magnitude, d),
            (Scaled::Nan, _) => f.write_str("nan"),
            (Scaled::Infinite { negative: false }, _) => f.write_str("inf"),
            (Scaled::Infinite { negative: true }, _) => f.write_str("-inf"),
            (Scaled::Overflow, _) => f.write_str("ovf"),
        }
    }
}

/// Thousandths printed as a decimal with 3 fractional digits: `Milli(12_345)` → `12.345`,
/// `Milli(-5)` → `-0.005`. Used for milli-slm flow and other milli-unit quantities.
///
/// ```
/// use ridge_pump_firmware::numfmt::Milli;
/// # let mut s = heapless::String::<16>::new();
/// ufmt::uwrite!(s, "{}", Milli(-273_067)).ok();
/// assert_eq!(s.as_str(), "-273.067");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Milli(pub i32);

impl uDisplay for Milli {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        write_decimal(f, self.0 < 0, self.0.unsigned_abs(), 3)
    }
}

/// An integer with an implied decimal point: prints `value / 10^digits` exactly, e.g.
/// `Decimal::new(1_234, 2)` → `12.34` (pump duty units of 0.01 % as percent).
///
/// `digits` above [`MAX_DIGITS`] is reduced to [`MAX_DIGITS`].
///
/// ```
/// use ridge_pump_firmware::numfmt::Decimal;
/// # let mut s = heapless::String::<16>::new();
/// ufmt::uwrite!(s, "{}", Decimal::new(-7, 4)).ok();
/// assert_eq!(s.as_str(), "-0.0007");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decimal {
    value: i32,
    digits: u8,
}

impl Decimal {
    /// Wraps `value` (in units of 10^−digits) for printing.
    pub const fn new(value: i32, digits: u8) -> Self {
        Decimal {
            value,
            digits: if digits > MAX_DIGITS {
                MAX_DIGITS
            } else {
                digits
            },
        }
    }
}

impl uDisplay for Decimal {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        write_decimal(f, self.value < 0, self.value.unsigned_abs(), self.digits)
    }
}

/// An unsigned integer (a count, an order, seconds) printed in decimal: `Int(1_234)` →
/// `1234`. Every integer of the report lines goes through this (the same digit loop as
/// [`Decimal`]) rather than `ufmt`'s own integer formatting, which would add 216 B of
/// ATmega2560 flash beside it and divide once per digit.
///
/// ```
/// use ridge_pump_firmware::numfmt::Int;
/// # let mut s = heapless::String::<16>::new();
/// ufmt::uwrite!(s, "n={} t={}", Int::from(7u8), Int(4_294_967_295)).ok();
/// assert_eq!(s.as_str(), "n=7 t=4294967295");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Int(pub u32);

impl From<u8> for Int {
    fn from(n: u8) -> Self {
        Int(n.into())
    }
}

impl From<u16> for Int {
    fn from(n: u16) -> Self {
        Int(n.into())
    }
}

impl From<u32> for Int {
    fn from(n: u32) -> Self {
        Int(n)
    }
}

impl uDisplay for Int {
    fn fmt<W>(&self, f: &mut Formatter<'_, W>) -> Result<(), W::Error>
    where
        W: uWrite + ?Sized,
    {
        write_decimal(f, false, self.0, 0)
    }
}

/// An `f32` scaled by a power of ten and rounded, or why it cannot be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scaled {
    Nan,
    Infinite { negative: bool },
    Overflow,
    Finite { negative: bool, magnitude: u32 },
}

/// [`scale_f32`] with `digits`, or with fewer until the magnitude is below 2³²; returns the
/// digits used.
fn fit(value: f32, digits: u8) -> (Scaled, u8) {
    let mut d = digits.min(MAX_DIGITS);
    loop {
        let s = scale_f32(value, d);
        if s != Scaled::Overflow || d == 0 {
            return (s, d);
        }
        d -= 1;
    }
}

/// `10^digits` for `digits ≤ MAX_DIGITS` (larger values are treated as `MAX_DIGITS`).
fn pow10(digits: u8) -> u32 {
    // A plain loop: `u32::pow` costs 200 bytes of ATmega2560 flash.
    let mut p = 1u32;
    for _ in 0..digits.min(MAX_DIGITS) {
        p *= 10;
    }
    p
}

/// Exact `round(|value| · 10^digits)`, halves away from zero, from the bits of `value`.
///
/// A finite f32 is `m · 2^e` with `m < 2^24`; `m · 10^digits < 2^24 · 10^9 < 2^54` fits a `u64`,
/// and the power of two is a shift whose dropped bits decide the rounding.
fn scale_f32(value: f32, digits: u8) -> Scaled {
    let bits = value.to_bits();
    let negative = bits >> 31 != 0;
    let biased_exponent = (bits >> 23) & 0xFF;
    let fraction = bits & 0x007F_FFFF;
    if biased_exponent == 0xFF {
        return if fraction == 0 {
            Scaled::Infinite { negative }
        } else {
            Scaled::Nan
        };
    }
    // value = mantissa · 2^exponent (IEEE 754 binary32: bias 127, 23 fraction bits).
    let (mantissa, exponent) = if biased_exponent == 0 {
        (fraction, -149_i32)
    } else {
        (fraction | 0x0080_0000, biased_exponent as i32 - 150)
    };
    let product = u64::from(mantissa) * u64::from(pow10(digits));
    let magnitude = if exponent >= 0 {
        // Only results below 2^32 are kept: a left shift of 32 or more of a non-zero product
        // always overflows.
        let shift = exponent.unsigned_abs();
        if product == 0 {
            0
        } else if shift >= 32 {
            return Scaled::Overflow;
        } else {
            product << shift
        }
    } else {
        // Round half up on the magnitude: keep one more bit than the result, add one, drop it.
        // (product < 2^54, so shifts of 55 or more round to 0.)
        let shift = exponent.unsigned_abs();
        if shift > 55 {
            0
        } else {
            ((product >> (shift - 1)) + 1) >> 1
        }
    };
    match u32::try_from(magnitude) {
        Ok(magnitude) => Scaled::Finite {
            negative,
            magnitude,
        },
        Err(_) => Scaled::Overflow,
    }
}

/// Writes `±magnitude / 10^digits` with exactly `digits` fractional digits.
///
/// Digit by digit from 10⁹ down, each by repeated subtraction: the ATmega2560 has no divide
/// instruction, and a 32-bit division (`__udivmodsi4`) costs ~600 cycles, one per digit in
/// ufmt's integer formatting. Measured in simavr (`scripts/avr-bench fmt-ours`,
/// `docs/hand-written.md`): a 4-decimal [`Fixed`] took 7 114 – 10 018 cycles with ufmt's
/// digits, 3 415 – 4 136 with these.
fn write_decimal<W>(
    f: &mut Formatter<'_, W>,
    negative: bool,
    magnitude: u32,
    digits: u8,
) -> Result<(), W::Error>
where
    W: uWrite + ?Sized,
{
    if negative && magnitude != 0 {
        f.write_str("-")?;
    }
    let mut rest = magnitude;
    // 10^place; `u32::MAX` < 10 · 10⁹, so the first digit is at most 4.
    let mut power: u32 = 1_000_000_000;
    let mut place: u8 = 9;
    // Still in the zeros before the integer part's first digit.
    let mut leading = true;
    loop {
        let mut digit = b'0';
        while rest >= power {
            rest -= power;
            digit += 1;
        }
        leading &= digit == b'0' && place > digits;
        if !leading {
            // Through `write_str`, as every other piece of a line (`write_char` would take
            // the writer's own path: +440 B on the ATmega2560).
            f.write_str(char::from(digit).encode_utf8(&mut [0; 4]))?;
        }
        if place == 0 {
            return Ok(());
        }
        if place == digits {
            f.write_str(".")?;
        }
        place -= 1;
        // power / 10 without a division: power / 2 is a multiple of 5, and an exact multiple
        // of 5 times 0xCCCC_CCCD (5⁻¹ mod 2³²) is its quotient by 5.
        power = (power >> 1).wrapping_mul(0xCCCC_CCCD);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finite(negative: bool, magnitude: u32) -> Scaled {
        Scaled::Finite {
            negative,
            magnitude,
        }
    }

    #[test]
    fn scale_special_values() {
        assert_eq!(scale_f32(f32::NAN, 2), Scaled::Nan);
        assert_eq!(
            scale_f32(f32::INFINITY, 2),
            Scaled::Infinite { negative: false }
        );
        assert_eq!(
            scale_f32(f32::NEG_INFINITY, 2),
            Scaled::Infinite { negative: true }
        );
        assert_eq!(scale_f32(f32::MAX, 0), Scaled::Overflow);
    }

    #[test]
    fn scale_rounds_half_away_from_zero() {
        // 0.125 and 2.5 are exact in binary: true halves.
        assert_eq!(scale_f32(0.125, 2), finite(false, 13));
        assert_eq!(scale_f32(-0.125, 2), finite(true, 13));
        assert_eq!(scale_f32(2.5, 0), finite(false, 3));
        assert_eq!(scale_f32(-2.5, 0), finite(true, 3));
        assert_eq!(scale_f32(0.375, 2), finite(false, 38));
    }

    #[test]
    fn scale_limit_is_two_to_the_32() {
        // 2^32 − 2^8, the largest f32 below 2^32: exponent field 158, fraction all ones.
        let below = f32::from_bits((158 << 23) | 0x7F_FFFF);
        assert_eq!(scale_f32(below, 0), finite(false, u32::MAX - 255));
        let limit = f32::from_bits(159 << 23); // 2^32
        assert_eq!(scale_f32(limit, 0), Scaled::Overflow);
        assert_eq!(scale_f32(-limit, 0), Scaled::Overflow);
    }

    #[test]
    fn scale_subnormals_and_zero() {
        assert_eq!(scale_f32(0.0, 9), finite(false, 0));
        assert_eq!(scale_f32(-0.0, 9), finite(true, 0));
        assert_eq!(scale_f32(f32::from_bits(1), 9), finite(false, 0));
        assert_eq!(scale_f32(f32::MIN_POSITIVE, 9), finite(false, 0));
    }
}
