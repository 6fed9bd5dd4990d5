//! ridge-pump firmware image for the Arduino Mega 2560 (ATmega2560, 16 MHz).
//!
//! Build: `scripts/build-boards` (nightly, `--target avr-none -Zbuild-std=core`). Pins, fuses and
//! flashing: `docs/boards.md`.
//!
//! Boot: read and clear the reset cause, set up UART, the exhalation valve (open), PWM (pump
//! stopped), TWI, the 100 Hz timer, read the stored record from EEPROM, start the state
//! machine, enable interrupts, arm the watchdog, print `BOOT ...`, then run the shared loop
//! (`board::app`).
//!
//! On the host this file compiles to a stub (`cargo build --all-features` stays a host build).
#![cfg_attr(target_arch = "avr", no_std, no_main)]
#![cfg_attr(target_arch = "avr", feature(abi_avr_interrupt, asm_experimental_arch))]

#[cfg(target_arch = "avr")]
#[path = "../board/mod.rs"]
mod board;

#[cfg(not(target_arch = "avr"))]
fn main() {
    eprintln!("atmega2560 is a board image: build it with scripts/build-boards");
    std::process::exit(2);
}

#[cfg(target_arch = "avr")]
mod image {
    use super::board::arduino_mega2560::{eeprom, pwm, stack, timer, twi, usart, valve, watchdog};
    use avr_device::atmega2560 as pac;
    #[cfg(not(feature = "atmega2560-reid"))]
    use core::mem::MaybeUninit;
    #[cfg(not(feature = "atmega2560-reid"))]
    use core::ptr::addr_of_mut;
    use ridge_pump_firmware::app::{App, Board, Console};
    #[cfg(feature = "atmega2560-reid")]
    use ridge_pump_firmware::event::Event;
    use ridge_pump_firmware::event::FaultReason;
    use ridge_pump_firmware::numfmt::Int;
    use ridge_pump_firmware::pump::Pump;
    use ridge_pump_firmware::resets::{self, Resets};
    use ridge_pump_firmware::selfid::{Defaults, SelfIdentification};
    use ridge_pump_firmware::sfm3300::Sfm3300;
    use ridge_pump_firmware::slots::{self, Plan, SLOT_LEN, STORE_LEN};
    use ridge_pump_firmware::ventilation::Valve;
    use ufmt::uwriteln;

    /// I2C clock: 400 kHz, the SFM3300's maximum (fast mode). One 3-byte read then takes
    /// ~0.1 ms of the tick instead of ~0.4 ms at 100 kHz, which the 1.6 ms tick budget needs.
    /// Fast mode allows 300 ns rise time: with the Mega's 10 kΩ and the 4.7 kΩ pull-ups at the
    /// sensor (3.2 kΩ) that holds up to ~110 pF of bus capacitance, i.e. a sensor cable of up to
    /// about 1 m; for longer cables use 100 kHz (reads then cost ~0.3 ms more per tick).
    const I2C_HZ: u32 = 400_000;

    struct Mega {
        ticker: timer::Ticker,
        watchdog: watchdog::Watchdog,
        eeprom: eeprom::Eeprom<SLOT_LEN>,
        /// Which slot is in use and where the next save goes.
        plan: Plan,
        /// A save in progress: whether it forgets (writes the all-0xFF tombstone).
        forgetting: Option<bool>,
        /// The reset count of this boot (`resets`), cleared in EEPROM after
        /// [`resets::CLEAN_TICKS`] unless it is a reset loop.
        resets: Resets,
        /// Ticks left until the count is cleared (0: done).
        clean: u16,
        console: Console,
        /// The exhalation valve (D22).
        valve: valve::ValvePin,
    }

    impl Board for Mega {
        const TICK_DURING_SEARCH: bool = false;
        fn poll_tick(&mut self) -> Option<u16> {
            self.ticker.poll()
        }
        fn pet(&mut self) {
            self.watchdog.pet();
        }
        /// Writes `record` into the slot not in use, sequence number last (`slots`).
        #[inline(never)]
        fn save(&mut self, record: &[u8]) {
            self.forgetting = Some(slots::is_tombstone(record));
            let plan = &self.plan;
            self.eeprom
                .save(slots::target_offset(plan), record, plan.seq);
        }
        fn poll_store(&mut self) -> Option<bool> {
            // A clean run: the resets before it were no loop (a loop keeps its count, and the
            // pump off, until a power-on or reset-pin reset).
            if self.clean > 0 {
                self.clean -= 1;
                if self.clean == 0
                    && !self.resets.is_loop()
                    && !self
                        .eeprom
                        .put(resets::COUNT_OFFSET, Resets::default().to_byte())
                {
                    self.clean = 1; // a slot save is in progress: next tick
                }
            }
            let done = self.eeprom.poll();
            if done == Some(true) {
                if let Some(forgot) = self.forgetting.take() {
                    self.plan = slots::after_write(&self.plan, forgot);
                }
            }
            done
        }
        fn stack(&self) -> Option<(u16, u16)> {
            Some(stack::usage())
        }
        fn receive(&mut self) -> Option<u8> {
            usart::receive()
        }
        fn tx_room(&self) -> usize {
            usart::tx_room()
        }
        fn console(&mut self) -> Option<&mut Console> {
            Some(&mut self.console)
        }
        fn set_valve(&mut self, valve: Valve) {
            self.valve.set(valve);
        }
    }

    type MegaApp = App<twi::Twi, pwm::Pwm4A, usart::Usart0, Defaults>;

    /// With run mode's re-identification (the state machine 3.1 KB) the loop state and the
    /// board parts live in `main`'s frame, which never returns: `init` builds them into it
    /// through its return value (the compiler passes it the frame's slot), and the state
    /// machine into that through its constructor's, so no copy of it is made on the way. Moved
    /// into statics (the default image's way, below) they were built in `init`'s frame first:
    /// 3 865 B of stack. The default image keeps the statics: `main`'s frame costs it 2.4 KB
    /// more flash (its code then addresses the state through a pointer). `build-boards` checks
    /// static RAM plus the stack either way.
    #[cfg(feature = "atmega2560-reid")]
    #[avr_device::entry]
    fn main() -> ! {
        let (app, board, boot_fault) = &mut init();
        if let Some(reason) = boot_fault {
            latch(app, *reason);
        }
        app.run(board)
    }

    /// Latches the reset loop's fault that `init` reported (`fault_detected` returns the
    /// `Event::Fault(reason)` it printed). Out of line: the returned event's slot would stay in
    /// `main`'s frame for good.
    #[cfg(feature = "atmega2560-reid")]
    #[inline(never)]
    fn latch(app: &mut MegaApp, reason: FaultReason) {
        app.selfid_mut().fault_detected(reason);
    }

    /// Sets everything up into `main`'s frame (this frame is gone afterwards); the reset loop's
    /// fault, reported, for `main` to latch.
    #[cfg(feature = "atmega2560-reid")]
    #[inline(never)]
    fn init() -> (MegaApp, Mega, Option<FaultReason>) {
        let dp = pac::Peripherals::take().unwrap(); // ok: first and only call, at boot
        let reset_cause = watchdog::take_reset_cause(&dp.CPU);

        let mut out = usart::Usart0::new(dp.USART0);
        // The exhalation valve open before the pump is driven.
        let valve = valve::ValvePin::new(dp.PORTA);
        let pump = match Pump::new(pwm::Pwm4A::new(dp.TC4, dp.PORTH)) {
            Ok(pump) => pump,
            Err(e) => match e {},
        };
        let sensor = Sfm3300::new(twi::Twi::new(dp.TWI, dp.PORTD, I2C_HZ));
        let mut eeprom = eeprom::Eeprom::<SLOT_LEN>::new(dp.EEPROM);
        let store: [u8; STORE_LEN] = eeprom.load();
        let plan = slots::plan(&store);
        let stored = slots::record(&store, &plan);
        // Reset loops (`resets`): count this boot's watchdog / brown-out reset; the third in a
        // row starts in the fault state. The EEPROM is idle at boot, so the write starts.
        let resets = Resets::from_byte(eeprom.byte(resets::COUNT_OFFSET)).after_boot(reset_cause);
        eeprom.put(resets::COUNT_OFFSET, resets.to_byte());
        let boot_fault = resets.is_loop().then_some(FaultReason::ResetLoop {
            watchdog: resets.watchdog,
            brownout: resets.brownout,
        });

        let ticker = timer::Ticker::new(dp.TC3);
        // SAFETY: all interrupt handlers (Timer3 compare, USART0 UDRE and RX) only use state
        // that is initialised statically.
        unsafe { avr_device::interrupt::enable() };
        let watchdog = watchdog::Watchdog::start(dp.WDT);

        uwriteln!(
            out,
            "BOOT board=atmega2560 reset={} record={}",
            Int::from(reset_cause),
            if stored.is_some() { "stored" } else { "none" }
        )
        .ok();
        if let Some(reason) = boot_fault {
            uwriteln!(out, "{}", Event::Fault(reason)).ok();
        }
        let board = Mega {
            ticker,
            watchdog,
            eeprom,
            plan,
            forgetting: None,
            resets,
            clean: resets::CLEAN_TICKS,
            console: Console::new(),
            valve,
        };
        let sid = SelfIdentification::new(Defaults, stored);
        (App::new(sensor, pump, out, sid, I2C_HZ), board, boot_fault)
    }

    /// The loop state and the board parts live in statics, not in `main`'s frame: `main` never
    /// returns, so every local of it (and every copy made while moving the ~0.7 KB state
    /// machine around) would occupy stack for good. As statics they count as static RAM, which
    /// `build-boards` checks.
    #[cfg(not(feature = "atmega2560-reid"))]
    static mut APP: MaybeUninit<MegaApp> = MaybeUninit::uninit();
    #[cfg(not(feature = "atmega2560-reid"))]
    static mut BOARD: MaybeUninit<Mega> = MaybeUninit::uninit();

    #[cfg(not(feature = "atmega2560-reid"))]
    #[avr_device::entry]
    fn main() -> ! {
        // SAFETY: `main` runs once, and these are the only references ever made to the statics.
        let (app, board) = unsafe { (&mut *addr_of_mut!(APP), &mut *addr_of_mut!(BOARD)) };
        let (app, board) = init(app, board);
        app.run(board)
    }

    /// Sets everything up and moves it into the statics (this frame is gone afterwards).
    #[cfg(not(feature = "atmega2560-reid"))]
    #[inline(never)]
    fn init<'a>(
        app: &'a mut MaybeUninit<MegaApp>,
        board: &'a mut MaybeUninit<Mega>,
    ) -> (&'a mut MegaApp, &'a mut Mega) {
        let dp = pac::Peripherals::take().unwrap(); // ok: first and only call, at boot
        let reset_cause = watchdog::take_reset_cause(&dp.CPU);

        let mut out = usart::Usart0::new(dp.USART0);
        // The exhalation valve open before the pump is driven.
        let valve = valve::ValvePin::new(dp.PORTA);
        let pump = match Pump::new(pwm::Pwm4A::new(dp.TC4, dp.PORTH)) {
            Ok(pump) => pump,
            Err(e) => match e {},
        };
        let sensor = Sfm3300::new(twi::Twi::new(dp.TWI, dp.PORTD, I2C_HZ));
        let mut eeprom = eeprom::Eeprom::<SLOT_LEN>::new(dp.EEPROM);
        let store: [u8; STORE_LEN] = eeprom.load();
        let plan = slots::plan(&store);
        let stored = slots::record(&store, &plan);
        let mut sid = SelfIdentification::new(Defaults, stored);
        // Reset loops (`resets`): count this boot's watchdog / brown-out reset; the third in a
        // row starts in the fault state. The EEPROM is idle at boot, so the write starts.
        let resets = Resets::from_byte(eeprom.byte(resets::COUNT_OFFSET)).after_boot(reset_cause);
        eeprom.put(resets::COUNT_OFFSET, resets.to_byte());
        let boot_fault = resets.is_loop().then(|| {
            sid.fault_detected(FaultReason::ResetLoop {
                watchdog: resets.watchdog,
                brownout: resets.brownout,
            })
        });

        let ticker = timer::Ticker::new(dp.TC3);
        // SAFETY: all interrupt handlers (Timer3 compare, USART0 UDRE and RX) only use state
        // that is initialised statically.
        unsafe { avr_device::interrupt::enable() };
        let watchdog = watchdog::Watchdog::start(dp.WDT);

        uwriteln!(
            out,
            "BOOT board=atmega2560 reset={} record={}",
            Int::from(reset_cause),
            if stored.is_some() { "stored" } else { "none" }
        )
        .ok();
        if let Some(event) = boot_fault {
            uwriteln!(out, "{}", event).ok();
        }
        let app = app.write(App::new(sensor, pump, out, sid, I2C_HZ));
        let board = board.write(Mega {
            ticker,
            watchdog,
            eeprom,
            plan,
            forgetting: None,
            resets,
            clean: resets::CLEAN_TICKS,
            console: Console::new(),
            valve,
        });
        (app, board)
    }

    /// Panic: pump off first (PWM compare register to 0 and the pin driven low, written
    /// directly) and the exhalation valve open (D22 low), interrupts off, a `PANIC` line sent
    /// by polling, then spin until the watchdog (0.5 s) resets the MCU.
    ///
    /// Resetting is deliberate: the loop's state cannot be trusted after a panic, and a fresh
    /// start (which reports `BOOT ... reset=8`, WDRF, unless the bootloader cleared MCUSR)
    /// restores service with the pump stopped until the state machine commands it again. During
    /// the reset the AVR's pins float: the pump driver input needs a pull-down (docs/boards.md).
    /// Neither message nor location is printed: the message would pull `core::fmt` into the
    /// image, and using the location keeps every panic's file name in .data (~1 KB of SRAM:
    /// constants live in RAM on AVR).
    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        avr_device::interrupt::disable();
        // SAFETY: interrupts are off and nothing runs after this handler.
        unsafe { pwm::force_off() };
        // SAFETY: as above.
        unsafe { valve::force_open() };
        uwriteln!(usart::Polled, "\nPANIC").ok();
        loop {
            core::hint::spin_loop();
        }
    }
}
