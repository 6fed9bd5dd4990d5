//! simavr harness: runs the release ELF of the ATmega2560 firmware in simavr at 16 MHz, closed
//! loop with a simulated SFM3300 on TWI address 0x40 and the blower model, driven by the PWM
//! duty the firmware programs; captures and parses the UART report lines; measures tick times,
//! CPU load, missed ticks and the search time from the cycle counter.
//!
//! - [`machine`]: safe wrapper over simavr (`simavr-ffi`, the simavr that `avr-tester` 0.6
//!   builds from source with its TWI fixes): cycle counter, data space, EEPROM, IRQ hooks.
//! - [`sensor`]: the SFM3300 as an `avr_tester::TwiSlave`, with fault injection.
//! - [`bus`]: the I2C lines at the pin level: pull-ups, a sensor holding SDA low, the clock
//!   pulses and START/STOP conditions the firmware makes.
//! - [`pwm`]: duty from the 16-bit timer registers.
//! - [`bench`](mod@bench): the bench ([`bench::Bench`]): the simulated MCU wired to the simulated plant,
//!   closed loop, with the timing meter. (The plant alone, stepped once per sample without an
//!   MCU, is `pump_sim::Rig`.)
//! - [`transcript`]: the UART transcript: [`transcript::Line`] (text and cycle stamp), split into
//!   keyword, words and `key=value` fields by the firmware's own parser
//!   (`ridge_pump_firmware::lines`, beside the lines' writer).
//! - [`firmware`]: locating/building the ELF and its section sizes.
//! - [`session`]: a whole power-up identification run and its figures (what `simavr-run`
//!   prints through `harness_kit::report`, the report both boards share, and the tests check).
//! - [`tracking`]: run mode's view of the bench for `harness_kit::run` (rebuilt tick by tick,
//!   checked against the firmware's `TRACK` lines and scored), and the design's cycles.
//!
//! What does not depend on simavr (the records rebuilt from the served frames, the host rerun,
//! validation scoring, run mode, the SFM3300's I2C side, the report) is `harness-kit`'s,
//! shared with `stm32-harness`.
//! - [`uart`]: a serial line into USART0 (commands to the firmware's console at 115 200
//!   baud, scheduled at a cycle or after a line the firmware printed), down to the UART's
//!   receiver ([`uart::UartInput`]); [`Bench::send_at`](bench::Bench::send_at),
//!   [`Bench::send_after`](bench::Bench::send_after).
//! - [`capture`]: the firmware's UART output as the CSV `ridge-id capture` writes (its log).
//! - [`stack`]: worst-case stack from the image's call graph ([`stack::StackAnalysis`], what
//!   `avr-stack` prints).
//! - [`ticks`]: each tick's timing from the core's cycle counter ([`ticks::TickTiming`]: busy
//!   cycles, control latency, missed ticks), with no help from the firmware.
//! - [`ventilation`]: a ventilated session (identify, design, then `VENT` over the console,
//!   the exhalation valve on its pin), breath by breath against the lung's truth.
//! - [`vent_bench`]: issue 32's ventilation targets on the image (ISO rows, lung changes),
//!   scored with the host benchmark's rules (`pump_sim::vent_bench`; `avr-vent-bench` prints).

pub mod bench;
pub mod bus;
pub mod capture;
pub mod firmware;
pub mod machine;
pub mod pwm;
pub mod relax;
pub mod sensor;
pub mod session;
pub mod stack;
pub mod ticks;
pub mod tracking;
pub mod transcript;
pub mod uart;
pub mod vent_bench;
pub mod ventilation;
