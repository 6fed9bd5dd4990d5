//! The persisted model record: round trip, and rejection of every corruption.

use ridge_core::{ArxModel, InputMap, Offset, MAP_KNOTS};
use ridge_pump_firmware::persist::{
    crc32, decode, encode, PersistError, MAGIC, RECORD_LEN, VERSION,
};

fn model() -> ArxModel<f32> {
    ArxModel::new(
        &[0.4537, 0.3643, -0.1207],
        &[6.6208, -4.9694],
        3,
        Offset::Intercept,
        -4.447,
    )
    .unwrap()
}

/// A blower-like map: 15 % + k · 5.33 %, flows in counts.
fn map() -> InputMap {
    let mut knots = [0i16; MAP_KNOTS];
    for (k, v) in knots.iter_mut().enumerate() {
        *v = (k * k * 60 + 700 + k) as i16;
    }
    InputMap::new(1_500, 533, knots).unwrap()
}

/// Re-seals a modified record with a correct CRC.
fn reseal(rec: &mut [u8; RECORD_LEN]) {
    let crc = crc32(&rec[..RECORD_LEN - 4]);
    rec[RECORD_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn crc32_check_value() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
}

#[test]
fn round_trip_is_exact() {
    for (m, fit) in [
        (model(), 87.25f32),
        (
            ArxModel::new(&[0.935], &[6.5], 0, Offset::None, 0.0).unwrap(),
            -12.5,
        ),
        (
            ArxModel::new(&[0.1; 6], &[-1e-7; 6], 6, Offset::Intercept, 1e6).unwrap(),
            100.0,
        ),
    ] {
        let rec = encode(&m, &map(), fit);
        let (back, map_back, fit_back) = decode(&rec).unwrap();
        assert_eq!(back, m);
        assert_eq!(map_back, map());
        assert_eq!(fit_back.to_bits(), fit.to_bits());
    }
}

#[test]
fn layout_is_as_documented() {
    let rec = encode(&model(), &map(), 87.25);
    assert_eq!(RECORD_LEN, 105);
    assert_eq!(&rec[0..4], &MAGIC);
    assert_eq!(&rec[0..4], b"RPMD");
    assert_eq!(rec[4], VERSION);
    assert_eq!(&rec[5..9], &[3, 2, 3, 1]);
    assert_eq!(&rec[9..13], &0.4537f32.to_le_bytes());
    assert_eq!(&rec[17..21], &(-0.1207f32).to_le_bytes());
    assert_eq!(&rec[21..33], &[0; 12]); // θ_4..θ_6 unused
    assert_eq!(&rec[33..37], &6.6208f32.to_le_bytes());
    assert_eq!(&rec[41..57], &[0; 16]); // φ_2..φ_5 unused
    assert_eq!(&rec[57..61], &(-4.447f32).to_le_bytes());
    assert_eq!(&rec[61..65], &87.25f32.to_le_bytes());
    assert_eq!(&rec[65..67], &1_500u16.to_le_bytes());
    assert_eq!(&rec[67..69], &533u16.to_le_bytes());
    for k in 0..MAP_KNOTS {
        assert_eq!(
            &rec[69 + 2 * k..71 + 2 * k],
            &map().knots()[k].to_le_bytes()
        );
    }
    assert_eq!(
        u32::from_le_bytes(rec[101..105].try_into().unwrap()),
        crc32(&rec[..101])
    );
}

#[test]
fn every_single_bit_flip_is_rejected() {
    let rec = encode(&model(), &map(), 87.25);
    for byte in 0..RECORD_LEN {
        for bit in 0..8 {
            let mut bad = rec;
            bad[byte] ^= 1 << bit;
            let expect = match byte {
                0..=3 => PersistError::Magic,
                4 => PersistError::Version,
                _ => PersistError::Crc,
            };
            assert_eq!(decode(&bad), Err(expect), "byte {byte} bit {bit}");
        }
    }
}

#[test]
fn truncation_is_rejected_and_extra_bytes_are_ignored() {
    let rec = encode(&model(), &map(), 87.25);
    for len in 0..RECORD_LEN {
        assert_eq!(decode(&rec[..len]), Err(PersistError::Length), "len {len}");
    }
    let mut page = [0xFFu8; 128];
    page[..RECORD_LEN].copy_from_slice(&rec);
    assert_eq!(decode(&page).unwrap().0, model());
}

#[test]
fn erased_and_zeroed_memory_is_not_a_record() {
    assert_eq!(decode(&[0xFF; RECORD_LEN]), Err(PersistError::Magic));
    assert_eq!(decode(&[0x00; RECORD_LEN]), Err(PersistError::Magic));
}

#[test]
fn other_versions_are_rejected_even_with_a_valid_crc() {
    // Version 1 is the 69-byte record of a model from duty to flow without a map.
    for v in [0u8, 1, 3, 0xFF] {
        let mut rec = encode(&model(), &map(), 87.25);
        rec[4] = v;
        reseal(&mut rec);
        assert_eq!(decode(&rec), Err(PersistError::Version), "version {v}");
    }
}

#[test]
fn invalid_structures_are_rejected_even_with_a_valid_crc() {
    // (byte, value): p = 0, p = 7, q = 0, q = 7, d = 7, offset flag 2.
    for (at, v) in [(5, 0u8), (5, 7), (6, 0), (6, 7), (7, 7), (8, 2)] {
        let mut rec = encode(&model(), &map(), 87.25);
        rec[at] = v;
        reseal(&mut rec);
        assert_eq!(
            decode(&rec),
            Err(PersistError::Structure),
            "byte {at} = {v}"
        );
    }
    // A non-zero unused θ slot (θ_4), φ slot (φ_2), and c without an intercept.
    for at in [21usize, 41] {
        let mut rec = encode(&model(), &map(), 87.25);
        rec[at..at + 4].copy_from_slice(&1.0f32.to_le_bytes());
        reseal(&mut rec);
        assert_eq!(decode(&rec), Err(PersistError::Structure), "slot at {at}");
    }
    let mut rec = encode(&model(), &map(), 87.25);
    rec[8] = 0;
    reseal(&mut rec);
    assert_eq!(decode(&rec), Err(PersistError::Structure));
}

#[test]
fn a_map_that_is_not_one_is_rejected_even_with_a_valid_crc() {
    // Spacing 0; a spacing that puts the last knot past 65 535; two equal knots; a knot below
    // the one before.
    let equal = (69 + 2 * 7, map().knots()[6]);
    let lower = (69 + 2 * 15, 0i16);
    let cases: [(usize, [u8; 2]); 4] = [
        (67, 0u16.to_le_bytes()),
        (67, 5_000u16.to_le_bytes()),
        (equal.0, equal.1.to_le_bytes()),
        (lower.0, lower.1.to_le_bytes()),
    ];
    for (at, bytes) in cases {
        let mut rec = encode(&model(), &map(), 87.25);
        rec[at..at + 2].copy_from_slice(&bytes);
        reseal(&mut rec);
        assert_eq!(decode(&rec), Err(PersistError::Map), "bytes {at}..");
    }
}

#[test]
fn non_finite_numbers_are_rejected_even_with_a_valid_crc() {
    // θ_1, φ_0, c, fit.
    for at in [9usize, 33, 57, 61] {
        for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut rec = encode(&model(), &map(), 87.25);
            rec[at..at + 4].copy_from_slice(&v.to_le_bytes());
            reseal(&mut rec);
            assert_eq!(decode(&rec), Err(PersistError::NonFinite), "at {at} = {v}");
        }
    }
}

#[test]
fn error_names() {
    let names: Vec<&str> = [
        PersistError::Length,
        PersistError::Magic,
        PersistError::Version,
        PersistError::Crc,
        PersistError::Structure,
        PersistError::NonFinite,
        PersistError::Map,
    ]
    .iter()
    .map(|e| e.name())
    .collect();
    assert_eq!(
        names,
        [
            "length",
            "magic",
            "version",
            "crc",
            "structure",
            "nonfinite",
            "map"
        ]
    );
}
