//! Slanted disparity fit over the whole object (Section IV.D.2, beyond the
//! paper's 8 × 8 blocks).
//!
//! The length needs the disparity at the fish's two ends. A straight fish's
//! disparity is affine along its image axis, `d(t) = d₀ + (d₁ − d₀)·(t −
//! t₀)/(t₁ − t₀)` between the ends `t₀`, `t₁`, and the line through the
//! refined 8 × 8 blocks ([`crate::refine`], [`crate::length`]'s resistant
//! line) estimates it from block minima — on a smooth, low-contrast body
//! most blocks hold water-like noise, and the line's *slope*, extrapolated
//! to the ends, was wrong by a median 11 px where the two masks' own end
//! disparities (right within 2 px of the truth in most of those frames)
//! disagreed with it (synthetic hauls, session 30). Here the two end
//! disparities are fitted jointly on every template pixel:
//!
//! - Template: the left mask's runs widened by `m` pixels on both sides
//!   (the outline and a little water: on a flat body the outline carries
//!   the disparity), on a lattice thinned to at most [`SLANT_BUDGET`]
//!   pixels.
//! - Cost of `(d₀, d₁)`: the zero-mean SAD per pixel between the template
//!   and the right image sampled at `x − d(t)` by linear interpolation on a
//!   1/1024-pixel grid (integers per sample, so the device and the host's
//!   reference compute the same figures; the grid is fine enough that the
//!   cost is all but continuous in `(d₀, d₁)` — on the 1/16 grid it used
//!   before, f32 and f64 rounded a few dozen samples differently, costs
//!   differed by 10⁻⁴, and on a flat cost the search then settled a pixel
//!   apart, seed 8 frame 9); `None` when fewer than 90 % of the
//!   template's pixels have a right sample inside the image.
//! - Search: the best of the caller's starting hypotheses (the block line,
//!   the mask ends' chord, the flat `d_o`), then a grid of ±8 px in steps of
//!   2 around it, ±1.5 in steps of ½, ±¼ in steps of ⅛, then the vertex of
//!   a parabola through the best and its ±⅛ neighbours in each end's
//!   disparity — at most [`MAX_EVALUATIONS`] costs. (The coarse grid on a quarter of the
//!   lattice cost accuracy: seeds 1–30 per-frame 3.01 → 3.14 %.)
//!
//! Bounded work: at most `MAX_EVALUATIONS · SLANT_BUDGET` samples, each one
//! interpolation; memory: one `SLANT_BUDGET` buffer of differences
//! (16 KiB of `i32`) on the stack. No heap, no panic.

use crate::epipolar::template;
use crate::image::ImageView;
use crate::object::Run;

/// Most template pixels compared per hypothesis.
pub const SLANT_BUDGET: usize = 4096;

/// Most cost evaluations of one fit (starting hypotheses, the three grids
/// 81 + 49 + 25, and the sub-step parabola's 4).
pub const MAX_EVALUATIONS: usize = 4 + 81 + 49 + 25 + 4;

/// Least share of the template's pixels with a right sample in the image.
const MIN_COMPARED: f32 = 0.9;

/// Sub-pixel grid of the right image's interpolation.
const SUB: i32 = 1024;

/// The axis the disparity varies along: centre, unit direction, and the
/// two end positions `t₀ < t₁` the end disparities refer to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Centre x (left view).
    pub cx: f32,
    /// Centre y.
    pub cy: f32,
    /// Unit direction x.
    pub ux: f32,
    /// Unit direction y.
    pub uy: f32,
    /// First end's position along the axis.
    pub t0: f32,
    /// Second end's position.
    pub t1: f32,
}

/// A fitted slanted disparity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SlantFit {
    /// Disparity at `t₀`.
    pub d0: f32,
    /// Disparity at `t₁`.
    pub d1: f32,
    /// Zero-mean SAD per pixel (grey levels) at the fit.
    pub cost: f32,
}

impl SlantFit {
    /// The fit as a line `d = a + b·t` in the axis coordinate `t`.
    pub fn line(&self, axis: &Axis) -> (f32, f32) {
        let span = axis.t1 - axis.t0;
        let b = if span > 1e-3 {
            (self.d1 - self.d0) / span
        } else {
            0.0
        };
        (self.d0 - b * axis.t0, b)
    }
}

/// The template's lattice step `(columns, rows)` for `pixels` template
/// pixels: every pixel up to [`SLANT_BUDGET`], then every other column and
/// every `k`-th row.
pub fn lattice(pixels: u64) -> (u32, u32) {
    // half the budget: short rows round their lattice counts up
    let k = pixels.div_ceil(SLANT_BUDGET as u64 / 2).max(1);
    if k == 1 {
        (1, 1)
    } else {
        (2, k.div_ceil(2).min(1 << 16) as u32)
    }
}

/// Zero-mean SAD per pixel (in grey levels) of the template of
/// `runs` widened by `m`, on the lattice `step`, against the right image at
/// the slanted disparity `(d0, d1)` over `axis`. Also adds the samples to
/// `ops`. `None` when too few samples fall inside the right image.
#[allow(clippy::too_many_arguments)]
pub fn slant_cost(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[Run],
    m: u32,
    step: (u32, u32),
    axis: &Axis,
    d0: f32,
    d1: f32,
    ops: &mut u64,
) -> Option<f32> {
    let w = left.width().min(right.width()) as u32;
    let (cs, rs) = (step.0.max(1), step.1.max(1));
    let span = axis.t1 - axis.t0;
    let slope = if span > 1e-3 { (d1 - d0) / span } else { 0.0 };
    // the disparity's whole part apart, so the sample position's
    // fraction is computed on small numbers: `x − d = (x − k₀) − e` with
    // `k₀ = ⌊d₀⌋` and `e = (d₀ − k₀) + slope·(t − t₀)`, `e·SUB` rounded
    // (f32 keeps `e` to ~10⁻⁵ px where `x − d` itself would lose 10⁻⁴)
    let k0 = libm::floorf(d0);
    if !(k0.is_finite() && slope.is_finite()) || k0.abs() > (1 << 20) as f32 {
        return None;
    }
    let (k0, f0) = (k0 as i32, d0 - k0);
    let hi = (w as i32).saturating_sub(1).saturating_mul(SUB);
    let mut diffs = [0i32; SLANT_BUDGET];
    let (mut n, mut total) = (0usize, 0usize);
    let mut sum: i64 = 0;
    'rows: for s in template(runs, m, w).filter(|s| s.y % rs == 0) {
        let y = s.y as usize;
        let (Some(lrow), Some(rrow)) = (
            left.row(y).get(..w as usize),
            right.row(y).get(..w as usize),
        ) else {
            continue;
        };
        let first = s.x0.div_ceil(cs) * cs;
        let mut x = first;
        while x < s.x1 {
            if total >= SLANT_BUDGET {
                break 'rows;
            }
            total += 1;
            let t = (x as f32 - axis.cx) * axis.ux + (s.y as f32 - axis.cy) * axis.uy;
            let e = (f0 + slope * (t - axis.t0)) * SUB as f32;
            // the position `(x − k₀)·SUB − e` rounded half up, as the
            // reference's `round` of the whole (non-negative) position:
            // `(x − k₀)·SUB + ⌊½ − e⌋` (a cast, not a libm call per
            // sample); |e| is bounded by the template's reach
            let v = 0.5 - e;
            if v.is_nan() || v.abs() >= (1 << 30) as f32 {
                x += cs;
                continue;
            }
            let fl = {
                let i = v as i32;
                if (i as f32) > v {
                    i - 1
                } else {
                    i
                }
            };
            // right sample at x − d on the 1/SUB-pixel grid
            let q = (x as i32)
                .saturating_sub(k0)
                .saturating_mul(SUB)
                .saturating_add(fl);
            if (0..hi).contains(&q) {
                let (i, f) = ((q / SUB) as usize, q % SUB);
                if let (Some(&a), Some(&r0), Some(&r1), Some(slot)) = (
                    lrow.get(x as usize),
                    rrow.get(i),
                    rrow.get(i + 1),
                    diffs.get_mut(n),
                ) {
                    let r = r0 as i32 * (SUB - f) + r1 as i32 * f;
                    let v = a as i32 * SUB - r;
                    *slot = v;
                    sum += v as i64;
                    n += 1;
                }
            }
            x += cs;
        }
    }
    *ops = ops.saturating_add(total as u64);
    if n == 0 || (n as f32) < MIN_COMPARED * total as f32 {
        return None;
    }
    let ni = n as i64;
    let acc: i64 = diffs
        .get(..n)?
        .iter()
        .map(|&v| (ni * v as i64 - sum).abs())
        .sum();
    let nf = n as f64;
    Some((acc as f64 / (nf * nf * SUB as f64)) as f32)
}

/// Fits the slanted disparity of the object with mask `runs` (see the
/// module documentation), starting from `starts` (end-disparity pairs
/// `(d₀, d₁)`; non-finite ones are skipped) and widening the mask by `m`.
/// `None` when no hypothesis could be scored.
pub fn fit_slant(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[Run],
    m: u32,
    axis: &Axis,
    starts: &[(f32, f32)],
    ops: &mut u64,
) -> Option<SlantFit> {
    let w = left.width().min(right.width()) as u32;
    let pixels: u64 = template(runs, m, w)
        .map(|s| s.x1.saturating_sub(s.x0) as u64)
        .sum();
    let step = lattice(pixels);
    let mut eval = |d0: f32, d1: f32| slant_cost(left, right, runs, m, step, axis, d0, d1, ops);
    let mut best: Option<(f32, f32, f32)> = None;
    let consider = |d0: f32, d1: f32, best: &mut Option<(f32, f32, f32)>, c: Option<f32>| {
        if let Some(c) = c {
            // ties keep the earlier hypothesis: the order is fixed
            if best.is_none_or(|b| c < b.2) {
                *best = Some((d0, d1, c));
            }
        }
    };
    for &(d0, d1) in starts.iter().take(4) {
        if d0.is_finite() && d1.is_finite() {
            let c = eval(d0, d1);
            consider(d0, d1, &mut best, c);
        }
    }
    for (radius, h) in [(4i32, 2.0f32), (3, 0.5), (2, 0.125)] {
        let (c0, c1, _) = best?;
        for i in -radius..=radius {
            for j in -radius..=radius {
                if i == 0 && j == 0 {
                    continue;
                }
                let (d0, d1) = (c0 + i as f32 * h, c1 + j as f32 * h);
                let c = eval(d0, d1);
                consider(d0, d1, &mut best, c);
            }
        }
    }
    // sub-step vertex of a parabola through the best and its ±⅛ neighbours
    // in each end's disparity (clamped to ±⅛): a near tie between two grid
    // points — which f32 and f64 arithmetic may break differently — then
    // moves the fit by a fraction of a step, not by one
    let (c0, c1, cost) = best?;
    let h = 0.125f32;
    let vertex = |m: Option<f32>, p: Option<f32>| -> f32 {
        match (m, p) {
            (Some(m), Some(p)) => {
                let den = m - 2.0 * cost + p;
                if den > 1e-9 {
                    (0.5 * h * (m - p) / den).clamp(-h, h)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        }
    };
    let v0 = vertex(eval(c0 - h, c1), eval(c0 + h, c1));
    let v1 = vertex(eval(c0, c1 - h), eval(c0, c1 + h));
    Some(SlantFit {
        d0: c0 + v0,
        d1: c1 + v1,
        cost,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use crate::image::ImageView;
    extern crate std;
    use std::vec::Vec;

    /// A textured ellipse-ish blob whose right view is shifted by a
    /// disparity that grows linearly from `d0` at x = 100 to `d1` at x = 300.
    fn scene(d0: f32, d1: f32) -> (Vec<u8>, Vec<u8>, Vec<Run>, Axis) {
        let (w, h) = (512usize, 128usize);
        let tex = |x: f32, y: f32| -> f32 {
            let inside = ((x - 200.0) / 100.0).powi(2) + ((y - 64.0) / 30.0).powi(2) <= 1.0;
            if inside {
                120.0 + 20.0 * libm::sinf(x * 0.21) * libm::cosf(y * 0.17)
            } else {
                40.0
            }
        };
        let mut l = std::vec![0u8; w * h];
        let mut r = std::vec![0u8; w * h];
        let mut runs = Vec::new();
        for y in 0..h {
            let mut run: Option<(u16, u16)> = None;
            for x in 0..w {
                let xf = x as f32;
                l[y * w + x] = tex(xf, y as f32) as u8;
                if tex(xf, y as f32) > 60.0 {
                    run = Some(match run {
                        None => (x as u16, x as u16 + 1),
                        Some((a, _)) => (a, x as u16 + 1),
                    });
                }
                // right pixel xr shows the left point x with x − d(x) = xr:
                // solve by fixed point (d varies slowly)
                let mut xl = xf + d0;
                for _ in 0..8 {
                    let d = d0 + (d1 - d0) * (xl - 100.0) / 200.0;
                    xl = xf + d;
                }
                r[y * w + x] = tex(xl, y as f32) as u8;
            }
            if let Some((a, b)) = run {
                runs.push(Run {
                    y: y as u16,
                    x0: a,
                    x1: b,
                });
            }
        }
        let axis = Axis {
            cx: 200.0,
            cy: 64.0,
            ux: 1.0,
            uy: 0.0,
            t0: -100.0,
            t1: 100.0,
        };
        (l, r, runs, axis)
    }

    #[test]
    fn recovers_a_slanted_disparity_from_a_wrong_start() {
        let (l, r, runs, axis) = scene(20.0, 32.0);
        let lv = ImageView::packed(&l, 512, 128).unwrap();
        let rv = ImageView::packed(&r, 512, 128).unwrap();
        let mut ops = 0;
        // a start 6 px off at each end, in opposite directions
        let fit = fit_slant(&lv, &rv, &runs, 4, &axis, &[(26.0, 26.0)], &mut ops).unwrap();
        assert!((fit.d0 - 20.0).abs() <= 0.5, "{fit:?}");
        assert!((fit.d1 - 32.0).abs() <= 0.5, "{fit:?}");
        assert!(ops > 0);
        let (a, b) = fit.line(&axis);
        assert!(
            (a - 26.0).abs() <= 0.5 && (b - 0.06).abs() <= 0.005,
            "{a} {b}"
        );
    }

    #[test]
    fn the_true_slant_costs_less_than_a_flat_disparity() {
        let (l, r, runs, axis) = scene(20.0, 32.0);
        let lv = ImageView::packed(&l, 512, 128).unwrap();
        let rv = ImageView::packed(&r, 512, 128).unwrap();
        let mut ops = 0;
        let step = (1, 1);
        let good = slant_cost(&lv, &rv, &runs, 4, step, &axis, 20.0, 32.0, &mut ops).unwrap();
        let flat = slant_cost(&lv, &rv, &runs, 4, step, &axis, 26.0, 26.0, &mut ops).unwrap();
        assert!(good < flat, "{good} {flat}");
    }

    /// The cost against the same cost with the right image interpolated
    /// continuously in f64: the 1/SUB grid (and f32 positions) are all but
    /// exact — a coarse grid (1/16 px) misses by ~10⁻², enough for f32 and
    /// f64 searches to part on a flat cost.
    #[test]
    fn cost_is_all_but_continuous_interpolation() {
        let (l, r, runs, axis) = scene(20.0, 32.0);
        let lv = ImageView::packed(&l, 512, 128).unwrap();
        let rv = ImageView::packed(&r, 512, 128).unwrap();
        let exact = |d0: f64, d1: f64| -> f64 {
            let slope = (d1 - d0) / (axis.t1 - axis.t0) as f64;
            let mut v = Vec::new();
            // the first SLANT_BUDGET template pixels, as the core takes them
            let pixels = template(&runs, 4, 512)
                .flat_map(|s| (s.x0..s.x1).map(move |x| (s, x)))
                .take(SLANT_BUDGET);
            for (s, x) in pixels {
                {
                    let t = x as f64 - axis.cx as f64;
                    let p = x as f64 - (d0 + slope * (t - axis.t0 as f64));
                    let i = p.floor() as usize;
                    let f = p - p.floor();
                    let rr = r[s.y as usize * 512 + i] as f64 * (1.0 - f)
                        + r[s.y as usize * 512 + i + 1] as f64 * f;
                    v.push(l[s.y as usize * 512 + x as usize] as f64 - rr);
                }
            }
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|q| (q - mean).abs()).sum::<f64>() / v.len() as f64
        };
        let mut ops = 0;
        let mut worst = 0.0f64;
        for k in 0..40 {
            let d0 = 17.0 + 0.1731 * k as f64;
            let d1 = 35.0 - 0.0917 * k as f64;
            let c = slant_cost(
                &lv,
                &rv,
                &runs,
                4,
                (1, 1),
                &axis,
                d0 as f32,
                d1 as f32,
                &mut ops,
            )
            .unwrap() as f64;
            worst = worst.max((c - exact(d0, d1)).abs());
        }
        assert!(worst < 2e-3, "worst cost difference {worst}");
    }

    #[test]
    fn nothing_to_compare_is_none_not_a_panic() {
        let l = [0u8; 64];
        let lv = ImageView::packed(&l, 8, 8).unwrap();
        let axis = Axis {
            cx: 0.0,
            cy: 0.0,
            ux: 1.0,
            uy: 0.0,
            t0: 0.0,
            t1: 0.0,
        };
        let mut ops = 0;
        assert!(fit_slant(&lv, &lv, &[], 4, &axis, &[(1.0, 1.0)], &mut ops).is_none());
        let runs = [Run { y: 3, x0: 2, x1: 6 }];
        // every right sample outside the image
        assert!(fit_slant(&lv, &lv, &runs, 0, &axis, &[(100.0, 100.0)], &mut ops).is_none());
        assert!(fit_slant(&lv, &lv, &runs, 0, &axis, &[(f32::NAN, 1.0)], &mut ops).is_none());
    }

    /// A view wider than 2²¹ px: the sample grid's bound saturates rather
    /// than overflowing (it panicked in debug builds).
    #[test]
    fn a_very_wide_view_does_not_overflow() {
        let w = 2_200_000usize;
        let l = std::vec![7u8; w];
        let lv = ImageView::packed(&l, w, 1).unwrap();
        let axis = Axis {
            cx: 2_100_010.0,
            cy: 0.0,
            ux: 1.0,
            uy: 0.0,
            t0: -10.0,
            t1: 10.0,
        };
        let runs = [Run {
            y: 0,
            x0: u16::MAX - 20,
            x1: u16::MAX,
        }];
        let mut ops = 0;
        let _ = slant_cost(&lv, &lv, &runs, 0, (1, 1), &axis, 3.0, 3.5, &mut ops);
        let _ = fit_slant(&lv, &lv, &runs, 0, &axis, &[(3.0, 3.5)], &mut ops);
    }

    #[test]
    fn lattice_keeps_the_budget() {
        for p in [0u64, 1, 4096, 4097, 10_000, 1 << 22] {
            let (c, r) = lattice(p);
            let kept = p.div_ceil(c as u64 * r as u64);
            assert!(kept <= SLANT_BUDGET as u64 / 2, "{p}: {c} {r}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Random images, masks, axes and starts: never a panic, and a fit
        /// stays within the search's reach of its best start (±8 + 1.5 + ¼
        /// px of the grids and ⅛ of the sub-step parabola) with a finite
        /// cost.
        #[test]
        fn fit_never_panics_and_stays_near_its_starts(
            seed in 0u32..1000,
            w in 8usize..64,
            h in 4usize..32,
            runs in proptest::collection::vec((0u16..40, 0u16..80, 0u16..20), 0..20),
            axis in (-50.0f32..100.0, -50.0f32..50.0, -1.0f32..1.0, -60.0f32..0.0, 0.0f32..60.0),
            starts in proptest::collection::vec((-20.0f32..40.0, -20.0f32..40.0), 0..4),
        ) {
            let mut st = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
            let mut px = || { st = st.wrapping_mul(1_664_525).wrapping_add(1_013_904_223); (st >> 24) as u8 };
            let l: Vec<u8> = (0..w * h).map(|_| px()).collect();
            let r: Vec<u8> = (0..w * h).map(|_| px()).collect();
            let lv = ImageView::packed(&l, w, h).unwrap();
            let rv = ImageView::packed(&r, w, h).unwrap();
            let mut rs: Vec<Run> = runs.iter().map(|&(y, x0, n)| Run { y, x0, x1: x0.saturating_add(n) }).collect();
            rs.sort_by_key(|r| (r.y, r.x0));
            let (ang, n) = (axis.2 * 3.2, 1.0f32);
            let ax = Axis { cx: axis.0, cy: axis.1, ux: libm::cosf(ang) * n, uy: libm::sinf(ang) * n, t0: axis.3, t1: axis.4 };
            let mut ops = 0;
            if let Some(f) = fit_slant(&lv, &rv, &rs, 4, &ax, &starts, &mut ops) {
                proptest::prop_assert!(f.cost.is_finite() && f.cost >= 0.0);
                let near = starts.iter().any(|s| (f.d0 - s.0).abs() <= 9.875 + 1e-3 && (f.d1 - s.1).abs() <= 9.875 + 1e-3);
                proptest::prop_assert!(near, "{:?} from {:?}", f, starts);
            }
        }
    }
}
