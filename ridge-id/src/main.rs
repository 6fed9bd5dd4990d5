//! `ridge-id`: ARX identification of a logged CSV record.
//!
//! ```text
//! cargo run --release -p ridge-id -- identify --input LOG.csv \
//!     [--validate VAL.csv] [--method ridge-m|ridge|ols|rls|alasso] \
//!     [--criterion paper|aic|bic|validation] [--offset none|intercept] [--json] [--plot OUT.png]
//! ```
//!
//! All the work is in the `ridge_id` library; see `ridge-id identify --help`.

fn main() -> std::process::ExitCode {
    ridge_id::cli::main()
}
