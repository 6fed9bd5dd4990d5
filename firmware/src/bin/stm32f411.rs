//! ridge-pump firmware image for the STM32F411 "Black Pill" (STM32F411CEU6, 25 MHz HSE,
//! 100 MHz system clock).
//!
//! Build: `scripts/build-boards` (stable, `--target thumbv7em-none-eabihf`, linked with the root
//! `memory.x`). Pins and flashing: `docs/boards.md`.
//!
//! On the host this file compiles to a stub (`cargo build --all-features` stays a host build).
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

#[cfg(all(target_arch = "arm", target_os = "none"))]
#[path = "../board/mod.rs"]
mod board;

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("stm32f411 is a board image: build it with scripts/build-boards");
    std::process::exit(2);
}

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod image {
    use super::board::blackpill_f411::valve::{self, ValvePin};
    use super::board::blackpill_f411::{self as bp, FlashStore, ResetCount, Ticker, WATCHDOG_MS};
    use cortex_m_rt::entry;
    use ridge_pump_firmware::app::{App, Board, Console};
    use ridge_pump_firmware::event::FaultReason;
    use ridge_pump_firmware::numfmt::Int;
    use ridge_pump_firmware::pump::Pump;
    use ridge_pump_firmware::resets::{self, Resets};
    use ridge_pump_firmware::selfid::{Defaults, SelfIdentification};
    use ridge_pump_firmware::sfm3300::Sfm3300;
    use ridge_pump_firmware::ventilation::Valve;
    use stm32f4xx_hal::i2c::{I2c, Mode};
    use stm32f4xx_hal::pac;
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::rcc::Config as ClockConfig;
    use stm32f4xx_hal::watchdog::IndependentWatchdog;
    use ufmt::uwriteln;

    /// I2C clock: standard mode (the STM32F411's 100 MHz core has no tick budget problem, and
    /// 100 kHz tolerates long sensor cables).
    const I2C_HZ: u32 = 100_000;

    struct BlackPill {
        ticker: Ticker,
        watchdog: IndependentWatchdog,
        store: FlashStore,
        /// The reset count of this boot and where it is kept (`resets`), cleared after
        /// [`resets::CLEAN_TICKS`] unless it is a reset loop.
        resets: Resets,
        count: ResetCount,
        /// Ticks left until the count is cleared (0: done).
        clean: u16,
        console: Console,
        /// The exhalation valve (PB0).
        valve: ValvePin,
    }

    impl Board for BlackPill {
        const TICK_DURING_SEARCH: bool = true;
        fn poll_tick(&mut self) -> Option<u16> {
            self.ticker.poll()
        }
        fn pet(&mut self) {
            self.watchdog.feed();
        }
        fn save(&mut self, record: &[u8]) {
            self.store.save(record);
        }
        fn poll_store(&mut self) -> Option<bool> {
            // A clean run: the resets before it were no loop (a loop keeps its count, and the
            // pump off, until a power-on or reset-pin reset).
            if self.clean > 0 {
                self.clean -= 1;
                if self.clean == 0 && !self.resets.is_loop() {
                    self.count.store(Resets::default());
                }
            }
            self.store.take_result()
        }
        fn stack(&self) -> Option<(u16, u16)> {
            None
        }
        fn receive(&mut self) -> Option<u8> {
            bp::receive()
        }
        fn receive_overrun(&mut self) -> bool {
            bp::receive_overrun()
        }
        fn tx_room(&self) -> usize {
            bp::tx_room()
        }
        fn console(&mut self) -> Option<&mut Console> {
            Some(&mut self.console)
        }
        fn set_valve(&mut self, valve: Valve) {
            self.valve.set(valve);
        }
    }

    #[entry]
    fn main() -> ! {
        let dp = pac::Peripherals::take().unwrap(); // ok: first and only call, at boot

        // Reset cause (RCC_CSR bits 31..24: LPWR, WWDG, IWDG, SFT, POR, PIN, BOR), then clear.
        let reset_cause = (dp.RCC.csr().read().bits() >> 24) as u8;
        dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());

        let mut rcc = dp.RCC.freeze(ClockConfig::hse(25.MHz()).sysclk(100.MHz()));
        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);

        // The exhalation valve open (PB0 low) before the pump is driven.
        let valve = ValvePin::new(gpiob.pb0);
        // Pump PWM next, so the pin is driven low (duty 0) as early as possible.
        let (_pwm, (ch1, ..)) = dp.TIM3.pwm_hz(20.kHz(), &mut rcc);
        let mut ch1 = ch1.with(gpioa.pa6);
        ch1.set_duty(0);
        ch1.enable();
        let pump = match Pump::new(ch1) {
            Ok(pump) => pump,
            Err(e) => match e {},
        };

        let mut out = bp::console_uart(dp.USART1, gpioa.pa9, gpioa.pa10, &mut rcc).unwrap(); // ok: fixed config, valid at 100 MHz; a panic stops the pump

        let i2c = I2c::new(
            dp.I2C1,
            (gpiob.pb6, gpiob.pb7),
            Mode::standard(I2C_HZ.Hz()),
            &mut rcc,
        );
        let sensor = Sfm3300::new(bp::bus::Bus::new(i2c));

        // The watchdog from here on. A record store that needs room gets it now, before the
        // pump is driven: an erase stalls the CPU for ~2 s (`FlashStore::prepare`).
        let mut watchdog = IndependentWatchdog::new(dp.IWDG);
        watchdog.stop_on_debug(&dp.DBGMCU, true);
        watchdog.start(WATCHDOG_MS.millis());
        let mut store = FlashStore::new(dp.FLASH);
        store.prepare(&mut watchdog);
        let stored = store.load();
        let mut sid = SelfIdentification::new(Defaults, stored.as_ref().map(|r| &r[..]));
        // Reset loops (`resets`): count this boot's watchdog / brown-out reset; the third in a
        // row starts in the fault state.
        let mut count = ResetCount::new(dp.PWR, dp.RTC, &mut rcc);
        let resets = count
            .load()
            .after_boot(resets::cause_from_rcc_csr(reset_cause));
        count.store(resets);
        let boot_fault = resets.is_loop().then(|| {
            sid.fault_detected(FaultReason::ResetLoop {
                watchdog: resets.watchdog,
                brownout: resets.brownout,
            })
        });

        let ticker = Ticker::new(dp.TIM5.counter(&mut rcc));

        uwriteln!(
            out,
            "BOOT board=stm32f411 reset={} record={}",
            Int::from(reset_cause),
            match (store.available(), stored.is_some()) {
                (false, _) => "unavailable",
                (true, true) => "stored",
                (true, false) => "none",
            }
        )
        .ok();
        if let Some(event) = boot_fault {
            uwriteln!(out, "{}", event).ok();
        }
        let mut app = App::new(sensor, pump, out, sid, I2C_HZ);
        let mut board = BlackPill {
            ticker,
            watchdog,
            store,
            resets,
            count,
            clean: resets::CLEAN_TICKS,
            console: Console::new(),
            valve,
        };
        app.run(&mut board)
    }

    /// Panic: interrupts off, pump off (TIM3 CCR1 = 0, written directly), the exhalation valve
    /// open (PB0 low, written directly), a polled `PANIC` line, then spin until the IWDG (0.5 s)
    /// resets the MCU; the next boot reports `reset=` with the IWDG bit (0x20) set. See the
    /// ATmega2560 image for the reasoning.
    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        cortex_m::interrupt::disable();
        bp::force_pump_off();
        valve::force_open();
        for &byte in b"\nPANIC\n" {
            bp::send_polled(byte);
        }
        loop {
            core::hint::spin_loop();
        }
    }
}
