//! The USART1 transcript: one [`Line`] per report line the image printed, with when its bytes
//! went out; split into keyword, words and `key=value` fields by the firmware's own parser
//! (`ridge_pump_firmware::lines`, beside the lines' writer).

use ridge_pump_firmware::lines::ParsedLine;

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
