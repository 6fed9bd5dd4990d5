//! Board glue, compiled into the board images (`src/bin/*.rs` include it with `#[path]`), not
//! into the library: the library stays hardware-agnostic and testable on the host. One folder
//! or file per board, named after the board:
//!
//! - `arduino_mega2560`: Arduino Mega 2560 (ATmega2560) register-level adapters on
//!   `avr-device` (built for `target_arch = "avr"` only).
//! - `blackpill_f411`: WeAct "Black Pill" STM32F411 glue on stm32f4xx-hal (built for Cortex-M
//!   only).
//!
//! The 100 Hz loop both boards run is the library's [`ridge_pump_firmware::app`]; the UART
//! transmit queues are its [`ridge_pump_firmware::ring::Ring`].

#[cfg(target_arch = "avr")]
pub mod arduino_mega2560;
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub mod blackpill_f411;
