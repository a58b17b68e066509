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
//! - Scan: every other template row at disparity steps of 2 (coarser when
//!   the range holds more than [`MAX_SCAN`] steps), then every row at the
//!   disparities within ±2 of the scan's best.
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
//! at `d`. Lengths then go through the same end validation, refinement and
//! consistency gate as any pair ([`crate::length`]).
//!
//! Bounded work: per unpaired left object at most [`MAX_SCAN`] scan
//! disparities over half its template, plus 5 full evaluations; every
//! difference is counted in [`crate::stereo::PairingStats::sad_ops`].
//! Memory: the scan's disparities and costs (`MAX_SCAN` of them, 8 KiB) and a 511-bin histogram
//! on the stack; no heap. A right object that does not fit the object or run
//! capacity is not added (the left object stays unpaired, counted).

use crate::geometry::StereoGeometry;
use crate::image::{ImageView, Roi};
use crate::object::{Object, Objects, Run, RunSpan, HIST_BINS};
use crate::stereo::{object_height_blocks, sad_per_pixel, PairingLimits, StereoPair, StereoPairs};

/// [`Object::level`] of a right object found by this search rather than
/// segmented.
pub const SEARCHED_LEVEL: u8 = 2;

/// Most scan disparities per object (the step grows beyond it).
pub const MAX_SCAN: usize = 1024;

/// Least share of the template's pixels whose right counterpart must lie
/// inside the right image for a disparity to count.
const MIN_COMPARED: f32 = 0.9;

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
struct Seg {
    y: u32,
    x0: u32,
    x1: u32,
}

/// The widened, merged template segments of `runs` (sorted by row, then
/// column, as segmentation writes them; an unsorted mask only merges less).
fn template<'a>(runs: &'a [Run], m: u32, width: u32) -> impl Iterator<Item = Seg> + 'a {
    let mut it = runs.iter().filter(|r| !r.is_empty()).peekable();
    core::iter::from_fn(move || {
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
        Some(Seg { y, x0, x1 })
    })
}

/// Zero-mean SAD per pixel of the template rows `y ≡ 0 (mod row_step)`
/// against the right image shifted by `−d`; `None` below [`MIN_COMPARED`]
/// of those rows' pixels compared. Adds the differences to `ops`.
fn cost_at(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[Run],
    m: u32,
    d: i32,
    row_step: u32,
    ops: &mut u64,
) -> Option<f32> {
    let w = left.width() as u32;
    let mut hist = [0u32; 511];
    let (mut n, mut total) = (0u64, 0u64);
    for s in template(runs, m, w).filter(|s| s.y % row_step == 0) {
        total += (s.x1 - s.x0) as u64;
        // right column x − d inside [0, w)
        let lo = (s.x0 as i64).max(d as i64).max(0);
        let hi = (s.x1 as i64).min(w as i64 + d as i64);
        if hi <= lo {
            continue;
        }
        let (rlo, rhi) = ((lo - d as i64) as usize, (hi - d as i64) as usize);
        let (y, lo, hi) = (s.y as usize, lo as usize, hi as usize);
        let (Some(a), Some(b)) = (left.row(y).get(lo..hi), right.row(y).get(rlo..rhi)) else {
            continue;
        };
        for (&p, &q) in a.iter().zip(b) {
            if let Some(c) = hist.get_mut((p as usize + 255) - q as usize) {
                *c += 1;
            }
        }
        n += a.len() as u64;
    }
    *ops = ops.saturating_add(n);
    if n == 0 || (n as f32) < MIN_COMPARED * total as f32 {
        return None;
    }
    let ni = n as i64;
    let sum: i64 = hist.iter().zip(-255i64..).map(|(&c, v)| c as i64 * v).sum();
    // |n·v − sum| ≤ 2⁴¹ for n < 2³²; counts ≤ 2³²: u128 holds the total
    let acc: u128 = hist
        .iter()
        .zip(-255i64..)
        .filter(|(&c, _)| c > 0)
        .map(|(&c, v)| c as u128 * (ni * v - sum).unsigned_abs() as u128)
        .sum();
    let nf = n as f64;
    Some((acc as f64 / (nf * nf)) as f32)
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
    let hi = micromath::F32(d_hi).floor().0 as i32;
    if hi < lo || runs.is_empty() {
        return None;
    }
    let m = ((obj.obb.half_h * 0.5) as u32).max(4);
    let span = (hi - lo) as usize + 1;
    let step = span.div_ceil(MAX_SCAN).max(2);
    let mut scan = [(0i32, f32::INFINITY); MAX_SCAN];
    let mut n = 0usize;
    let mut d = lo;
    while d <= hi {
        if let Some(c) = cost_at(left, right, runs, m, d, 2, ops) {
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
    for d in (coarse_d - 2).max(lo)..=(coarse_d + 2).min(hi) {
        if let Some(c) = cost_at(left, right, runs, m, d, 1, ops) {
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
