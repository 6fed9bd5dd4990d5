//! The scalar type of the solve-time arithmetic: `f32` on the device, `f64` on the host.
//!
//! Statistics are accumulated exactly (integers) or in `f64`; only the small solves of
//! the structure search run in [`Real`]. Precision measured on simulated pump records
//! is documented in the crate root.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar usable by the solvers (`f32` or `f64`).
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Largest finite value.
    const MAX: Self;
    /// Converts from `f64`, rounding to nearest.
    fn from_f64(x: f64) -> Self;
    /// Converts from a 64-bit integer, rounding to nearest.
    fn from_i64(x: i64) -> Self;
    /// Converts from an unsigned 64-bit integer, rounding to nearest.
    fn from_u64(x: u64) -> Self;
    /// Widens to `f64`.
    fn to_f64(self) -> f64;
    /// Square root (NaN for negative input).
    fn sqrt(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// `true` unless NaN or ±∞.
    fn is_finite(self) -> bool;
    /// Converts a count (e.g. a number of samples) exactly up to 2^24 (f32) / 2^53 (f64).
    fn from_u32(x: u32) -> Self;
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f32::EPSILON;
    const MAX: Self = f32::MAX;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn from_i64(x: i64) -> Self {
        x as f32
    }
    #[inline]
    fn from_u64(x: u64) -> Self {
        x as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn sqrt(self) -> Self {
        // On AVR avr-libc's assembly `sqrt`: 140 bytes of flash against 562 for `sqrt_f32` below
        // (and ~8000 cycles for libm's sqrtf, which works with 64-bit products), and correctly
        // rounded like both (`scripts/avr-arith-check` compares it with `sqrt_f32`).
        #[cfg(target_arch = "avr")]
        {
            // SAFETY: avr-libc's `sqrt(double)` with `double` 32-bit on AVR: a pure function.
            unsafe { avr_libm::sqrt(self) }
        }
        #[cfg(not(target_arch = "avr"))]
        {
            libm::sqrtf(self)
        }
    }
    #[inline]
    fn ln(self) -> Self {
        // On AVR avr-libc's assembly `log`: ~240 bytes with its helpers against 700 for libm's
        // logf; within 2 ulp of the correctly rounded value where logf is within 1
        // (`scripts/avr-arith-check` measures it).
        #[cfg(target_arch = "avr")]
        {
            // SAFETY: as for `sqrt`.
            unsafe { avr_libm::log(self) }
        }
        #[cfg(not(target_arch = "avr"))]
        {
            libm::logf(self)
        }
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    // One out-of-line copy on AVR: inlined, each test is a 4-byte mask-and-compare on an
    // 8-bit core, at some 40 call sites. The ATmega2560 image is 682 bytes smaller, 922 with
    // the firmware's own tests written `Real::is_finite(x)` (`x.is_finite()` picks the
    // inherent, inlined `f32::is_finite`).
    #[cfg_attr(target_arch = "avr", inline(never))]
    #[cfg_attr(not(target_arch = "avr"), inline)]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline]
    fn from_u32(x: u32) -> Self {
        x as f32
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f64::EPSILON;
    const MAX: Self = f64::MAX;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn from_i64(x: i64) -> Self {
        x as f64
    }
    #[inline]
    fn from_u64(x: u64) -> Self {
        x as f64
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn ln(self) -> Self {
        libm::log(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn from_u32(x: u32) -> Self {
        x as f64
    }
}

/// Correctly rounded `√x` of an `f32` (round to nearest, as IEEE 754 requires of `sqrt`) with
/// 32-bit integer operations only (~1000 cycles on AVR against ~8000 for `libm::sqrtf`): the
/// reference the ATmega2560's [`Real::sqrt`] (avr-libc's) is checked against. Special values as IEEE 754: `√(−0) = −0`,
/// `√(+∞) = +∞`, NaN for NaN and for any input below zero.
///
/// Method: the digit-by-digit (restoring) square root of the significand, one result bit per
/// step, 25 steps: 24 bits of the result and one more that, with the remainder, decides the
/// rounding. (The exact root of an `f32` is never halfway between two `f32`s, so "round half
/// up" on that extra bit is round to nearest.)
///
/// ```
/// use ridge_core::real::sqrt_f32;
/// assert_eq!(sqrt_f32(2.0), 2.0f32.sqrt());
/// assert_eq!(sqrt_f32(6.25), 2.5);
/// assert!(sqrt_f32(-1.0).is_nan());
/// ```
pub fn sqrt_f32(x: f32) -> f32 {
    let bits = x.to_bits();
    let magnitude = bits & 0x7FFF_FFFF;
    if magnitude == 0 {
        return x; // ±0
    }
    if bits >> 31 != 0 || magnitude > 0x7F80_0000 {
        return f32::NAN; // below zero, or NaN
    }
    if magnitude == 0x7F80_0000 {
        return x; // +∞
    }
    // x = sig · 2^(exp − 23) with sig in [2^23, 2^24).
    let mut exp = (bits >> 23) as i32 - 127;
    let mut sig = bits & 0x007F_FFFF;
    if exp == -127 {
        // Subnormal: shift the leading one up to bit 23 (a loop: `leading_zeros` is ~290
        // bytes of AVR code, and subnormals never occur in the solves).
        exp = -126;
        while sig & 0x0080_0000 == 0 {
            sig <<= 1;
            exp -= 1;
        }
    } else {
        sig |= 0x0080_0000;
    }
    // Make the exponent even so that it halves exactly: sig/2^23 then lies in [1, 4).
    if exp & 1 != 0 {
        sig <<= 1;
        exp -= 1;
    }
    // Digit-by-digit root of sig/2^23 in [1, 4), so the root lies in [1, 2). `rem` holds the
    // remainder scaled by 2^(24 + step) (pre-doubled once: `bit` starts at 2^24 for the
    // result's units digit), `root` the root so far (each bit counted twice: the `2·root·bit`
    // term of (root + bit)² − root²).
    let mut rem = sig << 1;
    let mut root = 0u32; // result bits, units digit at 2^24
    let mut twice = 0u32; // 2 · root, at the same scale as `rem`
    let mut bit = 1u32 << 24;
    while bit != 0 {
        let trial = twice + bit;
        if trial <= rem {
            rem -= trial;
            twice = trial + bit;
            root += bit;
        }
        rem <<= 1;
        bit >>= 1;
    }
    // `root` has 25 bits (units at 2^24); its last bit rounds. A carry out of the significand
    // (root = 2^25 − 1 → 2^24 after rounding) moves into the exponent field by itself.
    let rounded = (root >> 1) + (root & 1);
    let biased = (exp / 2 + 126) as u32; // + 1 from the leading significand bit below
    f32::from_bits((biased << 23) + rounded)
}

#[cfg(test)]
mod tests {
    use super::sqrt_f32;

    fn check(x: f32) {
        let want = x.sqrt();
        let got = sqrt_f32(x);
        assert!(
            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
            "sqrt_f32({x:e} = {:#010x}) = {got:e}, std {want:e}",
            x.to_bits()
        );
    }

    #[test]
    fn special_values_follow_ieee() {
        for x in [
            0.0,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -1.0,
            -f32::MIN_POSITIVE,
        ] {
            check(x);
        }
        assert_eq!(sqrt_f32(-0.0).to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn perfect_squares_are_exact() {
        for k in 1..=4096u32 {
            let k = k as f32;
            assert_eq!(sqrt_f32(k * k), k);
        }
    }

    /// Against the host's correctly rounded `f32::sqrt`: every subnormal near the bottom and
    /// top of the subnormal range, both ends of each exponent's significand range (where the
    /// rounding carry and the odd/even exponent cases live), and a stride through all
    /// positive `f32` bit patterns.
    #[test]
    fn matches_std_sqrt_bit_for_bit() {
        for b in (1u32..1 << 16).chain(0x007F_0000..0x0080_0000) {
            check(f32::from_bits(b));
        }
        for exp in 1u32..255 {
            let base = exp << 23;
            for off in (0..4096).chain(0x7F_F000..0x80_0000) {
                check(f32::from_bits(base + off));
            }
        }
        let mut b = 1u32;
        while b < 0x7F80_0000 {
            check(f32::from_bits(b));
            b += 997;
        }
    }
}

/// avr-libc's math functions, linked from its `libm.a` by the firmware's linker wrapper
/// (`scripts/avr-gcc-wrapper`); `double` is 32-bit there.
#[cfg(target_arch = "avr")]
mod avr_libm {
    extern "C" {
        pub fn sqrt(x: f32) -> f32;
        pub fn log(x: f32) -> f32;
    }
}
