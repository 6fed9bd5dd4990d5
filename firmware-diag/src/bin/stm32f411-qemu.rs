//! Console test image for QEMU's `netduinoplus2` machine (an STM32F405: the same USART
//! register block as the STM32F411, USART1 at the same address, on the same interrupt, 37),
//! not flashed by users. It runs the STM32F411 image's USART1 code unchanged (the HAL's
//! `Serial` on PA9/PA10, `blackpill_f411::Uart`, its interrupt and queues, `receive`,
//! `receive_overrun`, `tx_room`) and its TIM5 `Ticker` under the library's loop with the
//! console, so that commands sent to QEMU's serial port are answered. Driven by
//! `scripts/qemu-console`.
//!
//! What differs from `stm32f411`, because QEMU does not model it: no clock setup (QEMU has no
//! RCC: the HSE never reports ready and `RCC.freeze` would wait forever; the HAL assumes the
//! reset clocks, 16 MHz HSI), no I2C (QEMU's I2C1 is a dummy on which the HAL waits forever
//! for the start condition: the sensor here always NACKs, so the loop reports
//! `SENSOR start failed` and `FAULT sensor=nack n=5`), a PWM that only stores the duty, no
//! watchdog and no flash store.
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

#[cfg(all(target_arch = "arm", target_os = "none"))]
#[path = "../../../firmware/src/board/mod.rs"]
#[allow(dead_code)] // the flash store, watchdog and pump helpers are not used here
mod board;

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("stm32f411-qemu is a QEMU test image: run it with scripts/qemu-console");
    std::process::exit(2);
}

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod image {
    use super::board::blackpill_f411::{self as bp, Ticker, Uart};
    use core::convert::Infallible;
    use core::sync::atomic::Ordering;
    use cortex_m::peripheral::NVIC;
    use cortex_m_rt::entry;
    use embedded_hal::i2c::{self, ErrorKind, NoAcknowledgeSource, Operation};
    use embedded_hal::pwm::{self, SetDutyCycle};
    use ridge_pump_firmware::app::{App, Board, Console};
    use ridge_pump_firmware::pump::Pump;
    use ridge_pump_firmware::selfid::{Defaults, SelfIdentification};
    use ridge_pump_firmware::sfm3300::Sfm3300;
    use stm32f4xx_hal::pac;
    use stm32f4xx_hal::prelude::*;
    use ufmt::{uWrite, uwriteln};

    /// A sensor that never answers.
    struct NoSensor;

    impl i2c::ErrorType for NoSensor {
        type Error = ErrorKind;
    }

    impl i2c::I2c for NoSensor {
        fn transaction(&mut self, _: u8, _: &mut [Operation<'_>]) -> Result<(), ErrorKind> {
            Err(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address))
        }
    }

    /// A PWM channel that only keeps the duty.
    struct Pwm(u16);

    impl pwm::ErrorType for Pwm {
        type Error = Infallible;
    }

    impl SetDutyCycle for Pwm {
        fn max_duty_cycle(&self) -> u16 {
            1000
        }
        fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
            self.0 = duty;
            Ok(())
        }
    }

    /// The board's writer, kicked: QEMU 7.2's USART model raises no TXE interrupt (only RXNE),
    /// so after each byte this pends USART1 until the queue is empty; the handler's transmit
    /// half then sends it as it would on the TXE interrupt.
    struct Kicked<T>(Uart<T>);

    impl<T> uWrite for Kicked<T> {
        type Error = Infallible;

        fn write_str(&mut self, s: &str) -> Result<(), Infallible> {
            for (i, c) in s.char_indices() {
                self.0.write_str(&s[i..i + c.len_utf8()])?;
                while bp::tx_room() < TX_CAPACITY {
                    NVIC::pend(pac::Interrupt::USART1);
                }
            }
            Ok(())
        }
    }

    /// Longest wait for the burst at boot, in ticks (QEMU 7.2 clocks TIM5 at 1 GHz / 1600, so
    /// a tick is 160 µs there: 1.6 s).
    const HOLD_TICKS: u32 = 10_000;

    /// Free bytes in the board's empty transmit queue.
    const TX_CAPACITY: usize = 255;

    struct Qemu {
        ticker: Ticker,
        console: Console,
    }

    /// As `stm32f411`'s board, without watchdog, store and stack figures.
    impl Board for Qemu {
        const TICK_DURING_SEARCH: bool = true;
        fn poll_tick(&mut self) -> Option<u16> {
            self.ticker.poll()
        }
        fn pet(&mut self) {}
        fn save(&mut self, _record: &[u8]) {}
        fn poll_store(&mut self) -> Option<bool> {
            None
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
    }

    #[entry]
    fn main() -> ! {
        let dp = pac::Peripherals::take().unwrap(); // ok: first and only call, at boot
        let mut rcc = dp.RCC.constrain();
        let gpioa = dp.GPIOA.split(&mut rcc);
        // The `stm32f411` image's own USART1 setup.
        let uart = bp::console_uart(dp.USART1, gpioa.pa9, gpioa.pa10, &mut rcc).unwrap(); // ok: fixed config; a panic prints PANIC
        let mut out = Kicked(uart);
        let mut ticker = Ticker::new(dp.TIM5.counter(&mut rcc));

        uwriteln!(out, "BOOT board=stm32f411-qemu").ok();
        // A stretch in which the loop does not read while the interrupt runs (as during the
        // ticking search, but longer than its 15 ms, which the release image never exceeds):
        // until the first received byte is lost, at most HOLD_TICKS. A burst of more than 255
        // bytes sent now fills the receive queue exactly.
        let mut held = 0u32;
        while held < HOLD_TICKS && !bp::RX_LOST.load(Ordering::Acquire) {
            held += ticker.poll().map_or(0, u32::from);
        }
        let pump = match Pump::new(Pwm(0)) {
            Ok(pump) => pump,
            Err(e) => match e {},
        };
        let sid = SelfIdentification::new(Defaults, None);
        let mut app = App::new(Sfm3300::new(NoSensor), pump, out, sid, 100_000);
        let mut board = Qemu {
            ticker,
            console: Console::new(),
        };
        app.run(&mut board)
    }

    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        cortex_m::interrupt::disable();
        for &byte in b"\nPANIC\n" {
            bp::send_polled(byte);
        }
        loop {
            core::hint::spin_loop();
        }
    }
}
