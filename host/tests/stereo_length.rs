//! Stereo pairing (Section IV.A) and 3-D length (Section IV.D) of the core
//! on rendered synthetic stereo pairs with known 3-D fish.
//!
//! Run with `--nocapture` to see the figures.

mod stereo_scene;

use fishtrack_core::length::{measure_length, FishLength, LengthConfig};
use fishtrack_core::stereo::{pair_objects, PairingLimits};
use fishtrack_core::{ImageView, Params};
use stereo_scene::*;

fn objects(img: &[u8], masks: &[&Vec<bool>], w: usize, h: usize) -> Objs {
    let mut o = Objs::new();
    for m in masks {
        push_object(&mut o, img, m, w, h);
    }
    o
}

#[test]
fn pairing_with_swapped_order_distractor_border_cut_and_no_match() {
    let sc = Scene::new(1024, 640);
    let a = fish_at(-380.0, -150.0, 1600.0, [1.0, 0.1, 0.15], 280.0, 110.0, 1);
    let b = fish_at(-150.0, 70.0, 2200.0, [1.0, -0.05, -0.1], 350.0, 110.0, 2);
    let c = fish_at(-150.0, -30.0, 1300.0, [1.0, 0.2, 0.0], 250.0, 110.0, 3);
    // cut by the right border in the left view, whole in the right view
    let e = fish_at(560.0, 200.0, 1500.0, [1.0, 0.0, 0.0], 300.0, 110.0, 5);
    // only in the left view (no match), same band as b
    let d = fish_at(-420.0, 90.0, 2400.0, [1.0, 0.0, 0.1], 300.0, 110.0, 4);
    // only in the right view: a distractor on a's band, different texture
    let f = fish_at(-50.0, -160.0, 1700.0, [1.0, 0.05, 0.0], 280.0, 110.0, 99);
    let with_left = render(&sc, &[a, b, c, e, d]);
    let with_right = render(&sc, &[a, b, c, e, f]);
    let (w, h) = (sc.w, sc.h);
    let m = |r: &Rendered, k: usize, v: usize| r.masks[k][v].clone();
    // left: a b c e d (full masks, view 0 → index 1)
    let lm: Vec<Vec<bool>> = (0..5).map(|k| m(&with_left, k, 1)).collect();
    // right, swapped order: f e c b a (view 1 → index 3)
    let rm: Vec<Vec<bool>> = [4, 3, 2, 1, 0]
        .iter()
        .map(|&k| m(&with_right, k, 3))
        .collect();
    let left = objects(&with_left.left, &lm.iter().collect::<Vec<_>>(), w, h);
    let right = objects(&with_right.right, &rm.iter().collect::<Vec<_>>(), w, h);
    assert!(
        left.items[3].bbox.right() as usize == w,
        "e must be cut by the border in the left view"
    );
    let lv = ImageView::packed(&with_left.left, w, h).unwrap();
    let rv = ImageView::packed(&with_right.right, w, h).unwrap();
    let geom = sc.geometry();
    let out = pair_objects(&lv, &rv, &left, &right, &geom, &PairingLimits::default()).unwrap();
    let got: Vec<(u16, u16)> = out.pairs.iter().map(|p| (p.left, p.right)).collect();
    println!("pairs (left, right): {got:?}; stats {:?}", out.stats);
    for p in out.pairs.iter() {
        println!("  pair {:?}", p);
    }
    // a→4, b→3, c→2, e→1; d unpaired; f (right 0) unused
    assert_eq!(got, vec![(0, 4), (1, 3), (2, 2), (3, 1)]);
    assert_eq!(out.stats.unpaired_left, 1);
    // coarse disparity within a few pixels of the truth at the box centre
    for (p, fish) in out.pairs.iter().zip([a, b, c, e]) {
        let zc = 0.5 * (fish.head[2] + fish.tail[2]);
        let d_true = sc.f * sc.baseline / zc;
        let tol = 0.5 * (sc.project(fish.head).2 - sc.project(fish.tail).2).abs() + 3.0;
        assert!(
            (p.d_o as f64 - d_true).abs() <= tol,
            "d_o {} vs {d_true}",
            p.d_o
        );
    }
    // dense block matching over the frame would cost this many absolute differences
    let dense = fishtrack_core::stereo::dense_sad_ops(w as u64, h as u64, 256);
    println!(
        "SAD ops: object-height blocks {} vs dense {} (×{:.0})",
        out.stats.sad_ops,
        dense,
        dense as f64 / out.stats.sad_ops as f64
    );
    assert!(dense >= 50 * out.stats.sad_ops);
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Seg {
    /// Both views include the tail.
    Full,
    /// Left crops the tail, right keeps it.
    LeftCropped,
    /// Both views crop the tail.
    BothCropped,
}

/// Renders `fish` alone in `sc`, segments it as `seg` says, pairs it (one
/// pair) and measures its length with `params` and `cfg`.
fn measure_fish(
    sc: &Scene,
    fish: Fish,
    seg: Seg,
    params: &Params,
    cfg: &LengthConfig,
) -> FishLength {
    let r = render(sc, &[fish]);
    let (w, h) = (sc.w, sc.h);
    let (lmask, rmask) = match seg {
        Seg::Full => (&r.masks[0][1], &r.masks[0][3]),
        Seg::LeftCropped => (&r.masks[0][0], &r.masks[0][3]),
        Seg::BothCropped => (&r.masks[0][0], &r.masks[0][2]),
    };
    let left = objects(&r.left, &[lmask], w, h);
    let right = objects(&r.right, &[rmask], w, h);
    let lv = ImageView::packed(&r.left, w, h).unwrap();
    let rv = ImageView::packed(&r.right, w, h).unwrap();
    let geom = sc.geometry();
    let pairs = pair_objects(&lv, &rv, &left, &right, &geom, &PairingLimits::default()).unwrap();
    assert_eq!(pairs.pairs.len(), 1, "{fish:?} {seg:?}");
    measure_length::<N, R, 1024>(&lv, &rv, &left, &right, &pairs.pairs[0], &geom, params, cfg)
        .unwrap()
}

fn length_error(fish: Fish, seg: Seg, comp: bool, every_end: bool, noise: f64) -> (f64, bool) {
    let mut sc = Scene::new(1024, 640);
    sc.noise = noise;
    let params = Params {
        tail_compensation: comp,
        ..Params::default()
    };
    // this renderer's body is an ellipse, as blunt at the tail as at the
    // head: the taper rule (`tail_by_taper`, tested in `core::fin`) cannot
    // tell them apart here, so it is off
    let cfg = LengthConfig {
        snake_every_end: every_end,
        tail_by_taper: false,
        ..LengthConfig::default()
    };
    let l = measure_fish(&sc, fish, seg, &params, &cfg);
    let truth = fish.length();
    if std::env::var("STEREO_DEBUG").is_ok() {
        let (hx, hy, hd) = sc.project(fish.head);
        let (tx, ty, td) = sc.project(fish.tail);
        println!(
            "truth head ({hx:.1},{hy:.1},d {hd:.2}) tail ({tx:.1},{ty:.1},d {td:.2})\n  got {l:?}"
        );
    }
    let err = (l.length_mm as f64 - truth) / truth * 100.0;
    let comped = l.ends.iter().any(|e| e.compensated);
    if comp && !every_end {
        println!(
            "   eq15 SAD ratios {:.2} {:.2}",
            l.ends[0].sad_ratio, l.ends[1].sad_ratio
        );
    }
    (err, comped)
}

fn poses(tail_grey: f64) -> Vec<Fish> {
    vec![
        fish_at(-150.0, -20.0, 1500.0, [1.0, 0.0, 0.0], 300.0, tail_grey, 11),
        fish_at(-200.0, 40.0, 1800.0, [1.0, 0.15, 0.3], 320.0, tail_grey, 12),
        fish_at(
            -100.0,
            -60.0,
            1300.0,
            [1.0, -0.25, -0.2],
            240.0,
            tail_grey,
            13,
        ),
        fish_at(-250.0, 0.0, 2200.0, [1.0, 0.05, 0.5], 400.0, tail_grey, 14),
        // head on the right (swimming the other way), tilted
        fish_at(150.0, 30.0, 1600.0, [-1.0, 0.3, 0.1], 280.0, tail_grey, 15),
    ]
}

#[test]
fn length_with_and_without_tail_compensation() {
    for noise in [4.0, 8.0] {
        println!("noise σ {noise}: fish | seg | comp off % | comp eq15 % | comp every end %");
        let mut worst_bright = 0.0f64;
        let mut worst_dim_asym = 0.0f64;
        let mut worst_dim_sym_every = 0.0f64;
        let mut sum_off = 0.0;
        let mut sum_on = 0.0;
        let mut n_dim = 0.0;
        for (grey, segs) in [
            (110.0, vec![Seg::Full]),
            (48.0, vec![Seg::LeftCropped, Seg::BothCropped]),
        ] {
            for (i, fish) in poses(grey).into_iter().enumerate() {
                for &seg in &segs {
                    let (off, _) = length_error(fish, seg, false, false, noise);
                    let (on, c_on) = length_error(fish, seg, true, false, noise);
                    let (every, c_every) = length_error(fish, seg, true, true, noise);
                    println!(
                        "{i} tail {grey} | {seg:?} | {off:+.2} | {on:+.2}{} | {every:+.2}{}",
                        if c_on { " (snake)" } else { "" },
                        if c_every { " (snake)" } else { "" }
                    );
                    match seg {
                        Seg::Full => {
                            worst_bright =
                                worst_bright.max(off.abs()).max(on.abs()).max(every.abs());
                            // compensation must not hurt fish whose tail is whole
                            assert!(
                                on.abs() <= off.abs() + 0.5,
                                "comp hurt fish {i}: {off} → {on}"
                            );
                            assert!(
                                every.abs() <= off.abs() + 1.0,
                                "every-end hurt fish {i}: {off} → {every}"
                            );
                        }
                        Seg::LeftCropped => {
                            worst_dim_asym = worst_dim_asym.max(on.abs());
                            sum_off += off.abs();
                            sum_on += on.abs();
                            n_dim += 1.0;
                            assert!(
                                on.abs() < off.abs(),
                                "comp did not help fish {i}: {off} → {on}"
                            );
                        }
                        Seg::BothCropped => {
                            worst_dim_sym_every = worst_dim_sym_every.max(every.abs());
                            assert!(
                                every.abs() < off.abs(),
                                "every-end did not help fish {i}: {off} → {every}"
                            );
                        }
                    }
                }
            }
        }
        println!(
        "worst |err|: whole tails {worst_bright:.2} %, dim tail cropped in left view (eq15 snake) {worst_dim_asym:.2} %, \
         dim tail cropped in both views (every-end snake) {worst_dim_sym_every:.2} %; \
         mean |err| dim/left-cropped off {:.2} % on {:.2} %",
        sum_off / n_dim,
        sum_on / n_dim
    );
        assert!(worst_bright < 3.0);
        assert!(worst_dim_asym < 5.0);
        assert!(worst_dim_sym_every < 5.0);
    }
}

/// The core against the f64 reference (`fishtrack::reference::stereo`):
/// identical pairs, lengths within 0.5 %, on the pairing scene and on every
/// length scene (tail compensation on, eq. 15 and every-end modes).
#[test]
fn core_agrees_with_the_f64_reference() {
    use fishtrack::reference::stereo as rs;
    let sc = Scene::new(1024, 640);
    let mut scenes: Vec<(Vec<Fish>, Seg)> = vec![(
        vec![
            fish_at(-380.0, -150.0, 1600.0, [1.0, 0.1, 0.15], 280.0, 110.0, 1),
            fish_at(-150.0, 70.0, 2200.0, [1.0, -0.05, -0.1], 350.0, 110.0, 2),
            fish_at(-150.0, -30.0, 1300.0, [1.0, 0.2, 0.0], 250.0, 110.0, 3),
            fish_at(560.0, 200.0, 1500.0, [1.0, 0.0, 0.0], 300.0, 110.0, 5),
        ],
        Seg::Full,
    )];
    for f in poses(110.0) {
        scenes.push((vec![f], Seg::Full));
    }
    for f in poses(48.0) {
        scenes.push((vec![f], Seg::LeftCropped));
        scenes.push((vec![f], Seg::BothCropped));
    }
    let geom = sc.geometry();
    let rgeom = rs::Geometry::from_core(&geom);
    let limits = PairingLimits::default();
    let params = Params::default();
    let mut worst = 0.0f64;
    let mut n_pairs = 0;
    for every_end in [false, true] {
        let cfg = LengthConfig {
            snake_every_end: every_end,
            ..LengthConfig::default()
        };
        for (fish, seg) in &scenes {
            let r = render(&sc, fish);
            let (w, h) = (sc.w, sc.h);
            let (li, ri) = match seg {
                Seg::Full => (1, 3),
                Seg::LeftCropped => (0, 3),
                Seg::BothCropped => (0, 2),
            };
            let lm: Vec<&Vec<bool>> = r.masks.iter().map(|m| &m[li]).collect();
            let rm: Vec<&Vec<bool>> = r.masks.iter().rev().map(|m| &m[ri]).collect();
            let left = objects(&r.left, &lm, w, h);
            let right = objects(&r.right, &rm, w, h);
            let lv = ImageView::packed(&r.left, w, h).unwrap();
            let rv = ImageView::packed(&r.right, w, h).unwrap();
            let pairs = pair_objects(&lv, &rv, &left, &right, &geom, &limits).unwrap();
            let core: Vec<(usize, usize, Option<f64>)> = pairs
                .pairs
                .iter()
                .map(|p| {
                    let l = measure_length::<N, R, 1024>(
                        &lv, &rv, &left, &right, p, &geom, &params, &cfg,
                    );
                    (
                        p.left as usize,
                        p.right as usize,
                        l.ok().map(|l| l.length_mm as f64),
                    )
                })
                .collect();
            let (gl, gr) = (
                rs::Gray {
                    data: &r.left,
                    w,
                    h,
                },
                rs::Gray {
                    data: &r.right,
                    w,
                    h,
                },
            );
            let (rl, rr) = (rs::ref_objects(&left), rs::ref_objects(&right));
            let rpairs = rs::pair(&gl, &gr, &rl, &rr, &rgeom, &rs::Limits::from(&limits));
            let reference: Vec<(usize, usize, Option<f64>)> = rpairs
                .iter()
                .map(|p| {
                    let l = rs::length(&gl, &gr, &rl, &rr, p, &rgeom, &params, &cfg);
                    (p.left, p.right, l.map(|l| l.length))
                })
                .collect();
            let a = rs::compare(&core, &reference);
            assert!(
                a.ok(),
                "{seg:?} every_end={every_end}: {a:?}\ncore {core:?}\nref {reference:?}"
            );
            worst = worst.max(a.max_length_rel_diff);
            n_pairs += core.len();
        }
    }
    println!(
        "core vs f64 reference: {n_pairs} pairs identical, worst length difference {:.4} %",
        worst * 100.0
    );
}

/// Occlusion exception: two fish separate in the left view merge into one
/// blob in the right view; both pair with it, the second flagged `occluded`.
#[test]
fn occlusion_shares_a_right_blob() {
    let sc = Scene::new(1024, 640);
    let a = fish_at(-300.0, 0.0, 1500.0, [1.0, 0.0, 0.0], 200.0, 110.0, 21);
    // far fish: left x ≈ 200..280, right x ≈ 120..200, touching a's right image
    let b = fish_at(-967.0, 10.0, 2500.0, [1.0, 0.0, 0.0], 250.0, 110.0, 22);
    let r = render(&sc, &[a, b]);
    let (w, h) = (sc.w, sc.h);
    let left = objects(&r.left, &[&r.masks[0][1], &r.masks[1][1]], w, h);
    let union: Vec<bool> = r.masks[0][3]
        .iter()
        .zip(&r.masks[1][3])
        .map(|(p, q)| *p || *q)
        .collect();
    let right = objects(&r.right, &[&union], w, h);
    println!(
        "left boxes {:?} {:?}, right blob {:?}",
        left.items[0].bbox, left.items[1].bbox, right.items[0].bbox
    );
    let lv = ImageView::packed(&r.left, w, h).unwrap();
    let rv = ImageView::packed(&r.right, w, h).unwrap();
    let limits = PairingLimits {
        min_size_ratio: 0.3,
        ..PairingLimits::default()
    };
    let out = pair_objects(&lv, &rv, &left, &right, &sc.geometry(), &limits).unwrap();
    println!("{:?}\n{:?}", out.pairs, out.stats);
    assert_eq!(out.pairs.len(), 2);
    assert!(out.pairs.iter().all(|p| p.right == 0));
    assert_eq!(out.pairs.iter().filter(|p| p.occluded).count(), 1);
    assert_eq!(out.stats.occlusions, 1);
    // each keeps its own disparity
    let mut d: Vec<f32> = out.pairs.iter().map(|p| p.d_o).collect();
    d.sort_by(|x, y| x.total_cmp(y));
    assert!(
        (d[0] - 80.0).abs() <= 3.0 && (d[1] - 133.3).abs() <= 3.0,
        "{d:?}"
    );
}

/// The epipolar search (`core::epipolar`): fish the right segmentation
/// "missed" (their masks left out of the right objects) are found at
/// their disparity, a fish seen in the left view only stays unpaired, and
/// the core agrees with the f64 reference (`reference::epipolar`) pair
/// for pair.
#[test]
fn epipolar_search_finds_fish_missing_from_the_right_objects_like_the_reference() {
    use fishtrack::reference::{epipolar as re, stereo as rs};
    use fishtrack_core::epipolar::{search_unpaired, SEARCHED_LEVEL};
    let sc = Scene::new(1024, 640);
    let a = fish_at(-380.0, -150.0, 1600.0, [1.0, 0.1, 0.15], 280.0, 110.0, 1);
    let b = fish_at(-150.0, 70.0, 2200.0, [1.0, -0.05, -0.1], 350.0, 110.0, 2);
    let c = fish_at(-150.0, -30.0, 1300.0, [1.0, 0.2, 0.0], 250.0, 110.0, 3);
    // only in the left view
    let d = fish_at(-300.0, 220.0, 2400.0, [1.0, 0.0, 0.1], 300.0, 110.0, 4);
    let with_left = render(&sc, &[a, b, c, d]);
    let with_right = render(&sc, &[a, b, c]);
    let (w, h) = (sc.w, sc.h);
    let lm: Vec<&Vec<bool>> = (0..4).map(|k| &with_left.masks[k][1]).collect();
    let left = objects(&with_left.left, &lm, w, h);
    // the right segmentation found a only
    let mut right = objects(&with_right.right, &[&with_right.masks[0][3]], w, h);
    let lv = ImageView::packed(&with_left.left, w, h).unwrap();
    let rv = ImageView::packed(&with_right.right, w, h).unwrap();
    let geom = sc.geometry();
    let limits = PairingLimits::default();
    let mut pairs = pair_objects(&lv, &rv, &left, &right, &geom, &limits).unwrap();
    assert_eq!(pairs.pairs.len(), 1);
    // the reference, from the same objects
    let (gl, gr) = (
        rs::Gray {
            data: &with_left.left,
            w,
            h,
        },
        rs::Gray {
            data: &with_right.right,
            w,
            h,
        },
    );
    let (rl, mut rr) = (rs::ref_objects(&left), rs::ref_objects(&right));
    let rgeom = rs::Geometry::from_core(&geom);
    let mut rpairs = rs::pair(&gl, &gr, &rl, &rr, &rgeom, &rs::Limits::from(&limits));
    search_unpaired(&lv, &rv, &left, &mut right, &mut pairs, &geom, &limits);
    re::search_unpaired(
        &gl,
        &gr,
        &rl,
        &mut rr,
        &mut rpairs,
        &rgeom,
        &rs::Limits::from(&limits),
    );
    let core: Vec<(usize, usize, f64, bool)> = pairs
        .pairs
        .iter()
        .map(|p| (p.left as usize, p.right as usize, p.d_o as f64, p.searched))
        .collect();
    let reference: Vec<(usize, usize, f64, bool)> = rpairs
        .iter()
        .map(|p| (p.left, p.right, p.d_o, p.searched))
        .collect();
    println!(
        "core {core:?}\nreference {reference:?}\nstats {:?}",
        pairs.stats
    );
    assert_eq!(core, reference);
    // a by its blocks, b and c by the search, d unpaired
    let got: Vec<(usize, bool)> = core.iter().map(|c| (c.0, c.3)).collect();
    assert_eq!(got, vec![(0, false), (1, true), (2, true)]);
    assert_eq!(pairs.stats.searched, 2);
    for p in pairs.pairs.iter().filter(|p| p.searched) {
        let ro = right.items[p.right as usize];
        assert_eq!(ro.level, SEARCHED_LEVEL);
        // the found box against the fish's own right mask
        let mut truth = Objs::new();
        push_object(
            &mut truth,
            &with_right.right,
            &with_right.masks[p.left as usize][3],
            w,
            h,
        );
        let iou = ro.bbox.iou(&truth.items[0].bbox);
        assert!(iou >= 0.8, "fish {}: IoU {iou}", p.left);
        // measured, but withheld by the length stage, core and reference
        let cl = measure_length::<N, R, 1024>(
            &lv,
            &rv,
            &left,
            &right,
            p,
            &geom,
            &Params::default(),
            &LengthConfig::default(),
        )
        .unwrap();
        assert!(!cl.consistent && cl.length_mm > 0.0);
        let rp = rpairs.iter().find(|q| q.left == p.left as usize).unwrap();
        let rlen = rs::length(
            &gl,
            &gr,
            &rl,
            &rr,
            rp,
            &rgeom,
            &Params::default(),
            &LengthConfig::default(),
        );
        assert!(rlen.is_some_and(|v| !v.consistent));
        let rb = rr[p.right as usize].bbox;
        assert_eq!(
            (rb.0 as u32, rb.1 as u32, rb.2 as u32, rb.3 as u32),
            (ro.bbox.x, ro.bbox.y, ro.bbox.w, ro.bbox.h)
        );
    }
}

/// The slanted fit (`core::slant`, on by default) puts both ends' disparity
/// within a pixel of the truth on fish lying obliquely in depth, textured
/// or nearly flat, and on the smooth bodies it does better than the block
/// line alone (`slant_fit: false`), whose slope the noise sets there.
#[test]
fn slanted_fit_finds_both_end_disparities() {
    let mut worst = 0.0f64;
    let (mut err_fit, mut err_line) = (0.0f64, 0.0f64);
    for texture in [35.0, 3.0] {
        for (k, dir) in [[1.0, 0.05, 0.6], [1.0, -0.2, -0.5], [-1.0, 0.1, 0.45]]
            .iter()
            .enumerate()
        {
            let mut fish = fish_at(
                -150.0 * dir[0],
                -10.0,
                1600.0,
                *dir,
                320.0,
                120.0,
                21 + k as u32,
            );
            fish.texture = texture;
            let mut sc = Scene::new(1024, 640);
            sc.noise = 4.0;
            let truth_d = |px: (f32, f32)| {
                let (hx, hy, hd) = sc.project(fish.head);
                let (tx, ty, td) = sc.project(fish.tail);
                let dh = (px.0 as f64 - hx).powi(2) + (px.1 as f64 - hy).powi(2);
                let dt = (px.0 as f64 - tx).powi(2) + (px.1 as f64 - ty).powi(2);
                if dh < dt {
                    hd
                } else {
                    td
                }
            };
            let mut errs = [0.0f64; 2];
            for (i, slant_fit) in [true, false].into_iter().enumerate() {
                let cfg = LengthConfig {
                    slant_fit,
                    // the line's own value at both ends, not the masks'
                    mask_end_tolerance: 0.0,
                    ..LengthConfig::default()
                };
                let l = measure_fish(&sc, fish, Seg::Full, &Params::default(), &cfg);
                for e in l.ends {
                    errs[i] = errs[i].max((e.d as f64 - truth_d(e.px)).abs());
                }
            }
            println!("texture {texture} dir {dir:?}: end disparity error fit {:.2} px, block line {:.2} px", errs[0], errs[1]);
            worst = worst.max(errs[0]);
            if texture < 10.0 {
                err_fit += errs[0];
                err_line += errs[1];
            }
        }
    }
    assert!(
        worst <= 1.0,
        "slanted fit's end disparity off by {worst:.2} px"
    );
    assert!(
        err_fit < err_line,
        "smooth bodies: fit {err_fit:.2} px, block line {err_line:.2} px"
    );
}

/// A caudal fin a few grey levels above the water, lost alike in both
/// views' masks: the snake's pixel level (above the noise) cannot see it,
/// the averaged fin profile (`core::fin`, `LengthConfig::fin_profile`)
/// can, and it restores the length; with the profile off the fish stays
/// short. Whole tails are left as they are. (This renderer's body is an
/// ellipse, as blunt at the tail as at the head, so the taper rule that
/// keeps compensation to the tail, `tail_by_taper`, is off here; the
/// rule has its own test in `core::fin`.)
#[test]
fn a_fin_too_dim_for_the_snake_is_found_by_its_profile() {
    let measure = |fish: Fish, seg: Seg, fin: bool| -> f64 {
        let mut sc = Scene::new(1024, 640);
        sc.noise = 1.0;
        let cfg = LengthConfig {
            fin_profile: fin,
            tail_by_taper: false,
            ..LengthConfig::default()
        };
        let l = measure_fish(&sc, fish, seg, &Params::default(), &cfg);
        (l.length_mm as f64 - fish.length()) / fish.length() * 100.0
    };
    let mut restored = 0;
    for (i, fish) in poses(36.0).into_iter().enumerate() {
        let off = measure(fish, Seg::BothCropped, false);
        let on = measure(fish, Seg::BothCropped, true);
        let whole_off = measure(fish, Seg::Full, false);
        let whole_on = measure(fish, Seg::Full, true);
        println!("fish {i}: dim fin cut in both views {off:+.2} → {on:+.2} %; whole {whole_off:+.2} → {whole_on:+.2} %");
        // never worse, whole tails untouched
        assert!(on.abs() <= off.abs() + 0.5, "fish {i}: {off} → {on}");
        assert!(
            (whole_on - whole_off).abs() <= 0.5,
            "whole tail changed: fish {i}"
        );
        assert!(off < -15.0, "fish {i}: the cropped fin costs {off} %");
        if on.abs() <= 2.0 {
            restored += 1;
        }
    }
    // this renderer's fan is only ~3 px wide where it leaves the body, so
    // the profile's start (over 2J + 1 ≈ h_o/1.5 pixels) sees it in two
    // of the five poses (0 and 2: −19.8 → +0.6 %, −19.5 → +0.3 %)
    assert!(restored >= 2, "{restored} of 5 dim fins restored");
}
