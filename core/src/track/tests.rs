//! Scenario and property tests of the tracker. Test-only: declared as
//! `#[cfg(test)] mod tests;` in `track/mod.rs`, so std is fine here.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use super::*;
use crate::params::Tracker as Assoc;
use proptest::prelude::*;
use std::vec::Vec;

const W: u32 = 2048;

/// A fish-like observation centred at (x, y): `len` px long, depth z mm,
/// histogram peaked at `bin`, right view shifted by the disparity.
fn fish(x: f32, y: f32, len: f32, bin: usize, z: f32, pair: u16) -> Observation {
    let h = len * 0.25;
    // the visible part of the box (a fish beyond x = 0 or y = 0 is cut)
    let (x0, y0) = ((x - len / 2.0).max(0.0), (y - h / 2.0).max(0.0));
    let bbox = Roi::new(
        x0 as u32,
        y0 as u32,
        (x + len / 2.0 - x0).max(1.0) as u32,
        (y + h / 2.0 - y0).max(1.0) as u32,
    );
    let mut hist = [0u32; 16];
    for (b, v) in hist.iter_mut().enumerate() {
        let d = b as i32 - bin as i32;
        *v = match d.abs() {
            0 => 60,
            1 => 25,
            2 => 5,
            _ => 0,
        };
    }
    let area = (len * h * 0.7) as u32;
    let left = CameraView {
        cx: x,
        cy: y,
        bbox,
        area,
        hist,
        ..Default::default()
    };
    let disp = 2000.0 * 300.0 / z;
    let mut right = left;
    right.cx -= disp;
    right.bbox.x = right.bbox.x.saturating_sub(disp as u32);
    Observation {
        left,
        right: Some(right),
        depth_mm: Some(z),
        pair,
    }
}

#[derive(Default)]
struct Log {
    frames: Vec<(u32, u32, Option<u16>)>, // (track, frame, obs)
    closed: Vec<(u32, CloseReason, u32, Vec<PathStep>)>,
}

impl Log {
    fn sink(&mut self) -> impl FnMut(&TrackEvent<'_>) + '_ {
        move |e: &TrackEvent<'_>| match e {
            TrackEvent::Frame { track, step } => self.frames.push((*track, step.frame, step.obs)),
            TrackEvent::Closed {
                track,
                reason,
                hits,
                path,
                ..
            } => self.closed.push((*track, *reason, *hits, path.to_vec())),
        }
    }

    /// Track id that claims observation `obs` of frame `f`.
    fn ids_of(&self, f: u32, obs: u16) -> Vec<u32> {
        let mut v: Vec<u32> = self
            .frames
            .iter()
            .filter(|&&(_, fr, o)| fr == f && o == Some(obs))
            .map(|&(t, _, _)| t)
            .collect();
        v.sort();
        v.dedup();
        v
    }
}

fn run(frames: &[Vec<Observation>], assoc: Assoc) -> (Log, TrackStats) {
    run_assoc_cfg(frames, assoc, TrackConfig::for_frame(W, W))
}

fn run_assoc_cfg(frames: &[Vec<Observation>], assoc: Assoc, cfg: TrackConfig) -> (Log, TrackStats) {
    let mut tr: DefaultTracker = Tracker::new(cfg).unwrap();
    let p = Params {
        tracker: assoc,
        ..Params::for_frame(W)
    };
    let mut log = Log::default();
    {
        let mut sink = log.sink();
        for (f, obs) in frames.iter().enumerate() {
            tr.step(f as u32, obs, &p, &mut sink).unwrap();
        }
        tr.finish(&mut sink);
    }
    (log, tr.stats())
}

#[test]
fn occlusion_two_fish_crossing_keep_one_id_each() {
    // A goes down-left, B up-left; at frame 2 they overlap and segmentation
    // sees one merged object (obs 0 of frame 2), shared by both paths.
    let mut frames = Vec::new();
    for t in 0..5 {
        let tf = t as f32;
        let a = fish(1950.0 - 400.0 * tf, 800.0 + 100.0 * tf, 300.0, 4, 2000.0, 0);
        let b = fish(
            1950.0 - 400.0 * tf,
            1200.0 - 100.0 * tf,
            300.0,
            11,
            2000.0,
            1,
        );
        if t == 2 {
            // Realistic merge: union of both masks (histograms add, 0.8 of
            // the summed area visible), centroid between the two.
            let mut m = fish(1150.0, 1000.0, 360.0, 7, 2000.0, 0);
            let area = ((a.left.area + b.left.area) as f32 * 0.8) as u32;
            let mut hist = a.left.hist;
            for (h, o) in hist.iter_mut().zip(b.left.hist.iter()) {
                *h += o;
            }
            m.left.area = area;
            m.left.hist = hist;
            if let Some(r) = m.right.as_mut() {
                r.area = area;
                r.hist = hist;
            }
            frames.push(std::vec![m]);
        } else {
            frames.push(std::vec![a, b]);
        }
    }
    {
        let (log, _) = run(&frames, Assoc::Viterbi);
        let ida: Vec<u32> = [0, 1, 3, 4].iter().map(|&f| log.ids_of(f, 0)[0]).collect();
        let idb: Vec<u32> = [0, 1, 3, 4].iter().map(|&f| log.ids_of(f, 1)[0]).collect();
        assert!(ida.iter().all(|&i| i == ida[0]), "{ida:?}");
        assert!(idb.iter().all(|&i| i == idb[0]), "{idb:?}");
        assert_ne!(ida[0], idb[0]);
        // The merged object is never taken by one of the two fish alone (no
        // id swap). With the default costs its appearance (summed histogram,
        // 1.6× area) costs more than a lost frame, so both paths carry it by
        // prediction and it becomes a 1-hit target of its own.
        let m = log.ids_of(2, 0);
        assert!(!m.contains(&ida[0]) || m.contains(&idb[0]), "{m:?}");
        assert!(!m.contains(&idb[0]) || m.contains(&ida[0]), "{m:?}");
        let fish_tracks: Vec<_> = log
            .closed
            .iter()
            .filter(|c| c.0 == ida[0] || c.0 == idb[0])
            .collect();
        assert_eq!(fish_tracks.len(), 2);
        assert!(fish_tracks
            .iter()
            .all(|c| c.3.len() == 5 && c.3.iter().filter(|s| s.obs.is_some()).count() == 4));
    }
}

#[test]
fn fish_lost_for_one_frame_keeps_its_id() {
    let mut frames = Vec::new();
    for t in 0..6 {
        let tf = t as f32;
        let mut v = Vec::new();
        // Debris away from the border (never a target: small, mid-frame).
        // It appears from the second frame on: in a haul's first frame
        // every observation is a birth (the fish already in view).
        if t > 0 {
            v.push(fish(
                700.0 + 13.0 * tf,
                250.0 + 60.0 * (t % 2) as f32,
                90.0,
                1,
                2500.0,
                9,
            ));
        }
        if t != 3 {
            v.push(fish(
                1980.0 - 330.0 * tf,
                1000.0 + 20.0 * tf,
                400.0,
                9,
                1800.0,
                1,
            ));
        }
        frames.push(v);
    }
    for assoc in [Assoc::Viterbi, Assoc::Mc, Assoc::Nn] {
        let (log, _) = run(&frames, assoc);
        let fish_closed: Vec<_> = log.closed.iter().filter(|c| c.2 > 0).collect();
        assert_eq!(fish_closed.len(), 1, "{assoc:?}: {:?}", log.closed);
        let path = &fish_closed[0].3;
        assert_eq!(path.len(), 6, "{assoc:?}");
        assert_eq!(fish_closed[0].2, 5);
        assert_eq!(path[3].obs, None);
        // The predicted position is the motion projection (≈ 990 px).
        assert!((path[3].x as i32 - 990).abs() < 40, "{:?}", path[3]);
        assert!(path.iter().enumerate().all(|(i, s)| s.frame == i as u32));
    }
}

/// An unpaired view (no right object, no depth) does not erase the
/// target's depth: the next frame's depth cue still compares against the
/// last known depth, so a fish at another range that sits right on the
/// prediction does not take the track.
#[test]
fn unpaired_view_carries_depth() {
    let (za, zb) = (1400.0, 2500.0);
    let mut frames = Vec::new();
    for t in 0..4 {
        let tf = t as f32;
        let mut a = fish(1900.0 - 330.0 * tf, 1000.0, 400.0, 9, za, 0);
        if t == 2 {
            a.right = None;
            a.depth_mm = None;
        }
        let mut v = std::vec![a];
        if t == 3 {
            // A's true view 120 px off the prediction; B (same raw size and
            // grey levels) right on it.
            v[0].left.cy += 120.0;
            if let Some(r) = v[0].right.as_mut() {
                r.cy += 120.0;
            }
            v.push(fish(1900.0 - 330.0 * tf, 1000.0, 400.0, 9, zb, 1));
        }
        frames.push(v);
    }
    let (log, _) = run(&frames, Assoc::Viterbi);
    let id = log.ids_of(0, 0);
    assert_eq!(id.len(), 1);
    for f in 1..4 {
        assert_eq!(log.ids_of(f, 0), id, "frame {f}: {:?}", log.frames);
    }
    assert!(!log.ids_of(3, 1).contains(&id[0]));
}

#[test]
fn long_track_commits_by_depth_and_truncates_its_path() {
    // 40 frames of a slow fish: the trellis (D = 16) commits as it goes.
    let frames: Vec<Vec<Observation>> = (0..40)
        .map(|t| std::vec![fish(1990.0 - 45.0 * t as f32, 1000.0, 200.0, 8, 2000.0, 0)])
        .collect();
    let (log, st) = run(&frames, Assoc::Viterbi);
    assert_eq!(log.closed.len(), 1);
    let ids: Vec<u32> = (0..40).flat_map(|f| log.ids_of(f, 0)).collect();
    assert_eq!(ids.len(), 40);
    assert!(ids.iter().all(|&i| i == ids[0]));
    assert_eq!(log.closed[0].3.len(), 32);
    assert_eq!(st.path_steps_dropped, 8);
    // Frame events come out in frame order and at most D frames late.
    let fr: Vec<u32> = log.frames.iter().map(|f| f.1).collect();
    assert!(fr.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn config_and_frame_order_errors() {
    let mut c = TrackConfig::for_frame(W, W);
    c.max_lost = 15;
    assert!(matches!(DefaultTracker::new(c), Err(TrackError::Config(_))));
    for v in [0.0, -1.0, f32::NAN] {
        let mut c = TrackConfig::for_frame(W, W);
        c.area_robust = v;
        assert!(matches!(DefaultTracker::new(c), Err(TrackError::Config(_))));
        let mut c = TrackConfig::for_frame(W, W);
        c.hist_robust = v;
        assert!(matches!(DefaultTracker::new(c), Err(TrackError::Config(_))));
    }
    let mut c = TrackConfig::for_frame(W, W);
    c.area_robust = 9.0;
    c.hist_robust = f32::INFINITY;
    assert!(DefaultTracker::new(c).is_ok());
    assert!(matches!(
        Tracker::<4, 1, 4, 4, 4>::new(TrackConfig::for_frame(W, W)),
        Err(TrackError::Config(_))
    ));
    let mut tr: DefaultTracker = Tracker::new(TrackConfig::for_frame(W, W)).unwrap();
    let p = Params::default();
    let mut sink = |_: &TrackEvent<'_>| {};
    tr.step(5, &[], &p, &mut sink).unwrap();
    assert_eq!(
        tr.step(5, &[], &p, &mut sink),
        Err(TrackError::FrameOrder { last: 5, got: 5 })
    );
    let bad = Params { alpha: 2.0, ..p };
    assert!(matches!(
        tr.step(6, &[], &bad, &mut sink),
        Err(TrackError::Params(_))
    ));
}

#[test]
fn tracker_state_fits_the_budget() {
    let sz = core::mem::size_of::<DefaultTracker>();
    std::println!("size_of::<DefaultTracker>() = {sz} bytes");
    assert!(sz <= 128 * 1024, "{sz}");
}

fn arb_obs() -> impl Strategy<Value = Observation> {
    let coord = prop_oneof![
        8 => -100.0f32..2200.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => -1e30f32..1e30,
    ];
    (
        coord.clone(),
        coord,
        0u32..3000,
        0u32..3000,
        0u32..200_000,
        proptest::array::uniform16(0u32..1000),
        proptest::option::of(-10.0f32..5000.0),
        any::<bool>(),
        -300.0f32..300.0,
        (
            prop_oneof![
                8 => -4.0f32..4.0,
                1 => Just(f32::NAN),
                1 => Just(f32::INFINITY),
                1 => Just(-1e38f32),
                1 => -100.0f32..100.0,
            ],
            prop_oneof![4 => 0.0f32..8.0, 1 => Just(f32::NAN), 1 => Just(f32::INFINITY)],
        ),
    )
        .prop_map(
            |(x, y, bx, by, area, hist, depth, stereo, dx, (angle, elongation))| {
                let left = CameraView {
                    cx: x,
                    cy: y,
                    bbox: Roi::new(bx, by, 300, 80),
                    area,
                    hist,
                    angle,
                    elongation,
                };
                let mut right = left;
                right.cx = x + dx;
                Observation {
                    left,
                    right: stereo.then_some(right),
                    depth_mm: depth,
                    pair: 7,
                }
            },
        )
}

proptest! {
    // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
    #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 64 }))]

    /// Random observations, tiny capacities (every overflow path), all three
    /// associations: no panic, events consistent.
    #[test]
    fn random_observations_never_panic(
        frames in proptest::collection::vec(proptest::collection::vec(arb_obs(), 0..12), 1..25),
        assoc in prop_oneof![Just(Assoc::Viterbi), Just(Assoc::Mc), Just(Assoc::Nn)],
        cues in 0u8..32,
    ) {
        let mut cfg = TrackConfig::for_frame(W, W);
        cfg.cues = Cues(cues);
        cfg.max_lost = 1;
        let mut tr: Tracker<3, 3, 2, 4, 6> = Tracker::new(cfg).unwrap();
        let p = Params { tracker: assoc, ..Params::default() };
        let mut frames_seen: Vec<(u32, u32)> = Vec::new();
        let mut closed = 0u32;
        let mut bad = false;
        {
            let mut sink = |e: &TrackEvent<'_>| match e {
                TrackEvent::Frame { track, step } => {
                    if let Some(o) = step.obs {
                        if o as usize >= 12 { bad = true; }
                    }
                    frames_seen.push((*track, step.frame));
                }
                TrackEvent::Closed { hits, path, .. } => {
                    closed += 1;
                    if *hits as usize > path.len().max(*hits as usize) { bad = true; }
                }
            };
            for (f, obs) in frames.iter().enumerate() {
                tr.step(f as u32 * 2, obs, &p, &mut sink).unwrap();
            }
            tr.finish(&mut sink);
        }
        prop_assert!(!bad);
        prop_assert_eq!(tr.live_targets(), 0);
        prop_assert_eq!(tr.stats().tracks_closed, closed);
        prop_assert_eq!(tr.stats().targets_born, closed);
        // Per track, committed frames strictly increase.
        for id in 1..=closed {
            let fr: Vec<u32> = frames_seen.iter().filter(|x| x.0 == id).map(|x| x.1).collect();
            prop_assert!(fr.windows(2).all(|w| w[0] < w[1]));
        }
    }
}

/// [`run`] with a tracking configuration of the caller's.
fn run_cfg(frames: &[Vec<Observation>], cfg: TrackConfig) -> Log {
    let mut tr: DefaultTracker = Tracker::new(cfg).unwrap();
    let p = Params::for_frame(W);
    let mut log = Log::default();
    {
        let mut sink = log.sink();
        for (f, obs) in frames.iter().enumerate() {
            tr.step(f as u32, obs, &p, &mut sink).unwrap();
        }
        tr.finish(&mut sink);
    }
    log
}

#[test]
fn the_raw_views_rectangle_is_the_border() {
    // The raw left view starts at x = 550 of the rectified frame (a free
    // scaling alpha > 0 puts fill to its left). A fish crossing towards -x
    // at 200 px/frame is last seen at x = 800; a small object appears at
    // x = 600, within M of the view's edge but far from the frame's.
    let mut frames = Vec::new();
    for t in 0..7 {
        let mut v = Vec::new();
        if t < 4 {
            v.push(fish(1400.0 - 200.0 * t as f32, 1000.0, 400.0, 9, 1800.0, 0));
        }
        if t == 2 {
            v.push(fish(600.0, 400.0, 90.0, 2, 2500.0, 1));
        }
        frames.push(v);
    }
    let full = TrackConfig::for_frame(W, W);
    let view = TrackConfig {
        view: [Roi::new(550, 0, W - 550, W), Roi::new(0, 0, W - 550, W)],
        ..full
    };
    let (a, b) = (run_cfg(&frames, full), run_cfg(&frames, view));
    let reason = |l: &Log| l.closed.iter().find(|c| c.2 == 4).map(|c| c.1);
    // whole frame: the predictions (x = 600, 400) stay inside the margin,
    // the fish is lost; raw view: at x = 600 it left through the view's
    // border (x < 550 + M)
    assert_eq!(reason(&a), Some(CloseReason::Lost), "{:?}", a.closed);
    assert_eq!(reason(&b), Some(CloseReason::Exit), "{:?}", b.closed);
    // the small object is born only where it touches the view's margin
    assert!(a.ids_of(2, 1).is_empty(), "{:?}", a.frames);
    assert_eq!(b.ids_of(2, 1).len(), 1, "{:?}", b.frames);
    // the view is clipped to the frame; an empty one is refused
    assert_eq!(
        TrackConfig {
            view: [Roi::new(0, 0, 9999, 9999); 2],
            ..full
        }
        .views(),
        [Roi::full(W, W); 2]
    );
    let bad = TrackConfig {
        view: [Roi::new(W, 0, 10, 10), Roi::full(W, W)],
        ..full
    };
    assert!(bad.validate(16).is_err());
}

#[test]
fn near_edge_is_the_border_test_of_a_box() {
    let v = Roi::new(100, 50, 1000, 800);
    assert!(near_edge(&Roi::new(102, 400, 50, 50), &v, 2));
    assert!(!near_edge(&Roi::new(103, 400, 50, 50), &v, 2));
    assert!(near_edge(&Roi::new(500, 400, 598, 50), &v, 2)); // right = 1098
    assert!(!near_edge(&Roi::new(500, 400, 597, 50), &v, 2));
    assert!(near_edge(&Roi::new(0, 0, 5, 5), &v, 0)); // outside the view
    assert!(near_edge(&Roi::new(500, 52, 10, 10), &v, 2));
    assert!(near_edge(&Roi::new(500, 400, 10, 448), &v, 2)); // bottom = 848
}

/// A left-only observation with an explicit box (a view the border may cut).
fn boxed(bbox: Roi, area: u32, pair: u16) -> Observation {
    let mut o = fish(0.0, 0.0, 100.0, 8, 2000.0, pair);
    o.left.bbox = bbox;
    o.left.cx = bbox.x as f32 + bbox.w as f32 / 2.0;
    o.left.cy = bbox.y as f32 + bbox.h as f32 / 2.0;
    o.left.area = area;
    o.right = None;
    o.depth_mm = None;
    o
}

#[test]
fn a_fish_entering_cut_by_the_border_is_followed_by_its_head() {
    // A 400-px fish swims in from the right border at 500 px/frame. In
    // frame 0 only its front 150 px are in view, so its centroid moves
    // 375 px to frame 1, not 500; a school mate appears in frame 2 where
    // that centroid step would put it (x = W − 825), while the fish itself
    // is at W − 950. Measured on the uncut (left) box sides, the first step
    // is the fish's 500 px and its track takes the fish; with centroids
    // (the paper) it takes the school mate.
    let (y, h) = (900u32, 100u32);
    let body = 400 * h * 7 / 10;
    let at = |x0: u32, w: u32, area: u32, pair: u16| boxed(Roi::new(x0, y, w, h), area, pair);
    let frames = std::vec![
        std::vec![at(W - 150, 150, body * 150 / 400, 0)],
        std::vec![at(W - 650, 400, body, 0)],
        std::vec![at(W - 1150, 400, body, 0), at(W - 1025, 400, body, 1)],
        std::vec![at(W - 1650, 400, body, 0)],
    ];
    let cfg = TrackConfig::for_frame(W, W);
    let aware = run_cfg(&frames, cfg);
    let paper = run_cfg(
        &frames,
        TrackConfig {
            cut_aware_motion: false,
            ..cfg
        },
    );
    let id = |l: &Log, f: u32, o: u16| l.ids_of(f, o).first().copied();
    let first = id(&aware, 0, 0);
    assert!(first.is_some(), "{:?}", aware.frames);
    for f in 1..4 {
        assert_eq!(id(&aware, f, 0), first, "frame {f}: {:?}", aware.frames);
    }
    assert_ne!(id(&aware, 2, 1), first, "{:?}", aware.frames);
    // the paper's centroid step hands frame 2's school mate to the fish
    assert_eq!(id(&paper, 2, 1), id(&paper, 0, 0), "{:?}", paper.frames);
}

#[test]
fn motion_delta_uses_the_sides_the_border_does_not_cut() {
    let view = Roi::full(W, W);
    let feat = |b: Roi| cost::ViewFeat {
        pos: [b.x as f32 + b.w as f32 / 2.0, b.y as f32 + b.h as f32 / 2.0],
        area: (b.w * b.h) as f32,
        cut: near_edge(&b, &view, 2),
        bbox: [b.x as f32, b.y as f32, b.right() as f32, b.bottom() as f32],
        cut_sides: cut_sides(&b, &view, 2),
        cdf: None,
        axis: cost::NO_AXIS,
    };
    // cut at the right border, then whole: the left sides' step in x, the
    // centroids' in y (no side cut along y)
    let a = feat(Roi::new(W - 150, 500, 150, 100));
    let b = feat(Roi::new(W - 650, 560, 400, 120));
    assert_eq!(a.cut_sides, cost::CUT_X_MAX);
    assert_eq!(cost::motion_delta(&a, &b, true), [-500.0, 70.0]);
    assert_eq!(cost::motion_delta(&a, &b, false), [-375.0, 70.0]);
    // leaving at the left border: the right sides
    let c = feat(Roi::new(0, 560, 120, 120));
    assert_eq!(c.cut_sides, cost::CUT_X_MIN);
    assert_eq!(
        cost::motion_delta(&b, &c, true),
        [120.0 - (W as f32 - 250.0), 0.0]
    );
    // cut on both sides of an axis (wider than the view): centroids
    let d = feat(Roi::new(0, 0, W, 50));
    assert_eq!(
        d.cut_sides,
        cost::CUT_X_MIN | cost::CUT_X_MAX | cost::CUT_Y_MIN
    );
    assert_eq!(cost::motion_delta(&d, &b, true)[0], b.pos[0] - d.pos[0]);
    // nothing cut: centroids
    let e = feat(Roi::new(700, 700, 300, 80));
    assert_eq!(
        cost::motion_delta(&b, &e, true),
        cost::motion_delta(&b, &e, false)
    );
    // the 2-px tolerance at both ends of an axis
    assert_eq!(feat(Roi::new(2, 500, 50, 20)).cut_sides, cost::CUT_X_MIN);
    assert_eq!(feat(Roi::new(3, 500, 50, 20)).cut_sides, 0);
    assert_eq!(
        feat(Roi::new(W - 52, 500, 50, 20)).cut_sides,
        cost::CUT_X_MAX
    );
    assert_eq!(feat(Roi::new(W - 53, 500, 50, 20)).cut_sides, 0);
    assert_eq!(
        feat(Roi::new(500, W - 22, 50, 20)).cut_sides,
        cost::CUT_Y_MAX
    );
    // the vicinity and direction of an edge use that displacement: a
    // target moving by (−500, 70) predicts the cut view's whole successor
    // exactly, where its centroid step would be 125 px short
    let edge = |aware| {
        let v = [-500.0, 70.0];
        cost::edge_features(
            &a,
            v,
            &b,
            (None, None),
            cost::DirectionRef::velocity([-1.0, 0.0]),
            2000.0,
            aware,
        )
    };
    let (f, g) = (edge(true), edge(false));
    assert_eq!(f.d2, 0.0);
    assert_eq!(g.d2, 125.0 * 125.0);
    let th = libm::atan2f(70.0, 500.0);
    assert!((f.m2 - th * th).abs() < 1e-6, "{}", f.m2);
}

#[test]
fn a_box_that_misses_its_centroid_counts_as_uncut() {
    // Observations whose boxes were left empty move by their centroids,
    // not by a side of a meaningless box (which would make every
    // displacement 0 and leave the choice to appearance): the fish at the
    // newborn's projection wins over a decoy listed first (with every
    // displacement 0 the two would tie, and the first would win).
    let v = default_v_init(&Params::for_frame(W), W);
    let at = |x: f32, y: f32, area: u32, pair: u16| {
        let mut o = boxed(Roi::new(0, 0, 0, 0), area, pair);
        o.left.cx = x;
        o.left.cy = y;
        o.left.bbox = Roi::default();
        o
    };
    let frames = std::vec![
        std::vec![at(1200.0, 700.0, 6000, 0)],
        std::vec![
            at(1300.0 + v[0], 1300.0, 6000, 0),
            at(1200.0 + v[0], 700.0 + v[1], 7500, 1),
        ],
    ];
    let log = run_cfg(&frames, TrackConfig::for_frame(W, W));
    let id = log.ids_of(0, 0);
    assert_eq!(id.len(), 1, "{:?}", log.frames);
    assert_eq!(log.ids_of(1, 1), id, "{:?}", log.frames);
}

#[test]
fn a_newborn_is_projected_across_the_crossing_width_not_the_frame() {
    // On a frame twice as wide as the view the fish cross (a canvas that
    // keeps every raw pixel), a newborn's default velocity is the view's
    // width over the 4.3-frame lifespan. A fish at that projection and a
    // decoy at the frame width's projection (listed first): with
    // `crossing_width` the view's width the fish wins; left at the frame
    // width, the decoy does.
    let p = Params::for_frame(W);
    let (v, v2) = (default_v_init(&p, W), default_v_init(&p, 2 * W));
    let frames = std::vec![
        std::vec![fish(1900.0, 1000.0, 200.0, 9, 1800.0, 0)],
        std::vec![
            fish(1900.0 + v2[0], 1000.0 + v2[1], 200.0, 9, 1800.0, 0),
            fish(1900.0 + v[0], 1000.0 + v[1], 200.0, 9, 1800.0, 1),
        ],
    ];
    let tight = Sigmas {
        v0: 30.0 * 30.0,
        ..Sigmas::for_frame(W)
    };
    let cfg = |crossing| TrackConfig {
        sigma_defaults: tight,
        crossing_width: crossing,
        ..TrackConfig::for_frame(2 * W, W)
    };
    for (crossing, want) in [(W, 1u16), (2 * W, 0)] {
        let log = run_cfg(&frames, cfg(crossing));
        let id = log.ids_of(0, 0);
        assert_eq!(id.len(), 1, "{:?}", log.frames);
        assert_eq!(
            log.ids_of(1, want),
            id,
            "crossing {crossing}: {:?}",
            log.frames
        );
    }
    let bad = TrackConfig {
        crossing_width: 0,
        ..TrackConfig::for_frame(W, W)
    };
    assert!(bad.validate(16).is_err());
}

#[test]
fn a_newborn_swimming_against_the_school_keeps_its_id() {
    // At 2.5 fps (crossing width twice the view's) a newborn is projected
    // by v_init ≈ (−952, 0). A fish in view when the haul starts swims +x
    // at 900 px/frame: the forward projection misses it by ~1 850 px (z_v
    // ≈ 28 per camera, over the gate), the reversed one by ~50 px. With the
    // reversed projection it keeps one id; without it (cost ∞) it is born
    // again.
    let p = Params::for_frame(W);
    let cfg = |reverse: f32, crossing: u32| TrackConfig {
        crossing_width: crossing,
        newborn_reverse_cost: reverse,
        ..TrackConfig::for_frame(W, W)
    };
    let v = default_v_init(&p, 2 * W);
    assert!(v[0] < -900.0 && v[1].abs() < 1.0, "{v:?}");
    let frames = std::vec![
        std::vec![fish(300.0, 1000.0, 300.0, 9, 1800.0, 0)],
        std::vec![fish(1200.0, 1010.0, 300.0, 9, 1800.0, 0)],
    ];
    for (reverse, same) in [(NEWBORN_REVERSE_COST, true), (f32::INFINITY, false)] {
        let log = run_cfg(&frames, cfg(reverse, 2 * W));
        let (a, b) = (log.ids_of(0, 0), log.ids_of(1, 0));
        assert_eq!((a.len(), b.len()), (1, 1), "{:?}", log.frames);
        assert_eq!(a == b, same, "reverse cost {reverse}: {:?}", log.frames);
    }
    // NN, the paper's baseline, keeps its one prediction x + v_init.
    let (log, _) = run_assoc_cfg(&frames, Assoc::Nn, cfg(NEWBORN_REVERSE_COST, 2 * W));
    let (a, b) = (log.ids_of(0, 0), log.ids_of(1, 0));
    assert!(a.len() == 1 && b.len() == 1 && a != b, "{:?}", log.frames);
    // The reversed projection pays its cost: between a look-alike where
    // v_init (5 fps, ≈ (−476, 0)) puts it and one as far the other way
    // (listed first), the forward one wins.
    let v = default_v_init(&p, W);
    let frames = std::vec![
        std::vec![fish(1000.0, 1000.0, 300.0, 9, 1800.0, 0)],
        std::vec![
            fish(1000.0 - v[0], 1000.0, 300.0, 9, 1800.0, 0),
            fish(1000.0 + v[0], 1000.0, 300.0, 9, 1800.0, 1),
        ],
    ];
    let log = run_cfg(&frames, cfg(NEWBORN_REVERSE_COST, W));
    let id = log.ids_of(0, 0);
    assert_eq!(id.len(), 1, "{:?}", log.frames);
    assert_eq!(log.ids_of(1, 1), id, "{:?}", log.frames);
    assert!(cfg(-1.0, W).validate(16).is_err());
    assert!(cfg(f32::NAN, W).validate(16).is_err());
    assert!(cfg(0.0, W).validate(16).is_ok());
}

#[test]
fn a_fish_leaving_cut_by_the_border_is_not_a_new_fish() {
    // A 400-px fish swims out through the left border at 500 px/frame: its
    // prediction for frame 3 (x = 60) is inside the exit margin, so its
    // track closes there (Exit). In frame 3 only its tail end is in view,
    // cut by the border and of other grey levels (the head has left), so
    // the track does not take it. That cut view at the exiting track's
    // prediction is the same fish leaving — no new target; a short fish
    // wholly in view at the same place is a new one.
    for cut in [true, false] {
        let mut frames = Vec::new();
        for t in 0..3 {
            frames.push(std::vec![fish(
                1560.0 - 500.0 * t as f32,
                1000.0,
                400.0,
                9,
                1800.0,
                0
            )]);
        }
        let len = if cut { 400.0 } else { 100.0 };
        frames.push(std::vec![fish(60.0, 1000.0, len, 1, 1800.0, 0)]);
        frames.push(Vec::new());
        let (log, _) = run(&frames, Assoc::Viterbi);
        let fish_id = log.ids_of(0, 0);
        assert_eq!(fish_id.len(), 1, "{:?}", log.frames);
        assert_eq!(log.ids_of(2, 0), fish_id, "{:?}", log.frames);
        let exit = log.closed.iter().find(|c| c.0 == fish_id[0]).map(|c| c.1);
        assert_eq!(exit, Some(CloseReason::Exit), "{:?}", log.closed);
        let later = log.ids_of(3, 0);
        assert!(!later.contains(&fish_id[0]), "{:?}", log.frames);
        if cut {
            assert!(
                later.is_empty(),
                "the leaving tail was born: {:?}",
                log.frames
            );
            assert_eq!(log.closed.len(), 1, "{:?}", log.closed);
        } else {
            assert_eq!(later.len(), 1, "{:?}", log.frames);
        }
    }
}

#[test]
fn a_newborn_lost_on_its_first_step_does_not_block_another_fish() {
    // Frame 1: fish A enters at the right border and is born. Frame 2: A is
    // not seen; fish B (other grey levels, so A's edge to it is gated out)
    // swims 350 px beside A's first-step guess x = 1900 − 476 (v_init).
    // Within `lost_gate` of an established target's prediction B would be
    // that target's partly hidden view, but A has no velocity: B is born in
    // frame 2 and keeps its id in frame 3. With `newborn_lost_gate` =
    // `lost_gate` (the former rule) B is blocked in frame 2.
    let frames = std::vec![
        Vec::new(),
        std::vec![fish(1900.0, 1000.0, 200.0, 9, 1800.0, 0)],
        std::vec![fish(1774.0, 1000.0, 400.0, 1, 1800.0, 0)],
        std::vec![fish(1324.0, 1000.0, 400.0, 1, 1800.0, 0)],
        Vec::new(),
    ];
    for (newborn_gate, blocked) in [
        (TrackConfig::for_frame(W, W).newborn_lost_gate, false),
        (6.0, true),
    ] {
        for assoc in [Assoc::Viterbi, Assoc::Mc] {
            let cfg = TrackConfig {
                newborn_lost_gate: newborn_gate,
                ..TrackConfig::for_frame(W, W)
            };
            let (log, _) = run_assoc_cfg(&frames, assoc, cfg);
            let a = log.ids_of(1, 0);
            assert_eq!(a.len(), 1, "{assoc:?}: {:?}", log.frames);
            let (b2, b3) = (log.ids_of(2, 0), log.ids_of(3, 0));
            assert!(
                !b3.is_empty() && !b3.contains(&a[0]),
                "{assoc:?}: {:?}",
                log.frames
            );
            if blocked {
                assert!(b2.is_empty(), "{assoc:?}: {:?}", log.frames);
            } else {
                assert_eq!(b2, b3, "{assoc:?}: {:?}", log.frames);
            }
        }
    }
}

/// `o` with the body axis at `angle` (radians) and elongation `e` in both
/// views, its boxes turned to match a vertical fish when `angle` is near
/// ±π/2.
fn with_axis(mut o: Observation, angle: f32, e: f32) -> Observation {
    for v in core::iter::once(&mut o.left).chain(o.right.as_mut()) {
        v.angle = angle;
        v.elongation = e;
        if libm::fabsf(libm::cosf(angle)) < 0.5 {
            let (w, h) = (v.bbox.w, v.bbox.h);
            let (cx, cy) = (v.bbox.x + w / 2, v.bbox.y + h / 2);
            v.bbox = Roi::new(cx - h / 2, cy - w / 2, h, w);
        }
    }
    o
}

#[test]
fn a_newborn_moves_along_its_body_axis() {
    // A fish swimming down (body vertical), first seen mid-frame, and at
    // frame 1 two candidates: itself 400 px further along its body, and a
    // new fish close to where the fleet's default velocity (−476, 0)
    // projects it but across its body (76° off its axis). Frame 2 carries
    // both on. With the body axis as the first transition's direction
    // reference the fish keeps its own continuation; without it
    // (`axis_direction` false: vicinity alone), or with views too round
    // for an axis (elongation 1.5 < 2), it takes the other fish.
    let v = std::f32::consts::FRAC_PI_2;
    let h = 0.0;
    let scene = |e: f32| {
        std::vec![
            std::vec![with_axis(fish(1000.0, 1000.0, 300.0, 6, 2000.0, 0), v, e)],
            std::vec![
                with_axis(fish(1000.0, 1400.0, 300.0, 6, 2000.0, 0), v, e),
                with_axis(fish(600.0, 1100.0, 300.0, 6, 2000.0, 1), h, e),
            ],
            std::vec![
                with_axis(fish(1000.0, 1800.0, 300.0, 6, 2000.0, 0), v, e),
                with_axis(fish(200.0, 1200.0, 300.0, 6, 2000.0, 1), h, e),
            ],
        ]
    };
    // (axis on, elongation, the observation the fish takes at frames 1, 2)
    for (axis, e, want) in [(true, 4.0, 0u16), (false, 4.0, 1), (true, 1.5, 1)] {
        let cfg = TrackConfig {
            axis_direction: axis,
            ..TrackConfig::for_frame(W, W)
        };
        let log = run_cfg(&scene(e), cfg);
        let id = log.ids_of(0, 0);
        assert_eq!(id.len(), 1, "{:?}", log.frames);
        let why = std::format!("axis {axis}, elongation {e}: {:?}", log.frames);
        assert_eq!(log.ids_of(1, want), id, "{why}");
        assert_eq!(log.ids_of(2, want), id, "{why}");
    }
}

#[test]
fn a_fish_first_seen_small_mid_view_is_counted_once_it_is_confirmed() {
    // The segmentation missed this small fish while it entered: it is
    // first seen mid-view, smaller than `birth_area_factor` · θ_A^L, where
    // the paper's birth rule takes it for a false alarm. Frame 0 holds
    // nothing (in a haul's first frame every observation is born).
    let p = Params::for_frame(W);
    let small = |x: f32, y: f32| fish(x, y, 140.0, 6, 2000.0, 3);
    assert!(
        (small(0.0, 0.0).left.area as f32) < 2.0 * p.area_min as f32,
        "the test fish must be small"
    );
    let cfg = |confirm: u8, min_step: f32| TrackConfig {
        confirm_births: confirm,
        confirm_min_step: min_step,
        ..TrackConfig::for_frame(W, W)
    };
    let swims = |n: usize| -> Vec<Vec<Observation>> {
        let mut frames = std::vec![Vec::new()];
        for t in 0..n {
            frames.push(std::vec![small(
                1500.0 - 400.0 * t as f32,
                1000.0 + 10.0 * t as f32
            )]);
        }
        frames.push(Vec::new());
        frames.push(Vec::new());
        frames
    };
    let ids = |log: &Log, n: usize| -> Vec<Vec<u32>> {
        (1..=n as u32).map(|f| log.ids_of(f, 0)).collect()
    };
    // Seen in 3 frames: one track holding all three (default), none by the
    // paper's rule.
    let frames = swims(3);
    let def = TrackConfig::for_frame(W, W);
    for assoc in [Assoc::Viterbi, Assoc::Mc, Assoc::Nn] {
        let (log, _) = run_assoc_cfg(&frames, assoc, def);
        let got = ids(&log, 3);
        assert!(
            got.iter().all(|v| v.len() == 1 && *v == got[0]),
            "{assoc:?}: {:?}",
            log.frames
        );
        let (log, _) = run_assoc_cfg(&frames, assoc, cfg(0, def.confirm_min_step));
        assert!(log.frames.is_empty(), "{assoc:?}: {:?}", log.frames);
    }
    // Seen in 2 frames: not confirmed at 3 observations (closed as
    // unconfirmed, nothing reported), confirmed at 2.
    let frames = swims(2);
    let log = run_cfg(&frames, def);
    assert!(log.frames.is_empty(), "{:?}", log.frames);
    assert!(
        log.closed.iter().all(|c| c.1 == CloseReason::Unconfirmed),
        "{:?}",
        log.closed
    );
    let log = run_cfg(&frames, cfg(2, def.confirm_min_step));
    assert_eq!(ids(&log, 2).concat().len(), 2, "{:?}", log.frames);
    // A speck that stays put (a spot on the window, slow debris) for 5
    // frames is no fish: refused by the motion test, kept without it.
    let mut frames = std::vec![Vec::new()];
    for t in 0..5 {
        frames.push(std::vec![small(
            1000.0 + 9.0 * t as f32,
            1000.0 + 3.0 * t as f32
        )]);
    }
    frames.push(Vec::new());
    frames.push(Vec::new());
    let log = run_cfg(&frames, def);
    assert!(log.frames.is_empty(), "{:?}", log.frames);
    let log = run_cfg(&frames, cfg(3, 0.0));
    assert_eq!(ids(&log, 5).concat().len(), 5, "{:?}", log.closed);
    // Longer than the trellis is deep (its oldest stages are committed
    // while it lives): still nothing reported, and the track closes as
    // unconfirmed.
    let mut frames = std::vec![Vec::new()];
    for t in 0..40 {
        frames.push(std::vec![small(1000.0 + 2.0 * t as f32, 1000.0)]);
    }
    frames.push(Vec::new());
    frames.push(Vec::new());
    let log = run_cfg(&frames, def);
    assert!(log.frames.is_empty(), "{:?}", log.frames);
    assert!(!log.closed.is_empty());
    assert!(
        log.closed
            .iter()
            .all(|c| c.1 == CloseReason::Unconfirmed && c.3.is_empty()),
        "{:?}",
        log.closed
    );
    // A fish confirmed before its trellis fills reports every frame.
    let log = run_cfg(&frames, cfg(3, 0.0));
    assert_eq!(ids(&log, 40).concat().len(), 40, "{:?}", log.closed);
    assert!(cfg(3, -1.0).validate(16).is_err());
    assert!(cfg(3, f32::NAN).validate(16).is_err());
}
