//! A thin, safe wrapper over simavr (`simavr-ffi`, the simavr that `avr-tester` builds from
//! source, with its TWI fixes) that exposes what `avr-tester` keeps private: the cycle counter,
//! data space (I/O registers, SRAM), EEPROM, interrupt and pin events with cycle stamps.
//!
//! Everything runs on the calling thread: simavr calls back into the notification functions
//! below from inside [`Machine::step`], and they only touch state owned by the [`Machine`].

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::ffi::{c_void, CString};
use std::path::Path;
use std::ptr::NonNull;
use std::rc::Rc;

use avr_tester::{TwiPacket, TwiSlave};
use simavr_ffi as ffi;

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

/// A byte sent by the firmware on a UART, with the cycle at which simavr delivered it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UartByte {
    /// Core cycle.
    pub cycle: u64,
    /// The byte.
    pub byte: u8,
}

/// A logic-level change of a watched output pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PinEdge {
    /// Core cycle.
    pub cycle: u64,
    /// New level.
    pub high: bool,
}

/// Interrupt entry (`running = true`) or return (`false`) of a watched vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IrqEvent {
    /// Core cycle.
    pub cycle: u64,
    /// Entered (true) or left (false).
    pub running: bool,
    /// On entry: the interrupted program counter (bytes), read from the return address just
    /// pushed (3 bytes on cores with more than 128 KB of flash, 2 otherwise). 0 on return.
    pub ret_pc: u32,
    /// On entry: the interrupted stack pointer (before the return address was pushed).
    pub ret_sp: u16,
}

/// Callback state: a pointer to the core (to read its cycle counter) plus a sink.
struct Hook<T> {
    avr: *mut ffi::avr_t,
    base: Rc<Cell<u64>>,
    sink: Rc<RefCell<T>>,
}

impl<T> Hook<T> {
    fn cycle(&self) -> u64 {
        // SAFETY: `avr` outlives every hook (hooks are freed in `Machine::drop` after the core
        // has stopped running); reading a plain field.
        self.base.get() + unsafe { (*self.avr).cycle }
    }
}

struct TwiHook {
    avr: *mut ffi::avr_t,
    base: Rc<Cell<u64>>,
    input: *mut ffi::avr_irq_t,
    clock: Rc<Cell<u64>>,
    slave: Box<dyn TwiSlave>,
}

/// Decodes simavr's `avr_twi_msg_irq_t` (bitfields `unused:8, msg:8, addr:8, data:8`).
pub fn twi_decode(v: u32) -> TwiPacket {
    let [_, msg, addr, data] = v.to_le_bytes();
    TwiPacket { msg, addr, data }
}

/// Encodes a [`TwiPacket`] as simavr's `avr_twi_msg_irq_t`.
pub fn twi_encode(p: &TwiPacket) -> u32 {
    u32::from_le_bytes([0, p.msg, p.addr, p.data])
}

unsafe extern "C" fn on_uart(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is the `Hook<Vec<UartByte>>` registered in `Machine::new`.
    let hook = unsafe { &*(param as *const Hook<Vec<UartByte>>) };
    let cycle = hook.cycle();
    hook.sink.borrow_mut().push(UartByte {
        cycle,
        byte: value as u8,
    });
}

unsafe extern "C" fn on_pin(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is a `Hook<Vec<PinEdge>>` registered in `Machine::watch_pin`.
    let hook = unsafe { &*(param as *const Hook<Vec<PinEdge>>) };
    let cycle = hook.cycle();
    let high = value != 0;
    let mut v = hook.sink.borrow_mut();
    if v.last().is_none_or(|e| e.high != high) {
        v.push(PinEdge { cycle, high });
    }
}

unsafe extern "C" fn on_irq_running(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is a `Hook<Vec<IrqEvent>>` registered in `Machine::watch_vector`.
    let hook = unsafe { &*(param as *const Hook<Vec<IrqEvent>>) };
    let cycle = hook.cycle();
    let running = value != 0;
    let mut ret_pc = 0;
    let mut ret_sp = 0;
    if running {
        // SAFETY: live core; the stack bytes above SP are inside `data` (SP ≤ RAMEND).
        unsafe {
            let avr = &*hook.avr;
            let sp = usize::from(u16::from_le_bytes([
                *avr.data.add(0x5D),
                *avr.data.add(0x5E),
            ]));
            let n = usize::from(avr.address_size);
            let top = usize::from(avr.ramend);
            let mut words: u32 = 0;
            for i in 1..=n {
                if sp + i <= top {
                    words = (words << 8) | u32::from(*avr.data.add(sp + i));
                }
            }
            ret_pc = words * 2;
            ret_sp = (sp + n) as u16;
        }
    }
    hook.sink.borrow_mut().push(IrqEvent {
        cycle,
        running,
        ret_pc,
        ret_sp,
    });
}

unsafe extern "C" fn on_twi(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is the `TwiHook` registered in `Machine::attach_twi`; simavr does not
    // re-enter this callback while the slave runs (the answer goes to the *input* IRQ).
    let hook = unsafe { &mut *(param as *mut TwiHook) };
    // SAFETY: plain field read of the live core that is calling us.
    hook.clock
        .set(hook.base.get() + unsafe { (*hook.avr).cycle });
    if let Some(answer) = hook.slave.recv(twi_decode(value)) {
        // SAFETY: `input` is the TWI input IRQ of the same core.
        unsafe { ffi::avr_raise_irq(hook.input, twi_encode(&answer)) };
    }
}

/// What an intercepted I/O register write does (see [`Machine::intercept_write`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IoWrite {
    /// Hand the write to the peripheral that owns the register, as without the interception.
    Pass,
    /// The register takes this value; the peripheral never sees the write.
    Store(u8),
}

/// An intercepted register write: `(cycle, register value before, value written)`.
type WriteFn = Box<dyn FnMut(u64, u8, u8) -> IoWrite>;

struct WriteHook {
    avr: *mut ffi::avr_t,
    base: Rc<Cell<u64>>,
    /// The handler that owned the register before (the peripheral's, or simavr's muxer).
    original: ffi::avr_io_write_t,
    original_param: *mut c_void,
    f: WriteFn,
}

unsafe extern "C" fn on_io_write(avr: *mut ffi::avr_t, addr: u16, v: u8, param: *mut c_void) {
    // SAFETY: `param` is the `WriteHook` installed by `Machine::intercept_write`; simavr calls
    // it from the core's register write on this thread.
    let hook = unsafe { &mut *(param as *mut WriteHook) };
    // SAFETY: `addr` is an I/O register address below `ramend` (checked at installation).
    let old = unsafe { *(*avr).data.add(addr.into()) };
    // SAFETY: plain field read of the live core that is calling us.
    let cycle = hook.base.get() + unsafe { (*hook.avr).cycle };
    match (hook.f)(cycle, old, v) {
        IoWrite::Pass => match hook.original {
            // SAFETY: the handler and its parameter as simavr registered them.
            Some(c) => unsafe { c(avr, addr, v, hook.original_param) },
            // SAFETY: as above.
            None => unsafe { *(*avr).data.add(addr.into()) = v },
        },
        // SAFETY: as above.
        IoWrite::Store(x) => unsafe { *(*avr).data.add(addr.into()) = x },
    }
}

/// A pin-level callback: `(cycle, new level)`.
type PinFn = Box<dyn FnMut(u64, bool)>;

unsafe extern "C" fn on_pin_level(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is a `Hook<PinFn>` registered in `Machine::on_pin_change`. simavr does
    // not re-enter a hook that is running (`hook->busy`), so the borrow is not shared.
    let hook = unsafe { &*(param as *const Hook<PinFn>) };
    let cycle = hook.cycle();
    (hook.sink.borrow_mut())(cycle, value != 0);
}

/// Drives the input side of one port's pins from outside the MCU, as pull-up resistors and
/// open-drain devices on the board do (see [`Machine::external_pins`]). Clones share the levels.
/// Does nothing once its [`Machine`] is dropped.
#[derive(Clone)]
pub struct ExternalPins {
    avr: *mut ffi::avr_t,
    alive: Rc<Cell<bool>>,
    port: char,
    irqs: [*mut ffi::avr_irq_t; 8],
    /// (mask, value) given to simavr so far.
    levels: Rc<Cell<(u8, u8)>>,
}

impl std::fmt::Debug for ExternalPins {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (mask, value) = self.levels.get();
        f.debug_struct("ExternalPins")
            .field("port", &self.port)
            .field("mask", &mask)
            .field("value", &value)
            .finish()
    }
}

impl ExternalPins {
    /// From now on, the pins in `mask` read `value`'s bits (1 = high) whenever the MCU does not
    /// drive them (DDR bit 0), whatever its PORT bit (internal pull-up) says; takes effect at
    /// once on the pins that are inputs now. Other pins keep what they had. Can be called from
    /// inside the machine's callbacks ([`Machine::on_pin_change`], [`Machine::intercept_write`]).
    pub fn set(&self, mask: u8, value: u8) {
        if !self.alive.get() {
            return;
        }
        let (m, v) = self.levels.get();
        let (m, v) = (m | mask, (v & !mask) | (value & mask));
        self.levels.set((m, v));
        // SAFETY: live core (`alive`); both ioctls take the structs bindgen generated for them.
        unsafe {
            let mut ext: ffi::avr_ioport_external_t = std::mem::zeroed();
            ext.set_name(self.port as u8 as _);
            ext.set_mask(m.into());
            ext.set_value(v.into());
            ffi::avr_ioctl(
                self.avr,
                ioctl(b'i', b'o', b'p', self.port as u8),
                (&mut ext as *mut ffi::avr_ioport_external_t).cast(),
            );
            let mut state: ffi::avr_ioport_state_t = std::mem::zeroed();
            ffi::avr_ioctl(
                self.avr,
                ioctl(b'i', b'o', b's', self.port as u8),
                (&mut state as *mut ffi::avr_ioport_state_t).cast(),
            );
            let ddr = state.ddr() as u8;
            for bit in 0..8 {
                if mask & !ddr & (1 << bit) != 0 {
                    ffi::avr_raise_irq(self.irqs[bit], u32::from((value >> bit) & 1));
                }
            }
        }
    }
}

/// What became of a byte handed to a UART's receiver ([`UartInput::send`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delivery {
    /// In simavr's input FIFO: the receiver raises RXC for it one frame time after the FIFO
    /// was last empty (or after the byte before it).
    Queued,
    /// The firmware had the receiver off (`RXENn` = 0): the byte is lost, as on the chip.
    ReceiverOff,
    /// simavr's 64-entry input FIFO was full (it had signalled `UART_IRQ_OUT_XOFF`): the byte is
    /// lost and `DORn` set. (The chip has a 2-byte FIFO; a firmware that reads `UDRn` in its
    /// receive interrupt never lets simavr's fill.)
    FifoFull,
}

/// simavr's `UART_IRQ_OUT_XOFF`: 1 when the UART's input FIFO is full, 0 when it has room.
unsafe extern "C" fn on_xoff(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is the `Rc<Cell<bool>>` leaked in `Machine::uart_input`; it lives until
    // the core is freed.
    let full = unsafe { &*(param as *const Rc<Cell<bool>>) };
    full.set(value != 0);
}

/// The receive side of one UART, seen from the wire: hands bytes to simavr's UART input IRQ
/// (`UART_IRQ_INPUT`) as the line delivers them (see [`crate::uart`] for the line's timing).
/// Clones share the FIFO-full flag. Does nothing once its [`Machine`] is dropped.
#[derive(Clone)]
pub struct UartInput {
    avr: *mut ffi::avr_t,
    alive: Rc<Cell<bool>>,
    input: *mut ffi::avr_irq_t,
    /// simavr's input FIFO is full (last `UART_IRQ_OUT_XOFF` value).
    full: Rc<Cell<bool>>,
    /// Data-space address of `UCSRnB` (receiver enable `RXENn`, bit 4).
    ucsrb: u16,
}

impl std::fmt::Debug for UartInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UartInput")
            .field("ucsrb", &self.ucsrb)
            .field("fifo_full", &self.full.get())
            .finish()
    }
}

/// `RXENn` in `UCSRnB` (ATmega2560 datasheet, USART register description).
const RXEN: u8 = 1 << 4;

impl UartInput {
    /// Whether the firmware has the receiver on (`RXENn` in `UCSRnB`).
    pub fn receiver_enabled(&self) -> bool {
        if !self.alive.get() {
            return false;
        }
        // SAFETY: live core; `ucsrb` is an I/O register below RAMEND.
        unsafe { *(*self.avr).data.add(self.ucsrb.into()) & RXEN != 0 }
    }

    /// Whether simavr's input FIFO is full (it signalled XOFF and not XON since).
    pub fn fifo_full(&self) -> bool {
        self.full.get()
    }

    /// Hands `byte` to the receiver now (its start bit is on the line now; simavr raises RXC
    /// one frame time later, see [`crate::uart`]).
    pub fn send(&self, byte: u8) -> Delivery {
        if !self.receiver_enabled() {
            return Delivery::ReceiverOff;
        }
        if self.full.get() {
            // simavr drops it and sets DORn: raise it anyway so that the firmware sees the
            // overrun flag as it would on the chip.
            // SAFETY: live core (checked above); the input IRQ of the same core.
            unsafe { ffi::avr_raise_irq(self.input, u32::from(byte)) };
            return Delivery::FifoFull;
        }
        // SAFETY: as above.
        unsafe { ffi::avr_raise_irq(self.input, u32::from(byte)) };
        Delivery::Queued
    }
}

/// Data-space address of `UCSRnA` of USART `id` (`'0'` … `'3'`) on the ATmega2560 (datasheet,
/// register summary); `UCSRnB`, `UCSRnC`, `UBRRnL`, `UBRRnH`, `UDRn` follow at +1, +2, +4,
/// +5, +6.
pub fn uart_base(id: char) -> Option<u16> {
    Some(match id {
        '0' => 0xC0,
        '1' => 0xC8,
        '2' => 0xD0,
        '3' => 0x130,
        _ => return None,
    })
}

/// A post-write hook on a UART's frame registers (see [`Machine::uart_chip_timing`]).
struct FrameHook {
    uart: *mut ffi::avr_uart_t,
    /// `UCSRnA`'s address.
    base: u16,
    /// The handler that owned the register before (simavr's UART, or none).
    original: ffi::avr_io_write_t,
    original_param: *mut c_void,
}

impl FrameHook {
    /// Sets simavr's frame time from the registers as the chip times its frames.
    ///
    /// # Safety
    /// `avr` and `self.uart` are the live core and its UART.
    unsafe fn apply(&self, avr: *mut ffi::avr_t) {
        // SAFETY: the registers are I/O addresses below RAMEND; `uart` is live (caller).
        unsafe {
            let reg = |k: u16| *(*avr).data.add(usize::from(self.base + k));
            let ubrr = u16::from_le_bytes([reg(4), reg(5) & 0x0F]);
            (*self.uart).cycles_per_byte =
                crate::uart::chip_frame_cycles(ubrr, reg(0), reg(1), reg(2));
        }
    }
}

unsafe extern "C" fn on_frame_write(avr: *mut ffi::avr_t, addr: u16, v: u8, param: *mut c_void) {
    // SAFETY: `param` is the `FrameHook` installed by `Machine::uart_chip_timing`; simavr calls
    // it from the core's register write on this thread.
    let hook = unsafe { &*(param as *const FrameHook) };
    match hook.original {
        // SAFETY: the handler and its parameter as simavr registered them.
        Some(c) => unsafe { c(avr, addr, v, hook.original_param) },
        // SAFETY: `addr` is an I/O register below RAMEND (checked at installation).
        None => unsafe { *(*avr).data.add(addr.into()) = v },
    }
    // SAFETY: the live core calling us, and its UART.
    unsafe { hook.apply(avr) };
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

    unsafe fn hook_uart(&mut self, id: char) -> Result<(), String> {
        let avr = self.raw();
        let mut flags: u32 = 0;
        // SAFETY: UART flags ioctls take a `uint32_t *`.
        unsafe {
            if ffi::avr_ioctl(
                avr,
                ioctl(b'u', b'a', b'g', id as u8),
                (&mut flags as *mut u32).cast(),
            ) != 0
            {
                return Err(format!("no UART{id}"));
            }
            flags &= !ffi::AVR_UART_FLAG_STDIO;
            ffi::avr_ioctl(
                avr,
                ioctl(b'u', b'a', b's', id as u8),
                (&mut flags as *mut u32).cast(),
            );
            let irq = ffi::avr_io_getirq(
                avr,
                ioctl(b'u', b'a', b'r', id as u8),
                ffi::UART_IRQ_OUTPUT as _,
            );
            if irq.is_null() {
                return Err(format!("no UART{id} output IRQ"));
            }
            let hook = self.leak(Hook {
                avr,
                base: self.base.clone(),
                sink: self.uart0.clone(),
            });
            ffi::avr_irq_register_notify(irq, Some(on_uart), hook.cast());
        }
        Ok(())
    }

    /// The receive side of UART `id` (`'0'` … `'3'`: USART0 … USART3 of the ATmega2560), to
    /// send it bytes from outside ([`UartInput::send`]).
    pub fn uart_input(&mut self, id: char) -> Result<UartInput, String> {
        let ucsrb = uart_base(id).ok_or_else(|| format!("no UART{id}"))? + 1;
        let avr = self.raw();
        let ctl = ioctl(b'u', b'a', b'r', id as u8);
        let full = Rc::new(Cell::new(false));
        // SAFETY: IRQ look-ups on a valid core; the flag outlives the core's use of it.
        unsafe {
            let input = ffi::avr_io_getirq(avr, ctl, ffi::UART_IRQ_INPUT as _);
            let xoff = ffi::avr_io_getirq(avr, ctl, ffi::UART_IRQ_OUT_XOFF as _);
            if input.is_null() || xoff.is_null() {
                return Err(format!("no UART{id} input IRQ"));
            }
            let flag = self.leak(full.clone());
            ffi::avr_irq_register_notify(xoff, Some(on_xoff), flag.cast());
            Ok(UartInput {
                avr,
                alive: self.alive.clone(),
                input,
                full,
                ucsrb,
            })
        }
    }

    /// Makes simavr time UART `id`'s frames as the chip does, from now on and after every
    /// write to its frame registers (`UBRRnL/H`, `UCSRnA/B/C`): `(UBRR + 1) · (U2X ? 8 : 16)`
    /// cycles a bit and start + data + parity + stop bits a frame
    /// ([`crate::uart::chip_frame_cycles`]). simavr itself recomputes its frame time only when
    /// `UBRRnL` is written, so a `U2Xn` set afterwards (as the firmware does) is not seen, and
    /// counts a parity bit in every frame: at `UBRR0 = 16` with U2X it transmits and receives a
    /// byte every 2 992 cycles instead of the chip's 1 360.
    pub fn uart_chip_timing(&mut self, id: char) -> Result<(), String> {
        let base = uart_base(id).ok_or_else(|| format!("no UART{id}"))?;
        let avr = self.raw();
        let want = ioctl(b'u', b'a', b'r', id as u8);
        // SAFETY: walks simavr's list of I/O modules of a valid core; a module whose IRQs are
        // the UART's is an `avr_uart_t` (its `avr_io_t` is the first member).
        let uart = unsafe {
            let mut io = (*avr).io_port;
            while !io.is_null() && (*io).irq_ioctl_get != want {
                io = (*io).next;
            }
            io.cast::<ffi::avr_uart_t>()
        };
        if uart.is_null() {
            return Err(format!("no UART{id} module"));
        }
        for k in [0u16, 1, 2, 4, 5] {
            let io = usize::from(base + k - 32);
            // SAFETY: `io` is within `avr->io`; the hook outlives the core's use of it.
            unsafe {
                let slot = &mut (*avr).io[io].w;
                let hook = self.leak(FrameHook {
                    uart,
                    base,
                    original: slot.c,
                    original_param: slot.param,
                });
                slot.c = Some(on_frame_write);
                slot.param = hook.cast();
                if k == 0 {
                    (*hook).apply(avr);
                }
            }
        }
        Ok(())
    }

    /// Attaches a TWI (I2C) slave to TWI0; it sees every packet. `clock` is set to the core
    /// cycle just before each packet is handed to the slave (slaves have no clock of their
    /// own in `avr_tester`'s [`TwiSlave`] interface).
    pub fn attach_twi(
        &mut self,
        slave: Box<dyn TwiSlave>,
        clock: Rc<Cell<u64>>,
    ) -> Result<(), String> {
        let avr = self.raw();
        let ctl = ioctl(b't', b'w', b'i', 0);
        // SAFETY: IRQ look-ups on a valid core; the hook outlives the core's use of it.
        unsafe {
            let input = ffi::avr_io_getirq(avr, ctl, ffi::TWI_IRQ_INPUT as _);
            let output = ffi::avr_io_getirq(avr, ctl, ffi::TWI_IRQ_OUTPUT as _);
            if input.is_null() || output.is_null() {
                return Err("no TWI0".into());
            }
            let hook = self.leak(TwiHook {
                avr,
                base: self.base.clone(),
                input,
                clock,
                slave,
            });
            ffi::avr_irq_register_notify(output, Some(on_twi), hook.cast());
        }
        Ok(())
    }

    /// Records every level change of output pin `port``bit` (e.g. `('B', 7)`) from now on.
    pub fn watch_pin(&mut self, port: char, bit: u8) -> Rc<RefCell<Vec<PinEdge>>> {
        if let Some(s) = self.pins.get(&(port, bit)) {
            return s.clone();
        }
        let sink = Rc::new(RefCell::new(Vec::new()));
        let avr = self.raw();
        // SAFETY: as in `attach_twi`.
        unsafe {
            let irq = ffi::avr_io_getirq(avr, ioctl(b'i', b'o', b'g', port as u8), bit.into());
            if !irq.is_null() {
                let hook = self.leak(Hook {
                    avr,
                    base: self.base.clone(),
                    sink: sink.clone(),
                });
                ffi::avr_irq_register_notify(irq, Some(on_pin), hook.cast());
            }
        }
        self.pins.insert((port, bit), sink.clone());
        sink
    }

    /// Calls `f(cycle, level)` at every level change of pin `port``bit` (e.g. `('D', 0)`) from
    /// now on, whoever makes it: the MCU (output, or the pull-up it selects) or
    /// [`ExternalPins`]. `f` may itself drive pins through an [`ExternalPins`].
    pub fn on_pin_change(
        &mut self,
        port: char,
        bit: u8,
        f: impl FnMut(u64, bool) + 'static,
    ) -> Result<(), String> {
        let avr = self.raw();
        // SAFETY: as in `attach_twi`.
        unsafe {
            let irq = ffi::avr_io_getirq(avr, ioctl(b'i', b'o', b'g', port as u8), bit.into());
            if irq.is_null() || bit > 7 {
                return Err(format!("no pin P{port}{bit}"));
            }
            let f: PinFn = Box::new(f);
            let hook = self.leak(Hook {
                avr,
                base: self.base.clone(),
                sink: Rc::new(RefCell::new(f)),
            });
            ffi::avr_irq_register_notify(irq, Some(on_pin_level), hook.cast());
        }
        Ok(())
    }

    /// A handle that drives port `port`'s pins from outside (pull-ups, a device holding a line
    /// low); see [`ExternalPins::set`].
    pub fn external_pins(&mut self, port: char) -> Result<ExternalPins, String> {
        let avr = self.raw();
        let mut irqs = [std::ptr::null_mut(); 8];
        for (bit, irq) in irqs.iter_mut().enumerate() {
            // SAFETY: IRQ look-up on a valid core.
            *irq =
                unsafe { ffi::avr_io_getirq(avr, ioctl(b'i', b'o', b'g', port as u8), bit as _) };
            if irq.is_null() {
                return Err(format!("no port {port}"));
            }
        }
        Ok(ExternalPins {
            avr,
            alive: self.alive.clone(),
            port,
            irqs,
            levels: Rc::new(Cell::new((0, 0))),
        })
    }

    /// Puts `f` in front of the peripheral that handles writes to I/O register `addr` (data
    /// space address, e.g. `0xBC` = TWCR): every write the firmware makes calls
    /// `f(cycle, value before, value written)`, and [`IoWrite`] says whether the peripheral
    /// sees it. Reads are untouched.
    pub fn intercept_write(
        &mut self,
        addr: u16,
        f: impl FnMut(u64, u8, u8) -> IoWrite + 'static,
    ) -> Result<(), String> {
        let io = usize::from(addr)
            .checked_sub(32)
            .filter(|&io| io < ffi::MAX_IOs as usize && addr <= self.ramend())
            .ok_or_else(|| format!("{addr:#x} is not an I/O register"))?;
        let avr = self.raw();
        // SAFETY: `io` is within `avr->io`; the hook outlives the core's use of it.
        unsafe {
            let slot = &mut (*avr).io[io].w;
            let hook = self.leak(WriteHook {
                avr,
                base: self.base.clone(),
                original: slot.c,
                original_param: slot.param,
                f: Box::new(f),
            });
            slot.c = Some(on_io_write);
            slot.param = hook.cast();
        }
        Ok(())
    }

    /// Records entries into and returns from interrupt vector `vector` (e.g. 17 =
    /// `TIMER1_COMPA` on the ATmega2560) from now on.
    pub fn watch_vector(&mut self, vector: u8) -> Rc<RefCell<Vec<IrqEvent>>> {
        let sink = Rc::new(RefCell::new(Vec::new()));
        let avr = self.raw();
        // SAFETY: as in `attach_twi`.
        unsafe {
            let irq = ffi::avr_get_interrupt_irq(avr, vector);
            if !irq.is_null() {
                let hook = self.leak(Hook {
                    avr,
                    base: self.base.clone(),
                    sink: sink.clone(),
                });
                ffi::avr_irq_register_notify(
                    irq.add(ffi::AVR_INT_IRQ_RUNNING as usize),
                    Some(on_irq_running),
                    hook.cast(),
                );
            }
        }
        sink
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

    /// Everything UART0 has sent so far.
    pub fn uart0(&self) -> Rc<RefCell<Vec<UartByte>>> {
        self.uart0.clone()
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
