//! The ATmega2560 firmware image: where it is, how to build it, how big it is.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Workspace root (parent of `simavr-harness/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("simavr-harness lives in the workspace")
        .to_path_buf()
}

/// Cargo target directory (`CARGO_TARGET_DIR` or `<root>/target`).
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|p| {
            if p.is_absolute() {
                p
            } else {
                workspace_root().join(p)
            }
        })
        .unwrap_or_else(|| workspace_root().join("target"))
}

/// Where the release ELF of the ATmega2560 image lands.
pub fn default_elf() -> PathBuf {
    if let Some(p) = std::env::var_os("RIDGE_PUMP_ELF") {
        return PathBuf::from(p);
    }
    target_dir().join("avr-none/release/atmega2560.elf")
}

/// Builds the image with the ATmega2560 step of `scripts/build-boards` (nightly,
/// `--target avr-none -Zbuild-std=core`; the script also builds the STM32 image and checks the
/// size budgets). Output goes to stderr. Environment that would leak the calling cargo's
/// settings into the nightly cross build (RUSTFLAGS, RUSTC, …) is removed.
pub fn build() -> Result<PathBuf, String> {
    let root = workspace_root();
    let mut cmd = Command::new("cargo");
    cmd.args([
        "+nightly",
        "build",
        "-q",
        "-p",
        "ridge-pump-firmware",
        "--bin",
        "atmega2560",
        "--features",
        "board-atmega2560",
        "--release",
        "--target",
        "avr-none",
        "-Zbuild-std=core",
    ]);
    cmd.current_dir(&root);
    for v in [
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "RUSTC",
        "RUSTC_WRAPPER",
        "RUSTC_WORKSPACE_WRAPPER",
        "RUSTDOC",
        "CARGO",
        "CARGO_BUILD_TARGET",
        "RUSTUP_TOOLCHAIN",
        "CARGO_MAKEFLAGS",
        "MAKEFLAGS",
        "CARGO_TARGET_AVR_NONE_RUNNER",
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

/// The ELF, brought up to date by one (incremental) build per process, so that tests never run
/// a stale image. `RIDGE_PUMP_ELF` names a prebuilt image instead (no build).
pub fn ensure_elf() -> Result<PathBuf, String> {
    static BUILT: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    if std::env::var_os("RIDGE_PUMP_ELF").is_some() {
        let elf = default_elf();
        return if elf.is_file() {
            Ok(elf)
        } else {
            Err(format!("RIDGE_PUMP_ELF: no such file {}", elf.display()))
        };
    }
    BUILT.get_or_init(build).clone()
}

/// Section sizes of an AVR ELF: text = `.text` (code and vectors, includes `.progmem`), bss =
/// `.bss` + `.noinit`.
pub use harness_kit::image::Sizes;

/// Reads the section headers of a 32-bit little-endian ELF.
pub fn sizes(elf: &Path) -> Result<Sizes, String> {
    let b = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let u16at =
        |o: usize| -> Option<u16> { Some(u16::from_le_bytes(b.get(o..o + 2)?.try_into().ok()?)) };
    let u32at =
        |o: usize| -> Option<u32> { Some(u32::from_le_bytes(b.get(o..o + 4)?.try_into().ok()?)) };
    if b.get(..5) != Some(b"\x7fELF\x01") {
        return Err("not a 32-bit ELF".into());
    }
    let bad = || "truncated ELF".to_string();
    let shoff = u32at(0x20).ok_or_else(bad)? as usize;
    let shentsize = usize::from(u16at(0x2E).ok_or_else(bad)?);
    let shnum = usize::from(u16at(0x30).ok_or_else(bad)?);
    let shstrndx = usize::from(u16at(0x32).ok_or_else(bad)?);
    let sh = |i: usize| shoff + i * shentsize;
    let stroff = u32at(sh(shstrndx) + 0x10).ok_or_else(bad)? as usize;
    let mut s = Sizes::default();
    for i in 0..shnum {
        let name_off = u32at(sh(i)).ok_or_else(bad)? as usize;
        let size = u32at(sh(i) + 0x14).ok_or_else(bad)?;
        let name_bytes = b.get(stroff + name_off..).ok_or_else(bad)?;
        let end = name_bytes.iter().position(|&c| c == 0).unwrap_or(0);
        let name = std::str::from_utf8(&name_bytes[..end]).unwrap_or("");
        match name {
            ".text" => s.text += size,
            ".data" => s.data += size,
            ".bss" | ".noinit" => s.bss += size,
            _ => {}
        }
    }
    Ok(s)
}
