//! Shared helpers for FishTrack's cross-crate integration tests.
//!
//! The binaries belong to other packages (`fishtrack`,
//! `fishtrack-firmware-sim`), so cargo neither builds them for these tests
//! nor sets `CARGO_BIN_EXE_*` here (bins are only built for integration tests
//! of their own package). [`built_bin`] therefore runs `cargo build -p PKG
//! --bin NAME` once per binary, for the profile these tests were built with
//! (cargo has released its build lock by the time tests run; up to date, this
//! is a no-op), so the tests never run a stale binary.
#![deny(missing_docs)]

use std::collections::HashMap;
use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Mutex, OnceLock};

/// Path where cargo puts a workspace binary for the profile of this test.
pub fn bin(name: &str) -> PathBuf {
    let mut p = std::env::current_exe().expect("test executable path");
    p.pop();
    if p.ends_with("deps") {
        p.pop();
    }
    p.join(format!("{name}{}", std::env::consts::EXE_SUFFIX))
}

/// The up-to-date `fishtrack` binary.
pub fn fishtrack() -> &'static Path {
    built_bin("fishtrack", "fishtrack")
}

/// Runs `fishtrack` with `args` and captures its exit status and output;
/// panics if it cannot be started.
pub fn run_fishtrack<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(fishtrack())
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", fishtrack().display()))
}

/// Captured output as text (lossy UTF-8).
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A test path as `&str` (the temporary paths the tests make are UTF-8).
pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("test path is UTF-8")
}

/// Path of an up-to-date binary `name` of package `package`, built on first
/// use; panics with a clear message if it cannot be built.
pub fn built_bin(package: &str, name: &str) -> &'static Path {
    static BUILT: OnceLock<Mutex<HashMap<String, &'static Path>>> = OnceLock::new();
    let mut map = BUILT
        .get_or_init(|| Mutex::new(HashMap::new()))
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = map.get(name) {
        return p;
    }
    let path = bin(name);
    let profile_dir = path.parent().expect("binary has a parent directory");
    let target_dir = profile_dir.parent().expect("profile dir has a parent");
    let profile = match profile_dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") | None => "dev".to_string(),
        Some(other) => other.to_string(),
    };
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.toml");
    let status = Command::new(&cargo)
        .args([
            "build",
            "--quiet",
            "--locked",
            "-p",
            package,
            "--bin",
            name,
            "--profile",
            &profile,
        ])
        .arg("--manifest-path")
        .arg(&manifest)
        .arg("--target-dir")
        .arg(target_dir)
        .status();
    assert!(
        matches!(status, Ok(s) if s.success()) && path.is_file(),
        "could not build {name} at {} (cargo: {status:?}); try `cargo build -p {package} --profile {profile}`",
        path.display()
    );
    let leaked: &'static Path = Box::leak(path.into_boxed_path());
    map.insert(name.to_string(), leaked);
    leaked
}

/// A child process killed (and reaped) when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A real pseudo-terminal pair made by socat: `a` for the device, `b` for
/// the host. socat lives as long as the pair.
pub struct PtyPair {
    /// The socat process joining the two ptys.
    pub socat: Proc,
    /// Device side.
    pub a: String,
    /// Host side.
    pub b: String,
}

/// Makes a [`PtyPair`] (`socat -d -d pty,raw,echo=0 pty,raw,echo=0`);
/// panics with a clear message when socat is missing.
pub fn pty_pair() -> PtyPair {
    let mut child = Command::new("socat")
        .args(["-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("socat is needed for the pseudo-terminal tests (apt-get install socat)");
    let err = child.stderr.take().expect("socat stderr");
    let socat = Proc(child);
    let mut ptys = Vec::new();
    let mut lines = BufReader::new(err).lines();
    while let Some(Ok(l)) = lines.next() {
        if let Some(i) = l.find("PTY is ") {
            ptys.push(l[i + 7..].trim().to_string());
        }
        if l.contains("starting data transfer loop") {
            break;
        }
    }
    assert_eq!(ptys.len(), 2, "socat did not report two ptys");
    // Keep draining socat's stderr so it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    let b = ptys.pop().expect("pty b");
    let a = ptys.pop().expect("pty a");
    PtyPair { socat, a, b }
}
