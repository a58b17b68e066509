//! The core's segmentation primitives against OpenCV (the external oracle):
//! equal pixel for pixel, value for value. Conventions are OpenCV's defaults
//! on both sides (morphology ignores pixels outside the image; the median
//! replicates the border); the test writes frames, runs
//! `scripts/opencv_segment_oracle.py`, and compares.

mod support;

use fishtrack_core::hist::{add_row_256, bin_of, fold_bins, ratio_backprojection_lut};
use fishtrack_core::label::label_components;
use fishtrack_core::lowres::{box_mean16, gradient_disk_u16};
use fishtrack_core::morph::{
    close_disk_in_place, dilate_disk, disk_scratch_len, erode_disk, gradient_disk, median3_binary,
    open_disk_in_place, remove_mesh, Disk,
};
use fishtrack_core::threshold::otsu;
use fishtrack_core::ImageView;
use support::*;

fn count_diff(a: &[u8], b: &[u8]) -> usize {
    a.iter().zip(b).filter(|(x, y)| x != y).count()
}

fn check_frame(w: usize, h: usize, grey: &[u8], seed: u64) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_pgm(&d.join("grey.pgm"), w, h, grey);
    // a binary mask with speckle and blobs: grey above its Otsu level plus noise
    let mut hist = [0u32; 256];
    add_row_256(&mut hist, grey);
    let t = otsu(&hist);
    let mut rng = Lcg(seed);
    let mask: Vec<u8> = grey
        .iter()
        .map(|&p| if p > t || rng.next() < 0.05 { 255 } else { 0 })
        .collect();
    write_pgm(&d.join("mask.pgm"), w, h, &mask);
    // M_low ⊇ M_high, as the double thresholds make them
    let m_low: Vec<u8> = grey
        .iter()
        .map(|&p| if p as i32 > t as i32 - 12 { 255 } else { 0 })
        .collect();
    let m_high: Vec<u8> = grey
        .iter()
        .map(|&p| if p as i32 > t as i32 - 4 { 255 } else { 0 })
        .collect();
    write_pgm(&d.join("m_low.pgm"), w, h, &m_low);
    write_pgm(&d.join("m_high.pgm"), w, h, &m_high);
    if run_python("opencv_segment_oracle.py", &[d]).is_none() {
        return;
    }
    let cv = |name: &str| {
        let (cw, ch, px) = read_pgm(&d.join(name));
        assert_eq!((cw, ch), (w, h), "{name}");
        px
    };
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("otsu.json")).unwrap()).unwrap();

    // Otsu
    assert_eq!(t as i64, json["otsu"].as_i64().unwrap(), "Otsu threshold");

    // morphology with the 7 × 7 MORPH_ELLIPSE
    let v = ImageView::packed(grey, w, h).unwrap();
    let disk = Disk::opencv_ellipse(7);
    let mut scratch = vec![0u8; disk_scratch_len(w, 3)];
    let mut out = vec![0u8; w * h];
    let mut tmp = vec![0u8; w * h];
    dilate_disk(v, &disk, &mut out, &mut scratch).unwrap();
    assert_eq!(count_diff(&out, &cv("dilate.pgm")), 0, "dilate");
    erode_disk(v, &disk, &mut out, &mut scratch).unwrap();
    assert_eq!(count_diff(&out, &cv("erode.pgm")), 0, "erode");
    gradient_disk(v, &disk, &mut out, &mut scratch).unwrap();
    assert_eq!(count_diff(&out, &cv("gradient.pgm")), 0, "gradient");
    out.copy_from_slice(grey);
    open_disk_in_place(&mut out, w, h, &disk, &mut tmp, &mut scratch).unwrap();
    assert_eq!(count_diff(&out, &cv("open.pgm")), 0, "open");
    out.copy_from_slice(grey);
    close_disk_in_place(&mut out, w, h, &disk, &mut tmp, &mut scratch).unwrap();
    assert_eq!(count_diff(&out, &cv("close.pgm")), 0, "close");
    remove_mesh(v, 7, &mut tmp, &mut out).unwrap();
    assert_eq!(count_diff(&out, &cv("mesh.pgm")), 0, "mesh removal");

    // 3 × 3 median on a binary mask
    median3_binary(ImageView::packed(&mask, w, h).unwrap(), &mut out).unwrap();
    assert_eq!(count_diff(&out, &cv("median.pgm")), 0, "median");

    // connected components: the same partition of the pixels. (The
    // numbering differs by convention: ours is raster order of each
    // component's first pixel; OpenCV's block-based scan numbers otherwise.)
    let mut labels = vec![0i32; w * h];
    let n = label_components(ImageView::packed(&mask, w, h).unwrap(), &mut labels, |_| {
        true
    })
    .unwrap();
    assert_eq!(
        n as i64,
        json["components"].as_i64().unwrap(),
        "component count"
    );
    let raw = std::fs::read(d.join("labels.bin")).unwrap();
    let cvl: Vec<i32> = raw
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(cvl.len(), w * h);
    let mut ours_to_cv = vec![-1i32; n as usize + 1];
    let mut cv_to_ours = vec![-1i32; n as usize + 1];
    for (&a, &b) in labels.iter().zip(&cvl) {
        assert_eq!(a == 0, b == 0, "foreground differs");
        assert!(b >= 0 && b as u32 <= n, "OpenCV label {b} out of range");
        if ours_to_cv[a as usize] == -1 {
            ours_to_cv[a as usize] = b;
        }
        if cv_to_ours[b as usize] == -1 {
            cv_to_ours[b as usize] = a;
        }
        assert_eq!(
            ours_to_cv[a as usize], b,
            "one component of ours spans two of OpenCV's"
        );
        assert_eq!(
            cv_to_ours[b as usize], a,
            "one component of OpenCV's spans two of ours"
        );
    }
    // statistics per component (area, box, centroid) from our labels
    let cc = json["cc"].as_array().unwrap();
    let mut m = vec![fishtrack_core::label::Moments::EMPTY; n as usize];
    for (i, &l) in labels.iter().enumerate() {
        if l > 0 {
            m[l as usize - 1].add_run((i / w) as u32, (i % w) as u32, (i % w) as u32 + 1);
        }
    }
    for (k, mm) in m.iter().enumerate() {
        let c = &cc[ours_to_cv[k + 1] as usize - 1];
        assert_eq!(mm.area as i64, c["area"].as_i64().unwrap(), "area {k}");
        assert_eq!(mm.x_min as i64, c["left"].as_i64().unwrap(), "left {k}");
        assert_eq!(mm.y_min as i64, c["top"].as_i64().unwrap(), "top {k}");
        assert_eq!(
            (mm.x_max - mm.x_min + 1) as i64,
            c["width"].as_i64().unwrap()
        );
        assert_eq!(
            (mm.y_max - mm.y_min + 1) as i64,
            c["height"].as_i64().unwrap()
        );
        let (cx, cy) = mm.centroid();
        assert!(
            (cx as f64 - c["cx"].as_f64().unwrap()).abs() < 1e-3,
            "cx {k}"
        );
        assert!(
            (cy as f64 - c["cy"].as_f64().unwrap()).abs() < 1e-3,
            "cy {k}"
        );
    }

    // histograms of the two masks, ratio histogram, backprojection
    for bins in [8usize, 16, 32] {
        let (mut hl, mut hh) = ([0u32; 256], [0u32; 256]);
        for ((&p, &l), &hm) in grey.iter().zip(&m_low).zip(&m_high) {
            hl[p as usize] += (l != 0) as u32;
            hh[p as usize] += (hm != 0) as u32;
        }
        let (mut bl, mut bh) = (vec![0u32; bins], vec![0u32; bins]);
        fold_bins(&hl, &mut bl);
        fold_bins(&hh, &mut bh);
        let lut = ratio_backprojection_lut(&bh, &bl, 0.3);
        let ours: Vec<u8> = grey
            .iter()
            .map(|&p| if lut[p as usize] { 255 } else { 0 })
            .collect();
        assert_eq!(
            count_diff(&ours, &cv(&format!("backproject_{bins}.pgm"))),
            0,
            "backprojection, {bins} bins"
        );
        assert!(bin_of(255, bins) == bins - 1);
    }
    // reduced-resolution coarse pass: INTER_AREA downsample (×16, rounded)
    // and the 16-bit morphological gradient by the 5 × 5 ellipse
    for f in [4usize, 8] {
        let path = d.join(format!("lowres_{f}.bin"));
        if w % f != 0 || h % f != 0 {
            assert!(!path.exists());
            continue;
        }
        let read16 = |p: &std::path::Path| -> Vec<u16> {
            std::fs::read(p)
                .unwrap()
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect()
        };
        let (lw, lh) = (w / f, h / f);
        let mut low = vec![0u16; lw * lh];
        assert_eq!(box_mean16(v, f, &mut low), Ok((lw, lh)));
        assert_eq!(low, read16(&path), "INTER_AREA downsample by {f}");
        let mut g = vec![0u16; lw * lh];
        gradient_disk_u16(&low, lw, lh, &Disk::opencv_ellipse(5), &mut g).unwrap();
        assert_eq!(
            g,
            read16(&d.join(format!("lowgrad_{f}.bin"))),
            "16-bit gradient at 1/{f}"
        );
    }
    eprintln!("OpenCV oracle: {w}x{h}: Otsu {t}, {n} components, all primitives identical");
}

#[test]
fn primitives_equal_opencv_on_a_drawn_haul_frame() {
    let (w, h) = (320, 256);
    let fish = school(w, h, 4, 3);
    let grey = draw(w, h, &fish, 6.0, true, 3);
    check_frame(w, h, &grey, 3);
}

#[test]
fn primitives_equal_opencv_on_noise_and_odd_sizes() {
    for (w, h, seed) in [
        (97usize, 61usize, 1u64),
        (7, 5, 2),
        (1, 9, 3),
        (33, 1, 4),
        (64, 40, 5),
        (8, 8, 6),
    ] {
        let mut rng = Lcg(seed);
        let grey: Vec<u8> = (0..w * h).map(|_| (rng.next() * 256.0) as u8).collect();
        check_frame(w, h, &grey, seed);
    }
}
