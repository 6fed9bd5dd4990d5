//! The cells of a CSV row, shared by both readers: the [`Sample`] a row gives and the
//! [`Header`] that places its columns, the finite numbers a cell may hold ([`number`],
//! [`decimal`]), the lookup of a column by name, and how a cell is quoted in a message.

use std::path::Path;

use crate::error::IdError;

/// Longest line accepted, in bytes (1 MiB): a row of `t,u,y` is a few dozen bytes.
pub const MAX_LINE: u64 = 1 << 20;

/// Most characters of a cell or a header quoted in an error message.
pub const QUOTE_CHARS: usize = 80;

/// Bytes of each read, [`CsvRecord`](super::CsvRecord)'s and the `csv` crate's (64 KiB): it reads a
/// line itself when it finds its end within this many bytes.
pub(super) const BUFFER: usize = 1 << 16;

/// `text` as a quoted string for a message: `"abc"` (Rust string syntax, so control
/// characters are escaped), cut to its first [`QUOTE_CHARS`] characters and marked
/// `"abc…" (1234 characters)` when longer.
pub fn quote(text: &str) -> String {
    let total = text.chars().count();
    if total <= QUOTE_CHARS {
        return format!("{text:?}");
    }
    let head: String = text.chars().take(QUOTE_CHARS).collect();
    let mut q = format!("{head:?}");
    q.insert(q.len() - 1, '…');
    format!("{q} ({total} characters)")
}

/// One `(u_t, y_t)` sample and the line it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// 1-based line number in the file.
    pub line: u64,
    /// Input `u_t` (the unit of the record's `u` column).
    pub u: f64,
    /// Output `y_t` (the unit of the record's `y` column).
    pub y: f64,
}

/// Where the `u` and `y` columns are, from the header.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Header {
    /// Line of the header.
    pub(super) line: u64,
    /// Cells a row must have.
    pub(super) columns: usize,
    pub(super) u_col: usize,
    pub(super) y_col: usize,
}

/// The sample of a row of `count` cells whose `u` and `y` cells are `u` and `y` (`None`
/// when the row is too short), else the error naming line `at`.
pub(super) fn sample(
    path: &Path,
    at: u64,
    h: &Header,
    count: usize,
    u: Option<&str>,
    y: Option<&str>,
) -> Result<Sample, IdError> {
    let (Some(u), Some(y), true) = (u, y, count == h.columns) else {
        return Err(IdError::line(
            path,
            at,
            format!(
                "expected {} columns as in the header (line {}), found {count}",
                h.columns, h.line
            ),
        ));
    };
    Ok(Sample {
        line: at,
        u: number(unquote(u), "u", path, at)?,
        y: number(unquote(y), "y", path, at)?,
    })
}

/// The columns `u` and `y` among the header's `names` (unquoted), else the error naming
/// line `line` of `path`.
pub(super) fn header_columns(
    names: &[&str],
    path: &Path,
    line: u64,
) -> Result<(usize, usize), IdError> {
    let find = |want: &str| -> Result<usize, IdError> {
        column(names, want, path, line)?.ok_or_else(|| {
            let other_separator = matches!(names, [one] if one.contains([';', '\t']));
            let hint = if other_separator {
                " (columns must be separated by commas)"
            } else {
                ""
            };
            IdError::line(
                path,
                line,
                format!(
                    "header has no column named {want} (found: {}){hint}",
                    found(names)
                ),
            )
        })
    };
    Ok((find("u")?, find("y")?))
}

/// The error of an input without a header, at line `line`.
pub(super) fn empty_file(path: &Path, line: u64) -> IdError {
    IdError::line(
        path,
        line,
        "empty file: expected a header row naming the columns u and y",
    )
}

/// The index of the header column `want` among `names` (`None`: there is none); two columns
/// of that name are an error on line `line` of `path`.
pub(crate) fn column(
    names: &[&str],
    want: &str,
    path: &Path,
    line: u64,
) -> Result<Option<usize>, IdError> {
    let mut hits = names.iter().enumerate().filter(|(_, n)| **n == want);
    match (hits.next(), hits.next()) {
        (Some(_), Some(_)) => Err(IdError::line(
            path,
            line,
            format!("header has two columns named {want}"),
        )),
        (hit, _) => Ok(hit.map(|(i, _)| i)),
    }
}

/// The finite number in the (unquoted) cell `s` of column `column`, else an error on line
/// `line` of `path` naming the cell.
pub(crate) fn number(s: &str, column: &str, path: &Path, line: u64) -> Result<f64, IdError> {
    if s.is_empty() {
        return Err(IdError::line(
            path,
            line,
            format!("column {column}: empty cell"),
        ));
    }
    if let Some(v) = decimal(s.as_bytes()) {
        return Ok(v);
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(IdError::line(
            path,
            line,
            format!("column {column}: {} is not a finite number", quote(s)),
        )),
        Err(_) => Err(IdError::line(
            path,
            line,
            format!("column {column}: {} is not a number", quote(s)),
        )),
    }
}

/// The column names of a header for a message: `t, u`, cut to about [`QUOTE_CHARS`]
/// characters (`a, b, … (1234 columns)` when longer).
pub(crate) fn found(names: &[&str]) -> String {
    let all = names.join(", ");
    if all.chars().count() <= QUOTE_CHARS {
        return all;
    }
    let head: String = all.chars().take(QUOTE_CHARS).collect();
    format!("{head}… ({} columns)", names.len())
}

/// A cell without surrounding blanks and double quotes. The `csv` reader has removed the
/// quotes of a cell that starts with one; this also takes them off ` "u" ` (blanks outside
/// the quotes, which the reader keeps as text).
pub(crate) fn unquote(cell: &str) -> &str {
    let t = cell.trim();
    t.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .map(str::trim)
        .unwrap_or(t)
}

/// `s` read as a number when it is `-?d+(.d*)?` with at most 19 digits whose value is
/// at most 2⁵³ — `w / 10^k` with both exact in `f64`, so one correctly rounded division
/// gives the correctly rounded value, exactly what `str::parse::<f64>` gives — else `None`.
#[inline]
pub(super) fn decimal(s: &[u8]) -> Option<f64> {
    match decimal_prefix(s) {
        (Some(v), used) if used == s.len() => Some(v),
        _ => None,
    }
}

/// The longest prefix of `s` of the form `-?d+(.d*)?` and the bytes it takes, with its
/// value when [`decimal`] reads it (at most 19 digits, at most 2⁵³ without the point).
#[inline(always)]
pub(super) fn decimal_prefix(s: &[u8]) -> (Option<f64>, usize) {
    const POW10: [f64; 20] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19,
    ];
    let negative = s.first() == Some(&b'-');
    let mut i = usize::from(negative);
    let mut w: u64 = 0;
    // Wrapping: more than 19 digits are refused below, whatever `w` became.
    let mut digits = |i: &mut usize| {
        let start = *i;
        while let Some(&b) = s.get(*i) {
            let d = b.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            w = w.wrapping_mul(10).wrapping_add(u64::from(d));
            *i += 1;
        }
        *i - start
    };
    let whole = digits(&mut i);
    if whole == 0 {
        return (None, 0);
    }
    let mut fraction = 0;
    if s.get(i) == Some(&b'.') {
        i += 1;
        fraction = digits(&mut i);
    }
    if whole + fraction > 19 || w > 1 << 53 {
        return (None, i);
    }
    let v = w as f64 / POW10[fraction];
    (Some(if negative { -v } else { v }), i)
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config {
            cases: 20_000,
            failure_persistence: None,
            ..Default::default()
        })]

        /// The plain decimal reading is `str::parse` wherever it answers: on decimals of
        /// every length and precision, with leading zeros, and on strings that only look
        /// like them.
        #[test]
        fn decimal_is_str_parse(
            sign in proptest::prop_oneof![proptest::strategy::Just(""), proptest::strategy::Just("-"), proptest::strategy::Just("+")],
            int in "[0-9]{0,21}",
            dot in proptest::bool::ANY,
            frac in "[0-9]{0,21}",
            tail in proptest::prop_oneof![4 => proptest::strategy::Just(String::new()), 1 => "[eE.x -]{1,2}"],
        ) {
            let text = format!("{sign}{int}{}{frac}{tail}", if dot { "." } else { "" });
            if let Some(v) = decimal(text.as_bytes()) {
                let parsed: f64 = text.parse().unwrap();
                proptest::prop_assert_eq!(v.to_bits(), parsed.to_bits(), "{}", text);
            }
        }

        #[test]
        fn decimal_is_str_parse_on_printed_values(v in proptest::num::f64::NORMAL, digits in 0usize..18) {
            let text = format!("{v:.digits$}");
            if let Some(w) = decimal(text.as_bytes()) {
                proptest::prop_assert_eq!(w.to_bits(), text.parse::<f64>().unwrap().to_bits(), "{}", text);
            }
        }
    }

    #[test]
    fn decimal_answers_the_common_forms_only() {
        let yes = [
            "0",
            "-0",
            "5.",
            "0.0001",
            "-12.3456",
            "9007199254740992",
            "0.1234567890123456",
        ];
        for t in yes {
            assert_eq!(
                decimal(t.as_bytes()).map(f64::to_bits),
                Some(t.parse::<f64>().unwrap().to_bits()),
                "{t}"
            );
        }
        assert_eq!(decimal(b"-0").map(f64::is_sign_negative), Some(true));
        for t in [
            "",
            "-",
            ".5",
            "+1",
            "1e3",
            "1.2.3",
            "9007199254740993",
            "1234567890123456789",
            "12345678901234567890",
            " 1",
            "inf",
            "NaN",
        ] {
            assert_eq!(decimal(t.as_bytes()), None, "{t}");
        }
    }
}
