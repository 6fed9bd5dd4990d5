//! Byte-level and value-level fuzzing with proptest, bounded in cases so that it runs in
//! `cargo test` (and so in CI) in seconds: never a panic, never a hang, every error one
//! short line.
//!
//! - the CSV reader on arbitrary bytes and on CSV-like token soup, and its plain-line reading
//!   against the `csv` crate's ([`Reference`]): the same samples, lines and errors, with the
//!   input arriving in arbitrary pieces and failing after some;
//! - ridge-core's statistics, structure search (every estimator and criterion) and RLS on
//!   arbitrary finite data (magnitudes from 1e-300 to 1e300, constant runs, few rows);
//! - the whole `ridge_id::run` pipeline on arbitrary finite records with arbitrary valid
//!   options: a report whose warnings agree with its own figures, or a one-line error.
//!
//! Case counts are the `cases` of each block (figures in the README); set
//! `RIDGE_FUZZ_SCALE=N` to multiply them for a longer run. Each case of the last two is
//! also timed: one taking over 10 s fails as a hang.

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::Config;
use ridge_core_host::{
    AdaptiveLasso, Criterion, Evaluation, FloatGram, Grid, Method, MethodKind, Offset, OrderRange,
    Ridge, RidgeM, Rls, Scale, Search, Structure,
};
use ridge_id::csv::{CsvRecord, Reference};
use ridge_id::warnings::WarningKind;
use ridge_id::{run, IdError, Options};

fn config(cases: u32) -> Config {
    let scale = std::env::var("RIDGE_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse::<u32>().ok())
        .unwrap_or(1)
        .max(1);
    Config {
        cases: cases.saturating_mul(scale),
        failure_persistence: None,
        max_shrink_iters: 2000,
        ..Config::default()
    }
}

/// Longest error message accepted: the file name, a line number and ~80 quoted characters.
const MESSAGE_MAX: usize = 400;

fn check_error(e: &IdError, text: &[u8]) {
    let m = e.to_string();
    assert!(!m.contains('\n'), "{m}");
    assert!(m.len() <= MESSAGE_MAX, "{} bytes: {m}", m.len());
    if let Some(line) = e.line_number() {
        let lines = text.iter().filter(|&&b| b == b'\n').count() as u64 + 1;
        assert!(
            (1..=lines + 1).contains(&line),
            "line {line} of {lines}: {m}"
        );
    }
}

fn read(text: &[u8]) {
    match CsvRecord::from_reader(text, "F.csv") {
        Err(e) => check_error(&e, text),
        Ok(r) => {
            let mut last = 0;
            for s in r {
                match s {
                    Ok(s) => {
                        assert!(s.u.is_finite() && s.y.is_finite());
                        assert!(s.line > last, "lines {last} then {}", s.line);
                        last = s.line;
                    }
                    Err(e) => check_error(&e, text),
                }
            }
        }
    }
}

/// CSV-like tokens, including the awkward ones.
fn token() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        Just(b"u".to_vec()),
        Just(b"y".to_vec()),
        Just(b"t".to_vec()),
        Just(b",".to_vec()),
        Just(b",".to_vec()),
        Just(b"\n".to_vec()),
        Just(b"\n".to_vec()),
        Just(b"\r\n".to_vec()),
        Just(b"\"".to_vec()),
        Just(b"#".to_vec()),
        Just(b" ".to_vec()),
        Just("\u{feff}".as_bytes().to_vec()),
        Just(b"\xff".to_vec()),
        Just(b"NaN".to_vec()),
        Just(b"-inf".to_vec()),
        Just(b"1e400".to_vec()),
        Just(b"1e-320".to_vec()),
        Just(b"u,y\n".to_vec()),
        any::<f64>().prop_map(|v| v.to_string().into_bytes()),
        (-1000i32..1000).prop_map(|v| v.to_string().into_bytes()),
        prop::collection::vec(any::<u8>(), 0..4),
    ]
}

proptest! {
    #![proptest_config(config(10_000))]

    #[test]
    fn csv_reader_on_arbitrary_bytes(text in prop::collection::vec(any::<u8>(), 0..600)) {
        read(&text);
    }

    #[test]
    fn csv_reader_on_csv_like_tokens(tokens in prop::collection::vec(token(), 0..120)) {
        read(&tokens.concat());
    }
}

proptest! {
    #![proptest_config(config(3_000))]

    #[test]
    fn csv_reader_reads_arbitrary_bytes_as_the_csv_crate(
        text in prop::collection::vec(any::<u8>(), 0..600),
        pieces in pieces(),
    ) {
        same_as_reference(&text, &pieces);
    }

    #[test]
    fn csv_reader_reads_token_soup_as_the_csv_crate(
        tokens in prop::collection::vec(token(), 0..120),
        pieces in pieces(),
    ) {
        same_as_reference(&tokens.concat(), &pieces);
    }

    #[test]
    fn csv_reader_reads_logs_as_the_csv_crate(text in log_text(), pieces in pieces()) {
        same_as_reference(&text, &pieces);
    }
}

/// How an input arrives: the sizes of successive reads (cycled), and whether a read fails
/// after the given number of reads.
type Pieces = (Vec<usize>, Option<usize>);

fn pieces() -> impl Strategy<Value = Pieces> {
    (
        prop_oneof![
            Just(vec![usize::MAX]),
            prop::collection::vec(1usize..40, 1..6),
        ],
        prop_oneof![3 => Just(None), 1 => (0usize..30).prop_map(Some)],
    )
}

/// `text` read in `pieces`.
struct Pieced<'a> {
    text: &'a [u8],
    sizes: &'a [usize],
    reads: usize,
    fail_after: Option<usize>,
}

impl std::io::Read for Pieced<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.fail_after == Some(self.reads) {
            return Err(std::io::Error::other("unplugged"));
        }
        let size = self.sizes[self.reads % self.sizes.len()];
        self.reads += 1;
        let n = size.min(buf.len()).min(self.text.len());
        buf[..n].copy_from_slice(&self.text[..n]);
        self.text = &self.text[n..];
        Ok(n)
    }
}

/// Everything a reader says about an input: the header's line or error, then each sample
/// (line, bits of u and y) or the error, and the last line read.
fn transcript<I>(opened: Result<I, IdError>, lines: impl Fn(&I) -> (u64, u64)) -> Vec<String>
where
    I: Iterator<Item = Result<ridge_id::csv::Sample, IdError>>,
{
    let mut out = Vec::new();
    match opened {
        Err(e) => out.push(format!("header error: {e}")),
        Ok(mut r) => {
            out.push(format!("header line {}", lines(&r).0));
            for s in r.by_ref() {
                out.push(match s {
                    Ok(s) => format!("{} {:x} {:x}", s.line, s.u.to_bits(), s.y.to_bits()),
                    Err(e) => format!("error: {e}"),
                });
            }
            out.push(format!("last line {}", lines(&r).1));
        }
    }
    out
}

fn same_as_reference(text: &[u8], (sizes, fail_after): &Pieces) {
    let input = || Pieced {
        text,
        sizes,
        reads: 0,
        fail_after: *fail_after,
    };
    let ours = transcript(CsvRecord::from_reader(input(), "F.csv"), |r| {
        (r.header_line(), r.line())
    });
    let csv = transcript(Reference::from_reader(input(), "F.csv"), |r| {
        (r.header_line(), r.line())
    });
    assert_eq!(ours, csv, "input {:?}", String::from_utf8_lossy(text));
}

/// A case the property above found: a last row longer than the 64 KiB buffer, without a
/// line end, and the input failing on the read after it ended (the `csv` crate never makes
/// that read: the row's bytes end the input).
#[test]
fn csv_reader_long_last_row_then_failing_input() {
    let mut text = b"t,u,y\n1,2,".to_vec();
    text.extend(std::iter::repeat_n(b'5', 68_081));
    for fail_after in [Some(1), Some(2), Some(3), None] {
        same_as_reference(&text, &(vec![usize::MAX], fail_after));
        same_as_reference(&text, &(vec![7, 30_000], fail_after));
    }
    text.push(b'\n');
    same_as_reference(&text, &(vec![usize::MAX], Some(2)));
}

/// One of `texts`, owned.
fn one_of(texts: &[&'static str]) -> impl Strategy<Value = String> + Clone {
    prop::sample::select(texts.to_vec()).prop_map(String::from)
}

/// A log as written by a program or a person: a header, rows of numbers, and now and then a
/// comment, a blank or empty line, a quoted cell, a `\r`, a wrong cell count, a non-ASCII
/// byte or a long line.
fn log_text() -> impl Strategy<Value = Vec<u8>> {
    let number = prop_oneof![
        4 => (-1e4f64..1e4).prop_map(|v| format!("{v:.4}")),
        2 => any::<f64>().prop_map(|v| v.to_string()),
        1 => (-99_999i64..99_999).prop_map(|v| v.to_string()),
        1 => any::<f64>().prop_map(|v| format!("{v:e}")),
        1 => (-1e6f64..1e6).prop_map(|v| format!("{v:E}")),
        8 => one_of(&[
            "1e-3", "1e400", "-2.5E+3", "3e", "123456789012345678901234567890", " 2.5 ",
            "\"3\"", "x", "",
        ]),
    ];
    let line = prop_oneof![
        12 => (number.clone(), number.clone(), number).prop_map(|(a, b, c)| format!("{a},{b},{c}\n")),
        9 => one_of(&[
            "\n", "  \t\n", "# note \"q\n", "  # note\n", "1,2,3\r\n", "1,2\n",
            "\"a\nb\",1,2\n", "1,\u{e9},2\n", "\u{feff}t,u,y\n",
        ]),
        1 => (1usize..70_000).prop_map(|n| format!("1,2,{}\n", "5".repeat(n))),
    ];
    let header = one_of(&[
        "t,u,y\n",
        "\u{feff}t,u,y\n",
        "# log\n\nt , \"u\" ,y\n",
        "u;y\n",
        "",
    ]);
    (header, prop::collection::vec(line, 0..40), any::<bool>()).prop_map(|(h, lines, cut)| {
        let mut text = h.into_bytes();
        for l in lines {
            text.extend_from_slice(l.as_bytes());
        }
        if cut && text.last() == Some(&b'\n') {
            text.pop();
        }
        text
    })
}

/// A finite value of any magnitude, or a level from a small set (constant runs, repeats).
fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => -10.0f64..10.0,
        1 => (-4i32..4).prop_map(f64::from),
        1 => (-300i32..300, -1.0f64..1.0).prop_map(|(e, m)| m * 10f64.powi(e)),
        1 => any::<f64>().prop_filter("finite", |v| v.is_finite()),
    ]
}

/// A record: random values, or a random plant-like response to steps (so that some
/// records fit well and the later stages run).
fn record() -> impl Strategy<Value = Vec<(f64, f64)>> {
    prop_oneof![
        prop::collection::vec((value(), value()), 0..160),
        (
            prop::collection::vec(-1.0f64..1.0, 2..40),
            -0.99f64..1.05,
            -3.0f64..3.0,
            1usize..12,
            prop_oneof![Just(1.0), Just(1e-4), Just(1e-150), Just(1e120)],
        )
            .prop_map(|(levels, a, b, hold, scale)| {
                let mut y = 0.0;
                let mut out = Vec::new();
                for l in levels {
                    for _ in 0..hold {
                        y = a * y + b * l;
                        out.push((l * scale, y * scale));
                    }
                }
                out
            }),
    ]
}

fn range(max: u8, lo: u8) -> impl Strategy<Value = OrderRange> {
    (lo..=max, lo..=max).prop_map(|(a, b)| OrderRange::new(a.min(b), a.max(b)))
}

fn grid() -> impl Strategy<Value = Grid> {
    (range(6, 1), range(6, 1), range(6, 0)).prop_map(|(p, q, d)| Grid { p, q, d })
}

fn method() -> impl Strategy<Value = Method<f64>> {
    prop_oneof![
        Just(Method::Ols),
        (1e-6f64..1e6).prop_map(|gamma| Method::Ridge(Ridge { gamma })),
        (1e-6f64..1e6, 0.0f64..0.999, 0.0f64..1e-2, 1u32..300).prop_map(
            |(gamma, beta, tol, max_iter)| Method::RidgeM(RidgeM {
                gamma,
                beta,
                tol,
                max_iter
            })
        ),
        Just(Method::AdaptiveLasso(AdaptiveLasso::default())),
    ]
}

fn criterion() -> impl Strategy<Value = Criterion> {
    prop::sample::select(Criterion::ALL.to_vec())
}

fn offset() -> impl Strategy<Value = Offset> {
    prop::sample::select(Offset::ALL.to_vec())
}

const HANG: Duration = Duration::from_secs(10);

proptest! {
    #![proptest_config(config(1000))]

    #[test]
    fn core_search_and_rls_on_arbitrary_finite_data(
        data in record(),
        val in record(),
        grid in grid(),
        method in method(),
        criterion in criterion(),
        offset in offset(),
        alpha in prop_oneof![0.0f64..50.0, Just(1e300)],
        lambda in prop_oneof![Just(1.0), 0.5f64..1.0, 1e-12f64..1e-3],
        delta in prop_oneof![Just(1e3), 1e-300f64..1e300],
    ) {
        let start = Instant::now();
        let gram = |d: &[(f64, f64)]| {
            let mut g = FloatGram::new();
            for &(u, y) in d {
                if g.push(u, y).is_err() {
                    break;
                }
            }
            g
        };
        let (g, gv) = (gram(&data), gram(&val));
        if let (Ok(n), nv) = (g.normal::<f64>(Scale::UNIT), gv.normal::<f64>(Scale::UNIT)) {
            let search = Search { grid, offset, criterion, alpha, method, prune: true };
            let nv = nv.ok();
            let v = if criterion == Criterion::Validation { nv.as_ref() } else { None };
            if let Ok(sel) = search.run(&n, v) {
                let s = sel.structure();
                prop_assert!(grid.p.min <= s.p && s.p <= grid.p.max);
                prop_assert!(grid.q.min <= s.q && s.q <= grid.q.max);
                prop_assert!(grid.d.min <= s.d && s.d <= grid.d.max);
                prop_assert!(sel.score.is_finite());
                // The model scores on the data without panicking, whatever it predicts.
                let mut ev = Evaluation::new(sel.fit.model());
                for &(u, y) in &data {
                    ev.push(u, y);
                }
                let _ = (ev.one_step(), ev.free_run());
                if let Ok(mut rls) = Rls::new(s, offset, lambda, delta) {
                    for &(u, y) in &data {
                        if rls.update(u, y).is_err() {
                            break;
                        }
                    }
                    let _ = rls.model();
                }
            }
        }
        prop_assert!(start.elapsed() < HANG, "{:?}", start.elapsed());
    }
}

fn write_record(name: &str, data: &[(f64, f64)]) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("ridge_id_fuzz");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    let mut f = std::io::BufWriter::new(std::fs::File::create(&p).unwrap());
    writeln!(f, "t,u,y").unwrap();
    for (i, (u, y)) in data.iter().enumerate() {
        // `{:?}` prints the shortest text that reads back to the same f64.
        writeln!(f, "{i},{u:?},{y:?}").unwrap();
    }
    f.flush().unwrap();
    p
}

fn options() -> impl Strategy<Value = (MethodKind, Criterion, Offset, Option<Structure>, Grid)> {
    (
        prop::sample::select(MethodKind::ALL.to_vec()),
        prop::sample::select(vec![
            Criterion::Aic,
            Criterion::Bic,
            Criterion::Paper,
            Criterion::Validation,
        ]),
        offset(),
        prop::option::of(
            (1u8..=6, 1u8..=6, 0u8..=6).prop_map(|(p, q, d)| Structure::new(p, q, d).unwrap()),
        ),
        grid(),
    )
}

proptest! {
    #![proptest_config(config(500))]

    #[test]
    fn the_pipeline_on_arbitrary_finite_records(
        data in record(),
        val in prop::option::of(record()),
        (method, criterion, offset, structure, grid) in options(),
        gamma in prop_oneof![Just(1000.0), 1e-300f64..1e300],
        beta in prop_oneof![Just(0.01), 0.0f64..0.999_999],
        tol in prop_oneof![Just(1e-6), 0.0f64..1.0],
        max_iter in 1u32..400,
        lambda in prop_oneof![Just(1.0), 1e-9f64..1.0],
    ) {
        let start = Instant::now();
        let mut opts = Options::new(write_record("est.csv", &data));
        opts.validate = val.as_ref().map(|v| write_record("val.csv", v));
        opts.method = method;
        opts.criterion = if opts.validate.is_none() && criterion == Criterion::Validation {
            Criterion::Aic
        } else {
            criterion
        };
        opts.offset = offset;
        opts.structure = structure;
        opts.grid = grid;
        opts.hyper.gamma = gamma;
        opts.hyper.beta = beta;
        opts.hyper.tol = tol;
        opts.hyper.max_iter = max_iter;
        opts.hyper.lambda = lambda;
        match run(&opts) {
            Ok(report) => {
                let json: serde_json::Value =
                    serde_json::from_str(&report.to_json_string()).unwrap();
                prop_assert!(json["warnings"].is_array());
                // The warnings agree with the report's own figures.
                let negative =
                    |f: &ridge_id::Figures| f.fit_free_run.is_nan() || f.fit_free_run < 0.0;
                let want = negative(&report.estimation)
                    || report.validation.as_ref().is_some_and(negative);
                let got = report.warnings.iter().any(|w| w.kind == WarningKind::NegativeFit);
                prop_assert_eq!(got, want, "{:?}", report.warnings);
                let _ = report.to_text();
            }
            Err(e) => {
                let m = e.to_string();
                prop_assert!(!m.contains('\n'), "{}", m);
                prop_assert!(m.len() <= MESSAGE_MAX + 200, "{} bytes: {}", m.len(), m);
            }
        }
        prop_assert!(start.elapsed() < HANG, "{:?}", start.elapsed());
    }
}
