//! Report formatting written into a `heapless::String` through `ufmt`.
//!
//! Expected strings are worked out by hand from the exact binary value of each `f32` (given in
//! the comments), not produced by the code under test.

use heapless::String;
use ridge_pump_firmware::numfmt::{Decimal, Fixed, Int, Milli, FIXED_LIMIT, MAX_DIGITS};
use ufmt::{uDisplay, uwrite};

fn show<T: uDisplay>(value: T) -> String<64> {
    let mut s = String::new();
    uwrite!(s, "{}", value).unwrap();
    s
}

fn fixed(value: f32, digits: u8) -> String<64> {
    show(Fixed::new(value, digits))
}

#[test]
fn fixed_typical_values() {
    // −1.9472_f32 = −1.94719994068…; ×10⁴ = −19471.9994 → −19472.
    assert_eq!(fixed(-1.9472, 4), "-1.9472");
    // 123456.78_f32 = 123456.78125; ×100 = 12345678.125 → 12345678.
    assert_eq!(fixed(123_456.78, 2), "123456.78");
    // π_f32 = 3.14159274101…; ×10⁶ = 3141592.741 → 3141593.
    assert_eq!(fixed(core::f32::consts::PI, 6), "3.141593");
    // 0.1_f32 = 0.100000001490116…; ×10⁹ = 100000001.49 → 100000001.
    assert_eq!(fixed(0.1, 9), "0.100000001");
    // 0.3_f32 = 0.30000001192…; one digit → 3.
    assert_eq!(fixed(0.3, 1), "0.3");
    assert_eq!(fixed(-0.3, 1), "-0.3");
    assert_eq!(fixed(42.0, 3), "42.000");
}

#[test]
fn fixed_zero_digits_has_no_point() {
    assert_eq!(fixed(3.0, 0), "3");
    assert_eq!(fixed(-3.0, 0), "-3");
    assert_eq!(fixed(16_777_216.0, 0), "16777216");
}

#[test]
fn fixed_leading_zeros_of_the_fraction() {
    // 0.0625 = 2⁻⁴ exactly.
    assert_eq!(fixed(0.0625, 4), "0.0625");
    assert_eq!(fixed(-0.0625, 4), "-0.0625");
    assert_eq!(fixed(-0.0625, 6), "-0.062500");
    // 1.5 = exact.
    assert_eq!(fixed(1.5, 3), "1.500");
    // 2⁻¹⁰ = 0.0009765625 → 5 digits: 97.65625 → 98 → 0.00098.
    assert_eq!(fixed(0.000_976_562_5, 5), "0.00098");
}

#[test]
fn fixed_rounds_half_away_from_zero() {
    // These are exact binary fractions, so the halves are real halves.
    assert_eq!(fixed(0.5, 0), "1");
    assert_eq!(fixed(-0.5, 0), "-1");
    assert_eq!(fixed(1.5, 0), "2");
    assert_eq!(fixed(2.5, 0), "3");
    assert_eq!(fixed(-2.5, 0), "-3");
    assert_eq!(fixed(0.125, 2), "0.13");
    assert_eq!(fixed(-0.125, 2), "-0.13");
    // 1.005_f32 = 1.00499999523…: below the half, rounds down.
    assert_eq!(fixed(1.005, 2), "1.00");
    // 0.999_96 rounds up into the integer part.
    assert_eq!(fixed(0.999_96, 4), "1.0000");
    assert_eq!(fixed(-9.999_96, 4), "-10.0000");
}

#[test]
fn fixed_has_no_negative_zero() {
    assert_eq!(fixed(0.0, 3), "0.000");
    assert_eq!(fixed(-0.0, 3), "0.000");
    assert_eq!(fixed(-0.0001, 2), "0.00");
    assert_eq!(fixed(-0.4, 0), "0");
    // Smallest subnormal, 1.4e−45.
    assert_eq!(fixed(f32::from_bits(1), 9), "0.000000000");
    assert_eq!(fixed(-f32::from_bits(1), 9), "0.000000000");
}

#[test]
fn fixed_special_values() {
    assert_eq!(fixed(f32::NAN, 4), "nan");
    assert_eq!(fixed(-f32::NAN, 4), "nan");
    assert_eq!(fixed(f32::INFINITY, 4), "inf");
    assert_eq!(fixed(f32::NEG_INFINITY, 4), "-inf");
}

#[test]
fn fixed_drops_digits_above_two_to_the_32_and_overflows_without_any() {
    assert_eq!(FIXED_LIMIT, 4_294_967_296);
    // 2^32 − 2^8 = 4294967040 is the largest f32 below the limit.
    let below = f32::from_bits((158 << 23) | 0x7F_FFFF);
    assert_eq!(fixed(below, 0), "4294967040");
    assert_eq!(fixed(-below, 0), "-4294967040");
    // With digits asked for, as many as fit: 4294967040 has none to spare.
    assert_eq!(fixed(below, 3), "4294967040");
    // 2^32 itself, and anything that reaches it with no digit left.
    assert_eq!(fixed(f32::from_bits(159 << 23), 0), "ovf");
    assert_eq!(fixed(-1e19, 0), "ovf");
    assert_eq!(fixed(f32::MAX, 0), "ovf");
    assert_eq!(fixed(f32::MIN, 3), "ovf");
    // 12345.5 with 6 digits would be 12 345 500 000 ≥ 2^32: 5 digits fit.
    assert_eq!(fixed(12_345.5, 6), "12345.50000");
    // 4.25 with 9 digits: 4 250 000 000 < 2^32, all 9.
    assert_eq!(fixed(4.25, 9), "4.250000000");
    assert_eq!(fixed(4.5, 9), "4.50000000");
}

#[test]
fn fixed_digits_are_capped() {
    assert_eq!(MAX_DIGITS, 9);
    assert_eq!(Fixed::new(1.0, 12).digits(), 9);
    assert_eq!(fixed(1.0, 12), "1.000000000");
    assert_eq!(fixed(1.0, u8::MAX), "1.000000000");
}

#[test]
fn fixed_scaled_value() {
    assert_eq!(Fixed::new(-1.9472, 4).scaled(), Some((-19_472, 4)));
    assert_eq!(Fixed::new(0.125, 2).scaled(), Some((13, 2)));
    assert_eq!(Fixed::new(-0.0, 2).scaled(), Some((0, 2)));
    assert_eq!(Fixed::new(12_345.5, 6).scaled(), Some((1_234_550_000, 5)));
    assert_eq!(Fixed::new(f32::NAN, 2).scaled(), None);
    assert_eq!(Fixed::new(f32::NEG_INFINITY, 2).scaled(), None);
    assert_eq!(Fixed::new(1e19, 0).scaled(), None);
    assert_eq!(Fixed::new(-1.5, 0).value(), -1.5);
}

#[test]
fn milli_values() {
    assert_eq!(show(Milli(12_345)), "12.345");
    assert_eq!(show(Milli(0)), "0.000");
    assert_eq!(show(Milli(5)), "0.005");
    assert_eq!(show(Milli(50)), "0.050");
    assert_eq!(show(Milli(-1)), "-0.001");
    assert_eq!(show(Milli(1_000)), "1.000");
    assert_eq!(show(Milli(-1_000)), "-1.000");
    assert_eq!(show(Milli(-273_067)), "-273.067");
    assert_eq!(show(Milli(250_000)), "250.000");
    assert_eq!(show(Milli(i32::MAX)), "2147483.647");
    assert_eq!(show(Milli(i32::MIN)), "-2147483.648");
}

#[test]
fn decimal_values() {
    assert_eq!(show(Decimal::new(1_234, 2)), "12.34");
    assert_eq!(show(Decimal::new(10_000, 2)), "100.00");
    assert_eq!(show(Decimal::new(-5, 0)), "-5");
    assert_eq!(show(Decimal::new(-7, 4)), "-0.0007");
    assert_eq!(show(Decimal::new(7, 9)), "0.000000007");
    assert_eq!(show(Decimal::new(i32::MIN, 9)), "-2.147483648");
    assert_eq!(show(Decimal::new(1, 20)), "0.000000001");
}

#[test]
fn int_values() {
    assert_eq!(show(Int(0)), "0");
    assert_eq!(show(Int(7)), "7");
    assert_eq!(show(Int(10)), "10");
    assert_eq!(show(Int(1_000_000_000)), "1000000000");
    assert_eq!(show(Int(u32::MAX)), "4294967295");
    assert_eq!(show(Int::from(u8::MAX)), "255");
    assert_eq!(show(Int::from(u16::MAX)), "65535");
}

/// `Decimal` and `Int` against std's integer formatting (quotient and zero-padded remainder),
/// on every power of ten and its neighbours and on pseudo-random values, for every number of
/// digits: the digit loop (repeated subtraction, power / 10 by a multiplicative inverse) has
/// its edges where a digit is 9 or 0 and where the power changes.
#[test]
fn decimal_and_int_match_std_formatting() {
    fn reference(value: i32, digits: u8) -> std::string::String {
        let p = 10u64.pow(u32::from(digits));
        let m = u64::from(value.unsigned_abs());
        let sign = if value < 0 { "-" } else { "" };
        if digits == 0 {
            format!("{sign}{m}")
        } else {
            format!("{sign}{}.{:0w$}", m / p, m % p, w = usize::from(digits))
        }
    }
    let mut values: Vec<i64> = vec![0, 1, 9, i64::from(i32::MAX), i64::from(i32::MIN)];
    let mut p = 1i64;
    while p <= i64::from(u32::MAX) {
        for v in [p - 1, p, p + 1, 9 * p, 10 * p - 1] {
            values.push(v);
        }
        p *= 10;
    }
    let mut x: u32 = 0x9E37_79B9;
    for _ in 0..20_000 {
        // xorshift32
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        values.push(i64::from(x));
        values.push(i64::from(x >> (x % 32)));
    }
    for &v in &values {
        if let Ok(u) = u32::try_from(v) {
            assert_eq!(show(Int(u)).as_str(), u.to_string(), "Int({u})");
        }
        for signed in [v, -v] {
            let Ok(s) = i32::try_from(signed) else {
                continue;
            };
            for digits in 0..=MAX_DIGITS {
                // No negative zero: a zero prints unsigned.
                let want = reference(s, digits);
                assert_eq!(
                    show(Decimal::new(s, digits)).as_str(),
                    want,
                    "Decimal::new({s}, {digits})"
                );
            }
        }
    }
}

#[test]
fn a_whole_report_line() {
    let mut line: String<96> = String::new();
    uwrite!(
        line,
        "s,{},{},{},{}\n",
        42u32,
        Decimal::new(5_000, 2),
        Milli(-273_067),
        Fixed::new(-1.9472, 4)
    )
    .unwrap();
    assert_eq!(line, "s,42,50.00,-273.067,-1.9472\n");
}

#[test]
fn writer_errors_propagate() {
    // A String too small for the output reports the writer's error instead of panicking.
    let mut tiny: String<4> = String::new();
    assert!(uwrite!(tiny, "{}", Milli(-273_067)).is_err());
}

/// Reference: round the exact decimal expansion of `x` (from std's exact `{:.150}` formatting of
/// the lossless `f64`) as a digit string, half away from zero, then apply the documented
/// special cases.
fn reference_fixed(x: f32, digits: u8) -> std::string::String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf".into() } else { "-inf".into() };
    }
    let exact = format!("{:.150}", f64::from(x).abs());
    let (int_part, frac_part) = exact.split_once('.').unwrap();
    // The most digits (up to those asked for) whose rounded magnitude is below 2^32.
    let rounded = |d: usize| {
        let kept = format!("{int_part}{}", &frac_part[..d]);
        let round_up = frac_part.as_bytes()[d] >= b'5';
        kept.parse::<u128>()
            .ok()
            .and_then(|m| m.checked_add(u128::from(round_up)))
            .filter(|&m| m < 1u128 << 32)
    };
    let Some((magnitude, d)) = (0..=usize::from(digits))
        .rev()
        .find_map(|d| rounded(d).map(|m| (m, d)))
    else {
        return "ovf".into();
    };
    let digits = d as u8;
    let scale = 10u128.pow(u32::from(digits));
    let sign = if x.is_sign_negative() && magnitude != 0 {
        "-"
    } else {
        ""
    };
    if digits == 0 {
        format!("{sign}{magnitude}")
    } else {
        format!(
            "{sign}{}.{:0width$}",
            magnitude / scale,
            magnitude % scale,
            width = d
        )
    }
}

#[test]
fn fixed_matches_exact_decimal_reference_over_many_floats() {
    let mut checked = 0u32;
    // A stride through all bit patterns (both signs, every exponent), plus dense runs around
    // values where ties and carries happen.
    let strided = (0..=u32::MAX).step_by(65_521);
    let dense = (0..2_000u32).flat_map(|i| {
        [
            0.5f32.to_bits() - 1_000 + i,
            2.5f32.to_bits() - 1_000 + i,
            1.9472f32.to_bits() - 1_000 + i,
            (-0.125f32).to_bits() - 1_000 + i,
        ]
    });
    for bits in strided.chain(dense) {
        let x = f32::from_bits(bits);
        for digits in 0..=MAX_DIGITS {
            let got = fixed(x, digits);
            assert_eq!(
                got.as_str(),
                reference_fixed(x, digits),
                "x = {x:e} (bits {bits:#010x}), digits = {digits}"
            );
            checked += 1;
        }
    }
    assert!(checked > 600_000);
}

#[test]
fn fixed_matches_reference_on_exact_halves() {
    // k + 0.5 and k/2^n halves for many k: true ties, where std's half-to-even would differ.
    for k in -2_000i32..2_000 {
        for (x, digits) in [
            (k as f32 + 0.5, 0u8),
            (k as f32 / 8.0, 2),
            (k as f32 / 32.0, 4),
        ] {
            assert_eq!(
                fixed(x, digits).as_str(),
                reference_fixed(x, digits),
                "x = {x}"
            );
        }
    }
}
