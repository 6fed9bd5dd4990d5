//! Streaming reader of `u`/`y` records in CSV, with line-numbered errors: [`CsvRecord`] (its own
//! reader of plain lines, handing the rest to the `csv` crate) and [`Reference`] (the `csv`
//! crate's reading); the cells they share are in `cells.rs`.
//!
//! Format:
//! - the first line that is neither blank nor a comment (first non-blank character `#`) is
//!   the header: comma-separated column names; the columns named `u` (input) and `y`
//!   (output) are required, any others (`t`, …) are ignored, in any order. Names are
//!   trimmed and may be double-quoted; a UTF-8 byte order mark at the start of the file is
//!   skipped.
//! - every further non-blank, non-comment line is one sample and must have as many
//!   comma-separated cells as the header; the `u` and `y` cells must be finite decimal
//!   numbers (`1.5`, `-2e-3`, ` 4 `, `"3"`; `NaN` and `inf` are rejected). Cells may be
//!   double-quoted as RFC 4180 says (a quoted comma does not separate cells).
//! - line ends may be `\n` or `\r\n`; the text must be UTF-8.
//!
//! - a line may be at most [`MAX_LINE`] bytes (1 MiB) long: a longer one is an error naming
//!   its line, so that a file without line ends (a binary file, a log written without
//!   `\n`) cannot make the reader grow its buffer without bound.
//!
//! The parsing is the `csv` crate's ([`Reference`]); [`CsvRecord`] reads the common rows —
//! one line, no double quote, ASCII — itself, which the `csv` crate would split on the
//! commas alone, and hands the rest of the input to [`Reference`] at the first row that is
//! not such a line (a quote, a non-ASCII byte, a line whose end is not within 64 KiB): the
//! results, errors included, are the `csv` crate's, which a test checks on arbitrary bytes.
//! This module adds the column lookup, the checks and the messages. Rows are read one at a
//! time into reused buffers, so a record of any length streams in constant memory. Errors
//! name the file, the 1-based line and the problem, e.g.
//! `LOG.csv line 17: column y: "abc" is not a number`; a cell or a header is quoted with at
//! most [`QUOTE_CHARS`] characters.

// Measured (`scripts/bench-speed` with a random-step log: `ridge-id identify --input LOG
// --json`, release build, 10^6 rows, 23 MB, two passes, user CPU of the whole run on a
// shared 2-core machine): 0.24 s
// with every row through the `csv` crate (ridge-id at opt-level 3); 0.18 s with the line
// reader splitting cells and `number`; 0.10 s with `quick_row` (one pass over a common row's
// bytes, its numbers read on the way) together with grid-sized statistics
// (`MeasuredGram::for_grid`) and the residual analysis's ring buffer.

mod cells;
mod lines;
mod record;
mod reference;

pub(crate) use cells::{column, found, number, unquote};
pub use cells::{quote, Sample, MAX_LINE, QUOTE_CHARS};
pub use record::CsvRecord;
pub use reference::Reference;
