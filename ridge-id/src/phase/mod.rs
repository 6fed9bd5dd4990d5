//! `--phase`: one segment of a pump's log capture as the estimation record, and the operating
//! point the pump identified around (`--operating-point`).
//!
//! A capture (see `docs/real-logs.md`, "Check the pump's identification on the PC") is the
//! pump's live log: the header `t,u,y,r,phase`, one row per 10 ms tick, and every other line
//! the pump printed as a comment `# …`, in order:
//!
//! ```text
//! t,u,y,r,phase
//! # SCAN n=441 lag=20 u0=30.00 y0=19.058 attempt=1/3
//! 1.52,0.3040,19.06667,,scan
//! …
//! # MAP first=15.00 step=5.33 flow=6.325,8.417,13.433,…
//! …
//! # EXCITE flow-steps n=700 u0=30.00 y0=19.058 attempt=1/3
//! 5.94,0.4512,19.05833,,scan
//! 5.95,0.4512,21.26667,,excite
//! …
//! # ID p=5 q=4 d=3 off=1 theta=… phi=… c=-0.218269 score=1149.6 eval=1/252 skip=0 iters=10
//! ```
//!
//! A *segment* is a maximal run of consecutive rows whose `phase` cell equals the asked
//! phase. The rows of an `excite` segment are exactly the samples of the pump's estimation
//! record; the `# EXCITE` comment before it gives the record's length `n` and its operating
//! point (`u0` in percent, `y0` in slm), and the first `# ID` comment after it the model the
//! pump identified on it ([`DeviceId`]).
//!
//! The pump's model is Hammerstein (`firmware/src/selfid/`): the static map of the attempt's
//! `# MAP` line, then the dynamics from the map's flow to the measured flow. When a `# MAP`
//! comment precedes the segment's `# EXCITE` line, the segment's input is that map's flow
//! (slm) at each row's duty, and so is the operating point's (`u0` through the map): the
//! statistics the pump accumulated ([`DeviceMap`]).
//!
//! Which segment: the `--attempt N`-th of the file (counted from 1 in file order), or by
//! default the last *complete* one (followed by a row of another phase, or holding the `n`
//! rows its `# EXCITE` line announces; a segment cut off by the end of the capture is not).
//! The chosen segment is refused, never silently patched, when rows are missing: fewer or
//! more rows than its `# EXCITE` line's `n`, a step of the `t` column that is not one sample
//! period (a dropped log row, `# LOG dropped=…`, or a lost tick, `# MISSED … lost=…`), or a
//! malformed row inside it or at its end. A `# LOG dropped=` comment inside a segment whose
//! rows are all there (the count covers the whole second before it) is not an error; without
//! a `t` column such a comment refuses the segment.
//!
//! The file is read once, line by line, in memory bounded by two segments of at most
//! [`MEMORY_ROWS`](crate::input::MEMORY_ROWS) rows each; lines are at most 1 MiB of UTF-8 text
//! ([`MAX_LINE`](crate::csv::MAX_LINE)). Cells are separated by commas and may be
//! blank-padded or double-quoted (a quoted comma is not supported here: the pump writes none).
//!
//! Files: `options.rs` (what `--phase` asks for), `read.rs` (the segment), `lines.rs` (the
//! capture's line reader), `device_lines.rs` (the pump's `EXCITE` and `ID` lines), `shift.rs`
//! (the operating point), `info.rs` (what the report says about the segment).

mod device_lines;
mod info;
mod lines;
mod options;
mod read;
mod shift;

pub use device_lines::{DeviceId, DeviceMap, ExciteLine};
pub use info::{Agreement, SegmentInfo};
pub use options::{OperatingPoint, SegmentOptions, EXCITE_PHASE};
pub use read::{read, read_from, Segment};
pub use shift::{absolute_model, read_shifted};
