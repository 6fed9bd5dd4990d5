//! The firmware's UART output as the CSV `ridge-id capture` writes: the header
//! `t,u,y,r,phase`, every log row verbatim and every other line the firmware sent as a `# `
//! comment, in order (`ridge_id::capture`, whose [`Capture`] writer this module calls, so the
//! two files cannot differ in format). `ridge-id identify --input FILE --device` reads it.
//!
//! The bench has every byte from reset on, so no line is cut at the start (a port capture
//! drops the line in progress when it opens); a line still without its `\n` when the run ends
//! is dropped and counted, as `ridge-id capture` does at Ctrl-C.

use std::path::Path;

use ridge_id::capture::{Capture, Counts};

use crate::bench::Bench;

/// The capture of everything `bench`'s firmware sent on USART0 so far, as CSV bytes.
pub fn capture_bytes(bench: &Bench) -> Result<(Vec<u8>, Counts), String> {
    let bytes: Vec<u8> = bench
        .machine
        .uart0()
        .borrow()
        .iter()
        .map(|b| b.byte)
        .collect();
    let mut csv = Vec::new();
    let mut cap = Capture::new(&mut csv).map_err(|e| e.to_string())?;
    cap.feed(&bytes).map_err(|e| e.to_string())?;
    let counts = cap.finish().map_err(|e| e.to_string())?;
    Ok((csv, counts))
}

/// Writes [`capture_bytes`] to `path` (parent directories created); returns the counts.
pub fn write_capture(bench: &Bench, path: &Path) -> Result<Counts, String> {
    let (csv, counts) = capture_bytes(bench)?;
    let err = |e: std::io::Error| format!("{}: {e}", path.display());
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(err)?;
    }
    std::fs::write(path, csv).map_err(err)?;
    Ok(counts)
}
