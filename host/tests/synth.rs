//! `fishtrack synth`: determinism, truth consistency, the calibration file
//! against OpenCV (Python `cv2`), and the hardness of the motion.

use std::path::Path;
use std::process::Command;

use fishtrack::synth::hardness::hardness;
use fishtrack::synth::rig::Cam;
use fishtrack::synth::{write_haul, Haul, SynthConfig};
use fishtrack::truth::Truth;

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for sub in ["", "left", "right"] {
        let d = dir.join(sub);
        let mut names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.is_file())
            .collect();
        names.sort();
        for p in names {
            out.push((
                p.strip_prefix(dir).unwrap().display().to_string(),
                std::fs::read(&p).unwrap(),
            ));
        }
    }
    out
}

fn cfg(seed: u64, size: u32, frames: u32) -> SynthConfig {
    SynthConfig {
        frames,
        seed,
        size,
        fish_rate: 1.0,
    }
}

#[test]
fn same_seed_same_bytes_and_different_seeds_differ() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let c = tempfile::tempdir().unwrap();
    write_haul(a.path(), &cfg(5, 256, 6)).unwrap();
    write_haul(b.path(), &cfg(5, 256, 6)).unwrap();
    write_haul(c.path(), &cfg(6, 256, 6)).unwrap();
    let (fa, fb, fc) = (files(a.path()), files(b.path()), files(c.path()));
    // 6 left + 6 right + calibration.yml + truth.json, no temporary files left.
    assert_eq!(
        fa.len(),
        14,
        "{:?}",
        fa.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    assert_eq!(fa, fb);
    assert_eq!(fc.len(), fa.len());
    for ((na, da), (nc, dc)) in fa.iter().zip(&fc) {
        assert_eq!(na, nc);
        assert_ne!(da, dc, "{na} is the same for seeds 5 and 6");
    }
}

#[test]
fn frames_are_8_bit_grey_of_the_requested_size_and_look_dark() {
    let d = tempfile::tempdir().unwrap();
    write_haul(d.path(), &cfg(9, 320, 2)).unwrap();
    for side in ["left", "right"] {
        let img = image::open(d.path().join(side).join("000002.png")).unwrap();
        assert_eq!(img.color(), image::ColorType::L8);
        let g = img.to_luma8();
        assert_eq!(g.dimensions(), (320, 320));
        let mean = g.pixels().map(|p| p.0[0] as f64).sum::<f64>() / (320.0 * 320.0);
        assert!((5.0..90.0).contains(&mean), "{side} mean grey {mean}");
    }
}

fn check_truth(t: &Truth) {
    let (w, h) = (t.width as f64, t.height as f64);
    for (k, f) in t.fish.iter().enumerate() {
        assert_eq!(f.id, k as u32 + 1);
        assert!((200.0..=700.0).contains(&f.length_mm));
        assert!(f.tail_reflectivity > 0.0 && f.tail_reflectivity < 1.0);
        assert!(!f.frames.is_empty());
        assert!(f.frames.windows(2).all(|p| p[0].frame < p[1].frame));
        for fr in &f.frames {
            assert!(fr.frame >= 1 && fr.frame <= t.frames);
            assert!(fr.left_area > 0.0 || fr.right_area > 0.0);
            for (bx, area, frac, inside) in [
                (
                    fr.left_box,
                    fr.left_area,
                    fr.left_visible_fraction,
                    fr.inside_left,
                ),
                (
                    fr.right_box,
                    fr.right_area,
                    fr.right_visible_fraction,
                    fr.inside_right,
                ),
            ] {
                assert_eq!(bx.is_some(), area > 0.0);
                assert!((0.0..=1.0).contains(&frac));
                if let Some([x, y, bw, bh]) = bx {
                    assert!(x >= 0.0 && y >= 0.0 && bw >= 1.0 && bh >= 1.0);
                    assert!(x + bw <= w && y + bh <= h, "box {bx:?} outside {w}x{h}");
                    assert!(area <= bw * bh);
                    assert_eq!(area.fract(), 0.0);
                }
                if !inside && area > 0.0 {
                    // Cut by the border: part of the silhouette is missing.
                    assert!(frac < 1.0);
                }
            }
            let d: f64 = (0..3)
                .map(|i| (fr.head_mm[i] - fr.tail_mm[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(
                d <= f.length_mm * (1.0 + 1e-6) && d >= 0.98 * f.length_mm,
                "fish {} frame {}: head-tail {d} vs length {}",
                f.id,
                fr.frame,
                f.length_mm
            );
            let range = 0.5 * (fr.head_mm[2] + fr.tail_mm[2]);
            assert!((900.0..3600.0).contains(&range), "range {range}");
        }
    }
}

#[test]
fn truth_is_consistent() {
    let d = tempfile::tempdir().unwrap();
    let t = write_haul(d.path(), &cfg(3, 512, 12)).unwrap();
    assert_eq!(Truth::load(&d.path().join("truth.json")).unwrap(), t);
    assert!(t.fish.len() >= 5, "only {} fish", t.fish.len());
    check_truth(&t);
    // Some fish are wholly inside, some cut by the border.
    let frames: Vec<_> = t.fish.iter().flat_map(|f| &f.frames).collect();
    assert!(frames.iter().any(|f| f.inside_left));
    assert!(frames.iter().any(|f| !f.inside_left && f.left_area > 0.0));
}

/// Runs a Python script; `None` (after a skip notice) when python3 or cv2
/// is missing and FISHTRACK_REQUIRE_PYTHON is not set.
fn python(script: &str, args: &[&str]) -> Option<String> {
    let probe = Command::new("python3")
        .args(["-c", "import cv2, numpy"])
        .output();
    if !probe.map(|o| o.status.success()).unwrap_or(false) {
        if std::env::var("FISHTRACK_REQUIRE_PYTHON").as_deref() == Ok("1") {
            panic!("python3 with cv2 and numpy is required (FISHTRACK_REQUIRE_PYTHON=1)");
        }
        eprintln!("skipping: python3 with cv2/numpy not available");
        return None;
    }
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "python failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(String::from_utf8_lossy(&out.stdout).into_owned())
}

const CV_CHECK: &str = r#"
import sys, json, cv2, numpy as np
d = sys.argv[1]
exp = json.load(open(d + '/expected.json'))
fs = cv2.FileStorage(d + '/calibration.yml', cv2.FILE_STORAGE_READ)
assert fs.isOpened()
assert int(fs.getNode('image_width').real()) == exp['width']
assert int(fs.getNode('image_height').real()) == exp['height']
mats = {}
for k in ['M1', 'D1', 'M2', 'D2', 'R', 'T']:
    m = fs.getNode(k).mat()
    e = np.array(exp[k], dtype=np.float64)
    assert m.dtype == np.float64, k
    assert m.shape == e.shape, (k, m.shape, e.shape)
    assert np.array_equal(m, e), (k, m, e)
    mats[k] = m
fs.release()
# Byte-exact: the same matrices written by cv2 give the same text (after the header line).
out = cv2.FileStorage('.yml', cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
out.write('image_width', exp['width'])
out.write('image_height', exp['height'])
for k in ['M1', 'D1', 'M2', 'D2', 'R', 'T']:
    out.write(k, mats[k])
ours = open(d + '/calibration.yml').read()
assert ours.startswith('%YAML:1.0\n---\n'), ours[:20]
theirs = out.releaseAndGetString()
assert ours.split('\n', 1)[1] == theirs.split('\n', 1)[1], (ours, theirs)
# Projection of 3-D points (mm, left frame) through each camera.
pts = np.array(exp['points'], dtype=np.float64).reshape(-1, 1, 3)
worst = 0.0
for cam, rv, tv, M, D in [('left', np.zeros(3), np.zeros(3), mats['M1'], mats['D1']),
                          ('right', cv2.Rodrigues(mats['R'])[0], mats['T'], mats['M2'], mats['D2'])]:
    p, _ = cv2.projectPoints(pts, rv, tv, M, D)
    e = np.array(exp['proj_' + cam]).reshape(-1, 2)
    worst = max(worst, float(np.abs(p.reshape(-1, 2) - e).max()))
assert worst < 1e-6, worst
# Snout and tail tip of wholly visible fish fall in (or on the edge of) their boxes.
t = json.load(open(d + '/truth.json'))
checked = 0
for f in t['fish']:
    for fr in f['frames']:
        for side, M, D, rv, tv in [('left', mats['M1'], mats['D1'], np.zeros(3), np.zeros(3)),
                                   ('right', mats['M2'], mats['D2'], cv2.Rodrigues(mats['R'])[0], mats['T'])]:
            if not fr['inside_' + side] or fr[side + '_visible_fraction'] < 1.0:
                continue
            x, y, w, h = fr[side + '_box']
            ends = np.array([fr['head_mm'], fr['tail_mm']], dtype=np.float64).reshape(-1, 1, 3)
            p, _ = cv2.projectPoints(ends, rv, tv, M, D)
            for u, v in p.reshape(-1, 2):
                # truth boxes count whole pixels: pixel i covers [i, i+1), its centre is i + 0.5
                u, v = u + 0.5, v + 0.5
                assert x - 1.5 <= u <= x + w + 1.5 and y - 1.5 <= v <= y + h + 1.5, (f['id'], fr['frame'], side, u, v, x, y, w, h)
            checked += 1
assert checked >= 5, checked
print('ok', worst, checked)
"#;

#[test]
fn calibration_reads_back_in_opencv_and_projects_like_it() {
    let d = tempfile::tempdir().unwrap();
    let config = cfg(11, 512, 8);
    write_haul(d.path(), &config).unwrap();
    let haul = Haul::plan(config).unwrap();
    let rig = &haul.rig;
    let m = |m: &nalgebra::Matrix3<f64>| -> Vec<Vec<f64>> {
        (0..3)
            .map(|r| (0..3).map(|c| m[(r, c)]).collect())
            .collect()
    };
    let mut points = Vec::new();
    let mut proj = [Vec::new(), Vec::new()];
    for i in 0..40 {
        let z = 1000.0 + 70.0 * i as f64;
        let p = nalgebra::Vector3::new(
            (i as f64 * 37.0) % 900.0 - 450.0,
            (i as f64 * 53.0) % 800.0 - 400.0,
            z,
        );
        points.push(vec![p.x, p.y, p.z]);
        for cam in Cam::BOTH {
            let (u, v) = rig.project(cam, &p).unwrap();
            proj[cam.index()].push(vec![u, v]);
        }
    }
    let expected = serde_json::json!({
        "width": rig.width, "height": rig.height,
        "M1": m(&rig.left.matrix()), "D1": [rig.left.dist.to_vec()],
        "M2": m(&rig.right.matrix()), "D2": [rig.right.dist.to_vec()],
        "R": m(&rig.r), "T": [[rig.t.x], [rig.t.y], [rig.t.z]],
        "points": points, "proj_left": proj[0], "proj_right": proj[1],
    });
    std::fs::write(d.path().join("expected.json"), expected.to_string()).unwrap();
    if let Some(out) = python(CV_CHECK, &[d.path().to_str().unwrap()]) {
        assert!(out.starts_with("ok"), "{out}");
    }
}

#[test]
fn nearest_neighbour_on_perfect_detections_fails_as_in_the_paper() {
    // Paper Table V: NN 0.36. The synthetic motion must keep NN below 0.6
    // even at NN's best gate/α/coasting for each haul.
    for seed in [1, 2, 3] {
        let d = tempfile::tempdir().unwrap();
        let t = write_haul(d.path(), &cfg(seed, 1024, 30)).unwrap();
        let h = hardness(&t);
        eprintln!("seed {seed}: {h:?}");
        assert!(h.fish >= 15, "seed {seed}: only {} countable fish", h.fish);
        assert!(h.best_rate < 0.6, "seed {seed}: NN success {h:?}");
        assert!(
            (2.5..6.5).contains(&h.mean_life),
            "seed {seed}: life {}",
            h.mean_life
        );
    }
}

#[test]
fn fish_enter_and_leave_across_every_border_in_about_four_frames() {
    let d = tempfile::tempdir().unwrap();
    let t = write_haul(d.path(), &cfg(9, 256, 100)).unwrap();
    let w = t.width as f64;
    let touches = |b: [f64; 4]| [b[0] <= 0.0, b[1] <= 0.0, b[0] + b[2] >= w, b[1] + b[3] >= w];
    let mut entries = [0; 4];
    let mut exits = [0; 4];
    let mut lives = Vec::new();
    let mut minus_x = 0;
    let mut plus_x = 0;
    for f in &t.fish {
        let seen: Vec<_> = f.frames.iter().filter_map(|fr| fr.left_box).collect();
        let (Some(first), Some(last)) = (seen.first(), seen.last()) else {
            continue;
        };
        lives.push(seen.len() as f64);
        for (k, hit) in touches(*first).iter().enumerate() {
            entries[k] += usize::from(*hit);
        }
        for (k, hit) in touches(*last).iter().enumerate() {
            exits[k] += usize::from(*hit);
        }
        let dx = f.frames.last().unwrap().head_mm[0] - f.frames[0].head_mm[0];
        if f.frames.len() > 1 {
            if dx < 0.0 {
                minus_x += 1;
            } else {
                plus_x += 1;
            }
        }
    }
    // [left, top, right, bottom]
    assert!(entries.iter().all(|&n| n >= 2), "entries {entries:?}");
    assert!(exits.iter().all(|&n| n >= 2), "exits {exits:?}");
    assert!(
        minus_x > 2 * plus_x && plus_x > 0,
        "-x {minus_x}, +x {plus_x}"
    );
    let life = lives.iter().sum::<f64>() / lives.len() as f64;
    assert!((2.5..6.0).contains(&life), "mean visible life {life}");
}

/// An independent re-implementation of the NN-on-truth association and the
/// eq. 16 success rate, to check `fishtrack::synth::hardness`.
const NN_PY: &str = r#"
import json, sys
t = json.load(open(sys.argv[1]))
W = t['width']
area_min = int(2000 * (W / 2048) ** 2) if W != 2048 else 2000
obs = {}
for f in t['fish']:
    for fr in f['frames']:
        b = fr['left_box']
        if b and fr['left_area'] >= area_min:
            obs.setdefault(fr['frame'], []).append((f['id'], (b[0] + b[2] / 2, b[1] + b[3] / 2)))
def run(gate, alpha, coast):
    tracks, nid, asg = [], 1, {}
    for fr in range(1, t['frames'] + 1):
        here = sorted(obs.get(fr, []))
        pairs = []
        for ti, tr in enumerate(tracks):
            p = (tr['x'][0] + tr['v'][0], tr['x'][1] + tr['v'][1])
            for oi, (i, c) in enumerate(here):
                d = ((c[0] - p[0]) ** 2 + (c[1] - p[1]) ** 2) ** .5
                if d <= gate:
                    pairs.append((d, ti, oi))
        pairs.sort()
        tu, ou = set(), set()
        for d, ti, oi in pairs:
            if ti in tu or oi in ou:
                continue
            tu.add(ti); ou.add(oi)
            tr = tracks[ti]; c = here[oi][1]
            vo = (c[0] - tr['x'][0], c[1] - tr['x'][1])
            tr['v'] = (alpha * vo[0] + (1 - alpha) * tr['v'][0], alpha * vo[1] + (1 - alpha) * tr['v'][1])
            tr['x'] = c; tr['m'] = 0
            asg[(fr, here[oi][0])] = tr['id']
        for ti, tr in enumerate(tracks):
            if ti not in tu:
                tr['x'] = (tr['x'][0] + tr['v'][0], tr['x'][1] + tr['v'][1]); tr['m'] += 1
        tracks = [tr for tr in tracks if tr['m'] <= coast]
        for oi, (i, c) in enumerate(here):
            if oi not in ou:
                tracks.append(dict(id=nid, x=c, v=(0.0, 0.0), m=0)); asg[(fr, i)] = nid; nid += 1
    ids, owners = {}, {}
    for (fr, i), tid in asg.items():
        ids.setdefault(i, set()).add(tid); owners.setdefault(tid, set()).add(i)
    ok = sum(1 for i, s in ids.items() if len(s) == 1 and len(owners[next(iter(s))]) == 1)
    return ok / len(ids)
default = run(0.2 * W, 0.3, 1)
best = max(run(g * W, a, c) for g in (0.05, 0.1, 0.2, 0.3, 0.5) for a in (0.3, 1.0) for c in (0, 1))
print(json.dumps([default, best]))
"#;

#[test]
fn hardness_agrees_with_an_independent_python_nn() {
    let d = tempfile::tempdir().unwrap();
    let t = write_haul(d.path(), &cfg(4, 384, 30)).unwrap();
    let h = hardness(&t);
    let Some(out) = python(NN_PY, &[d.path().join("truth.json").to_str().unwrap()]) else {
        return;
    };
    let v: Vec<f64> = serde_json::from_str(out.trim()).unwrap();
    assert!(
        (v[0] - h.default_rate).abs() < 1e-12,
        "python {v:?} vs {h:?}"
    );
    assert!((v[1] - h.best_rate).abs() < 1e-12, "python {v:?} vs {h:?}");
    assert!(h.fish >= 10 && h.best_rate < 0.6, "{h:?}");
}
