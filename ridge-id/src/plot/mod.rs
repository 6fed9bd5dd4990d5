//! PNG plots of a run: the fit ([`write_fit_png`]), the residual analysis
//! ([`write_residuals_png`]) and the simulated closed-loop step of `--control`
//! ([`write_control_png`]), their axes naming the quantities and, when known, the units
//! ([`Axes`]); every drawing of ridge-id is here.
//!
//! Drawn with `plotters` (bitmap backend, PNG encoder) and text rendered by `ab_glyph` from
//! the DejaVu Sans font embedded by the `dejavu` crate.

mod axes;
mod fit;
mod fonts;
mod residuals;
mod step;

pub use axes::Axes;
pub use fit::{write_fit_png, Panel};
pub use residuals::write_residuals_png;
pub use step::write_control_png;

use std::path::{Path, PathBuf};

use crate::error::IdError;

/// Checks, before any work, that a PNG can be written to `path` (`--plot`): its directory
/// exists and a file can be created there. A file that did not exist is removed again.
///
/// Errors: [`IdError::Plot`] saying which.
pub fn check_output(path: &Path) -> Result<(), IdError> {
    let err = |message: String| IdError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(err(format!(
            "the directory {} does not exist",
            dir.display()
        )));
    }
    if path.is_dir() {
        return Err(err("it is a directory".into()));
    }
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|e| err(format!("cannot create it: {e}")))?;
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

/// Where `--plot OUT.png` puts the closed-loop step of `--control`: `OUT-control.png`, next
/// to it.
pub fn control_plot_path(plot: &Path) -> PathBuf {
    beside(plot, "control")
}

/// Where `--plot OUT.png` puts the residual analysis: `OUT-residuals.png`, next to it.
pub fn residuals_plot_path(plot: &Path) -> PathBuf {
    beside(plot, "residuals")
}

/// `OUT-{what}.png` next to `OUT.png` (the extension, if any, kept).
fn beside(plot: &Path, what: &str) -> PathBuf {
    let stem = plot
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = plot
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    plot.with_file_name(format!("{stem}-{what}{ext}"))
}
