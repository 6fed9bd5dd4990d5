//! The STM32F411's bus as the core sees it: which peripheral model answers which address
//! (RM0383 §2.3, Table 1 "STM32F411xC/E register boundary addresses"; PM0214 §4.1 for the
//! Cortex-M4's private peripheral bus), byte and halfword accesses onto word registers, the
//! clock tree carried to the peripherals after each RCC write, the interrupt lines, and the
//! log of accesses no model answers.

use std::collections::BTreeMap;

use crate::periph::backup::{self, Backup};
use crate::periph::bitband;
use crate::periph::dbgmcu::{self, Dbgmcu};
use crate::periph::flash::{Effect, Flash};
use crate::periph::gpio::Gpio;
use crate::periph::i2c::{Device, I2c};
use crate::periph::iwdg::Iwdg;
use crate::periph::nvic::{Nvic, IRQ_USART1};
use crate::periph::rcc::{Clocks, Rcc, ResetCause};
use crate::periph::scb::Scb;
use crate::periph::timer::Timer;
use crate::periph::usart::Usart;
use crate::periph::{Time, Unmodelled};

/// TIM3 (pump PWM).
pub const TIM3: u32 = 0x4000_0400;
/// TIM5 (loop tick counter).
pub const TIM5: u32 = 0x4000_0C00;
/// IWDG.
pub const IWDG: u32 = 0x4000_3000;
/// I2C1 (the sensor).
pub const I2C1: u32 = 0x4000_5400;
/// USART1 (the console).
pub const USART1: u32 = 0x4001_1000;
/// GPIOA.
pub const GPIOA: u32 = 0x4002_0000;
/// GPIOB.
pub const GPIOB: u32 = 0x4002_0400;
/// RCC.
pub const RCC: u32 = 0x4002_3800;
/// FLASH interface registers.
pub const FLASH_R: u32 = 0x4002_3C00;
/// NVIC registers (ISER0).
pub const NVIC: u32 = 0xE000_E100;

/// Which model a peripheral address belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Unit {
    /// TIM3.
    Tim3,
    /// TIM5.
    Tim5,
    /// IWDG.
    Iwdg,
    /// I2C1.
    I2c1,
    /// USART1.
    Usart1,
    /// GPIOA.
    GpioA,
    /// GPIOB.
    GpioB,
    /// RCC.
    Rcc,
    /// FLASH interface.
    Flash,
    /// NVIC.
    Nvic,
    /// SCB, FPU system registers, SysTick.
    Scb,
    /// DBGMCU.
    Dbgmcu,
    /// Device electronic signature.
    Signature,
    /// PWR.
    Pwr,
    /// RTC (its backup registers).
    Rtc,
}

/// The unit and register offset of `addr`, if a model covers it.
pub fn decode(addr: u32) -> Option<(Unit, u32)> {
    let block = |base: u32, size: u32| (base..base + size).contains(&addr).then(|| addr - base);
    let table = [
        (Unit::Tim3, TIM3, 0x400),
        (Unit::Tim5, TIM5, 0x400),
        (Unit::Iwdg, IWDG, 0x400),
        (Unit::I2c1, I2C1, 0x400),
        (Unit::Usart1, USART1, 0x400),
        (Unit::GpioA, GPIOA, 0x400),
        (Unit::GpioB, GPIOB, 0x400),
        (Unit::Rcc, RCC, 0x400),
        (Unit::Flash, FLASH_R, 0x400),
        (Unit::Nvic, NVIC, 0x3F0),
        (Unit::Dbgmcu, dbgmcu::BASE, 0x10),
        (Unit::Signature, 0x1FFF_7A00, 0x100),
        (Unit::Pwr, backup::PWR, 0x400),
        (Unit::Rtc, backup::RTC, 0x400),
    ];
    for (unit, base, size) in table {
        if let Some(off) = block(base, size) {
            return Some((unit, off));
        }
    }
    if (0xE000_E000..0xE000_F000).contains(&addr) {
        return Some((Unit::Scb, addr));
    }
    None
}

/// An access no model answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Miss {
    /// Address.
    pub addr: u32,
    /// Write (else read).
    pub write: bool,
}

/// All peripheral models and the bus between them.
pub struct Chip {
    /// RCC.
    pub rcc: Rcc,
    /// Flash memory and interface.
    pub flash: Flash,
    /// GPIOA.
    pub gpioa: Gpio,
    /// GPIOB.
    pub gpiob: Gpio,
    /// TIM3.
    pub tim3: Timer,
    /// TIM5.
    pub tim5: Timer,
    /// USART1.
    pub usart1: Usart,
    /// I2C1 with the sensor.
    pub i2c1: I2c,
    /// IWDG.
    pub iwdg: Iwdg,
    /// NVIC.
    pub nvic: Nvic,
    /// SCB, FPU system registers, SysTick.
    pub scb: Scb,
    /// DBGMCU.
    pub dbgmcu: Dbgmcu,
    /// PWR and the backup registers.
    pub backup: Backup,
    /// Exceptions active now, innermost last (kept by the machine, for ICSR).
    pub active: Vec<u32>,
    /// Accesses no model answered, with their counts.
    pub misses: BTreeMap<Miss, u64>,
    /// Instructions executed at the access being served (set by the machine).
    pub instr: u64,
    clocks: Clocks,
}

impl std::fmt::Debug for Chip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Chip")
            .field("clocks", &self.clocks)
            .finish()
    }
}

impl Chip {
    /// A powered-up chip with erased flash and `device` on I2C1.
    pub fn new(device: Box<dyn Device>) -> Self {
        let rcc = Rcc::new();
        let clocks = rcc.clocks();
        let mut chip = Chip {
            rcc,
            flash: Flash::new(),
            gpioa: Gpio::new('A'),
            gpiob: Gpio::new('B'),
            tim3: Timer::new(false),
            tim5: Timer::new(true),
            usart1: Usart::new(),
            i2c1: I2c::new(device),
            iwdg: Iwdg::new(),
            nvic: Nvic::new(),
            scb: Scb::new(),
            dbgmcu: Dbgmcu::default(),
            backup: Backup::new(),
            active: Vec::new(),
            misses: BTreeMap::new(),
            instr: 0,
            clocks,
        };
        chip.clocks_changed(0);
        chip
    }

    /// A system reset by `cause` at `now`: every register to its reset value; the flash
    /// memory, the reset flags, the backup registers and what is on the external lines are
    /// kept. A power-on also resets the backup domain (no battery on VBAT: see
    /// [`crate::periph::backup`]).
    pub fn reset(&mut self, cause: ResetCause, now: Time) {
        if cause == ResetCause::PowerOn {
            self.backup.domain_reset();
        } else {
            self.backup.reset();
        }
        self.rcc.reset(cause);
        self.flash.reset();
        self.gpioa.reset();
        self.gpiob.reset();
        // The pins are inputs again: the MCU drives neither line.
        self.i2c1.device.pins(now, false, false);
        self.tim3.reset();
        self.tim5.reset();
        self.usart1.advance(now);
        self.usart1.reset();
        self.i2c1.reset();
        self.iwdg = Iwdg::new();
        self.nvic = Nvic::new();
        self.scb = Scb::new();
        self.dbgmcu = Dbgmcu::default();
        self.active.clear();
        self.clocks_changed(now);
    }

    /// The clocks in effect.
    pub fn clocks(&self) -> Clocks {
        self.clocks
    }

    fn clocks_changed(&mut self, now: Time) {
        let c = self.rcc.clocks();
        self.clocks = c;
        self.tim3.set_clock(c.tim1clk, now);
        self.tim5.set_clock(c.tim1clk, now);
        self.usart1.set_clock(c.pclk2);
        self.i2c1.set_clock(c.pclk1);
    }

    /// Brings the self-timed models up to `now`.
    pub fn advance(&mut self, now: Time) {
        self.usart1.advance(now);
        self.i2c1.advance(now);
        self.iwdg.settle(now);
    }

    /// The next time a model changes by itself (a frame or a byte ends, the watchdog
    /// expires).
    pub fn next_event(&self) -> Option<Time> {
        [
            self.usart1.next_event(),
            self.i2c1.next_event(),
            self.iwdg.next_event(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Interrupt lines that are high.
    pub fn lines(&self) -> Vec<u32> {
        let mut v = Vec::new();
        if self.usart1.irq() {
            v.push(IRQ_USART1);
        }
        v
    }

    /// The interrupt (exception number 16 + IRQ) to take now, if any may preempt what runs
    /// (PM0214 §2.3.4: a lower group-priority value preempts; PRIGROUP splits the byte).
    pub fn pending_exception(&self) -> Option<u32> {
        let irq = self.nvic.next(&self.lines())?;
        let p = self.nvic.priority(irq);
        let group = |p: u8| u32::from(p) >> (self.scb.prigroup() + 1).min(8);
        match self.active.last() {
            None => Some(16 + irq),
            Some(&exc) => {
                let cur = if exc >= 16 {
                    self.nvic.priority(exc - 16)
                } else {
                    self.scb.system_priority(exc)
                };
                (group(p) < group(cur)).then_some(16 + irq)
            }
        }
    }

    /// `ICSR` as the core would show it (VECTACTIVE, VECTPENDING, ISRPENDING).
    fn icsr(&self) -> u32 {
        let active = self.active.last().copied().unwrap_or(0);
        let pending = self.nvic.next(&self.lines()).map_or(0, |i| i + 16);
        active | (pending << 12) | if pending != 0 { 1 << 22 } else { 0 }
    }

    fn miss(&mut self, addr: u32, write: bool) {
        let n = self.misses.entry(Miss { addr, write }).or_insert(0);
        if *n == 0 {
            eprintln!(
                "stm32-harness: unmodelled {} at {addr:#010x}",
                if write { "write" } else { "read" }
            );
        }
        *n += 1;
    }

    fn read_word(&mut self, addr: u32, now: Time) -> Result<u32, Unmodelled> {
        let (unit, off) = decode(addr).ok_or(Unmodelled)?;
        match unit {
            Unit::Tim3 => self.tim3.read(off, now),
            Unit::Tim5 => self.tim5.read(off, now),
            Unit::Iwdg => self.iwdg.read(off, now),
            Unit::I2c1 => self.i2c1.read(off, now),
            Unit::Usart1 => self.usart1.read(off, now),
            Unit::GpioA => self.gpioa.read(off),
            Unit::GpioB if off == 0x10 => {
                // IDR: PB6/PB7 read the I2C lines.
                let (scl, sda) = self.i2c1.device.levels(now);
                let v = self.gpiob.read(off)? & !((1 << 6) | (1 << 7));
                Ok(v | u32::from(scl) << 6 | u32::from(sda) << 7)
            }
            Unit::GpioB => self.gpiob.read(off),
            Unit::Rcc => self.rcc.read(off),
            Unit::Flash => self.flash.read(off, now),
            Unit::Nvic => {
                let lines = self.lines();
                self.nvic.read(off, &lines)
            }
            Unit::Scb => {
                let icsr = self.icsr();
                self.scb.read(off, now, self.clocks.hclk, icsr)
            }
            Unit::Dbgmcu => self.dbgmcu.read(off),
            Unit::Pwr => self.backup.read_pwr(off),
            Unit::Rtc => self.backup.read_rtc(off),
            Unit::Signature => Err(Unmodelled),
        }
    }

    fn write_word(
        &mut self,
        addr: u32,
        v: u32,
        size: u32,
        now: Time,
    ) -> Result<Effect, Unmodelled> {
        let (unit, off) = decode(addr).ok_or(Unmodelled)?;
        match unit {
            Unit::Tim3 => self.tim3.write(off, v, now)?,
            Unit::Tim5 => self.tim5.write(off, v, now)?,
            Unit::Iwdg => self.iwdg.write(off, v, now)?,
            Unit::I2c1 => self.i2c1.write(off, v, now)?,
            Unit::Usart1 => self.usart1.write(off, v, now, self.instr)?,
            Unit::GpioA => self.gpioa.write(off, v)?,
            Unit::GpioB => {
                self.gpiob.write(off, v)?;
                let (scl, sda) = (self.gpiob.drives_low(6), self.gpiob.drives_low(7));
                self.i2c1.device.pins(now, scl, sda);
            }
            Unit::Rcc => {
                self.rcc.write(off, v)?;
                self.clocks_changed(now);
            }
            Unit::Flash => return self.flash.write(off, v, now),
            Unit::Nvic => self.nvic.write(off, v, size)?,
            Unit::Scb if off == 0xE000_EF00 => self.nvic.trigger(v),
            Unit::Scb => self.scb.write(off, v, now, self.clocks.hclk)?,
            Unit::Dbgmcu => self.dbgmcu.write(off, v)?,
            Unit::Pwr => {
                let clock = self.rcc.pwr_clock();
                self.backup.write_pwr(off, v, clock)?
            }
            Unit::Rtc => self.backup.write_rtc(off, v)?,
            Unit::Signature => return Err(Unmodelled),
        }
        Ok(Effect::default())
    }

    /// A read of `size` bytes at `addr` at `now` (peripheral, bit-band alias, signature or
    /// system space); an unmodelled one reads 0 and is logged.
    pub fn read(&mut self, addr: u32, size: u32, now: Time) -> u32 {
        if (bitband::ALIAS..bitband::ALIAS + bitband::ALIAS_SIZE).contains(&addr) {
            let (word, bit) = bitband::target(addr);
            return match self.read_word(word, now) {
                Ok(v) => (v >> bit) & 1,
                Err(Unmodelled) => {
                    self.miss(addr, false);
                    0
                }
            };
        }
        if (0x1FFF_7A00..0x1FFF_7B00).contains(&addr) {
            return Flash::signature(addr, size).unwrap_or_else(|_| {
                self.miss(addr, false);
                0
            });
        }
        let shift = 8 * (addr & 3);
        let mask = if size >= 4 {
            u32::MAX
        } else {
            (1u32 << (8 * size)) - 1
        };
        match self.read_word(addr & !3, now) {
            Ok(v) => (v >> shift) & mask,
            Err(Unmodelled) => {
                self.miss(addr, false);
                0
            }
        }
    }

    /// A write of `size` bytes of `v` at `addr` at `now`; returns its effect on the flash
    /// memory (a started erase). An unmodelled one is logged.
    pub fn write(&mut self, addr: u32, size: u32, v: u32, now: Time) -> Effect {
        if (bitband::ALIAS..bitband::ALIAS + bitband::ALIAS_SIZE).contains(&addr) {
            let (word, bit) = bitband::target(addr);
            let r = self.read_word(word, now).and_then(|old| {
                let new = if v & 1 != 0 {
                    old | (1 << bit)
                } else {
                    old & !(1 << bit)
                };
                self.write_word(word, new, 4, now)
            });
            return r.unwrap_or_else(|_| {
                self.miss(addr, true);
                Effect::default()
            });
        }
        let (word, value, n) = match decode(addr) {
            Some((Unit::Nvic, off)) if off >= 0x300 => (addr, v, size),
            _ => (addr & !3, v << (8 * (addr & 3)), 4),
        };
        self.write_word(word, value, n, now).unwrap_or_else(|_| {
            self.miss(addr, true);
            Effect::default()
        })
    }

    /// Whether the register at `addr` can change by itself (a counter, a status flag, an
    /// input): only such a register can be waited on, so only reads of one count as polling
    /// for the clock jump. Reading a constant (the flash-size word in a loop over the record
    /// slots) is work, not a wait.
    pub fn changes_by_itself(addr: u32) -> bool {
        use crate::periph::{flash, i2c, iwdg, timer, usart};
        let Some((unit, off)) = decode(addr & !3) else {
            return false;
        };
        match unit {
            Unit::Tim3 | Unit::Tim5 => matches!(off, timer::CNT | timer::SR),
            Unit::Usart1 => off == usart::SR,
            Unit::I2c1 => matches!(off, i2c::SR1 | i2c::SR2 | i2c::CR1),
            Unit::Flash => off == flash::SR,
            Unit::Iwdg => off == iwdg::SR,
            Unit::Rcc => matches!(off, 0x00 | 0x08 | 0x74),
            Unit::GpioA | Unit::GpioB => off == 0x10,
            Unit::Scb => matches!(off, 0xE000_E010 | 0xE000_E018 | 0xE000_ED04),
            Unit::Nvic | Unit::Dbgmcu | Unit::Signature | Unit::Pwr | Unit::Rtc => false,
        }
    }

    /// Changes of state that the machine must act on: a reset requested by software.
    pub fn take_reset_request(&mut self) -> bool {
        std::mem::take(&mut self.scb.reset_requested)
    }
}
