//! EEPROM storage of the self-identification record (ATmega2560: 4 KB EEPROM, ~3.4 ms per
//! byte write).
//!
//! Writing a whole record at once would block the 100 Hz loop for `3.4 ms × RECORD_LEN`, so
//! [`Eeprom::save`] only copies the record, and [`Eeprom::poll`] (once per tick) starts at most
//! one byte write when the EEPROM is idle. Bytes that already hold the right value are skipped
//! (no wear, no time); at the end the whole record is read back and compared, and a mismatch
//! restarts the write (up to [`ATTEMPTS`] times).
//!
//! The store starts at [`BASE`]: two slots ([`ridge_pump_firmware::slots`]), so that a reset or
//! power loss in the middle of a save, which leaves a mix of old and new bytes in the slot
//! being written, never loses the record in the other slot. This driver only reads the store
//! and writes one slot's bytes in address order.

use avr_device::atmega2560::EEPROM;

/// EEPROM address of the store (slot 0; slot 1 follows), defined in the library so that host
/// tools (`ridge-id identify --eeprom`) use the same one.
pub const BASE: u16 = ridge_pump_firmware::slots::EEPROM_BASE;

/// Write passes (each followed by a read-back) before a save is reported as failed.
pub const ATTEMPTS: u8 = 3;

// EECR bits.
const EERE: u8 = 1 << 0;
const EEPE: u8 = 1 << 1;

/// The EEPROM with a background writer for `N` bytes (one slot) at a time.
pub struct Eeprom<const N: usize> {
    ee: EEPROM,
    buf: [u8; N],
    /// Address of `buf`'s first byte.
    at: u16,
    next: usize,
    attempts_left: u8,
}

impl<const N: usize> Eeprom<N> {
    /// Takes the EEPROM; nothing pending.
    pub fn new(ee: EEPROM) -> Self {
        Eeprom {
            ee,
            buf: [0xFF; N],
            at: BASE,
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

    /// The byte at `offset` from [`BASE`] (outside the slots: the reset count).
    pub fn byte(&mut self, offset: u16) -> u8 {
        self.read_byte(BASE + offset)
    }

    /// Starts writing `byte` at `offset` from [`BASE`] if the EEPROM is idle and no save is in
    /// progress (`true`), else does nothing (`false`: try again later). Takes 3.4 ms in the
    /// background, like a slot byte.
    pub fn put(&mut self, offset: u16, byte: u8) -> bool {
        if self.pending() || self.busy() {
            return false;
        }
        if self.read_byte(BASE + offset) != byte {
            self.start_write(BASE + offset, byte);
        }
        true
    }

    /// Reads the `M` bytes of the store.
    pub fn load<const M: usize>(&mut self) -> [u8; M] {
        let mut store = [0u8; M];
        for (i, byte) in store.iter_mut().enumerate() {
            *byte = self.read_byte(BASE + i as u16);
        }
        store
    }

    /// Queues `body` then `last` (`N` bytes in all) for writing at `offset` from [`BASE`] (a
    /// save in progress is superseded). Ignored unless `body` has `N − 1` bytes.
    pub fn save(&mut self, offset: u16, body: &[u8], last: u8) {
        if body.len() + 1 == N {
            for (slot, &b) in self.buf.iter_mut().zip(body) {
                *slot = b;
            }
            if let Some(slot) = self.buf.last_mut() {
                *slot = last;
            }
            self.at = BASE + offset;
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
            let address = self.at + i as u16;
            if self.read_byte(address) != self.buf[i] {
                self.start_write(address, self.buf[i]);
                return None;
            }
        }
        // Pass complete and the last write finished: verify everything.
        let (buf, at) = (self.buf, self.at);
        let mismatch = (0..N).any(|i| self.read_byte(at + i as u16) != buf[i]);
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
