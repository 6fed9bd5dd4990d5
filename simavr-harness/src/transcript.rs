//! The firmware's UART transcript: its bytes split into lines, each with the core cycle of its
//! terminator. The lines themselves are parsed by the firmware's own parser
//! (`ridge_pump_firmware::lines`, beside their writer).

use ridge_pump_firmware::lines::ParsedLine;

/// One UART line with the core cycle at which its terminating `\n` was sent.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Core cycle of the line end.
    pub cycle: u64,
    /// Text without the line terminator.
    pub text: String,
}

impl Line {
    /// The line split into keyword, words and fields (the firmware's parser).
    pub fn parsed(&self) -> ParsedLine {
        ParsedLine::parse(&self.text)
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
    fn splits_lines_at_their_terminator() {
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
