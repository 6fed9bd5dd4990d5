//! Cross-crate integration tests of ridge-pump: `tests/` drives the firmware library's state
//! machine with the plant simulator (`pump-sim`) and checks the core's precision on simulated
//! records; `benches/` times the core on them. No library code lives here.
