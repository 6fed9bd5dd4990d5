//! `ridge-id`: ARX identification of a logged `u`/`y` record (CSV), as a library.
//!
//! The crate is `ridge-id/` in the workspace. Its binary `ridge-id` (`src/main.rs`) only
//! calls [`cli::main`], which parses the command line (clap) into [`Options`], runs
//! [`run`] and prints the [`Report`] with a printer:
//!
//! ```text
//! cargo run --release -p ridge-id -- identify --input LOG.csv [--validate VAL.csv] [--json]
//!     [--control [--speed TAU_S] [--ts SECONDS]]
//! ```
//!
//! Everything else is here, so that other programs (e.g. the paper tables, the whole-firmware
//! simulation's plots) can reuse the pieces. Floors, from the bottom (a module uses only
//! modules of lower floors):
//! - leaves: [`error`] ([`IdError`]: every failure, one line naming the file, the line and
//!   the problem), [`numfmt`] (number formatting), [`initial`], [`residuals`] (the residual
//!   analysis's streaming sums), [`capture`] (`ridge-id capture`);
//! - reading: [`csv`] (streaming CSV reader, line-numbered errors), [`eval`] (one streaming
//!   pass into exact statistics, [`read_record`]; one pass scoring a model one-step and free
//!   run from measured initial conditions, [`evaluate_file`], with a bounded [`eval::Trace`]
//!   for the plot), [`input`] (a regular file streamed for every pass, or input read once:
//!   `--input -`, a pipe, a FIFO), [`phase`] (`--phase`: one segment of a pump's log capture
//!   around its operating point);
//! - computation: [`refine`] (`--refine oe`, `--select free-run`), [`control`] (`--control`:
//!   the firmware's controller design, its checks, closed-loop poles and a simulated step;
//!   a refused controller is part of the [`Report`], and the binary exits with
//!   [`control::EXIT_REFUSED`]), [`warnings`] (what should not be trusted about a model;
//!   `--strict` exits 1 on any);
//! - settings: [`options`] ([`Options`], [`Hyper`], `--select`/`--refine`; estimators,
//!   criteria and offsets are ridge-core's [`ridge_core_host::MethodKind`],
//!   [`ridge_core_host::Criterion`] and [`ridge_core_host::Offset`], named by their `name()`),
//!   [`device_check`] (`--device`: the firmware's identification settings);
//! - the run: [`pipeline`] ([`run`]: read → identify → select/refine → score → control →
//!   render), [`outcome`] ([`Report`]), [`plot`] (every PNG);
//! - presentation: [`printer`] (the report as text or JSON, knowing no flags), [`export`]
//!   (`--eeprom`, `--record`, `--stm32-store`), [`cli`] (flags → [`Options`] → printer).
//!
//! Tests: `tests/cli.rs` runs the binary (JSON shape, bad input, a known ARX plant from
//! `pump-sim`, 10⁶ rows in flat memory); `tests/logged_data.rs` checks the library on the
//! two real records of `shared/data/` against an explicit regression built with nalgebra;
//! `tests/control.rs` checks `--control` against a known plant (closed-loop polynomial and
//! poles rebuilt from the JSON, the loop simulated on the true plant, refusals); `--phase`
//! and `--device` are tested against the firmware itself in `host-tests/tests/device_log.rs`.
//!
//! Memory is independent of the record length: the estimation record is read once for
//! the statistics, once more to score the model (and once more for RLS); the
//! validation record once for its statistics and once to score the model. The plot
//! keeps at most ~2000 points per signal (a min/max envelope for longer records).

pub mod capture;
pub mod cli;
pub mod control;
pub mod csv;
pub mod device_check;
pub mod error;
pub mod eval;
pub mod export;
pub mod initial;
pub mod input;
pub mod numfmt;
pub mod options;
pub mod outcome;
pub mod phase;
pub mod pipeline;
pub mod plot;
pub mod printer;
pub mod refine;
pub mod residuals;
pub mod warnings;

pub use control::{ControlOptions, ControlReport};
pub use error::IdError;
pub use eval::{
    evaluate_file, read_record, read_record_with, Figures, RecordStats, Trace, PLOT_POINTS,
    TINY_PRODUCT,
};
pub use initial::Initial;
pub use options::{Hyper, Options};
pub use outcome::{Report, SearchInfo};
pub use pipeline::{rows_needed, run};
pub use plot::{control_plot_path, residuals_plot_path};
