// SPDX-License-Identifier: GPL-2.0-or-later (links Unicorn, GPL-2.0; the product crates keep
// their own licence).
//! STM32F411 harness: runs the unchanged release image of the Black Pill (the ELF `cargo
//! flash-f411` writes) in Unicorn's Cortex-M4 core, with register models of the peripherals it
//! touches written from the reference manual RM0383, closed loop with the simulated SFM3300 on
//! I2C1 and the blower (and test lung) of `pump-sim` on TIM3's PWM; captures the firmware's
//! USART1 report lines and counts instructions per control tick, of the search and of the
//! design. The ATmega2560 counterpart is `simavr-harness`.
//!
//! - [`machine`]: Unicorn with the STM32F411's memory map, emulated time, the clock jump,
//!   exception entry and return, faults and resets.
//! - [`chip`]: the bus: which model answers which address, clocks, interrupt lines, the log of
//!   unmodelled accesses.
//! - [`periph`]: one model per peripheral: RCC, FLASH (with the flash-size word), GPIO, the
//!   general-purpose timers (TIM3 PWM, TIM5 counter), USART1, I2C1, IWDG, NVIC, SCB/FPU/SysTick,
//!   DBGMCU, the bit-band alias.
//! - [`sensor`]: the SFM3300 as an I2C slave, with faults; [`bus`]: the I2C lines at the
//!   pins (a slave holding SDA low, the firmware's recovery clocks).
//! - [`bench`](mod@bench): the machine wired to the plant, closed loop; line capture; scheduled faults,
//!   resets and power cuts; bytes into the console.
//! - [`ticks`]: the loop's ticks seen from the bus (no marker in the firmware).
//! - [`session`]: one power-up and its figures (the records rebuilt, instructions per tick,
//!   of the search and of the design); [`tracking`]: run mode's view of the bench for
//!   `harness_kit::run`; [`report`]: what `stm32-run` prints, through `harness_kit::report`
//!   (the same report as `simavr-run`'s); [`transcript`]: the report lines with their times.
//!   The board-independent analysis (host rerun, validation scoring, run mode rebuilt) is
//!   `harness-kit`'s.
//! - [`elf`], [`firmware`]: the image, its sizes, its build.
//!
//! # Emulated time
//! Unicorn executes instructions without a timing model, so emulated time is counted from
//! instructions: **1 core clock cycle per instruction** ([`machine::CPI`]) at the HCLK the RCC
//! selects (16 MHz HSI until the image switches to the 100 MHz PLL). Instruction counts are
//! exact; the times are a lower bound of the chip's. What the Cortex-M4's real timing adds to
//! a control tick: flash wait states (3 at 100 MHz and 3.3 V, RM0383 §3.4 Table 5) that the
//! ART accelerator hides for straight-line code and cache hits but not after every taken
//! branch to a cold line (up to 3 cycles each); loads and stores of 2 cycles (1 when
//! pipelined), 2–12-cycle integer divides, 14-cycle FP divides and square roots, 1–3-cycle
//! FP multiply-accumulates, and 1–3-cycle branch refills (ARM Cortex-M4 TRM, "Instruction set
//! summary"; FPU "Cycle counts"). The peripherals' own times are modelled: I2C bytes at the
//! bus clock CCR sets (90 µs a byte at 100 kHz), UART frames from BRR (86.8 µs at 115 200
//! baud), the flash's program and erase times (the CPU stalls), the IWDG's LSI countdown.
//!
//! When the image only polls a register (its 10 ms tick counter between ticks, a status flag
//! during an I2C byte), the machine jumps the clock to the next event that can change what it
//! reads (the next count, the end of the byte, a UART frame, the watchdog's expiry, a plant
//! step): the default 46.0 s run executes 67 M instructions instead of 4.6 G. Instruction
//! counts of a tick are the CPU's work; the waits for the buses show in its emulated time.

pub mod bench;
pub mod bus;
pub mod chip;
pub mod elf;
pub mod firmware;
pub mod machine;
pub mod periph;
pub mod report;
pub mod sensor;
pub mod session;
pub mod ticks;
pub mod tracking;
pub mod transcript;
