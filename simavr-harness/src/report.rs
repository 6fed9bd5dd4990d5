//! Parsing of the firmware's report lines (`firmware/src/event.rs`): a keyword, then words
//! and `key=value` fields separated by single spaces, e.g.
//! `ID p=2 q=2 d=3 off=1 theta=1.2,-0.3 phi=0.1,0.2 c=-0.1 score=-1234.5 eval=14/252`.

use std::collections::BTreeMap;

/// One UART line with the core cycle at which its terminating `\n` was sent.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Core cycle of the line end.
    pub cycle: u64,
    /// Text without the line terminator.
    pub text: String,
}

impl Line {
    /// The line split into keyword, words and fields.
    pub fn parsed(&self) -> ParsedLine {
        ParsedLine::parse(&self.text)
    }
}

/// One report line split into its keyword, its bare words and its `key=value` fields (no
/// cycle stamp: that stays with the [`Line`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParsedLine {
    /// First word, e.g. `ID`, `FAULT`, `STACK`.
    pub keyword: String,
    /// Words without `=`, after the keyword (e.g. `A-Multistep`, `persist`, `stall`).
    pub words: Vec<String>,
    /// `key=value` fields.
    pub fields: BTreeMap<String, String>,
}

impl ParsedLine {
    /// Splits `text` on whitespace.
    pub fn parse(text: &str) -> Self {
        let mut it = text.split_whitespace();
        let keyword = it.next().unwrap_or("").to_string();
        let mut words = Vec::new();
        let mut fields = BTreeMap::new();
        for w in it {
            match w.split_once('=') {
                Some((k, v)) => {
                    fields.insert(k.to_string(), v.to_string());
                }
                None => words.push(w.to_string()),
            }
        }
        Self {
            keyword,
            words,
            fields,
        }
    }

    /// Raw text of field `key`.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.fields.get(key).map(String::as_str)
    }

    /// Field `key` as a number (the part before any `<`, `/`, `%`).
    pub fn num(&self, key: &str) -> Option<f64> {
        let v = self.get(key)?;
        let v = v.split(['<', '/', '%']).next()?;
        v.parse().ok()
    }

    /// Field `key` as an integer.
    pub fn int(&self, key: &str) -> Option<i64> {
        let v = self.get(key)?;
        v.split(['<', '/', '%']).next()?.parse().ok()
    }

    /// Field `key` as a comma-separated list of numbers (empty field → empty list).
    pub fn list(&self, key: &str) -> Option<Vec<f64>> {
        let v = self.get(key)?;
        if v.is_empty() || v == "-" {
            return Some(Vec::new());
        }
        v.split(',').map(|x| x.parse().ok()).collect()
    }

    /// `a/b` field as a pair (e.g. `eval=14/252`, `attempt=1/3`).
    pub fn ratio(&self, key: &str) -> Option<(i64, i64)> {
        let (a, b) = self.get(key)?.split_once('/')?;
        Some((a.parse().ok()?, b.parse().ok()?))
    }

    /// Whether the line contains the bare word `w`.
    pub fn has_word(&self, w: &str) -> bool {
        self.words.iter().any(|x| x == w)
    }
}

/// Splits a byte stream into lines (`\n`-terminated, `\r` dropped), keeping the cycle of
/// each terminator.
#[derive(Clone, Debug, Default)]
pub struct LineSplitter {
    buf: Vec<u8>,
}

impl LineSplitter {
    /// Feeds one byte; returns a completed line.
    pub fn push(&mut self, cycle: u64, byte: u8) -> Option<Line> {
        match byte {
            b'\n' => {
                let text = String::from_utf8_lossy(&self.buf).into_owned();
                self.buf.clear();
                Some(Line { cycle, text })
            }
            b'\r' => None,
            b => {
                self.buf.push(b);
                None
            }
        }
    }

    /// The incomplete last line, if any.
    pub fn pending(&self) -> &[u8] {
        &self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_event_lines() {
        let r = ParsedLine::parse(
            "ID p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000,-1.25 c=-0.125000 score=-1234.5 eval=14/252 skip=0 iters=200",
        );
        assert_eq!(r.keyword, "ID");
        assert_eq!(r.int("p"), Some(1));
        assert_eq!(r.list("phi"), Some(vec![6.5, -1.25]));
        assert_eq!(r.ratio("eval"), Some((14, 252)));
        let f = ParsedLine::parse("FAULT stall duty=45.00 flow=0.125");
        assert!(f.has_word("stall"));
        assert_eq!(f.num("duty"), Some(45.0));
        let j = ParsedLine::parse("REJECT fit=42.1<70.0 attempt=1/3");
        assert_eq!(j.num("fit"), Some(42.1));
        let mut s = LineSplitter::default();
        let mut out = Vec::new();
        for (i, b) in b"A x=1\r\nB\n".iter().enumerate() {
            out.extend(s.push(i as u64, *b));
        }
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].text, "A x=1");
        assert_eq!(out[1].cycle, 8);
    }
}
