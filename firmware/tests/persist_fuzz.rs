//! Fuzzing the persisted-record decoder (`persist::decode`) with a seeded generator, bounded
//! in cases (and so in time) for CI: never a panic, and every answer checked against an
//! independent truth:
//! - arbitrary bytes: whatever `decode` accepts, `encode` writes back byte for byte (the
//!   module's claim "decode accepts only what encode can produce");
//! - records with random fields and a correct CRC: accepted exactly when the layout table of
//!   the module docs says the fields are valid (an oracle written here from that table);
//! - a valid record with a burst error of 1..=32 bits: always rejected (CRC-32 detects every
//!   burst up to 32 bits), and with random multi-bit damage rejected or decoded to exactly
//!   the damaged bytes.
//!
//! Case counts: `CASES` below (×4 families); `RIDGE_FUZZ_SCALE=N` multiplies them for a
//! longer local run.

use ridge_core::{ArxModel, InputMap, Offset, MAP_KNOTS};
use ridge_pump_firmware::persist::{
    crc32, decode, encode, PersistError, MAGIC, RECORD_LEN, VERSION,
};

/// Cases per family in `cargo test` (measured: 0.5 s for all four families in the test
/// profile on a 2-core machine).
const CASES: u64 = 200_000;

fn cases() -> u64 {
    let scale = std::env::var("RIDGE_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
        .unwrap_or(1);
    CASES * scale.max(1)
}

/// SplitMix64: a small, seeded, reproducible generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
    /// An `f32` from interesting bit patterns: zeros, NaN, ±∞, subnormals, ordinary values.
    fn f32(&mut self) -> f32 {
        match self.below(8) {
            0 => 0.0,
            1 => -0.0,
            2 => f32::NAN,
            3 => f32::INFINITY,
            4 => f32::from_bits(self.next() as u32 & 0x007F_FFFF),
            5 => (self.below(2001) as f32 - 1000.0) / 100.0,
            _ => f32::from_bits(self.next() as u32),
        }
    }
}

fn le(v: f32) -> [u8; 4] {
    v.to_le_bytes()
}

fn seal(rec: &mut [u8; RECORD_LEN]) {
    let crc = crc32(&rec[..RECORD_LEN - 4]);
    rec[RECORD_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
}

/// `Ok` ⇒ re-encoding gives the same bytes.
fn check_round_trip(bytes: &[u8]) {
    if let Ok((model, map, fit)) = decode(bytes) {
        assert_eq!(
            &encode(&model, &map, fit)[..],
            &bytes[..RECORD_LEN],
            "accepted bytes that encode would not write"
        );
    }
}

#[test]
fn arbitrary_bytes_never_panic_and_accepted_ones_round_trip() {
    let mut rng = Rng(1);
    let mut accepted = 0u64;
    for _ in 0..cases() {
        let len = rng.below(RECORD_LEN as u64 + 20) as usize;
        let mut b: Vec<u8> = (0..len).map(|_| rng.byte()).collect();
        // Half of them with the magic and version, so the CRC check is reached.
        if len >= 5 && rng.below(2) == 0 {
            b[..4].copy_from_slice(&MAGIC);
            b[4] = VERSION;
        }
        // A quarter sealed, so the checks after the CRC are reached.
        if len >= RECORD_LEN && rng.below(2) == 0 {
            let crc = crc32(&b[..RECORD_LEN - 4]);
            b[RECORD_LEN - 4..RECORD_LEN].copy_from_slice(&crc.to_le_bytes());
        }
        match decode(&b) {
            Ok(_) => accepted += 1,
            Err(PersistError::Length) => assert!(len < RECORD_LEN),
            Err(_) => assert!(len >= RECORD_LEN),
        }
        check_round_trip(&b);
    }
    // Random bytes are almost never a valid record.
    assert!(accepted < cases() / 100, "{accepted}");
}

/// The fields of a record.
struct Fields {
    p: u8,
    q: u8,
    d: u8,
    off: u8,
    theta: [f32; 6],
    phi: [f32; 6],
    c: f32,
    fit: f32,
    first: u16,
    step: u16,
    knots: [i16; MAP_KNOTS],
}

/// The layout table of `persist`'s docs, as an independent oracle: is a sealed record with
/// these fields valid?
fn valid_by_the_table(f: &Fields) -> bool {
    let (pu, qu) = (usize::from(f.p).min(6), usize::from(f.q).min(6));
    (1..=6).contains(&f.p)
        && (1..=6).contains(&f.q)
        && f.d <= 6
        && f.off <= 1
        && f.theta[pu..].iter().all(|v| v.to_bits() == 0)
        && f.phi[qu..].iter().all(|v| v.to_bits() == 0)
        && (f.off == 1 || f.c.to_bits() == 0)
        && f.theta[..pu].iter().all(|v| v.is_finite())
        && f.phi[..qu].iter().all(|v| v.is_finite())
        && f.c.is_finite()
        && f.fit.is_finite()
        && f.step > 0
        && u32::from(f.first) + 15 * u32::from(f.step) <= 65_535
        && f.knots.windows(2).all(|w| w[0] < w[1])
}

#[test]
fn sealed_records_are_accepted_exactly_when_their_fields_are_valid() {
    let mut rng = Rng(2);
    let (mut ok, mut bad) = (0u64, 0u64);
    for _ in 0..cases() {
        // Fields near and past their ranges; unused slots mostly zero.
        let p = rng.below(8) as u8;
        let q = rng.below(8) as u8;
        let d = rng.below(9) as u8;
        let off = if rng.below(8) == 0 {
            rng.byte()
        } else {
            rng.below(2) as u8
        };
        let mut theta = [0.0f32; 6];
        let mut phi = [0.0f32; 6];
        for (i, t) in theta.iter_mut().enumerate() {
            if i < usize::from(p) || rng.below(16) == 0 {
                *t = rng.f32();
            }
        }
        for (i, f) in phi.iter_mut().enumerate() {
            if i < usize::from(q) || rng.below(16) == 0 {
                *f = rng.f32();
            }
        }
        let c = if off == 1 || rng.below(8) == 0 {
            rng.f32()
        } else {
            0.0
        };
        let fit = rng.f32();
        // A map: mostly increasing knots on a grid within range, sometimes not.
        let first = rng.below(4_000) as u16;
        let step = match rng.below(64) {
            0 => 0,
            1 => 4_000 + rng.below(1_000) as u16,
            _ => 1 + rng.below(600) as u16,
        };
        let mut knots = [0i16; MAP_KNOTS];
        let mut v = rng.below(2_000) as i32 - 1_000;
        for k in knots.iter_mut() {
            *k = v as i16;
            v += if rng.below(512) == 0 {
                -1
            } else {
                1 + rng.below(1_500) as i32
            };
            v = v.min(i32::from(i16::MAX));
        }
        let mut rec = [0u8; RECORD_LEN];
        rec[..4].copy_from_slice(&MAGIC);
        rec[4..9].copy_from_slice(&[VERSION, p, q, d, off]);
        for (i, v) in theta.iter().chain(&phi).chain([&c, &fit]).enumerate() {
            rec[9 + 4 * i..13 + 4 * i].copy_from_slice(&le(*v));
        }
        rec[65..67].copy_from_slice(&first.to_le_bytes());
        rec[67..69].copy_from_slice(&step.to_le_bytes());
        for (k, v) in knots.iter().enumerate() {
            rec[69 + 2 * k..71 + 2 * k].copy_from_slice(&v.to_le_bytes());
        }
        seal(&mut rec);
        let want = valid_by_the_table(&Fields {
            p,
            q,
            d,
            off,
            theta,
            phi,
            c,
            fit,
            first,
            step,
            knots,
        });
        match decode(&rec) {
            Ok((m, map, f)) => {
                assert!(want, "accepted p {p} q {q} d {d} off {off}: {rec:?}");
                let s = m.structure();
                assert_eq!((s.p, s.q, s.d), (p, q, d));
                assert_eq!(m.theta(), &theta[..usize::from(p)]);
                assert_eq!(m.phi(), &phi[..usize::from(q)]);
                assert_eq!(f.to_bits(), fit.to_bits());
                assert_eq!(
                    (map.first(), map.step(), *map.knots()),
                    (first, step, knots)
                );
                ok += 1;
            }
            Err(e) => {
                assert!(!want, "rejected ({e:?}) a valid record: {rec:?}");
                assert!(matches!(
                    e,
                    PersistError::Structure | PersistError::NonFinite | PersistError::Map
                ));
                bad += 1;
            }
        }
    }
    // Both answers were exercised.
    assert!(
        ok > cases() / 50 && bad > cases() / 50,
        "{ok} accepted, {bad} rejected"
    );
}

fn valid_record(rng: &mut Rng) -> [u8; RECORD_LEN] {
    let p = 1 + rng.below(6) as usize;
    let q = 1 + rng.below(6) as usize;
    let theta: Vec<f32> = (0..p)
        .map(|_| (rng.below(2001) as f32 - 1000.0) / 1000.0)
        .collect();
    let phi: Vec<f32> = (0..q)
        .map(|_| (rng.below(2001) as f32 - 1000.0) / 100.0)
        .collect();
    let offset = if rng.below(2) == 0 {
        Offset::None
    } else {
        Offset::Intercept
    };
    let c = if offset == Offset::Intercept {
        1.5
    } else {
        0.0
    };
    let m = ArxModel::new(&theta, &phi, rng.below(7) as u8, offset, c).unwrap();
    let mut knots = [0i16; MAP_KNOTS];
    let mut v = rng.below(1_000) as i16;
    for k in knots.iter_mut() {
        *k = v;
        v += 1 + rng.below(1_500) as i16;
    }
    let map = InputMap::new(1_500, 1 + rng.below(600) as u16, knots).unwrap();
    encode(&m, &map, (rng.below(200) as f32) - 100.0)
}

#[test]
fn burst_errors_up_to_32_bits_are_always_rejected() {
    let mut rng = Rng(3);
    for _ in 0..cases() {
        let good = valid_record(&mut rng);
        assert!(decode(&good).is_ok());
        // A burst: first and last bit of a span of 1..=32 bits flipped, any bits between.
        let len = 1 + rng.below(32) as usize;
        let start = rng.below((RECORD_LEN * 8 - len + 1) as u64) as usize;
        let mut rec = good;
        for k in 0..len {
            if k == 0 || k == len - 1 || rng.below(2) == 0 {
                let bit = start + k;
                rec[bit / 8] ^= 1 << (bit % 8);
            }
        }
        assert!(
            decode(&rec).is_err(),
            "burst of {len} bits at {start} accepted"
        );
    }
}

#[test]
fn random_damage_is_rejected_or_decodes_to_the_damaged_bytes() {
    let mut rng = Rng(4);
    for _ in 0..cases() {
        let mut rec = valid_record(&mut rng);
        for _ in 0..1 + rng.below(12) {
            let i = rng.below(RECORD_LEN as u64) as usize;
            rec[i] ^= rng.byte() | 1;
        }
        check_round_trip(&rec);
    }
}
