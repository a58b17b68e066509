//! The analysis scripts of `scripts/` that the README's figures come from,
//! run on a small synthetic haul (512², 12 frame pairs) and checked
//! against `fishtrack eval`'s own counts: `length_accounting.py` (where
//! per-fish lengths are lost) accounts for exactly eval's measurable fish,
//! `intensity_seed_probe.py` for exactly its countable fish-frames, and
//! `track_failures.py` (why fish fail eq. 16) for exactly its fish, with
//! eval's successes and a linking ceiling of at most those fish.
//! Needs python3 with cv2, numpy and scipy; skipped without them unless
//! `FISHTRACK_REQUIRE_PYTHON=1` (the README's test command sets it).

use std::path::{Path, PathBuf};
use std::process::Command;

use fishtrack_tests::{fishtrack, text};

fn have_python() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import cv2, numpy, scipy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        if std::env::var("FISHTRACK_REQUIRE_PYTHON").as_deref() == Ok("1") {
            panic!("python3 with cv2, numpy and scipy is required (FISHTRACK_REQUIRE_PYTHON=1)");
        }
        eprintln!("SKIP: python3 with cv2, numpy and scipy not available");
    }
    ok
}

fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("scripts")
        .join(name)
}

/// Runs a command, asserting success; returns its stdout.
fn ok(cmd: &mut Command) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// The integer before `label` on a line of `out` that ends with it.
fn count(out: &str, label: &str) -> u64 {
    out.lines()
        .filter(|l| l.trim_end().ends_with(label))
        .map(|l| {
            l.split_whitespace()
                .next()
                .and_then(|n| n.parse::<u64>().ok())
                .unwrap_or_else(|| panic!("no count on {l:?}"))
        })
        .sum()
}

#[test]
fn the_scripts_account_for_evals_fish() {
    if !have_python() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (haul, out) = (dir.path().join("haul"), dir.path().join("out"));
    ok(Command::new(fishtrack())
        .arg("-q")
        .arg("synth")
        .arg(&haul)
        .args(["--size", "512", "--frames", "12", "--seed", "11"]));
    ok(Command::new(fishtrack())
        .env("FISHTRACK_STEREO_DIAG", "1")
        .arg("-q")
        .arg("track")
        .arg(&haul)
        .arg("--out")
        .arg(&out));
    assert!(out.join("stereo_diag.csv").is_file());
    let eval: serde_json::Value = serde_json::from_str(&ok(Command::new(fishtrack())
        .arg("-q")
        .arg("eval")
        .arg(&haul)
        .arg(&out)
        .arg("--json")))
    .unwrap();
    let measurable = eval["tracking"]["length"]["measurable"].as_u64().unwrap();
    let measured = eval["tracking"]["length"]["measured"].as_u64().unwrap();
    let det = &eval["segmentation"]["detection"];
    let countable = det["tp"].as_u64().unwrap() + det["fn_"].as_u64().unwrap();
    assert!(
        measurable > 0 && countable > 0,
        "a haul without fish: {eval}"
    );

    // length_accounting.py: every measurable fish in exactly one class
    let la = ok(Command::new("python3")
        .arg(script("length_accounting.py"))
        .arg(&haul)
        .arg(&out));
    let head = format!("measurable fish: {measurable}");
    assert!(la.contains(&head), "expected {head:?} in\n{la}");
    let classes: u64 = la
        .lines()
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .map(|l| l.split_whitespace().next().unwrap().parse::<u64>().unwrap())
        .sum();
    assert_eq!(classes, measurable, "{la}");
    // its matching is eval's: the same fish are measured
    assert_eq!(count(&la, "measured"), measured, "{la}");

    // intensity_seed_probe.py: every countable fish-frame once
    let probe = ok(Command::new("python3")
        .arg(script("intensity_seed_probe.py"))
        .args(["10", "8"])
        .arg(&haul)
        .arg(out.join("detections.csv")));
    let frames: u64 = [
        "detected",
        "detected, candidate",
        "missed",
        "missed, candidate",
    ]
    .iter()
    .map(|l| count(&probe, l))
    .sum();
    assert_eq!(frames, countable, "{probe}");
    let detected = count(&probe, "detected") + count(&probe, "detected, candidate");
    assert!(
        detected.abs_diff(det["tp"].as_u64().unwrap()) <= 2,
        "detected {detected} vs eval tp {}\n{probe}",
        det["tp"]
    );

    // track_failures.py: every fish with a countable frame in one class,
    // its successes eval's, its linking ceiling a count of those fish (not
    // a bound on the successes: a track's predicted rows may match a fish
    // in frames no detection does)
    let tf = ok(Command::new("python3")
        .arg(script("track_failures.py"))
        .arg(&haul)
        .arg(&out));
    let success = &eval["tracking"]["success"];
    let fish = success["fish"].as_u64().unwrap();
    let classes: u64 = tf
        .lines()
        .filter(|l| l.contains('%'))
        .map(|l| l.split_whitespace().next().unwrap().parse::<u64>().unwrap())
        .sum();
    assert_eq!(classes, fish, "{tf}");
    let labelled = success["correctly_labelled"].as_u64().unwrap();
    assert_eq!(count(&tf, "success"), labelled, "{tf}");
    let ceiling = count(
        &tf,
        "linking ceiling (fish an ideal linker of the detections would label)",
    );
    assert!(ceiling > 0 && ceiling <= fish, "{tf}");
}
