//! Column fixed-pattern noise (`fishtrack::columns`): a small synthetic
//! haul and its copy with a stripe pattern added to every raw frame of both
//! cameras. `fishtrack track` must find the pattern in the copy, report it
//! in `summary.json` and take it out (the copy then segments as the clean
//! haul does), and leave the clean haul untouched.

use std::path::Path;

use fishtrack_tests::{run_fishtrack as run, text};

/// Column offsets in grey levels: a fixed pseudo-random pattern, RMS ≈ 2.
fn offset(x: u32) -> i32 {
    let mut s = (x as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    s ^= s >> 31;
    (s % 7) as i32 - 3
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

fn track(haul: &Path, out: &Path) {
    let o = run(&[
        "-q",
        "track",
        haul.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "track: {}", text(&o.stderr));
}

#[test]
fn a_stripe_pattern_is_found_reported_and_taken_out() {
    let dir = tempfile::tempdir().unwrap();
    let (h, g) = (dir.path().join("clean"), dir.path().join("striped"));
    let o = run(&[
        "synth",
        h.to_str().unwrap(),
        "--size",
        "512",
        "--frames",
        "8",
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "synth: {}", text(&o.stderr));
    for sub in ["left", "right"] {
        std::fs::create_dir_all(g.join(sub)).unwrap();
        for e in std::fs::read_dir(h.join(sub)).unwrap() {
            let p = e.unwrap().path();
            let mut im = image::open(&p).unwrap().to_luma8();
            for (x, _, v) in im.enumerate_pixels_mut() {
                v.0[0] = (v.0[0] as i32 + offset(x)).clamp(0, 255) as u8;
            }
            im.save(g.join(sub).join(p.file_name().unwrap())).unwrap();
        }
    }
    for f in ["calibration.yml", "truth.json"] {
        std::fs::copy(h.join(f), g.join(f)).unwrap();
    }
    let (oh, og) = (dir.path().join("out_clean"), dir.path().join("out_striped"));
    track(&h, &oh);
    track(&g, &og);
    let (sh, sg) = (summary(&oh), summary(&og));
    for cam in 0..2 {
        let (ch, cg) = (&sh["column_offsets"][cam], &sg["column_offsets"][cam]);
        assert_eq!(ch["applied"], false, "clean haul: {ch}");
        assert!(ch["rms"].as_f64().unwrap() < 0.3, "clean haul: {ch}");
        assert_eq!(cg["applied"], true, "striped haul: {cg}");
        assert!(cg["rms"].as_f64().unwrap() > 1.2, "striped haul: {cg}");
    }
    // the detections of the corrected copy are those of the clean haul,
    // up to a few (the correction is not exact to the grey level)
    let rows = |o: &Path| {
        std::fs::read_to_string(o.join("detections.csv"))
            .unwrap()
            .lines()
            .count()
    };
    let (nh, ng) = (rows(&oh), rows(&og));
    assert!(
        (nh as f64 - ng as f64).abs() <= 0.1 * nh as f64 + 2.0,
        "{ng} detections on the corrected copy, {nh} on the clean haul"
    );
}
