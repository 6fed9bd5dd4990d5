//! `ridge-id`: ARX identification of a logged CSV record.
//!
//! ```text
//! cargo run --release -p host-tests --bin ridge-id -- identify --input LOG.csv \
//!     [--validate VAL.csv] [--method ridge-m|ridge|ols|rls|alasso] \
//!     [--criterion paper|aic|bic|validation] [--offset none|intercept] [--json] [--plot OUT.png]
//! ```
//!
//! All the work is in [`host_tests::identify`]; see `ridge-id identify --help`.

fn main() -> std::process::ExitCode {
    host_tests::identify::cli::main()
}
