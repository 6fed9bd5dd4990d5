//! The console's transcript as both harnesses' tests read it: which lines answer a command
//! ([`is_answer`]), the log rows (`t,u,y,r,phase`, [`log_rows`]) and whether they are one per
//! tick ([`consecutive`]), the controller's three `RST` lines ([`rst_polynomials`]), and the
//! `ridge-id` arguments that check the pump's own identification from its log
//! ([`device_argv`]). Each harness's tests compare these with their bench (frames served, duty
//! on the pin) and keep their assertions.

use std::path::Path;

use ridge_id::capture::{classify, Kind};
use ridge_pump_firmware::lines::ParsedLine;

/// An answer to a console command (not a log row, not a periodic report).
pub fn is_answer(text: &str) -> bool {
    ["OK ", "ERR ", "STATUS ", "MODEL ", "MAP ", "RST "]
        .iter()
        .any(|k| text.starts_with(k))
        || text == ridge_pump_firmware::console::LOG_HEADER
}

/// One log row (`t,u,y,r,phase`) and its line index.
#[derive(Clone, Debug, PartialEq)]
pub struct LogRow {
    /// Index of the line in the transcript.
    pub line: usize,
    /// Ticks (`t` · 100, `t` in s).
    pub tick: i64,
    /// Duty, fraction 0..1.
    pub u: f64,
    /// Reading, slm.
    pub y: f64,
    /// Setpoint, slm (`None`: empty, no setpoint).
    pub r: Option<f64>,
    /// Phase (`excite`, `run`, …).
    pub phase: String,
}

/// The log rows among `texts` (lines `first`, `first + 1`, … of a transcript; the lines
/// `ridge_id::capture::classify` calls rows); `Err` is a row whose fields do not parse.
pub fn log_rows<'a>(
    texts: impl IntoIterator<Item = &'a str>,
    first: usize,
) -> Result<Vec<LogRow>, String> {
    texts
        .into_iter()
        .enumerate()
        .filter(|(_, t)| classify(t.as_bytes()) == Kind::Row)
        .map(|(i, t)| {
            let c: Vec<&str> = t.split(',').collect();
            let field = |k: usize| c.get(k).copied().ok_or_else(|| t.to_string());
            let num = |k: usize| field(k)?.parse::<f64>().map_err(|_| t.to_string());
            let r = field(3)?;
            Ok(LogRow {
                line: first + i,
                tick: (num(0)? * 100.0).round() as i64,
                u: num(1)?,
                y: num(2)?,
                r: if r.is_empty() { None } else { Some(num(3)?) },
                phase: field(4)?.to_string(),
            })
        })
        .collect()
}

/// The first of `rows` if they are consecutive ticks (`t` steps of 0.01 s); `Err` says where
/// they are not, or that there are none.
pub fn consecutive(rows: &[LogRow]) -> Result<&LogRow, String> {
    let first = rows.first().ok_or("no log rows")?;
    for w in rows.windows(2) {
        if w[1].tick != w[0].tick + 1 {
            return Err(format!(
                "rows not consecutive: t {} then {} (line {})",
                w[0].tick, w[1].tick, w[1].line
            ));
        }
    }
    Ok(first)
}

/// Rising crossings of `level` in `x` (sample indices), and their mean spacing (samples; NaN
/// for fewer than two).
pub fn rising_crossings(x: &[f64], level: f64) -> (Vec<usize>, f64) {
    let ups: Vec<usize> = (1..x.len())
        .filter(|&i| x[i - 1] < level && x[i] >= level)
        .collect();
    let p = if ups.len() >= 2 {
        (ups[ups.len() - 1] - ups[0]) as f64 / (ups.len() - 1) as f64
    } else {
        f64::NAN
    };
    (ups, p)
}

/// The controller's polynomials `R`, `S`, `T` from the three lines after `MODEL`'s `MAP` line
/// (`RST r=…`, `RST s=…`, `RST t=…`; a missing line reads as empty); `Err` names the first
/// line that is not an `RST` line or lacks its list.
pub fn rst_polynomials(lines: [Option<ParsedLine>; 3]) -> Result<[Vec<f64>; 3], String> {
    let mut out: [Vec<f64>; 3] = Default::default();
    for ((l, name), o) in lines.into_iter().zip(["r", "s", "t"]).zip(&mut out) {
        let l = l.unwrap_or_default();
        if l.keyword != "RST" {
            return Err(format!(
                "{:?} where an RST line ({name}=) was due",
                l.keyword
            ));
        }
        *o = l.list(name).ok_or_else(|| format!("no {name}="))?;
    }
    Ok(out)
}

/// The options docs/boards.md and docs/real-logs.md give for checking the pump's own
/// identification from its log (`capture`, as `ridge-id capture` writes it): `--device` (the
/// firmware's search settings) with the segment options spelled out, and the JSON report.
/// `None` when the path is not UTF-8.
pub fn device_argv(capture: &Path) -> Option<Vec<String>> {
    let path = capture.to_str()?;
    Some(
        [
            "ridge-id",
            "identify",
            "--input",
            path,
            "--device",
            "--phase",
            "excite",
            "--attempt",
            "1",
            "--operating-point",
            "log",
            "--json",
        ]
        .map(String::from)
        .into(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows are parsed field by field (empty setpoint: none), other lines skipped, and the
    /// line indices count from `first`.
    #[test]
    fn log_rows_are_parsed_and_counted_from_first() {
        let t = [
            "OK log",
            "0.01,0.3000,12.50000,,excite",
            "# x",
            "0.02,0.3100,12.6,40.0,run",
        ];
        let rows = log_rows(t, 7).expect("rows");
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].line, rows[0].tick, rows[0].r), (8, 1, None));
        assert_eq!((rows[1].line, rows[1].tick, rows[1].r), (10, 2, Some(40.0)));
        assert_eq!(
            (rows[1].u, rows[1].y, rows[1].phase.as_str()),
            (0.31, 12.6, "run")
        );
        assert_eq!(consecutive(&rows).map(|r| r.line), Ok(8));
        let gap = log_rows(["0.01,0.3,1,,run", "0.03,0.3,1,,run"], 0).expect("rows");
        assert!(consecutive(&gap).is_err());
        assert!(consecutive(&[]).is_err());
    }

    /// A square wave of period 4 samples crosses its middle upwards every 4 samples.
    #[test]
    fn rising_crossings_of_a_square_wave() {
        let x: Vec<f64> = (0..20).map(|i| if i % 4 < 2 { 0.0 } else { 1.0 }).collect();
        let (ups, p) = rising_crossings(&x, 0.5);
        assert_eq!(ups, vec![2, 6, 10, 14, 18]);
        assert_eq!(p, 4.0);
        assert!(rising_crossings(&[0.0, 1.0], 0.5).1.is_nan());
    }
}
