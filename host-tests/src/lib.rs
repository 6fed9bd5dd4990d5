//! std side of ridge-pump.
