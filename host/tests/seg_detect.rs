//! Segmentation quality on small synthetic hauls (issue 4, Section V.A):
//! `fishtrack::detect::detect_haul` over three 768² 12-frame hauls (seeds
//! 1–3), scored by `fishtrack::eval` against each haul's truth and pooled.
//!
//! Session 2 changed the synthetic fish motion (smooth, carried by the
//! flow), which moved every fish: the former single haul (seed 7, 15
//! countable fish frames) then scored R 0.27 — too few samples to bound
//! recall — so three hauls are pooled. Bounds: measured P 0.986, R 0.583,
//! large-target MAPE 8.0 % over 57 objects (session 2, before that
//! session's segmentation changes); asserted with margin so the test fails on a real
//! regression (segmentation that finds nothing gives R 0; the whole-scale
//! 16-bin backprojection lowered P by 0.04 on the former haul).

use fishtrack::detect::detect_haul;
use fishtrack::eval::evaluate;
use fishtrack::synth::{write_haul, SynthConfig};
use fishtrack_core::params::Params;

/// Writes the 768² 12-frame synthetic haul of `seed` under `dir`.
fn small_haul(dir: &std::path::Path, seed: u64) -> std::path::PathBuf {
    let haul = dir.join(format!("haul{seed}"));
    let cfg = SynthConfig {
        frames: 12,
        seed,
        size: 768,
        ..SynthConfig::default()
    };
    write_haul(&haul, &cfg).unwrap();
    haul
}

#[test]
fn segmentation_precision_recall_and_length_on_small_haul() {
    let dir = tempfile::tempdir().unwrap();
    let (mut tp, mut fp, mut fn_) = (0u64, 0u64, 0u64);
    let (mut ape, mut measured) = (0.0f64, 0u64);
    for seed in 1..=3u64 {
        let haul = small_haul(dir.path(), seed);
        let out = dir.path().join(format!("out{seed}"));
        let params = Params::for_frame(768);
        let sum = detect_haul(&haul, &params, &out).unwrap();
        assert_eq!(sum.frames, 12);
        assert_eq!(sum.dropped, 0);
        let rep = evaluate(&haul, &out).unwrap();
        let seg = rep.segmentation.expect("detections.csv is scored");
        let d = &seg.detection;
        eprintln!(
            "seed {seed}: P {:.4} R {:.4} tp {} fp {} fn {}",
            d.precision, d.recall, d.tp, d.fp, d.fn_
        );
        tp += d.tp;
        fp += d.fp;
        fn_ += d.fn_;
        let len = seg
            .large_target_length
            .expect("truth carries head/tail pixels");
        if len.measured > 0 {
            ape += len.mape * len.measured as f64;
            measured += len.measured;
        }
    }
    let precision = tp as f64 / (tp + fp).max(1) as f64;
    let recall = tp as f64 / (tp + fn_).max(1) as f64;
    let mape = ape / measured.max(1) as f64;
    eprintln!("pooled: P {precision:.4} R {recall:.4}, large-target MAPE {mape:.4} ({measured})");
    assert!(precision >= 0.80, "precision {precision}");
    assert!(recall >= 0.45, "recall {recall}");
    assert!(measured >= 15, "measured {measured}");
    assert!(mape <= 0.12, "large-target MAPE {mape}");
}

/// The dim level (`Params::dim_level`, beyond the paper) on the same kind
/// of hauls: it must find fish that level 0 alone misses (more true
/// positives) and only a few false ones.
#[test]
fn dim_level_adds_fish_not_false_alarms() {
    let dir = tempfile::tempdir().unwrap();
    let mut tot = [[0u64; 3]; 2]; // [off, on] × [tp, fp, fn]
    for seed in 1..=8u64 {
        let haul = small_haul(dir.path(), seed);
        for (k, on) in [false, true].into_iter().enumerate() {
            let out = dir.path().join(format!("out{seed}_{on}"));
            let mut params = Params::for_frame(768);
            params.dim_level = on;
            detect_haul(&haul, &params, &out).unwrap();
            let d = evaluate(&haul, &out)
                .unwrap()
                .segmentation
                .unwrap()
                .detection;
            eprintln!(
                "seed {seed} dim_level {on}: tp {} fp {} fn {}",
                d.tp, d.fp, d.fn_
            );
            for (t, v) in tot[k].iter_mut().zip([d.tp, d.fp, d.fn_]) {
                *t += v;
            }
        }
    }
    let ([tp0, fp0, _], [tp1, fp1, _]) = (tot[0], tot[1]);
    eprintln!("pooled: off {:?}, on {:?}", tot[0], tot[1]);
    assert!(tp1 > tp0, "no fish added: {tot:?}");
    assert!(
        fp1 <= fp0 + (tp1 - tp0),
        "more false alarms than fish added: {tot:?}"
    );
}
