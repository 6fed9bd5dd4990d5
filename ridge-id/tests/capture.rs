//! `ridge-id capture` end to end: a file, a FIFO and a pseudo-terminal fed with mixed lines
//! (rows, device lines, noise, a cut last line); the CSV is checked line by line against what
//! was fed (each input line paired with the output line the documented rules give), Ctrl-C
//! (SIGINT) leaves a file of complete lines and prints the final counts, and `identify`
//! reads the captured file.

use std::fs;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_ridge-id");

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("ridge_id_capture")
        .join(name);
    fs::remove_dir_all(&d).ok();
    fs::create_dir_all(&d).unwrap();
    d
}

/// Input lines (as sent, without `\n`) and the output line each must give (`None`: not
/// written).
fn mixed() -> Vec<(Vec<u8>, Option<&'static str>)> {
    vec![
        (
            b"SENSOR ready tries=1".to_vec(),
            Some("# SENSOR ready tries=1"),
        ),
        (b"OK log".to_vec(), Some("# OK log")),
        (b"t,u,y,r,phase".to_vec(), Some("# t,u,y,r,phase")),
        (
            b"EXCITE A-Multistep n=3000 u0=30.00 y0=19.058 attempt=1/3".to_vec(),
            Some("# EXCITE A-Multistep n=3000 u0=30.00 y0=19.058 attempt=1/3"),
        ),
        (
            b"2.01,0.3000,19.05833,,excite".to_vec(),
            Some("2.01,0.3000,19.05833,,excite"),
        ),
        // CRLF line end.
        (
            b"2.02,0.4500,19.10000,,excite\r".to_vec(),
            Some("2.02,0.4500,19.10000,,excite"),
        ),
        (
            b"\xff\xfe\x01garbage\\".to_vec(),
            Some("# bad: \\xff\\xfe\\x01garbage\\\\"),
        ),
        (b"".to_vec(), None),
        (b"LOG dropped=2".to_vec(), Some("# LOG dropped=2")),
        (
            b"0.35,19.1,excite".to_vec(),
            Some("# bad: 0.35,19.1,excite"),
        ),
        (
            b"12.34,0.3500,40.12500,40.000,run".to_vec(),
            Some("12.34,0.3500,40.12500,40.000,run"),
        ),
        (
            b"ID p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000 c=-0.125000 score=-1234.5".to_vec(),
            Some("# ID p=1 q=1 d=3 off=1 theta=0.935000 phi=6.500000 c=-0.125000 score=-1234.5"),
        ),
        (b"ERR range flow".to_vec(), Some("# ERR range flow")),
    ]
}

/// The bytes fed: every line with `\n`, then `tail` without one.
fn fed(lines: &[(Vec<u8>, Option<&str>)], tail: &[u8]) -> Vec<u8> {
    let mut b = Vec::new();
    for (l, _) in lines {
        b.extend_from_slice(l);
        b.push(b'\n');
    }
    b.extend_from_slice(tail);
    b
}

/// The CSV the rules give: the header, then the expected line of each input line.
fn expected(lines: &[(Vec<u8>, Option<&str>)]) -> String {
    let mut s = String::from("t,u,y,r,phase\n");
    for (_, out) in lines {
        if let Some(o) = out {
            s.push_str(o);
            s.push('\n');
        }
    }
    s
}

/// (rows, comments, bad) of the expected lines, counted from the expectations.
fn expected_counts(lines: &[(Vec<u8>, Option<&str>)]) -> (u64, u64, u64) {
    let outs: Vec<&str> = lines.iter().filter_map(|(_, o)| *o).collect();
    let bad = outs.iter().filter(|o| o.starts_with("# bad: ")).count() as u64;
    let comments = outs.iter().filter(|o| o.starts_with("# ")).count() as u64 - bad;
    let rows = outs.len() as u64 - bad - comments;
    (rows, comments, bad)
}

/// The final counts line of stderr: `capture: rows=… comments=… bad=… dropped=… (why); …`.
fn final_counts(stderr: &str) -> (u64, u64, u64, u64, String) {
    let last = stderr
        .lines()
        .rev()
        .find(|l| l.contains("wrote"))
        .unwrap_or_else(|| panic!("no final line in {stderr:?}"));
    let get = |k: &str| -> u64 {
        let at = last.find(&format!("{k}=")).unwrap() + k.len() + 1;
        last[at..]
            .split(|c: char| !c.is_ascii_digit())
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let why = last[last.find('(').unwrap() + 1..last.find(')').unwrap()].to_string();
    (
        get("rows"),
        get("comments"),
        get("bad"),
        get("dropped"),
        why,
    )
}

#[test]
fn a_file_gives_the_fed_lines_and_drops_the_cut_last_one() {
    let d = dir("file");
    let lines = mixed();
    let input = d.join("in.txt");
    fs::write(&input, fed(&lines, b"12.35,0.3500,40.1")).unwrap();
    let out_path = d.join("log.csv");
    let out = Command::new(BIN)
        .args(["capture", "--input"])
        .arg(&input)
        .arg("--out")
        .arg(&out_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert_eq!(fs::read_to_string(&out_path).unwrap(), expected(&lines));
    let (rows, comments, bad) = expected_counts(&lines);
    assert_eq!(
        final_counts(&stderr),
        (rows, comments, bad, 1, "end of input".to_string())
    );
}

#[test]
fn a_line_longer_than_the_limit_is_bad_and_cut() {
    let d = dir("long");
    let input = d.join("in.txt");
    let long = "A".repeat(5000);
    fs::write(&input, format!("{long}\nOK log\n")).unwrap();
    let out_path = d.join("log.csv");
    let out = Command::new(BIN)
        .args(["capture", "--input"])
        .arg(&input)
        .arg("--out")
        .arg(&out_path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let want = format!("t,u,y,r,phase\n# bad: {}…\n# OK log\n", "A".repeat(200));
    assert_eq!(fs::read_to_string(&out_path).unwrap(), want);
}

fn spawn_capture(port: &Path, out: &Path) -> Child {
    Command::new(BIN)
        .args(["capture", "--port"])
        .arg(port)
        .arg("--out")
        .arg(out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until `path` holds `want` (up to 20 s).
fn wait_for(path: &Path, want: &str) {
    let start = Instant::now();
    loop {
        let got = fs::read_to_string(path).unwrap_or_default();
        if got == want {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "timeout; file holds {got:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn interrupt_and_wait(mut child: Child) -> (std::process::ExitStatus, String) {
    let pid = rustix::process::Pid::from_raw(child.id() as i32).unwrap();
    rustix::process::kill_process(pid, rustix::process::Signal::Int).unwrap();
    let status = child.wait().unwrap();
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    (status, stderr)
}

#[test]
fn ctrl_c_on_a_fifo_leaves_complete_lines_and_the_counts() {
    let d = dir("fifo");
    let fifo = d.join("port");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let out_path = d.join("log.csv");
    let child = spawn_capture(&fifo, &out_path);
    // Opening for writing waits for the capture to open the FIFO for reading.
    let mut w = fs::OpenOptions::new().write(true).open(&fifo).unwrap();
    let lines = mixed();
    w.write_all(&fed(&lines, b"12.35,0.3500,40.1")).unwrap();
    w.flush().unwrap();
    wait_for(&out_path, &expected(&lines));
    // The writer stays open: the capture ends on SIGINT, not on end of input.
    let (status, stderr) = interrupt_and_wait(child);
    drop(w);
    assert!(status.success(), "{status:?} {stderr}");
    let text = fs::read_to_string(&out_path).unwrap();
    assert_eq!(text, expected(&lines));
    assert!(text.ends_with('\n'));
    let (rows, comments, bad) = expected_counts(&lines);
    assert_eq!(
        final_counts(&stderr),
        (rows, comments, bad, 1, "interrupted".to_string())
    );
}

#[test]
fn ctrl_c_on_a_pseudo_terminal_port() {
    use rustix::pty::{grantpt, openpt, ptsname, unlockpt, OpenptFlags};
    let d = dir("pty");
    let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY).unwrap();
    grantpt(&master).unwrap();
    unlockpt(&master).unwrap();
    let slave = PathBuf::from(ptsname(&master, Vec::new()).unwrap().into_string().unwrap());
    let out_path = d.join("log.csv");
    let mut child = spawn_capture(&slave, &out_path);
    // Wait for "capture: reading … at 115200 baud" (the port is configured raw by then), then
    // longer than the start gap, so that the first line counts as complete.
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    err.read_line(&mut first).unwrap();
    assert!(first.contains("at 115200 baud"), "{first}");
    std::thread::sleep(Duration::from_millis(300));
    let mut m = fs::File::from(master);
    let lines = mixed();
    m.write_all(&fed(&lines, b"EXCITE B-Multi")).unwrap();
    wait_for(&out_path, &expected(&lines));
    // The device saw nothing from the capture (no --send; raw mode: no echo). Checked while the
    // capture still holds the port open (afterwards the master side reports a hang-up).
    let mut fds = [rustix::event::PollFd::new(&m, rustix::event::PollFlags::IN)];
    assert_eq!(rustix::event::poll(&mut fds, 50).unwrap(), 0);
    child.stderr = None;
    let pid = rustix::process::Pid::from_raw(child.id() as i32).unwrap();
    rustix::process::kill_process(pid, rustix::process::Signal::Int).unwrap();
    let status = child.wait().unwrap();
    let mut rest = String::new();
    err.read_to_string(&mut rest).unwrap();
    assert!(status.success(), "{status:?} {rest}");
    assert_eq!(fs::read_to_string(&out_path).unwrap(), expected(&lines));
    let (rows, comments, bad) = expected_counts(&lines);
    assert_eq!(
        final_counts(&rest),
        (rows, comments, bad, 1, "interrupted".to_string())
    );
}

#[test]
fn identify_reads_the_captured_file_as_the_plain_log() {
    let d = dir("identify");
    // A first-order plant y_t = 0.9 y_{t-1} + 4 u_{t-2} + 1 in the firmware's number format.
    let mut u_state = 7u64;
    let mut u = Vec::new();
    while u.len() < 2000 {
        u_state = u_state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let level = 0.2 + 0.4 * ((u_state >> 33) as f64 / (1u64 << 31) as f64);
        for _ in 0..25 {
            u.push((level * 1e4).round() / 1e4);
        }
    }
    let mut y = vec![10.0f64; u.len()];
    for t in 2..u.len() {
        y[t] = 0.9 * y[t - 1] + 4.0 * u[t - 2] + 1.0 + 0.01 * (((t * 7919) % 13) as f64 - 6.0);
    }
    let mut device = String::from("SENSOR ready tries=1\nOK log\nt,u,y,r,phase\n");
    let mut plain = String::from("t,u,y,r,phase\n");
    for t in 0..u.len() {
        let row = format!("{:.2},{:.4},{:.5},,excite\n", t as f64 * 0.01, u[t], y[t]);
        device.push_str(&row);
        plain.push_str(&row);
        if t == 1000 {
            device.push_str("EXCITE B-Multistep n=3000 u0=30.00 y0=19.058 attempt=1/3\n");
        }
    }
    let (input, csv, plain_csv) = (d.join("in.txt"), d.join("log.csv"), d.join("plain.csv"));
    fs::write(&input, device).unwrap();
    fs::write(&plain_csv, plain).unwrap();
    let out = Command::new(BIN)
        .args(["capture", "--input"])
        .arg(&input)
        .arg("--out")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success());
    let run = |p: &Path| -> Value {
        let o = Command::new(BIN)
            .args(["identify", "--offset", "intercept", "--json", "--input"])
            .arg(p)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let (a, b) = (run(&csv), run(&plain_csv));
    for k in ["structure", "theta", "phi", "offset"] {
        assert_eq!(a[k], b[k], "{k}");
    }
    assert_eq!(a["structure"]["d"], 2);
}
