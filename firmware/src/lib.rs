#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]
#![deny(unsafe_code)]
//! ridge-pump firmware: everything the pump runs, as a `no_std` library that is tested on the
//! host, plus thin board images (`src/bin/`, board glue in `src/board/`).
//!
//! | module | what |
//! |---|---|
//! | [`app`] | the 100 Hz loop both boards run, over a [`app::Board`] (tick, watchdog, storage) |
//! | [`selfid`] | the power-up self-identification state machine |
//! | [`monitor`] | run-mode residual monitor and drift detection |
//! | [`sfm3300`] | SFM3300 flow-sensor driver (embedded-hal I2C) |
//! | [`pump`] | blower PWM output with limits and a ramp limit (embedded-hal PWM) |
//! | [`persist`] | the stored model record (magic, version, CRC-32) |
//! | [`slots`] | two slots for that record: a write cut at any byte keeps the previous model |
//! | [`flash_store`] | the record in flash (STM32F411): a slot log over two sectors, cut-proof too |
//! | [`resets`] | reset loops: watchdog and brown-out resets counted across boots |
//! | [`event`], [`report`] | report lines and their fixed-point formatting (ufmt) |
//! | [`command`], [`console`] | the operator's console: command lines, their answers, the CSV log |
//! | [`units`] | the rig's units: duty scale, SFM3300 encoding, loop rate, [`units::SCALE`] |
//! | [`excitation`] | the pump's excitation presets ([`excitation::Record`]) |
//! | [`ring`] | the lock-free UART queues (the crate's only `unsafe`) |
//! | [`arith`] | a fixed computation for `scripts/avr-arith-check` |

pub mod app;
pub mod arith;
pub mod command;
pub mod console;
pub mod event;
pub mod excitation;
// Offsets in a 512 KB flash: not for the 16-bit AVR (its store is `slots`, in EEPROM).
#[cfg(not(target_arch = "avr"))]
pub mod flash_store;
pub mod monitor;
pub mod persist;
pub mod pump;
pub mod report;
pub mod resets;
// The one module with `unsafe`: a lock-free SPSC byte queue for UART interrupts.
#[allow(unsafe_code)]
pub mod ring;
pub mod selfid;
pub mod setpoint;
pub mod sfm3300;
pub mod slots;
pub mod tracking;
pub mod units;
