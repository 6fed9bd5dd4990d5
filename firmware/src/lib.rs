#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]
#![deny(unsafe_code)]
//! ridge-pump firmware: everything the pump runs, as a `no_std` library that is tested on the
//! host, plus thin board images (`src/bin/`, board glue in `src/board/`). The diagnostic images
//! (measurements, the arithmetic check, the QEMU console test) are the crate `firmware-diag`.
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
//! | [`event`], [`numfmt`] | report lines and their fixed-point number formatting (ufmt) |
//! | `lines` | host builds only: the report lines' parsers, for the host tools and tests |
//! | [`command`], [`console`] | the operator's console: command lines, their answers, the CSV log |
//! | [`units`] | the rig's units: duty scale, SFM3300 encoding, loop rate, [`units::SCALE`] |
//! | [`excitation`] | the pump's excitation presets ([`excitation::Record`]) |
//! | [`ring`] | the lock-free UART queues (the crate's only `unsafe`) |
//! | [`ventilation`] | volume-controlled breaths: `VENT` settings, the exhalation valve, per-breath volume, alarm and trim |
//! | `reid` | on the ATmega2560 only with the feature `atmega2560-reid` (no room in the budget): run mode's closed-loop re-identification while ventilating, `REID` lines |

pub mod app;
pub mod command;
pub mod console;
pub mod event;
pub mod excitation;
// Offsets in a 512 KB flash: not for the 16-bit AVR (its store is `slots`, in EEPROM).
#[cfg(not(target_arch = "avr"))]
pub mod flash_store;
// Host-side parsing of the report lines (std); no board target has an OS, so neither image
// contains it.
#[cfg(not(target_os = "none"))]
pub mod lines;
pub mod monitor;
pub mod numfmt;
pub mod persist;
pub mod pump;
// Not on the ATmega2560 unless opted in (feature `atmega2560-reid`): its flash budget has no
// room for it (docs/boards.md).
#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
pub mod reid;
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
pub mod ventilation;
