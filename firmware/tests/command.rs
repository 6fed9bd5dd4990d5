//! The console's command grammar (`ridge_pump_firmware::command`): every command and its
//! fields, every refusal, numbers against a reference conversion, and arbitrary bytes
//! (deterministic byte-level fuzzing: no panic, every line answers).

use ridge_pump_firmware::command::{
    parse, Command, CommandError, Line, ProfileArgs, VentArgs, LOST, MAX_LINE,
};
use ridge_pump_firmware::setpoint::Shape;

#[test]
fn every_command_parses() {
    let profile = |shape| ProfileArgs {
        shape,
        peak: None,
        bias: None,
        rate: None,
        ie: None,
        rise: None,
    };
    let cases: &[(&str, Command)] = &[
        ("STATUS", Command::Status),
        ("status", Command::Status),
        ("  Stop  ", Command::Stop),
        ("START\r", Command::Start),
        ("SET flow=25", Command::Set(25_000)),
        ("set FLOW=-0.5", Command::Set(-500)),
        ("SET flow=+12.125", Command::Set(12_125)),
        ("SET flow=.5", Command::Set(500)),
        ("SET flow=7.", Command::Set(7_000)),
        ("REID", Command::Reid),
        ("MODEL", Command::Model),
        ("FORGET", Command::Forget),
        ("LOG on", Command::Log(true)),
        ("log OFF", Command::Log(false)),
        ("PROFILE square", Command::Profile(profile(Shape::Square))),
        (
            "PROFILE ramp peak=60 bias=10 rate=20 ie=2 rise=0.3",
            Command::Profile(ProfileArgs {
                peak: Some(60_000),
                bias: Some(10_000),
                rate: Some(20_000),
                ie: Some(2_000),
                rise: Some(300),
                ..profile(Shape::Ramp)
            }),
        ),
        (
            "PROFILE Square\tRISE=0.125",
            Command::Profile(ProfileArgs {
                rise: Some(125),
                ..profile(Shape::Square)
            }),
        ),
        ("VENT vt=500 rate=20", Command::Vent(vent(500_000, 20_000))),
        (
            "vent RATE=12 Vt=300.5 ie=4 wave=RAMP peep=10 bias=2.5 rise=0.05 trim=off",
            Command::Vent(VentArgs {
                ie: Some(4_000),
                wave: Some(Shape::Ramp),
                peep: Some(10_000),
                bias: Some(2_500),
                rise: Some(50),
                trim: Some(false),
                ..vent(300_500, 12_000)
            }),
        ),
        (
            "VENT vt=200 rate=20 ti=1 wave=square trim=ON",
            Command::Vent(VentArgs {
                ti: Some(1_000),
                wave: Some(Shape::Square),
                trim: Some(true),
                ..vent(200_000, 20_000)
            }),
        ),
    ];
    for (line, want) in cases {
        assert_eq!(parse(line.as_bytes()), Ok(*want), "{line:?}");
    }
    // The longest valid line fits.
    let longest = "VENT vt=2000.000 rate=60.000 ie=10.000 wave=square peep=30.000 bias=250.000 \
                   rise=0.050 trim=off";
    assert_eq!(longest.len(), 95);
    assert!(longest.len() <= MAX_LINE);
    assert!(matches!(parse(longest.as_bytes()), Ok(Command::Vent(_))));
}

fn vent(vt: i32, rate: i32) -> VentArgs {
    VentArgs::new(vt, rate)
}

#[test]
fn malformed_lines_say_why() {
    let cases: &[(&[u8], CommandError)] = &[
        (b"", CommandError::Unknown),
        (b"STOPP", CommandError::Unknown),
        (b"STOP now", CommandError::BadField),
        (b"SET", CommandError::Missing),
        (b"SET flow", CommandError::BadField),
        (b"SET flow=", CommandError::BadField),
        (b"SET =4", CommandError::BadField),
        (b"SET speed=4", CommandError::BadField),
        (b"SET flow=4 flow=5", CommandError::BadField),
        (b"SET flow=1e3", CommandError::BadNumber),
        (b"SET flow=1.2345", CommandError::BadNumber),
        (b"SET flow=1..2", CommandError::BadNumber),
        (b"SET flow=-", CommandError::BadNumber),
        (b"SET flow=.", CommandError::BadNumber),
        (b"SET flow=--1", CommandError::BadNumber),
        (b"SET flow=1000000", CommandError::BadNumber),
        (b"SET flow=0000001", CommandError::BadNumber),
        (b"SET flow=99999999999999999999", CommandError::BadNumber),
        (b"SET flow=\xff", CommandError::BadNumber),
        (b"LOG", CommandError::Missing),
        (b"LOG 1", CommandError::BadField),
        (b"PROFILE", CommandError::Missing),
        (b"PROFILE sine", CommandError::BadField),
        (b"PROFILE ramp peak=60 tidal=5", CommandError::BadField),
        (b"VENT", CommandError::Missing),
        (b"VENT vt=500", CommandError::Missing),
        (b"VENT rate=20", CommandError::Missing),
        (b"VENT vt=500 rate=20 ti=1 ie=2", CommandError::BadField),
        (b"VENT vt=500 rate=20 vt=400", CommandError::BadField),
        (b"VENT vt=500 rate=20 wave=sine", CommandError::BadField),
        (
            b"VENT vt=500 rate=20 wave=ramp wave=ramp",
            CommandError::BadField,
        ),
        (b"VENT vt=500 rate=20 trim=1", CommandError::BadField),
        (
            b"VENT vt=500 rate=20 trim=on trim=off",
            CommandError::BadField,
        ),
        (b"VENT vt=500 rate=20 pip=30", CommandError::BadField),
        (b"VENT vt=500 rate=20 peep", CommandError::BadField),
        (b"VENT vt=5e2 rate=20", CommandError::BadNumber),
    ];
    for (line, want) in cases {
        assert_eq!(
            parse(line),
            Err(*want),
            "{:?}",
            String::from_utf8_lossy(line)
        );
    }
    assert_eq!(parse(&[b' '; MAX_LINE + 1]), Err(CommandError::TooLong));
}

#[test]
fn numbers_equal_a_reference_conversion() {
    // Every value with up to 3 decimals on a grid, against f64 parsing of the same text.
    for milli in (-999_999_999i64..=999_999_999)
        .step_by(7_654_321)
        .chain([0, 1, -1, 999])
    {
        for decimals in 0..=3u32 {
            let scale = 10i64.pow(3 - decimals);
            let v = milli / scale * scale;
            let text = format!("{:.*}", decimals as usize, v as f64 / 1000.0);
            let want = (text.parse::<f64>().unwrap() * 1000.0).round() as i32;
            let line = format!("SET flow={text}");
            assert_eq!(parse(line.as_bytes()), Ok(Command::Set(want)), "{text}");
        }
    }
}

/// xorshift64*: a fixed, reproducible byte stream.
struct Bytes(u64);

impl Bytes {
    fn next(&mut self) -> u8 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8
    }
}

/// 200 000 random lines, biased towards the grammar's own bytes, through the line assembler:
/// no panic, every non-empty line answers exactly once, and a command that parses is one the
/// grammar can print back (`SET` values within ±10⁶ slm, exclusive).
#[test]
fn arbitrary_bytes_never_panic_and_every_line_answers() {
    const TOKENS: &[&str] = &[
        "STATUS",
        "STOP",
        "START",
        "SET",
        "flow=",
        "flow=40",
        "PROFILE",
        "square",
        "ramp",
        "peak=",
        "bias=",
        "rate=",
        "ie=",
        "rise=0.3",
        "REID",
        "MODEL",
        "FORGET",
        "LOG",
        "on",
        "off",
        "-12.5",
        "1e3",
        "999999.999",
        "=",
        ".",
    ];
    const ALPHABET: &[u8] =
        b"SETflowPROFILEsquarerampeakbiasrateierise=LOGonfSTOPARTMDUX0123456789.-+ \t\r";
    let mut rng = Bytes(0x9E37_79B9_7F4A_7C15);
    let mut line = Line::new();
    let mut fed = Line::new();
    let (mut lines, mut answers, mut parsed) = (0u32, 0u32, 0u32);
    for _ in 0..200_000 {
        // Up to 8 pieces: grammar tokens (whole or cut), numbers, or random bytes.
        let mut text = Vec::new();
        for _ in 0..rng.next() % 9 {
            match rng.next() % 4 {
                0 | 1 => {
                    let t = TOKENS[usize::from(rng.next()) % TOKENS.len()].as_bytes();
                    let cut = if rng.next() < 16 {
                        usize::from(rng.next()) % (t.len() + 1)
                    } else {
                        t.len()
                    };
                    text.extend_from_slice(&t[..cut]);
                }
                2 => {
                    for _ in 0..rng.next() % 12 {
                        text.push(ALPHABET[usize::from(rng.next()) % ALPHABET.len()]);
                    }
                }
                _ => {
                    for _ in 0..rng.next() % 30 {
                        text.push(rng.next());
                    }
                }
            }
            if rng.next() < 200 {
                text.push(b' ');
            }
        }
        text.retain(|&b| b != b'\n' && b != b'\r');
        let blank = text.iter().all(|&b| b == b' ' || b == b'\t');
        let mut got = None;
        for &b in text.iter().chain(b"\n") {
            if let Some(answer) = line.push(b) {
                assert!(got.is_none(), "two answers for one line");
                got = Some(answer);
            }
        }
        // The main loop's way (feed in the idle wait, take in the pass) answers the same, and
        // tells a STOP without parsing exactly when the parser reads one.
        let mut held = None;
        for &b in text.iter().chain(b"\n") {
            if held.is_none() && fed.feed(b) {
                assert!(fed.is_complete());
                held = Some(fed.is_stop());
            }
        }
        if let Some(stop) = held {
            assert_eq!(
                stop,
                got == Some(Ok(Command::Stop)),
                "{:?}",
                String::from_utf8_lossy(&text)
            );
            assert_eq!(Some(fed.take()), got);
        }
        assert!(!fed.is_complete());
        lines += 1;
        match got {
            None => assert!(blank, "{:?} got no answer", String::from_utf8_lossy(&text)),
            Some(answer) => {
                answers += 1;
                assert_eq!(
                    answer.is_err() && text.len() > MAX_LINE,
                    text.len() > MAX_LINE
                );
                if let Ok(Command::Set(v)) = answer {
                    assert!(v.unsigned_abs() < 1_000_000_000);
                }
                parsed += u32::from(answer.is_ok());
            }
        }
    }
    assert_eq!(lines, 200_000);
    assert!(answers > 150_000, "{answers} answered lines");
    eprintln!("{lines} lines, {answers} answered, {parsed} parsed");
    // The bias towards the grammar reaches the parser's accepting paths too.
    assert!(parsed > 100, "{parsed} lines parsed");
}

/// A receiver's [`LOST`] marker damages the line it falls in, and only that one: the line
/// before it and the line after it are read as sent.
#[test]
fn a_lost_marker_refuses_its_line_only() {
    let mut line = Line::new();
    let mut answers = Vec::new();
    for &b in b"SET flow=15\nSET flow=1\x005\nSTOP\n".iter() {
        if let Some(a) = line.push(b) {
            answers.push(a);
        }
    }
    assert_eq!(
        answers,
        [
            Ok(Command::Set(15_000)),
            Err(CommandError::Overrun),
            Ok(Command::Stop)
        ]
    );
    // A marker alone on a line still answers (bytes were lost there).
    assert_eq!(line.push(LOST), None);
    assert_eq!(line.push(b'\n'), Some(Err(CommandError::Overrun)));
}

/// A held line (fed, complete, not yet taken) takes no new line: bytes fed meanwhile are
/// dropped and the held line answers `too-long`, never a command it was not.
#[test]
fn a_held_line_takes_no_more_bytes() {
    let mut line = Line::new();
    assert!(!line.feed(b' '));
    assert!(!line.feed(b'\r'), "a blank line is skipped");
    for &b in b"stop\t" {
        assert!(!line.feed(b));
    }
    assert!(line.feed(b'\r'));
    assert!(line.is_complete() && line.is_stop());
    assert!(!line.feed(b'\n'));
    assert!(!line.is_stop(), "damaged");
    assert_eq!(line.take(), Err(CommandError::TooLong));
    assert!(!line.is_complete());
    for &b in b"START" {
        assert!(!line.feed(b));
    }
    assert!(line.feed(b'\n'));
    assert!(!line.is_stop());
    assert_eq!(line.take(), Ok(Command::Start));
}
