//! Epipolar search for the left objects that stereo pairing left unpaired
//! (beyond Section IV.A).
//!
//! Object-height blocks (Fig. 7) compare a left object only with the
//! *segmented* right objects. When the right view's segmentation missed the
//! fish (a dim fish found in one view only) or merged it with a neighbour,
//! the left object has no candidate and stays unpaired: no depth for the
//! tracker's area and depth cues, no length. Here the left object's own
//! pixels are looked for directly in the right image, along its epipolar
//! band (the same rows, rectified frames), over the disparities
//! [`PairingLimits::disparity_range`] allows:
//!
//! - Template: the left object's mask runs, each widened by `m = max(4,
//!   h_o/4)` pixels on both sides (so the fish's outline and a little water
//!   are matched, not just its flat body); overlapping widened runs of a row
//!   are merged.
//! - Cost at disparity `d`: the zero-mean SAD per pixel between the template
//!   and the right image shifted by `−d` (`Σ |(a − b) − mean(a − b)| / n`,
//!   as [`crate::stereo::zsad_per_pixel`]: the two cameras see the water at
//!   different levels), over the template pixels whose right counterpart
//!   lies in the image, at least 90 % of them.
//! - Scan: every other column of every fourth template row (an eighth of
//!   its pixels; fewer rows for templates over 8 · [`SCAN_BUDGET`] pixels,
//!   so that a scan step compares about `SCAN_BUDGET`) at every disparity
//!   (in steps when the range holds more than [`MAX_SCAN`] of them), then
//!   the whole template at the scan's best and its neighbours within a
//!   step. (Disparity steps of 2 missed a finely textured fish whose cost
//!   has a basin one disparity wide, which a unit test keeps.)
//! - Acceptance: the best cost must stand out from the scan — at most
//!   [`PairingLimits::search_max_ratio`] of the scan's median cost (the
//!   template over water and unrelated clutter), and at most
//!   [`PairingLimits::search_max_runner_up`] of the lowest cost at
//!   disparities more than half the box's width away (a second fish of the
//!   same look on the same rows) — and the found box must not be mostly
//!   (IoU ≥ 0.5) a right object another pair already explains.
//!
//! A found match becomes a right object ([`SEARCHED_LEVEL`]): the left mask
//! shifted by `−d` (clipped to the frame), with area, mean, variance and
//! histogram measured on the right image under it, and a pair flagged
//! [`StereoPair::searched`] with `d_o = d`, `μ_SAD` the mean of the 4
//! object-height blocks' SADs at `d` (eq. 15's normaliser), and every block
//! at `d`. Its length is measured as any pair's ([`crate::length`]) but
//! withheld (the pipeline marks it not consistent): the right mask is the
//! left one shifted, so the consistency gate has no second view to check.
//!
//! Bounded work: per unpaired left object at most [`MAX_SCAN`] scan
//! disparities of about [`SCAN_BUDGET`] pixels each (every `4k`-th row:
//! exact for rows of equal length), plus `2·step + 1` whole-template ones;
//! every difference is counted in [`crate::stereo::PairingStats::sad_ops`].
//! Memory: the scan's disparities and costs (`MAX_SCAN` of them, 8 KiB)
//! and a 511-bin histogram on the stack; no heap. A right object that does
//! not fit the object or run capacity is not added (the left object stays
//! unpaired, counted).

use crate::geometry::StereoGeometry;
use crate::image::{ImageView, Roi};
use crate::object::{Object, Objects, Run, RunSpan, HIST_BINS};
use crate::stereo::{object_height_blocks, sad_per_pixel, PairingLimits, StereoPair, StereoPairs};

/// [`Object::level`] of a right object found by this search rather than
/// segmented.
pub const SEARCHED_LEVEL: u8 = 2;

/// Most scan disparities per object (the step grows beyond it).
pub const MAX_SCAN: usize = 1024;

/// The scan's pixel lattice (every `.0`-th column of every `.1`-th row)
/// for templates of up to `8 ·` [`SCAN_BUDGET`] pixels; larger ones take
/// every `4k`-th row so the scan compares about `SCAN_BUDGET` pixels per
/// disparity.
const SCAN_LATTICE: (u32, u32) = (2, 4);

/// Most template pixels the scan compares per disparity.
pub const SCAN_BUDGET: u64 = 16_384;

/// Least share of the template's pixels whose right counterpart must lie
/// inside the right image for a disparity to count.
const MIN_COMPARED: f32 = 0.9;

/// The search's acceptance of a disparity: [`MIN_COMPARED`] of the
/// template's pixels compared.
const ALL: (f32, u64) = (MIN_COMPARED, u64::MAX);

/// How a search for one left object came out (for diagnostics and tests).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SearchScore {
    /// Best disparity, pixels.
    pub d: i32,
    /// Zero-mean SAD per pixel at `d` (every template row).
    pub best: f32,
    /// Median of the scan's costs.
    pub median: f32,
    /// Lowest scan cost more than half the box's width from `d`
    /// (`f32::INFINITY` when there is none).
    pub runner_up: f32,
}

impl SearchScore {
    /// The acceptance test of the module documentation (cost ratios only).
    pub fn stands_out(&self, limits: &PairingLimits) -> bool {
        self.best.is_finite()
            && self.best <= limits.search_max_ratio * self.median
            && self.best <= limits.search_max_runner_up * self.runner_up
    }
}

/// One template segment: row `y`, left columns `[x0, x1)`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Seg {
    pub(crate) y: u32,
    pub(crate) x0: u32,
    pub(crate) x1: u32,
}

/// The widened, merged template segments of `runs` (sorted by row, then
/// column, as segmentation writes them; an unsorted mask only merges less).
pub(crate) fn template<'a>(runs: &'a [Run], m: u32, width: u32) -> impl Iterator<Item = Seg> + 'a {
    let mut it = runs.iter().filter(|r| !r.is_empty()).peekable();
    core::iter::from_fn(move || loop {
        let r = it.next()?;
        let y = r.y as u32;
        let x0 = (r.x0 as u32).saturating_sub(m);
        let mut x1 = (r.x1 as u32).saturating_add(m).min(width);
        while let Some(n) = it.peek() {
            if n.y as u32 == y && (n.x0 as u32).saturating_sub(m) <= x1 {
                x1 = x1.max((n.x1 as u32).saturating_add(m).min(width));
                it.next();
            } else {
                break;
            }
        }
        // a run beyond the frame's right edge leaves nothing
        if x1 > x0 {
            return Some(Seg { y, x0, x1 });
        }
    })
}

/// Columns `x` of `[x0, x1)` with `x ≡ 0 (mod step)`.
const fn multiples(x0: u32, x1: u32, step: u32) -> u64 {
    (x1.div_ceil(step) as u64).saturating_sub(x0.div_ceil(step) as u64)
}

/// Zero-mean SAD per pixel of the template pixels on the lattice
/// `(x, y) ≡ (0, 0) mod (step.0, step.1)` against the right image shifted
/// by `−d`; `None` when fewer than `need.0` of `min(those pixels, need.1)`
/// are compared (the search: [`MIN_COMPARED`] of all of them). Adds the
/// differences to `ops`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn template_cost(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[Run],
    m: u32,
    d: i32,
    step: (u32, u32),
    need: (f32, u64),
    ops: &mut u64,
) -> Option<f32> {
    let w = left.width() as u32;
    let (cs, rs) = (step.0.max(1), step.1.max(1));
    let mut hist = [0u32; 511];
    let (mut n, mut total) = (0u64, 0u64);
    for s in template(runs, m, w).filter(|s| s.y % rs == 0) {
        total += multiples(s.x0, s.x1, cs);
        // right column x − d inside [0, w), x on the lattice
        let lo = (s.x0 as i64).max(d as i64).max(0);
        let hi = (s.x1 as i64).min(w as i64 + d as i64);
        let lo = lo + (cs as i64 - lo % cs as i64) % cs as i64;
        if hi <= lo {
            continue;
        }
        let (rlo, rhi) = ((lo - d as i64) as usize, (hi - d as i64) as usize);
        let (y, lo, hi) = (s.y as usize, lo as usize, hi as usize);
        let (Some(a), Some(b)) = (left.row(y).get(lo..hi), right.row(y).get(rlo..rhi)) else {
            continue;
        };
        let (a, b) = (a.iter().step_by(cs as usize), b.iter().step_by(cs as usize));
        n += a.len() as u64;
        for (&p, &q) in a.zip(b) {
            if let Some(c) = hist.get_mut((p as usize + 255) - q as usize) {
                *c += 1;
            }
        }
    }
    *ops = ops.saturating_add(n);
    if n == 0 || (n as f32) < need.0 * total.min(need.1) as f32 {
        return None;
    }
    Some(zero_mean_sad(&hist, n))
}

/// `Σ |n·v − S| · c_v / n²` over a histogram `c` of the differences `v`
/// (`S = Σ c_v·v`, `n = Σ c_v`): the zero-mean SAD per pixel, exactly, as
/// `n·(S_hi − S_lo) − S·(C_hi − C_lo)` over the bins above and below the
/// mean — integer sums over the bins and four products, not a product per
/// bin. `|S| ≤ 255·n` and every sum fits `i64` for `n < 2³²`; the products
/// are taken in `i128`.
fn zero_mean_sad(hist: &[u32; 511], n: u64) -> f32 {
    let ni = n as i64;
    let sum: i64 = hist.iter().zip(-255i64..).map(|(&c, v)| c as i64 * v).sum();
    let (mut c_hi, mut s_hi, mut c_lo, mut s_lo) = (0i64, 0i64, 0i64, 0i64);
    for (&c, v) in hist.iter().zip(-255i64..) {
        let t = ni * v - sum;
        if t > 0 {
            c_hi += c as i64;
            s_hi += c as i64 * v;
        } else if t < 0 {
            c_lo += c as i64;
            s_lo += c as i64 * v;
        }
    }
    let acc = ni as i128 * (s_hi - s_lo) as i128 - sum as i128 * (c_hi - c_lo) as i128;
    let nf = n as f64;
    (acc as f64 / (nf * nf)) as f32
}

/// Searches the right image for one left object (see the module
/// documentation); `None` when no disparity could be evaluated.
pub fn search_object(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    obj: &Object,
    runs: &[Run],
    d_lo: f32,
    d_hi: f32,
    ops: &mut u64,
) -> Option<SearchScore> {
    let lo = (micromath::F32(d_lo).ceil().0 as i32).max(0);
    // no pixel has a counterpart beyond the frame's width (and the scan's
    // `d += step` cannot run past i32::MAX)
    let hi = (micromath::F32(d_hi).floor().0 as i32).min(left.width().min(1 << 30) as i32);
    if hi < lo || runs.is_empty() {
        return None;
    }
    let m = ((obj.obb.half_h * 0.5) as u32).max(4);
    let pixels: u64 = template(runs, m, left.width() as u32)
        .map(|s| s.x1.saturating_sub(s.x0) as u64)
        .sum();
    let k = pixels.div_ceil(8 * SCAN_BUDGET).max(1);
    let lattice = (
        SCAN_LATTICE.0,
        SCAN_LATTICE.1.saturating_mul(k.min(1 << 16) as u32),
    );
    let span = (hi - lo) as usize + 1;
    let step = span.div_ceil(MAX_SCAN).max(1);
    let mut scan = [(0i32, f32::INFINITY); MAX_SCAN];
    let mut n = 0usize;
    let mut d = lo;
    while d <= hi {
        if let Some(c) = template_cost(left, right, runs, m, d, lattice, ALL, ops) {
            if let Some(slot) = scan.get_mut(n) {
                *slot = (d, c);
                n += 1;
            }
        }
        d = d.saturating_add(step as i32);
    }
    let scan = scan.get_mut(..n)?;
    let (coarse_d, _) = scan.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1))?;
    // runner-up: the scan's lowest cost more than half a box width away
    let far = (obj.bbox.w / 2).max(step as u32) as i32;
    let runner_up = scan
        .iter()
        .filter(|(d, _)| (d - coarse_d).abs() > far)
        .map(|s| s.1)
        .fold(f32::INFINITY, f32::min);
    let (_, mid, _) = scan.select_nth_unstable_by(n / 2, |a, b| a.1.total_cmp(&b.1));
    let median = mid.1;
    // refine at every row around the scan's best
    let mut fine: Option<(i32, f32)> = None;
    let reach = step as i32;
    for d in (coarse_d - reach).max(lo)..=(coarse_d + reach).min(hi) {
        if let Some(c) = template_cost(left, right, runs, m, d, (1, 1), ALL, ops) {
            if fine.is_none_or(|(_, b)| c < b) {
                fine = Some((d, c));
            }
        }
    }
    let (d, best) = fine?;
    Some(SearchScore {
        d,
        best,
        median,
        runner_up,
    })
}

/// The right object a match found at disparity `d` stands for: the left
/// mask shifted by `−d`, clipped to the frame, measured on the right image.
/// `None` when nothing of it lies in the frame or the run pool is full.
fn shifted_object<const N: usize, const R: usize>(
    right: &ImageView<'_>,
    obj: &Object,
    runs: &[Run],
    d: i32,
    out: &mut Objects<N, R>,
) -> Option<Object> {
    let w = right.width() as i64;
    let start = out.runs.len();
    let (mut x_min, mut y_min, mut x_max, mut y_max) = (u32::MAX, u32::MAX, 0u32, 0u32);
    let mut hist = [0u32; HIST_BINS];
    let (mut area, mut sum, mut sum2) = (0u64, 0u64, 0u64);
    for r in runs {
        let x0 = (r.x0 as i64 - d as i64).clamp(0, w);
        let x1 = (r.x1 as i64 - d as i64).clamp(0, w);
        if x1 <= x0 {
            continue;
        }
        let Some(px) = right.row(r.y as usize).get(x0 as usize..x1 as usize) else {
            out.runs.truncate(start);
            return None;
        };
        if out
            .runs
            .push(Run {
                y: r.y,
                x0: x0 as u16,
                x1: x1 as u16,
            })
            .is_err()
        {
            out.runs.truncate(start);
            return None;
        }
        for &p in px {
            if let Some(h) = hist.get_mut((p >> 4) as usize) {
                *h += 1;
            }
            sum += p as u64;
            sum2 += p as u64 * p as u64;
        }
        area += px.len() as u64;
        x_min = x_min.min(x0 as u32);
        x_max = x_max.max(x1 as u32);
        y_min = y_min.min(r.y as u32);
        y_max = y_max.max(r.y as u32 + 1);
    }
    if area == 0 {
        out.runs.truncate(start);
        return None;
    }
    let a = area as f64;
    let mean = sum as f64 / a;
    let variance = if area > 1 {
        ((sum2 as f64 - a * mean * mean) / (a - 1.0)).max(0.0)
    } else {
        0.0
    };
    let mut obb = obj.obb;
    obb.cx -= d as f32;
    Some(Object {
        bbox: Roi::new(x_min, y_min, x_max - x_min, y_max - y_min),
        obb,
        area: area as u32,
        mean: mean as f32,
        variance: variance as f32,
        hist,
        runs: RunSpan {
            start: start as u32,
            len: (out.runs.len() - start) as u32,
        },
        level: SEARCHED_LEVEL,
    })
}

/// Mean of the object-height blocks' SADs per pixel at disparity `d`
/// (eq. 15's `μ_SAD` for a searched pair).
fn block_mu_sad(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    bbox: Roi,
    d: i32,
    ops: &mut u64,
) -> f32 {
    let (mut s, mut k) = (0.0f32, 0u32);
    for b in object_height_blocks(bbox) {
        if b.w == 0 {
            continue;
        }
        if let Some(v) = sad_per_pixel(left, right, b.x, b.right(), b.y, b.bottom(), d, ops) {
            s += v;
            k += 1;
        }
    }
    if k == 0 {
        f32::INFINITY
    } else {
        s / k as f32
    }
}

/// Runs the search for every left object `pairs` leaves unpaired (see the
/// module documentation), appending the right objects and pairs it finds;
/// pairs stay ordered by left index (the caller decides whether to search:
/// `Params::stereo_search`).
pub fn search_unpaired<const N: usize, const R: usize>(
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: &Objects<N, R>,
    right: &mut Objects<N, R>,
    pairs: &mut StereoPairs<N>,
    geom: &StereoGeometry,
    limits: &PairingLimits,
) {
    if left_img.width() != right_img.width() || left_img.height() != right_img.height() {
        return;
    }
    let (d_lo, d_hi) = limits.disparity_range(geom);
    let segmented = right.items.len();
    for (i, lo) in left.items.iter().enumerate() {
        if pairs.pairs.iter().any(|p| p.left as usize == i) {
            continue;
        }
        let runs = left.runs_of(lo);
        let mut ops = 0u64;
        let score = search_object(left_img, right_img, lo, runs, d_lo, d_hi, &mut ops);
        pairs.stats.sad_ops = pairs.stats.sad_ops.saturating_add(ops);
        let Some(score) = score else { continue };
        if !score.stands_out(limits) {
            continue;
        }
        let found = shifted(&lo.bbox, score.d);
        // a region another pair already explains is not this fish's
        let explained = pairs.pairs.iter().any(|p| {
            (p.right as usize) < segmented
                && right
                    .items
                    .get(p.right as usize)
                    .is_some_and(|ro| ro.bbox.iou(&found) >= 0.5)
        });
        if explained || right.items.is_full() {
            continue;
        }
        let Some(obj) = shifted_object(right_img, lo, runs, score.d, right) else {
            continue;
        };
        let mut ops = 0u64;
        let mu_sad = block_mu_sad(left_img, right_img, lo.bbox, score.d, &mut ops);
        pairs.stats.sad_ops = pairs.stats.sad_ops.saturating_add(ops);
        let j = right.items.len();
        if right.items.push(obj).is_err() {
            continue;
        }
        let d = score.d as f32;
        if pairs
            .pairs
            .push(StereoPair {
                left: i as u16,
                right: j as u16,
                d_o: d,
                mu_sad,
                block_disparity: [d; crate::stereo::BLOCKS],
                occluded: false,
                searched: true,
            })
            .is_ok()
        {
            pairs.stats.searched += 1;
            pairs.stats.unpaired_left = pairs.stats.unpaired_left.saturating_sub(1);
        }
    }
    pairs.pairs.sort_unstable_by_key(|p| p.left);
}

/// `b` moved left by `d` pixels (clamped at 0).
fn shifted(b: &Roi, d: i32) -> Roi {
    Roi::new((b.x as i64 - d as i64).max(0) as u32, b.y, b.w, b.h)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::object::OrientedBox;
    use proptest::prelude::*;
    use std::vec::Vec;

    const W: usize = 400;
    const H: usize = 200;

    /// f 600 px, baseline 100 mm: disparities 3 (20 m) to 120 (0.5 m), ± 8.
    fn geom() -> StereoGeometry {
        StereoGeometry {
            f: 600.0,
            cx: 200.0,
            cy: 100.0,
            cx_right: 200.0,
            baseline_mm: 100.0,
        }
    }

    /// Water at `level` with deterministic noise of ± `amp` grey levels.
    fn water(level: u8, amp: u32, seed: u32) -> Vec<u8> {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        (0..W * H)
            .map(|_| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let n = (s >> 16) % (2 * amp + 1);
                (level as u32 + n).saturating_sub(amp).min(255) as u8
            })
            .collect()
    }

    /// Is `(x, y)` inside the fish (an ellipse of half-axes 50 × 15) centred at `cx, cy`?
    fn in_fish(x: i64, y: i64, cx: i64, cy: i64) -> bool {
        let (u, v) = ((x - cx) as f32 / 50.0, (y - cy) as f32 / 15.0);
        u * u + v * v <= 1.0
    }

    /// Paints a textured fish into `img` centred at `(cx, cy)`: grey
    /// `base` plus a texture that moves with the fish.
    fn paint(img: &mut [u8], cx: i64, cy: i64, base: u8) {
        for y in 0..H as i64 {
            for x in 0..W as i64 {
                if in_fish(x, y, cx, cy) {
                    let t = ((x - cx + 60) * 7 % 23 + (y - cy + 20) * 3 % 11) as u8;
                    img[y as usize * W + x as usize] = base.saturating_add(t);
                }
            }
        }
    }

    /// Adds the object whose mask is `inside` on a `w × h` frame (one run
    /// per row, from its first to its last pixel) with the oriented box
    /// `obb`; box and area from the runs.
    fn push_object<const N: usize, const R: usize>(
        objs: &mut Objects<N, R>,
        (w, h): (usize, usize),
        inside: impl Fn(i64, i64) -> bool,
        obb: OrientedBox,
    ) {
        let start = objs.runs.len() as u32;
        let (mut x0, mut y0, mut x1, mut y1) = (i64::MAX, i64::MAX, 0, 0);
        let mut area = 0u32;
        for y in 0..h as i64 {
            let xs: Vec<i64> = (0..w as i64).filter(|&x| inside(x, y)).collect();
            if let (Some(&a), Some(&b)) = (xs.first(), xs.last()) {
                objs.runs
                    .push(Run {
                        y: y as u16,
                        x0: a as u16,
                        x1: b as u16 + 1,
                    })
                    .unwrap();
                area += xs.len() as u32;
                (x0, x1, y0, y1) = (x0.min(a), x1.max(b + 1), y0.min(y), y1.max(y + 1));
            }
        }
        let len = objs.runs.len() as u32 - start;
        objs.items
            .push(Object {
                bbox: Roi::new(x0 as u32, y0 as u32, (x1 - x0) as u32, (y1 - y0) as u32),
                obb,
                area,
                runs: RunSpan { start, len },
                ..Object::default()
            })
            .unwrap();
    }

    /// The left object of a fish painted at `(cx, cy)`.
    fn fish_object(objs: &mut Objects<8, 512>, cx: i64, cy: i64) {
        let obb = OrientedBox {
            cx: cx as f32,
            cy: cy as f32,
            half_w: 50.0,
            half_h: 15.0,
            angle: 0.0,
        };
        push_object(objs, (W, H), |x, y| in_fish(x, y, cx, cy), obb);
    }

    struct Scene {
        left: Vec<u8>,
        right: Vec<u8>,
        lobj: Objects<8, 512>,
    }

    /// One fish at (250, 100) in the left view; in the right view at each
    /// of `disparities` (none: the right view is water only).
    fn scene(disparities: &[i64]) -> Scene {
        let (mut left, mut right) = (water(60, 4, 1), water(64, 4, 2));
        paint(&mut left, 250, 100, 110);
        for &d in disparities {
            paint(&mut right, 250 - d, 100, 114);
        }
        let mut lobj = Objects::new();
        fish_object(&mut lobj, 250, 100);
        Scene { left, right, lobj }
    }

    fn run(s: &Scene, robj: &mut Objects<8, 512>, pairs: &mut StereoPairs<8>) {
        let l = ImageView::packed(&s.left, W, H).unwrap();
        let r = ImageView::packed(&s.right, W, H).unwrap();
        search_unpaired(
            &l,
            &r,
            &s.lobj,
            robj,
            pairs,
            &geom(),
            &PairingLimits::default(),
        );
    }

    #[test]
    fn finds_a_fish_the_right_segmentation_missed_at_its_disparity() {
        let s = scene(&[37]);
        let (mut robj, mut pairs) = (Objects::new(), StereoPairs::default());
        pairs.stats.unpaired_left = 1;
        run(&s, &mut robj, &mut pairs);
        assert_eq!(pairs.pairs.len(), 1);
        let p = pairs.pairs[0];
        assert!(p.searched && !p.occluded);
        assert_eq!((p.left, p.right, p.d_o), (0, 0, 37.0));
        assert_eq!(p.block_disparity, [37.0; 4]);
        assert!(p.mu_sad < 10.0, "{}", p.mu_sad);
        let (lo, ro) = (s.lobj.items[0], robj.items[0]);
        assert_eq!(ro.level, SEARCHED_LEVEL);
        assert_eq!(
            ro.bbox,
            Roi::new(lo.bbox.x - 37, lo.bbox.y, lo.bbox.w, lo.bbox.h)
        );
        assert_eq!(ro.area, lo.area);
        assert_eq!(ro.obb.cx, lo.obb.cx - 37.0);
        // measured on the right image: the fish there is 4 levels brighter
        assert!(ro.mean > 114.0, "{}", ro.mean);
        assert_eq!(ro.hist.iter().sum::<u32>(), ro.area);
        assert_eq!(robj.runs_of(&ro).len(), s.lobj.runs_of(&lo).len());
        assert_eq!((pairs.stats.searched, pairs.stats.unpaired_left), (1, 0));
        assert!(pairs.stats.sad_ops > 0);
    }

    #[test]
    fn the_search_score_stands_out_only_at_the_fish() {
        let s = scene(&[37]);
        let l = ImageView::packed(&s.left, W, H).unwrap();
        let r = ImageView::packed(&s.right, W, H).unwrap();
        let (lo, hi) = PairingLimits::default().disparity_range(&geom());
        let o = s.lobj.items[0];
        let mut ops = 0;
        let sc = search_object(&l, &r, &o, s.lobj.runs_of(&o), lo, hi, &mut ops).unwrap();
        assert_eq!(sc.d, 37);
        // noise of ± 4 in each view: about 2.5 levels per pixel at the fish
        assert!(sc.best < 4.0 && sc.median > 2.0 * sc.best, "{sc:?}");
        assert!(sc.stands_out(&PairingLimits::default()));
    }

    #[test]
    fn zero_mean_sad_is_the_plain_formula() {
        let mut state = 7u32;
        for _ in 0..200 {
            let mut hist = [0u32; 511];
            let mut diffs = std::vec::Vec::new();
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let (k, spread) = (1 + (state >> 8) % 300, 1 + (state >> 20) % 511);
            for _ in 0..k {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let v = ((state >> 9) % spread) as i64 - 255;
                hist[(v + 255) as usize] += 1;
                diffs.push(v as f64);
            }
            let n = diffs.len() as f64;
            let mean = diffs.iter().sum::<f64>() / n;
            let plain = diffs.iter().map(|v| (v - mean).abs()).sum::<f64>() / n;
            let fast = zero_mean_sad(&hist, diffs.len() as u64) as f64;
            assert!(
                (fast - plain).abs() <= 1e-5 * plain.max(1.0),
                "{fast} {plain}"
            );
        }
    }

    #[test]
    #[cfg_attr(miri, ignore = "four 1024-step scans: too slow to interpret")]
    fn a_degenerate_geometry_neither_hangs_nor_panics() {
        let s = scene(&[37]);
        let l = ImageView::packed(&s.left, W, H).unwrap();
        let r = ImageView::packed(&s.right, W, H).unwrap();
        let o = s.lobj.items[0];
        let mut ops = 0;
        // disparity ranges of a bad calibration: enormous, inverted, NaN
        for (lo, hi) in [
            (0.0, 1e12),
            (-1e12, 1e12),
            (50.0, 10.0),
            (f32::NAN, f32::NAN),
        ] {
            let _ = search_object(&l, &r, &o, s.lobj.runs_of(&o), lo, hi, &mut ops);
        }
        let g = StereoGeometry {
            baseline_mm: 1e12,
            ..geom()
        };
        let (mut robj, mut pairs) = (Objects::<8, 512>::new(), StereoPairs::<8>::default());
        search_unpaired(
            &l,
            &r,
            &s.lobj,
            &mut robj,
            &mut pairs,
            &g,
            &PairingLimits::default(),
        );
        assert!(pairs.pairs.len() <= 1);
    }

    #[test]
    fn water_alone_in_the_right_view_leaves_the_object_unpaired() {
        let s = scene(&[]);
        let (mut robj, mut pairs) = (Objects::new(), StereoPairs::default());
        run(&s, &mut robj, &mut pairs);
        assert!(pairs.pairs.is_empty() && robj.items.is_empty() && robj.runs.is_empty());
        assert_eq!(pairs.stats.searched, 0);
    }

    #[test]
    fn two_lookalikes_on_the_band_are_refused() {
        // the same fish at disparities 10 and 120: which is it?
        let s = scene(&[10, 120]);
        let (mut robj, mut pairs) = (Objects::new(), StereoPairs::default());
        run(&s, &mut robj, &mut pairs);
        assert!(pairs.pairs.is_empty(), "{:?}", pairs.pairs);
    }

    #[test]
    fn a_region_another_pair_explains_is_not_taken() {
        let s = scene(&[37]);
        // a right object where the fish is, already paired with left object 1
        let mut robj: Objects<8, 512> = Objects::new();
        fish_object(&mut robj, 250 - 37, 100);
        let mut pairs = StereoPairs::default();
        pairs
            .pairs
            .push(StereoPair {
                left: 1,
                right: 0,
                ..StereoPair::default()
            })
            .unwrap();
        run(&s, &mut robj, &mut pairs);
        assert_eq!(pairs.pairs.len(), 1);
        assert_eq!(robj.items.len(), 1);
    }

    #[test]
    fn full_right_objects_are_reported_not_overrun() {
        let s = scene(&[37]);
        let mut robj: Objects<8, 512> = Objects::new();
        for k in 0..8 {
            robj.items
                .push(Object {
                    bbox: Roi::new(k * 4, 0, 2, 2),
                    ..Object::default()
                })
                .unwrap();
        }
        let mut pairs = StereoPairs::default();
        pairs.stats.unpaired_left = 1;
        run(&s, &mut robj, &mut pairs);
        assert!(pairs.pairs.is_empty());
        assert_eq!(pairs.stats.unpaired_left, 1);
        // no run pool room: nothing added either
        let mut robj: Objects<8, 512> = Objects::new();
        while robj.runs.push(Run::default()).is_ok() {}
        let mut pairs = StereoPairs::default();
        run(&s, &mut robj, &mut pairs);
        assert!(pairs.pairs.is_empty() && robj.items.is_empty());
        assert_eq!(robj.runs.len(), 512);
    }

    #[test]
    #[cfg_attr(miri, ignore = "a 1400 × 600 pair: too slow to interpret")]
    fn a_large_template_is_scanned_within_the_budget() {
        // a 1200 × 500 px fish (≈ 470 000 mask pixels) in 1400 × 600 views
        let (w, h) = (1400usize, 600usize);
        let inside = |x: i64, y: i64, cx: i64| {
            let (u, v) = ((x - cx) as f32 / 600.0, (y - 300) as f32 / 250.0);
            u * u + v * v <= 1.0
        };
        // the same textured fish, at x = 650 in the left view, 605 in the right
        let paint = |cx: i64| {
            let mut img = vec![60u8; w * h];
            for y in 0..h as i64 {
                for x in (0..w as i64).filter(|&x| inside(x, y, cx)) {
                    let t = (x - cx + 700) * 13 % 29 + ((x - cx) * 13 + y * 7).rem_euclid(29) % 3;
                    img[y as usize * w + x as usize] = 100 + t as u8;
                }
            }
            img
        };
        let (left, right) = (paint(650), paint(650 - 45));
        let mut lobj: Objects<4, 1024> = Objects::new();
        let obb = OrientedBox {
            cx: 650.0,
            cy: 300.0,
            half_w: 600.0,
            half_h: 250.0,
            angle: 0.0,
        };
        push_object(&mut lobj, (w, h), |x, y| inside(x, y, 650), obb);
        let obj = lobj.items[0];
        let (l, r) = (
            ImageView::packed(&left, w, h).unwrap(),
            ImageView::packed(&right, w, h).unwrap(),
        );
        let mut ops = 0u64;
        let sc = search_object(&l, &r, &obj, lobj.runs_of(&obj), 0.0, 100.0, &mut ops).unwrap();
        assert_eq!(sc.d, 45);
        let template: u64 = template(lobj.runs_of(&obj), 62, w as u32)
            .map(|s| (s.x1 - s.x0) as u64)
            .sum();
        assert!(template > 8 * SCAN_BUDGET, "{template}");
        // 101 scan disparities of about SCAN_BUDGET pixels, 3 whole templates
        let bound = 101 * SCAN_BUDGET * 11 / 10 + 3 * template;
        assert!(ops <= bound, "{ops} > {bound}");
        assert!(ops >= 3 * template, "{ops}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 48 }))]
        /// Random views, random masks anywhere (cut by the border, outside
        /// it): never a panic; what is added is consistent.
        #[test]
        fn random_scenes_never_panic(
            seed in 0u32..1000,
            d in 0i64..130,
            runs in proptest::collection::vec((0u16..220, 0u16..420, 1u16..80), 1..40),
        ) {
            let (mut left, mut right) = (water(60, 30, seed), water(60, 30, seed + 7));
            paint(&mut left, 250, 100, 110);
            paint(&mut right, 250 - d, 100, 110);
            let mut lobj: Objects<8, 512> = Objects::new();
            let mut sorted = runs.clone();
            sorted.sort();
            for (y, x0, len) in sorted {
                lobj.runs.push(Run { y, x0, x1: x0.saturating_add(len) }).unwrap();
            }
            lobj.items.push(Object {
                bbox: Roi::new(0, 0, W as u32 + 30, H as u32 + 30),
                runs: RunSpan { start: 0, len: lobj.runs.len() as u32 },
                ..Object::default()
            }).unwrap();
            let s = Scene { left, right, lobj };
            let (mut robj, mut pairs) = (Objects::new(), StereoPairs::default());
            run(&s, &mut robj, &mut pairs);
            for p in pairs.pairs.iter() {
                let ro = robj.items[p.right as usize];
                prop_assert!(p.searched);
                for r in robj.runs_of(&ro) {
                    prop_assert!((r.y as usize) < H && r.x0 < r.x1 && r.x1 as usize <= W);
                }
                prop_assert!(ro.bbox.right() as usize <= W && ro.area > 0);
            }
        }
    }
}
