//! What the two whole-image harnesses share: `simavr-harness` (the ATmega2560 image in simavr)
//! and `stm32-harness` (the STM32F411 image in Unicorn) each keep what is their emulator's (the
//! machine, its peripherals and pins, cycle or instruction accounting) and hand this crate
//! board-neutral views of a run: time stamps in the harness's own unit (simavr: core cycles;
//! stm32: picoseconds) with the number of them per second.
//!
//! - [`samples`]: a record (`EXCITE` / `VALIDATE`) rebuilt from the frames the simulated
//!   sensor served and the duty on the pump's pin ([`samples::Samples`]).
//! - [`host`]: the firmware's structure search rerun on the host on those samples, and the
//!   coefficient comparison.
//! - [`validation`]: scoring a model on a record, the fresh host-side validation signal with
//!   the loop's timing, the fit plot.
//! - [`image`]: a firmware image's section sizes ([`image::Sizes`]).
//! - [`console`]: the console's transcript as the tests read it: answers, log rows, the `RST`
//!   lines, the `ridge-id` check of the pump's own identification.
//! - [`firmware`]: a board's release image built from the workspace once per process
//!   ([`firmware::Image`]).
//! - [`run`]: run mode rebuilt tick by tick and checked against the `TRACK` lines
//!   ([`run::RunTrace`]), scored as `pump_sim::baseline` scores its host runs.
//! - [`sfm3300`]: the SFM3300's I2C side (commands, frames, NACKs, faults), which each
//!   harness's bus feeds ([`sfm3300::SensorState`]).
//! - [`i2c_lines`]: the I2C lines at the pin level beside the emulated I2C peripheral: pull-ups,
//!   a slave holding SDA low, what the lines did ([`i2c_lines::Lines`]).
//! - [`report`]: the report `scripts/simulate` prints for either board, one function per
//!   section, with the board-specific figures labelled as such ([`report::Board`]).

pub mod console;
pub mod firmware;
pub mod host;
pub mod i2c_lines;
pub mod image;
pub mod report;
pub mod run;
pub mod samples;
pub mod sfm3300;
pub mod validation;
