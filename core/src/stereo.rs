//! Stereo pairing with object-height blocks (Section IV.A, Fig. 7).
//!
//! Each left object's upright box is split into 4 non-overlapping blocks
//! side by side ([`object_height_blocks`]: block height = box height, width =
//! box width / 4). In rectified frames corresponding rows are equal, so a
//! block is compared only with the 4 blocks of every right object whose rows
//! overlap it (same epipolar band), by the sum of absolute differences (SAD)
//! over the shared rows, normalised per pixel so that objects of different
//! sizes compare. The right object with the least sum of the 4 minimum block
//! SADs is the pair; `μ_SAD` (eq. 15) is the average of those 4 minima.
//!
//! Beyond the paper:
//! - Candidates are gated for plausibility ([`PairingLimits`]): row overlap,
//!   size ratio (not along a side where an object is cut by the frame
//!   border), disparity within the range the geometry allows between
//!   `min_range_mm` and `max_range_mm` (negative or too-large shifts are never
//!   evaluated), and `μ_SAD` per pixel. A left object with no plausible
//!   candidate stays unpaired rather than being mis-paired.
//! - Pairing is one-to-one: an optimal assignment (shortest augmenting path,
//!   Jonker–Volgenant style) over the `μ_SAD` cost matrix maximises the number
//!   of plausible pairs, then minimises the summed cost. Occlusion exception:
//!   a left object left out by the assignment may share its best right object
//!   with the left object assigned to it when that right box covers ≥ 90 % of
//!   both left boxes shifted by their disparities (two fish merged into one
//!   blob in the right view); such pairs are flagged `occluded`.
//! - The coarse disparity `d_o` is the candidate (the 4 block disparities and
//!   the two box-edge alignments) with the least whole-box SAD per pixel, so a
//!   box cut by the frame border or cropped at one end still gets the
//!   disparity of its visible part. By default (session 16,
//!   [`PairingLimits::zero_mean_d_o`]) that whole-box SAD is *zero-mean*
//!   ([`zsad_per_pixel`]): the two cameras record the water at different
//!   levels (their own strobes and vignetting; on the synthetic hauls of
//!   seeds 1–12 the medians of the same 256-px tile differ by up to 57 grey
//!   levels, over 36 in a tenth of the frames), and a box that is mostly water — a fish entering
//!   across the border, whose head alone is in the left view — then
//!   matched the other view's brighter water better than its own head at
//!   the plain SAD: seed 5, frame 14, depth 1978 mm for a fish at 2908 mm,
//!   and the depth cue of the tracker then split the fish's track. It is
//!   evaluated only for the pairs the assignment chooses
//!   ([`CoarseCost::Deferred`]), as pairing itself needs only `μ_SAD`.
//!   Since session 25 ([`PairingLimits::masked_d_o`], default on) that
//!   score is taken over the left object's mask widened by `max(4,
//!   h_o/4)` columns ([`masked_d_o`], the epipolar search's template)
//!   rather than its upright box: a fish lying diagonally fills a small
//!   part of its box, and on a dim fish the box's water decided the
//!   score (seed 9, frame 10: d_o 400 px for a fish at 276, depth 1254 mm
//!   for 1846). A shift is scored when at least half of the smaller view
//!   is compared ([`zsad_whole`]: the left image's left border hides part
//!   of a fish from the right camera).
//!
//! Cost: a candidate costs `16 · (w/4) · h = 4·w·h` absolute differences;
//! a chosen pair adds ≤ 6 whole-box evaluations for `d_o`; [`PairingStats::sad_ops`] counts them,
//! [`dense_sad_ops`] gives the dense block-matching figure to compare with.
//! Memory bound: the cost matrix `N² · 4` bytes and `O(N)` work arrays on the
//! stack (the chosen pairs' block matches are recomputed, not stored), and
//! the zero-mean SAD's 2 KiB histogram of differences; no heap.

use crate::error::ImageError;
use crate::geometry::StereoGeometry;
use crate::image::{ImageView, Roi};
use crate::object::Objects;

/// Number of object-height blocks per object (Fig. 7).
pub const BLOCKS: usize = 4;

/// Cost given to implausible pairs in the assignment (never selected as a pair).
const NO_PAIR: f32 = 1.0e6;

/// Plausible candidate matches [`pair_objects`] keeps for the chosen pairs
/// (on the stack; beyond it they are recomputed).
const KEPT_MATCHES: usize = 32;

/// Plausibility gate of a left/right candidate pair.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PairingLimits {
    /// Nearest plausible range of a fish, mm: gives the largest disparity.
    pub min_range_mm: f32,
    /// Farthest plausible range, mm: gives the smallest disparity.
    pub max_range_mm: f32,
    /// Disparity slack, pixels, around that range (rectification error, box jitter).
    pub disparity_slack: f32,
    /// Minimum shared rows as a fraction of the smaller box height.
    pub min_row_overlap: f32,
    /// Minimum ratio smaller/larger of box widths and of box heights (not
    /// applied along an axis where a box touches the frame border).
    pub min_size_ratio: f32,
    /// Largest acceptable `μ_SAD`, grey levels per pixel.
    pub max_sad_per_pixel: f32,
    /// Choose `d_o` among its candidates by the *zero-mean* whole-box SAD
    /// ([`zsad_per_pixel`]; beyond the paper): the two cameras see the
    /// water and the fish at different levels (their own strobes and
    /// vignetting), and a box that is mostly water — a fish cut by the
    /// frame border, a thin or dim fish — then matches the other view's
    /// brighter water better than the fish itself at the plain SAD. False:
    /// the plain SAD, as the blocks.
    pub zero_mean_d_o: bool,
    /// Score the zero-mean `d_o` candidates on the left object's widened
    /// mask ([`masked_d_o`]) rather than its upright box.
    pub masked_d_o: bool,
    /// Epipolar search ([`crate::epipolar`], `Params::stereo_search`): the
    /// best cost must be at most this share of the scan's median cost.
    pub search_max_ratio: f32,
    /// Epipolar search: the best cost must be at most this share of the
    /// lowest cost more than half the box's width away.
    pub search_max_runner_up: f32,
    /// Beyond the paper: after the candidates, the masked zero-mean score
    /// is scanned at every whole disparity within this many pixels of the
    /// chosen `d_o` ([`scan_d_o`]; with [`PairingLimits::masked_d_o`]).
    /// The six candidates are where the blocks and the box edges put the
    /// fish; a view the frame border cuts has box edges and blocks that do
    /// not line up with the other view's, and the true disparity can lie
    /// between them. Default 16 (Table I's refinement range r; session 32:
    /// depth of tracked rows against the truth, seeds 1–30, fish cut by the
    /// left view's border |Δz|/z median 2.23 → 1.46 %, p90 7.17 → 5.07 %;
    /// inside both views p90 1.67 → 1.42 %; tracking success 591 → 598 of
    /// 899). 0: off.
    pub d_o_scan: u8,
}

impl Default for PairingLimits {
    fn default() -> Self {
        PairingLimits {
            min_range_mm: 500.0,
            max_range_mm: 20_000.0,
            disparity_slack: 8.0,
            min_row_overlap: 0.6,
            min_size_ratio: 0.5,
            max_sad_per_pixel: 40.0,
            zero_mean_d_o: true,
            masked_d_o: true,
            search_max_ratio: 0.7,
            search_max_runner_up: 0.85,
            d_o_scan: 16,
        }
    }
}

impl PairingLimits {
    /// Disparity interval `[d_min, d_max]` (slack included) allowed by `geom`.
    pub fn disparity_range(&self, geom: &StereoGeometry) -> (f32, f32) {
        let lo = geom.disparity_at_depth(self.max_range_mm) - self.disparity_slack;
        let hi = geom.disparity_at_depth(self.min_range_mm) + self.disparity_slack;
        (lo, hi)
    }
}

/// One stereo-corresponding object pair.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StereoPair {
    /// Index into the left [`Objects::items`].
    pub left: u16,
    /// Index into the right [`Objects::items`].
    pub right: u16,
    /// Coarse disparity `d_o`, pixels (`x_left − x_right`).
    pub d_o: f32,
    /// `μ_SAD`: mean of the 4 minimum block SADs, grey levels per pixel (eq. 15).
    pub mu_sad: f32,
    /// Disparity of each left block's best right block.
    pub block_disparity: [f32; BLOCKS],
    /// True when this pair shares its right object with another pair (occlusion).
    pub occluded: bool,
    /// True when the right object was found by the epipolar search
    /// ([`crate::epipolar`]) rather than segmented.
    pub searched: bool,
}

/// Counters of one pairing run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PairingStats {
    /// Left/right candidates evaluated by block SAD.
    pub candidates: u32,
    /// Candidates rejected by the plausibility gate after evaluation.
    pub rejected: u32,
    /// Absolute differences computed (the "SAD operations").
    pub sad_ops: u64,
    /// Left objects left unpaired.
    pub unpaired_left: u32,
    /// Pairs accepted through the occlusion exception.
    pub occlusions: u32,
    /// Pairs whose right object the epipolar search found ([`crate::epipolar`]).
    pub searched: u32,
}

/// The pairs of one frame.
#[derive(Debug, Clone, Default)]
pub struct StereoPairs<const N: usize> {
    /// The pairs, ordered by left index.
    pub pairs: heapless::Vec<StereoPair, N>,
    /// Counters.
    pub stats: PairingStats,
}

/// The 4 object-height blocks of an upright box (Fig. 7): full box height,
/// width `w/4` (the remainder spread so the blocks tile the box exactly).
pub fn object_height_blocks(bbox: Roi) -> [Roi; BLOCKS] {
    let mut out = [Roi::default(); BLOCKS];
    let w = bbox.w as u64;
    for (k, b) in out.iter_mut().enumerate() {
        let x0 = (k as u64 * w / BLOCKS as u64) as u32;
        let x1 = ((k as u64 + 1) * w / BLOCKS as u64) as u32;
        *b = Roi::new(bbox.x.saturating_add(x0), bbox.y, x1 - x0, bbox.h);
    }
    out
}

/// Absolute differences of dense block matching over a whole `width × height`
/// frame with `num_disparities` candidate disparities: every pixel's
/// difference at every disparity is computed at least once (box filtering
/// aggregates them), so this is a lower bound for dense SAD stereo.
pub const fn dense_sad_ops(width: u64, height: u64, num_disparities: u64) -> u64 {
    width * height * num_disparities
}

/// `(sum, compared pixels, pixels of the clipped area)` of [`sad_sum`].
type RawSad = (u64, u64, u64);

/// Raw SAD over left pixels `[x0, x1) × [y0, y1)` against the right image
/// shifted by `−d`: `(sum, compared pixels, pixels of the clipped area)`.
/// Columns whose right counterpart lies outside the right image are
/// skipped. Sums over column ranges that tile a range add up exactly, so
/// [`match_boxes`] builds whole-box SADs from its block SADs.
#[allow(clippy::too_many_arguments)]
fn sad_sum(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    d: i32,
) -> RawSad {
    let Some(c) = Compared::new(left, right, x0, x1, y0, y1, d) else {
        return (0, 0, 0);
    };
    let (mut sum, mut n) = (0u64, 0u64);
    for (a, b) in c.rows(left, right) {
        sum += row_sad(a, b) as u64;
        n += a.len() as u64;
    }
    (sum, n, c.total)
}

/// The pixels a SAD of left pixels `[x0, x1) × [y0, y1)` against the right
/// image shifted by `−d` compares: the left columns whose right
/// counterpart lies inside the right image, of the rows both views have.
struct Compared {
    left_cols: core::ops::Range<usize>,
    right_cols: core::ops::Range<usize>,
    rows: core::ops::Range<usize>,
    /// Pixels of the (clipped) box, compared or not.
    total: u64,
}

impl Compared {
    /// `None` for a box empty after clipping to the views.
    fn new(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        x0: u32,
        x1: u32,
        y0: u32,
        y1: u32,
        d: i32,
    ) -> Option<Compared> {
        let x1 = x1.min(left.width() as u32);
        let y1 = y1.min(left.height() as u32).min(right.height() as u32);
        if x1 <= x0 || y1 <= y0 {
            return None;
        }
        let lo = (x0 as i64).max(d as i64);
        let hi = (x1 as i64).min(right.width() as i64 + d as i64).max(lo);
        Some(Compared {
            left_cols: lo as usize..hi as usize,
            right_cols: (lo - d as i64) as usize..(hi - d as i64) as usize,
            rows: y0 as usize..y1 as usize,
            total: (x1 - x0) as u64 * (y1 - y0) as u64,
        })
    }

    /// The compared (left, right) row slices, top to bottom.
    fn rows<'a>(
        &self,
        left: &'a ImageView<'_>,
        right: &'a ImageView<'_>,
    ) -> impl Iterator<Item = (&'a [u8], &'a [u8])> + 'a {
        let (lc, rc) = (self.left_cols.clone(), self.right_cols.clone());
        self.rows.clone().filter_map(move |y| {
            Some((left.row(y).get(lc.clone())?, right.row(y).get(rc.clone())?))
        })
    }
}

/// Zero-mean SAD per pixel between left pixels `[x0, x1) × [y0, y1)` and
/// the right image shifted by `−d`, over the same pixels as [`sad_sum`]:
/// `Σ |(a − b) − (ā − b̄)| / n`, the two windows' means taken out (the
/// zero-mean SAD of stereo matching under unequal illumination). Integer
/// arithmetic: `Σ |n(a − b) − (Σa − Σb)|` over `n²`, exact for any box
/// up to 65535² (n < 2³², each term ≤ 2⁴¹, summed in `u128`). `None` when fewer than
/// half of the pixels could be compared. One pass over the pixels (a
/// histogram of the differences); also returns the differences computed.
pub fn zsad_per_pixel(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    d: i32,
) -> (Option<f32>, u64) {
    zsad_whole(left, right, x0, x1, y0, y1, d, u64::MAX)
}

/// Pixels of box `rb` inside the image `img` over rows `[y0, y1)`: what the
/// right view shows of an object in the rows both boxes share.
fn visible_pixels(rb: &Roi, img: &ImageView<'_>, y0: u32, y1: u32) -> u64 {
    let x1 = rb.right().min(img.width() as u32);
    let y1 = y1.min(img.height() as u32);
    if x1 <= rb.x || y1 <= y0 {
        return 0;
    }
    (x1 - rb.x) as u64 * (y1 - y0) as u64
}

/// [`zsad_per_pixel`] accepting the comparison when at least half of
/// `min(box pixels, need)` pixels could be compared. A coarse disparity
/// candidate is scored over the left box, but an object the left image's
/// left border cuts is seen by the right camera only up to its shifted
/// border: at the true shift `d` only the left columns ≥ `d` have a right
/// counterpart — the right box's part, possibly well under half of the
/// left box (session 25: seeds 1–10, border-cut fish with the right pair
/// had their depth more than 10 % off in 13 % of frames, 1.1–3× too far,
/// because the true shift was never scored). `need` is the right box's
/// pixels in the shared rows ([`visible_pixels`]).
#[allow(clippy::too_many_arguments)]
fn zsad_whole(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    d: i32,
    need: u64,
) -> (Option<f32>, u64) {
    let Some(mut c) = Compared::new(left, right, x0, x1, y0, y1, d) else {
        return (None, 0);
    };
    c.total = c.total.min(need);
    // one pass: the histogram of the differences a − b (511 bins, offset
    // 255); the sums and the zero-mean SAD follow from it exactly
    let mut hist = [0u32; 511];
    let mut n = 0u64;
    for (a, b) in c.rows(left, right) {
        for (&p, &q) in a.iter().zip(b) {
            if let Some(c) = hist.get_mut((p as usize + 255) - q as usize) {
                *c += 1;
            }
        }
        n += a.len() as u64;
    }
    if n == 0 || 2 * n < c.total {
        return (None, n);
    }
    let ni = n as i64;
    let m: i64 = hist.iter().zip(-255i64..).map(|(&c, v)| c as i64 * v).sum();
    // |n·v − m| ≤ 2⁴¹ and a count ≤ 2³²: each term and the sum fit u128
    let acc: u128 = hist
        .iter()
        .zip(-255i64..)
        .filter(|(&c, _)| c > 0)
        .map(|(&c, v)| c as u128 * (ni * v - m).unsigned_abs() as u128)
        .sum();
    let nf = n as f64;
    (Some((acc as f64 / (nf * nf)) as f32), n)
}

/// `Σ |a[i] − b[i]|` over the common length: 32-byte chunks summed in u16
/// lanes (at most 32 × 255 each, no overflow), which vectorises to packed
/// absolute differences, then the tail.
fn row_sad(a: &[u8], b: &[u8]) -> u32 {
    const C: usize = 32;
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut total: u32 = 0;
    let (ac, bc) = (a.chunks_exact(C), b.chunks_exact(C));
    let (at, bt) = (ac.remainder(), bc.remainder());
    for (ca, cb) in ac.zip(bc) {
        let mut lanes = [0u16; C];
        for ((l, &p), &q) in lanes.iter_mut().zip(ca).zip(cb) {
            *l = p.abs_diff(q) as u16;
        }
        total += lanes.iter().map(|&l| l as u32).sum::<u32>();
    }
    for (&p, &q) in at.iter().zip(bt) {
        total += p.abs_diff(q) as u32;
    }
    total
}

/// Per-pixel SAD from [`sad_sum`]'s figures; `None` when fewer than half of
/// the pixels could be compared.
fn per_pixel((sum, n, total): RawSad) -> Option<f32> {
    if n == 0 || 2 * n < total {
        return None;
    }
    Some(sum as f32 / n as f32)
}

/// SAD per pixel between left pixels `[x0, x1) × [y0, y1)` and the right
/// image shifted by `−d` (right column = left column − d). Pixels whose right
/// column falls outside the image are skipped; `None` when fewer than half of
/// the pixels could be compared.
#[allow(clippy::too_many_arguments)]
pub fn sad_per_pixel(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    d: i32,
    ops: &mut u64,
) -> Option<f32> {
    let r = sad_sum(left, right, x0, x1, y0, y1, d);
    *ops += r.1;
    per_pixel(r)
}

/// Result of matching one left box against one right box.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BlockMatch {
    /// `μ_SAD`, grey levels per pixel.
    pub mu_sad: f32,
    /// Disparity of each left block's best right block.
    pub block_disparity: [f32; BLOCKS],
    /// Coarse disparity `d_o`.
    pub d_o: f32,
}

fn touches_x(b: &Roi, width: u32) -> bool {
    b.x == 0 || b.right() >= width
}

fn touches_y(b: &Roi, height: u32) -> bool {
    b.y == 0 || b.bottom() >= height
}

fn ratio(a: u32, b: u32) -> f32 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    if hi == 0 {
        0.0
    } else {
        lo as f32 / hi as f32
    }
}

/// Geometric gate applied before any SAD is computed.
fn shapes_compatible(lb: &Roi, rb: &Roi, w: u32, h: u32, lim: &PairingLimits) -> bool {
    let y0 = lb.y.max(rb.y);
    let y1 = lb.bottom().min(rb.bottom());
    if y1 <= y0 {
        return false;
    }
    let overlap = (y1 - y0) as f32 / lb.h.min(rb.h).max(1) as f32;
    if overlap < lim.min_row_overlap {
        return false;
    }
    let cut_x = touches_x(lb, w) || touches_x(rb, w);
    let cut_y = touches_y(lb, h) || touches_y(rb, h);
    if !cut_x && ratio(lb.w, rb.w) < lim.min_size_ratio {
        return false;
    }
    if !cut_y && ratio(lb.h, rb.h) < lim.min_size_ratio {
        return false;
    }
    true
}

/// How [`match_boxes`] chooses the coarse disparity `d_o` among its
/// candidates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoarseCost {
    /// Least whole-box SAD (the blocks' own measure).
    Plain,
    /// Not chosen: `d_o` is the blocks' mean disparity, to be replaced by
    /// [`zero_mean_d_o`] (least zero-mean whole-box SAD,
    /// [`PairingLimits::zero_mean_d_o`]) once the pair is chosen: pairing
    /// itself needs only `μ_SAD`, so only the chosen pairs pay for the
    /// whole-box passes.
    Deferred,
}

/// Object-height block matching of one left box against one right box
/// (Section IV.A) over their shared rows; `None` when no block pair lies in
/// the allowed disparity interval `[d_lo, d_hi]`. `cost` says how `d_o`
/// is chosen among its candidates.
#[allow(clippy::too_many_arguments)]
pub fn match_boxes(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    lb: Roi,
    rb: Roi,
    d_lo: f32,
    d_hi: f32,
    cost: CoarseCost,
    ops: &mut u64,
) -> Option<BlockMatch> {
    let y0 = lb.y.max(rb.y);
    let y1 = lb.bottom().min(rb.bottom());
    if y1 <= y0 {
        return None;
    }
    let lblocks = object_height_blocks(lb);
    let rblocks = object_height_blocks(rb);
    let mut mins = [f32::INFINITY; BLOCKS];
    let mut disp = [0.0f32; BLOCKS];
    // raw block sums by (left block, right block), reused for the whole-box
    // SADs below (the blocks tile the box, so sums add up exactly)
    let mut memo: [[Option<(i32, RawSad)>; BLOCKS]; BLOCKS] = [[None; BLOCKS]; BLOCKS];
    for ((k, l), memo_k) in lblocks.iter().enumerate().zip(memo.iter_mut()) {
        if l.w == 0 {
            continue;
        }
        for (r, slot) in rblocks.iter().zip(memo_k.iter_mut()) {
            if r.w == 0 {
                continue;
            }
            let d = l.x as i32 - r.x as i32;
            if (d as f32) < d_lo || (d as f32) > d_hi {
                continue;
            }
            let raw = sad_sum(left, right, l.x, l.right(), y0, y1, d);
            *ops += raw.1;
            *slot = Some((d, raw));
            if let Some(s) = per_pixel(raw) {
                if let Some((m, dk)) = mins.get_mut(k).zip(disp.get_mut(k)) {
                    if s < *m {
                        *m = s;
                        *dk = d as f32;
                    }
                }
            }
        }
    }
    let mut n = 0;
    let mut sum = 0.0;
    for m in mins.iter().filter(|m| m.is_finite()) {
        sum += *m;
        n += 1;
    }
    if n == 0 {
        return None;
    }
    // blocks that found nothing inherit the mean disparity of the others
    let mut dsum = 0.0;
    for k in 0..BLOCKS {
        if mins[k].is_finite() {
            dsum += disp[k];
        }
    }
    let dmean = dsum / n as f32;
    for k in 0..BLOCKS {
        if !mins[k].is_finite() {
            disp[k] = dmean;
        }
    }
    // coarse disparity: the candidate with the least whole-box SAD
    let cands = d_o_candidates(&lb, &rb, &disp);
    // whole-box SAD at disparity `d`: the blocks' memoised sums, the
    // missing ones computed (each distinct `d` once)
    let mut whole = |d: i32| -> Option<f32> {
        let mut acc = (0u64, 0u64);
        for (l, memo_k) in lblocks.iter().zip(memo.iter()) {
            if l.w == 0 {
                continue;
            }
            let raw = match memo_k.iter().flatten().find(|(dm, _)| *dm == d) {
                Some((_, raw)) => *raw,
                None => {
                    let raw = sad_sum(left, right, l.x, l.right(), y0, y1, d);
                    *ops += raw.1;
                    raw
                }
            };
            acc = (acc.0 + raw.0, acc.1 + raw.1);
        }
        let x1 = lb.right().min(left.width() as u32);
        let y1c = y1.min(left.height() as u32).min(right.height() as u32);
        let total = if x1 <= lb.x || y1c <= y0 {
            0
        } else {
            (x1 - lb.x) as u64 * (y1c - y0) as u64
        };
        per_pixel((acc.0, acc.1, total.min(visible_pixels(&rb, right, y0, y1c))))
    };
    let d_o = match cost {
        CoarseCost::Plain => choose_d_o(&cands, d_lo, d_hi, dmean, &mut whole),
        CoarseCost::Deferred => dmean,
    };
    Some(BlockMatch {
        mu_sad: sum / n as f32,
        block_disparity: disp,
        d_o,
    })
}

/// The `d_o` candidates of a match (Section IV.A, beyond the paper's
/// single block disparity): the 4 block disparities and the two box-edge
/// alignments.
fn d_o_candidates(lb: &Roi, rb: &Roi, disp: &[f32; BLOCKS]) -> [f32; BLOCKS + 2] {
    [
        disp[0],
        disp[1],
        disp[2],
        disp[3],
        lb.x as f32 - rb.x as f32,
        lb.right() as f32 - rb.right() as f32,
    ]
}

/// The candidate in `[d_lo, d_hi]` with the least whole-box cost
/// `whole(d)` (each distinct shift evaluated once; the first on ties);
/// `fallback` when none has a cost.
fn choose_d_o(
    cands: &[f32; BLOCKS + 2],
    d_lo: f32,
    d_hi: f32,
    fallback: f32,
    whole: &mut dyn FnMut(i32) -> Option<f32>,
) -> f32 {
    let mut seen: [Option<(i32, Option<f32>)>; BLOCKS + 2] = [None; BLOCKS + 2];
    let mut best = (f32::INFINITY, fallback);
    for (&c, seen_slot) in cands.iter().zip(0..) {
        if c < d_lo || c > d_hi {
            continue;
        }
        let d = c as i32;
        let s = match seen.iter().flatten().find(|(sd, _)| *sd == d) {
            Some((_, s)) => *s,
            None => {
                let s = whole(d);
                if let Some(slot) = seen.get_mut(seen_slot) {
                    *slot = Some((d, s));
                }
                s
            }
        };
        if let Some(s) = s {
            if s < best.0 {
                best = (s, c);
            }
        }
    }
    best.1
}

/// The zero-mean `d_o` of a match whose `d_o` was deferred
/// ([`CoarseCost::Deferred`]): the candidate with the least
/// [`zsad_per_pixel`] over the left box and the rows it shares with the
/// right box, chosen as [`CoarseCost::Plain`] chooses by the plain SAD.
#[allow(clippy::too_many_arguments)]
pub fn zero_mean_d_o(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    lb: Roi,
    rb: Roi,
    m: &BlockMatch,
    d_lo: f32,
    d_hi: f32,
    ops: &mut u64,
) -> f32 {
    let (y0, y1) = (lb.y.max(rb.y), lb.bottom().min(rb.bottom()));
    let cands = d_o_candidates(&lb, &rb, &m.block_disparity);
    let need = visible_pixels(&rb, right, y0, y1);
    choose_d_o(&cands, d_lo, d_hi, m.d_o, &mut |d| {
        let (s, n) = zsad_whole(left, right, lb.x, lb.right(), y0, y1, d, need);
        *ops += n;
        s
    })
}

/// The zero-mean `d_o` scored on the left object's own pixels: its mask
/// runs widened by `max(4, h_o/4)` (the fish's outline and a little water,
/// the epipolar search's template, [`crate::epipolar`]) instead of its
/// upright box, which for a fish lying diagonally is mostly water. A
/// candidate is scored when at least half of `min(template pixels, right
/// object's area)` pixels are compared (an object the left image's left
/// border cuts shows the right camera only its part, see [`zsad_whole`]).
/// [`pair_objects`] scores an object without mask runs (its runs did not
/// fit the run pool) on its box instead ([`zero_mean_d_o`]).
#[allow(clippy::too_many_arguments)]
pub fn masked_d_o(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[crate::object::Run],
    lo: &crate::object::Object,
    ro: &crate::object::Object,
    m: &BlockMatch,
    d_lo: f32,
    d_hi: f32,
    ops: &mut u64,
) -> f32 {
    let cands = d_o_candidates(&lo.bbox, &ro.bbox, &m.block_disparity);
    choose_d_o(&cands, d_lo, d_hi, m.d_o, &mut |d| {
        masked_score(left, right, runs, lo, ro, d, ops)
    })
}

/// The score [`masked_d_o`] and [`scan_d_o`] give shift `d`: zero-mean SAD
/// per pixel over the left mask widened by `max(4, h_o/4)` columns, when
/// at least half of `min(template, right object's area)` is compared.
fn masked_score(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[crate::object::Run],
    lo: &crate::object::Object,
    ro: &crate::object::Object,
    d: i32,
    ops: &mut u64,
) -> Option<f32> {
    let margin = ((lo.obb.half_h * 0.5) as u32).max(4);
    crate::epipolar::template_cost(
        left,
        right,
        runs,
        margin,
        d,
        (1, 1),
        (0.5, ro.area as u64),
        ops,
    )
}

/// The whole disparity within `radius` of `d0` (truncated) and inside
/// `[d_lo, d_hi]` with the least masked zero-mean score of [`masked_d_o`]
/// (the lowest on ties); `d0` when none is scored
/// ([`PairingLimits::d_o_scan`], beyond the paper). `2·radius + 1`
/// template evaluations, added to `ops`.
#[allow(clippy::too_many_arguments)]
pub fn scan_d_o(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[crate::object::Run],
    lo: &crate::object::Object,
    ro: &crate::object::Object,
    d0: f32,
    radius: u8,
    (d_lo, d_hi): (f32, f32),
    ops: &mut u64,
) -> f32 {
    if !d0.is_finite() {
        return d0;
    }
    let c = d0 as i32;
    let r = radius as i32;
    let mut best: Option<(f32, i32)> = None;
    for d in c.saturating_sub(r)..=c.saturating_add(r) {
        if (d as f32) < d_lo || (d as f32) > d_hi {
            continue;
        }
        if let Some(cost) = masked_score(left, right, runs, lo, ro, d, ops) {
            if best.is_none_or(|(b, _)| cost < b) {
                best = Some((cost, d));
            }
        }
    }
    best.map_or(d0, |(_, d)| d as f32)
}

/// Fraction of `a` covered by `b`.
fn covered(a: &Roi, b: &Roi) -> f32 {
    let i = a.intersect(b).area();
    if a.area() == 0 {
        0.0
    } else {
        i as f32 / a.area() as f32
    }
}

/// `b` shifted left by `d` pixels (clamped at 0).
fn shifted(b: &Roi, d: f32) -> Roi {
    let x = b.x as f32 - d;
    let x = if x > 0.0 { x as u32 } else { 0 };
    Roi::new(x, b.y, b.w, b.h)
}

/// Pairs left objects with right objects (Section IV.A), one-to-one with
/// the occlusion exception described in the module documentation.
///
/// Errors when the two frames differ in size.
pub fn pair_objects<const N: usize, const R: usize>(
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: &Objects<N, R>,
    right: &Objects<N, R>,
    geom: &StereoGeometry,
    limits: &PairingLimits,
) -> Result<StereoPairs<N>, ImageError> {
    if left_img.width() != right_img.width() || left_img.height() != right_img.height() {
        return Err(ImageError::SizeMismatch);
    }
    let (w, h) = (left_img.width() as u32, left_img.height() as u32);
    let (d_lo, d_hi) = limits.disparity_range(geom);
    let nl = left.items.len().min(N);
    let nr = right.items.len().min(N);
    let mut out = StereoPairs::<N>::default();
    let mut cost = [[NO_PAIR; N]; N];
    let mut kept: heapless::Vec<(u16, u16, BlockMatch), KEPT_MATCHES> = heapless::Vec::new();
    let scan_cost = if limits.zero_mean_d_o {
        CoarseCost::Deferred
    } else {
        CoarseCost::Plain
    };
    for (i, lo) in left.items.iter().enumerate().take(nl) {
        for (j, ro) in right.items.iter().enumerate().take(nr) {
            let (lb, rb) = (lo.bbox, ro.bbox);
            if lb.is_empty() || rb.is_empty() || !shapes_compatible(&lb, &rb, w, h, limits) {
                continue;
            }
            // every block pair's disparity lies in [lb.x − rb.right(), lb.right() − rb.x]
            let dmax_possible = lb.right() as f32 - rb.x as f32;
            let dmin_possible = lb.x as f32 - rb.right() as f32;
            if dmax_possible < d_lo || dmin_possible > d_hi {
                continue;
            }
            out.stats.candidates += 1;
            let m = match_boxes(
                left_img,
                right_img,
                lb,
                rb,
                d_lo,
                d_hi,
                scan_cost,
                &mut out.stats.sad_ops,
            );
            match m {
                Some(m) if m.mu_sad <= limits.max_sad_per_pixel => {
                    if let Some(c) = cost.get_mut(i).and_then(|row| row.get_mut(j)) {
                        *c = m.mu_sad;
                    }
                    // kept while there is room; the rest are recomputed
                    let _ = kept.push((i as u16, j as u16, m));
                }
                _ => out.stats.rejected += 1,
            }
        }
    }
    // the chosen matches come from `kept`, or are recomputed when it was
    // full (N² of them would not fit; `match_boxes` is deterministic)
    // the zero-mean d_o passes of the chosen pairs, for `stats.sad_ops`
    let d_o_ops = core::cell::Cell::new(0u64);
    let rematch = |i: usize, j: usize| -> Option<BlockMatch> {
        let plausible = cost
            .get(i)
            .and_then(|r| r.get(j))
            .is_some_and(|c| *c < NO_PAIR);
        let (lo, ro) = (left.items.get(i)?, right.items.get(j)?);
        let mut scratch = 0u64;
        if !plausible {
            return None;
        }
        let m = match kept
            .iter()
            .find(|(ki, kj, _)| *ki as usize == i && *kj as usize == j)
        {
            Some((_, _, m)) => Some(*m),
            None => match_boxes(
                left_img,
                right_img,
                lo.bbox,
                ro.bbox,
                d_lo,
                d_hi,
                scan_cost,
                &mut scratch,
            ),
        };
        m.map(|mut m| {
            if scan_cost == CoarseCost::Deferred {
                let mut ops = 0u64;
                // an object whose mask runs did not fit the run pool has
                // only its box to be scored on
                let has_mask = left.runs_of(lo).iter().any(|r| !r.is_empty());
                m.d_o = if limits.masked_d_o && has_mask {
                    masked_d_o(
                        left_img,
                        right_img,
                        left.runs_of(lo),
                        lo,
                        ro,
                        &m,
                        d_lo,
                        d_hi,
                        &mut ops,
                    )
                } else {
                    zero_mean_d_o(
                        left_img, right_img, lo.bbox, ro.bbox, &m, d_lo, d_hi, &mut ops,
                    )
                };
                if limits.masked_d_o && has_mask && limits.d_o_scan > 0 {
                    m.d_o = scan_d_o(
                        left_img,
                        right_img,
                        left.runs_of(lo),
                        lo,
                        ro,
                        m.d_o,
                        limits.d_o_scan,
                        (d_lo, d_hi),
                        &mut ops,
                    );
                }
                d_o_ops.set(d_o_ops.get().saturating_add(ops));
            }
            m
        })
    };
    let n = nl.max(nr);
    let mut col4row = [usize::MAX; N];
    solve_assignment(&cost, n, &mut col4row);
    let mut taken_by = [usize::MAX; N];
    for i in 0..nl {
        let j = col4row.get(i).copied().unwrap_or(usize::MAX);
        let m = rematch(i, j);
        if let (Some(m), Some(t)) = (m, taken_by.get_mut(j)) {
            *t = i;
            let _ = out.pairs.push(StereoPair {
                left: i as u16,
                right: j as u16,
                d_o: m.d_o,
                mu_sad: m.mu_sad,
                block_disparity: m.block_disparity,
                occluded: false,
                searched: false,
            });
        }
    }
    // occlusion exception for left objects the assignment left out
    for i in 0..nl {
        if out.pairs.iter().any(|p| p.left as usize == i) {
            continue;
        }
        let Some(row) = cost.get(i) else { continue };
        let mut best: Option<(usize, f32)> = None;
        for (j, c) in row.iter().enumerate().take(nr) {
            if *c < NO_PAIR && best.map(|(_, b)| *c < b).unwrap_or(true) {
                best = Some((j, *c));
            }
        }
        let Some((j, m)) = best.and_then(|(j, _)| Some((j, rematch(i, j)?))) else {
            out.stats.unpaired_left += 1;
            continue;
        };
        let other = taken_by.get(j).copied().unwrap_or(usize::MAX);
        let (Some(lo), Some(ro)) = (left.items.get(i), right.items.get(j)) else {
            continue;
        };
        let other_pair = out.pairs.iter().find(|p| p.left as usize == other).copied();
        let ok = match (other_pair, left.items.get(other)) {
            (Some(op), Some(oo)) => {
                covered(&shifted(&lo.bbox, m.d_o), &ro.bbox) >= 0.9
                    && covered(&shifted(&oo.bbox, op.d_o), &ro.bbox) >= 0.9
            }
            _ => false,
        };
        if ok {
            out.stats.occlusions += 1;
            let _ = out.pairs.push(StereoPair {
                left: i as u16,
                right: j as u16,
                d_o: m.d_o,
                mu_sad: m.mu_sad,
                block_disparity: m.block_disparity,
                occluded: true,
                searched: false,
            });
        } else {
            out.stats.unpaired_left += 1;
        }
    }
    out.stats.sad_ops = out.stats.sad_ops.saturating_add(d_o_ops.get());
    out.pairs.sort_unstable_by_key(|p| p.left);
    Ok(out)
}

/// Minimum-cost assignment of the leading `n × n` part of `cost` (rows to
/// columns), by shortest augmenting paths with dual potentials (the
/// Jonker–Volgenant / Crouse formulation used by SciPy's
/// `linear_sum_assignment`). Writes `col4row`. Work: `O(n³)`.
///
/// Every index below is `< n ≤ N` by construction (rows and columns come
/// from `0..n` or from the arrays this function fills), so indexing cannot
/// fail whatever the costs are.
#[allow(clippy::needless_range_loop)]
pub fn solve_assignment<const N: usize>(cost: &[[f32; N]; N], n: usize, col4row: &mut [usize; N]) {
    let n = n.min(N);
    let mut u = [0.0f64; N];
    let mut v = [0.0f64; N];
    let mut row4col = [usize::MAX; N];
    let mut path = [usize::MAX; N];
    let mut spc = [f64::INFINITY; N];
    let mut sr = [false; N];
    let mut sc = [false; N];
    let mut remaining = [0usize; N];
    col4row.iter_mut().for_each(|c| *c = usize::MAX);
    let c = |i: usize, j: usize| -> f64 {
        cost.get(i)
            .and_then(|r| r.get(j))
            .copied()
            .unwrap_or(NO_PAIR) as f64
    };
    for cur in 0..n {
        // --- shortest augmenting path from row `cur`
        let mut min_val = 0.0f64;
        let mut num_remaining = n;
        for (it, r) in remaining.iter_mut().enumerate().take(n) {
            *r = n - it - 1;
        }
        sr.iter_mut().for_each(|s| *s = false);
        sc.iter_mut().for_each(|s| *s = false);
        spc.iter_mut().for_each(|s| *s = f64::INFINITY);
        let mut i = cur;
        let mut sink = usize::MAX;
        let mut guard = 0;
        while sink == usize::MAX && guard <= n {
            guard += 1;
            let mut index = usize::MAX;
            let mut lowest = f64::INFINITY;
            sr[i] = true;
            for it in 0..num_remaining {
                let j = remaining[it];
                let r = min_val + c(i, j) - u[i] - v[j];
                if r < spc[j] {
                    path[j] = i;
                    spc[j] = r;
                }
                let sj = spc[j];
                if sj < lowest || (sj == lowest && row4col[j] == usize::MAX) {
                    lowest = sj;
                    index = it;
                }
            }
            if index == usize::MAX || !lowest.is_finite() {
                return;
            }
            min_val = lowest;
            let j = remaining[index];
            if row4col[j] == usize::MAX {
                sink = j;
            } else {
                i = row4col[j];
            }
            sc[j] = true;
            num_remaining -= 1;
            remaining[index] = remaining[num_remaining];
        }
        if sink == usize::MAX {
            return;
        }
        // --- update the dual variables
        u[cur] += min_val;
        for r in 0..n {
            if sr[r] && r != cur {
                u[r] += min_val - spc[col4row[r]];
            }
        }
        for j in 0..n {
            if sc[j] {
                v[j] -= min_val - spc[j];
            }
        }
        // --- augment along the path
        let mut j = sink;
        for _ in 0..=n {
            let Some(&i) = path.get(j) else { break };
            if let Some(r) = row4col.get_mut(j) {
                *r = i;
            }
            let Some(slot) = col4row.get_mut(i) else {
                break;
            };
            core::mem::swap(slot, &mut j);
            if i == cur {
                break;
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// The differences `a − b` of the pixels a SAD compares, written
    /// plainly; `None` when fewer than half of the box's pixels (at most
    /// `need` of them) have a right counterpart.
    #[allow(clippy::too_many_arguments)]
    fn naive_diffs(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        x0: u32,
        x1: u32,
        y0: u32,
        y1: u32,
        d: i32,
        need: usize,
    ) -> Option<Vec<i32>> {
        let w = right.width() as i64;
        let x1 = x1.min(left.width() as u32);
        let y1 = y1.min(left.height() as u32).min(right.height() as u32);
        let (mut diffs, mut total) = (Vec::new(), 0usize);
        for y in y0..y1 {
            for x in x0..x1 {
                total += 1;
                let rx = x as i64 - d as i64;
                if rx >= 0 && rx < w {
                    let a = left.row(y as usize)[x as usize] as i32;
                    diffs.push(a - right.row(y as usize)[rx as usize] as i32);
                }
            }
        }
        (!diffs.is_empty() && 2 * diffs.len() >= total.min(need)).then_some(diffs)
    }

    /// The straightforward per-pixel SAD (the pre-session-6 code).
    #[allow(clippy::too_many_arguments)]
    fn naive_sad(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        x0: u32,
        x1: u32,
        y0: u32,
        y1: u32,
        d: i32,
        need: usize,
    ) -> Option<f32> {
        let diffs = naive_diffs(left, right, x0, x1, y0, y1, d, need)?;
        let sum: u64 = diffs.iter().map(|v| v.unsigned_abs() as u64).sum();
        Some(sum as f32 / diffs.len() as f32)
    }

    /// The zero-mean SAD written plainly: Σ|(a − b) − mean| as
    /// Σ|n(a − b) − Σ(a − b)| / n², exactly (i128), so near-ties between
    /// candidates round as in the core.
    #[allow(clippy::too_many_arguments)]
    fn naive_zsad(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        x0: u32,
        x1: u32,
        y0: u32,
        y1: u32,
        d: i32,
        need: usize,
    ) -> Option<f32> {
        let diffs = naive_diffs(left, right, x0, x1, y0, y1, d, need)?;
        let n = diffs.len() as i128;
        let m: i128 = diffs.iter().map(|&v| v as i128).sum();
        let acc: i128 = diffs.iter().map(|&v| (n * v as i128 - m).abs()).sum();
        Some((acc as f64 / (n as f64 * n as f64)) as f32)
    }

    /// [`match_boxes`] written plainly: every block pair and every
    /// whole-box candidate computed from scratch.
    fn naive_match(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        lb: Roi,
        rb: Roi,
        d_lo: f32,
        d_hi: f32,
        zero_mean: bool,
    ) -> Option<BlockMatch> {
        let y0 = lb.y.max(rb.y);
        let y1 = lb.bottom().min(rb.bottom());
        if y1 <= y0 {
            return None;
        }
        let (lbl, rbl) = (object_height_blocks(lb), object_height_blocks(rb));
        let mut mins = [f32::INFINITY; BLOCKS];
        let mut disp = [0.0f32; BLOCKS];
        for k in 0..BLOCKS {
            let l = lbl[k];
            for r in rbl.iter() {
                let d = l.x as i32 - r.x as i32;
                if l.w == 0 || r.w == 0 || (d as f32) < d_lo || (d as f32) > d_hi {
                    continue;
                }
                if let Some(s) = naive_sad(left, right, l.x, l.right(), y0, y1, d, usize::MAX) {
                    if s < mins[k] {
                        mins[k] = s;
                        disp[k] = d as f32;
                    }
                }
            }
        }
        let found: Vec<usize> = (0..BLOCKS).filter(|&k| mins[k].is_finite()).collect();
        if found.is_empty() {
            return None;
        }
        let sum: f32 = found.iter().map(|&k| mins[k]).sum();
        let dmean = found.iter().map(|&k| disp[k]).sum::<f32>() / found.len() as f32;
        for k in 0..BLOCKS {
            if !mins[k].is_finite() {
                disp[k] = dmean;
            }
        }
        let cands = [
            disp[0],
            disp[1],
            disp[2],
            disp[3],
            lb.x as f32 - rb.x as f32,
            lb.right() as f32 - rb.right() as f32,
        ];
        // the right box's pixels in the shared rows, counted one by one
        let need = (y0..y1.min(right.height() as u32))
            .flat_map(|_| rb.x..rb.right())
            .filter(|&x| (x as usize) < right.width())
            .count();
        let mut best = (f32::INFINITY, dmean);
        for c in cands {
            if c < d_lo || c > d_hi {
                continue;
            }
            let whole = if zero_mean { naive_zsad } else { naive_sad };
            if let Some(s) = whole(left, right, lb.x, lb.right(), y0, y1, c as i32, need) {
                if s < best.0 {
                    best = (s, c);
                }
            }
        }
        Some(BlockMatch {
            mu_sad: sum / found.len() as f32,
            block_disparity: disp,
            d_o: best.1,
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn row_sad_is_the_plain_sum(a in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200), seed in proptest::prelude::any::<u64>()) {
            let b: Vec<u8> = a.iter().enumerate().map(|(i, &v)| v ^ ((seed >> (i % 57)) as u8)).collect();
            let want: u32 = a.iter().zip(&b).map(|(p, q)| p.abs_diff(*q) as u32).sum();
            proptest::prop_assert_eq!(row_sad(&a, &b), want);
            proptest::prop_assert_eq!(row_sad(&a, &b[..b.len() / 2]), a.iter().zip(&b[..b.len() / 2]).map(|(p, q)| p.abs_diff(*q) as u32).sum::<u32>());
        }

        #[test]
        fn match_boxes_equals_the_plain_version(
            w in 8usize..90, h in 4usize..30, seed in proptest::prelude::any::<u64>(),
            lx in 0u32..100, lw in 1u32..60, rx in 0u32..100, rw in 1u32..60,
            ly in 0u32..30, lh in 1u32..30, ry in 0u32..30, rh in 1u32..30,
            d_lo in -40.0f32..20.0, span in 0.0f32..80.0, smooth in proptest::prelude::any::<bool>(),
            zero_mean in proptest::prelude::any::<bool>(),
        ) {
            let mut s = seed;
            let mut next = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 56) as u8 };
            let img: Vec<u8> = (0..w * h).map(|i| if smooth { (i % w) as u8 / 4 + next() % 8 } else { next() }).collect();
            let img2: Vec<u8> = (0..w * h).map(|i| if smooth { (i % w) as u8 / 3 + next() % 8 } else { next() }).collect();
            let (lv, rv) = (ImageView::packed(&img, w, h).unwrap(), ImageView::packed(&img2, w, h).unwrap());
            let (lb, rb) = (Roi::new(lx, ly, lw, lh), Roi::new(rx, ry, rw, rh));
            let mut ops = 0u64;
            let got = if zero_mean {
                // deferred, then chosen, as `pair_objects` does
                match_boxes(&lv, &rv, lb, rb, d_lo, d_lo + span, CoarseCost::Deferred, &mut ops)
                    .map(|mut m| { m.d_o = zero_mean_d_o(&lv, &rv, lb, rb, &m, d_lo, d_lo + span, &mut ops); m })
            } else {
                match_boxes(&lv, &rv, lb, rb, d_lo, d_lo + span, CoarseCost::Plain, &mut ops)
            };
            let want = naive_match(&lv, &rv, lb, rb, d_lo, d_lo + span, zero_mean);
            proptest::prop_assert_eq!(got, want);
        }
    }

    /// The failure the zero-mean `d_o` mends (h5 frame 14 of the synthetic
    /// hauls: a fish entering at the right border, its depth 32 % short):
    /// the left view shows only the fish's head, cut by the border, on dark
    /// water; the right camera sees the water 40 grey levels brighter and
    /// the whole head. Only the box-edge candidate on the uncut side is the
    /// true disparity, and by the plain SAD the head matches the right
    /// view's bright water better than the head itself.
    #[test]
    fn zero_mean_d_o_of_a_border_cut_fish_on_unequal_water() {
        let (w, h) = (200usize, 40usize);
        let true_d = 60i32;
        // the fish: x in [120, 230) in the left view (cut at 200), rows 10..30
        let fish = |x: i64, y: usize| (100..=230).contains(&x) && (10..30).contains(&y);
        let body = |x: i64| 70 + ((x * 7) % 11) as u8; // a little texture
        let left: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, i / w);
                if fish(x, y) && x >= 120 {
                    body(x)
                } else {
                    30
                }
            })
            .collect();
        let right: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, i / w);
                let lx = x + true_d as i64;
                if fish(lx, y) && lx >= 120 {
                    body(lx) + 40
                } else {
                    70
                }
            })
            .collect();
        let (lv, rv) = (
            ImageView::packed(&left, w, h).unwrap(),
            ImageView::packed(&right, w, h).unwrap(),
        );
        let lb = Roi::new(120, 10, 80, 20); // cut by the right border
        let rb = Roi::new(60, 10, 140, 20); // the whole visible fish
        let mut ops = 0u64;
        let plain = match_boxes(&lv, &rv, lb, rb, 0.0, 150.0, CoarseCost::Plain, &mut ops).unwrap();
        let mut zm =
            match_boxes(&lv, &rv, lb, rb, 0.0, 150.0, CoarseCost::Deferred, &mut ops).unwrap();
        zm.d_o = zero_mean_d_o(&lv, &rv, lb, rb, &zm, 0.0, 150.0, &mut ops);
        assert_eq!(zm.d_o, true_d as f32, "zero-mean d_o {zm:?}");
        assert_ne!(
            plain.d_o, true_d as f32,
            "the plain SAD was expected to fail here: {plain:?}"
        );
    }

    /// A fish the left image's *left* border cuts (session 25): the right
    /// camera sees it shifted left by its disparity, so it shows only the
    /// fish's last `w − d` columns, under half of the left box. The true
    /// shift (the box-edge candidate on the uncut right side) compares just
    /// those columns and must still be scored, or a wrong candidate that
    /// compares more columns wins (on the synthetic hauls: depths 1.1–3×
    /// too far for 13 % of such fish-frames).
    #[test]
    fn d_o_of_a_fish_cut_by_the_left_border() {
        let (w, h) = (300usize, 40usize);
        let true_d = 150i32;
        // the fish spans x in [−60, 200) of the left view, rows 10..30
        let fish = |x: i64, y: usize| (-60..200).contains(&x) && (10..30).contains(&y);
        let body =
            |x: i64| 90 + ((x * 7).rem_euclid(23)) as u8 + ((x / 9).rem_euclid(3) * 20) as u8;
        let water = |x: i64, y: usize| 30 + ((x * 3 + y as i64 * 5).rem_euclid(7)) as u8;
        let left: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, i / w);
                if fish(x, y) {
                    body(x)
                } else {
                    water(x, y)
                }
            })
            .collect();
        let right: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, i / w);
                let lx = x + true_d as i64;
                if fish(lx, y) {
                    body(lx)
                } else {
                    water(lx, y)
                }
            })
            .collect();
        let (lv, rv) = (
            ImageView::packed(&left, w, h).unwrap(),
            ImageView::packed(&right, w, h).unwrap(),
        );
        let lb = Roi::new(0, 10, 200, 20); // cut by the left border
        let rb = Roi::new(0, 10, 50, 20); // the fish's last 50 columns
        let mut ops = 0u64;
        let deferred = match_boxes(
            &lv,
            &rv,
            lb,
            rb,
            10.0,
            250.0,
            CoarseCost::Deferred,
            &mut ops,
        )
        .unwrap();
        let plain =
            match_boxes(&lv, &rv, lb, rb, 10.0, 250.0, CoarseCost::Plain, &mut ops).unwrap();
        let zero_mean = zero_mean_d_o(&lv, &rv, lb, rb, &deferred, 10.0, 250.0, &mut ops);
        assert_eq!(plain.d_o, true_d as f32, "plain SAD: {plain:?}");
        assert_eq!(zero_mean, true_d as f32, "zero-mean SAD");
        // the old rule (half of the left box) would have refused it
        assert!(naive_zsad(&lv, &rv, lb.x, lb.right(), 10, 30, true_d, usize::MAX).is_none());
        // scored on the masks as well: the left mask is the whole visible
        // fish, the right one its last 50 columns
        let runs: Vec<crate::object::Run> = (10..30)
            .map(|y| crate::object::Run { y, x0: 0, x1: 200 })
            .collect();
        let (lo, ro) = (object_of(lb, 20.0, 200 * 20), object_of(rb, 20.0, 50 * 20));
        let d = masked_d_o(&lv, &rv, &runs, &lo, &ro, &deferred, 10.0, 250.0, &mut ops);
        assert_eq!(d, true_d as f32);
        let plain_version = naive_masked_d_o(&lv, &rv, &runs, &lo, &ro, &deferred, 10.0, 250.0);
        assert_eq!(plain_version, d);
        // the scan around a candidate that missed (blocks and box edges
        // 9 px off): it finds the fish's shift within its radius
        let scan = |d0: f32, r: u8, ops: &mut u64| {
            scan_d_o(&lv, &rv, &runs, &lo, &ro, d0, r, (10.0, 250.0), ops)
        };
        let before = ops;
        assert_eq!(scan(true_d as f32 - 9.0, 16, &mut ops), true_d as f32);
        assert_eq!(scan(true_d as f32 + 9.5, 16, &mut ops), true_d as f32);
        assert!(ops > before, "the scan's differences are counted");
        // out of reach: the best shift within ±3 of 141, never beyond
        let near = scan(true_d as f32 - 9.0, 3, &mut ops);
        assert!((138.0..=144.0).contains(&near), "{near}");
        // radius 0 is the start itself (when scored), the range clips
        assert_eq!(scan(140.0, 0, &mut ops), 140.0);
        assert_eq!(
            scan_d_o(
                &lv,
                &rv,
                &runs,
                &lo,
                &ro,
                140.0,
                16,
                (141.0, 146.0),
                &mut ops
            ),
            146.0
        );
        assert!(scan(f32::NAN, 16, &mut ops).is_nan());
    }

    /// An object with box `b`, oriented-box height `h_o` and mask area `area`.
    fn object_of(b: Roi, h_o: f32, area: u32) -> crate::object::Object {
        crate::object::Object {
            bbox: b,
            obb: crate::object::OrientedBox {
                half_h: h_o / 2.0,
                ..Default::default()
            },
            area,
            ..Default::default()
        }
    }

    /// The masked zero-mean score of shift `d`, pixel by pixel (as
    /// [`naive_masked_d_o`] scores each candidate).
    fn naive_template_cost(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        runs: &[crate::object::Run],
        lo: &crate::object::Object,
        ro: &crate::object::Object,
        d: i32,
    ) -> Option<f32> {
        let w = left.width() as i64;
        let margin = ((lo.obb.half_h * 0.5) as i64).max(4);
        let mut px = std::collections::BTreeSet::new();
        for r in runs.iter().filter(|r| r.x1 > r.x0) {
            for x in (r.x0 as i64 - margin).max(0)..(r.x1 as i64 + margin).min(w) {
                px.insert((r.y as usize, x));
            }
        }
        let d = d as i64;
        let diffs: Vec<i32> = px
            .iter()
            .filter(|&&(_, x)| x - d >= 0 && x - d < w)
            .map(|&(y, x)| left.row(y)[x as usize] as i32 - right.row(y)[(x - d) as usize] as i32)
            .collect();
        if diffs.is_empty() || 2 * diffs.len() < px.len().min(ro.area as usize) {
            return None;
        }
        let n = diffs.len() as i128;
        let sum: i128 = diffs.iter().map(|&v| v as i128).sum();
        let acc: i128 = diffs.iter().map(|&v| (n * v as i128 - sum).abs()).sum();
        Some((acc as f64 / (n as f64 * n as f64)) as f32)
    }

    /// [`masked_d_o`] written plainly: the template as a set of pixels
    /// within `max(4, h_o/4)` columns of a mask pixel on its row, each
    /// candidate scored from scratch.
    #[allow(clippy::too_many_arguments)]
    fn naive_masked_d_o(
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        runs: &[crate::object::Run],
        lo: &crate::object::Object,
        ro: &crate::object::Object,
        m: &BlockMatch,
        d_lo: f32,
        d_hi: f32,
    ) -> f32 {
        let cands = d_o_candidates(&lo.bbox, &ro.bbox, &m.block_disparity);
        let mut best = (f32::INFINITY, m.d_o);
        for c in cands {
            if c < d_lo || c > d_hi {
                continue;
            }
            let Some(score) = naive_template_cost(left, right, runs, lo, ro, c as i32) else {
                continue;
            };
            if score < best.0 {
                best = (score, c);
            }
        }
        best.1
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn masked_d_o_equals_the_plain_version(
            w in 8usize..90, h in 4usize..30, seed in proptest::prelude::any::<u64>(),
            lx in 0u32..100, lw in 1u32..60, rx in 0u32..100, rw in 1u32..60,
            ly in 0u32..30, lh in 1u32..30, h_o in 1.0f32..40.0, area in 1u32..2000,
            d_lo in -40.0f32..20.0, span in 0.0f32..80.0,
            spans in proptest::collection::vec((0u16..100, 0u16..40), 0..30),
        ) {
            let mut s = seed;
            let mut next = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 56) as u8 };
            let img: Vec<u8> = (0..w * h).map(|_| next()).collect();
            let img2: Vec<u8> = (0..w * h).map(|_| next()).collect();
            let (lv, rv) = (ImageView::packed(&img, w, h).unwrap(), ImageView::packed(&img2, w, h).unwrap());
            let (lb, rb) = (Roi::new(lx, ly, lw, lh), Roi::new(rx, ly, rw, lh));
            // one run per row (as segmentation writes them, sorted)
            let runs: Vec<crate::object::Run> = spans
                .iter()
                .enumerate()
                .map(|(k, &(x0, len))| crate::object::Run { y: (k % h) as u16, x0, x1: x0 + len })
                .filter(|r| (r.y as usize) < h)
                .take(h)
                .collect();
            let mut runs = runs;
            runs.sort_by_key(|r| (r.y, r.x0));
            runs.dedup_by_key(|r| r.y);
            let (lo, ro) = (object_of(lb, h_o, area), object_of(rb, h_o, area));
            let mut ops = 0u64;
            if let Some(m) = match_boxes(&lv, &rv, lb, rb, d_lo, d_lo + span, CoarseCost::Deferred, &mut ops) {
                let got = masked_d_o(&lv, &rv, &runs, &lo, &ro, &m, d_lo, d_lo + span, &mut ops);
                let want = naive_masked_d_o(&lv, &rv, &runs, &lo, &ro, &m, d_lo, d_lo + span);
                proptest::prop_assert_eq!(got, want);
                // the scan: the first least-cost whole shift of the range,
                // every shift scored as the plain version scores one
                let r = (seed % 7) as u8;
                let scanned = scan_d_o(&lv, &rv, &runs, &lo, &ro, got, r, (d_lo, d_lo + span), &mut ops);
                let c = got as i32;
                let mut best: Option<(f32, i32)> = None;
                for d in (c - r as i32)..=(c + r as i32) {
                    if (d as f32) < d_lo || (d as f32) > d_lo + span {
                        continue;
                    }
                    if let Some(cst) = naive_template_cost(&lv, &rv, &runs, &lo, &ro, d) {
                        if best.is_none_or(|(b, _)| cst < b) {
                            best = Some((cst, d));
                        }
                    }
                }
                proptest::prop_assert_eq!(scanned, best.map_or(got, |(_, d)| d as f32));
            }
        }
    }

    #[test]
    fn blocks_tile_the_box() {
        let b = Roi::new(10, 20, 103, 30);
        let bl = object_height_blocks(b);
        assert_eq!(bl[0].x, 10);
        assert_eq!(bl[3].right(), 113);
        for k in 0..3 {
            assert_eq!(bl[k].right(), bl[k + 1].x);
            assert_eq!(bl[k].h, 30);
        }
        let total: u32 = bl.iter().map(|r| r.w).sum();
        assert_eq!(total, 103);
    }

    #[test]
    fn assignment_is_optimal_on_small_matrices() {
        // brute force over permutations of 4
        let mut seed = 12345u32;
        for _ in 0..200 {
            let mut cost = [[0.0f32; 4]; 4];
            for r in cost.iter_mut() {
                for c in r.iter_mut() {
                    seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
                    *c = (seed >> 16) as f32 / 655.36;
                }
            }
            let mut col = [0usize; 4];
            solve_assignment(&cost, 4, &mut col);
            let got: f32 = (0..4).map(|i| cost[i][col[i]]).sum();
            let mut best = f32::INFINITY;
            let perms = permutations4();
            for p in perms.iter() {
                let s: f32 = (0..4).map(|i| cost[i][p[i]]).sum();
                best = best.min(s);
            }
            assert!((got - best).abs() < 1e-3, "{got} vs {best}");
            let mut seen = [false; 4];
            for c in col {
                assert!(!seen[c]);
                seen[c] = true;
            }
        }
    }

    fn permutations4() -> Vec<[usize; 4]> {
        let mut v = Vec::new();
        for a in 0..4 {
            for b in 0..4 {
                for c in 0..4 {
                    for d in 0..4 {
                        let p = [a, b, c, d];
                        let mut s = [false; 4];
                        p.iter().for_each(|&x| s[x] = true);
                        if s.iter().all(|&x| x) {
                            v.push(p);
                        }
                    }
                }
            }
        }
        v
    }
}
