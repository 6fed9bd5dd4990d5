//! STM32F411 "Black Pill" (STM32F411CEU6, 25 MHz HSE, 512 KB flash) glue on stm32f4xx-hal.
//!
//! | function | peripheral | pin |
//! |---|---|---|
//! | SFM3300 | I2C1, 100 kHz, bus recovery ([`bus::Bus`]) | PB6 SCL, PB7 SDA (5 V tolerant; external pull-ups) |
//! | pump PWM | TIM3 CH1, 20 kHz | PA6 |
//! | exhalation valve | GPIO push-pull output, high = closed ([`valve`]) | PB0 |
//! | reports, console | USART1 115200 8N1 (one interrupt: TXE + queue, RXNE + queue) | PA9 TX, PA10 RX |
//! | tick | TIM5, free-running 10 kHz counter, polled | — |
//! | watchdog | IWDG, 0.5 s | — |
//! | record | flash sectors 6 and 7 (0x0804_0000, 0x0806_0000, 128 KB each), a slot log | — |
//! | reset-loop count | backup register RTC_BKP0R (PWR_CR.DBP for writes) | — |
//!
//! The tick is a free-running 32-bit TIM5 count rather than an interrupt: it keeps counting
//! while the CPU is stalled by a flash erase, so lost ticks are counted exactly.

use core::convert::Infallible;
use core::sync::atomic::{AtomicBool, Ordering};

use stm32f4xx_hal::flash::FlashExt;
use stm32f4xx_hal::gpio::{PA10, PA9};
use stm32f4xx_hal::pac::{self, interrupt, FLASH, PWR, RTC, TIM5, USART1};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::{Enable, Rcc};
use stm32f4xx_hal::serial::config::InvalidConfig;
use stm32f4xx_hal::serial::Serial;
use stm32f4xx_hal::timer::Counter;
use stm32f4xx_hal::watchdog::IndependentWatchdog;

use ridge_pump_firmware::flash_store::{self, SECTORS, SECTOR_LEN};
use ridge_pump_firmware::persist::RECORD_LEN;
use ridge_pump_firmware::resets::Resets;
use ridge_pump_firmware::ring::Ring;
use ridge_pump_firmware::slots;

pub mod bus;
pub mod valve;

/// Frequency of the TIM5 tick counter.
pub const COUNTER_HZ: u32 = 10_000;
/// Counter ticks per 10 ms loop tick.
const PERIOD: u32 = COUNTER_HZ / 100;

/// Loop ticks from a free-running TIM5.
pub struct Ticker {
    timer: Counter<TIM5, COUNTER_HZ>,
    /// Counter value of the last tick boundary handled.
    last: u32,
}

impl Ticker {
    /// Starts TIM5 counting at [`COUNTER_HZ`], wrapping after 2³² − 1 counts (≈ 119 h).
    pub fn new(mut timer: Counter<TIM5, COUNTER_HZ>) -> Self {
        // ARR = u32::MAX − 1: the largest the HAL allows; the one-count irregularity at the wrap
        // (every 119 h) shifts one tick by 0.1 ms.
        timer
            .start(fugit::TimerDurationU32::from_ticks(u32::MAX))
            .ok();
        let last = timer.now().ticks();
        Ticker { timer, last }
    }

    fn now(&self) -> u32 {
        self.timer.now().ticks()
    }

    /// Non-blocking: the 10 ms boundaries passed since the last call that returned `Some`
    /// (saturated to 65535), or `None`.
    pub fn poll(&mut self) -> Option<u16> {
        let since = self.now().wrapping_sub(self.last);
        if since < PERIOD {
            return None;
        }
        let elapsed = since / PERIOD;
        self.last = self.last.wrapping_add(elapsed * PERIOD);
        Some(u16::try_from(elapsed).unwrap_or(u16::MAX))
    }
}

// USART_SR bits (RM0383 §19.6.1). FE and NF come with the byte in DR (it is damaged); ORE
// says a byte after it was lost. All three are cleared by a read of SR followed by a read of
// DR (§19.3.3, "Overrun error", "Noise error", "Framing error").
const SR_FE: u16 = 1 << 1;
const SR_NF: u16 = 1 << 2;
const SR_ORE: u16 = 1 << 3;
const SR_RXNE: u16 = 1 << 5;
const SR_TXE: u16 = 1 << 7;
// USART_CR1 bits (RM0383 §19.6.4). RXNEIE raises the interrupt for RXNE and for ORE (§19.4).
const CR1_RXNEIE: u16 = 1 << 5;
const CR1_TXEIE: u16 = 1 << 7;

/// Transmit queue, drained by the USART1 interrupt.
static TX: Ring<256> = Ring::new();

/// Receive queue, filled by the USART1 interrupt, read by the main loop ([`receive`]). 255
/// bytes: 22 ms at 115200 baud without a read; the loop reads while it waits for each tick
/// (one command line per pass), not during the ticking search.
static RX: Ring<256> = Ring::new();

/// Set by the USART1 interrupt when a received byte is lost (queue full, or an overrun,
/// noise or framing error); cleared by [`receive_overrun`] once the main loop has read every
/// byte received before the loss. Until then the interrupt drops every byte, so the gap lies
/// in the line the main loop is assembling when it learns of the loss, and that line is
/// refused (`ERR overrun`); lines received whole before the loss are still executed.
/// `pub(crate)` for the QEMU test image, which waits for a loss (read only).
pub(crate) static RX_LOST: AtomicBool = AtomicBool::new(false);

/// The next received byte, if any (main loop only). `None` at a loss, until
/// [`receive_overrun`] has reported it.
pub fn receive() -> Option<u8> {
    RX.pop()
}

/// Whether received bytes were lost at this point of the byte stream (main loop only): `true`
/// once, when a loss is pending and the bytes received before it have all been read.
pub fn receive_overrun() -> bool {
    if RX_LOST.load(Ordering::Acquire) && RX.is_empty() {
        // The interrupt pushes nothing while the flag is set: the queue stays empty.
        RX_LOST.store(false, Ordering::Release);
        true
    } else {
        false
    }
}

/// Free bytes in the transmit queue (main loop only).
pub fn tx_room() -> usize {
    TX.room()
}

/// Console baud rate (8N1).
pub const BAUD: u32 = 115_200;

/// The console's USART1 as a [`Uart`]: [`BAUD`] 8N1 on PA9 (TX) and PA10 (RX, with the
/// internal pull-up: an unconnected PA10 idles high instead of floating into framing errors).
/// Fails only if `rcc`'s clocks cannot reach the baud rate.
pub fn console_uart(
    usart: USART1,
    tx: PA9,
    rx: PA10,
    rcc: &mut Rcc,
) -> Result<Uart<Serial<USART1, u8>>, InvalidConfig> {
    let rx = rx.internal_pull_up(true);
    let serial = usart.serial((tx, rx), BAUD.bps(), rcc)?;
    Ok(Uart::new(serial))
}

/// USART1 transmitter (`ufmt::uWrite`) over a queue, and receiver into a queue. The HAL's
/// `Serial` has configured the peripheral (baud, TE and RE, pins) and is kept so nothing else
/// can take it.
pub struct Uart<T> {
    _serial: T,
}

impl<T> Uart<T> {
    /// Takes the configured USART, discards what the receiver holds (a byte or an error from
    /// before the RX pin was connected), enables the receive interrupt and unmasks USART1.
    pub fn new(serial: T) -> Self {
        // SAFETY: USART1 is configured and its interrupt still masked: nothing else accesses
        // it; SR then DR clears RXNE and the error flags (§19.3.3).
        let usart = unsafe { &*USART1::ptr() };
        let _ = usart.sr().read();
        let _ = usart.dr().read();
        usart
            .cr1()
            .modify(|r, w| unsafe { w.bits(r.bits() | CR1_RXNEIE) });
        // SAFETY: the handler only uses the queues, RX_LOST and USART1's SR/DR/CR1.TXEIE.
        unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
        Uart { _serial: serial }
    }

    fn write_byte(&mut self, byte: u8) {
        while !TX.push(byte) {
            // `Primask::Active`: PRIMASK clear, interrupts taken.
            if cortex_m::register::primask::read().is_active() {
                continue; // the interrupt drains the queue
            }
            // Interrupts are masked: nobody else drains the queue.
            if let Some(old) = TX.pop() {
                send_polled(old);
            }
        }
        cortex_m::interrupt::free(|_| {
            // SAFETY: read-modify-write of CR1 inside a critical section.
            let usart = unsafe { &*USART1::ptr() };
            usart.cr1().modify(|_, w| w.txeie().set_bit());
        });
    }
}

impl<T> ufmt::uWrite for Uart<T> {
    type Error = Infallible;

    fn write_str(&mut self, s: &str) -> Result<(), Infallible> {
        for &byte in s.as_bytes() {
            self.write_byte(byte);
        }
        Ok(())
    }
}

/// Sends one byte on USART1 by polling TXE (bounded), e.g. from the panic handler.
pub fn send_polled(byte: u8) {
    // SAFETY: DR/SR accesses only; used where the queue's interrupt cannot run.
    let usart = unsafe { &*USART1::ptr() };
    for _ in 0..100_000u32 {
        if usart.sr().read().txe().bit_is_set() {
            usart.dr().write(|w| unsafe { w.bits(u16::from(byte)) });
            return;
        }
    }
}

/// USART1: transmit and receive share this handler. Receive first (a byte waits in DR only
/// until the next one arrives, 87 µs at 115200 baud), then at most one byte to transmit if
/// TXEIE is on.
#[interrupt]
fn USART1() {
    // SAFETY: the main loop only sets TXEIE (inside a critical section; RXNEIE once, in
    // `Uart::new`, before the interrupt is unmasked) and touches SR/DR only through
    // `send_polled` with interrupts masked.
    let usart = unsafe { &*USART1::ptr() };
    let sr = usart.sr().read().bits();
    if sr & (SR_RXNE | SR_ORE) != 0 {
        // Reading DR after SR takes the byte and clears RXNE, ORE, NF and FE (§19.3.3). With
        // ORE and no RXNE there is nothing new in DR, but the read is still needed to clear
        // ORE, which would otherwise raise the interrupt again at once. With ORE and RXNE the
        // byte in DR is valid and older than the lost one.
        let byte = usart.dr().read().bits() as u8;
        let valid = sr & (SR_RXNE | SR_NF | SR_FE) == SR_RXNE;
        let kept = valid && !RX_LOST.load(Ordering::Relaxed) && RX.push(byte);
        if !kept || sr & SR_ORE != 0 {
            RX_LOST.store(true, Ordering::Release);
        }
    }
    let txeie = usart.cr1().read().bits() & CR1_TXEIE != 0;
    if txeie && sr & SR_TXE != 0 {
        match TX.pop() {
            Some(byte) => {
                usart.dr().write(|w| unsafe { w.bits(u16::from(byte)) });
            }
            None => {
                usart.cr1().modify(|_, w| w.txeie().clear_bit());
            }
        }
    }
}

/// Pump off without the PWM adapter, for the panic handler: TIM3 CCR1 = 0 (PWM mode 1: output
/// constantly low).
pub fn force_pump_off() {
    // SAFETY: a single register write; the panic handler runs with interrupts disabled and
    // never returns to the owner of TIM3.
    let tim3 = unsafe { &*pac::TIM3::ptr() };
    tim3.ccr1().write(|w| unsafe { w.bits(0) });
}

/// Watchdog timeout while a sector erase (typ. 2 s, max 4 s at 8-bit parallelism, DS10314)
/// stalls the CPU: 8 s at the LSI's typical 32 kHz, ≥ 5.4 s at its fastest 47 kHz.
const ERASE_WATCHDOG_MS: u32 = 8_000;
/// Normal watchdog timeout.
pub const WATCHDOG_MS: u32 = 500;
/// Reads of IWDG_SR while a new prescaler and reload value reach the watchdog's domain (up
/// to 5 LSI periods: 294 µs at the slowest LSI, 17 kHz; one read takes ≥ 2 cycles, so this
/// bounds the wait at ≥ 2 ms at 100 MHz).
const IWDG_UPDATE_POLLS: u32 = 100_000;

/// Sets the IWDG's timeout to `ms` and reloads the counter with it. The HAL's `start` writes
/// the prescaler and reload value and reloads at once, while IWDG_SR.PVU/RVU are still set:
/// that reload uses the old values (RM0383 §15.4.4: the new ones are carried into the
/// watchdog's domain over up to 5 LSI periods), so a timeout raised for an erase would not be
/// in effect during it. Here the reload waits (bounded) until both flags have cleared.
fn set_watchdog(watchdog: &mut IndependentWatchdog, ms: u32) {
    watchdog.start(fugit::MillisDurationU32::millis(ms));
    // SAFETY: a read of IWDG_SR only; `watchdog` owns the IWDG and is borrowed mutably here.
    let iwdg = unsafe { &*pac::IWDG::ptr() };
    for _ in 0..IWDG_UPDATE_POLLS {
        if iwdg.sr().read().bits() & 0b11 == 0 {
            break;
        }
    }
    watchdog.feed();
}

/// The record store ([`ridge_pump_firmware::flash_store`]): a log of slots over flash sectors
/// 6 and 7 (0x0804_0000 and 0x0806_0000, 128 KB each), so that a power cut at any program
/// access of a save, or during the erase that makes room, leaves the previous record
/// loadable. A save programs 117 bytes (~16 µs each, the CPU stalled meanwhile). An erase
/// (making room when the sector in use fills up, 1 024 saves) stalls the CPU for ~2 s (up to
/// 4 s): no sensor reads, the PWM holding its duty. So it is done only at boot, before the pump
/// is driven ([`prepare`](Self::prepare), [`flash_store::boot_erase`]); a save that would need
/// one while running is refused. The watchdog's timeout is raised for an erase
/// ([`set_watchdog`]).
pub struct FlashStore {
    flash: FLASH,
    /// Whether the chip has sectors 6 and 7 (512 KB parts; 256 KB parts end at sector 5):
    /// without them persistence is off.
    available: bool,
    result: Option<bool>,
}

impl FlashStore {
    /// Takes the flash interface.
    pub fn new(flash: FLASH) -> Self {
        let (_, last) = SECTORS[1];
        let available = flash.len() >= last as usize + SECTOR_LEN;
        FlashStore {
            flash,
            available,
            result: None,
        }
    }

    /// Whether the chip has the store's sectors (persistence available).
    pub fn available(&self) -> bool {
        self.available
    }

    fn sectors(&self) -> [&[u8]; 2] {
        let mem = self.flash.read();
        SECTORS.map(|(_, offset)| {
            let at = offset as usize;
            mem.get(at..at + SECTOR_LEN).unwrap_or(&[])
        })
    }

    /// At boot, before the pump is driven: erases the sector [`flash_store::boot_erase`] names,
    /// if any (~2 s, the CPU stalled), with the watchdog's timeout raised meanwhile. Returns
    /// whether it erased; a failed erase leaves the store as the next save finds it (a save
    /// needing the erase is then refused).
    pub fn prepare(&mut self, watchdog: &mut IndependentWatchdog) -> bool {
        if !self.available {
            return false;
        }
        match flash_store::boot_erase(self.sectors()) {
            Some(index) => self.erase(index, watchdog).is_ok(),
            None => false,
        }
    }

    /// Erases the store's sector `index` (into [`SECTORS`]) with the watchdog's timeout raised.
    fn erase(&mut self, index: u8, watchdog: &mut IndependentWatchdog) -> Result<(), ()> {
        let (number, _) = SECTORS.get(usize::from(index)).copied().ok_or(())?;
        set_watchdog(watchdog, ERASE_WATCHDOG_MS);
        let erased = self.flash.unlocked().erase(number);
        set_watchdog(watchdog, WATCHDOG_MS);
        erased.map_err(drop)
    }

    /// The record to load ([`flash_store::plan`]).
    pub fn load(&self) -> Option<[u8; RECORD_LEN]> {
        if !self.available {
            return None;
        }
        let sectors = self.sectors();
        let plan = flash_store::plan(sectors);
        flash_store::record(sectors, &plan).and_then(|r| r.try_into().ok())
    }

    /// Saves `record` ([`RECORD_LEN`] bytes, or all `0xFF` to forget), blocking: ~1.9 ms of
    /// programming. A save that needs a sector erased first (the run made more than
    /// [`flash_store::RUN_SAVES`] saves) is refused: it fails, and the next boot makes the
    /// room ([`prepare`](Self::prepare)). A record equal to the one loaded now (or
    /// forgetting with none loaded) is not written again. The outcome comes from
    /// [`take_result`](Self::take_result).
    pub fn save(&mut self, record: &[u8]) {
        if record.len() != RECORD_LEN || !self.available {
            return;
        }
        let sectors = self.sectors();
        let plan = flash_store::plan(sectors);
        let same = match flash_store::record(sectors, &plan) {
            Some(current) => current == record,
            None => slots::is_tombstone(record),
        };
        let ok = same || (!plan.erase && self.append(record, &plan).is_ok());
        self.result = Some(ok);
    }

    /// Programs `record`'s slot where `plan` says (its sector erased already).
    fn append(&mut self, record: &[u8], plan: &flash_store::Plan) -> Result<(), ()> {
        let bytes = flash_store::slot_bytes(record, plan.seq).ok_or(())?;
        let at = plan.target.offset() as usize;
        self.flash
            .unlocked()
            .program(at, bytes.iter())
            .map_err(drop)?;
        let written = self.flash.read().get(at..at + bytes.len());
        if written == Some(&bytes[..]) {
            Ok(())
        } else {
            Err(())
        }
    }

    /// The result of the last save, once.
    pub fn take_result(&mut self) -> Option<bool> {
        self.result.take()
    }
}

/// Marks a reset count written by this image in [`ResetCount`]'s register: the top three
/// bytes, `"RPC"`. The register reads 0 after a backup-domain reset (RM0383 §17.6.20), which
/// is then no count.
const COUNT_MARK: u32 = 0x5250_4300;

/// The reset-loop count ([`ridge_pump_firmware::resets`]) in the backup register RTC_BKP0R.
///
/// Why there: the backup registers keep their content across every system reset (watchdog,
/// software, the reset pin) and across a power reset (brown-out, power-down) as long as the
/// backup domain stays powered (RM0383 §5.1.2, §6.1.2: "a power reset sets all registers to
/// their reset values except the Backup domain"): from VDD, and from VBAT while VDD is off.
/// A write is one 32-bit register access, so a reset during it leaves the old count or the
/// new one. RAM that survives a reset (an `.uninit` section) is not guaranteed to keep its
/// content through a brown-out; a flash word would be programmed at every boot and need
/// erasing. The count is lost only when the backup domain loses its supply, i.e. with VDD and
/// VBAT both off, a power-on, which clears the count anyway.
///
/// Reads need nothing (the RTC's own clock stays off); writes need the PWR interface's clock
/// (RCC_APB1ENR.PWREN) and the backup domain's write protection off (PWR_CR.DBP, RM0383
/// §5.4.1), both set by [`ResetCount::new`] and left so.
pub struct ResetCount {
    _pwr: PWR,
    rtc: RTC,
}

impl ResetCount {
    /// Takes PWR and the RTC (for its backup registers) and allows writes to the backup
    /// domain.
    pub fn new(pwr: PWR, rtc: RTC, rcc: &mut Rcc) -> Self {
        PWR::enable(rcc);
        pwr.cr().modify(|_, w| w.dbp().set_bit());
        ResetCount { _pwr: pwr, rtc }
    }

    /// The count stored (none if the register holds no count of this image).
    pub fn load(&self) -> Resets {
        let v = self.rtc.bkp0r().read().bits();
        if v & !0xFF == COUNT_MARK {
            Resets::from_byte(v as u8)
        } else {
            Resets::default()
        }
    }

    /// Stores `resets`.
    pub fn store(&mut self, resets: Resets) {
        let v = COUNT_MARK | u32::from(resets.to_byte());
        self.rtc.bkp0r().write(|w| unsafe { w.bits(v) });
    }
}
