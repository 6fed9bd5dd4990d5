#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]
#![forbid(unsafe_code)]
//! ridge-pump firmware: SFM3300 flow-sensor driver, pump PWM control and report formatting for
//! the on-device self-identification loop (ATmega2560 and STM32F411).

pub mod arith;
pub mod event;
pub mod excitation;
pub mod monitor;
pub mod persist;
pub mod pump;
pub mod report;
pub mod selfid;
pub mod sfm3300;
pub mod units;
