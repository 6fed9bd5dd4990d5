//! placeholder
pub mod bench;
pub mod chip;
pub mod elf;
pub mod firmware;
pub mod lines;
pub mod machine;
pub mod periph;
pub mod report;
pub mod session;
pub mod sensor;
pub mod ticks;
