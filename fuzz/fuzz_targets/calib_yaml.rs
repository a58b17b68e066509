//! The calibration readers on random input (first byte even: OpenCV
//! FileStorage YAML text; odd: `.npz` bytes). Neither the parsers nor the
//! full `StereoCalib::load` (validation, rectification set-up) may panic;
//! a loaded calibration must write YAML that loads back equal.
#![no_main]

use std::io::Write;
use std::path::Path;

use fishtrack::calib::{npz, yaml, StereoCalib};
use libfuzzer_sys::fuzz_target;

/// Writes `bytes` to `name` in a fresh temporary directory and loads it.
fn load(name: &str, bytes: &[u8]) -> Option<(tempfile::TempDir, StereoCalib)> {
    let dir = tempfile::tempdir().ok()?;
    let path = dir.path().join(name);
    std::fs::File::create(&path).ok()?.write_all(bytes).ok()?;
    let calib = StereoCalib::load(&path, Some((640, 480))).ok()?;
    Some((dir, calib))
}

fn round_trip(calib: &StereoCalib) {
    let text = calib.to_yaml();
    let (_dir, again) = load("calibration.yml", text.as_bytes()).expect("written YAML loads");
    assert_eq!(again.to_yaml(), text, "YAML round trip");
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, bytes)) = data.split_first() else {
        return;
    };
    let path = Path::new("fuzz");
    if mode & 1 == 0 {
        let Ok(text) = std::str::from_utf8(bytes) else {
            return;
        };
        // The parser alone, then the whole loader only when it parses.
        if yaml::parse(path, text).is_ok() {
            if let Some((_dir, calib)) = load("calibration.yml", bytes) {
                round_trip(&calib);
            }
        }
    } else {
        let _ = npz::parse_npy(path, "fuzz", bytes);
        if let Some((_dir, calib)) = load("cal.npz", bytes) {
            round_trip(&calib);
        }
    }
});
