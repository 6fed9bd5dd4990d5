//! Reads the PWM duty the firmware drives from the ATmega2560's 16-bit timers (1, 3, 4, 5)
//! straight from their registers: waveform mode → TOP, compare-output mode, OCR, clock select
//! and the pin's data direction. Nothing here depends on how the firmware sets them up.
//!
//! Register addresses, bits and modes are those of the ATmega640/1280/1281/2560/2561
//! datasheet: chapter "16-bit Timer/Counter (Timer/Counter 1, 3, 4, and 5)" (TCCRnA/B, OCRnX,
//! ICRn, compare-output modes, Table 17-2 "Waveform Generation Mode Bit Description"), the
//! "Register Summary" (data-space addresses) and the "I/O-Ports" chapter (OCnX pins, DDRx).

use crate::machine::Machine;

/// One output-compare channel of a 16-bit timer: timer 1, 3, 4 or 5, channel 'A', 'B' or 'C'.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Channel {
    /// Timer number.
    pub timer: u8,
    /// Channel letter.
    pub channel: char,
}

impl std::fmt::Display for Channel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (port, bit) = self.pin();
        write!(f, "OC{}{} (P{}{})", self.timer, self.channel, port, bit)
    }
}

/// Register block of a 16-bit timer on the ATmega2560 (data-space addresses).
#[derive(Clone, Copy, Debug)]
struct Regs {
    tccra: u16,
    tccrb: u16,
    icr: u16,
    ocra: u16,
    /// Port letter of the OCnA/B/C pins and the bit of OCnA (B and C follow).
    port: char,
    bit_a: u8,
}

fn regs(timer: u8) -> Option<Regs> {
    Some(match timer {
        1 => Regs {
            tccra: 0x80,
            tccrb: 0x81,
            icr: 0x86,
            ocra: 0x88,
            port: 'B',
            bit_a: 5,
        },
        3 => Regs {
            tccra: 0x90,
            tccrb: 0x91,
            icr: 0x96,
            ocra: 0x98,
            port: 'E',
            bit_a: 3,
        },
        4 => Regs {
            tccra: 0xA0,
            tccrb: 0xA1,
            icr: 0xA6,
            ocra: 0xA8,
            port: 'H',
            bit_a: 3,
        },
        5 => Regs {
            tccra: 0x120,
            tccrb: 0x121,
            icr: 0x126,
            ocra: 0x128,
            port: 'L',
            bit_a: 3,
        },
        _ => return None,
    })
}

/// Data-space address of `DDRx` for a port letter.
pub fn ddr_addr(port: char) -> Option<u16> {
    Some(match port {
        'A' => 0x21,
        'B' => 0x24,
        'C' => 0x27,
        'D' => 0x2A,
        'E' => 0x2D,
        'F' => 0x30,
        'G' => 0x33,
        'H' => 0x101,
        'J' => 0x104,
        'K' => 0x107,
        'L' => 0x10A,
        _ => return None,
    })
}

/// What a channel drives at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Duty {
    /// Duty as a fraction 0..1 of the pin's high time.
    pub fraction: f64,
    /// Raw compare value.
    pub ocr: u16,
    /// Timer TOP.
    pub top: u16,
}

impl Channel {
    /// All twelve 16-bit channels.
    pub fn all() -> impl Iterator<Item = Channel> {
        [1u8, 3, 4, 5].into_iter().flat_map(|timer| {
            ['A', 'B', 'C']
                .into_iter()
                .map(move |channel| Channel { timer, channel })
        })
    }

    fn index(&self) -> u16 {
        match self.channel {
            'A' => 0,
            'B' => 1,
            _ => 2,
        }
    }

    /// Port and bit of the OCnX pin.
    pub fn pin(&self) -> (char, u8) {
        let r = regs(self.timer).expect("16-bit timer");
        (r.port, r.bit_a + self.index() as u8)
    }

    /// Compare-output mode bits COMnX1:0 (0 = disconnected, 2 = non-inverting, 3 = inverting).
    pub fn com(&self, m: &Machine) -> u8 {
        let r = regs(self.timer).expect("16-bit timer");
        (m.data(r.tccra) >> (6 - 2 * self.index())) & 3
    }

    /// Data-space address of `TCCRnA` (compare-output mode of all three channels).
    pub fn tccra_addr(&self) -> u16 {
        regs(self.timer).expect("16-bit timer").tccra
    }

    /// Data-space address of `OCRnX` (low byte).
    pub fn ocr_addr(&self) -> u16 {
        regs(self.timer).expect("16-bit timer").ocra + 2 * self.index()
    }

    /// The duty this channel puts on its pin now, or `None` when the timer does not drive the
    /// pin with PWM (compare output disconnected, non-PWM mode, clock stopped, pin an input).
    pub fn duty(&self, m: &Machine) -> Option<Duty> {
        let r = regs(self.timer)?;
        let a = m.data(r.tccra);
        let b = m.data(r.tccrb);
        let com = self.com(m);
        let wgm = (a & 3) | ((b >> 1) & 0x0C);
        let cs = b & 7;
        let (port, bit) = self.pin();
        let ddr = m.data(ddr_addr(port)?);
        if com == 0 || cs == 0 || ddr & (1 << bit) == 0 {
            return None;
        }
        let icr = m.data16(r.icr);
        let ocra = m.data16(r.ocra);
        // (TOP, fast PWM?) per WGM mode (datasheet table 17-2).
        let (top, fast) = match wgm {
            1 => (0xFF, false),
            2 => (0x1FF, false),
            3 => (0x3FF, false),
            5 => (0xFF, true),
            6 => (0x1FF, true),
            7 => (0x3FF, true),
            8 | 10 => (icr, false),
            9 | 11 => (ocra, false),
            14 => (icr, true),
            15 => (ocra, true),
            _ => return None, // normal, CTC: not PWM
        };
        if top == 0 {
            return None;
        }
        let ocr = m.data16(self.ocr_addr()).min(top);
        // Fast PWM non-inverting: high for OCR+1 of TOP+1 counts (a one-count spike at OCR = 0,
        // which a blower does not see: treated as 0). Phase correct: OCR/TOP.
        let mut fraction = if fast {
            if ocr == 0 {
                0.0
            } else {
                f64::from(ocr + 1) / (f64::from(top) + 1.0)
            }
        } else {
            f64::from(ocr) / f64::from(top)
        };
        if com == 3 {
            fraction = 1.0 - fraction;
        }
        Some(Duty {
            fraction: fraction.clamp(0.0, 1.0),
            ocr,
            top,
        })
    }

    /// The first channel that currently drives its pin with PWM, if any.
    pub fn find_active(m: &Machine) -> Option<Channel> {
        Channel::all().find(|c| c.duty(m).is_some())
    }
}
