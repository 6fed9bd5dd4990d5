//! std side of ridge-pump.

pub mod sim;
