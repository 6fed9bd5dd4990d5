//! SFM3300 driver against a scripted I2C bus (`embedded-hal-mock`).
//!
//! Every expected CRC byte and flow value below was computed by hand from the datasheet facts in
//! Sensirion's documents (SFM3xxx I2C functional description and SF05 sample code: CRC-8 poly 0x31,
//! init 0x00; SFM3300 datasheet: flow = (raw − 32768) / 120 slm), not from the driver.

use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::i2c::{Mock, Transaction};
use ridge_pump_firmware::sfm3300::{
    counts_to_millislm, crc8, flow_millislm, in_range, raw_to_counts, Error, Sfm3300, ADDRESS,
    DEFAULT_READ_ATTEMPTS,
};

const NACK: ErrorKind = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);

fn start() -> Transaction {
    Transaction::write(0x40, vec![0x10, 0x00])
}

fn frame(bytes: [u8; 3]) -> Transaction {
    Transaction::read(0x40, bytes.to_vec())
}

fn nack() -> Transaction {
    Transaction::read(0x40, vec![0; 3]).with_error(NACK)
}

/// Runs `f` on a driver over a mock with `expectations`, then checks the mock was used up.
fn with_sensor<T>(expectations: &[Transaction], f: impl FnOnce(&mut Sfm3300<Mock>) -> T) -> T {
    let mut sensor = Sfm3300::new(Mock::new(expectations));
    let out = f(&mut sensor);
    let mut i2c = sensor.release();
    i2c.done();
    out
}

#[test]
fn address_is_0x40() {
    assert_eq!(ADDRESS, 0x40);
}

#[test]
fn new_sends_nothing() {
    with_sensor(&[], |_| ());
}

#[test]
fn start_continuous_sends_0x1000() {
    with_sensor(&[start()], |s| s.start_continuous()).unwrap();
}

#[test]
fn soft_reset_sends_0x2000() {
    with_sensor(&[Transaction::write(0x40, vec![0x20, 0x00])], |s| {
        s.soft_reset()
    })
    .unwrap();
}

#[test]
fn serial_number_sends_0x31ae_then_0x31af_and_joins_words() {
    // High word 0x1234 (CRC 0xB6), low word 0x5678 (CRC 0xFC), computed by hand.
    let expectations = [
        Transaction::write(0x40, vec![0x31, 0xAE]),
        frame([0x12, 0x34, 0xB6]),
        Transaction::write(0x40, vec![0x31, 0xAF]),
        frame([0x56, 0x78, 0xFC]),
    ];
    let serial = with_sensor(&expectations, |s| s.serial_number()).unwrap();
    assert_eq!(serial, 0x1234_5678);
}

#[test]
fn serial_number_bad_crc_is_crc_error_and_stops() {
    let expectations = [
        Transaction::write(0x40, vec![0x31, 0xAE]),
        frame([0x12, 0x34, 0xB7]),
    ];
    assert_eq!(
        with_sensor(&expectations, |s| s.serial_number()),
        Err(Error::Crc)
    );
}

#[test]
fn crc_vectors() {
    assert_eq!(crc8(&[0xBE, 0xEF]), 0x13);
    assert_eq!(crc8(&[0x80, 0x00]), 0x23);
}

#[test]
fn crc_vectors_accepted_on_the_wire() {
    let expectations = [frame([0xBE, 0xEF, 0x13]), frame([0x80, 0x00, 0x23])];
    with_sensor(&expectations, |s| {
        assert_eq!(s.read_raw(), Ok(0xBEEF));
        assert_eq!(s.read_raw(), Ok(0x8000));
    });
}

#[test]
fn bad_crc_is_crc_error() {
    assert_eq!(
        with_sensor(&[frame([0xBE, 0xEF, 0x12])], |s| s.read_raw()),
        Err(Error::Crc)
    );
    // A flipped data bit is caught too.
    assert_eq!(
        with_sensor(&[frame([0xBE, 0xEE, 0x13])], |s| s.read_raw()),
        Err(Error::Crc)
    );
}

#[test]
fn nack_then_success_is_ok_after_retry() {
    let expectations = [nack(), nack(), frame([0x80, 0x00, 0x23])];
    assert_eq!(with_sensor(&expectations, |s| s.read_raw()), Ok(0x8000));
}

#[test]
fn every_nack_kind_is_retried() {
    let expectations = [
        Transaction::read(0x40, vec![0; 3])
            .with_error(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data)),
        Transaction::read(0x40, vec![0; 3])
            .with_error(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Unknown)),
        frame([0x80, 0x00, 0x23]),
    ];
    assert_eq!(with_sensor(&expectations, |s| s.read_raw()), Ok(0x8000));
}

#[test]
fn nack_on_all_default_attempts_is_not_ready() {
    assert_eq!(DEFAULT_READ_ATTEMPTS, 3);
    let expectations = [nack(), nack(), nack()];
    assert_eq!(
        with_sensor(&expectations, |s| s.read_raw()),
        Err(Error::NotReady)
    );
}

#[test]
fn read_attempts_are_configurable() {
    let expectations = [nack(), nack(), nack(), nack(), nack()];
    let result = with_sensor(&expectations, |s| {
        s.set_read_attempts(5);
        assert_eq!(s.read_attempts(), 5);
        s.read_raw()
    });
    assert_eq!(result, Err(Error::NotReady));

    // Zero attempts would never read: it is raised to one.
    let result = with_sensor(&[nack()], |s| {
        s.set_read_attempts(0);
        assert_eq!(s.read_attempts(), 1);
        s.read_raw()
    });
    assert_eq!(result, Err(Error::NotReady));
}

#[test]
fn other_i2c_error_is_returned_at_once_without_retry() {
    let expectations = [Transaction::read(0x40, vec![0; 3]).with_error(ErrorKind::Bus)];
    assert_eq!(
        with_sensor(&expectations, |s| s.read_raw()),
        Err(Error::I2c(ErrorKind::Bus))
    );
}

#[test]
fn i2c_error_on_command_write_is_returned() {
    let expectations =
        [Transaction::write(0x40, vec![0x10, 0x00]).with_error(ErrorKind::ArbitrationLoss)];
    assert_eq!(
        with_sensor(&expectations, |s| s.start_continuous()),
        Err(Error::I2c(ErrorKind::ArbitrationLoss))
    );
}

#[test]
fn first_read_after_start_is_discarded() {
    let expectations = [
        start(),
        // Garbage first frame, CRC wrong too: discarded, not checked.
        frame([0xFF, 0xFF, 0x00]),
        // 32768 + 120 = 0x8078, CRC 0x62 by hand.
        frame([0x80, 0x78, 0x62]),
        // Next call reads once only.
        frame([0x80, 0x00, 0x23]),
    ];
    with_sensor(&expectations, |s| {
        s.start_continuous().unwrap();
        assert_eq!(s.read_raw(), Ok(0x8078));
        assert_eq!(s.read_raw(), Ok(0x8000));
    });
}

#[test]
fn discard_read_also_retries_nacks() {
    let expectations = [
        start(),
        nack(),
        frame([0x00, 0x00, 0x00]),
        nack(),
        frame([0x80, 0x78, 0x62]),
    ];
    assert_eq!(
        with_sensor(&expectations, |s| {
            s.start_continuous().unwrap();
            s.read_raw()
        }),
        Ok(0x8078)
    );
}

#[test]
fn discard_still_pending_after_not_ready_on_discard_read() {
    let expectations = [
        start(),
        nack(),
        nack(),
        nack(),
        // Second call: the discard read happens now.
        frame([0x12, 0x34, 0x00]),
        frame([0x80, 0x00, 0x23]),
    ];
    with_sensor(&expectations, |s| {
        s.start_continuous().unwrap();
        assert_eq!(s.read_raw(), Err(Error::NotReady));
        assert_eq!(s.read_raw(), Ok(0x8000));
    });
}

#[test]
fn discard_done_even_if_the_real_read_is_not_ready() {
    let expectations = [
        start(),
        frame([0x12, 0x34, 0x00]),
        nack(),
        nack(),
        nack(),
        // Next call reads once: no second discard.
        frame([0x80, 0x00, 0x23]),
    ];
    with_sensor(&expectations, |s| {
        s.start_continuous().unwrap();
        assert_eq!(s.read_raw(), Err(Error::NotReady));
        assert_eq!(s.read_raw(), Ok(0x8000));
    });
}

#[test]
fn read_counts_is_raw_minus_32768() {
    // 0x7F88 = 32648 = 32768 − 120 (CRC 0x61 by hand) → −120 counts = −1 slm.
    let expectations = [frame([0x7F, 0x88, 0x61]), frame([0x80, 0x78, 0x62])];
    with_sensor(&expectations, |s| {
        assert_eq!(s.read_counts(), Ok(-120));
        assert_eq!(s.read_counts(), Ok(120));
    });
}

#[test]
fn conversion_of_known_raw_words() {
    // flow [slm] = (raw − 32768) / 120, so milli-slm = (raw − 32768) · 1000 / 120.
    assert_eq!(flow_millislm(32_768), 0);
    // 120 counts = 1 slm.
    assert_eq!(flow_millislm(32_768 + 120), 1_000);
    assert_eq!(flow_millislm(32_768 - 120), -1_000);
    // raw 0: −32768 / 120 slm = −273.0666… slm = −273 066.67 milli-slm → rounds to −273 067.
    assert_eq!(flow_millislm(0), -273_067);
    // raw 65535: 32767 / 120 = 273.058333… slm → 273 058 milli-slm.
    assert_eq!(flow_millislm(u16::MAX), 273_058);
    // ±250 slm is ±30 000 counts.
    assert_eq!(flow_millislm(32_768 + 30_000), 250_000);
    assert_eq!(flow_millislm(32_768 - 30_000), -250_000);
    // One count is 8.333… milli-slm → 8; two counts 16.67 → 17; −1 count → −8.
    assert_eq!(flow_millislm(32_769), 8);
    assert_eq!(flow_millislm(32_770), 17);
    assert_eq!(flow_millislm(32_767), -8);
    assert_eq!(counts_to_millislm(-2), -17);
}

#[test]
fn raw_to_counts_of_known_words() {
    assert_eq!(raw_to_counts(0), -32_768);
    assert_eq!(raw_to_counts(32_768), 0);
    assert_eq!(raw_to_counts(u16::MAX), 32_767);
}

#[test]
fn range_is_plus_minus_250_slm() {
    assert!(in_range(32_768));
    assert!(in_range(2_768));
    assert!(in_range(62_768));
    assert!(!in_range(2_767));
    assert!(!in_range(62_769));
    assert!(!in_range(0));
}

#[test]
fn release_returns_the_bus() {
    let sensor = Sfm3300::new(Mock::new(&[]));
    let mut i2c = sensor.release();
    i2c.done();
}
