//! The embedded flash memory and its interface (RM0383 §3): the 512 KB main memory of the
//! STM32F411CE in sectors 0–7 (§3.3, Table 4), the interface registers (§3.8), the unlock,
//! program and sector-erase sequences (§3.5), and the flash-size word of the device electronic
//! signature (§24.2).
//!
//! Modelled:
//! - `FLASH_ACR` (§3.8.1) is stored. Simplification: its wait states (LATENCY) and the ART
//!   accelerator cost nothing: emulated time comes from instruction counts (see the crate
//!   docs).
//! - `FLASH_KEYR` (§3.8.2, §3.5.1): KEY1 = 0x4567_0123 then KEY2 = 0xCDEF_89AB clears
//!   `FLASH_CR.LOCK`; a wrong sequence locks `FLASH_CR` until the next reset (the chip also
//!   returns a bus error: here it is counted in [`Flash::errors`]).
//! - `FLASH_CR` (§3.8.5): PG, SER, MER, SNB, PSIZE, STRT, EOPIE, ERRIE, LOCK (set by writing
//!   1; cleared only by the key sequence). Writes are ignored while locked.
//! - `FLASH_SR` (§3.8.4): EOP, OPERR, WRPERR, PGAERR, PGPERR, PGSERR (rc_w1: writing 1 clears),
//!   BSY (read-only).
//! - programming (§3.5.4): with PG set, a write of PSIZE's width (x8/x16/x32) into the main
//!   memory programs it; a programmed bit can only go from 1 to 0 (the result is old AND new);
//!   a write without PG (or with SER/MER set too) sets PGSERR, one of another width PGPERR,
//!   one across a 128-bit row PGAERR, and programs nothing. EOP is set at the end of a
//!   successful operation only if EOPIE is set (§3.8.4).
//! - sector erase (§3.5.3): SER with SNB, then STRT, sets the sector to 0xFF. Mass erase and
//!   the option bytes are not modelled (an attempt is reported as unmodelled).
//! - busy time: an operation keeps BSY set for its duration, and since the image runs from
//!   this flash, a CPU fetch stalls until it ends (§3.5: "any attempt to read the Flash memory
//!   while it is being written or erased causes the bus to stall"); the machine models the
//!   stall by advancing emulated time by the duration at the write that starts the operation.
//!   Durations are the typical values of the STM32F411xC/E datasheet (DS10314, "Flash memory
//!   programming"): 16 µs per program access, sector erase at x8 parallelism 400 ms (16 KB),
//!   1.2 s (64 KB), 2 s (128 KB). Simplification: the x16/x32 erase times are taken equal to
//!   x8's (the image erases at x8).
//! - an erase cut by a power loss ([`Flash::erase_cut`], armed by the bench): the chip makes
//!   no promise about the sector then. Modelled as an erase a fraction `f` of the way through:
//!   every 0 bit of the sector has risen to 1 with probability `f` (seeded noise), and the
//!   power goes at `f` of the erase time ([`Effect::power_cut`]).

use super::{Time, Unmodelled};

/// Base address of the main memory.
pub const BASE: u32 = 0x0800_0000;
/// Main memory size of the STM32F411CE, bytes.
pub const SIZE: u32 = 512 * 1024;
/// Value of the flash-size word at 0x1FFF_7A22 (§24.2), KB.
pub const SIZE_KB: u16 = 512;
/// Address of the flash-size word.
pub const FLASH_SIZE_ADDR: u32 = 0x1FFF_7A22;
/// Address of the 96-bit unique device ID (§24.1).
pub const UID_ADDR: u32 = 0x1FFF_7A10;

/// Erased state of a flash byte.
pub const ERASED: u8 = 0xFF;
/// Typical time of one program access (DS10314), ps.
pub const PROGRAM_PS: Time = 16_000_000;

/// Sector start offsets and sizes (§3.3, Table 4): 4 × 16 KB, 64 KB, 3 × 128 KB.
pub const SECTORS: [(u32, u32); 8] = [
    (0x0_0000, 0x4000),
    (0x0_4000, 0x4000),
    (0x0_8000, 0x4000),
    (0x0_C000, 0x4000),
    (0x1_0000, 0x1_0000),
    (0x2_0000, 0x2_0000),
    (0x4_0000, 0x2_0000),
    (0x6_0000, 0x2_0000),
];

/// Typical sector erase time for a sector of `size` bytes (DS10314, x8), ps.
pub fn erase_ps(size: u32) -> Time {
    const MS: Time = 1_000_000_000;
    match size {
        0x4000 => 400 * MS,
        0x1_0000 => 1_200 * MS,
        _ => 2_000 * MS,
    }
}

/// Register offsets (§3.8.7, register map).
pub const ACR: u32 = 0x00;
/// Key register.
pub const KEYR: u32 = 0x04;
/// Option key register.
pub const OPTKEYR: u32 = 0x08;
/// Status register.
pub const SR: u32 = 0x0C;
/// Control register.
pub const CR: u32 = 0x10;
/// Option control register.
pub const OPTCR: u32 = 0x14;

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;

// FLASH_SR (§3.8.4).
/// End of operation.
pub const SR_EOP: u32 = 1 << 0;
/// Operation error.
pub const SR_OPERR: u32 = 1 << 1;
/// Write protection error.
pub const SR_WRPERR: u32 = 1 << 4;
/// Programming alignment error.
pub const SR_PGAERR: u32 = 1 << 5;
/// Programming parallelism error.
pub const SR_PGPERR: u32 = 1 << 6;
/// Programming sequence error.
pub const SR_PGSERR: u32 = 1 << 7;
/// Busy.
pub const SR_BSY: u32 = 1 << 16;
const SR_W1C: u32 = SR_EOP | SR_OPERR | SR_WRPERR | SR_PGAERR | SR_PGPERR | SR_PGSERR;

// FLASH_CR (§3.8.5).
/// Programming.
pub const CR_PG: u32 = 1 << 0;
/// Sector erase.
pub const CR_SER: u32 = 1 << 1;
/// Mass erase.
pub const CR_MER: u32 = 1 << 2;
/// Start (erase).
pub const CR_STRT: u32 = 1 << 16;
/// End-of-operation interrupt enable.
pub const CR_EOPIE: u32 = 1 << 24;
/// Lock.
pub const CR_LOCK: u32 = 1 << 31;

/// One program access that changed the memory, in order (for power-cut tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Programmed {
    /// When it started.
    pub at: Time,
    /// Offset from [`BASE`].
    pub offset: u32,
    /// Bytes (1, 2 or 4).
    pub size: u8,
    /// Value written (the memory holds old AND value).
    pub value: u32,
}

/// What an access did to the memory, for the machine to mirror and time.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Effect {
    /// Byte range of the memory changed (offset, length).
    pub changed: Option<(u32, u32)>,
    /// The CPU stalls this long (the operation's busy time), ps.
    pub stall: Time,
    /// The power goes at the end of the stall (an erase cut, [`Flash::erase_cut`]).
    pub power_cut: bool,
}

/// An erase to cut by a power loss: how far it gets, and the noise's seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EraseCut {
    /// Fraction of the erase done, 0..=1: each 0 bit has risen with this probability.
    pub fraction: f64,
    /// Seed of the bits' noise.
    pub seed: u64,
}

/// The flash memory and its interface.
#[derive(Clone, Debug)]
pub struct Flash {
    /// Main memory contents (offset 0 = [`BASE`]).
    pub mem: Vec<u8>,
    acr: u32,
    sr: u32,
    cr: u32,
    optcr: u32,
    /// Keys written so far in the unlock sequence.
    key_step: u8,
    /// A wrong key sequence locked `FLASH_CR` until reset.
    lockout: bool,
    busy_until: Time,
    /// Program accesses that changed the memory.
    pub programmed: Vec<Programmed>,
    /// Sector erases done: (time, sector).
    pub erased: Vec<(Time, u8)>,
    /// Protocol errors seen (wrong key, program without PG, …), in words.
    pub errors: Vec<String>,
    /// The next sector erase is cut by a power loss (see the module docs).
    pub erase_cut: Option<EraseCut>,
}

impl Default for Flash {
    fn default() -> Self {
        Self::new()
    }
}

impl Flash {
    /// An erased chip.
    pub fn new() -> Self {
        Flash {
            mem: vec![ERASED; SIZE as usize],
            acr: 0,
            sr: 0,
            cr: CR_LOCK,
            optcr: 0x0FFF_AAED,
            key_step: 0,
            lockout: false,
            busy_until: 0,
            programmed: Vec::new(),
            erased: Vec::new(),
            errors: Vec::new(),
            erase_cut: None,
        }
    }

    /// System reset: registers to their reset values (§3.8), memory kept.
    pub fn reset(&mut self) {
        self.acr = 0;
        self.sr = 0;
        self.cr = CR_LOCK;
        self.key_step = 0;
        self.lockout = false;
        self.busy_until = 0;
    }

    /// Writes `bytes` at `offset` directly (what a flasher does), without the interface.
    pub fn load(&mut self, offset: u32, bytes: &[u8]) -> Result<(), String> {
        let o = offset as usize;
        let dst = self
            .mem
            .get_mut(o..o + bytes.len())
            .ok_or_else(|| format!("segment at {offset:#x} outside the flash"))?;
        dst.copy_from_slice(bytes);
        Ok(())
    }

    /// Interface register read at `now`.
    pub fn read(&mut self, off: u32, now: Time) -> Result<u32, Unmodelled> {
        Ok(match off {
            ACR => self.acr,
            KEYR | OPTKEYR => 0,
            SR => {
                let bsy = if now < self.busy_until { SR_BSY } else { 0 };
                self.sr | bsy
            }
            CR => self.cr,
            OPTCR => self.optcr,
            _ => return Err(Unmodelled),
        })
    }

    /// Interface register write at `now`; returns what the write did to the memory.
    pub fn write(&mut self, off: u32, v: u32, now: Time) -> Result<Effect, Unmodelled> {
        match off {
            // LATENCY 3:0, PRFTEN 8, ICEN 9, DCEN 10; ICRST/DCRST (11, 12) read as 0.
            ACR => self.acr = v & 0x70F,
            KEYR => self.key(v),
            SR => self.sr &= !(v & SR_W1C),
            CR => return self.control(v, now),
            OPTKEYR | OPTCR => return Err(Unmodelled),
            _ => return Err(Unmodelled),
        }
        Ok(Effect::default())
    }

    fn key(&mut self, v: u32) {
        if self.lockout || self.cr & CR_LOCK == 0 {
            // A key written while unlocked is a wrong sequence too (§3.5.1).
            self.wrong_key(v);
            return;
        }
        match (self.key_step, v) {
            (0, KEY1) => self.key_step = 1,
            (1, KEY2) => {
                self.key_step = 0;
                self.cr &= !CR_LOCK;
            }
            _ => self.wrong_key(v),
        }
    }

    fn wrong_key(&mut self, v: u32) {
        self.key_step = 0;
        self.lockout = true;
        self.cr |= CR_LOCK;
        self.errors.push(format!(
            "wrong key sequence ({v:#010x}): FLASH_CR locked until reset"
        ));
    }

    fn control(&mut self, v: u32, now: Time) -> Result<Effect, Unmodelled> {
        if self.cr & CR_LOCK != 0 {
            // Locked: only LOCK itself stays set; nothing else changes.
            return Ok(Effect::default());
        }
        // Writable: PG 0, SER 1, MER 2, SNB 6:3, PSIZE 9:8, STRT 16, EOPIE 24, ERRIE 25, LOCK 31.
        const W: u32 = 0x7 | (0xF << 3) | (3 << 8) | CR_STRT | (3 << 24) | CR_LOCK;
        self.cr = v & W;
        if v & CR_MER != 0 && v & CR_STRT != 0 {
            return Err(Unmodelled);
        }
        if v & CR_STRT == 0 {
            return Ok(Effect::default());
        }
        // STRT: start an erase (§3.5.3); cleared when the operation ends.
        self.cr &= !CR_STRT;
        if v & CR_SER == 0 || v & CR_PG != 0 {
            self.sr |= SR_PGSERR;
            self.errors.push("STRT without SER (or with PG)".into());
            return Ok(Effect::default());
        }
        let snb = (v >> 3) & 0xF;
        let Some(&(start, len)) = SECTORS.get(snb as usize) else {
            self.sr |= SR_PGSERR;
            self.errors
                .push(format!("erase of sector {snb}: no such sector"));
            return Ok(Effect::default());
        };
        let sector = &mut self.mem[start as usize..(start + len) as usize];
        let busy = erase_ps(len);
        self.erased.push((now, snb as u8));
        if let Some(cut) = self.erase_cut.take() {
            let mut noise = cut.seed | 1;
            for b in sector.iter_mut() {
                for bit in 0..8 {
                    // xorshift64*, 53 bits to a uniform in [0, 1).
                    noise ^= noise >> 12;
                    noise ^= noise << 25;
                    noise ^= noise >> 27;
                    let u = (noise.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64
                        / (1u64 << 53) as f64;
                    if u < cut.fraction {
                        *b |= 1 << bit;
                    }
                }
            }
            return Ok(Effect {
                changed: Some((start, len)),
                stall: (busy as f64 * cut.fraction.clamp(0.0, 1.0)) as Time,
                power_cut: true,
            });
        }
        sector.fill(ERASED);
        self.busy_until = now.max(self.busy_until) + busy;
        if self.cr & CR_EOPIE != 0 {
            self.sr |= SR_EOP;
        }
        Ok(Effect {
            changed: Some((start, len)),
            stall: busy,
            power_cut: false,
        })
    }

    /// A CPU write of `size` bytes of `value` at `offset` into the main memory at `now`.
    pub fn program(&mut self, offset: u32, size: u8, value: u32, now: Time) -> Effect {
        let psize = match (self.cr >> 8) & 3 {
            0 => 1,
            1 => 2,
            _ => 4,
        };
        if self.cr & CR_PG == 0 || self.cr & (CR_SER | CR_MER) != 0 {
            self.sr |= SR_PGSERR;
            self.errors.push(format!(
                "write to flash +{offset:#x} without PG (FLASH_CR {:#x})",
                self.cr
            ));
            return Effect::default();
        }
        if size != psize {
            self.sr |= SR_PGPERR;
            self.errors.push(format!(
                "{size}-byte write with PSIZE of {psize} bytes at +{offset:#x}"
            ));
            return Effect::default();
        }
        if offset / 16 != (offset + u32::from(size) - 1) / 16 {
            self.sr |= SR_PGAERR;
            self.errors
                .push(format!("write across a 128-bit row at +{offset:#x}"));
            return Effect::default();
        }
        for k in 0..u32::from(size) {
            let b = (value >> (8 * k)) as u8;
            if let Some(m) = self.mem.get_mut((offset + k) as usize) {
                *m &= b;
            }
        }
        self.programmed.push(Programmed {
            at: now,
            offset,
            size,
            value,
        });
        self.busy_until = now.max(self.busy_until) + PROGRAM_PS;
        if self.cr & CR_EOPIE != 0 {
            self.sr |= SR_EOP;
        }
        Effect {
            changed: Some((offset, u32::from(size))),
            stall: PROGRAM_PS,
            power_cut: false,
        }
    }

    /// Reads of the device electronic signature area (§24): the flash-size word and the
    /// unique ID (a fixed value here).
    pub fn signature(addr: u32, size: u32) -> Result<u32, Unmodelled> {
        const UID: [u8; 12] = *b"ridge-pump00";
        if addr == FLASH_SIZE_ADDR && size <= 2 {
            return Ok(u32::from(SIZE_KB) & if size == 1 { 0xFF } else { 0xFFFF });
        }
        if (UID_ADDR..UID_ADDR + 12).contains(&addr) && addr + size <= UID_ADDR + 12 {
            let o = (addr - UID_ADDR) as usize;
            let mut v = 0u32;
            for k in 0..size as usize {
                v |= u32::from(UID[o + k]) << (8 * k);
            }
            return Ok(v);
        }
        Err(Unmodelled)
    }
}
