//! The `ridge-id` command line (clap derive) and its `main`.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use std::str::FromStr;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};
use ridge_core_host::{
    Criterion, Grid, MethodKind, Offset, OrderRange, Structure, UnknownName, D_MAX, P_MAX, Q_MAX,
};

use crate::control::{ControlOptions, DEFAULT_TS, EXIT_REFUSED};
use crate::error::IdError;
use crate::initial::Initial;
use crate::options::{parse_range, parse_structure, Options, MAX_ITER_LIMIT};
use crate::options::{GammaScale, Hyper, Refine, Select, STANDARDISED_GAMMA};
use crate::phase::{OperatingPoint, SegmentOptions};
use crate::pipeline::run;
use ridge_core::control::Spec;

/// `ridge-id`: identify an ARX model from a logged CSV record.
#[derive(Debug, Parser)]
#[command(name = "ridge-id", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Identify y_t = Σθ_i y_{t-i} + Σφ_j u_{t-j-d} (+ c) from a CSV log with columns u and y
    /// (other columns, such as t, are ignored). Scores are one-step and free-run RMSE / fit %
    /// from measured initial conditions: both predictors are seeded with the first
    /// m = max(p, d+q-1) measured samples and scored on samples m..N. With --control, also
    /// design the firmware's flow controller for the model.
    #[command(after_long_help = EXIT_HELP, after_help = EXIT_HELP)]
    Identify(IdentifyArgs),
    /// Capture the pump's serial output (log rows and report lines) into a CSV that identify
    /// reads: the header t,u,y,r,phase, every log row verbatim, every other device line as a
    /// "# " comment; only complete lines, a running count on stderr, Ctrl-C ends cleanly
    /// (src/capture.rs).
    Capture(crate::capture::CaptureArgs),
}

/// The exit statuses, in `--help`.
const EXIT_HELP: &str =
    "Exit status: 0 success; 1 an identification error (one line on stderr), or \
with --strict a report with warnings (the report is printed, then one line on stderr); 2 a \
command-line error; 3 the controller of --control was refused (the report, with the reason, \
is still printed).

Input: a regular file is streamed (any length, constant memory); --input - (standard input), a \
pipe or a FIFO is read once into memory, at most 4194304 rows. Lines longer than 1 MiB are an \
error.";

/// `--help` of `--control`: what is designed and the conventions.
const CONTROL_HELP: &str = "\
Design the firmware's flow controller for the identified model, with the same ridge-core code \
(pole placement with integral action, in f64), and print it (with --json: a \"control\" object; \
with --plot OUT.png: also OUT-control.png, a closed-loop setpoint step simulated on the model).

Conventions: polynomials in q^-1, coefficients in ascending powers. Model \
A(q^-1) y_t = q^-d B(q^-1) u_t + c, A = [1, -theta_1, ...], B = [phi_0, ...]. Controller \
R(q^-1) u_{t+1} = T(q^-1) r_{t+1} - S(q^-1) y_t, R monic (R(1) = 0: integral action; \
T(1) = S(1)). Closed loop P = A R + q^-(d+1) B S; its poles are the roots of P. Modulus margin \
1 / max_w |A R / P| (at least 0.5 required).

Checked first: every model pole within 0.995; static gain B(1)/A(1) above 0, or within \
--gain-min/--gain-max (no absolute size limit by default, the log's units being unknown), and \
large enough that the log's u span moves y by at least 1 % of the log's y span at steady state. \
The design is then retried up to 5 times, each 1.5 times slower, while its pole or margin check fails (the \
firmware's defaults). A refusal prints which check failed, with its numbers, and exits with \
status 3.";

/// A clap parser of the names of `all`: it accepts exactly `name(v)` for each `v` of `all`
/// (ridge-core's one name table) and converts with the enum's `FromStr`; `--help` lists
/// the names, each with `help(v)`, and clap's error for another word lists them too.
fn names<T>(
    all: &'static [T],
    name: fn(T) -> &'static str,
    help: fn(T) -> &'static str,
) -> impl TypedValueParser<Value = T>
where
    T: Copy + FromStr<Err = UnknownName> + Send + Sync + 'static,
{
    PossibleValuesParser::new(
        all.iter()
            .map(|&v| PossibleValue::new(name(v)).help(help(v))),
    )
    .try_map(|s| s.parse::<T>())
}

/// `--help` text of an estimator.
fn method_help(m: MethodKind) -> &'static str {
    match m {
        MethodKind::RidgeM => "Ridge with momentum (the paper's method)",
        MethodKind::Ridge => "Plain Ridge (one Ridge-M iterate)",
        MethodKind::Ols => "Ordinary least squares",
        MethodKind::Rls => {
            "Recursive least squares on the Ridge-M search's structure (or --structure)"
        }
        MethodKind::AdaptiveLasso => "Adaptive LASSO (weights from least squares, lambda by BIC)",
    }
}

/// `--help` text of a criterion.
fn criterion_help(c: Criterion) -> &'static str {
    match c {
        Criterion::Paper => "The paper's eq. (14): N ln(RSS/N) + alpha (p+q+d)",
        Criterion::Aic => "Delay-free AIC: N ln(RSS/N) + alpha (p+q)",
        Criterion::Bic => "BIC: N ln(RSS/N) + ln(N) (p+q)",
        Criterion::Validation => {
            "One-step (equation-error) loss on the --validate record, no penalty"
        }
    }
}

/// `--help` text of an offset choice.
fn offset_help(o: Offset) -> &'static str {
    match o {
        Offset::None => "No constant term (the paper's model)",
        Offset::Intercept => "A constant term c (absorbs a dead zone or sensor offset)",
    }
}

/// `--max-iter`: a whole number in `1..=MAX_ITER_LIMIT`, with a message saying so.
fn max_iter(s: &str) -> Result<u32, String> {
    s.trim()
        .parse::<u32>()
        .ok()
        .filter(|k| (1..=MAX_ITER_LIMIT).contains(k))
        .ok_or_else(|| format!("must be a whole number in 1..={MAX_ITER_LIMIT}"))
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
    /// Estimation record: CSV with a header row and columns u and y; - reads standard input
    /// (once, into memory: at most 4194304 rows).
    #[arg(long, value_name = "LOG.csv")]
    pub input: PathBuf,
    /// Validation record (same format), scored like the estimation record.
    #[arg(long, value_name = "VAL.csv")]
    pub validate: Option<PathBuf>,
    /// Estimator [default: ridge-m].
    #[arg(
        long,
        value_parser = names(&MethodKind::ALL, MethodKind::name, method_help)
    )]
    pub method: Option<MethodKind>,
    /// Structure criterion [default: aic] (aic: delay-free AIC, the core's default; validation
    /// needs --validate).
    #[arg(
        long,
        value_parser = names(&Criterion::ALL, Criterion::name, criterion_help)
    )]
    pub criterion: Option<Criterion>,
    /// Ridge / Ridge-M regularisation gamma, above 0, in the data's units (eq. 12 of the
    /// paper as printed: the paper's is 1000) [default: 1 on the standardised record, u and y
    /// divided by their standard deviations: scale-free, about one sample's weight].
    #[arg(long, value_name = "G", allow_negative_numbers = true)]
    pub gamma: Option<f64>,
    /// Ridge-M momentum beta, in [0, 1).
    #[arg(long, value_name = "B", default_value_t = Hyper::default().beta, allow_negative_numbers = true)]
    pub beta: f64,
    /// Penalty weight alpha of the paper and aic criteria, at least 0.
    #[arg(long, value_name = "A", default_value_t = Hyper::default().alpha, allow_negative_numbers = true)]
    pub alpha: f64,
    /// Ridge-M maximum iterations, 1..=100000.
    #[arg(long, value_name = "K", default_value_t = Hyper::default().max_iter, allow_negative_numbers = true, value_parser = max_iter)]
    pub max_iter: u32,
    /// Ridge-M stopping tolerance on ‖w_{k+1} − w_k‖, at least 0.
    #[arg(long, value_name = "E", default_value_t = Hyper::default().tol, allow_negative_numbers = true)]
    pub tol: f64,
    /// RLS forgetting factor lambda, in (0, 1] (--method rls only).
    #[arg(long, value_name = "L", default_value_t = Hyper::default().lambda, allow_negative_numbers = true)]
    pub lambda: f64,
    /// RLS initial covariance P0 = delta I, above 0 (--method rls only).
    #[arg(long, value_name = "D", default_value_t = Hyper::default().delta, allow_negative_numbers = true)]
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
    /// Constant term (intercept, the default, is estimated and never shrunk).
    #[arg(
        long,
        default_value_t = Offset::Intercept,
        value_parser = names(&Offset::ALL, Offset::name, offset_help)
    )]
    pub offset: Offset,
    /// Initial conditions of the regression: measured (the first M samples, M the grid's
    /// longest lag, fill the lag history; as MATLAB and SysIdentPy) or zero (the paper's
    /// eq. 6, the device's).
    #[arg(
        long,
        default_value_t = Initial::default(),
        value_parser = names(&Initial::ALL, Initial::name, Initial::help)
    )]
    pub initial: Initial,
    /// How the structure is chosen: by --criterion, or by the lowest free-run RMSE on the
    /// --validate record (auto: the latter with --validate, unless a particular model is asked
    /// for).
    #[arg(
        long,
        default_value_t = Select::default(),
        value_parser = names(&Select::ALL, Select::name, Select::help)
    )]
    pub select: Select,
    /// Output-error refinement of the chosen model (Gauss-Newton on the free-run error of the
    /// estimation record, from the ARX estimate); with --validate kept only if it lowers the
    /// validation free-run RMSE (auto: oe with --validate, unless a particular model is asked
    /// for).
    #[arg(
        long,
        default_value_t = Refine::default(),
        value_parser = names(&Refine::ALL, Refine::name, Refine::help)
    )]
    pub refine: Refine,
    /// Print exactly one JSON object instead of the readable report.
    #[arg(long)]
    pub json: bool,
    /// Exit with status 1 when the report has warnings (an unstable model, a negative fit,
    /// a record too short or too little excited for the structure, a Ridge-M run that
    /// stopped without converging, Ridge or LASSO coefficients shrunk); the report is printed
    /// all the same.
    #[arg(long)]
    pub strict: bool,
    /// The model for the pump: --eeprom, --record, --stm32-store (src/export.rs).
    #[command(flatten)]
    pub export: crate::export::ExportArgs,
    /// Write a PNG of measured vs one-step vs free-run output (with --control, also
    /// OUT-control.png: the simulated closed-loop step).
    #[arg(long, value_name = "OUT.png")]
    pub plot: Option<PathBuf>,
    /// Design the flow controller for the identified model (see --help).
    #[arg(long, long_help = CONTROL_HELP)]
    pub control: bool,
    /// Estimation record = the rows of --input whose phase column is NAME (a pump's log
    /// capture: header t,u,y,r,phase, other lines as # comments): the last complete segment
    /// of such rows, or the --attempt-th; refused when rows are missing. See
    /// docs/real-logs.md.
    #[arg(long, value_name = "NAME")]
    pub phase: Option<String>,
    /// --phase (or --device): take the N-th segment of the phase in the file (from 1) instead
    /// of the last complete one.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub attempt: Option<u32>,
    /// --phase (or --device): the operating point subtracted before the statistics (the model
    /// printed is the absolute one, with the intercept): log = u0, y0 of the `# EXCITE` line
    /// before the segment (the pump's; the default), none, or U0,Y0 in the log's units.
    #[arg(
        long,
        value_name = "log|none|U0,Y0",
        requires = "phase",
        allow_hyphen_values = true
    )]
    pub operating_point: Option<OperatingPoint>,
    /// Identify as the pump does (docs/real-logs.md), with the firmware's own settings: the
    /// same as --phase excite --operating-point log --initial zero --offset intercept
    /// --method ridge-m --criterion aic --gamma 1000 --beta 0.01 --alpha 12 --max-iter 200
    /// --tol 1e-6 --p 1..=5 --q 1..=6 --d 0..=6 (--phase, --attempt and --operating-point may
    /// still be given; the segment's input goes through the capture's MAP line).
    #[arg(long, conflicts_with_all = [
        "method", "criterion", "gamma", "beta", "alpha", "max_iter", "tol", "p", "q", "d",
        "structure", "offset", "initial", "select", "refine",
    ])]
    pub device: bool,
    /// The speed knob of --control: time constant of the closed-loop setpoint response, in
    /// seconds [default: a quarter of the model's open-loop time constant (its slow pole),
    /// within 2 Ts..2 s; 0.1 s without a slow pole].
    #[arg(
        long,
        value_name = "TAU_S",
        requires = "control",
        allow_negative_numbers = true
    )]
    pub speed: Option<f64>,
    /// --control: time constant of the observer pole, in seconds (beta = exp(-Ts/tau_o)): the
    /// slower, the larger the modulus margin and the slower the disturbance rejection. The
    /// default is the firmware's (beta 0.9 at 100 Hz); at another --ts, scale it with Ts
    /// (9.5 Ts keeps beta 0.9).
    #[arg(long, value_name = "TAU_O_S", default_value_t = Spec::<f64>::new(DEFAULT_TS).observer, requires = "control", allow_negative_numbers = true)]
    pub observer: f64,
    /// Sample period of the log in seconds, for --control (default: the pump's 100 Hz; the
    /// CSV's t column is not read).
    #[arg(long, value_name = "SECONDS", default_value_t = DEFAULT_TS, requires = "control", allow_negative_numbers = true)]
    pub ts: f64,
    /// --control: smallest accepted static gain B(1)/A(1), output units per input unit
    /// [default: any gain above 0].
    #[arg(
        long,
        value_name = "G",
        requires = "control",
        allow_negative_numbers = true
    )]
    pub gain_min: Option<f64>,
    /// --control: largest accepted static gain [default: no limit].
    #[arg(
        long,
        value_name = "G",
        requires = "control",
        allow_negative_numbers = true
    )]
    pub gain_max: Option<f64>,
    /// --control --plot: smallest input of the simulated loop [default: the log's smallest u].
    #[arg(
        long,
        value_name = "U",
        requires = "control",
        allow_negative_numbers = true
    )]
    pub u_min: Option<f64>,
    /// --control --plot: largest input of the simulated loop [default: the log's largest u].
    #[arg(
        long,
        value_name = "U",
        requires = "control",
        allow_negative_numbers = true
    )]
    pub u_max: Option<f64>,
    /// --control --plot: largest input change per sample of the simulated loop (rate limit)
    /// [default: none].
    #[arg(
        long,
        value_name = "DU",
        requires = "control",
        allow_negative_numbers = true
    )]
    pub u_step: Option<f64>,
}

impl IdentifyArgs {
    /// The library options of these arguments.
    ///
    /// Errors: `--device` with firmware settings ridge-id cannot express (see
    /// [`crate::device_check::apply`]).
    pub fn options(&self) -> Result<Options, IdError> {
        // A particular model asked for: the structure by its criterion, the estimator's model
        // as it is, unless --select or --refine says otherwise (see Select::Auto).
        let particular = self.method.is_some()
            || self.criterion.is_some()
            || self.gamma.is_some()
            || self.structure.is_some();
        let mut opts = Options {
            input: self.input.clone(),
            validate: self.validate.clone(),
            method: self.method.unwrap_or_default(),
            criterion: self.criterion.unwrap_or_default(),
            hyper: Hyper {
                gamma: self.gamma.unwrap_or(STANDARDISED_GAMMA),
                gamma_scale: match self.gamma {
                    Some(_) => GammaScale::Data,
                    None => GammaScale::Standardised,
                },
                beta: self.beta,
                alpha: self.alpha,
                max_iter: self.max_iter,
                tol: self.tol,
                lambda: self.lambda,
                delta: self.delta,
                initial: self.initial,
            },
            grid: Grid {
                p: self.p,
                q: self.q,
                d: self.d,
            },
            structure: self.structure,
            offset: self.offset,
            select: match self.select {
                Select::Auto if particular => Select::Criterion,
                s => s,
            },
            refine: match self.refine {
                Refine::Auto if particular => Refine::None,
                r => r,
            },
            plot: self.plot.clone(),
            control: self.control.then_some(ControlOptions {
                ts: self.ts,
                speed: self.speed,
                observer: self.observer,
                gain_min: self.gain_min,
                gain_max: self.gain_max,
                u_min: self.u_min,
                u_max: self.u_max,
                u_step: self.u_step,
            }),
            segment: self.phase.as_ref().map(|phase| SegmentOptions {
                phase: phase.clone(),
                attempt: self.attempt,
                operating_point: self.operating_point.unwrap_or_default(),
            }),
        };
        if self.device {
            crate::device_check::apply(&mut opts)?;
            if let Some(seg) = &mut opts.segment {
                seg.attempt = self.attempt.or(seg.attempt);
                if let Some(op) = self.operating_point {
                    seg.operating_point = op;
                }
            }
        }
        if opts.segment.is_none() && (self.attempt.is_some() || self.operating_point.is_some()) {
            return Err(IdError::Usage(
                "--attempt and --operating-point select within a segment: add --phase NAME \
                 (or --device)"
                    .into(),
            ));
        }
        Ok(opts)
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
/// (one line `error: …` on stderr) or, with `--strict`, a report with warnings (printed,
/// then one line `error: --strict: …` on stderr), 2 on a command-line error (clap's message),
/// [`EXIT_REFUSED`] (3) when the controller of `--control` was refused (the report, with the
/// reason, is printed as on success).
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
        Command::Identify(args) => match args.options().and_then(|o| run(&o)) {
            Ok(report) => {
                let text = if args.json {
                    let mut s = report.to_json_string();
                    s.push('\n');
                    s
                } else {
                    report.to_text()
                };
                let refused = report
                    .control
                    .as_ref()
                    .is_some_and(|c| c.refusal().is_some());
                if print(&text) {
                    let failed = args.strict && !report.warnings.is_empty();
                    if !failed && !refused && args.export.any() {
                        match crate::export::export(&args.export, &report) {
                            Ok(notes) => notes.iter().for_each(|n| eprintln!("{n}")),
                            Err(e) => {
                                eprintln!("error: {e}");
                                return ExitCode::FAILURE;
                            }
                        }
                    }
                    if args.strict && !report.warnings.is_empty() {
                        eprintln!(
                            "error: --strict: {} warning(s), the first: {}",
                            report.warnings.len(),
                            report.warnings[0].message
                        );
                        ExitCode::FAILURE
                    } else if refused {
                        ExitCode::from(EXIT_REFUSED)
                    } else {
                        ExitCode::SUCCESS
                    }
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
        Command::Capture(args) => match crate::capture::run(&args) {
            Ok(_) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identify(extra: &[&str]) -> Result<IdentifyArgs, clap::Error> {
        let mut argv = vec!["ridge-id", "identify", "--input", "x.csv"];
        argv.extend(extra);
        Cli::try_parse_from(argv).map(|cli| match cli.command {
            Command::Identify(a) => a,
            Command::Capture(_) => unreachable!("identify was parsed"),
        })
    }

    #[test]
    fn names_on_the_command_line() {
        let o = identify(&[]).unwrap().options().unwrap();
        assert_eq!(
            (o.method, o.criterion, o.offset),
            (MethodKind::RidgeM, Criterion::Aic, Offset::Intercept)
        );
        for (word, want) in [
            ("ridge-m", MethodKind::RidgeM),
            ("ridge", MethodKind::Ridge),
            ("ols", MethodKind::Ols),
            ("rls", MethodKind::Rls),
            ("alasso", MethodKind::AdaptiveLasso),
        ] {
            assert_eq!(identify(&["--method", word]).unwrap().method, Some(want));
        }
        for (word, want) in [
            ("paper", Criterion::Paper),
            ("aic", Criterion::Aic),
            ("bic", Criterion::Bic),
            ("validation", Criterion::Validation),
        ] {
            assert_eq!(
                identify(&["--criterion", word]).unwrap().criterion,
                Some(want)
            );
        }
        for (word, want) in [("none", Offset::None), ("intercept", Offset::Intercept)] {
            assert_eq!(identify(&["--offset", word]).unwrap().offset, want);
        }
        // Names are exact: no other spelling or case.
        for (flag, word) in [
            ("--method", "lasso"),
            ("--method", "Ridge-M"),
            ("--criterion", "AIC"),
            ("--offset", "const"),
        ] {
            let e = identify(&[flag, word]).unwrap_err();
            assert_eq!(
                e.kind(),
                clap::error::ErrorKind::InvalidValue,
                "{flag} {word}"
            );
        }
    }

    /// The defaults leave the model to the tool (scale-free γ, `auto` selection and
    /// refinement); naming a method, a criterion, a γ or a structure asks for that model as it
    /// is (the paper's settings included), unless --select or --refine says otherwise.
    #[test]
    fn a_particular_model_asked_for_turns_the_auto_choices_off() {
        let opts = |extra: &[&str]| {
            let mut a = vec!["--validate", "v.csv"];
            a.extend(extra);
            identify(&a).unwrap().options().unwrap()
        };
        let o = opts(&[]);
        assert_eq!((o.select, o.refine), (Select::Auto, Refine::Auto));
        assert_eq!(o.select_choice().0, Select::FreeRun);
        assert_eq!(o.refine_choice().0, Refine::Oe);
        assert_eq!(
            (o.hyper.gamma, o.hyper.gamma_scale),
            (STANDARDISED_GAMMA, GammaScale::Standardised)
        );
        for extra in [
            &["--method", "ridge-m"][..],
            &["--criterion", "aic"],
            &["--gamma", "1000"],
            &["--structure", "2,1,1"],
            &[
                "--gamma",
                "1000",
                "--criterion",
                "paper",
                "--initial",
                "zero",
                "--offset",
                "none",
            ],
        ] {
            let o = opts(extra);
            assert_eq!(
                (o.select, o.refine),
                (Select::Criterion, Refine::None),
                "{extra:?}"
            );
        }
        let o = opts(&["--gamma", "1000"]);
        assert_eq!(
            (o.hyper.gamma, o.hyper.gamma_scale),
            (1000.0, GammaScale::Data)
        );
        // Asked for all the same.
        let o = opts(&[
            "--criterion",
            "bic",
            "--select",
            "free-run",
            "--refine",
            "oe",
        ]);
        assert_eq!((o.select, o.refine), (Select::FreeRun, Refine::Oe));
        // `auto` spelled out is the default: the particular model keeps its criterion.
        let o = opts(&["--method", "ols", "--select", "auto"]);
        assert_eq!(o.select, Select::Criterion);
        // Without a validation record `auto` is the criterion and no refinement.
        let o = identify(&[]).unwrap().options().unwrap();
        assert_eq!(
            (o.select_choice().0, o.refine_choice().0),
            (Select::Criterion, Refine::None)
        );
    }
}
