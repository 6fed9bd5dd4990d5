//! The firmware's report lines (`firmware/src/event.rs`) as the harness reads them: a keyword,
//! then words and `key=value` fields separated by single spaces. The minimum the runner and
//! the tests need, until the firmware's shared host-side parser takes its place.

use std::collections::BTreeMap;

use crate::periph::Time;

/// One line from USART1.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Text without the terminator.
    pub text: String,
    /// When its first byte's frame started, ps.
    pub start: Time,
    /// Instructions executed when the firmware wrote its first byte.
    pub start_instr: u64,
    /// When its `\n` frame ended, ps.
    pub end: Time,
}

impl Line {
    /// The line split into keyword, words and fields.
    pub fn parsed(&self) -> ParsedLine {
        ParsedLine::parse(&self.text)
    }

    /// The first word.
    pub fn keyword(&self) -> &str {
        self.text.split_whitespace().next().unwrap_or("")
    }
}

/// A report line split into keyword, bare words and `key=value` fields.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParsedLine {
    /// First word (`ID`, `ACCEPT`, …).
    pub keyword: String,
    /// Words without `=` after the keyword.
    pub words: Vec<String>,
    /// `key=value` fields.
    pub fields: BTreeMap<String, String>,
}

impl ParsedLine {
    /// Splits `text` on whitespace.
    pub fn parse(text: &str) -> Self {
        let mut it = text.split_whitespace();
        let keyword = it.next().unwrap_or("").to_string();
        let mut p = ParsedLine {
            keyword,
            ..Self::default()
        };
        for w in it {
            match w.split_once('=') {
                Some((k, v)) => {
                    p.fields.insert(k.to_string(), v.to_string());
                }
                None => p.words.push(w.to_string()),
            }
        }
        p
    }

    /// Field `key` as text.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.fields.get(key).map(String::as_str)
    }

    /// Field `key` as a number (the part before any `<`, `/`, `%`).
    pub fn num(&self, key: &str) -> Option<f64> {
        self.get(key)?.split(['<', '/', '%']).next()?.parse().ok()
    }

    /// Field `key` as an integer.
    pub fn int(&self, key: &str) -> Option<i64> {
        self.get(key)?.split(['<', '/', '%']).next()?.parse().ok()
    }

    /// Field `key` as a comma-separated list of numbers (`-` or empty: none).
    pub fn list(&self, key: &str) -> Option<Vec<f64>> {
        let v = self.get(key)?;
        if v.is_empty() || v == "-" {
            return Some(Vec::new());
        }
        v.split(',').map(|x| x.parse().ok()).collect()
    }

    /// An `a/b` field.
    pub fn ratio(&self, key: &str) -> Option<(i64, i64)> {
        let (a, b) = self.get(key)?.split_once('/')?;
        Some((a.parse().ok()?, b.parse().ok()?))
    }

    /// Whether the bare word `w` is on the line.
    pub fn has_word(&self, w: &str) -> bool {
        self.words.iter().any(|x| x == w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_fields_words_and_lists() {
        let r = ParsedLine::parse("ID p=1 q=2 d=3 off=1 theta=0.5 phi=6.5,-1.25 eval=14/252");
        assert_eq!(r.keyword, "ID");
        assert_eq!(r.int("q"), Some(2));
        assert_eq!(r.list("phi"), Some(vec![6.5, -1.25]));
        assert_eq!(r.ratio("eval"), Some((14, 252)));
        let f = ParsedLine::parse("REJECT fit=42.1<70.0 attempt=1/3");
        assert_eq!(f.num("fit"), Some(42.1));
        assert!(ParsedLine::parse("FAULT stall duty=45.00").has_word("stall"));
    }
}
