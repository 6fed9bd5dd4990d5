//! The `ridge-id` binary: ARX identification of a logged CSV record.
//!
//! ```text
//! cargo run --release -p ridge-id -- identify --input LOG.csv \
//!     [--validate VAL.csv] [--method ridge-m|ridge|ols|rls|alasso] \
//!     [--criterion paper|aic|bic|validation] [--offset none|intercept] [--json] [--plot OUT.png]
//! ```
//!
//! This file only calls [`ridge_id::cli::main`]: the command line is in `src/cli.rs`, the
//! work in the `ridge_id` library (`src/lib.rs`); see `ridge-id identify --help` and
//! `docs/worked-example.md`.

fn main() -> std::process::ExitCode {
    ridge_id::cli::main()
}
