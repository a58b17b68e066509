//! Property tests: stereo pairing, refinement, the tail snake and the length
//! stage never panic, whatever boxes, masks, oriented boxes, images and
//! geometry they are given (out-of-image boxes and runs, NaN angles,
//! zero-size objects, indices out of range).
#![allow(clippy::unwrap_used)]

use fishtrack_core::length::{measure_length, LengthAccumulator, LengthConfig};
use fishtrack_core::object::{Object, Objects, OrientedBox, Run, RunSpan};
use fishtrack_core::snake::{tail_snake, SnakeParams};
use fishtrack_core::stereo::{pair_objects, PairingLimits, StereoPair};
use fishtrack_core::{ImageView, Params, Roi, StereoGeometry};
use proptest::prelude::*;

const N: usize = 4;
const R: usize = 64;

/// Upright box, oriented box (cx, cy, half_w, half_h, angle), runs (y, x0, x1).
type ObjSpec = (Roi, (f32, f32, f32, f32, f32), Vec<(u16, u16, u16)>);

fn obj_strategy() -> impl Strategy<Value = ObjSpec> {
    (
        (0u32..90, 0u32..70, 0u32..90, 0u32..70).prop_map(|(x, y, w, h)| Roi::new(x, y, w, h)),
        (
            -10.0f32..100.0,
            -10.0f32..80.0,
            0.0f32..60.0,
            0.0f32..40.0,
            prop_oneof![Just(f32::NAN), -4.0f32..4.0],
        ),
        proptest::collection::vec((0u16..80, 0u16..100, 0u16..100), 0..12),
    )
}

fn build(objs: &[ObjSpec]) -> Objects<N, R> {
    let mut o = Objects::<N, R>::new();
    for (bbox, (cx, cy, hw, hh, a), runs) in objs.iter().take(N) {
        let start = o.runs.len() as u32;
        for &(y, x0, x1) in runs {
            let _ = o.runs.push(Run { y, x0, x1 });
        }
        let area = runs.iter().map(|r| r.2.saturating_sub(r.1) as u32).sum();
        let _ = o.items.push(Object {
            bbox: *bbox,
            obb: OrientedBox {
                cx: *cx,
                cy: *cy,
                half_w: *hw,
                half_h: *hh,
                angle: *a,
            },
            area,
            mean: 100.0,
            variance: 50.0,
            hist: [0; 16],
            runs: RunSpan {
                start,
                len: o.runs.len() as u32 - start,
            },
            level: 0,
        });
    }
    o
}

proptest! {
    // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
    #![proptest_config(ProptestConfig { cases: if cfg!(miri) { 4 } else { 96 }, ..ProptestConfig::default() })]
    #[test]
    fn stereo_and_length_never_panic(
        seed in any::<u64>(),
        lobjs in proptest::collection::vec(obj_strategy(), 0..5),
        robjs in proptest::collection::vec(obj_strategy(), 0..5),
        f in prop_oneof![Just(0.0f32), 1.0f32..2000.0],
        base in prop_oneof![Just(-5.0f32), 1.0f32..500.0],
        d_o in -300.0f32..300.0,
        li in 0u16..6, ri in 0u16..6,
        every in any::<bool>(),
    ) {
        let (w, h) = (80usize, 60usize);
        let mut s = seed;
        let mut img = |_: u8| -> Vec<u8> {
            (0..w * h).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1); (s >> 56) as u8 }).collect()
        };
        let (l, r) = (img(0), img(1));
        let lv = ImageView::packed(&l, w, h).unwrap();
        let rv = ImageView::packed(&r, w, h).unwrap();
        let left = build(&lobjs);
        let right = build(&robjs);
        let geom = StereoGeometry { f, cx: 40.0, cy: 30.0, cx_right: 40.0, baseline_mm: base };
        let limits = PairingLimits { min_range_mm: 10.0, ..PairingLimits::default() };
        let pairs = pair_objects(&lv, &rv, &left, &right, &geom, &limits).unwrap();
        for p in pairs.pairs.iter() {
            prop_assert!((p.left as usize) < left.items.len() && (p.right as usize) < right.items.len());
        }
        let params = Params { refine_range: 4, ..Params::default() };
        let cfg = LengthConfig { snake_every_end: every, snake: SnakeParams { iterations: 20, ..SnakeParams::default() }, ..LengthConfig::default() };
        let pair = StereoPair { left: li, right: ri, d_o, mu_sad: 3.0, ..StereoPair::default() };
        let _ = measure_length::<N, R, 32>(&lv, &rv, &left, &right, &pair, &geom, &params, &cfg);
        for p in pairs.pairs.iter() {
            let _ = measure_length::<N, R, 32>(&lv, &rv, &left, &right, p, &geom, &params, &cfg);
        }
        let _ = tail_snake(&lv, (d_o, d_o), (f32::NAN, 0.0), d_o, 100.0, (30.0, 2.0), d_o, &cfg.snake);
        let mut acc = LengthAccumulator::<3>::new();
        for k in 0..5 { acc.push(Some(d_o + k as f32), k % 2 == 0); }
        let _ = acc.estimate();
    }
}
