//! `fishtrack track` end to end on a small synthetic haul (512², 15 frame
//! pairs): the output files exist and parse with eval's readers and agree
//! with each other, `fishtrack eval` scores them, a rerun is byte-identical,
//! several hauls go to one subfolder each, and bad input exits 2 naming
//! the file.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

use fishtrack::eval::io::{read_fish, read_mot, read_stereo};
use fishtrack_tests::{run_fishtrack as run, text};

const FRAMES: u32 = 15;
const FILES: [&str; 6] = [
    "tracks.csv",
    "fish.csv",
    "detections.csv",
    "detections.viame.csv",
    "stereo.csv",
    "summary.json",
];

fn os(s: &(impl AsRef<std::ffi::OsStr> + ?Sized)) -> &std::ffi::OsStr {
    s.as_ref()
}

/// The shared haul, synthesised once.
fn haul() -> &'static Path {
    static H: OnceLock<PathBuf> = OnceLock::new();
    H.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let h = dir.join("haul");
        let out = run(&[
            os("synth"),
            h.as_os_str(),
            os("--size"),
            os("512"),
            os("--frames"),
            os(&FRAMES.to_string()),
            os("--seed"),
            os("7"),
        ]);
        assert!(out.status.success(), "synth failed: {}", text(&out.stderr));
        h
    })
}

fn track(hauls: &[&Path], out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<&std::ffi::OsStr> = vec![os("track")];
    args.extend(hauls.iter().map(|h| h.as_os_str()));
    args.push(os("--out"));
    args.push(out.as_os_str());
    args.extend(extra.iter().map(os));
    run(&args)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(e.file_name()));
        } else {
            std::fs::copy(&p, to.join(e.file_name())).unwrap();
        }
    }
}

/// summary.json without its timings (the only clock-dependent part).
fn summary_without_timings(p: &Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let m = v.as_object_mut().unwrap();
    m.remove("timings_ms_per_frame");
    m.remove("timings_total_s");
    v
}

#[test]
fn track_writes_consistent_files_that_eval_reads_and_reruns_identically() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for o in [&a, &b] {
        let out = track(&[haul()], o, &[]);
        assert!(out.status.success(), "track failed: {}", text(&out.stderr));
    }
    for f in FILES {
        assert!(a.join(f).is_file(), "{f} missing");
    }
    // eval's readers accept every file
    let tracks = read_mot(&a.join("tracks.csv")).unwrap();
    let dets = read_mot(&a.join("detections.csv")).unwrap();
    let fish = read_fish(&a.join("fish.csv")).unwrap();
    let stereo = read_stereo(&a.join("stereo.csv")).unwrap();
    let summary = summary_without_timings(&a.join("summary.json"));

    // the synthetic haul has fish, and the pipeline sees some of them
    assert!(!dets.is_empty(), "no detections");
    assert!(!fish.is_empty(), "no fish counted");
    // frames within the haul, detections carry id −1, tracks one row per id and frame
    assert!(dets
        .iter()
        .all(|d| d.id == -1 && (1..=FRAMES).contains(&d.frame)));
    let mut seen = BTreeSet::new();
    for t in &tracks {
        assert!((1..=FRAMES).contains(&t.frame), "frame {}", t.frame);
        assert!(
            seen.insert((t.frame, t.id)),
            "id {} twice in frame {}",
            t.id,
            t.frame
        );
    }
    // one stereo row per left object
    assert_eq!(stereo.len(), dets.len());
    assert_eq!(
        summary["counts"]["left_objects"].as_u64().unwrap(),
        dets.len() as u64
    );
    // every fish is a track whose row count and frame span match fish.csv
    let mut rows: BTreeMap<i64, Vec<u32>> = BTreeMap::new();
    for t in &tracks {
        rows.entry(t.id).or_default().push(t.frame);
    }
    assert_eq!(
        rows.keys().copied().collect::<Vec<_>>(),
        fish.iter().map(|f| f.track_id).collect::<Vec<_>>()
    );
    for f in &fish {
        let fr = &rows[&f.track_id];
        assert_eq!(fr.len() as u32, f.frames, "track {}", f.track_id);
        assert!(f.first_frame >= *fr.iter().min().unwrap());
        assert!(f.last_frame <= *fr.iter().max().unwrap());
        assert!(f.first_frame <= f.last_frame);
        if let Some(l) = f.length_mm {
            assert!(l.is_finite() && l > 0.0, "length {l}");
        }
    }
    assert_eq!(summary["fish_count"].as_u64().unwrap(), fish.len() as u64);
    assert_eq!(summary["frames"].as_u64().unwrap(), FRAMES as u64);

    // eval scores the output
    let report = fishtrack::eval::evaluate(haul(), &a).unwrap();
    let t = report.tracking.as_ref().expect("tracking score");
    assert_eq!(t.count.tracks, fish.len() as u64);
    let out = run(&[os("eval"), haul().as_os_str(), a.as_os_str()]);
    assert!(out.status.success(), "eval failed: {}", text(&out.stderr));

    // rerun: byte-identical files (summary.json apart from its timings)
    for f in FILES.iter().filter(|f| **f != "summary.json") {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f} differs between runs"
        );
    }
    assert_eq!(summary, summary_without_timings(&b.join("summary.json")));
}

#[test]
fn several_hauls_go_to_one_subfolder_each() {
    let tmp = tempfile::tempdir().unwrap();
    let other = tmp.path().join("second");
    copy_dir(haul(), &other);
    let out_dir = tmp.path().join("out");
    let single = tmp.path().join("single");
    let out = track(&[haul(), &other], &out_dir, &["--tracker", "nn"]);
    assert!(out.status.success(), "track failed: {}", text(&out.stderr));
    let out = track(&[haul()], &single, &["--tracker", "nn"]);
    assert!(out.status.success(), "track failed: {}", text(&out.stderr));
    for sub in ["haul", "second"] {
        // same frames, same results
        assert_eq!(
            std::fs::read(out_dir.join(sub).join("tracks.csv")).unwrap(),
            std::fs::read(single.join("tracks.csv")).unwrap(),
            "{sub}"
        );
    }
}

#[test]
fn bad_input_exits_2_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    // missing calibration
    let nocal = tmp.path().join("nocal");
    copy_dir(haul(), &nocal);
    std::fs::remove_file(nocal.join("calibration.yml")).unwrap();
    let out = track(&[&nocal], &tmp.path().join("o1"), &[]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("calibration.yml"), "{err}");
    assert!(!tmp.path().join("o1").join("tracks.csv").exists());

    // a frame missing on one side
    let onesided = tmp.path().join("onesided");
    copy_dir(haul(), &onesided);
    std::fs::remove_file(onesided.join("right").join("000007.png")).unwrap();
    let out = track(&[&onesided], &tmp.path().join("o2"), &[]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("000007.png"), "{err}");

    // a corrupt frame: named with its frame number
    let corrupt = tmp.path().join("corrupt");
    copy_dir(haul(), &corrupt);
    std::fs::write(corrupt.join("left").join("000003.png"), b"not a png").unwrap();
    let out = track(&[&corrupt], &tmp.path().join("o3"), &[]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("000003.png") && err.contains("frame 3"),
        "{err}"
    );

    // unknown tracker
    let out = track(
        &[haul()],
        &tmp.path().join("o4"),
        &["--tracker", "hungarian"],
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("--tracker"));
    // --overlays: one picture per frame and the length-frequency plot
    let o5 = tmp.path().join("o5");
    let out = track(&[haul()], &o5, &["--overlays"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(o5.join("overlays/000001.png").is_file());
    assert!(o5.join("length_frequency.svg").is_file() && o5.join("length_frequency.png").is_file());
}
