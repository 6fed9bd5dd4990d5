//! Register models of the STM32F411 peripherals the release image touches, one per file, each
//! written from the reference manual RM0383 (Rev 3) with the section of every register and bit
//! beside it, and what the model leaves out written next to it.
//!
//! Common conventions:
//! - time is in picoseconds since power-up ([`Time`]); a model that changes on its own (a
//!   timer count, a byte on a bus) computes its state from the time it is given, and says
//!   when it next changes by itself ([`next_event`](usart::Usart::next_event) in each model),
//!   so that the machine never runs past such an event and the clock jump never skips one;
//! - registers are accessed as 32-bit words at their offset; byte and halfword accesses are
//!   mapped onto the word by the bus ([`crate::chip`]);
//! - a register the model does not know is reported as unmodelled by the bus, never read as a
//!   silent zero.

pub mod backup;
pub mod bitband;
pub mod dbgmcu;
pub mod flash;
pub mod gpio;
pub mod i2c;
pub mod iwdg;
pub mod nvic;
pub mod rcc;
pub mod scb;
pub mod timer;
pub mod usart;

/// Time since power-up, picoseconds (2⁶⁴ ps ≈ 213 days).
pub type Time = u64;

/// Picoseconds per second.
pub const PS_PER_S: u64 = 1_000_000_000_000;

/// Picoseconds of `cycles` cycles of a `hz` clock (rounded down).
pub fn cycles_to_ps(cycles: u64, hz: u32) -> Time {
    (u128::from(cycles) * u128::from(PS_PER_S) / u128::from(hz.max(1))) as Time
}

/// Whole cycles of a `hz` clock in `ps` picoseconds (rounded down).
pub fn ps_to_cycles(ps: Time, hz: u32) -> u64 {
    (u128::from(ps) * u128::from(hz) / u128::from(PS_PER_S)) as u64
}

/// The result of a register access the model does not implement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Unmodelled;
