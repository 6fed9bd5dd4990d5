//! `ridge-id capture`: the pump's serial output into a CSV that `ridge-id identify` reads.
//!
//! ```text
//! ridge-id capture --port /dev/ttyACM0 [--baud 115200] [--send "LOG on"] --out log.csv
//! ridge-id capture --input saved-terminal-output.txt --out log.csv
//! ```
//!
//! The output starts with the header `t,u,y,r,phase` (the firmware's `console::LOG_HEADER`),
//! then every line the device sent, in order:
//! - a **log row** (`12.34,0.3500,40.12500,40.000,run`: five cells, `t`, `u`, `y` finite
//!   numbers, `r` empty or a finite number, `phase` a lower-case word) verbatim;
//! - any other **device line** (printable ASCII 0x20..=0x7e, starting with an upper-case
//!   letter: `EXCITE … u0= y0=`, `ID p= …`, `STATUS …`, `LOG dropped=…`, `OK log`, `ERR …`,
//!   and the header the firmware prints after `LOG on`) as a comment `# <line>`, so that the
//!   file keeps the segment boundaries and the operating point;
//! - anything else (noise, bytes above 0x7e, a line longer than [`MAX_LINE`] bytes) is
//!   counted as **bad** and written as a comment `# bad: <line>` with every byte outside
//!   0x20..=0x7e and `\` escaped (`\xNN`, `\\`; a long line cut to 200 bytes and marked `…`).
//!
//! Line ends are `\n` with an optional `\r` before it; blank lines are skipped (not written,
//! not counted). Only complete lines are written: a line still without its `\n` when the input
//! ends or on Ctrl-C is **dropped** and counted, as is, on a serial port, the line that was in
//! progress when the capture started (bytes arriving within [`START_GAP_MS`] of opening the
//! port, up to their `\n`). Each line is written with one `write` and the file is not
//! buffered, so a kill at any time leaves only complete lines. The counts (rows, comments,
//! bad, dropped) go to stderr while capturing (a `\r`-updated line at most 5 times a second
//! on a terminal, otherwise a line at most once a second when they changed) and once at the
//! end. Ctrl-C (SIGINT) or SIGTERM ends the capture cleanly with exit status 0.
//!
//! `ridge-id identify --input log.csv` reads the file as it is (its reader skips `#` lines and
//! ignores the `t`, `r` and `phase` columns); it uses every row, whatever the phase.
//!
//! Serial ports are configured with termios through `rustix` (raw mode, 8N1, no flow control,
//! the baud rate, `CLOCAL | CREAD`) rather than the `serialport` crate, whose default
//! features link libudev (a system library and `-dev` package CI would have to install) for
//! port enumeration this command does not need; `rustix` is a safe wrapper of the same system
//! calls. `poll` with a 100 ms timeout lets the loop see Ctrl-C and update the counts while
//! the port is quiet. Ctrl-C is a `signal-hook` flag (no handler code runs in the signal).
//!
//! Note: opening the Arduino Mega 2560's USB port resets the board (DTR), so a capture starts
//! at its boot; `--send` is written once the first complete line arrived (the firmware's
//! `SENSOR ready …`) or [`SEND_AFTER_MS`] after opening, whichever comes first.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Args;

/// The log's header line (the firmware's, [`ridge_pump_firmware::console::LOG_HEADER`]).
pub const HEADER: &str = ridge_pump_firmware::console::LOG_HEADER;

/// Longest line kept in full, bytes (a log row is at most 48): longer ones are bad.
pub const MAX_LINE: usize = 4096;

/// Bytes of a bad line kept in its comment.
pub const BAD_QUOTE: usize = 200;

/// On a serial port, bytes arriving within this many ms of opening belong to a line already
/// in progress: they are dropped up to the first `\n`.
pub const START_GAP_MS: u64 = 100;

/// `--send` is written at the latest this many ms after opening the port.
pub const SEND_AFTER_MS: u64 = 3000;

/// The firmware's UART rate on both boards (ATmega2560 USART0, STM32F411 USART1), baud.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Options of `ridge-id capture`.
#[derive(Debug, Clone, Args)]
pub struct CaptureArgs {
    /// Serial port (configured raw, 8N1, --baud), or any other path to read as it is (a
    /// pseudo-terminal, a FIFO, a file).
    #[arg(
        long,
        value_name = "PATH",
        required_unless_present = "input",
        conflicts_with = "input"
    )]
    pub port: Option<PathBuf>,
    /// Read a file (or - for standard input) instead of a port, without configuring it.
    #[arg(long, value_name = "FILE")]
    pub input: Option<PathBuf>,
    /// Baud rate of --port when it is a terminal (the firmware's: 115200).
    #[arg(long, default_value_t = DEFAULT_BAUD)]
    pub baud: u32,
    /// The CSV to write (created or truncated).
    #[arg(long, value_name = "log.csv")]
    pub out: PathBuf,
    /// A command line to write to the port (with \n) once the device has sent its first
    /// complete line or 3 s after opening, e.g. "LOG on".
    #[arg(long, value_name = "LINE", requires = "port")]
    pub send: Option<String>,
}

/// What was written so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Log rows written verbatim.
    pub rows: u64,
    /// Device lines written as `# ` comments.
    pub comments: u64,
    /// Bad lines (written as `# bad: …`).
    pub bad: u64,
    /// Incomplete lines dropped (at the start of a port capture, at the end).
    pub dropped: u64,
}

impl std::fmt::Display for Counts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "rows={} comments={} bad={} dropped={}",
            self.rows, self.comments, self.bad, self.dropped
        )
    }
}

/// What a line is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A log row.
    Row,
    /// A device line (a comment).
    Device,
    /// Neither.
    Bad,
}

fn number(cell: &str) -> bool {
    // Decimal notation only (the firmware's): digits, one '.', a leading '-'.
    let body = cell.strip_prefix('-').unwrap_or(cell);
    !body.is_empty()
        && body.bytes().all(|b| b.is_ascii_digit() || b == b'.')
        && body.bytes().filter(|&b| b == b'.').count() <= 1
        && body.bytes().any(|b| b.is_ascii_digit())
}

/// Classifies one line (without its line end).
pub fn classify(line: &[u8]) -> Kind {
    let printable = line.iter().all(|&b| (0x20..=0x7e).contains(&b));
    if !printable || line.is_empty() || line.len() > MAX_LINE {
        return Kind::Bad;
    }
    // Printable ASCII is UTF-8.
    let text = std::str::from_utf8(line).unwrap_or_default();
    let cells: Vec<&str> = text.split(',').collect();
    if let [t, u, y, r, phase] = cells[..] {
        if number(t)
            && number(u)
            && number(y)
            && (r.is_empty() || number(r))
            && !phase.is_empty()
            && phase.bytes().all(|b| b.is_ascii_lowercase() || b == b'-')
        {
            return Kind::Row;
        }
    }
    if text == HEADER || line[0].is_ascii_uppercase() {
        Kind::Device
    } else {
        Kind::Bad
    }
}

/// `line` with bytes outside 0x20..=0x7e and `\` escaped, cut to [`BAD_QUOTE`] bytes.
pub fn escape(line: &[u8]) -> String {
    let mut s = String::new();
    for &b in line.iter().take(BAD_QUOTE) {
        match b {
            b'\\' => s.push_str("\\\\"),
            0x20..=0x7e => s.push(char::from(b)),
            _ => s.push_str(&format!("\\x{b:02x}")),
        }
    }
    if line.len() > BAD_QUOTE {
        s.push('…');
    }
    s
}

/// Splits a byte stream into lines and writes them to `out` as the [module docs](self) say.
pub struct Capture<W: Write> {
    out: W,
    /// The line being received (at most [`MAX_LINE`] + 1 bytes kept).
    line: Vec<u8>,
    /// Its length, including bytes not kept.
    line_len: usize,
    /// Dropping bytes up to the next `\n` (the line in progress at the start).
    skipping: bool,
    /// The counts.
    pub counts: Counts,
    /// Complete lines received (any kind, blank ones included).
    pub lines: u64,
}

impl<W: Write> Capture<W> {
    /// Writes the header to `out`.
    pub fn new(mut out: W) -> std::io::Result<Self> {
        out.write_all(format!("{HEADER}\n").as_bytes())?;
        out.flush()?;
        Ok(Capture {
            out,
            line: Vec::new(),
            line_len: 0,
            skipping: false,
            counts: Counts::default(),
            lines: 0,
        })
    }

    /// Drops everything up to the next `\n` (counted once as dropped if any byte was).
    pub fn skip_first_line(&mut self) {
        self.skipping = true;
    }

    /// Whether a line is in progress (received without its `\n` yet).
    pub fn pending(&self) -> bool {
        self.line_len > 0
    }

    /// Feeds received bytes; writes every line they complete.
    pub fn feed(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        for &b in bytes {
            if b == b'\n' {
                self.end_line()?;
            } else {
                if self.line.len() <= MAX_LINE {
                    self.line.push(b);
                }
                self.line_len += 1;
            }
        }
        Ok(())
    }

    fn end_line(&mut self) -> std::io::Result<()> {
        let mut line = std::mem::take(&mut self.line);
        let mut len = std::mem::replace(&mut self.line_len, 0);
        if self.skipping {
            self.skipping = false;
            if len > 0 {
                self.counts.dropped += 1;
            }
            return Ok(());
        }
        self.lines += 1;
        if line.last() == Some(&b'\r') && len <= line.len() {
            line.pop();
            len -= 1;
        }
        if len == 0 {
            return Ok(());
        }
        let kind = if len > MAX_LINE {
            Kind::Bad
        } else {
            classify(&line)
        };
        let text = match kind {
            Kind::Row => {
                self.counts.rows += 1;
                let mut t = line;
                t.push(b'\n');
                t
            }
            Kind::Device => {
                self.counts.comments += 1;
                let mut t = b"# ".to_vec();
                t.extend_from_slice(&line);
                t.push(b'\n');
                t
            }
            Kind::Bad => {
                self.counts.bad += 1;
                let mut q = escape(&line);
                if len > line.len() && !q.ends_with('…') {
                    q.push('…');
                }
                format!("# bad: {q}\n").into_bytes()
            }
        };
        self.out.write_all(&text)?;
        self.out.flush()
    }

    /// Ends the capture: a line without its `\n` is dropped and counted.
    pub fn finish(&mut self) -> std::io::Result<Counts> {
        if self.line_len > 0 {
            self.counts.dropped += 1;
        }
        self.line.clear();
        self.line_len = 0;
        self.out.flush()?;
        Ok(self.counts)
    }
}

/// The source being read.
struct Source {
    file: File,
    /// A terminal (configured; `--send` possible).
    tty: bool,
}

fn open_source(args: &CaptureArgs) -> Result<Source, String> {
    if let Some(input) = &args.input {
        if input.as_os_str() == "-" {
            let fd = std::io::stdin()
                .as_fd()
                .try_clone_to_owned()
                .map_err(|e| format!("cannot read standard input: {e}"))?;
            return Ok(Source {
                file: File::from(fd),
                tty: false,
            });
        }
        let file =
            File::open(input).map_err(|e| format!("cannot open {}: {e}", input.display()))?;
        return Ok(Source { file, tty: false });
    }
    let port = args.port.as_ref().ok_or("no --port or --input")?;
    let meta =
        std::fs::metadata(port).map_err(|e| format!("cannot open {}: {e}", port.display()))?;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    if !meta.file_type().is_char_device() {
        if args.send.is_some() {
            return Err(format!(
                "--send needs a serial port; {} is not a terminal",
                port.display()
            ));
        }
        // A FIFO opened blocking waits for its writer (non-blocking, it would read EOF).
        let file = File::open(port).map_err(|e| format!("cannot open {}: {e}", port.display()))?;
        return Ok(Source { file, tty: false });
    }
    // A character device: non-blocking (no wait for a carrier), not our controlling terminal.
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(libc_flags())
        .open(port)
        .map_err(|e| format!("cannot open {}: {e}", port.display()))?;
    let tty = rustix::termios::isatty(&file);
    if tty {
        configure(&file, args.baud).map_err(|e| format!("{}: {e}", port.display()))?;
    } else if args.send.is_some() {
        return Err(format!(
            "--send needs a serial port; {} is not a terminal",
            port.display()
        ));
    }
    Ok(Source { file, tty })
}

/// `O_NONBLOCK | O_NOCTTY`.
fn libc_flags() -> i32 {
    (rustix::fs::OFlags::NONBLOCK | rustix::fs::OFlags::NOCTTY).bits() as i32
}

/// Raw mode, 8N1, no flow control, `baud`; pending input discarded.
fn configure(file: &File, baud: u32) -> Result<(), String> {
    use rustix::termios::{
        tcflush, tcgetattr, tcsetattr, ControlModes, InputModes, OptionalActions, QueueSelector,
    };
    let mut t = tcgetattr(file).map_err(|e| format!("not a serial port: {e}"))?;
    t.make_raw();
    t.control_modes |= ControlModes::CLOCAL | ControlModes::CREAD;
    t.control_modes -= ControlModes::CSTOPB | ControlModes::PARENB | ControlModes::CRTSCTS;
    t.input_modes -= InputModes::IXON | InputModes::IXOFF;
    t.set_speed(baud)
        .map_err(|e| format!("baud rate {baud} not supported: {e}"))?;
    tcsetattr(file, OptionalActions::Now, &t).map_err(|e| format!("cannot configure: {e}"))?;
    tcflush(file, QueueSelector::IFlush).ok();
    Ok(())
}

/// Prints the running counts to stderr, at most 5 times a second on a terminal, otherwise
/// once a second when they changed.
struct Progress {
    tty: bool,
    last: Instant,
    shown: Option<Counts>,
}

impl Progress {
    fn tick(&mut self, c: Counts) {
        let every = if self.tty {
            Duration::from_millis(200)
        } else {
            Duration::from_secs(1)
        };
        if self.last.elapsed() < every || self.shown == Some(c) {
            return;
        }
        self.last = Instant::now();
        self.shown = Some(c);
        if self.tty {
            eprint!("\rcapture: {c}");
        } else {
            eprintln!("capture: {c}");
        }
    }
}

/// Runs `ridge-id capture`: the final counts, or a one-line error.
pub fn run(args: &CaptureArgs) -> Result<Counts, String> {
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))
            .map_err(|e| format!("cannot handle signal {sig}: {e}"))?;
    }
    let mut src = open_source(args)?;
    let out = File::create(&args.out)
        .map_err(|e| format!("cannot create {}: {e}", args.out.display()))?;
    let out_err = |e: std::io::Error| format!("cannot write {}: {e}", args.out.display());
    let mut cap = Capture::new(out).map_err(out_err)?;
    let name = args
        .port
        .as_ref()
        .or(args.input.as_ref())
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    eprintln!(
        "capture: reading {name}{} into {} (Ctrl-C ends)",
        if src.tty {
            format!(" at {} baud", args.baud)
        } else {
            String::new()
        },
        args.out.display()
    );
    let opened = Instant::now();
    let mut first_byte = true;
    let mut send = args.send.clone().filter(|_| src.tty);
    let mut progress = Progress {
        tty: rustix::termios::isatty(std::io::stderr()),
        last: Instant::now(),
        shown: None,
    };
    let mut buf = [0u8; 4096];
    let why = loop {
        if stop.load(Ordering::Relaxed) {
            break "interrupted";
        }
        if let Some(line) = &send {
            if cap.lines > 0 || opened.elapsed() >= Duration::from_millis(SEND_AFTER_MS) {
                src.file
                    .write_all(format!("{line}\n").as_bytes())
                    .map_err(|e| format!("cannot send to {name}: {e}"))?;
                send = None;
            }
        }
        progress.tick(cap.counts);
        let mut fds = [rustix::event::PollFd::new(
            &src.file,
            rustix::event::PollFlags::IN,
        )];
        match rustix::event::poll(&mut fds, 100) {
            Ok(0) => continue,
            Ok(_) => {}
            Err(rustix::io::Errno::INTR) => continue,
            Err(e) => return Err(format!("cannot read {name}: {e}")),
        }
        let n = match src.file.read(&mut buf) {
            Ok(0) => break "end of input",
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => continue,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            // A pseudo-terminal whose other side closed, an unplugged USB port.
            Err(e) if e.raw_os_error() == Some(rustix::io::Errno::IO.raw_os_error()) => {
                break "hang-up"
            }
            Err(e) => return Err(format!("cannot read {name}: {e}")),
        };
        if first_byte {
            first_byte = false;
            if src.tty && opened.elapsed() < Duration::from_millis(START_GAP_MS) {
                cap.skip_first_line();
            }
        }
        cap.feed(&buf[..n]).map_err(out_err)?;
    };
    let counts = cap.finish().map_err(out_err)?;
    if progress.tty && progress.shown.is_some() {
        eprintln!();
    }
    eprintln!("capture: {counts} ({why}); wrote {}", args.out.display());
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds() {
        for row in [
            "12.34,0.3500,40.12500,40.000,run",
            "0.01,0.3000,-0.12500,,excite",
        ] {
            assert_eq!(classify(row.as_bytes()), Kind::Row, "{row}");
        }
        for dev in [
            "EXCITE A-Multistep n=3000 u0=30.00 y0=19.058 attempt=1/3",
            "LOG dropped=3",
            "ERR range flow",
            "t,u,y,r,phase",
        ] {
            assert_eq!(classify(dev.as_bytes()), Kind::Device, "{dev}");
        }
        for bad in [
            &b"12.34,0.35,40.1,run"[..],
            b"1e5,0.3,1.0,,run",
            b"12.34,0.35,nan,,run",
            b"12.34,0.35,1.0,,Run",
            b"xyz",
            b"ID p=1 \xff",
            b"\x00\x01",
        ] {
            assert_eq!(classify(bad), Kind::Bad, "{}", escape(bad));
        }
        assert_eq!(escape(b"a\\b\xff\x01"), "a\\\\b\\xff\\x01");
    }
}
