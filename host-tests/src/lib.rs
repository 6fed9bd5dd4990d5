//! std side of ridge-pump.

pub mod identify;
pub mod sim;
pub mod simavr;
