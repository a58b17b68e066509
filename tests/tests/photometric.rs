//! Two cameras that record the fish at different grey levels
//! (`fishtrack_core::photometric`): a synthetic haul (1024², 16 frame
//! pairs, seed 2) and its copy with every right frame × 0.7. The pipeline
//! must estimate the mismatch from its stereo pairs, map the right view
//! and measure about as many 3-D lengths, as well, as on the matched haul;
//! and the float reference agrees with the core on the mismatched haul
//! (`fishtrack compare`). A third copy's right frames change with every
//! flash ([`FLASH`]: each right frame × its own factor, 0.7–1.3): the
//! frames' maps follow them. (Until session 30 the match turned off also
//! cost most of the lengths — the block line's SAD saw the mismatch; the
//! slanted fit's zero-mean SAD does not, and off now measures about as
//! many: 29 against 30 on the mismatched haul, 30 against 31 flickering.)

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use fishtrack_tests::{run_fishtrack as run, text};

const GAIN: f32 = 0.7;
/// The right camera's light per frame of the flickering copy.
const FLASH: [f32; 16] = [
    1.0, 0.7, 1.3, 0.8, 1.2, 0.75, 1.25, 0.9, 1.1, 0.7, 1.3, 0.85, 1.15, 0.7, 1.3, 1.0,
];

/// A copy of `h` at `to` whose right frames (sorted by name) are scaled by
/// `factor(i)`.
fn scaled_copy(h: &Path, to: &Path, factor: impl Fn(usize) -> f32) {
    for sub in ["left", "right"] {
        std::fs::create_dir_all(to.join(sub)).unwrap();
        let mut files: Vec<PathBuf> = std::fs::read_dir(h.join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for (i, p) in files.iter().enumerate() {
            let dst = to.join(sub).join(p.file_name().unwrap());
            if sub == "left" {
                std::fs::copy(p, &dst).unwrap();
            } else {
                let mut im = image::open(p).unwrap().to_luma8();
                let f = factor(i);
                for v in im.pixels_mut() {
                    v.0[0] = (v.0[0] as f32 * f).round().min(255.0) as u8;
                }
                im.save(&dst).unwrap();
            }
        }
    }
    for f in ["calibration.yml", "truth.json"] {
        std::fs::copy(h.join(f), to.join(f)).unwrap();
    }
}

/// The matched haul and its mismatched copy, made once.
fn hauls() -> &'static (PathBuf, PathBuf) {
    static H: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    H.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let (h, g) = (dir.join("matched"), dir.join("mismatched"));
        let out = run(&[
            "synth",
            h.to_str().unwrap(),
            "--size",
            "1024",
            "--frames",
            "16",
            "--seed",
            "2",
        ]);
        assert!(out.status.success(), "synth: {}", text(&out.stderr));
        scaled_copy(&h, &g, |_| GAIN);
        (h, g)
    })
}

/// `(gain_median, 3-D lengths measured, per-frame 3-D MAPE, frames
/// mapped)` of a track + eval run with `photometric` set.
fn run_case(haul: &Path, photometric: bool) -> (f64, u64, Option<f64>, u64) {
    let dir = tempfile::tempdir().unwrap();
    let params = dir.path().join("p.toml");
    std::fs::write(&params, format!("photometric = {photometric}\n")).unwrap();
    let out_dir = dir.path().join("out");
    let out = run(&[
        "-q",
        "track",
        haul.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--params",
        params.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "track: {}", text(&out.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap())
            .unwrap();
    let gain = summary["photometric"]["gain_median"].as_f64().unwrap();
    let mapped = summary["photometric"]["frames_mapped"].as_u64().unwrap();
    let ev = run(&[
        "eval",
        haul.to_str().unwrap(),
        out_dir.to_str().unwrap(),
        "--json",
    ]);
    assert!(ev.status.success(), "eval: {}", text(&ev.stderr));
    let e: serde_json::Value = serde_json::from_slice(&ev.stdout).unwrap();
    let l = &e["stereo"]["length"];
    (
        gain,
        l["measured"].as_u64().unwrap(),
        l["mape"].as_f64(),
        mapped,
    )
}

#[test]
fn a_gain_mismatch_between_the_cameras_is_estimated_and_mapped_away() {
    let (h, g) = hauls();
    let (g_matched, n_matched, mape_matched, m_matched) = run_case(h, true);
    let (g_on, n_on, mape_on, m_on) = run_case(g, true);
    let (_, n_off, mape_off, m_off) = run_case(g, false);
    eprintln!(
        "matched: gain {g_matched:.3}, {n_matched} measured, MAPE {mape_matched:?}, \
         {m_matched} frames mapped; × {GAIN}: gain {g_on:.3}, {n_on} measured, MAPE \
         {mape_on:?}, {m_on} mapped; off: {n_off} measured, MAPE {mape_off:?}"
    );
    // the estimate sees the right view's 0.7 (relative to the matched
    // haul's own estimate: the synthetic views differ by a few per cent)
    let want = 1.0 / GAIN as f64;
    assert!(
        ((g_on / g_matched) / want - 1.0).abs() < 0.04,
        "gain {g_on} / {g_matched}, want × {want}"
    );
    // every frame of the mismatched haul is mapped (16 pairs; the first
    // gives no estimate yet), few of the matched one, none when off
    assert!(
        m_on >= 14 && m_matched <= 4 && m_off == 0,
        "{m_on} {m_matched} {m_off}"
    );
    // mapped: about as many lengths as the matched haul, about as good
    assert_like_matched((n_on, mape_on), (n_matched, mape_matched));
}

/// At least 85 % of the matched haul's lengths, and a per-frame MAPE
/// within one point of its.
fn assert_like_matched(
    (n, mape): (u64, Option<f64>),
    (n_matched, mape_matched): (u64, Option<f64>),
) {
    assert!(n as f64 >= 0.85 * n_matched as f64, "{n} vs {n_matched}");
    let (a, b) = (mape.unwrap(), mape_matched.unwrap());
    assert!(a <= b + 0.01, "per-frame MAPE {a} vs matched {b}");
}

/// `fishtrack compare` on `haul` reports agreement.
fn assert_compare_agrees(haul: &Path) {
    let out = run(&["compare", haul.to_str().unwrap()]);
    let so = text(&out.stdout);
    assert!(out.status.success(), "{so}\n{}", text(&out.stderr));
    assert!(so.contains("core and reference agree"), "{so}");
}

#[test]
fn core_and_reference_agree_on_the_mismatched_haul() {
    assert_compare_agrees(&hauls().1);
}

/// The flickering copy of the matched haul, made once.
fn flickering() -> &'static PathBuf {
    static F: OnceLock<PathBuf> = OnceLock::new();
    F.get_or_init(|| {
        let (h, _) = hauls();
        let f = h.parent().unwrap().join("flickering");
        scaled_copy(h, &f, |i| FLASH[i % FLASH.len()]);
        f
    })
}

#[test]
fn a_right_camera_that_flickers_flash_to_flash_is_followed() {
    let (h, _) = hauls();
    let f = flickering();
    let (_, n_matched, mape_matched, m_matched) = run_case(h, true);
    let (_, n_on, mape_on, m_on) = run_case(f, true);
    let (_, n_off, mape_off, _) = run_case(f, false);
    eprintln!(
        "{}: matched {n_matched} measured, MAPE {mape_matched:?}, {m_matched} mapped; \
         flickering: {n_on} measured, MAPE {mape_on:?}, {m_on} mapped; off: {n_off} \
         measured, MAPE {mape_off:?}",
        f.display()
    );
    // the frames' maps follow the flashes: the frames whose flash is off
    // by more than 10 % (12 of 16) are mapped, and the lengths are about
    // as many and as good as the matched haul's (the rig's pool alone,
    // session 9's code, which cannot follow one flash, measured 17 where
    // the matched haul gave 25)
    let off_by_tenth = FLASH.iter().filter(|&&k| (k - 1.0).abs() > 0.1).count() as u64;
    assert!(
        m_on + 2 >= off_by_tenth && m_on >= m_matched + 8,
        "{m_on} frames mapped ({off_by_tenth} flashes off by > 10 %, matched haul {m_matched})"
    );
    assert_like_matched((n_on, mape_on), (n_matched, mape_matched));
}

#[test]
fn core_and_reference_agree_on_the_flickering_haul() {
    assert_compare_agrees(flickering());
}
