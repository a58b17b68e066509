//! Shared helpers for the eval tests: the py-motmetrics oracle and MOT files.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use fishtrack::eval::metrics::MotInputs;
use fishtrack::eval::mot::MotSummary;

/// Path of `scripts/motmetrics_oracle.py`.
pub fn oracle_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/motmetrics_oracle.py")
}

/// True when python3 with motmetrics is usable. Without it: a failure when
/// `FISHTRACK_REQUIRE_PYTHON=1`, else a skip notice and `false`.
pub fn have_motmetrics() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import motmetrics, numpy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        if std::env::var("FISHTRACK_REQUIRE_PYTHON").as_deref() == Ok("1") {
            panic!("python3 with motmetrics is required (FISHTRACK_REQUIRE_PYTHON=1) but not available");
        }
        eprintln!("SKIP: python3 with motmetrics not available (pip install motmetrics)");
    }
    ok
}

/// Runs the oracle on two MOT files; returns its JSON object.
pub fn oracle(gt: &Path, pred: &Path, max_distance: f64) -> serde_json::Value {
    oracle_many(&[(gt.to_path_buf(), pred.to_path_buf())], max_distance)
        .pop()
        .unwrap()
}

/// Runs the oracle on several (gt, pred) pairs in one interpreter.
pub fn oracle_many(files: &[(PathBuf, PathBuf)], max_distance: f64) -> Vec<serde_json::Value> {
    let out = Command::new("python3")
        .arg(oracle_script())
        .args(files.iter().flat_map(|(g, p)| [g, p]))
        .arg("--max-distance")
        .arg(max_distance.to_string())
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "oracle failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let v: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("oracle JSON"))
        .collect();
    assert_eq!(v.len(), files.len(), "one oracle line per pair");
    v
}

/// The directory of motmetrics' bundled data.
pub fn motmetrics_data_dir() -> PathBuf {
    let out = Command::new("python3")
        .arg(oracle_script())
        .arg("--data-dir")
        .output()
        .expect("run python3");
    assert!(out.status.success());
    PathBuf::from(String::from_utf8_lossy(&out.stdout).trim())
}

/// Writes MOT rows `(frame, id, box)` (shortest round-trip float format).
pub fn write_mot(path: &Path, rows: &[(u32, i64, [f64; 4])]) {
    let mut f = std::fs::File::create(path).unwrap();
    for (fr, id, b) in rows {
        writeln!(
            f,
            "{fr},{id},{},{},{},{},1,-1,-1,-1",
            b[0], b[1], b[2], b[3]
        )
        .unwrap();
    }
}

/// Reads a MOT file the way `motmetrics.io.loadtxt` does: file order,
/// bb_left/bb_top minus 1 (Matlab convention).
pub fn read_mot_like_motmetrics(path: &Path) -> Vec<(u32, i64, [f64; 4])> {
    fishtrack::eval::io::read_mot(path)
        .unwrap()
        .into_iter()
        .map(|r| {
            (
                r.frame,
                r.id,
                [r.bbox[0] - 1.0, r.bbox[1] - 1.0, r.bbox[2], r.bbox[3]],
            )
        })
        .collect()
}

/// Every metric of `ours` next to the oracle's, as (name, ours, theirs).
pub fn pairs(ours: &MotSummary, theirs: &serde_json::Value) -> Vec<(String, f64, f64)> {
    let ours = serde_json::to_value(ours).unwrap();
    let mut v = Vec::new();
    for (k, t) in theirs.as_object().unwrap() {
        if k == "motmetrics_version" {
            continue;
        }
        let o = ours.get(k).unwrap_or_else(|| panic!("we lack metric {k}"));
        let f = |x: &serde_json::Value| x.as_f64().unwrap_or(f64::NAN);
        v.push((k.clone(), f(o), f(t)));
    }
    v
}

/// Asserts agreement of every metric to `tol` (NaN equals NaN).
pub fn assert_agree(label: &str, ours: &MotSummary, theirs: &serde_json::Value, tol: f64) {
    for (k, o, t) in pairs(ours, theirs) {
        let same = (o.is_nan() && t.is_nan()) || (o - t).abs() <= tol;
        assert!(same, "{label}: {k}: ours {o} vs motmetrics {t}");
    }
}

/// Writes `inputs` to two MOT files in `dir` and runs the oracle on them.
pub fn oracle_on_inputs(dir: &Path, inputs: &MotInputs, max_distance: f64) -> serde_json::Value {
    let (g, p) = (dir.join("gt.txt"), dir.join("pred.txt"));
    write_mot(&g, &inputs.gt);
    write_mot(&p, &inputs.hyp);
    oracle(&g, &p, max_distance)
}
