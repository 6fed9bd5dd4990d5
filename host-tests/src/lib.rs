//! std side of ridge-pump.

pub mod identify;
pub mod paper;
pub mod sim;
pub mod simavr;
