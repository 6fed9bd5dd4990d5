//! The ATmega2560 firmware image: where it is, how to build it (the build itself:
//! `harness_kit::firmware`), how big it is.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use harness_kit::firmware::Image;

/// The image as the ATmega2560 step of `scripts/build-boards` builds it (nightly, `--target
/// avr-none -Zbuild-std=core`; the script also builds the STM32 image and checks the size
/// budgets); `RIDGE_PUMP_ELF` names another. The toolchain the calling cargo chose and its AVR
/// runner are removed from the build's environment too.
const IMAGE: Image = Image {
    cargo_args: &[
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
    ],
    elf: "avr-none/release/atmega2560.elf",
    elf_var: "RIDGE_PUMP_ELF",
    unset: &["RUSTUP_TOOLCHAIN", "CARGO_TARGET_AVR_NONE_RUNNER"],
};

/// The opt-in image with run mode's re-identification (feature `atmega2560-reid`): over the
/// 96 KB flash budget, built and measured on its own (docs/boards.md). Cargo keeps both builds
/// but puts the last one built at the default image's path: [`ensure_reid_elf`] copies it to
/// [`REID_ELF`]. `RIDGE_PUMP_REID_ELF` names another.
const REID_IMAGE: Image = Image {
    cargo_args: &[
        "+nightly",
        "build",
        "-q",
        "-p",
        "ridge-pump-firmware",
        "--bin",
        "atmega2560",
        "--features",
        "board-atmega2560,atmega2560-reid",
        "--release",
        "--target",
        "avr-none",
        "-Zbuild-std=core",
    ],
    elf: "avr-none/release/atmega2560.elf",
    elf_var: "RIDGE_PUMP_REID_ELF",
    unset: &["RUSTUP_TOOLCHAIN", "CARGO_TARGET_AVR_NONE_RUNNER"],
};

/// Where the release ELF of the ATmega2560 image lands (`RIDGE_PUMP_ELF` names another).
pub fn default_elf() -> PathBuf {
    IMAGE.default_elf()
}

/// Builds the image (output to stderr), with the environment that would leak the calling
/// cargo's settings into the nightly cross build (RUSTFLAGS, RUSTC, …) removed.
pub fn build() -> Result<PathBuf, String> {
    IMAGE.build()
}

/// The ELF, brought up to date by one (incremental) build per process, so that tests never run
/// a stale image. `RIDGE_PUMP_ELF` names a prebuilt image instead (no build).
pub fn ensure_elf() -> Result<PathBuf, String> {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    IMAGE.ensure_elf(&BUILT)
}

/// Where [`ensure_reid_elf`] keeps the opt-in image, relative to the target directory.
pub const REID_ELF: &str = "avr-none/release/atmega2560-reid.elf";

/// The opt-in image with the re-identification (feature `atmega2560-reid`), built once per
/// process and copied to [`REID_ELF`] (the default image's path holds it only until the next
/// default build); `RIDGE_PUMP_REID_ELF` names a prebuilt one instead.
pub fn ensure_reid_elf() -> Result<PathBuf, String> {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    if std::env::var_os(REID_IMAGE.elf_var).is_some() {
        return REID_IMAGE.ensure_elf(&BUILT);
    }
    BUILT
        .get_or_init(|| {
            let built = REID_IMAGE.build()?;
            let kept = harness_kit::firmware::target_dir().join(REID_ELF);
            std::fs::copy(&built, &kept).map_err(|e| format!("{}: {e}", kept.display()))?;
            Ok(kept)
        })
        .clone()
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
