//! One core, two hosts: the fish that `fishtrack-firmware-sim --haul DIR`
//! reports over the serial link (track ids, first/last frames, lengths)
//! equal the rows of `fish.csv` written by `fishtrack track DIR` on the
//! same small synthetic haul (`fishtrack synth --size 512 --frames 12`).
//!
//! Needs `socat` (a real pseudo-terminal pair, as in `timing.rs`). Cargo runs
//! test binaries one after another, so this never overlaps the pty tests of
//! `timing.rs`; the lock below serialises tests within this binary.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use fishtrack_core::link::{self, Decoder, FishClosed, Report, MAX_FRAME};

static SERIAL: Mutex<()> = Mutex::new(());

const FRAMES: u32 = 12;

use fishtrack_tests::{pty_pair, Proc};

fn run_ok(cmd: &mut Command) {
    let out = cmd.output().expect("run");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `fish.csv` rows as (id, first, last, length or −1).
fn fish_csv(path: &Path) -> Vec<(u32, u32, u32, f64)> {
    fishtrack::eval::io::read_fish(path)
        .expect("fish.csv")
        .into_iter()
        .map(|f| {
            (
                f.track_id as u32,
                f.first_frame,
                f.last_frame,
                f.length_mm.unwrap_or(-1.0),
            )
        })
        .collect()
}

#[test]
fn firmware_sim_reports_the_same_fish_as_track() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let host = fishtrack_tests::built_bin("fishtrack", "fishtrack");
    let sim = fishtrack_tests::built_bin("fishtrack-firmware-sim", "fishtrack-firmware-sim");
    let tmp = tempfile::tempdir().unwrap();
    let haul = tmp.path().join("haul");
    let out = tmp.path().join("out");
    run_ok(Command::new(host).arg("synth").arg(&haul).args([
        "--size",
        "512",
        "--frames",
        &FRAMES.to_string(),
        "--seed",
        "3",
    ]));
    run_ok(
        Command::new(host)
            .arg("track")
            .arg(&haul)
            .arg("--out")
            .arg(&out),
    );
    let expected = fish_csv(&out.join("fish.csv"));
    assert!(!expected.is_empty(), "the haul should give fish");

    let pty = pty_pair();
    let (a, b) = (pty.a.clone(), pty.b.clone());
    let mut child = Command::new(sim)
        .args(["--serial", &a, "--haul"])
        .arg(&haul)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start fishtrack-firmware-sim");
    let err = child.stderr.take().expect("sim stderr");
    let _sim = Proc(child);
    let mut lines = BufReader::new(err).lines();
    loop {
        match lines.next() {
            Some(Ok(l)) if l.contains("serving") => break,
            Some(Ok(_)) => {}
            other => panic!("firmware-sim did not start: {other:?}"),
        }
    }
    std::thread::spawn(move || for _ in lines {});

    let mut port = serialport::new(&b, 115_200)
        .timeout(Duration::from_millis(200))
        .open()
        .expect("open pty b");
    let mut buf = [0u8; MAX_FRAME];
    let n = link::encode(&link::Command::RunBench { frames: FRAMES }, &mut buf).expect("encode");
    port.write_all(&buf[..n]).expect("write");

    let mut dec = Decoder::new();
    let mut fish: Vec<FishClosed> = Vec::new();
    let mut frames = Vec::new();
    let t0 = Instant::now();
    let mut byte = [0u8; 256];
    'read: loop {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no BenchDone from the device"
        );
        let n = match port.read(&mut byte) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) => panic!("serial read: {e}"),
        };
        for &c in &byte[..n] {
            match dec.push::<Report>(c) {
                Some(Ok(Report::FishClosed(f))) => fish.push(f),
                Some(Ok(Report::Frame(f))) => frames.push(f),
                Some(Ok(Report::BenchDone { .. })) => break 'read,
                Some(Ok(_)) | None => {}
                Some(Err(e)) => panic!("bad frame from the device: {e}"),
            }
        }
    }
    assert_eq!(
        frames.len(),
        FRAMES as usize,
        "every frame went through the pipeline"
    );
    assert!(frames.iter().any(|f| f.objects > 0), "objects are reported");
    let mut got: Vec<(u32, u32, u32, f64)> = fish
        .iter()
        .map(|f| (f.track_id, f.first_frame, f.last_frame, f.length_mm as f64))
        .collect();
    got.sort_by_key(|f| f.0);
    assert_eq!(
        got.len(),
        expected.len(),
        "device {got:?} vs track {expected:?}"
    );
    for (g, e) in got.iter().zip(&expected) {
        assert_eq!(
            (g.0, g.1, g.2),
            (e.0, e.1, e.2),
            "device {g:?} vs track {e:?}"
        );
        // fish.csv keeps 3 decimals
        assert!(
            (g.3 - e.3).abs() <= 6e-4 * e.3.abs().max(1.0),
            "device {g:?} vs track {e:?}"
        );
    }
}
