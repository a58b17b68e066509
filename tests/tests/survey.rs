//! A survey through the CLI: several hauls in one `fishtrack track` run
//! (one folder each plus `survey.csv`), and interrupted runs (SIGKILL,
//! SIGINT) that leave no file that looks complete but is not, with a rerun
//! giving the same bytes as an uninterrupted run.

use fishtrack_tests::{fishtrack, path_str as s, run_fishtrack as run, text};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

#[track_caller]
fn ok(out: &Output) {
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

fn synth(dir: &Path, seed: u32, size: u32, frames: u32) {
    let (seed, size, frames) = (seed.to_string(), size.to_string(), frames.to_string());
    ok(&run(&[
        "synth",
        s(dir),
        "--seed",
        &seed,
        "--size",
        &size,
        "--frames",
        &frames,
    ]));
}

/// Every regular file under `dir` (relative path → bytes); hidden
/// temporary files are listed separately.
fn tree(dir: &Path) -> (BTreeMap<String, Vec<u8>>, Vec<String>) {
    let mut files = BTreeMap::new();
    let mut hidden = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
            if e.file_name().to_string_lossy().starts_with('.') {
                hidden.push(rel);
            } else if let Ok(b) = std::fs::read(&p) {
                files.insert(rel, b);
            }
        }
    }
    (files, hidden)
}

/// `summary.json` without what legitimately differs between runs (timings).
fn summary_sans_timings(bytes: &[u8]) -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_slice(bytes).unwrap();
    let m = v.as_object_mut().unwrap();
    m.remove("timings_ms_per_frame");
    m.remove("timings_total_s");
    v
}

/// Files of `got` equal those of `want` (summary.json up to timings).
#[track_caller]
fn assert_same(got: &BTreeMap<String, Vec<u8>>, want: &BTreeMap<String, Vec<u8>>) {
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>()
    );
    for (k, v) in got {
        if k.ends_with("summary.json") {
            assert_eq!(
                summary_sans_timings(v),
                summary_sans_timings(&want[k]),
                "{k}"
            );
        } else {
            assert!(v == &want[k], "{k} differs");
        }
    }
}

fn fish_lengths(fish_csv: &Path) -> (usize, Vec<f64>) {
    let t = std::fs::read_to_string(fish_csv).unwrap();
    let rows: Vec<&str> = t.lines().skip(1).collect();
    let lengths = rows
        .iter()
        .filter_map(|r| r.split(',').nth(4).filter(|v| !v.is_empty()))
        .map(|v| v.parse::<f64>().unwrap())
        .collect();
    (rows.len(), lengths)
}

#[test]
fn several_hauls_one_folder_each_and_a_survey_table() {
    let t = tempfile::tempdir().unwrap();
    let (a, b) = (t.path().join("hauls/tow_a"), t.path().join("hauls/tow_b"));
    synth(&a, 1, 256, 6);
    synth(&b, 2, 256, 6);
    let out = t.path().join("survey");
    let o = run(&["track", s(&a), s(&b), "--out", s(&out), "--overlays"]);
    ok(&o);

    // survey.csv against each folder's own fish.csv, recomputed here
    let table = std::fs::read_to_string(out.join("survey.csv")).unwrap();
    let mut lines = table.lines();
    assert_eq!(
        lines.next(),
        Some("haul,fish_count,length_mean_mm,length_sd_mm,fish_measured,frames")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2);
    for (row, name) in rows.iter().zip(["tow_a", "tow_b"]) {
        assert_eq!(row[0], name);
        let dir = out.join(name);
        assert!(dir.join("summary.json").is_file() && dir.join("overlays/000006.png").is_file());
        let (count, lengths) = fish_lengths(&dir.join("fish.csv"));
        assert_eq!(row[1].parse::<usize>().unwrap(), count);
        assert_eq!(row[4].parse::<usize>().unwrap(), lengths.len());
        assert_eq!(row[5], "6");
        let n = lengths.len() as f64;
        if !lengths.is_empty() {
            let mean = lengths.iter().sum::<f64>() / n;
            assert!(
                (row[2].parse::<f64>().unwrap() - mean).abs() < 2e-3,
                "{row:?}"
            );
            if lengths.len() > 1 {
                let sd =
                    (lengths.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
                assert!(
                    (row[3].parse::<f64>().unwrap() - sd).abs() < 2e-3,
                    "{row:?}"
                );
            }
        }
    }

    // each folder is what tracking that haul alone gives (parallel runs do
    // not interfere)
    let alone = t.path().join("alone");
    ok(&run(&["track", s(&b), "--out", s(&alone), "--overlays"]));
    assert_same(&tree(&out.join("tow_b")).0, &tree(&alone).0);

    // two hauls with the same name would share a folder: refused, named
    let c = t.path().join("other/tow_a");
    synth(&c, 3, 256, 2);
    let o = run(&["track", s(&a), s(&c), "--out", s(&t.path().join("dup"))]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("other/tow_a") && err.contains("hauls/tow_a"),
        "{err}"
    );

    // a bad haul among good ones: the others complete, no survey.csv, exit 2
    let bad = t.path().join("hauls/tow_bad");
    synth(&bad, 4, 256, 2);
    std::fs::write(bad.join("left/000002.png"), b"").unwrap();
    let out2 = t.path().join("survey2");
    let o = run(&["track", s(&a), s(&bad), "--out", s(&out2)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("tow_bad/left/000002.png"));
    assert!(out2.join("tow_a/summary.json").is_file());
    assert!(!out2.join("survey.csv").exists());
}

/// Starts `track` into `out`, waits until it has written `trigger` (a file
/// relative to `out`), then sends `signal`. Returns whether the process was
/// still running when signalled.
fn interrupt(haul: &Path, out: &Path, trigger: &str, signal: &str) -> bool {
    let mut child = Command::new(fishtrack())
        .args(["track", s(haul), "--out", s(out), "--overlays"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let running = loop {
        if out.join(trigger).exists() {
            break child.try_wait().unwrap().is_none();
        }
        if child.try_wait().unwrap().is_some() || start.elapsed() > Duration::from_secs(300) {
            break false;
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    let pid = child.id().to_string();
    // the shell's built-in `kill` (no procps needed)
    let _ = Command::new("sh")
        .args(["-c", &format!("kill {signal} {pid}")])
        .status();
    let _ = child.wait();
    running
}

#[test]
fn interrupted_runs_leave_nothing_that_looks_complete_and_rerun_identically() {
    let t = tempfile::tempdir().unwrap();
    let haul = t.path().join("haul");
    synth(&haul, 5, 320, 16);
    let reference = t.path().join("reference");
    ok(&run(&[
        "track",
        s(&haul),
        "--out",
        s(&reference),
        "--overlays",
    ]));
    let (want, want_hidden) = tree(&reference);
    assert!(want_hidden.is_empty(), "{want_hidden:?}");
    assert!(want.contains_key("overlays/000016.png"));

    let mut interrupted_mid_way = 0;
    // Kill points: while the CSVs are written, while the overlays are
    // written; SIGKILL and SIGINT (Ctrl-C); into a fresh folder and over a
    // previous complete run.
    for (i, (trigger, signal, over_previous)) in [
        ("tracks.csv", "-KILL", false),
        ("overlays/000003.png", "-KILL", false),
        ("overlays/000002.png", "-INT", true),
        ("fish.csv", "-KILL", true),
    ]
    .into_iter()
    .enumerate()
    {
        let out = t.path().join(format!("run{i}"));
        if over_previous {
            ok(&run(&["track", s(&haul), "--out", s(&out), "--overlays"]));
            // the previous run's files exist under the trigger's name, so
            // wait for the new run to delete the marker first
            std::fs::remove_file(out.join(trigger)).unwrap();
        }
        let mid = interrupt(&haul, &out, trigger, signal);
        let (got, _hidden) = tree(&out);
        if mid && !got.contains_key("summary.json") {
            interrupted_mid_way += 1;
        }
        // Every file present under its final name is complete: byte-equal
        // to the uninterrupted run's. The marker is present only if
        // everything is.
        for (k, v) in &got {
            assert!(want.contains_key(k), "{k}: unexpected file");
            if k != "summary.json" {
                assert!(v == &want[k], "run {i}: {k} is not the complete file");
            }
        }
        if got.contains_key("summary.json") {
            assert_same(&got, &want);
        }
        // Rerun: same bytes, no temporary files left.
        ok(&run(&["track", s(&haul), "--out", s(&out), "--overlays"]));
        let (again, hidden) = tree(&out);
        assert!(hidden.is_empty(), "run {i}: leftovers {hidden:?}");
        assert_same(&again, &want);
    }
    eprintln!("{interrupted_mid_way} of 4 runs were interrupted before completing");
    assert!(
        interrupted_mid_way >= 2,
        "the kills came too late to test anything"
    );
}
