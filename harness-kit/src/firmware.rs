//! A board's firmware image as a harness gets it: where the workspace's target directory is,
//! the release build of the image with the calling cargo's environment removed, and one build
//! per process (or a prebuilt image named by an environment variable). Each harness says which
//! image ([`Image`]: its cargo arguments, its ELF, its variable).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Workspace root (parent of `harness-kit/`, and of both harnesses).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Cargo target directory (`CARGO_TARGET_DIR`, relative to the workspace root if relative, or
/// `<root>/target`).
pub fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from) {
        Some(p) if p.is_absolute() => p,
        Some(p) => workspace_root().join(p),
        None => workspace_root().join("target"),
    }
}

/// Environment of the calling cargo that would leak its settings (flags, compiler, target,
/// jobserver) into the image's build; removed for it, with the board's own [`Image::unset`].
const CALLER_ENV: [&str; 10] = [
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
];

/// One board's release image.
#[derive(Clone, Copy, Debug)]
pub struct Image {
    /// The arguments of `cargo` that build it, from the workspace root.
    pub cargo_args: &'static [&'static str],
    /// Where the ELF lands, relative to the target directory.
    pub elf: &'static str,
    /// The environment variable that names a prebuilt ELF instead (no build).
    pub elf_var: &'static str,
    /// Variables removed from the build's environment besides the calling cargo's flags,
    /// compiler, target and jobserver (removed for every image).
    pub unset: &'static [&'static str],
}

impl Image {
    /// The ELF: the file `elf_var` names, or `elf` in the target directory.
    pub fn default_elf(&self) -> PathBuf {
        if let Some(p) = std::env::var_os(self.elf_var) {
            return PathBuf::from(p);
        }
        target_dir().join(self.elf)
    }

    /// Builds the image (output to stderr) and returns its ELF.
    pub fn build(&self) -> Result<PathBuf, String> {
        let mut cmd = Command::new("cargo");
        cmd.args(self.cargo_args);
        cmd.current_dir(workspace_root());
        for v in CALLER_ENV.iter().chain(self.unset) {
            cmd.env_remove(v);
        }
        let status = cmd
            .status()
            .map_err(|e| format!("cannot run the firmware build: {e}"))?;
        if !status.success() {
            return Err(format!("firmware build failed ({status})"));
        }
        let elf = self.default_elf();
        if elf.is_file() {
            Ok(elf)
        } else {
            Err(format!("build succeeded but {} is missing", elf.display()))
        }
    }

    /// The ELF brought up to date by one (incremental) build per process, kept in `built` (the
    /// harness's own, one per image); with `elf_var` set, that file as it is.
    pub fn ensure_elf(&self, built: &OnceLock<Result<PathBuf, String>>) -> Result<PathBuf, String> {
        if std::env::var_os(self.elf_var).is_some() {
            let elf = self.default_elf();
            return if elf.is_file() {
                Ok(elf)
            } else {
                Err(format!("{}: no such file {}", self.elf_var, elf.display()))
            };
        }
        built.get_or_init(|| self.build()).clone()
    }
}
