//! The STM32F411 release image: where `scripts/build-boards` (and `cargo flash-f411`) puts it
//! and how to build it (the build itself: `harness_kit::firmware`).

use std::path::PathBuf;
use std::sync::OnceLock;

use harness_kit::firmware::Image;

/// The image as `scripts/build-boards` builds it (stable, `--release --target
/// thumbv7em-none-eabihf`, the root `memory.x`); `STM32_ELF` names another.
const IMAGE: Image = Image {
    cargo_args: &[
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
    ],
    elf: "thumbv7em-none-eabihf/release/stm32f411",
    elf_var: "STM32_ELF",
    unset: &[],
};

/// The release ELF (`STM32_ELF` names another).
pub fn default_elf() -> PathBuf {
    IMAGE.default_elf()
}

/// Builds the image as `scripts/build-boards` does, with the calling cargo's environment
/// removed.
pub fn build() -> Result<PathBuf, String> {
    IMAGE.build()
}

/// The ELF, brought up to date by one (incremental) build per process; with `STM32_ELF` set,
/// that file as it is.
pub fn ensure_elf() -> Result<PathBuf, String> {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    IMAGE.ensure_elf(&BUILT)
}
