//! placeholder
pub mod chip;
pub mod elf;
pub mod machine;
pub mod periph;
pub mod sensor;
pub mod ticks;
