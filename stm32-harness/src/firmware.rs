//! The STM32F411 release image: where `scripts/build-boards` (and `cargo flash-f411`) puts it
//! and how to build it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Workspace root (parent of `stm32-harness/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Cargo target directory (`CARGO_TARGET_DIR` or `<root>/target`).
pub fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from) {
        Some(p) if p.is_absolute() => p,
        Some(p) => workspace_root().join(p),
        None => workspace_root().join("target"),
    }
}

/// The release ELF (`STM32_ELF` names another).
pub fn default_elf() -> PathBuf {
    if let Some(p) = std::env::var_os("STM32_ELF") {
        return PathBuf::from(p);
    }
    target_dir().join("thumbv7em-none-eabihf/release/stm32f411")
}

/// Builds the image as `scripts/build-boards` does (stable, `--release --target
/// thumbv7em-none-eabihf`, the root `memory.x`), with the calling cargo's environment removed.
pub fn build() -> Result<PathBuf, String> {
    let mut cmd = Command::new("cargo");
    cmd.args([
        "build",
        "-q",
        "-p",
        "ridge-pump-firmware",
        "--bin",
        "stm32f411",
        "--features",
        "board-stm32f411",
        "--release",
        "--target",
        "thumbv7em-none-eabihf",
    ]);
    cmd.current_dir(workspace_root());
    for v in [
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "RUSTC",
        "RUSTC_WRAPPER",
        "RUSTC_WORKSPACE_WRAPPER",
        "RUSTDOC",
        "CARGO",
        "CARGO_BUILD_TARGET",
        "CARGO_MAKEFLAGS",
        "MAKEFLAGS",
    ] {
        cmd.env_remove(v);
    }
    let status = cmd
        .status()
        .map_err(|e| format!("cannot run the firmware build: {e}"))?;
    if !status.success() {
        return Err(format!("firmware build failed ({status})"));
    }
    let elf = default_elf();
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(format!("build succeeded but {} is missing", elf.display()))
    }
}

/// The ELF, brought up to date by one (incremental) build per process; with `STM32_ELF` set,
/// that file as it is.
pub fn ensure_elf() -> Result<PathBuf, String> {
    static BUILT: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    if std::env::var_os("STM32_ELF").is_some() {
        let elf = default_elf();
        return if elf.is_file() {
            Ok(elf)
        } else {
            Err(format!("STM32_ELF: no such file {}", elf.display()))
        };
    }
    BUILT.get_or_init(build).clone()
}
