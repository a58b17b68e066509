//! MOTA / IDF1 / ID switches (and every other CLEAR MOT and ID measure) of
//! `fishtrack::eval::mot` against py-motmetrics 1.4 on the same files:
//! randomized gt/pred pairs with id swaps, fragments, misses, false
//! positives and jitter around the IoU threshold, and the TUD-Campus
//! sequence shipped inside the motmetrics package (also against the figures
//! published in motmetrics' own test suite).

mod common;

use common::*;
use fishtrack::eval::metrics::MotInputs;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A random scene: `n` objects over `frames` frames with random spans,
/// velocities and occasional crossings; predictions are the boxes with
/// jitter (some beyond IoU 0.4), misses, false positives, id swaps between
/// pairs of objects, id fragments (fresh ids mid-track) and duplicate
/// tracks on the same object.
fn random_scene(seed: u64) -> MotInputs {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let frames = rng.random_range(20..60u32);
    let n = rng.random_range(3..16usize);
    let mut out = MotInputs::default();
    struct Obj {
        span: (u32, u32),
        p: [f64; 2],
        v: [f64; 2],
        size: [f64; 2],
        hyp: i64,
    }
    let mut objs: Vec<Obj> = (0..n)
        .map(|k| {
            let a = rng.random_range(1..frames);
            let b = rng.random_range(a..=frames);
            Obj {
                span: (a, b),
                p: [rng.random_range(0.0..300.0), rng.random_range(0.0..200.0)],
                v: [rng.random_range(-15.0..15.0), rng.random_range(-8.0..8.0)],
                size: [rng.random_range(20.0..120.0), rng.random_range(20.0..80.0)],
                hyp: 100 + k as i64,
            }
        })
        .collect();
    let mut next_hyp = 1000;
    let jitter = rng.random_range(0.05..0.35);
    let p_miss = rng.random_range(0.0..0.3);
    let p_fp = rng.random_range(0.0..0.5);
    let p_dup = rng.random_range(0.0..0.4);
    for f in 1..=frames {
        // Id swaps between two objects and fresh-id fragments.
        if rng.random_bool(0.25) {
            let i = rng.random_range(0..n);
            let j = rng.random_range(0..n);
            let t = objs[i].hyp;
            objs[i].hyp = objs[j].hyp;
            objs[j].hyp = t;
        }
        if rng.random_bool(0.05) {
            let i = rng.random_range(0..n);
            objs[i].hyp = next_hyp;
            next_hyp += 1;
        }
        let mut hyp_rows = Vec::new();
        for (k, o) in objs.iter_mut().enumerate() {
            o.p[0] += o.v[0] + rng.random_range(-3.0..3.0);
            o.p[1] += o.v[1] + rng.random_range(-3.0..3.0);
            if f < o.span.0 || f > o.span.1 {
                continue;
            }
            let b = [o.p[0], o.p[1], o.size[0], o.size[1]];
            out.gt.push((f, k as i64 + 1, b));
            if rng.random_bool(p_miss) {
                continue;
            }
            let j = |r: &mut ChaCha8Rng, s: f64| r.random_range(-jitter..jitter) * s;
            let h = [
                b[0] + j(&mut rng, b[2]),
                b[1] + j(&mut rng, b[3]),
                b[2] * (1.0 + j(&mut rng, 1.0)),
                b[3] * (1.0 + j(&mut rng, 1.0)),
            ];
            hyp_rows.push((f, o.hyp, h));
            // A duplicate track on the same object: sometimes it overlaps
            // better than the established one, which CLEAR MOT must keep.
            if rng.random_bool(p_dup) {
                let d = [
                    b[0] + j(&mut rng, b[2]),
                    b[1] + j(&mut rng, b[3]),
                    b[2] * (1.0 + j(&mut rng, 1.0)),
                    b[3] * (1.0 + j(&mut rng, 1.0)),
                ];
                hyp_rows.push((f, 5000 + k as i64, d));
            }
        }
        while rng.random_bool(p_fp) {
            let b = [
                rng.random_range(0.0..300.0),
                rng.random_range(0.0..200.0),
                rng.random_range(20.0..120.0),
                rng.random_range(20.0..80.0),
            ];
            hyp_rows.push((f, next_hyp, b));
            next_hyp += 1;
        }
        // Ids unique within a frame: a swap can leave two objects with one
        // id only if i == j, which is a no-op; drop any duplicate anyway.
        let mut seen = std::collections::HashSet::new();
        hyp_rows.retain(|r| seen.insert(r.1));
        // Shuffle row order within the frame.
        for i in (1..hyp_rows.len()).rev() {
            let k = rng.random_range(0..=i);
            hyp_rows.swap(i, k);
        }
        out.hyp.extend(hyp_rows);
    }
    out
}

#[test]
fn random_scenes_agree_with_motmetrics() {
    if !have_motmetrics() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut worst: f64 = 0.0;
    let (mut switches, mut objects) = (0.0, 0.0);
    let seeds: Vec<u64> = (1..=16).collect();
    let mut files = Vec::new();
    for &seed in &seeds {
        let scene = random_scene(seed);
        let g = dir.path().join(format!("gt{seed}.txt"));
        let p = dir.path().join(format!("pred{seed}.txt"));
        write_mot(&g, &scene.gt);
        write_mot(&p, &scene.hyp);
        files.push((g, p));
    }
    let oracles = [
        (0.6, oracle_many(&files, 0.6)),
        (0.5, oracle_many(&files, 0.5)),
    ];
    for (k, &seed) in seeds.iter().enumerate() {
        let (g, p) = &files[k];
        // Read back as motmetrics does (x, y − 1), so both sides see the same floats.
        let ours_in = MotInputs {
            gt: read_mot_like_motmetrics(g),
            hyp: read_mot_like_motmetrics(p),
        };
        for (max_d, results) in &oracles {
            let max_d = *max_d;
            let ours = ours_in.summarize(max_d);
            let theirs = &results[k];
            assert_agree(
                &format!("seed {seed}, max distance {max_d}"),
                &ours,
                theirs,
                1e-6,
            );
            for (_, o, t) in pairs(&ours, theirs) {
                if o.is_finite() {
                    worst = worst.max((o - t).abs());
                }
            }
            if max_d == 0.6 {
                switches += ours.num_switches as f64;
                objects += ours.num_objects as f64;
                println!(
                    "seed {seed:2}: MOTA {:.6} IDF1 {:.6} IDSW {:3} FP {:3} FN {:3} | motmetrics MOTA {:.6} IDF1 {:.6} IDSW {}",
                    ours.mota, ours.idf1, ours.num_switches, ours.num_false_positives, ours.num_misses,
                    theirs["mota"], theirs["idf1"], theirs["num_switches"]
                );
            }
        }
    }
    println!("random scenes: worst |ours − motmetrics| = {worst:e} over all metrics; {switches} switches in {objects} objects");
    assert!(switches > 50.0, "the scenes must exercise id switches");
}

fn tud_campus() -> (MotInputs, std::path::PathBuf, std::path::PathBuf) {
    let d = motmetrics_data_dir().join("TUD-Campus");
    let (g, p) = (d.join("gt.txt"), d.join("test.txt"));
    assert!(
        g.is_file() && p.is_file(),
        "TUD-Campus not found in {}",
        d.display()
    );
    let inputs = MotInputs {
        gt: read_mot_like_motmetrics(&g),
        hyp: read_mot_like_motmetrics(&p),
    };
    (inputs, g, p)
}

#[test]
fn tud_campus_agrees_with_motmetrics() {
    if !have_motmetrics() {
        return;
    }
    let (inputs, g, p) = tud_campus();
    for max_d in [0.6, 0.5] {
        let ours = inputs.summarize(max_d);
        let theirs = oracle(&g, &p, max_d);
        assert_agree(
            &format!("TUD-Campus, max distance {max_d}"),
            &ours,
            &theirs,
            1e-6,
        );
        let worst = pairs(&ours, &theirs)
            .iter()
            .map(|(_, o, t)| (o - t).abs())
            .fold(0.0, f64::max);
        println!(
            "TUD-Campus @ max distance {max_d}: MOTA {:.6} IDF1 {:.6} IDSW {} (motmetrics {:.6} {:.6} {}), worst diff {worst:e}",
            ours.mota, ours.idf1, ours.num_switches, theirs["mota"], theirs["idf1"], theirs["num_switches"]
        );
    }
}

/// The figures motmetrics' own test suite asserts for TUD-Campus
/// (`motmetrics/tests/test_metrics.py::test_motchallenge_files`, IoU
/// distance threshold 0.5), rounded there to 6 decimals. No Python needed.
#[test]
fn tud_campus_matches_published_figures() {
    if !have_motmetrics() {
        return; // the data ships inside the motmetrics package
    }
    let (inputs, _, _) = tud_campus();
    let s = inputs.summarize(0.5);
    let close = |name: &str, ours: f64, published: f64| {
        assert!(
            (ours - published).abs() <= 1e-6,
            "{name}: {ours} vs published {published}"
        );
    };
    close("IDF1", s.idf1, 0.557659);
    close("IDP", s.idp, 0.729730);
    close("IDR", s.idr, 0.451253);
    close("recall", s.recall, 0.582173);
    close("precision", s.precision, 0.941441);
    close("MOTA", s.mota, 0.526462);
    close("MOTP", s.motp, 0.277201);
    assert_eq!(
        (
            s.num_unique_objects,
            s.mostly_tracked,
            s.partially_tracked,
            s.mostly_lost,
            s.num_false_positives,
            s.num_misses,
            s.num_switches,
            s.num_fragmentations
        ),
        (8, 1, 6, 1, 13, 150, 7, 7)
    );
}
