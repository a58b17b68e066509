//! `fishtrack eval` of the truth itself written as a tracker output scores
//! 1.0 everywhere; known degradations change the scores by exactly the
//! expected amounts. Small truths are built by hand here.

mod common;

use std::io::Write;
use std::path::Path;

use fishtrack::eval::{self, io::STEREO_HEADER, metrics, Report, TruthFrames};
use fishtrack::truth::{Truth, TruthFish, TruthFrame, TRUTH_VERSION};

const W: u32 = 2048; // θ_A^L = 2000 px

/// Four fish at well-separated heights swimming towards −x, 300×80 px boxes.
/// The first frame of each fish is an entry: visible area 1000 px (< θ_A^L,
/// not countable) and not wholly inside either view. Spans: fish 1 frames
/// 1–8, fish 2 2–9, fish 3 3–6, fish 4 5–10 → 22 countable fish-frames.
fn truth() -> Truth {
    let spans = [(1u32, 8u32), (2, 9), (3, 6), (5, 10)];
    let lengths = [350.0, 420.0, 515.0, 610.0];
    let fish = spans
        .iter()
        .enumerate()
        .map(|(i, &(a, b))| TruthFish {
            id: i as u32 + 1,
            length_mm: lengths[i],
            tail_reflectivity: 0.5,
            frames: (a..=b)
                .map(|f| {
                    let x = 1700.0 - 150.0 * (f - a) as f64;
                    let y = 100.0 + 450.0 * i as f64;
                    let entry = f == a;
                    let yc = y + 40.0;
                    TruthFrame {
                        frame: f,
                        left_box: Some([x, y, 300.0, 80.0]),
                        right_box: Some([x - 120.0, y, 300.0, 80.0]),
                        left_area: if entry { 1000.0 } else { 20000.0 },
                        right_area: if entry { 1000.0 } else { 20000.0 },
                        left_visible_fraction: if entry { 0.05 } else { 1.0 },
                        right_visible_fraction: if entry { 0.05 } else { 1.0 },
                        inside_left: !entry,
                        inside_right: !entry,
                        head_mm: [0.0, 0.0, 2000.0],
                        tail_mm: [lengths[i], 0.0, 2000.0],
                        head_px_left: Some([x, yc]),
                        tail_px_left: Some([x + 300.0, yc]),
                    }
                })
                .collect(),
        })
        .collect();
    Truth {
        version: TRUTH_VERSION,
        seed: 0,
        width: W,
        height: W,
        fps: 5.0,
        frames: 10,
        fish,
    }
}

/// A tracker output row: (frame, track id, box).
type Row = (u32, i64, [f64; 4]);

/// The truth's own left boxes as tracks (fish id = track id), every frame
/// that has a left box — including the non-countable entries.
fn truth_tracks(t: &Truth) -> Vec<Row> {
    let mut rows: Vec<Row> = t
        .fish
        .iter()
        .flat_map(|f| {
            f.frames
                .iter()
                .filter_map(move |a| a.left_box.map(|b| (a.frame, f.id as i64, b)))
        })
        .collect();
    rows.sort_by_key(|r| r.0);
    rows
}

fn write(path: &Path, text: &str) {
    std::fs::File::create(path)
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
}

fn write_tracks(dir: &Path, rows: &[Row]) {
    let s: String = rows
        .iter()
        .map(|(f, id, b)| format!("{f},{id},{},{},{},{},1,-1,-1,-1\n", b[0], b[1], b[2], b[3]))
        .collect();
    write(&dir.join("tracks.csv"), &s);
}

/// fish.csv: one row per (track id, length) with frames from `rows`.
fn write_fish(dir: &Path, rows: &[Row], lengths: &[(i64, Option<f64>)]) {
    let mut s =
        String::from("track_id,first_frame,last_frame,frames,length_mm,length_sd_mm,range_mm\n");
    for &(id, len) in lengths {
        let fr: Vec<u32> = rows.iter().filter(|r| r.1 == id).map(|r| r.0).collect();
        let (a, b) = (
            fr.iter().min().copied().unwrap_or(1),
            fr.iter().max().copied().unwrap_or(1),
        );
        let l = len.map_or(String::new(), |l| l.to_string());
        s += &format!("{id},{a},{b},{},{l},1.0,2000\n", fr.len());
    }
    write(&dir.join("fish.csv"), &s);
}

fn true_lengths(t: &Truth, scale: f64) -> Vec<(i64, Option<f64>)> {
    t.fish
        .iter()
        .map(|f| (f.id as i64, Some(f.length_mm * scale)))
        .collect()
}

/// detections.csv from the truth boxes; `length_px` column if asked.
fn write_detections(dir: &Path, t: &Truth, with_length: bool) {
    let mut s = String::new();
    for f in &t.fish {
        for a in &f.frames {
            let b = a.left_box.unwrap();
            s += &format!(
                "{},-1,{},{},{},{},1,-1,-1,-1",
                a.frame, b[0], b[1], b[2], b[3]
            );
            if with_length {
                let (h, tl) = (a.head_px_left.unwrap(), a.tail_px_left.unwrap());
                s += &format!(
                    ",{}",
                    ((h[0] - tl[0]).powi(2) + (h[1] - tl[1]).powi(2)).sqrt()
                );
            }
            s += "\n";
        }
    }
    write(&dir.join("detections.csv"), &s);
}

/// stereo.csv from the truth: left/right boxes, 3-D points, length × scale.
fn write_stereo(dir: &Path, t: &Truth, scale: f64, mispair: Option<(u32, u32)>) {
    let mut s = STEREO_HEADER.join(",") + "\n";
    for f in &t.fish {
        for a in &f.frames {
            let l = a.left_box.unwrap();
            let mut r = a.right_box.unwrap();
            if mispair == Some((f.id, a.frame)) {
                r[1] += 450.0; // the right box of the fish below
            }
            let (h, tl) = (a.head_mm, a.tail_mm);
            s += &format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                a.frame,
                l[0],
                l[1],
                l[2],
                l[3],
                r[0],
                r[1],
                r[2],
                r[3],
                h[0],
                h[1],
                h[2],
                tl[0],
                tl[1],
                tl[2],
                f.length_mm * scale
            );
        }
    }
    write(&dir.join("stereo.csv"), &s);
}

/// Writes a full tracker output (tracks, fish, detections, stereo).
fn perfect_output(dir: &Path, t: &Truth) {
    let rows = truth_tracks(t);
    write_tracks(dir, &rows);
    write_fish(dir, &rows, &true_lengths(t, 1.0));
    write_detections(dir, t, true);
    write_stereo(dir, t, 1.0, None);
}

fn eval(t: &Truth, dir: &Path) -> Report {
    eval::evaluate_truth(t, dir).unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

const N_COUNTABLE: f64 = 22.0;

#[test]
fn truth_as_output_scores_one_everywhere() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    let r = eval(&t, dir.path());
    assert_eq!(r.countable_fish, 4);
    assert_eq!(r.area_min_px, 2000.0);
    let tr = r.tracking.as_ref().unwrap();
    let d = &tr.detection;
    assert_eq!(
        (d.tp, d.fp, d.fn_, d.ignored),
        (22, 0, 0, 4),
        "entries ignored"
    );
    for v in [
        d.precision,
        d.recall,
        d.mean_frame_precision,
        d.mean_frame_recall,
    ] {
        assert_eq!(v, 1.0);
    }
    assert_eq!(
        (tr.mot.mota, tr.mot.idf1, tr.mot.num_switches),
        (1.0, 1.0, 0)
    );
    assert_eq!(tr.mot.num_objects as f64, N_COUNTABLE);
    assert_eq!(tr.success.rate, 1.0);
    let d = tr.success_detected.as_ref().unwrap();
    assert_eq!((d.correctly_labelled, d.fish, d.rate), (4, 4, 1.0));
    assert_eq!(tr.count.error, 0.0);
    let l = tr.length.as_ref().unwrap();
    assert_eq!((l.mape, l.fraction_measured, l.measurable), (0.0, 1.0, 4));
    let s = r.segmentation.as_ref().unwrap();
    assert_eq!((s.detection.precision, s.detection.recall), (1.0, 1.0));
    let lt = s.large_target_length.as_ref().unwrap();
    assert_eq!(
        (lt.mape, lt.fraction_measured, lt.measurable),
        (0.0, 1.0, 22)
    );
    let st = r.stereo.as_ref().unwrap();
    assert_eq!(
        (st.pairing_accuracy, st.length.mape, st.fish_frames),
        (1.0, 0.0, 22)
    );
    // The table and JSON render.
    println!("{}", r.table());
    assert!(r.table().contains("MOTA"));
    let j: serde_json::Value = serde_json::from_str(&r.json()).unwrap();
    assert_eq!(j["tracking"]["mot"]["mota"], 1.0);
}

#[test]
fn dropped_frames_lower_recall_by_exactly_k_over_n() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    // Drop frames 4 and 7: countable fish-frames there: frame 4 → fish 1, 2, 3
    // (3); frame 7 → fish 1, 2, 4 (3). k = 6 of N = 22.
    let rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .filter(|r| r.0 != 4 && r.0 != 7)
        .collect();
    write_tracks(dir.path(), &rows);
    let r = eval(&t, dir.path());
    let tr = r.tracking.unwrap();
    let k = 6.0;
    assert!(
        close(tr.detection.recall, 1.0 - k / N_COUNTABLE),
        "{}",
        tr.detection.recall
    );
    assert_eq!(tr.detection.precision, 1.0);
    // 9 frames hold countable fish (2..=10); two of them now have recall 0.
    assert!(close(tr.detection.mean_frame_recall, 7.0 / 9.0));
    assert!(close(tr.mot.mota, 1.0 - k / N_COUNTABLE));
    assert_eq!(tr.mot.num_switches, 0);
    // Fish 3 (countable 4, 5, 6) keeps 2 of 3 ≥ half: every fish still correct.
    assert_eq!(tr.success.rate, 1.0);
}

#[test]
fn swapped_ids_mid_track_add_two_switches() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    // Fish 1 and 2 exchange track ids from frame 5 on.
    let rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .map(|(f, id, b)| match (f >= 5, id) {
            (true, 1) => (f, 2, b),
            (true, 2) => (f, 1, b),
            _ => (f, id, b),
        })
        .collect();
    write_tracks(dir.path(), &rows);
    let r = eval(&t, dir.path());
    let tr = r.tracking.as_ref().unwrap();
    assert_eq!(tr.mot.num_switches, 2);
    assert!(close(tr.mot.mota, 1.0 - 2.0 / N_COUNTABLE));
    assert_eq!((tr.detection.precision, tr.detection.recall), (1.0, 1.0));
    // Fish 1 and 2 each carry two ids that the other shares: 2 of 4 correct.
    assert_eq!(tr.success.correctly_labelled, 2);
    assert_eq!(tr.success.rate, 0.5);
    // IDF1: fish 1 keeps id 2 for its countable frames 5–8 (4 of 7), fish 2
    // keeps id 1 for 5–9 (5 of 7) or the other way round: the global
    // matching picks the better total, 4 + 5 = 9 > 3 + 2; the others are
    // perfect: IDTP = 9 + 3 + 5 = 17 of 22 → IDF1 = 17/22.
    assert!(close(tr.mot.idf1, 17.0 / 22.0), "{}", tr.mot.idf1);
}

#[test]
fn jitter_within_iou_04_changes_nothing_and_beyond_gives_fn_and_fp() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    // Shift every box by 30 % of its width: IoU = 0.7 / 1.3 ≈ 0.54 ≥ 0.4.
    let rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .map(|(f, id, b)| (f, id, [b[0] + 0.3 * b[2], b[1], b[2], b[3]]))
        .collect();
    write_tracks(dir.path(), &rows);
    let tr = eval(&t, dir.path()).tracking.unwrap();
    assert_eq!((tr.detection.precision, tr.detection.recall), (1.0, 1.0));
    assert_eq!((tr.mot.mota, tr.mot.idf1, tr.success.rate), (1.0, 1.0, 1.0));
    // Now fish 2 in frame 5 by 50 %: IoU = 0.5 / 1.5 = 0.33 < 0.4 → 1 FN + 1 FP.
    let rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .map(|(f, id, b)| {
            let s = if (f, id) == (5, 2) { 0.5 } else { 0.3 };
            (f, id, [b[0] + s * b[2], b[1], b[2], b[3]])
        })
        .collect();
    write_tracks(dir.path(), &rows);
    let tr = eval(&t, dir.path()).tracking.unwrap();
    let d = &tr.detection;
    assert_eq!((d.tp, d.fp, d.fn_), (21, 1, 1));
    assert!(close(d.precision, 21.0 / 22.0) && close(d.recall, 21.0 / 22.0));
    assert!(close(tr.mot.mota, 1.0 - 2.0 / N_COUNTABLE));
    assert_eq!(
        tr.success.rate, 1.0,
        "one miss keeps fish 2 matched in ≥ half its frames"
    );
}

#[test]
fn lengths_scaled_by_1_05_give_mape_of_exactly_5_percent() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    let rows = truth_tracks(&t);
    write_fish(dir.path(), &rows, &true_lengths(&t, 1.05));
    write_stereo(dir.path(), &t, 1.05, None);
    let r = eval(&t, dir.path());
    let l = r.tracking.unwrap().length.unwrap();
    assert!(close(l.mape, 0.05), "{}", l.mape);
    assert_eq!(l.fraction_measured, 1.0);
    assert!(close(r.stereo.unwrap().length.mape, 0.05));
    // One fish unmeasured (empty length_mm): 3 of 4 measured, MAPE over those.
    let mut lengths = true_lengths(&t, 1.05);
    lengths[2].1 = None;
    write_fish(dir.path(), &rows, &lengths);
    let l = eval(&t, dir.path()).tracking.unwrap().length.unwrap();
    assert_eq!((l.measured, l.measurable), (3, 4));
    assert!(close(l.fraction_measured, 0.75) && close(l.mape, 0.05));
}

#[test]
fn count_error_counts_extra_tracks() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    // Fish 4 split into tracks 4 and 9 (frame 8 on): 5 tracks for 4 fish.
    let rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .map(|(f, id, b)| {
            if id == 4 && f >= 8 {
                (f, 9, b)
            } else {
                (f, id, b)
            }
        })
        .collect();
    write_tracks(dir.path(), &rows);
    let mut lengths = true_lengths(&t, 1.0);
    lengths.push((9, Some(610.0)));
    write_fish(dir.path(), &rows, &lengths);
    let tr = eval(&t, dir.path()).tracking.unwrap();
    assert_eq!((tr.count.tracks, tr.count.fish), (5, 4));
    assert!(close(tr.count.error, 0.25));
    // Fish 4 (countable 6–10) has ids 4 and 9: not correctly labelled.
    assert_eq!(tr.success.rate, 0.75);
    // Without fish.csv the count uses distinct ids of tracks.csv.
    std::fs::remove_file(dir.path().join("fish.csv")).unwrap();
    let tr = eval(&t, dir.path()).tracking.unwrap();
    assert!(close(tr.count.error, 0.25) && tr.length.is_none());
}

#[test]
fn segmentation_and_stereo_degradations() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    perfect_output(dir.path(), &t);
    // Without the length column: max(w, h) = 300 = the horizontal pixel length.
    write_detections(dir.path(), &t, false);
    let s = eval(&t, dir.path()).segmentation.unwrap();
    assert_eq!(s.large_target_length.unwrap().mape, 0.0);
    assert_eq!(s.length_source, "max(w, h) of the box");
    // One mispaired fish-frame out of 22 wholly inside both views.
    write_stereo(dir.path(), &t, 1.0, Some((2, 5)));
    let st = eval(&t, dir.path()).stereo.unwrap();
    assert_eq!((st.correctly_paired, st.fish_frames), (21, 22));
    assert_eq!((st.detected, st.wrongly_paired, st.unpaired), (22, 1, 0));
    assert!((st.pairing_accuracy_detected - 21.0 / 22.0).abs() < 1e-12);
    // Of the mispaired file's rows, drop one wholly-visible fish-frame (not
    // segmented) and unpair another: 22 fish-frames, 21 detected, 1 wrong,
    // 1 unpaired, 19 correct.
    let text = std::fs::read_to_string(dir.path().join("stereo.csv")).unwrap();
    let (header, body) = text.split_once('\n').unwrap();
    let mut lines: Vec<String> = body.lines().map(String::from).collect();
    let st_rows = fishtrack::eval::io::read_stereo(&dir.path().join("stereo.csv")).unwrap();
    let inside: Vec<usize> = (0..st_rows.len())
        .filter(|&k| {
            let r = &st_rows[k];
            let l = r.left();
            let right = r.right().unwrap();
            // the mispaired row (moved by 450 px) is left alone
            t.fish.iter().any(|f| {
                f.frames.iter().any(|a| {
                    a.frame == r.frame
                        && a.inside_left
                        && a.inside_right
                        && a.left_box == Some(l)
                        && a.right_box == Some(right)
                })
            })
        })
        .collect();
    let (unpair, drop) = (inside[0], inside[1]);
    let mut f: Vec<&str> = lines[unpair].split(',').collect();
    for v in f.iter_mut().skip(5) {
        *v = "";
    }
    lines[unpair] = f.join(",");
    lines.remove(drop);
    std::fs::write(
        dir.path().join("stereo.csv"),
        format!("{header}\n{}\n", lines.join("\n")),
    )
    .unwrap();
    let st = eval(&t, dir.path()).stereo.unwrap();
    assert_eq!(
        (
            st.fish_frames,
            st.detected,
            st.correctly_paired,
            st.wrongly_paired,
            st.unpaired
        ),
        (22, 21, 19, 1, 1)
    );
    assert!((st.pairing_accuracy - 19.0 / 22.0).abs() < 1e-12);
    assert!((st.pairing_accuracy_detected - 19.0 / 21.0).abs() < 1e-12);
}

#[test]
fn eval_mot_figures_agree_with_motmetrics_on_degraded_outputs() {
    if !common::have_motmetrics() {
        return;
    }
    let t = truth();
    let tf = TruthFrames::new(&t).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Swap + drop + jitter + a false positive, all at once.
    let mut rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .filter(|r| r.0 != 3)
        .map(|(f, id, b)| match (f >= 6, id) {
            (true, 1) => (f, 2, b),
            (true, 2) => (f, 1, b),
            _ => (f, id, [b[0] + 0.25 * b[2], b[1] + 7.0, b[2], b[3]]),
        })
        .collect();
    rows.push((6, 77, [900.0, 1900.0, 120.0, 60.0]));
    write_tracks(dir.path(), &rows);
    let tr = eval(&t, dir.path()).tracking.unwrap();
    let tracks = eval::io::read_mot(&dir.path().join("tracks.csv")).unwrap();
    let inputs = metrics::mot_inputs(&tf, &tracks);
    assert_eq!(inputs.summarize(0.6), tr.mot);
    let theirs = common::oracle_on_inputs(dir.path(), &inputs, 0.6);
    common::assert_agree("degraded truth", &tr.mot, &theirs, 1e-6);
    println!(
        "degraded truth: MOTA {} IDF1 {} IDSW {} | motmetrics {} {} {}",
        tr.mot.mota,
        tr.mot.idf1,
        tr.mot.num_switches,
        theirs["mota"],
        theirs["idf1"],
        theirs["num_switches"]
    );
}

/// A haul holding only the test truth, and an output directory holding
/// its perfect tracker output (for runs of the `fishtrack` binary).
fn cli_haul() -> (tempfile::TempDir, tempfile::TempDir) {
    let t = truth();
    let haul = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    write(
        &haul.path().join("truth.json"),
        &serde_json::to_string(&t).unwrap(),
    );
    perfect_output(out.path(), &t);
    (haul, out)
}

#[test]
fn cli_eval_prints_table_and_json_and_rejects_bad_input() {
    let (haul, out) = cli_haul();
    let bin = env!("CARGO_BIN_EXE_fishtrack");
    let run = |json: bool| {
        let mut c = std::process::Command::new(bin);
        c.arg("eval").arg(haul.path()).arg(out.path());
        if json {
            c.arg("--json");
        }
        c.output().unwrap()
    };
    let o = run(false);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("success rate"));
    let o = run(true);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["tracking"]["success"]["rate"], 1.0);
    // A bad row: exit code 2, message names file and line.
    write(
        &out.path().join("tracks.csv"),
        "1,1,10,10,5,5,1,-1,-1,-1\n1,1,oops,10,5,5,1,-1,-1,-1\n",
    );
    let o = run(false);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("tracks.csv: line 2") && err.contains("bb_left"),
        "{err}"
    );
    // A duplicate id in one frame.
    write(
        &out.path().join("tracks.csv"),
        "1,1,10,10,5,5\n1,1,20,10,5,5\n",
    );
    let o = run(false);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("appears twice in frame 1"));
}

/// `fishtrack eval --json | head -1`: the reader closes the pipe before the
/// report is written. The program must neither panic ("failed printing to
/// stdout") nor fail; a bad output directory still fails with its error.
#[test]
fn cli_eval_into_a_closed_pipe_ends_quietly() {
    use std::process::{Command, Stdio};
    let (haul, out) = cli_haul();
    let bin = env!("CARGO_BIN_EXE_fishtrack");
    let run = |out_dir: &std::path::Path| {
        let mut child = Command::new(bin)
            .arg("eval")
            .arg("--json")
            .arg(haul.path())
            .arg(out_dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // close the reading end before the program writes anything
        drop(child.stdout.take());
        child.wait_with_output().unwrap()
    };
    let o = run(out.path());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{:?}: {err}", o.status);
    assert!(!err.contains("panicked"), "{err}");
    // the closed pipe does not hide an input error
    let empty = tempfile::tempdir().unwrap();
    let o = run(empty.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("tracks.csv"));
}

/// Eq. (16) among the detected fish: a fish the detections never found
/// leaves the population of `success_detected` but not that of `success`;
/// one found in under half of its countable frames leaves it too; a split
/// fish stays in both and fails both.
#[test]
fn success_among_detected_fish_drops_the_undetected_from_the_population() {
    let t = truth();
    let dir = tempfile::tempdir().unwrap();
    // tracks: the truth's, but fish 4 split over two ids
    let rows: Vec<Row> = truth_tracks(&t)
        .into_iter()
        .map(|(f, id, b)| (f, if id == 4 && f >= 8 { 40 } else { id }, b))
        .collect();
    write_tracks(dir.path(), &rows);
    // detections: none of fish 1; fish 2 in 3 of its 7 countable frames
    // (3–5), every other fish in every frame
    let mut s = String::new();
    for f in &t.fish {
        for a in &f.frames {
            let keep = match f.id {
                1 => false,
                2 => (2..=5).contains(&a.frame),
                _ => true,
            };
            if keep {
                let b = a.left_box.unwrap();
                s += &format!(
                    "{},-1,{},{},{},{},1,-1,-1,-1\n",
                    a.frame, b[0], b[1], b[2], b[3]
                );
            }
        }
    }
    write(&dir.path().join("detections.csv"), &s);
    let r = eval(&t, dir.path());
    let tr = r.tracking.unwrap();
    // every countable fish: 1, 2, 3 labelled, 4 split
    assert_eq!((tr.success.correctly_labelled, tr.success.fish), (3, 4));
    // detected (in at least half of their countable frames): fish 3 and 4
    let d = tr.success_detected.unwrap();
    assert_eq!((d.correctly_labelled, d.fish), (1, 2), "{d:?}");
    assert!(close(d.rate, 0.5));
    // without detections.csv there is no such score
    std::fs::remove_file(dir.path().join("detections.csv")).unwrap();
    assert!(eval(&t, dir.path())
        .tracking
        .unwrap()
        .success_detected
        .is_none());
}
