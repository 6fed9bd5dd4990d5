//! Exact 128-bit products and differences of `i64` statistics, from 64-bit limbs.
//!
//! Used instead of `i128` so that the exact pivot elimination does not depend on the
//! 128-bit integer support of the target (on AVR it is slow, and `i128 → f32`
//! conversion alone costs 1.7 KB of flash).

use crate::real::Real;

/// A 128-bit two's-complement integer as `(high, low)` 64-bit limbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Wide {
    hi: u64,
    lo: u64,
}

impl Wide {
    /// `a · b`, exactly.
    pub(crate) fn mul(a: i64, b: i64) -> Wide {
        let (ua, ub) = (a.unsigned_abs(), b.unsigned_abs());
        let (a1, a0) = (ua >> 32, ua & 0xFFFF_FFFF);
        let (b1, b0) = (ub >> 32, ub & 0xFFFF_FFFF);
        let p00 = a0 * b0;
        let p01 = a0 * b1;
        let p10 = a1 * b0;
        let p11 = a1 * b1;
        let mid = (p00 >> 32) + (p01 & 0xFFFF_FFFF) + (p10 & 0xFFFF_FFFF);
        let magnitude = Wide {
            hi: p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32),
            lo: (p00 & 0xFFFF_FFFF) | (mid << 32),
        };
        if (a < 0) != (b < 0) {
            magnitude.neg()
        } else {
            magnitude
        }
    }

    fn neg(self) -> Wide {
        let lo = (!self.lo).wrapping_add(1);
        let hi = (!self.hi).wrapping_add(u64::from(lo == 0));
        Wide { hi, lo }
    }

    /// `self − other`. Cannot overflow for differences of two products of `i64` values
    /// (each below 2^126 in magnitude).
    pub(crate) fn sub(self, other: Wide) -> Wide {
        let (lo, borrow) = self.lo.overflowing_sub(other.lo);
        let hi = self
            .hi
            .wrapping_sub(other.hi)
            .wrapping_sub(u64::from(borrow));
        Wide { hi, lo }
    }

    /// `true` below zero.
    pub(crate) fn is_negative(self) -> bool {
        self.hi >> 63 == 1
    }

    /// `true` for zero.
    pub(crate) fn is_zero(self) -> bool {
        self.hi == 0 && self.lo == 0
    }

    /// The value in `T`: `hi · 2^64 + lo` of the magnitude (no cancellation), with sign.
    pub(crate) fn to_real<T: Real>(self) -> T {
        let neg = self.is_negative();
        let m = if neg { self.neg() } else { self };
        let two32 = T::from_u32(1 << 16) * T::from_u32(1 << 16);
        let v = T::from_u64(m.hi) * two32 * two32 + T::from_u64(m.lo);
        if neg {
            -v
        } else {
            v
        }
    }
}

/// Diagnostics only: `a·b − c·d` as `(high, low)` limbs.
#[doc(hidden)]
pub fn probe(a: &i64, b: &i64, c: &i64, d: &i64) -> (u64, u64, f32) {
    let w = Wide::mul(*a, *b).sub(Wide::mul(*c, *d));
    (w.hi, w.lo, w.to_real::<f32>())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn as_i128(w: Wide) -> i128 {
        ((u128::from(w.hi) << 64) | u128::from(w.lo)) as i128
    }

    #[test]
    fn products_and_differences_match_i128() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // Mix magnitudes: full range and small values.
            let shift = (x >> 58) as u32;
            (x as i64) >> shift
        };
        let edge = [
            0,
            1,
            -1,
            i64::MAX,
            -i64::MAX,
            1 << 32,
            -(1 << 32),
            (1 << 32) - 1,
        ];
        for i in 0..20_000 {
            let (a, b, c, d) = if i < edge.len() * edge.len() {
                let (a, b) = (edge[i % edge.len()], edge[i / edge.len()]);
                (a, b, b, a.wrapping_sub(1).max(-i64::MAX))
            } else {
                (next(), next(), next(), next())
            };
            let (a, b, c, d) = (
                a.max(-i64::MAX),
                b.max(-i64::MAX),
                c.max(-i64::MAX),
                d.max(-i64::MAX),
            );
            let w = Wide::mul(a, b).sub(Wide::mul(c, d));
            let want = i128::from(a) * i128::from(b) - i128::from(c) * i128::from(d);
            assert_eq!(as_i128(w), want, "{a} {b} {c} {d}");
            assert_eq!(w.is_negative(), want < 0);
            assert_eq!(w.is_zero(), want == 0);
            let f: f64 = w.to_real();
            assert!((f - want as f64).abs() <= 4.0 * f64::EPSILON * (want as f64).abs());
        }
    }
}
