//! Links the QEMU `mps2-an386` memory map (`../boards/mps2-an386.x`, code at 0x0) as
//! `memory.x` for cortex-m-rt's `link.x`.
//!
//! This works only because this crate is its own workspace: cargo runs the linker in
//! the workspace root, the linker looks for `memory.x` there before any `-L` path, and
//! the repository root's `memory.x` (STM32F411, flash at 0x0800_0000) would otherwise
//! win silently (GNU ld searches the working directory first). Keep no `memory.x` in this directory.
use std::{env, fs, path::PathBuf};

fn main() {
    let map = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"))
        .join("../boards/mps2-an386.x");
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets it"));
    fs::copy(&map, out.join("memory.x")).expect("copy boards/mps2-an386.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", map.display());
    println!("cargo:rerun-if-changed=build.rs");
}
