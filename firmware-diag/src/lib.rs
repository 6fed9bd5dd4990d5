#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]
#![deny(unsafe_code)]
//! Diagnostics of the ridge-pump firmware, apart from the product crate (as avr-hal keeps its
//! examples apart): images that measure or check the firmware's building blocks on a board or
//! an emulator, never flashed by users.
//!
//! | image (`src/bin/`) | what | run by |
//! |---|---|---|
//! | `avr-bench` | cycles, stack and flash of the hand-written routines against crates (docs/hand-written.md) | `scripts/avr-bench` |
//! | `avr-arith` | [`arith_check`] on the ATmega2560, to diff with the host's | `scripts/avr-arith-check` |
//! | `stm32f411-qemu` | the STM32F411's console (USART1, its interrupt and queues) on QEMU | `scripts/qemu-console` |
//!
//! The images take the board glue from the firmware's `src/board/` with `#[path]`, as the
//! board images do: the glue stays in one place, the firmware's library stays free of
//! hardware (and of `unsafe` but its UART queue), and the board images are built exactly as
//! before.

pub mod arith_check;
