#![no_std]
//! ridge-core: no_std, no-alloc ARX identification.

pub mod excitation;
