//! Board glue, compiled into the board binaries (`src/bin/*.rs` include it with `#[path]`), not
//! into the library: the library stays `forbid(unsafe_code)` and hardware-agnostic.
//!
//! - [`app`]: the 100 Hz loop shared by both boards (sensor, state machine, pump, reports).
//! - [`ring`]: the lock-free UART transmit queue.
//! - `avr`: ATmega2560 register-level adapters (built for `target_arch = "avr"` only).
//! - `stm32f411`: STM32F411 glue on stm32f4xx-hal (built for Cortex-M only).

pub mod app;
pub mod ring;

#[cfg(target_arch = "avr")]
pub mod avr;
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub mod stm32f411;
