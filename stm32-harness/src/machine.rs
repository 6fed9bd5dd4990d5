//! The emulated STM32F411: Unicorn's Cortex-M4 core (Thumb-2 and the FPU) with the memory map
//! of the STM32F411CE (RM0383 §2.3: 512 KB flash at 0x0800_0000, 128 KB SRAM at
//! 0x2000_0000, peripherals at 0x4000_0000, the bit-band alias at 0x4200_0000, the Cortex-M4
//! system space at 0xE000_0000) and the peripheral models of [`crate::chip`] behind it, with
//! what Unicorn leaves to its user: time, interrupts, resets.
//!
//! **Time.** Unicorn has no timing model. Emulated time advances by a fixed number of core
//! clock cycles per instruction ([`CPI`], 1.0) at the HCLK the RCC selects, counted per
//! translated block (a block hook adds the block's instruction count). Peripherals compute
//! their state from that time. The run is cut into chunks that end at the next time a
//! peripheral changes by itself ([`crate::chip::Chip::next_event`]) or the caller's deadline,
//! so no event is passed over.
//!
//! **Clock jump.** When the firmware polls one register that can change by itself (a counter,
//! a status flag: [`Chip::changes_by_itself`]; the same value read [`POLL_READS`] times in a
//! row, each within [`POLL_GAP`] instructions of the last, with no other bus access between),
//! nothing it can observe changes until the next peripheral event,
//! the next change of that register (a timer's next count) or the caller's deadline; the
//! machine jumps emulated time there at once. Interrupts are events too, so a jump never
//! skips one. What changes: the poll loop runs fewer iterations than on the chip, so a loop
//! that counts iterations as a timeout (e.g. the panic handler's bounded UART wait) times
//! out later in emulated time, never earlier.
//!
//! **Exceptions.** Unicorn has no NVIC. Between chunks the machine takes the highest-priority
//! pending interrupt that may preempt (PRIMASK clear) as the core would (PM0214 §2.3.7,
//! "Exception entry and return"): it stacks R0–R3, R12, LR, the return address and xPSR on
//! the main stack (8-byte aligned with CCR.STKALIGN, xPSR bit 9 marking the padding), plus
//! S0–S15 and FPSCR when CONTROL.FPCA is set and FPCCR.ASPEN enables automatic FP state
//! preservation (the image's setting: ASPEN and LSPEN, the reset value), loads LR with the
//! EXC_RETURN value and PC from the vector table. The handler's return to EXC_RETURN is a
//! fetch from 0xFFFF_FFxx, which Unicorn refuses: the machine catches it and unstacks.
//! Simplifications: lazy stacking (LSPEN) is done eagerly (the FP registers are saved at
//! entry and restored at return, which leaves the same register state; only the frame's
//! memory and the timing differ); the core's IPSR reads 0 inside handlers (`ICSR.VECTACTIVE`
//! is right); the process stack (CONTROL.SPSEL) is not supported (cortex-m-rt uses the main
//! stack); tail-chaining and late arrival are not modelled (each exception is entered and
//! returned in full, which only changes timing).
//!
//! **Faults and resets.** A CPU fault (undefined instruction, unmapped access) enters
//! HardFault (exception 3), as on the chip; a fault inside HardFault locks the core up until
//! the watchdog resets it. A watchdog expiry, `AIRCR.SYSRESETREQ` or [`Machine::reset`]
//! resets the chip: peripherals to their reset values, the flash memory and RAM kept (a
//! power cycle, [`Machine::power_cycle`], clears the RAM to a pattern), the reset flags
//! accumulated in RCC_CSR.

use std::path::Path;

use unicorn_engine::unicorn_const::{Arch, HookType, MemType, Mode, Prot};
use unicorn_engine::{ArmCpuModel, RegisterARM, Unicorn};

use crate::chip::{Chip, TIM3, TIM5};
use crate::elf::{self, Image};
use crate::periph::flash::{self, Effect};
use crate::periph::i2c::Device;
use crate::periph::rcc::ResetCause;
use crate::periph::scb::FPCCR_ASPEN;
use crate::periph::timer::{CCR1, CNT};
use crate::periph::{Time, PS_PER_S};
use crate::ticks::{TickMeter, POLL_GAP, POLL_READS};

/// Core clock cycles per instruction assumed (see the crate docs for what the real Cortex-M4
/// timing would add).
pub const CPI: u64 = 1;
/// SRAM.
pub const SRAM: u32 = 0x2000_0000;
/// SRAM size, bytes.
pub const SRAM_SIZE: u32 = 128 * 1024;
/// RAM fill after a power cycle (what uninitialised RAM holds is undefined on the chip).
pub const RAM_FILL: u8 = 0x55;

/// How a chunk of execution ended, seen by the run loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Exit {
    /// A power cut was due (after a flash program access, or in an erase).
    PowerCut,
}

/// A reset the machine went through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reset {
    /// When.
    pub at: Time,
    /// Why.
    pub cause: ResetCause,
}

/// A flash operation that stalled the CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stall {
    /// When it started, ps.
    pub at: Time,
    /// How long the CPU stalled, ps (cut short by a watchdog reset or a power cut).
    pub len: Time,
    /// When the IWDG would have reset the chip as the stall began (`None`: not running).
    pub watchdog: Option<Time>,
}

/// What the run loop and the bus callbacks share (Unicorn's user data).
pub struct Core {
    /// The peripherals.
    pub chip: Chip,
    /// Emulated time, ps.
    pub now: Time,
    /// Instructions executed.
    pub instr: u64,
    /// Time jumped over by the clock jump, ps.
    pub jumped: Time,
    ps_per_instr: Time,
    deadline: Time,
    exit: Option<Exit>,
    /// Poll detector: last read (address, value, instruction count), run length, and the
    /// run's first read (time, instructions).
    poll: Option<(u32, u32, u64)>,
    poll_run: u32,
    poll_first: (Time, u64),
    /// Ticks seen on the bus.
    pub ticks: TickMeter,
    /// Cut the power after this many flash program accesses in all (power-cut tests).
    pub power_cut_after: Option<usize>,
    /// Sector erases (stalls longer than a program access), in order.
    pub erase_stalls: Vec<Stall>,
    /// Writes of the pump's compare register `TIM3_CCR1`: (time, value), in order.
    pub pwm_writes: Vec<(Time, u32)>,
    /// Whether polling jumps the clock (on by default; off, every poll iteration runs).
    pub clock_jump: bool,
    /// Bus accesses, exception entries and returns still to print on stderr (debugging: the
    /// environment variable `STM32_TRACE=<n>` sets it at start).
    pub trace: u64,
}

impl Core {
    /// Ends the chunk at the next block. (Stopping Unicorn from inside a bus callback would
    /// restart the accessing instruction and repeat the access.)
    fn stop_soon(&mut self) {
        self.deadline = self.deadline.min(self.now);
    }

    fn update_rate(&mut self) {
        self.ps_per_instr = CPI * PS_PER_S / u64::from(self.chip.clocks().hclk.max(1));
    }

    /// Instructions in the block of `size` bytes at `addr` (Thumb-2: a halfword whose top
    /// five bits are 0b11101, 0b11110 or 0b11111 starts a 32-bit instruction).
    fn block_instructions(&self, addr: u32, size: u32) -> u64 {
        let mem = &self.chip.flash.mem;
        let Some(mut o) = addr.checked_sub(flash::BASE).map(|o| o as usize) else {
            return u64::from(size / 2).max(1);
        };
        let end = o + size as usize;
        let mut n = 0;
        while o < end {
            let hw = match mem.get(o..o + 2) {
                Some(b) => u16::from_le_bytes([b[0], b[1]]),
                None => break,
            };
            o += if hw >> 11 >= 0b11101 { 4 } else { 2 };
            n += 1;
        }
        n.max(1)
    }

    fn mmio_read(&mut self, addr: u32, size: u32) -> (u32, bool) {
        let now = self.now;
        self.chip.instr = self.instr;
        let v = self.chip.read(addr, size, now);
        if self.trace > 0 {
            self.trace -= 1;
            eprintln!(
                "{:>12} {:>14} R {addr:#010x} {size} -> {v:#x}",
                self.instr, self.now
            );
        }
        let counter = addr == TIM5 + CNT;
        let same = self
            .poll
            .is_some_and(|(a, pv, i)| a == addr && pv == v && self.instr - i <= POLL_GAP);
        if same {
            self.poll_run += 1;
        } else {
            self.poll_run = 1;
            self.poll_first = (now, self.instr);
        }
        self.poll = Some((addr, v, self.instr));
        // The loop's ticks are the main program's: an interrupt handler's accesses (the
        // UART's) neither start nor end one.
        let thread = self.chip.active.is_empty();
        if counter && thread {
            self.ticks.counter_read(now, self.instr);
        } else if thread {
            self.ticks.other_access();
        }
        let mut stop = self.chip.pending_exception().is_some();
        if self.poll_run >= POLL_READS && Chip::changes_by_itself(addr) {
            if counter && thread && self.poll_run == POLL_READS {
                self.ticks.idle(self.poll_first.0, self.poll_first.1);
            }
            // Jump to whatever can change what the loop reads next.
            let mut target = self.deadline;
            if let Some(t) = self.chip.next_event() {
                target = target.min(t);
            }
            let timer_change = match addr {
                a if a == TIM5 + CNT => self.chip.tim5.next_change(now),
                a if a == TIM3 + CNT => self.chip.tim3.next_change(now),
                _ => None,
            };
            if let Some(t) = timer_change {
                target = target.min(t);
            }
            if self.clock_jump && target > now && !stop {
                self.jumped += target - now;
                self.now = target;
                self.chip.advance(target);
                stop = true;
            }
        }
        (v, stop)
    }

    fn mmio_write(&mut self, addr: u32, size: u32, v: u32) -> (Effect, bool) {
        if self.trace > 0 {
            self.trace -= 1;
            eprintln!(
                "{:>12} {:>14} W {addr:#010x} {size} <- {v:#x}",
                self.instr, self.now
            );
        }
        self.poll = None;
        self.poll_run = 0;
        if addr == TIM3 + CCR1 {
            self.pwm_writes.push((self.now, v));
        }
        if self.chip.active.is_empty() {
            self.ticks.other_access();
            if addr == TIM3 + CCR1 {
                self.ticks.pwm_write(self.now, self.instr);
            }
        }
        self.chip.instr = self.instr;
        let e = self.chip.write(addr, size, v, self.now);
        if matches!(crate::chip::decode(addr), Some((crate::chip::Unit::Rcc, _)))
            || crate::periph::bitband::target_in(addr, crate::chip::RCC)
        {
            self.update_rate();
        }
        let stop = self.chip.pending_exception().is_some() || self.chip.scb.reset_requested;
        (e, stop)
    }
}

/// The emulated microcontroller.
pub struct Machine {
    uc: Unicorn<'static, Core>,
    image: Image,
    /// Resets so far (power-on first).
    pub resets: Vec<Reset>,
    /// The core is locked up (a fault in HardFault) until a reset.
    pub locked: bool,
    /// CPU faults taken (time, PC, Unicorn's error).
    pub faults: Vec<(Time, u32, String)>,
}

impl std::fmt::Debug for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Machine")
            .field("now", &self.core().now)
            .field("instr", &self.core().instr)
            .finish()
    }
}

fn uc_err(what: &str) -> impl Fn(unicorn_engine::unicorn_const::uc_error) -> String + '_ {
    move |e| format!("unicorn: {what}: {e:?}")
}

impl Machine {
    /// Loads `elf` into an erased flash (as `cargo flash-f411` writes it), puts `device` on
    /// I2C1 and powers the chip on (the core is at its reset vector).
    pub fn new(elf: &Path, device: Box<dyn Device>) -> Result<Self, String> {
        let image = elf::load(elf)?;
        let mut chip = Chip::new(device);
        for s in &image.segments {
            let off = s
                .addr
                .checked_sub(flash::BASE)
                .ok_or_else(|| format!("segment at {:#x} is not in flash", s.addr))?;
            chip.flash.load(off, &s.bytes)?;
        }
        let core = Core {
            chip,
            now: 0,
            instr: 0,
            jumped: 0,
            ps_per_instr: 1,
            deadline: 0,
            exit: None,
            poll: None,
            poll_run: 0,
            poll_first: (0, 0),
            ticks: TickMeter::default(),
            power_cut_after: None,
            erase_stalls: Vec::new(),
            pwm_writes: Vec::new(),
            clock_jump: true,
            trace: std::env::var("STM32_TRACE")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(0),
        };
        let mut uc = Unicorn::new_with_data(Arch::ARM, Mode::THUMB | Mode::MCLASS, core)
            .map_err(uc_err("open"))?;
        uc.ctl_set_cpu_model(ArmCpuModel::CORTEX_M4 as i32)
            .map_err(uc_err("cpu model"))?;
        let fb = u64::from(flash::BASE);
        uc.mem_map(fb, u64::from(flash::SIZE), Prot::READ | Prot::EXEC)
            .map_err(uc_err("map flash"))?;
        uc.mem_map(u64::from(SRAM), u64::from(SRAM_SIZE), Prot::ALL)
            .map_err(uc_err("map SRAM"))?;
        // Peripherals (APB1, APB2, AHB1), the bit-band alias of that range, the signature
        // page and the Cortex-M4 system space.
        for (base, size) in [
            (0x4000_0000u64, 0x0003_0000u64),
            (0x4200_0000, 0x0060_0000),
            (0x1FFF_7000, 0x1000),
            (0xE000_0000, 0x0010_0000),
        ] {
            uc.mmio_map(
                base,
                size,
                Some(move |uc: &mut Unicorn<'_, Core>, off: u64, size: usize| {
                    let c = uc.get_data_mut();
                    let (v, stop) = c.mmio_read((base + off) as u32, size as u32);
                    if stop {
                        c.stop_soon();
                    }
                    u64::from(v)
                }),
                Some(
                    move |uc: &mut Unicorn<'_, Core>, off: u64, size: usize, v: u64| {
                        let addr = (base + off) as u32;
                        let (effect, stop) =
                            uc.get_data_mut().mmio_write(addr, size as u32, v as u32);
                        let stop = Self::apply_flash(uc, &effect) || stop;
                        if stop {
                            uc.get_data_mut().stop_soon();
                        }
                    },
                ),
            )
            .map_err(uc_err("map peripherals"))?;
        }
        uc.add_block_hook(1, 0, |uc: &mut Unicorn<'_, Core>, addr: u64, size: u32| {
            // Called before the block runs; stopping here stops before it, so a block is
            // counted only when it will run (one that starts before the deadline runs whole).
            let c = uc.get_data_mut();
            if c.now >= c.deadline {
                uc.emu_stop().ok();
                return;
            }
            let n = c.block_instructions(addr as u32, size);
            c.instr += n;
            c.now += n * c.ps_per_instr;
        })
        .map_err(uc_err("block hook"))?;
        uc.add_mem_hook(
            HookType::MEM_WRITE_PROT,
            fb,
            fb + u64::from(flash::SIZE) - 1,
            |uc: &mut Unicorn<'_, Core>, _t: MemType, addr: u64, size: usize, v: i64| {
                let c = uc.get_data_mut();
                let off = addr as u32 - flash::BASE;
                let now = c.now;
                c.poll = None;
                c.ticks.other_access();
                let effect = c.chip.flash.program(off, size as u8, v as u32, now);
                let cut = c
                    .power_cut_after
                    .is_some_and(|n| c.chip.flash.programmed.len() >= n);
                if Self::apply_flash(uc, &effect) || cut {
                    let c = uc.get_data_mut();
                    if cut {
                        c.exit = Some(Exit::PowerCut);
                    }
                    c.stop_soon();
                }
                true
            },
        )
        .map_err(uc_err("flash hook"))?;
        // Mirror the loaded flash into Unicorn's memory; RAM holds a pattern at power-up
        // (its content is undefined on the chip), which also shows how deep the stack went.
        let mem = uc.get_data().chip.flash.mem.clone();
        uc.mem_write(fb, &mem).map_err(uc_err("load flash"))?;
        uc.mem_write(u64::from(SRAM), &vec![RAM_FILL; SRAM_SIZE as usize])
            .map_err(uc_err("fill RAM"))?;
        let mut m = Machine {
            uc,
            image,
            resets: Vec::new(),
            locked: false,
            faults: Vec::new(),
        };
        m.core_mut().update_rate();
        m.boot(ResetCause::PowerOn)?;
        Ok(m)
    }

    /// Applies a flash operation's effect to Unicorn's copy and the clock (the CPU stalls);
    /// returns whether the chunk should stop.
    fn apply_flash(uc: &mut Unicorn<'_, Core>, e: &Effect) -> bool {
        let Some((off, len)) = e.changed else {
            return false;
        };
        let bytes = uc.get_data().chip.flash.mem[off as usize..(off + len) as usize].to_vec();
        uc.mem_write(u64::from(flash::BASE + off), &bytes).ok();
        let c = uc.get_data_mut();
        // The CPU stalls until the operation ends, unless the watchdog resets the chip first
        // (the run loop then resets it at that time). Simplification: an erase cut short by
        // the reset has erased its sector all the same (the chip leaves it undefined).
        let end = c.now + e.stall;
        let start = c.now;
        let watchdog = c.chip.iwdg.expiry();
        c.now = match watchdog {
            Some(x) if x < end => x.max(c.now),
            _ => end,
        };
        if e.stall > flash::PROGRAM_PS {
            c.erase_stalls.push(Stall {
                at: start,
                len: c.now - start,
                watchdog,
            });
        }
        c.chip.advance(c.now);
        if e.power_cut {
            c.exit = Some(Exit::PowerCut);
        }
        true
    }

    /// The shared state.
    pub fn core(&self) -> &Core {
        self.uc.get_data()
    }

    /// The shared state, mutable.
    pub fn core_mut(&mut self) -> &mut Core {
        self.uc.get_data_mut()
    }

    /// The peripherals.
    pub fn chip(&self) -> &Chip {
        &self.core().chip
    }

    /// The peripherals, mutable.
    pub fn chip_mut(&mut self) -> &mut Chip {
        &mut self.core_mut().chip
    }

    /// Emulated time, ps.
    pub fn now(&self) -> Time {
        self.core().now
    }

    /// Instructions executed.
    pub fn instructions(&self) -> u64 {
        self.core().instr
    }

    /// The loaded image.
    pub fn image(&self) -> &Image {
        &self.image
    }

    fn reg(&self, r: RegisterARM) -> u32 {
        self.uc.reg_read(r).unwrap_or(0) as u32
    }

    fn set_reg(&mut self, r: impl Into<i32>, v: u32) -> Result<(), String> {
        self.uc
            .reg_write(r.into(), u64::from(v))
            .map_err(uc_err("register write"))
    }

    fn read_u32(&self, addr: u32) -> Result<u32, String> {
        let mut b = [0u8; 4];
        self.uc
            .mem_read(u64::from(addr), &mut b)
            .map_err(|e| format!("read {addr:#x}: {e:?}"))?;
        Ok(u32::from_le_bytes(b))
    }

    fn write_u32(&mut self, addr: u32, v: u32) -> Result<(), String> {
        self.uc
            .mem_write(u64::from(addr), &v.to_le_bytes())
            .map_err(|e| format!("write {addr:#x}: {e:?}"))
    }

    /// The vector table entry `n` (VTOR 0: the flash, aliased at 0 with BOOT0 low, RM0383
    /// §2.4 "Boot configuration").
    fn vector(&self, n: u32) -> Result<u32, String> {
        let vtor = self.chip().scb.vtor;
        let base = if vtor < flash::BASE {
            flash::BASE + vtor
        } else {
            vtor
        };
        self.read_u32(base + 4 * n)
    }

    /// The core's reset (PM0214 §2.1.3 / §2.3.2): MSP and PC from the vector table,
    /// special registers cleared, Thumb state.
    fn boot(&mut self, cause: ResetCause) -> Result<(), String> {
        let now = self.now();
        self.resets.push(Reset { at: now, cause });
        self.locked = false;
        let sp = self.vector(0)?;
        let pc = self.vector(1)?;
        for r in [
            RegisterARM::PRIMASK,
            RegisterARM::BASEPRI,
            RegisterARM::CONTROL,
        ] {
            self.set_reg(r, 0)?;
        }
        self.set_reg(RegisterARM::FAULTMASK, 0)?;
        for k in 0..13 {
            self.set_reg(RegisterARM::R0 as i32 + k, 0)?;
        }
        self.set_reg(RegisterARM::FPSCR, 0)?;
        self.set_reg(RegisterARM::MSP, sp)?;
        self.set_reg(RegisterARM::SP, sp)?;
        self.set_reg(RegisterARM::LR, 0xFFFF_FFFF)?;
        self.set_reg(RegisterARM::XPSR_NZCVQG, 1 << 24)?;
        self.set_reg(RegisterARM::PC, pc)?;
        let c = self.core_mut();
        c.poll = None;
        c.poll_run = 0;
        c.ticks.reset();
        c.update_rate();
        Ok(())
    }

    /// A system reset by `cause` now (peripherals reset, RAM and flash kept).
    pub fn reset(&mut self, cause: ResetCause) -> Result<(), String> {
        let now = self.now();
        self.chip_mut().reset(cause, now);
        self.boot(cause)
    }

    /// A power cycle now: RAM lost (filled with [`RAM_FILL`]), the flash kept, the reset
    /// flags those of a power-on reset.
    pub fn power_cycle(&mut self) -> Result<(), String> {
        let now = self.now();
        let fill = vec![RAM_FILL; SRAM_SIZE as usize];
        self.uc
            .mem_write(u64::from(SRAM), &fill)
            .map_err(uc_err("clear RAM"))?;
        self.chip_mut().reset(ResetCause::PowerOn, now);
        self.boot(ResetCause::PowerOn)
    }

    /// Exception entry for exception `exc` (see the module docs).
    fn enter(&mut self, exc: u32) -> Result<(), String> {
        let control = self.reg(RegisterARM::CONTROL);
        if control & 2 != 0 && self.chip().active.is_empty() {
            return Err("exception entry from the process stack: not modelled".into());
        }
        let fpca = control & 4 != 0;
        let fp = fpca && self.chip().scb.fpccr & FPCCR_ASPEN != 0;
        let sp = self.reg(RegisterARM::SP);
        let size = if fp { 0x68 } else { 0x20 };
        let mut frame = sp.wrapping_sub(size);
        let mut xpsr = self.reg(RegisterARM::XPSR) & !0x1FF;
        xpsr |= self.chip().active.last().copied().unwrap_or(0);
        if self.chip().scb.stkalign() && frame & 4 != 0 {
            frame &= !7;
            xpsr |= 1 << 9;
        }
        let pc = self.reg(RegisterARM::PC);
        let regs = [
            self.reg(RegisterARM::R0),
            self.reg(RegisterARM::R1),
            self.reg(RegisterARM::R2),
            self.reg(RegisterARM::R3),
            self.reg(RegisterARM::R12),
            self.reg(RegisterARM::LR),
            pc & !1,
            xpsr,
        ];
        for (k, v) in regs.iter().enumerate() {
            self.write_u32(frame + 4 * k as u32, *v)?;
        }
        if fp {
            for k in 0..16u32 {
                let s = self
                    .uc
                    .reg_read(RegisterARM::S0 as i32 + k as i32)
                    .unwrap_or(0) as u32;
                self.write_u32(frame + 0x20 + 4 * k, s)?;
            }
            let fpscr = self.reg(RegisterARM::FPSCR);
            self.write_u32(frame + 0x60, fpscr)?;
        }
        let handler_mode = !self.chip().active.is_empty();
        let exc_return = 0xFFFF_FFE1 | if fp { 0 } else { 0x10 } | if handler_mode { 0 } else { 8 };
        let vector = self.vector(exc)?;
        self.set_reg(RegisterARM::SP, frame)?;
        self.set_reg(RegisterARM::LR, exc_return)?;
        self.set_reg(RegisterARM::CONTROL, control & !4)?;
        let apsr = self.reg(RegisterARM::XPSR) & 0xF80F_0000;
        self.set_reg(RegisterARM::XPSR_NZCVQG, apsr | (1 << 24))?;
        self.set_reg(RegisterARM::PC, vector)?;
        if self.core().trace > 0 {
            eprintln!("enter {exc} pc {pc:#x} sp {sp:#x} frame {frame:#x} fp {fp} -> {vector:#x}");
        }
        let chip = self.chip_mut();
        chip.active.push(exc);
        if exc >= 16 {
            chip.nvic.set_active(exc - 16, true);
        }
        // Entry costs 12 cycles on the Cortex-M4 (PM0214 §2.3.7 does not give it; ARM's
        // Cortex-M4 TRM, "Exception handling": 12 cycles with zero-wait-state memory).
        let c = self.core_mut();
        c.now += 12 * c.ps_per_instr;
        Ok(())
    }

    /// Exception return to `exc_return` (see the module docs).
    fn exception_return(&mut self, exc_return: u32) -> Result<(), String> {
        if exc_return & 4 != 0 {
            return Err("exception return to the process stack: not modelled".into());
        }
        let fp = exc_return & 0x10 == 0;
        let frame = self.reg(RegisterARM::SP);
        let mut regs = [0u32; 8];
        for (k, r) in regs.iter_mut().enumerate() {
            *r = self.read_u32(frame + 4 * k as u32)?;
        }
        let names = [
            RegisterARM::R0,
            RegisterARM::R1,
            RegisterARM::R2,
            RegisterARM::R3,
            RegisterARM::R12,
            RegisterARM::LR,
        ];
        for (r, v) in names.iter().zip(regs) {
            self.set_reg(*r, v)?;
        }
        let size = if fp { 0x68 } else { 0x20 };
        if fp {
            for k in 0..16u32 {
                let s = self.read_u32(frame + 0x20 + 4 * k)?;
                self.set_reg(RegisterARM::S0 as i32 + k as i32, s)?;
            }
            let fpscr = self.read_u32(frame + 0x60)?;
            self.set_reg(RegisterARM::FPSCR, fpscr)?;
        }
        let xpsr = regs[7];
        if self.core().trace > 0 {
            eprintln!("return {exc_return:#x} to {:#x} xpsr {xpsr:#x}", regs[6]);
        }
        let pad = if xpsr & (1 << 9) != 0 { 4 } else { 0 };
        self.set_reg(RegisterARM::SP, frame + size + pad)?;
        let control = self.reg(RegisterARM::CONTROL);
        self.set_reg(
            RegisterARM::CONTROL,
            if fp { control | 4 } else { control & !4 },
        )?;
        self.set_reg(
            RegisterARM::XPSR_NZCVQG,
            (xpsr & !0x1FF & !(1 << 9)) | (1 << 24),
        )?;
        self.set_reg(RegisterARM::PC, regs[6] | 1)?;
        let chip = self.chip_mut();
        if let Some(exc) = chip.active.pop() {
            if exc >= 16 {
                chip.nvic.set_active(exc - 16, false);
            }
        }
        let c = self.core_mut();
        c.now += 10 * c.ps_per_instr;
        Ok(())
    }

    /// Runs until emulated time `until` (ps).
    pub fn run_until(&mut self, until: Time) -> Result<(), String> {
        while self.now() < until {
            self.step_chunk(until)?;
        }
        Ok(())
    }

    /// One chunk: events due, a pending interrupt, then execution up to the next event or
    /// `until`.
    fn step_chunk(&mut self, until: Time) -> Result<(), String> {
        let now = self.now();
        self.chip_mut().advance(now);
        if self.chip().iwdg.expiry().is_some_and(|t| t <= now) {
            return self.reset(ResetCause::Watchdog);
        }
        if self.chip_mut().take_reset_request() {
            return self.reset(ResetCause::Software);
        }
        let next = self.chip().next_event().unwrap_or(Time::MAX);
        if self.locked {
            // Nothing runs until a reset (the watchdog's expiry is an event).
            let t = until.min(next);
            let c = self.core_mut();
            c.jumped += t.saturating_sub(c.now);
            c.now = c.now.max(t);
            c.chip.advance(c.now);
            return Ok(());
        }
        let primask = self.reg(RegisterARM::PRIMASK) & 1 != 0;
        let pending = self.chip().pending_exception();
        let mut deadline = until.min(next);
        match pending {
            Some(exc) if !primask => self.enter(exc)?,
            Some(_) => {
                // Masked: look again after a few instructions (a critical section is short).
                let c = self.core();
                deadline = deadline.min(c.now + 8 * c.ps_per_instr);
            }
            None => {}
        }
        let c = self.core_mut();
        c.deadline = deadline.max(c.now + 1);
        c.exit = None;
        let pc = self.reg(RegisterARM::PC);
        let r = self.uc.emu_start(u64::from(pc | 1), 0, 0, 0);
        let exit = self.core_mut().exit.take();
        let pc_now = self.reg(RegisterARM::PC);
        if exit == Some(Exit::PowerCut) {
            self.core_mut().power_cut_after = None;
            return self.power_cycle();
        }
        match r {
            Ok(()) => Ok(()),
            // The handler's return to EXC_RETURN: a fetch Unicorn refuses.
            Err(_) if pc_now >= 0xFFFF_FF00 && !self.chip().active.is_empty() => {
                self.exception_return(pc_now | 1)
            }
            Err(e) => {
                let now = self.now();
                if self.core().trace > 0 {
                    eprintln!("fault {e:?} at pc {pc_now:#x}");
                }
                self.faults.push((now, pc_now, format!("{e:?}")));
                if self.chip().active.contains(&3) {
                    self.locked = true;
                    Ok(())
                } else {
                    self.enter(3)
                }
            }
        }
    }
}

impl Machine {
    /// Stack high-water mark since power-up, bytes: from the initial stack pointer
    /// (`_stack_start`) down to the lowest byte below it, above the static RAM (`_stack_end`),
    /// that no longer holds the power-up pattern [`RAM_FILL`]. `None` without those symbols.
    /// (A stack byte that happens to be written with the pattern itself is not seen: the
    /// figure can only be low by the few bytes at the deepest point.)
    pub fn stack_used(&self) -> Option<u32> {
        let top = self.image.symbol("_stack_start")?.addr;
        let end = self.image.symbol("_stack_end")?.addr;
        let mut ram = vec![0u8; top.checked_sub(end)? as usize];
        self.uc.mem_read(u64::from(end), &mut ram).ok()?;
        let deepest = ram.iter().position(|&b| b != RAM_FILL)?;
        Some(top - end - deepest as u32)
    }

    /// Whether the function `sym` is on the call chain now: a return address into it (Thumb
    /// bit set) lies on the live main stack, between SP and the initial stack pointer of the
    /// vector table, or the PC is in it.
    pub fn on_call_stack(&self, sym: &crate::elf::Symbol) -> bool {
        let start = sym.addr & !1;
        let inside = |a: u32| (start..start + sym.size).contains(&(a & !1));
        if inside(self.reg(RegisterARM::PC)) {
            return true;
        }
        let (Ok(top), sp) = (self.vector(0), self.reg(RegisterARM::SP)) else {
            return false;
        };
        let mut a = sp & !3;
        while a + 4 <= top {
            if self.read_u32(a).is_ok_and(|w| w & 1 == 1 && inside(w)) {
                return true;
            }
            a += 4;
        }
        false
    }

    /// Debug summary: PC, SP, PRIMASK, active exceptions.
    pub fn debug_state(&self) -> String {
        format!(
            "pc {:#x} sp {:#x} primask {} control {:#x} active {:?} usart {:?}",
            self.reg(RegisterARM::PC),
            self.reg(RegisterARM::SP),
            self.reg(RegisterARM::PRIMASK),
            self.reg(RegisterARM::CONTROL),
            self.chip().active,
            self.chip().usart1.next_event()
        )
    }
}

impl Machine {
    /// Replaces the whole flash memory (e.g. with another run's, kept across a power cycle)
    /// and reboots from it.
    pub fn load_flash(&mut self, mem: &[u8]) -> Result<(), String> {
        if mem.len() != flash::SIZE as usize {
            return Err(format!(
                "flash image of {} bytes, not {}",
                mem.len(),
                flash::SIZE
            ));
        }
        self.chip_mut().flash.mem.copy_from_slice(mem);
        self.uc
            .mem_write(u64::from(flash::BASE), mem)
            .map_err(uc_err("load flash"))?;
        self.resets.clear();
        self.boot(ResetCause::PowerOn)
    }

    /// Writes `bytes` at `offset` into the flash while the image runs, without the flash
    /// interface and without a stall (a test's shortcut to a store state a run would take
    /// many saves to reach).
    pub fn write_flash(&mut self, offset: u32, bytes: &[u8]) -> Result<(), String> {
        self.chip_mut().flash.load(offset, bytes)?;
        self.uc
            .mem_write(u64::from(flash::BASE + offset), bytes)
            .map_err(uc_err("write flash"))
    }
}
