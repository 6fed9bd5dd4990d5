//! Exact 128-bit products and differences of `i64` statistics, in bytes.
//!
//! Used instead of `i128` so that the exact pivot elimination does not depend on the
//! 128-bit integer support of the target (on AVR it is slow, and `i128 → f32`
//! conversion alone costs 1.7 KB of flash). Little-endian bytes and byte loops rather than
//! 64-bit limbs: the ATmega2560 multiplies 8 × 8 → 16 bits in one instruction and adds one
//! byte at a time, so the limb form (four 64-bit library multiplications, 64-bit shifts and
//! negations) was 1.2 KB of its flash and the byte form is 0.6 KB less (measured on the
//! console image).

use crate::real::Real;

/// A 128-bit two's-complement integer as 16 little-endian bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Wide([u8; 16]);

impl Wide {
    /// `a · b`, exactly.
    ///
    /// By reference, and `a·b − c·d` as two calls ([`product`](Self::product) then
    /// [`sub_product`](Self::sub_product)) rather than one function of four values: the
    /// compiler passes referenced `i64`s by value, and four of them are more than the AVR
    /// argument registers hold. Arguments on the stack are read one byte off on the
    /// ATmega2560 (its return addresses are 3 bytes): `scripts/avr-arith-check` caught it.
    #[inline(never)]
    pub(crate) fn product(a: &i64, b: &i64) -> Wide {
        let mut r = Wide([0; 16]);
        add_product(&mut r.0, a, b);
        if (*a < 0) != (*b < 0) {
            negate(&mut r.0);
        }
        r
    }

    /// `self ← self − c · d`, exactly (cannot overflow for a product of `i64` values minus
    /// another, each below 2^126 in magnitude). A positive `c·d` is added to `−self`, then
    /// the sum negated.
    #[inline(never)]
    pub(crate) fn sub_product(&mut self, c: &i64, d: &i64) {
        let flip = (*c < 0) == (*d < 0);
        if flip {
            negate(&mut self.0);
        }
        add_product(&mut self.0, c, d);
        if flip {
            negate(&mut self.0);
        }
    }

    /// The low and high 64-bit halves.
    fn halves(self) -> (u64, u64) {
        let (lo, hi) = self.0.split_at(8);
        let limb = |b: &[u8]| b.try_into().map(u64::from_le_bytes).unwrap_or_default();
        (limb(lo), limb(hi))
    }

    /// `true` below zero.
    pub(crate) fn is_negative(self) -> bool {
        self.0[15] >> 7 == 1
    }

    /// `true` for zero.
    pub(crate) fn is_zero(self) -> bool {
        self.0.iter().all(|&b| b == 0)
    }

    /// The value in `T`: `hi · 2^64 + lo` of the magnitude (no cancellation), with sign.
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[cfg_attr(target_arch = "avr", inline(never))]
    pub(crate) fn to_real<T: Real>(self) -> T {
        let neg = self.is_negative();
        let mut m = self;
        if neg {
            negate(&mut m.0);
        }
        let (lo, hi) = m.halves();
        let two32 = T::from_u32(1 << 16) * T::from_u32(1 << 16);
        let v = T::from_u64(hi) * two32 * two32 + T::from_u64(lo);
        if neg {
            -v
        } else {
            v
        }
    }
}

/// `r ← r + |a|·|b|` (schoolbook, byte by byte: the ATmega2560 multiplies 8 × 8 → 16 bits in
/// one instruction), modulo 2^128.
fn add_product(r: &mut [u8; 16], a: &i64, b: &i64) {
    let (ua, ub) = (magnitude(a), magnitude(b));
    for (i, &x) in ua.iter().enumerate() {
        // Statistics are far below 2^64: their high bytes are zero rows.
        if x == 0 {
            continue;
        }
        let mut carry = 0u16;
        for (k, slot) in r.iter_mut().enumerate().skip(i) {
            let y = ub.get(k - i).copied().unwrap_or(0);
            // ≤ 255 · 255 + 255 + 255 = 65 535: no overflow.
            let t = u16::from(x) * u16::from(y) + u16::from(*slot) + carry;
            *slot = t as u8;
            carry = t >> 8;
        }
    }
}

/// `|x|` as little-endian bytes (`|i64::MIN|` = 2^63 included).
fn magnitude(x: &i64) -> [u8; 8] {
    let mut bytes = x.to_le_bytes();
    if *x < 0 {
        negate(&mut bytes);
    }
    bytes
}

/// Two's-complement negation of the little-endian integer `bytes`, in place (one loop for the
/// 8-byte magnitudes and the 16-byte results).
#[inline(never)]
fn negate(bytes: &mut [u8]) {
    let mut carry = 1u16;
    for b in bytes.iter_mut() {
        let t = u16::from(!*b) + carry;
        *b = t as u8;
        carry = t >> 8;
    }
}

/// Diagnostics only: `a·b − c·d` as `(high, low)` 64-bit halves and in `f32`.
#[doc(hidden)]
pub fn probe(a: &i64, b: &i64, c: &i64, d: &i64) -> (u64, u64, f32) {
    let mut w = Wide::product(a, b);
    w.sub_product(c, d);
    let (lo, hi) = w.halves();
    (hi, lo, w.to_real::<f32>())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn as_i128(w: Wide) -> i128 {
        i128::from_le_bytes(w.0)
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
            let mut w = Wide::product(&a, &b);
            w.sub_product(&c, &d);
            let want = i128::from(a) * i128::from(b) - i128::from(c) * i128::from(d);
            assert_eq!(as_i128(w), want, "{a} {b} {c} {d}");
            assert_eq!(w.is_negative(), want < 0);
            assert_eq!(w.is_zero(), want == 0);
            let f: f64 = w.to_real();
            assert!((f - want as f64).abs() <= 4.0 * f64::EPSILON * (want as f64).abs());
        }
    }
}
