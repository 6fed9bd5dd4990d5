//! A thin, safe wrapper over simavr (`simavr-ffi`, the simavr that `avr-tester` builds from
//! source, with its TWI fixes) that exposes what `avr-tester` keeps private: the cycle counter,
//! data space (I/O registers, SRAM), EEPROM, interrupt and pin events with cycle stamps.
//!
//! - `mod.rs`: the core ([`Machine`]): made from an ELF, run cycle by cycle, its memories and
//!   symbols read and written.
//! - `hooks.rs`: what the harness attaches to it: IRQ, pin, TWI, UART and register-write
//!   callbacks with their cycle stamps ([`Machine::watch_pin`], [`Machine::attach_twi`],
//!   [`Machine::intercept_write`], [`Machine::uart_input`] …).
//!
//! Everything runs on the calling thread: simavr calls back into the notification functions
//! from inside [`Machine::step`], and they only touch state owned by the [`Machine`].

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::ffi::{c_void, CString};
use std::path::Path;
use std::ptr::NonNull;
use std::rc::Rc;

use simavr_ffi as ffi;

mod hooks;

pub use hooks::{
    twi_decode, twi_encode, uart_base, ExternalPins, IoWrite, IrqEvent, PinEdge, UartByte,
};

/// `AVR_IOCTL_DEF(a, b, c, d)` of simavr's `sim_io.h`.
const fn ioctl(a: u8, b: u8, c: u8, d: u8) -> u32 {
    u32::from_be_bytes([a, b, c, d])
}

extern "C" {
    fn free(p: *mut c_void);
    fn vsnprintf(
        buf: *mut std::ffi::c_char,
        n: usize,
        fmt: *const std::ffi::c_char,
        ap: *mut ffi::__va_list_tag,
    ) -> i32;
}

/// simavr's logger: errors to stderr, prefixed; the rest (firmware loading, warnings such as
/// OCR writes while a timer is stopped, traces) dropped.
unsafe extern "C" fn logger(
    _avr: *mut ffi::avr_t,
    level: i32,
    fmt: *const std::ffi::c_char,
    ap: *mut ffi::__va_list_tag,
) {
    if level != ffi::LOG_ERROR as i32 {
        return;
    }
    let mut buf = [0 as std::ffi::c_char; 512];
    // SAFETY: `fmt`/`ap` come from simavr's printf-style logging call; `buf` bounds the output.
    unsafe { vsnprintf(buf.as_mut_ptr(), buf.len(), fmt, ap) };
    // SAFETY: vsnprintf NUL-terminates within `buf`.
    let msg = unsafe { std::ffi::CStr::from_ptr(buf.as_ptr()) };
    eprint!("simavr: {}", msg.to_string_lossy());
}

/// Why a run stopped before its target cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Halt {
    /// The core reached its target cycle (still running).
    Reached,
    /// The program ended (`cpu_Done`: e.g. `cli; sleep`).
    Done,
    /// simavr detected an invalid instruction or similar.
    Crashed,
}

/// simavr's raw run loop calls `avr->sleep` while the core sleeps, which paces the host to real
/// time (`usleep`). The harness wants simulated time only.
unsafe extern "C" fn no_sleep(_avr: *mut ffi::avr_t, _how_long: ffi::avr_cycle_count_t) {}

/// An ELF symbol (name, address as simavr reports it: data symbols at `0x800000 + addr`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Symbol {
    /// Name.
    pub name: String,
    /// Address.
    pub addr: u32,
    /// Size in bytes.
    pub size: u32,
}

/// One simulated AVR with a loaded firmware.
pub struct Machine {
    avr: NonNull<ffi::avr_t>,
    /// simavr restarts `avr->cycle` at 0 on every reset (watchdog, `avr_reset`): cycles before
    /// the last reset, so that [`Machine::cycle`] is monotonic.
    base: Rc<Cell<u64>>,
    resets: Vec<u64>,
    uart0: Rc<RefCell<Vec<UartByte>>>,
    symbols: Vec<Symbol>,
    sleep_cycles: u64,
    /// Owned callback states (freed on drop).
    frees: Vec<Box<dyn FnOnce()>>,
    pins: HashMap<(char, u8), Rc<RefCell<Vec<PinEdge>>>>,
    /// False once the core is freed (checked by [`ExternalPins`]).
    alive: Rc<Cell<bool>>,
}

impl std::fmt::Debug for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Machine")
            .field("cycle", &self.cycle())
            .finish()
    }
}

impl Machine {
    /// Creates core `mcu` (e.g. `"atmega2560"`) at `frequency` Hz and loads the ELF at `elf`.
    pub fn new(mcu: &str, frequency: u32, elf: &Path) -> Result<Self, String> {
        let c_mcu = CString::new(mcu).map_err(|e| e.to_string())?;
        let c_path = CString::new(elf.to_string_lossy().as_bytes()).map_err(|e| e.to_string())?;
        if !elf.is_file() {
            return Err(format!("no such firmware: {}", elf.display()));
        }
        // SAFETY: plain C constructors; every pointer is checked before use.
        unsafe {
            ffi::avr_global_logger_set(Some(logger));
            let avr = NonNull::new(ffi::avr_make_mcu_by_name(c_mcu.as_ptr()))
                .ok_or_else(|| format!("simavr does not know the MCU {mcu}"))?;
            let rc = ffi::avr_init(avr.as_ptr());
            if rc != 0 {
                return Err(format!("avr_init failed ({rc})"));
            }
            let fw: *mut ffi::elf_firmware_t =
                Box::into_raw(Box::new(std::mem::zeroed::<ffi::elf_firmware_t>()));
            let rc = ffi::elf_read_firmware(c_path.as_ptr(), fw);
            if rc != 0 {
                drop(Box::from_raw(fw));
                return Err(format!("simavr could not read {} ({rc})", elf.display()));
            }
            let mut symbols = Vec::new();
            for i in 0..(*fw).symbolcount as usize {
                let s = *(*fw).symbol.add(i);
                if s.is_null() {
                    continue;
                }
                let name = std::ffi::CStr::from_ptr((*s).symbol.as_ptr())
                    .to_string_lossy()
                    .into_owned();
                symbols.push(Symbol {
                    name,
                    addr: (*s).addr,
                    size: (*s).size,
                });
            }
            ffi::avr_load_firmware(avr.as_ptr(), fw);
            // The firmware struct and its symbol table stay referenced by simavr's trace data:
            // leak them (a few KB per machine).
            (*avr.as_ptr()).frequency = frequency;
            (*avr.as_ptr()).sleep = Some(no_sleep);

            let mut m = Machine {
                avr,
                base: Rc::new(Cell::new(0)),
                resets: Vec::new(),
                uart0: Rc::new(RefCell::new(Vec::new())),
                symbols,
                sleep_cycles: 0,
                frees: Vec::new(),
                pins: HashMap::new(),
                alive: Rc::new(Cell::new(true)),
            };
            m.hook_uart('0')?;
            Ok(m)
        }
    }

    fn raw(&self) -> *mut ffi::avr_t {
        self.avr.as_ptr()
    }

    fn leak<T: 'static>(&mut self, value: T) -> *mut T {
        let p = Box::into_raw(Box::new(value));
        let addr = p as usize;
        self.frees.push(Box::new(move || {
            // SAFETY: `addr` came from `Box::into_raw` above and is freed once, after the core
            // is terminated.
            drop(unsafe { Box::from_raw(addr as *mut T) });
        }));
        p
    }

    /// Core cycles since power-up (monotonic across resets).
    pub fn cycle(&self) -> u64 {
        self.base.get() + self.raw_cycle()
    }

    fn raw_cycle(&self) -> u64 {
        // SAFETY: plain field read of a live core.
        unsafe { (*self.raw()).cycle }
    }

    /// Cycles (monotonic) at which the core was reset (watchdog or [`Machine::reset`]).
    pub fn resets(&self) -> &[u64] {
        &self.resets
    }

    /// Clock frequency, Hz.
    pub fn frequency(&self) -> u32 {
        // SAFETY: plain field read of a live core.
        unsafe { (*self.raw()).frequency }
    }

    /// Program counter (bytes).
    pub fn pc(&self) -> u32 {
        // SAFETY: plain field read of a live core.
        unsafe { (*self.raw()).pc }
    }

    /// Continues execution at byte address `pc` (between two instructions): for tests that
    /// enter a handler the firmware reaches only on a failure, such as its panic handler.
    pub fn jump(&mut self, pc: u32) {
        // SAFETY: plain field write of a live core, between instructions.
        unsafe { (*self.raw()).pc = pc }
    }

    /// Global interrupt enable (SREG.I): false inside interrupt handlers and critical
    /// sections.
    pub fn interrupts_enabled(&self) -> bool {
        // SAFETY: plain field read (simavr keeps SREG split into `sreg[]`).
        unsafe { (*self.raw()).sreg[7] != 0 }
    }

    /// Cycles spent in SLEEP so far.
    pub fn sleep_cycles(&self) -> u64 {
        self.sleep_cycles
    }

    /// Runs one instruction (or one sleep interval).
    pub fn step(&mut self) -> Halt {
        let raw_before = self.raw_cycle();
        let before = self.cycle();
        // SAFETY: running a live core; callbacks only touch state owned by `self`.
        let state = unsafe { ffi::avr_run(self.raw()) } as u32;
        if self.raw_cycle() < raw_before {
            // Reset during this step: continue counting from where the core was.
            self.base.set(self.base.get() + raw_before);
            self.resets.push(before);
        }
        let after = self.cycle();
        match state {
            ffi::cpu_Done | ffi::cpu_Stopped => Halt::Done,
            ffi::cpu_Crashed => Halt::Crashed,
            ffi::cpu_Sleeping => {
                self.sleep_cycles += after - before;
                Halt::Reached
            }
            _ => Halt::Reached,
        }
    }

    /// Runs until the core cycle reaches `cycle` (or the program stops).
    pub fn run_until(&mut self, cycle: u64) -> Halt {
        while self.cycle() < cycle {
            match self.step() {
                Halt::Reached => {}
                h => return h,
            }
        }
        Halt::Reached
    }

    /// One byte of data space (registers, I/O, SRAM): `addr` as in the datasheet's data map.
    pub fn data(&self, addr: u16) -> u8 {
        // SAFETY: `data` is `ramend + 1` bytes; bounds are checked.
        unsafe {
            let avr = &*self.raw();
            if addr > avr.ramend {
                return 0;
            }
            *avr.data.add(addr.into())
        }
    }

    /// Program word at byte address `addr` (little-endian, as the core fetches it); `None`
    /// beyond the end of flash.
    pub fn flash_word(&self, addr: u32) -> Option<u16> {
        // SAFETY: `flash` is `flashend + 1` bytes; bounds are checked.
        unsafe {
            let avr = &*self.raw();
            if addr.checked_add(1)? > avr.flashend {
                return None;
            }
            let lo = *avr.flash.add(addr as usize);
            let hi = *avr.flash.add(addr as usize + 1);
            Some(u16::from_le_bytes([lo, hi]))
        }
    }

    /// Byte addresses of every `STS k, Rr` instruction in flash whose data address `k` is in
    /// `targets` (the 32-bit `STS`: `1001 001r rrrr 0000`, then `k`). Scanned word by word, so
    /// a second instruction word that happens to look like `STS` can be listed too; it is
    /// never executed as an instruction start, so callers matching executed addresses are not
    /// misled.
    pub fn sts_sites(&self, targets: &[u16]) -> Vec<u32> {
        let mut sites = Vec::new();
        let mut addr = 0u32;
        while let (Some(op), Some(k)) = (self.flash_word(addr), self.flash_word(addr + 2)) {
            if op & 0xFE0F == 0x9200 && targets.contains(&k) {
                sites.push(addr);
            }
            addr += 2;
        }
        sites
    }

    /// Little-endian 16-bit word at `addr` (low byte first, as AVR 16-bit registers).
    pub fn data16(&self, addr: u16) -> u16 {
        u16::from_le_bytes([self.data(addr), self.data(addr + 1)])
    }

    /// Writes one byte of SRAM (not I/O: no peripheral side effects).
    pub fn poke(&mut self, addr: u16, v: u8) {
        // SAFETY: bounds checked.
        unsafe {
            let avr = &mut *self.raw();
            if addr <= avr.ramend {
                *avr.data.add(addr.into()) = v;
            }
        }
    }

    /// Last SRAM address (`RAMEND`).
    pub fn ramend(&self) -> u16 {
        // SAFETY: plain field read.
        unsafe { (*self.raw()).ramend }
    }

    /// Stack pointer.
    pub fn sp(&self) -> u16 {
        self.data16(0x5D)
    }

    fn eeprom_desc(&self) -> Option<ffi::avr_eeprom_desc_t> {
        // SAFETY: plain field read.
        let size = unsafe { (*self.raw()).e2end } + 1;
        let mut d = ffi::avr_eeprom_desc_t {
            ee: std::ptr::null_mut(),
            offset: 0,
            size,
        };
        // SAFETY: EEPROM_GET with a null `ee` points `ee` at simavr's own EEPROM buffer.
        let rc = unsafe {
            ffi::avr_ioctl(
                self.raw(),
                ioctl(b'e', b'e', b'g', b'p'),
                (&mut d as *mut ffi::avr_eeprom_desc_t).cast(),
            )
        };
        (rc >= 0 && !d.ee.is_null()).then_some(d)
    }

    /// A copy of the whole EEPROM (4 KB on the ATmega2560).
    pub fn eeprom(&self) -> Vec<u8> {
        match self.eeprom_desc() {
            // SAFETY: simavr owns `size` bytes at `ee`.
            Some(d) => unsafe { std::slice::from_raw_parts(d.ee, d.size as usize).to_vec() },
            None => Vec::new(),
        }
    }

    /// Overwrites EEPROM from byte `offset` with `bytes` (as a programmer would).
    pub fn set_eeprom(&mut self, offset: u16, bytes: &[u8]) -> Result<(), String> {
        let Some(full) = self.eeprom_desc() else {
            return Err("no EEPROM".into());
        };
        if usize::from(offset) + bytes.len() > full.size as usize {
            return Err("EEPROM write out of range".into());
        }
        let mut buf = bytes.to_vec();
        let mut d = ffi::avr_eeprom_desc_t {
            ee: buf.as_mut_ptr(),
            offset,
            size: bytes.len() as u32,
        };
        // SAFETY: EEPROM_SET copies `size` bytes from `ee` to `offset`.
        unsafe {
            ffi::avr_ioctl(
                self.raw(),
                ioctl(b'e', b'e', b's', b'p'),
                (&mut d as *mut ffi::avr_eeprom_desc_t).cast(),
            );
        }
        Ok(())
    }

    /// The ELF's symbols.
    pub fn symbols(&self) -> &[Symbol] {
        &self.symbols
    }

    /// Address of symbol `name`, if present.
    pub fn symbol(&self, name: &str) -> Option<&Symbol> {
        self.symbols.iter().find(|s| s.name == name)
    }

    /// Resets the core as a power cycle would (SRAM kept as simavr keeps it; EEPROM kept).
    pub fn reset(&mut self) {
        let before = self.cycle();
        // SAFETY: `avr_reset` on a live core.
        unsafe { ffi::avr_reset(self.raw()) }
        self.base.set(before - self.raw_cycle());
        self.resets.push(before);
    }
}

impl Drop for Machine {
    fn drop(&mut self) {
        self.alive.set(false);
        // SAFETY: terminate, then free the core allocated by `avr_make_mcu_by_name`, then the
        // callback states it pointed to.
        unsafe {
            ffi::avr_terminate(self.raw());
            free(self.raw().cast());
        }
        for f in self.frees.drain(..) {
            f();
        }
    }
}
