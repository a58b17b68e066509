//! `fishtrack timing-check` against `fishtrack-firmware-sim` over a real
//! pseudo-terminal pair (socat): a healthy device passes, every `--fault`
//! kind is caught and named, a silent device times out, and a device of
//! another protocol version gets a clear error.
//!
//! Needs `socat` (installed by CI). The tests share one lock: pty pairs and
//! the child processes are not meant to run in parallel.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use fishtrack_core::link::{self, Decoder, Report, Status, MAX_FRAME};
use fishtrack_core::strobe::StrobeConfig;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// Both binaries, built once and up to date (see `built_bin`).
fn binaries() -> (&'static Path, &'static Path) {
    (
        fishtrack_tests::built_bin("fishtrack", "fishtrack"),
        fishtrack_tests::built_bin("fishtrack-firmware-sim", "fishtrack-firmware-sim"),
    )
}

use fishtrack_tests::{pty_pair, Proc};

/// Start the simulator on `port` and wait until it serves.
fn start_sim(port: &str, fault: Option<&str>) -> Proc {
    let (_, sim) = binaries();
    let mut cmd = Command::new(sim);
    cmd.args(["--serial", port]);
    if let Some(f) = fault {
        cmd.args(["--fault", f]);
    }
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start fishtrack-firmware-sim");
    let err = child.stderr.take().expect("sim stderr");
    let p = Proc(child);
    let mut lines = BufReader::new(err).lines();
    match lines.next() {
        Some(Ok(l)) if l.contains("serving") => {}
        other => panic!("firmware-sim did not start: {other:?}"),
    }
    std::thread::spawn(move || for _ in lines {});
    p
}

struct Outcome {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    took: Duration,
}

/// Run `fishtrack timing-check`, killing it after 60 s.
fn timing_check(port: &str, frames: u32) -> Outcome {
    let (host, _) = binaries();
    let t0 = Instant::now();
    let mut child = Command::new(host)
        .args([
            "timing-check",
            "--port",
            port,
            "--frames",
            &frames.to_string(),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start fishtrack timing-check");
    let mut out = child.stdout.take().expect("stdout");
    let mut err = child.stderr.take().expect("stderr");
    let o = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let e = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    let mut child = Proc(child);
    let status = loop {
        if let Some(s) = child.0.try_wait().expect("wait for timing-check") {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "timing-check hung");
        std::thread::sleep(Duration::from_millis(20));
    };
    Outcome {
        code: status.code(),
        stdout: o.join().expect("stdout reader"),
        stderr: e.join().expect("stderr reader"),
        took: t0.elapsed(),
    }
}

fn row<'a>(out: &'a str, name: &str) -> &'a str {
    out.lines()
        .find(|l| l.starts_with(name))
        .unwrap_or_else(|| panic!("no table line `{name}` in:\n{out}"))
}

/// The timing rows (everything but line integrity).
const TIMING_ROWS: [&str; 8] = [
    "frames reported",
    "missing edges",
    "frame period error (max)",
    "trigger jitter (max)",
    "trigger jitter (RMS)",
    "left/right trigger skew (max)",
    "strobe-to-exposure margin, start (min)",
    "strobe-to-exposure margin, end (min)",
];

fn run_device(fault: Option<&str>, frames: u32) -> Outcome {
    let pty = pty_pair();
    let _sim = start_sim(&pty.a, fault);
    timing_check(&pty.b, frames)
}

#[test]
fn healthy_device_passes() {
    let _g = serial();
    let o = run_device(None, 25);
    assert_eq!(
        o.code,
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        o.stdout,
        o.stderr
    );
    for name in TIMING_ROWS.iter().chain(&["serial frames discarded"]) {
        assert!(row(&o.stdout, name).contains("PASS"), "{}", o.stdout);
    }
    assert!(row(&o.stdout, "frames reported").contains("25/25"));
    // The simulated pins are exact: the default timing's 500 µs margins.
    assert!(row(&o.stdout, "strobe-to-exposure margin, start (min)").contains(" 500 us"));
    assert!(row(&o.stdout, "strobe-to-exposure margin, end (min)").contains(" 500 us"));
    assert!(o.stdout.contains("RESULT: PASS"));
    assert!(!o.stdout.contains("FAIL"));
}

/// Run a fault; the named row must FAIL, the output must name the fault,
/// and exit code 1.
fn fault_caught(fault: &str, failing_row: &str, named: &str) -> Outcome {
    let _g = serial();
    let o = run_device(Some(fault), 25);
    assert_eq!(
        o.code,
        Some(1),
        "{fault}: stdout:\n{}\nstderr:\n{}",
        o.stdout,
        o.stderr
    );
    let r = row(&o.stdout, failing_row);
    assert!(r.contains("FAIL"), "{fault}: {r}");
    assert!(r.contains(named), "{fault}: row does not name it: {r}");
    assert!(
        o.stderr.contains(failing_row),
        "{fault}: stderr lacks the failing line: {}",
        o.stderr
    );
    assert!(o.stdout.contains("RESULT: FAIL"));
    o
}

#[test]
fn jitter_is_caught() {
    let o = fault_caught("jitter", "trigger jitter (max)", "jitter");
    assert!(row(&o.stdout, "frame period error (max)").contains("FAIL"));
    // The whole frame moves: skew and strobe margins stay fine.
    assert!(row(&o.stdout, "left/right trigger skew (max)").contains("PASS"));
    assert!(row(&o.stdout, "strobe-to-exposure margin, start (min)").contains("PASS"));
}

#[test]
fn late_strobe_is_caught() {
    let o = fault_caught(
        "late-strobe",
        "strobe-to-exposure margin, start (min)",
        "late strobe",
    );
    // Lit 300 µs after the exposure started.
    assert!(row(&o.stdout, "strobe-to-exposure margin, start (min)").contains("-300 us"));
    assert!(row(&o.stdout, "trigger jitter (max)").contains("PASS"));
}

#[test]
fn short_strobe_is_caught() {
    let o = fault_caught(
        "short-strobe",
        "strobe-to-exposure margin, end (min)",
        "short strobe",
    );
    // Cut 1000 µs (half the 2 ms exposure) before the exposure ends.
    assert!(row(&o.stdout, "strobe-to-exposure margin, end (min)").contains("-1000 us"));
    assert!(row(&o.stdout, "strobe-to-exposure margin, start (min)").contains("PASS"));
}

#[test]
fn dropped_trigger_is_caught() {
    let o = fault_caught("dropped-trigger", "missing edges", "dropped trigger");
    // Every 5th frame from frame 2 loses both right-trigger edges: 5 × 2.
    let r = row(&o.stdout, "missing edges");
    assert!(r.contains(" 10 "), "{r}");
    assert!(
        r.contains("trigger R rise missing in frames 2, 7, 12, 17, 22"),
        "{r}"
    );
}

#[test]
fn garbage_is_survived_and_named() {
    let o = fault_caught("garbage", "serial frames discarded", "garbage");
    // Resynchronised: every frame arrived and every timing row passes.
    for name in TIMING_ROWS {
        assert!(
            row(&o.stdout, name).contains("PASS"),
            "{name}: {}",
            o.stdout
        );
    }
    assert!(row(&o.stdout, "frames reported").contains("25/25"));
}

#[test]
fn silent_device_times_out_with_a_clear_message() {
    let _g = serial();
    let pty = pty_pair();
    let o = timing_check(&pty.b, 5);
    assert_eq!(o.code, Some(1), "{}", o.stderr);
    assert!(
        o.stderr.contains("device stopped answering"),
        "{}",
        o.stderr
    );
    assert!(o.stderr.contains(&pty.b), "{}", o.stderr);
    assert!(
        o.took >= Duration::from_secs(3),
        "gave up after {:?}",
        o.took
    );
}

#[test]
fn other_protocol_version_is_named() {
    let _g = serial();
    let pty = pty_pair();
    // A fake device of protocol version 2 answering the first command.
    let mut dev = serialport::new(&pty.a, 115_200)
        .timeout(Duration::from_secs(5))
        .open()
        .expect("open pty a");
    let host = std::thread::spawn({
        let b = pty.b.clone();
        move || timing_check(&b, 5)
    });
    let mut dec = Decoder::new();
    let mut byte = [0u8; 1];
    let cmd = loop {
        dev.read_exact(&mut byte)
            .expect("read the host's first command");
        if let Some(r) = dec.push::<link::Command>(byte[0]) {
            break r;
        }
    };
    assert_eq!(cmd, Ok(link::Command::Stop));
    let status = Report::Status(Status {
        running: false,
        config: StrobeConfig::default(),
        frames: 0,
        uptime_us: 0,
    });
    let mut buf = [0u8; MAX_FRAME];
    let n = link::encode_with_version(2, &status, &mut buf).expect("encode");
    std::io::Write::write_all(&mut dev, &buf[..n]).expect("write");
    let o = host.join().expect("host thread");
    assert_eq!(o.code, Some(1), "{}", o.stderr);
    assert!(
        o.stderr.contains("protocol version 2, expected 1"),
        "{}",
        o.stderr
    );
}
