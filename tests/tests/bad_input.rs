//! What `fishtrack track` does with bad input, end to end through the
//! binary (README, "What FishTrack does with bad input"): every broken case
//! exits with code 2 and a message naming the file, frame or key; the
//! awkward-but-valid cases (a single frame, no fish, all-black or all-white
//! frames, colour or 16-bit frames) exit 0 with sensible output.
//!
//! Each test renders a small synthetic haul (`fishtrack synth --size 256`)
//! and breaks one thing in it. The library-level tests of the same cases
//! live next to the code (`host/src/haul.rs`, `host/tests/bad_calib.rs`,
//! `host/src/params_file.rs`); these check the whole path through the CLI.

use std::path::{Path, PathBuf};
use std::process::Output;

use fishtrack::calib::StereoCalib;
use fishtrack_tests::{path_str as s, run_fishtrack as run, text};
use image::{GrayImage, ImageBuffer, Luma, Rgb, RgbImage};

/// A synthetic 256² haul of `frames` pairs in a fresh temporary directory.
fn haul_with(frames: u32, extra: &[&str]) -> (tempfile::TempDir, PathBuf) {
    let t = tempfile::tempdir().unwrap();
    let h = t.path().join("haul");
    let f = frames.to_string();
    let mut args = vec![
        "synth",
        s(&h),
        "--size",
        "256",
        "--seed",
        "7",
        "--frames",
        &f,
    ];
    args.extend_from_slice(extra);
    let out = run(&args);
    assert_eq!(out.status.code(), Some(0), "synth: {}", text(&out.stderr));
    (t, h)
}

fn haul(frames: u32) -> (tempfile::TempDir, PathBuf) {
    haul_with(frames, &[])
}

fn track(h: &Path, extra: &[&str]) -> (Output, PathBuf) {
    let out = h.parent().unwrap().join("out");
    let mut args = vec!["track", s(h), "--out", s(&out)];
    args.extend_from_slice(extra);
    (run(&args), out)
}

/// Exit code 2 and every `needle` in stderr.
#[track_caller]
fn assert_bad(out: &Output, needles: &[&str]) {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "`{n}` missing from: {err}");
    }
}

#[track_caller]
fn assert_ok(out: &Output) -> String {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "stderr: {err}");
    err
}

fn frame(h: &Path, side: &str, n: u32) -> PathBuf {
    h.join(side).join(format!("{n:06}.png"))
}

fn rewrite_calibration(h: &Path, edit: impl FnOnce(&mut StereoCalib)) {
    let mut c = StereoCalib::load(h, None).unwrap();
    edit(&mut c);
    std::fs::write(h.join("calibration.yml"), c.to_yaml()).unwrap();
}

#[test]
fn corrupt_png_names_file_and_frame() {
    let (_t, h) = haul(3);
    let f = frame(&h, "left", 2);
    let mut bytes = std::fs::read(&f).unwrap();
    for b in bytes.iter_mut().skip(60) {
        *b ^= 0x5a; // keep the signature, scramble the chunks
    }
    std::fs::write(&f, bytes).unwrap();
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["left/000002.png", "frame 2", "corrupt"]);
}

#[test]
fn truncated_jpeg_names_file_and_frame() {
    let (_t, h) = haul(3);
    for side in ["left", "right"] {
        let png = frame(&h, side, 2);
        let img = image::open(&png).unwrap();
        let jpg = h.join(side).join("000002.jpg");
        img.save(&jpg).unwrap();
        std::fs::remove_file(png).unwrap();
        if side == "right" {
            let bytes = std::fs::read(&jpg).unwrap();
            std::fs::write(&jpg, &bytes[..bytes.len() / 2]).unwrap();
        }
    }
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["right/000002.jpg", "frame 2", "JPEG"]);
}

#[test]
fn zero_byte_frame_names_the_file() {
    let (_t, h) = haul(3);
    std::fs::write(frame(&h, "right", 3), b"").unwrap();
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["right/000003.png", "empty (0 bytes)"]);
}

#[test]
fn frame_missing_on_one_side_names_both_files() {
    let (_t, h) = haul(3);
    std::fs::remove_file(frame(&h, "right", 2)).unwrap();
    let (out, _) = track(&h, &[]);
    assert_bad(
        &out,
        &[
            "left/000002.png",
            "right/000002.png is missing",
            "no partner",
        ],
    );
}

#[test]
fn left_right_size_mismatch_names_frame_and_sizes() {
    let (_t, h) = haul(3);
    GrayImage::new(128, 128)
        .save(frame(&h, "right", 2))
        .unwrap();
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["000002.png", "frame 2", "256x256", "128x128"]);
}

#[test]
fn frames_of_another_size_than_the_calibration() {
    let (_t, h) = haul(2);
    for side in ["left", "right"] {
        for n in 1..=2 {
            GrayImage::new(200, 200).save(frame(&h, side, n)).unwrap();
        }
    }
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["000001.png", "frame 1", "200x200", "256x256"]);
}

/// Same pixels as 16-bit (`v · 257`, so `>> 8` gives `v` back) or as colour
/// (R = G = B = v, whose BT.601 luma is `v`): the run succeeds and tracks
/// exactly as on the 8-bit grey haul; 16-bit frames get one warning.
#[test]
fn sixteen_bit_and_colour_frames_track_like_grey() {
    let (_t, h) = haul(6);
    let (out, reference) = track(&h, &[]);
    assert_ok(&out);
    let want_tracks = std::fs::read(reference.join("tracks.csv")).unwrap();
    let want_fish = std::fs::read(reference.join("fish.csv")).unwrap();

    let convert = |to: &str| {
        let t = tempfile::tempdir().unwrap();
        let h2 = t.path().join("haul");
        std::fs::create_dir(&h2).unwrap();
        std::fs::copy(h.join("calibration.yml"), h2.join("calibration.yml")).unwrap();
        for side in ["left", "right"] {
            std::fs::create_dir(h2.join(side)).unwrap();
            for n in 1..=6 {
                let g = image::open(frame(&h, side, n)).unwrap().to_luma8();
                let dst = frame(&h2, side, n);
                if to == "16" {
                    let img: ImageBuffer<Luma<u16>, Vec<u16>> =
                        ImageBuffer::from_fn(g.width(), g.height(), |x, y| {
                            Luma([g.get_pixel(x, y).0[0] as u16 * 257])
                        });
                    img.save(&dst).unwrap();
                } else {
                    let img = RgbImage::from_fn(g.width(), g.height(), |x, y| {
                        let v = g.get_pixel(x, y).0[0];
                        Rgb([v, v, v])
                    });
                    img.save(&dst).unwrap();
                }
            }
        }
        let (out, o) = track(&h2, &[]);
        let err = assert_ok(&out);
        assert_eq!(
            std::fs::read(o.join("tracks.csv")).unwrap(),
            want_tracks,
            "{to}"
        );
        assert_eq!(
            std::fs::read(o.join("fish.csv")).unwrap(),
            want_fish,
            "{to}"
        );
        (t, err)
    };
    let (_t16, err16) = convert("16");
    assert!(
        err16.contains("16-bit") && err16.contains("000001.png") && err16.contains(">> 8"),
        "16-bit warning must name the file: {err16}"
    );
    let warnings = err16.lines().filter(|l| l.contains("16-bit")).count();
    assert_eq!(warnings, 1, "one warning per haul: {err16}");
    let (_tc, errc) = convert("rgb");
    assert!(!errc.contains("16-bit"), "{errc}");
    // --quiet silences the warning
    let q = run(&[
        "--quiet",
        "track",
        s(&_t16.path().join("haul")),
        "--out",
        s(&_t16.path().join("out-quiet")),
    ]);
    assert!(!assert_ok(&q).contains("16-bit"));
}

#[test]
fn calibration_with_nan_or_inf_names_the_key() {
    let (_t, h) = haul(2);
    let text = std::fs::read_to_string(h.join("calibration.yml")).unwrap();
    rewrite_calibration(&h, |c| c.t[0] = f64::NAN);
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["calibration.yml", "key `T`", "finite"]);

    // D1's first coefficient → +∞, written the way OpenCV writes it
    let d1 = text.find("D1:").unwrap();
    let open = d1 + text[d1..].find('[').unwrap() + 1;
    let comma = open + text[open..].find(',').unwrap();
    let edited = format!("{} .Inf{}", &text[..open], &text[comma..]);
    std::fs::write(h.join("calibration.yml"), edited).unwrap();
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["calibration.yml", "key `D1`", "finite"]);
}

#[test]
fn singular_calibration_matrices_name_the_key() {
    let (_t, h) = haul(2);
    let good = std::fs::read(h.join("calibration.yml")).unwrap();
    rewrite_calibration(&h, |c| c.m1 *= 0.0);
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["calibration.yml", "key `M1`"]);

    std::fs::write(h.join("calibration.yml"), &good).unwrap();
    rewrite_calibration(&h, |c| c.r *= 0.0);
    let (out, _) = track(&h, &[]);
    assert_bad(&out, &["calibration.yml", "key `R`"]);
}

#[test]
fn params_file_unknown_key_or_out_of_range_names_the_key() {
    let (t, h) = haul(2);
    let p = t.path().join("my.toml");
    std::fs::write(&p, "theta_bp = 0.3\nthetabp = 0.4\n").unwrap();
    let (out, _) = track(&h, &["--params", s(&p)]);
    assert_bad(&out, &["my.toml", "key `thetabp`", "unknown parameter"]);

    std::fs::write(&p, "theta_bp = 7.5\n").unwrap();
    let (out, _) = track(&h, &["--params", s(&p)]);
    assert_bad(&out, &["my.toml", "theta_bp"]);

    std::fs::write(&p, "area_min = \"big\"\n").unwrap();
    let (out, _) = track(&h, &["--params", s(&p)]);
    assert_bad(&out, &["my.toml", "key `area_min`"]);

    let (out, _) = track(&h, &["--tracker", "kalman"]);
    assert_bad(&out, &["--tracker", "kalman"]);
}

/// `--fps`: a bad frame rate names the flag; a good one reaches the
/// summary and the VIAME header, and the default is the Cam-trawl's 5.
#[test]
fn frame_rate_flag_is_checked_and_recorded() {
    let (_t, h) = haul(2);
    for bad in ["0", "-5", "nan", "inf", "2000"] {
        let (out, _) = track(&h, &[&format!("--fps={bad}")]);
        assert_bad(&out, &["--fps", "frame rate"]);
    }
    for (extra, fps) in [(&[][..], 5.0), (&["--fps", "2.5"][..], 2.5)] {
        let (out, o) = track(&h, extra);
        assert_ok(&out);
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(o.join("summary.json")).unwrap()).unwrap();
        assert_eq!(summary["fps"].as_f64(), Some(fps), "{extra:?}");
        // a newborn's first step spans the view in 4.3 frames at 5 fps, in
        // about 2 at 2.5 fps
        let raw = image::image_dimensions(h.join("left/000001.png"))
            .unwrap()
            .0;
        let want = (f64::from(raw) * 5.0 / fps).round();
        assert_eq!(
            summary["crossing_width_px"].as_f64(),
            Some(want),
            "{extra:?}"
        );
        // a lost fish is carried one frame at 5 fps, none at 2.5 fps
        let lost = if fps < 5.0 { 0 } else { 1 };
        assert_eq!(summary["max_lost"].as_u64(), Some(lost), "{extra:?}");
        let viame = std::fs::read_to_string(o.join("detections.viame.csv")).unwrap();
        let meta = viame.lines().nth(1).unwrap();
        assert!(
            meta.starts_with(&format!("# metadata,fps: {fps},")),
            "{meta}"
        );
    }
    // a params file's max_lost wins over the rate's
    let (t, h) = (_t, h);
    let p = t.path().join("lost.toml");
    std::fs::write(&p, "[track]\nmax_lost = 1\n").unwrap();
    let (out, o) = track(&h, &["--fps", "2.5", "--params", s(&p)]);
    assert_ok(&out);
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(o.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["max_lost"].as_u64(), Some(1));
}

#[test]
fn output_directory_that_cannot_be_created_or_written() {
    let (t, h) = haul(2);
    let file = t.path().join("a_file");
    std::fs::write(&file, "not a directory").unwrap();
    let bad = file.join("out");
    let out = run(&["track", s(&h), "--out", s(&bad)]);
    assert_bad(&out, &["a_file/out", "cannot create the output directory"]);
    // the regular file itself as OUT
    let out = run(&["track", s(&h), "--out", s(&file)]);
    assert_bad(&out, &["a_file", "output directory"]);
}

#[test]
fn single_frame_haul_is_valid() {
    let (_t, h) = haul(1);
    let (out, o) = track(&h, &["--overlays"]);
    assert_ok(&out);
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(o.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["frames"], 1);
    // the rectification used: the default (the canvas at alpha 0.25's
    // scale), a focal length, and the valid rectangles inside the frame
    let r = &summary["rectification"];
    assert_eq!(r["alpha"], 0.25);
    assert!(r["focal_px"].as_f64().unwrap() > 0.0);
    let w = summary["width"].as_u64().unwrap();
    for k in ["valid_left", "valid_right"] {
        let v: Vec<u64> = r[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .collect();
        assert!(v.len() == 4 && v[2] > 0 && v[0] + v[2] <= w, "{k}: {v:?}");
    }
    assert!(o.join("overlays/000001.png").is_file());
    assert!(o.join("length_frequency.svg").is_file());
    // `--rect-alpha auto` records the alpha the rig got (at least 0.25)
    let (out, o2) = track(&h, &["--rect-alpha", "auto"]);
    assert_ok(&out);
    let s2: serde_json::Value =
        serde_json::from_slice(&std::fs::read(o2.join("summary.json")).unwrap()).unwrap();
    assert!(s2["rectification"]["alpha"].as_f64().unwrap() >= 0.25);
    // `--rect-alpha 0.25`: the raw frame's size at the canvas's scale
    let raw = image::image_dimensions(h.join("left/000001.png")).unwrap();
    let (out, o4) = track(&h, &["--rect-alpha", "0.25"]);
    assert_ok(&out);
    let s4: serde_json::Value =
        serde_json::from_slice(&std::fs::read(o4.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s4["width"].as_u64(), Some(u64::from(raw.0)));
    assert_eq!(s4["rectification"]["focal_px"], r["focal_px"]);
    // `--rect-alpha canvas` (the default): frames larger than the raw
    // ones, every box written in raw pixels inside the raw frame
    let (out, o3) = track(&h, &["--rect-alpha", "canvas"]);
    assert_ok(&out);
    let s3: serde_json::Value =
        serde_json::from_slice(&std::fs::read(o3.join("summary.json")).unwrap()).unwrap();
    assert!(
        s3["width"].as_u64().unwrap() > u64::from(raw.0),
        "{}",
        s3["width"]
    );
    assert_eq!(s3["width"].as_u64(), Some(w), "the default is the canvas");
    assert_eq!(s3["rectification"]["focal_px"], r["focal_px"]);
    for f in ["detections.csv", "tracks.csv"] {
        for line in std::fs::read_to_string(o3.join(f)).unwrap().lines() {
            let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            assert!(
                v[2] >= 0.0
                    && v[3] >= 0.0
                    && v[2] + v[4] <= raw.0 as f64 + 1e-9
                    && v[3] + v[5] <= raw.1 as f64 + 1e-9,
                "{f}: {line}"
            );
        }
    }
}

/// A haul with no fish: `synth --fish-rate 0` (mesh, debris, snow, no fish)
/// runs and writes complete, consistent outputs (what it counts there are
/// false positives, reported as fish rows); the same haul with its frames
/// replaced by a smooth, slightly noisy background gives exactly zero fish.
#[test]
fn haul_without_fish_is_valid() {
    let (_t, h) = haul_with(4, &["--fish-rate", "0"]);
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(h.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["fish"].as_array().unwrap().len(), 0);
    let summary = |o: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(o.join("summary.json")).unwrap()).unwrap()
    };
    let (out, o) = track(&h, &["--overlays"]);
    assert_ok(&out);
    let fish = std::fs::read_to_string(o.join("fish.csv")).unwrap();
    assert_eq!(
        summary(&o)["fish_count"].as_u64().unwrap() as usize,
        fish.lines().count() - 1
    );
    assert!(o.join("length_frequency.png").is_file());

    // Background only: gradient + ±2 grey levels of deterministic noise.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for side in ["left", "right"] {
        for n in 1..=4 {
            let img = GrayImage::from_fn(256, 256, |x, y| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let noise = (state % 5) as f64 - 2.0;
                Luma([(20.0 + 10.0 * x as f64 / 256.0 + 5.0 * y as f64 / 256.0 + noise) as u8])
            });
            img.save(frame(&h, side, n)).unwrap();
        }
    }
    let (out, o) = track(&h, &["--overlays"]);
    assert_ok(&out);
    let fish = std::fs::read_to_string(o.join("fish.csv")).unwrap();
    assert_eq!(fish.lines().count(), 1, "header only: {fish}");
    assert_eq!(std::fs::read(o.join("tracks.csv")).unwrap(), b"");
    assert_eq!(summary(&o)["fish_count"], 0);
    assert!(o.join("overlays/000004.png").is_file());
    assert!(o.join("length_frequency.svg").is_file());
}

#[test]
fn all_black_and_all_white_frames_are_valid() {
    let (_t, h) = haul(4);
    for side in ["left", "right"] {
        GrayImage::from_pixel(256, 256, Luma([0]))
            .save(frame(&h, side, 2))
            .unwrap();
        GrayImage::from_pixel(256, 256, Luma([255]))
            .save(frame(&h, side, 3))
            .unwrap();
    }
    let (out, o) = track(&h, &["--overlays"]);
    assert_ok(&out);
    // nothing is detected on a uniform frame
    let dets = std::fs::read_to_string(o.join("detections.csv")).unwrap();
    assert!(
        !dets
            .lines()
            .any(|l| l.starts_with("2,") || l.starts_with("3,")),
        "{dets}"
    );
    assert!(o.join("overlays/000003.png").is_file());
}
