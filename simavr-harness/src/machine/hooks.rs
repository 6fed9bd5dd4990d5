//! What the harness attaches to the simulated core ([`Machine`]): callbacks on interrupt
//! vectors, output pins, the TWI bus, the UARTs and register writes, each event stamped with
//! the core cycle, and inputs driven from outside (external pins, a UART's receiver). simavr
//! calls them from inside [`Machine::step`], on the calling thread; their states are owned by
//! the [`Machine`] and freed when it drops.

use std::cell::{Cell, RefCell};
use std::ffi::c_void;
use std::rc::Rc;

use avr_tester::{TwiPacket, TwiSlave};
use simavr_ffi as ffi;

use super::{ioctl, Machine};
use crate::uart::UartInput;

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

/// simavr's `UART_IRQ_OUT_XOFF`: 1 when the UART's input FIFO is full, 0 when it has room.
unsafe extern "C" fn on_xoff(_irq: *mut ffi::avr_irq_t, value: u32, param: *mut c_void) {
    // SAFETY: `param` is the `Rc<Cell<bool>>` leaked in `Machine::uart_input`; it lives until
    // the core is freed.
    let full = unsafe { &*(param as *const Rc<Cell<bool>>) };
    full.set(value != 0);
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

impl Machine {
    pub(super) unsafe fn hook_uart(&mut self, id: char) -> Result<(), String> {
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
            Ok(UartInput::new(avr, self.alive.clone(), input, full, ucsrb))
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

    /// Everything UART0 has sent so far.
    pub fn uart0(&self) -> Rc<RefCell<Vec<UartByte>>> {
        self.uart0.clone()
    }
}
