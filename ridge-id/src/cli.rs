//! The `ridge-id` command line (clap derive) and its `main`.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};
use ridge_core::{Criterion, Grid, Offset, OrderRange, Structure, D_MAX, P_MAX, Q_MAX};

use crate::options::{parse_range, parse_structure, MethodName, Options};
use crate::report::Hyper;
use crate::run;

/// `ridge-id`: identify an ARX model from a logged CSV record.
#[derive(Debug, Parser)]
#[command(name = "ridge-id", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Identify y_t = Σθ_i y_{t-i} + Σφ_j u_{t-j-d} (+ c) from a CSV log with columns u and y
    /// (other columns, such as t, are ignored). Scores are one-step and free-run RMSE / fit %
    /// from measured initial conditions (samples m..N, SPEC §6).
    Identify(IdentifyArgs),
}

/// Estimator names on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Ridge with momentum (the paper's method).
    #[value(name = "ridge-m")]
    RidgeM,
    /// Plain Ridge (one Ridge-M iterate).
    Ridge,
    /// Ordinary least squares.
    Ols,
    /// Recursive least squares on the Ridge-M search's structure (or --structure).
    Rls,
    /// Adaptive LASSO (weights from least squares, lambda by BIC).
    Alasso,
}

impl From<MethodArg> for MethodName {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::RidgeM => MethodName::RidgeM,
            MethodArg::Ridge => MethodName::Ridge,
            MethodArg::Ols => MethodName::Ols,
            MethodArg::Rls => MethodName::Rls,
            MethodArg::Alasso => MethodName::AdaptiveLasso,
        }
    }
}

/// Criterion names on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CriterionArg {
    /// The paper's eq. (14): N ln(RSS/N) + alpha (p+q+d).
    Paper,
    /// Delay-free AIC: N ln(RSS/N) + alpha (p+q).
    Aic,
    /// BIC: N ln(RSS/N) + ln(N) (p+q).
    Bic,
    /// One-step (equation-error) loss on the --validate record, no penalty.
    Validation,
}

impl From<CriterionArg> for Criterion {
    fn from(c: CriterionArg) -> Self {
        match c {
            CriterionArg::Paper => Criterion::Paper,
            CriterionArg::Aic => Criterion::Aic,
            CriterionArg::Bic => Criterion::Bic,
            CriterionArg::Validation => Criterion::Validation,
        }
    }
}

/// Offset names on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OffsetArg {
    /// No constant term (the paper's model).
    None,
    /// A constant term c (absorbs a dead zone or sensor offset).
    Intercept,
}

fn p_range(s: &str) -> Result<OrderRange, String> {
    parse_range(s, 1, P_MAX as u8)
}
fn q_range(s: &str) -> Result<OrderRange, String> {
    parse_range(s, 1, Q_MAX as u8)
}
fn d_range(s: &str) -> Result<OrderRange, String> {
    parse_range(s, 0, D_MAX as u8)
}

/// Options of `ridge-id identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// Estimation record: CSV with a header row and columns u and y.
    #[arg(long, value_name = "LOG.csv")]
    pub input: PathBuf,
    /// Validation record (same format), scored like the estimation record.
    #[arg(long, value_name = "VAL.csv")]
    pub validate: Option<PathBuf>,
    /// Estimator.
    #[arg(long, value_enum, default_value = "ridge-m")]
    pub method: MethodArg,
    /// Structure criterion (aic: delay-free AIC, the core's default; validation needs --validate).
    #[arg(long, value_enum, default_value = "aic")]
    pub criterion: CriterionArg,
    /// Ridge / Ridge-M regularisation gamma.
    #[arg(long, value_name = "G", default_value_t = Hyper::default().gamma)]
    pub gamma: f64,
    /// Ridge-M momentum beta, in [0, 1).
    #[arg(long, value_name = "B", default_value_t = Hyper::default().beta)]
    pub beta: f64,
    /// Penalty weight alpha of the paper and aic criteria.
    #[arg(long, value_name = "A", default_value_t = Hyper::default().alpha)]
    pub alpha: f64,
    /// Ridge-M maximum iterations.
    #[arg(long, value_name = "K", default_value_t = Hyper::default().max_iter)]
    pub max_iter: u32,
    /// Ridge-M stopping tolerance on ‖w_{k+1} − w_k‖.
    #[arg(long, value_name = "E", default_value_t = Hyper::default().tol)]
    pub tol: f64,
    /// RLS forgetting factor lambda, in (0, 1] (--method rls only).
    #[arg(long, value_name = "L", default_value_t = Hyper::default().lambda)]
    pub lambda: f64,
    /// RLS initial covariance P0 = delta I (--method rls only).
    #[arg(long, value_name = "D", default_value_t = Hyper::default().delta)]
    pub delta: f64,
    /// Autoregressive orders searched: a..=b or a single number.
    #[arg(long = "p", value_name = "RANGE", default_value = "1..=6", value_parser = p_range)]
    pub p: OrderRange,
    /// Input orders searched: a..=b or a single number.
    #[arg(long = "q", value_name = "RANGE", default_value = "1..=6", value_parser = q_range)]
    pub q: OrderRange,
    /// Input delays searched (samples): a..=b or a single number.
    #[arg(long = "d", value_name = "RANGE", default_value = "0..=6", value_parser = d_range)]
    pub d: OrderRange,
    /// Fix the structure instead of searching.
    #[arg(long, value_name = "P,Q,D", value_parser = parse_structure, conflicts_with_all = ["p", "q", "d"])]
    pub structure: Option<Structure>,
    /// Constant term.
    #[arg(long, value_enum, default_value = "none")]
    pub offset: OffsetArg,
    /// Print exactly one JSON object instead of the readable report.
    #[arg(long)]
    pub json: bool,
    /// Write a PNG of measured vs one-step vs free-run output.
    #[arg(long, value_name = "OUT.png")]
    pub plot: Option<PathBuf>,
}

impl IdentifyArgs {
    /// The library options of these arguments.
    pub fn options(&self) -> Options {
        Options {
            input: self.input.clone(),
            validate: self.validate.clone(),
            method: self.method.into(),
            criterion: self.criterion.into(),
            hyper: Hyper {
                gamma: self.gamma,
                beta: self.beta,
                alpha: self.alpha,
                max_iter: self.max_iter,
                tol: self.tol,
                lambda: self.lambda,
                delta: self.delta,
            },
            grid: Grid {
                p: self.p,
                q: self.q,
                d: self.d,
            },
            structure: self.structure,
            offset: match self.offset {
                OffsetArg::None => Offset::None,
                OffsetArg::Intercept => Offset::Intercept,
            },
            plot: self.plot.clone(),
        }
    }
}

/// Prints `text` to stdout; a closed pipe (`ridge-id … | head`) is not an error.
fn print(text: &str) -> bool {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Ok(()) => true,
        Err(e) => e.kind() == std::io::ErrorKind::BrokenPipe,
    }
}

/// `main` of the `ridge-id` binary: exit 0 on success, 1 on an identification error
/// (one line `error: …` on stderr), 2 on a command-line error (clap's message).
pub fn main() -> ExitCode {
    // Defence in depth: a bug must still end in one line, not a backtrace.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!(
            "error: internal error{at}: {} (please report)",
            msg.replace('\n', " ")
        );
    }));
    let cli = Cli::parse();
    match cli.command {
        Command::Identify(args) => match run(&args.options()) {
            Ok(report) => {
                let text = if args.json {
                    let mut s = report.to_json_string();
                    s.push('\n');
                    s
                } else {
                    report.to_text()
                };
                if print(&text) {
                    ExitCode::SUCCESS
                } else {
                    eprintln!("error: cannot write to standard output");
                    ExitCode::FAILURE
                }
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        },
    }
}
