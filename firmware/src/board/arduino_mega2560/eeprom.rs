//! EEPROM storage of the self-identification record (ATmega2560: 4 KB EEPROM, ~3.4 ms per
//! byte write).
//!
//! Writing a whole record at once would block the 100 Hz loop for `3.4 ms × RECORD_LEN`, so
//! [`Eeprom::save`] only copies the record, and [`Eeprom::poll`] (once per tick) starts at most
//! one byte write when the EEPROM is idle. Bytes that already hold the right value are skipped
//! (no wear, no time); at the end the whole record is read back and compared, and a mismatch
//! restarts the write (up to [`ATTEMPTS`] times).
//!
//! The record sits at [`BASE`]. It carries no framing of its own here: the state machine's
//! record is expected to validate itself (magic/version/CRC), since a reset or power loss in the
//! middle of a save leaves a mix of old and new bytes. An erased EEPROM (all `0xFF`) is reported
//! as "no record".

use avr_device::atmega2560::EEPROM;

/// EEPROM address of the record (defined in the library, so that host tools use the same one).
pub const BASE: u16 = ridge_pump_firmware::persist::EEPROM_ADDRESS;

/// Write passes (each followed by a read-back) before a save is reported as failed.
pub const ATTEMPTS: u8 = 3;

// EECR bits.
const EERE: u8 = 1 << 0;
const EEPE: u8 = 1 << 1;

/// The EEPROM with a background writer for one record of `N` bytes.
pub struct Eeprom<const N: usize> {
    ee: EEPROM,
    buf: [u8; N],
    next: usize,
    attempts_left: u8,
}

impl<const N: usize> Eeprom<N> {
    /// Takes the EEPROM; nothing pending.
    pub fn new(ee: EEPROM) -> Self {
        Eeprom {
            ee,
            buf: [0xFF; N],
            next: 0,
            attempts_left: 0,
        }
    }

    fn busy(&self) -> bool {
        self.ee.eecr().read().bits() & EEPE != 0
    }

    /// Reads one byte, waiting for a write in progress to finish (≤ 3.4 ms).
    fn read_byte(&mut self, address: u16) -> u8 {
        while self.busy() {}
        self.ee.eear().write(|w| unsafe { w.bits(address) });
        self.ee.eecr().write(|w| unsafe { w.bits(EERE) });
        self.ee.eedr().read().bits()
    }

    /// Starts writing one byte (the EEPROM must be idle).
    fn start_write(&mut self, address: u16, byte: u8) {
        self.ee.eear().write(|w| unsafe { w.bits(address) });
        self.ee.eedr().write(|w| unsafe { w.bits(byte) });
        avr_device::interrupt::free(|_| {
            // EEPE must be set within 4 cycles of EEMPE (EECR is I/O address 0x1F; EEMPE is bit
            // 2, EEPE bit 1; EEPM = 00: erase and write in one operation). Two `sbi` do that.
            // SAFETY: only sets the two EEPROM control bits; interrupts are off.
            unsafe { core::arch::asm!("sbi 0x1f, 2", "sbi 0x1f, 1", options(nostack)) };
        });
    }

    /// Reads the stored record; `None` if the EEPROM is erased there (all `0xFF`).
    pub fn load(&mut self) -> Option<[u8; N]> {
        let mut record = [0u8; N];
        for (i, slot) in record.iter_mut().enumerate() {
            *slot = self.read_byte(BASE + i as u16);
        }
        if record.iter().all(|&b| b == 0xFF) {
            None
        } else {
            Some(record)
        }
    }

    /// Queues `record` for writing (a save in progress is superseded). Records of another
    /// length than `N` are ignored.
    pub fn save(&mut self, record: &[u8]) {
        if record.len() == N {
            self.buf.copy_from_slice(record);
            self.next = 0;
            self.attempts_left = ATTEMPTS;
        }
    }

    /// Whether a save is in progress.
    pub fn pending(&self) -> bool {
        self.attempts_left > 0
    }

    /// Call once per tick: starts at most one byte write. `Some(ok)` once, when a save ended
    /// (`true`: read back equal; `false`: still different after [`ATTEMPTS`] passes).
    pub fn poll(&mut self) -> Option<bool> {
        if !self.pending() || self.busy() {
            return None;
        }
        while self.next < N {
            let i = self.next;
            self.next += 1;
            let address = BASE + i as u16;
            if self.read_byte(address) != self.buf[i] {
                self.start_write(address, self.buf[i]);
                return None;
            }
        }
        // Pass complete and the last write finished: verify everything.
        let buf = self.buf;
        let mismatch = (0..N).any(|i| self.read_byte(BASE + i as u16) != buf[i]);
        self.attempts_left -= 1;
        if !mismatch {
            self.attempts_left = 0;
            Some(true)
        } else if self.attempts_left == 0 {
            Some(false)
        } else {
            self.next = 0;
            None
        }
    }
}
