//! The printers of a [`Report`](crate::Report): readable text (`text.rs`, with the sections
//! of `--control` and `--phase` in `text_control.rs` and `text_phase.rs`) and one JSON object
//! (`json.rs`). They take the report alone and know nothing of the command line: the command
//! picks one (`--json`) and prints what it returns, as ripgrep's core hands its results to a
//! printer that knows no flags.

mod json;
mod text;
mod text_control;
mod text_phase;
