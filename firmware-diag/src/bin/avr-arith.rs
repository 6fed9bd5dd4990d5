//! Arithmetic self-check image for the ATmega2560 (diagnostics, not flashed by users): runs
//! the ridge-core statistics path on a fixed record and prints the results over USART0, so
//! that a host run of the same computation can be compared bit for bit. `AVR_ARITH=reid` at
//! build time selects the re-identification part (`arith_check::write_reid`) instead.
#![cfg_attr(target_arch = "avr", no_std, no_main)]

#[cfg(not(target_arch = "avr"))]
fn main() {
    eprintln!("avr-arith is a board image: build it for avr-none");
    std::process::exit(2);
}

#[cfg(target_arch = "avr")]
mod image {
    use avr_device::atmega2560 as pac;
    use core::panic::PanicInfo;

    struct Tx;
    impl ufmt::uWrite for Tx {
        type Error = core::convert::Infallible;
        fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
            let u = unsafe { &*pac::USART0::ptr() };
            for &b in s.as_bytes() {
                while u.ucsr0a().read().bits() & (1 << 5) == 0 {}
                u.udr0().write(|w| unsafe { w.bits(b) });
            }
            Ok(())
        }
    }

    #[avr_device::entry]
    fn main() -> ! {
        let dp = unsafe { pac::Peripherals::steal() };
        dp.USART0.ubrr0().write(|w| unsafe { w.bits(16) });
        dp.USART0.ucsr0a().write(|w| unsafe { w.bits(1 << 1) });
        dp.USART0.ucsr0b().write(|w| unsafe { w.bits(1 << 3) });
        dp.USART0.ucsr0c().write(|w| unsafe { w.bits(0b110) });
        match option_env!("AVR_ARITH") {
            Some("reid") => firmware_diag::arith_check::write_reid(&mut Tx),
            _ => firmware_diag::arith_check::write(&mut Tx),
        }
        loop {}
    }

    #[panic_handler]
    fn panic(_: &PanicInfo) -> ! {
        loop {}
    }
}
