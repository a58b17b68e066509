//! 3-D fish length (Section IV.D): body-end validation (eq. 15), fish-tail
//! end compensation ([`crate::snake`]), disparity refinement
//! ([`crate::refine`]), triangulation ([`crate::geometry`]) and
//! `L = ‖x_H − x_T‖`; plus the per-track length estimate.
//!
//! - End points: the two ends of the left object along its oriented box's
//!   first principal axis, taken as the `k`-th most extreme mask-pixel
//!   projections (`k = 1 + area/4096`, at most 16) so a stray pixel does not
//!   set the length, moved out by half a pixel to the outline.
//! - End validation, eq. (15): an `h_o × h_o` square centred on the axis just
//!   inside each end of the left object is compared (SAD per pixel) with the
//!   square at the corresponding end of the right object; `SAD / μ_SAD >
//!   θ_SAD` flags a mismatch. Comparing the two objects' own end regions
//!   ("the SAD of two end regions between the left and the right video
//!   frames") is what detects an end cropped in one view and not the other:
//!   the right square is the left square shifted by the disparity the two
//!   ends imply. When it flags the end of the left object as the shorter
//!   one, the tail snake runs there. [`LengthConfig::snake_every_end`]
//!   (default on) also tries the snake at ends that pass eq. (15): a dim
//!   tail cropped alike in both views is invisible to eq. (15) (on the
//!   synthetic hauls every fish has a caudal fin of 0.1–0.55 of the body's
//!   reflectivity, and the missing fin costs 12–17 % of the length). It
//!   runs only where the evidence says the end is cut
//!   ([`LengthConfig::probe_gate`]): the mean of an `h_o/2` square just
//!   beyond the end ([`crate::snake::end_probe`]) stands above the local
//!   background by at least the noise and 6 % of the body's contrast, and
//!   at most half of it (a fin is dimmer than the body), in both views. A
//!   whole (bright) tail ends on background, so the snake never runs there
//!   and cannot lengthen it; the snake's level τ then sits at half the
//!   fin's measured contrast, so it grows over the dim fin and stops at its
//!   edge. Such a region is accepted only when (a) the snake finds a region of about
//!   the same reach beside the right object's corresponding end
//!   ([`LengthConfig::snake_both_views`]; the mesh and neighbours sit at
//!   other disparities than the fish), (b) it fills at least
//!   [`LengthConfig::min_fin_fill`] of `reach · h_o` (a fan, not a mesh
//!   line), (c) it reaches at most [`LengthConfig::max_tail_fraction`] of
//!   the body, and (d) not at both ends (a fish has one tail).
//! - Disparity of the ends: a Tukey resistant line (three-group medians)
//!   `d(t) = a + b·t` fitted to the refined blocks' disparities against
//!   their position `t` along the axis — a few bad blocks do not move it.
//!   Fewer than `min_blocks` blocks: the median of the blocks, else `d_o`.
//!   Then ([`LengthConfig::slant_fit`], default on; beyond the paper) the
//!   line is fitted again on the whole widened mask ([`crate::slant`]),
//!   starting from that line, the two masks' end disparities and `d_o`: on
//!   smooth, low-contrast bodies the blocks' slope was off by a median
//!   11 px at the ends where the masks disagreed with it, while the masks'
//!   own end disparities were mostly right (synthetic hauls, session 30).
//!   At an end the two masks' outlines give a sharper disparity
//!   (`x_left − x_right` of the corresponding ends): it is used where it
//!   lies within [`LengthConfig::mask_end_tolerance`] of the line.
//! - Consistency (merged or cropped masks): where an uncompensated end's
//!   mask disparity departs from the line by more than
//!   [`LengthConfig::max_end_disagreement`] of the disparity, the two views'
//!   masks end at different points of the fish (merged with a neighbour or
//!   the mesh in one view, occluded, cropped): the length is computed but
//!   withheld ([`FishLength::consistent`] false). A survey prefers fewer,
//!   right lengths; the per-track median uses the consistent frames. A
//!   pair the epipolar search found ([`StereoPair::searched`]) is always
//!   withheld: its right mask is the left one shifted, nothing to check.
//!
//! Memory bound: the refinement's `B` blocks and two `B`-float work arrays
//! on the stack; the accumulator holds `F` floats. No heap.

use crate::error::ImageError;
use crate::geometry::StereoGeometry;
use crate::image::{ImageView, Roi};
use crate::object::{Object, Objects, Run};
use crate::params::Params;
use crate::refine::{refine_disparity, RefinedBlock};
use crate::slant::{fit_slant, Axis};
use crate::snake::{background_level, end_probe, tail_snake, SnakeParams};
use crate::stereo::StereoPair;
use nalgebra::Vector3;

/// An object's outline lies on average half a pixel beyond its outermost
/// mask-pixel centres (a pixel is in the mask when its centre is inside).
pub const END_HALF_PIXEL: f32 = 0.5;

/// Most extreme pixels considered when picking an end (rank `k` ≤ this).
const MAX_END_RANK: usize = 16;

/// Why a pair's length could not be measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LengthError {
    /// The pair's object indices are not in the object lists, or an object has no mask.
    BadPair,
    /// An end point triangulates at or beyond infinity.
    Triangulation,
    /// The images were rejected.
    Image(ImageError),
}

impl From<ImageError> for LengthError {
    fn from(e: ImageError) -> Self {
        LengthError::Image(e)
    }
}

impl core::fmt::Display for LengthError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LengthError::BadPair => f.write_str("stereo pair refers to a missing or empty object"),
            LengthError::Triangulation => {
                f.write_str("end point triangulates at or beyond infinity")
            }
            LengthError::Image(e) => write!(f, "image: {e}"),
        }
    }
}

impl core::error::Error for LengthError {}

/// Options of the length stage beyond [`Params`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LengthConfig {
    /// Tail snake weights.
    pub snake: SnakeParams,
    /// Also try the tail snake at ends that pass eq. (15).
    pub snake_every_end: bool,
    /// Fewest refined blocks for the disparity line.
    pub min_blocks: u16,
    /// Scale of the per-pixel SAD ratio before it meets θ_SAD in eq. (15):
    /// mismatch when `scale · SAD/μ_SAD > θ_SAD`. The paper's θ_SAD = 16
    /// belongs to its (unstated) SAD scale; with both SADs per pixel, ends
    /// that match give ratios ≤ 1.45 and ends cropped in one view ≥ 1.98 on
    /// the synthetic scenes of `host/tests/stereo_length.rs` (noise σ 4 and
    /// 8), so the default 9 puts Table I's 16 at a per-pixel ratio of 1.78.
    /// (Subtracting an estimated noise floor from both SADs did not separate
    /// them better.)
    pub sad_ratio_scale: f32,
    /// End disparity from the two masks: an end whose mask disparity
    /// (`x_left − x_right` of the two objects' ends) lies within this many
    /// pixels of the block line's value there takes the mask disparity
    /// (an outline's position is sharper than a textured block's match
    /// along the body); otherwise, or at a compensated end, the line's.
    pub mask_end_tolerance: f32,
    /// Consistency gate: the length is withheld ([`FishLength::consistent`]
    /// false) when an uncompensated end's mask disparity differs from the
    /// disparity line by more than this fraction of the line's disparity —
    /// the two views' masks end at different places on the fish (merged
    /// with a neighbour or the mesh, occluded, a tail cropped in one view
    /// only). Default 0.025 with the slanted fit (session 30; 0.04 with the
    /// block line alone): the fitted line is the sharper yardstick, and
    /// seeds 1–30 measured 842 fish-frames at 3.49 % MAPE against the block
    /// line's 776 at 3.62 % (0.02: 799 at 3.08 %; 0.03: 875 at 4.62 %).
    pub max_end_disagreement: f32,
    /// Longest tail extension the snake may add, as a fraction of the
    /// object's own length along its axis.
    pub max_tail_fraction: f32,
    /// Accept a tail region only when the snake finds one of about the
    /// same extent beside the right object's corresponding end too.
    pub snake_both_views: bool,
    /// Least above-level area of an accepted tail region, as a fraction of
    /// `far_t · h_o` (its reach times the body height).
    pub min_fin_fill: f32,
    /// At ends eq. (15) did not flag, run the snake only where something
    /// brighter than the background continues past the end in both views
    /// ([`crate::snake::end_probe`] over an `h_o/2` square): its contrast
    /// must reach `max(probe_noise_k · σ_bg, probe_body_fraction · (body −
    /// background), 1)` grey levels. A fully segmented (bright) tail ends on
    /// background and is left alone; a dim fin cut alike in both views shows.
    pub probe_gate: bool,
    /// Noise multiple of the probe gate.
    pub probe_noise_k: f32,
    /// Body-contrast fraction of the probe gate.
    pub probe_body_fraction: f32,
    /// A fin is dimmer than the body: above this fraction of the body's
    /// contrast in either view, what continues past the end is something
    /// else (a neighbour, glow) and the snake does not run there.
    pub probe_max_body_fraction: f32,
    /// Beyond the paper, off by default (measured worse, README "Stereo
    /// pairing and 3-D length"): when true, an end extended by the tail snake takes the
    /// disparity of the unextended end continued along the chord through
    /// the two unextended ends' disparities (a straight fish's disparity is
    /// affine along its image axis), not the block line extrapolated.
    pub chord_extension: bool,
    /// Beyond the paper: an end extended where eq. (15) did not flag it
    /// (both views cut alike) must still pass the consistency gate
    /// ([`LengthConfig::max_end_disagreement`]) on its unextended masks.
    /// Default false since session 40: on today's length stage (slanted
    /// fit, fin profile) the unextended masks of such an end disagree by
    /// design — the snake extends the view whose cut it found — and the
    /// lengths the gate withheld were as good as the kept ones (seeds 1–30:
    /// 68 more fish-frames measured at 2.65 % MAPE against 2.95 %; per-fish
    /// 2.40 % on 439 fish → 2.41 % on 454; seeds 31–60 3.39 % on 511 →
    /// 3.30 % on 523). Session 5 had turned it on for one +89 % frame
    /// that the block line, extrapolated, put too deep.
    pub gate_extended_ends: bool,
    /// Beyond the paper: an end within `occlusion_radius` of another
    /// object's mask in the left view may be where an occluder begins, not
    /// where the fish ends: the length is withheld. The radius is this
    /// fraction of `h_o`, clamped to 3–32 px; 0 switches the gate off.
    pub occlusion_radius_fraction: f32,
    /// Beyond the paper: the disparity line is fitted on the whole widened
    /// mask ([`crate::slant`]) from the block line, the mask ends' chord
    /// and `d_o`, instead of taken from the block line alone.
    pub slant_fit: bool,
    /// Beyond the paper: where no snake extended either end, a dim fin is
    /// looked for by its averaged intensity profile ([`crate::fin`]) in
    /// both views, and the end it continues is extended to its reach.
    pub fin_profile: bool,
    /// The fin profile's start must stand this many times its own noise
    /// (`σ_bg/√(2J + 1)`) above the background.
    pub fin_noise_k: f32,
    /// Beyond the paper: the snake extends an end eq. (15) did not flag
    /// only at the tail, the end whose last tenth of the mask holds fewer
    /// pixels ([`crate::fin::end_slabs`]; a fish tapers to its tail and is
    /// blunt at its head), and so does the fin profile.
    pub tail_by_taper: bool,
    /// Beyond the paper: a track's length is the median of the largest
    /// group of its per-frame lengths that agree within this fraction
    /// (`longest ≤ (1 + a) · shortest`), and is withheld when two such
    /// groups of that size do not overlap — the frames disagree with no
    /// majority ([`LengthAccumulator::estimate_agreeing`]). A merge with a
    /// neighbour that both views show alike passes every per-frame gate
    /// and measures the pair (+50 to +150 %), and a track that took two
    /// fish mixes their lengths; a correct frame is within a few percent.
    /// Default 0.25 (session 32; per-fish MAPE / fish measured, seeds 1–30:
    /// plain median 3.55 % / 444, 0.15: 3.05 % / 431, 0.25: 3.12 % / 438,
    /// 0.4: 3.18 % / 442). 0 (or not finite): the plain median of every
    /// frame.
    pub track_agreement: f32,
}

impl Default for LengthConfig {
    fn default() -> Self {
        LengthConfig {
            snake: SnakeParams::default(),
            snake_every_end: true,
            min_blocks: 6,
            sad_ratio_scale: 9.0,
            mask_end_tolerance: 8.0,
            max_end_disagreement: 0.025,
            max_tail_fraction: 0.3,
            snake_both_views: true,
            min_fin_fill: 0.15,
            probe_gate: true,
            probe_noise_k: 1.0,
            probe_body_fraction: 0.06,
            probe_max_body_fraction: 0.5,
            chord_extension: false,
            gate_extended_ends: false,
            occlusion_radius_fraction: 0.25,
            slant_fit: true,
            fin_profile: true,
            fin_noise_k: 4.0,
            tail_by_taper: true,
            track_agreement: 0.25,
        }
    }
}

/// One end of a fish (index 0: the end at `−u`, 1: at `+u`, `u` the axis).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FishEnd {
    /// Left-view pixel position.
    pub px: (f32, f32),
    /// Disparity used.
    pub d: f32,
    /// Disparity implied by the two objects' ends (`x_left − x_right` of
    /// this end and the right object's corresponding end).
    pub mask_d: f32,
    /// `|mask_d − line disparity| / line disparity` at the unextended end.
    pub mask_dev: f32,
    /// 3-D point, mm, rectified left camera frame.
    pub xyz: [f32; 3],
    /// `SAD / μ_SAD` of eq. (15), both per pixel (before `sad_ratio_scale`).
    pub sad_ratio: f32,
    /// Eq. (15) flagged a mismatch.
    pub mismatch: bool,
    /// The tail snake extended this end.
    pub compensated: bool,
    /// Grey-level contrast above the local background just beyond this end
    /// in the left and the right view ([`crate::snake::end_probe`]).
    pub probe: [f32; 2],
    /// Left view's background robust SD (1.4826·MAD of the ring).
    pub noise: f32,
    /// Body mean minus background, left view.
    pub contrast: f32,
    /// Another left object's mask lies within the occlusion radius of this
    /// (unextended) end ([`LengthConfig::occlusion_radius_fraction`]).
    pub touches_other: bool,
}

/// The 3-D length of one stereo pair in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FishLength {
    /// The two ends (head/tail are not told apart: the length does not need it).
    pub ends: [FishEnd; 2],
    /// `L = ‖x_H − x_T‖`, mm.
    pub length_mm: f32,
    /// 3-D point of the box centre on the axis, mm.
    pub centre: [f32; 3],
    /// Refined blocks used for the disparity line.
    pub blocks: u16,
    /// Slope of the disparity line, pixels of disparity per pixel along the axis.
    pub slope: f32,
    /// Absolute differences spent (refinement + validation).
    pub sad_ops: u64,
    /// Both views' masks agree at every uncompensated end
    /// ([`LengthConfig::max_end_disagreement`]): the length is usable.
    pub consistent: bool,
}

/// The rank-`k` extreme projections `(t_lo, t_hi)` of the mask pixels of
/// `runs` on the axis through `(cx, cy)` with direction `(ux, uy)`.
pub fn axis_extent(
    runs: &[Run],
    cx: f32,
    cy: f32,
    ux: f32,
    uy: f32,
    k: usize,
) -> Option<(f32, f32)> {
    let k = k.clamp(1, MAX_END_RANK);
    let mut lo = [f32::INFINITY; MAX_END_RANK];
    let mut hi = [f32::NEG_INFINITY; MAX_END_RANK];
    let mut n = 0usize;
    for r in runs {
        if r.is_empty() {
            continue;
        }
        let base = (r.y as f32 - cy) * uy - cx * ux;
        let len = r.len() as usize;
        // along a run t is monotonic: only its k first and k last pixels
        // matter (each pixel counted once: a run of at most 2k pixels is
        // taken whole, not its overlapping head and tail twice)
        let x0 = r.x0 as usize;
        let (head, tail_from) = if len <= 2 * k {
            (len, len)
        } else {
            (k, len - k)
        };
        for x in (x0..x0 + head).chain(x0 + tail_from..x0 + len) {
            let t = base + x as f32 * ux;
            insert_lo(&mut lo, k, t);
            insert_hi(&mut hi, k, t);
        }
        n += len;
    }
    if n == 0 {
        return None;
    }
    let kk = k.min(n) - 1;
    let (a, b) = (lo.get(kk).copied()?, hi.get(kk).copied()?);
    if a.is_finite() && b.is_finite() {
        Some((a, b))
    } else {
        None
    }
}

fn insert_lo(arr: &mut [f32; MAX_END_RANK], k: usize, t: f32) {
    let k = k.min(MAX_END_RANK);
    if k == 0 || t.partial_cmp(&arr[k - 1]) != Some(core::cmp::Ordering::Less) {
        return;
    }
    let mut i = k - 1;
    while i > 0 && arr[i - 1] > t {
        arr[i] = arr[i - 1];
        i -= 1;
    }
    arr[i] = t;
}

fn insert_hi(arr: &mut [f32; MAX_END_RANK], k: usize, t: f32) {
    let k = k.min(MAX_END_RANK);
    if k == 0 || t.partial_cmp(&arr[k - 1]) != Some(core::cmp::Ordering::Greater) {
        return;
    }
    let mut i = k - 1;
    while i > 0 && arr[i - 1] < t {
        arr[i] = arr[i - 1];
        i -= 1;
    }
    arr[i] = t;
}

/// End rank used for an object of `area` pixels.
pub const fn end_rank(area: u32) -> usize {
    let k = 1 + (area / 4096) as usize;
    if k > MAX_END_RANK {
        MAX_END_RANK
    } else {
        k
    }
}

/// SAD per pixel between the `side × side` square centred at `cl` in the
/// left image and the one centred at `cr` in the right image (pixels outside
/// either image skipped); `None` when fewer than a quarter could be compared.
pub fn end_square_sad(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    cl: (f32, f32),
    cr: (f32, f32),
    side: u32,
    ops: &mut u64,
) -> Option<f32> {
    let side = side.clamp(1, 1024) as i64;
    let half = side / 2;
    let fl = |v: f32| -> Option<i64> {
        if v.is_finite() && v.abs() < 1.0e7 {
            Some(micromath::F32(v).round().0 as i64)
        } else {
            None
        }
    };
    let (lx, ly) = (fl(cl.0)? - half, fl(cl.1)? - half);
    let (rx, ry) = (fl(cr.0)? - half, fl(cr.1)? - half);
    // the columns i of the square inside both images, the same for every
    // row: one slice pair per row (rows outside either image skipped)
    let i0 = 0i64.max(-lx).max(-rx);
    let i1 = side
        .min(left.width() as i64 - lx)
        .min(right.width() as i64 - rx);
    let mut sum = 0u64;
    let mut n = 0u64;
    if i1 > i0 {
        let (a0, b0) = ((lx + i0) as usize, (rx + i0) as usize);
        let len = (i1 - i0) as usize;
        for j in 0..side {
            let (ya, yb) = (ly + j, ry + j);
            if ya < 0 || yb < 0 {
                continue;
            }
            let (Some(a), Some(b)) = (
                left.row(ya as usize).get(a0..a0 + len),
                right.row(yb as usize).get(b0..b0 + len),
            ) else {
                continue;
            };
            // at most 1024 · 255 per row: u32
            let s: u32 = a.iter().zip(b).map(|(&p, &q)| p.abs_diff(q) as u32).sum();
            sum += s as u64;
            n += len as u64;
        }
    }
    *ops += n;
    if n == 0 || 4 * n < (side * side) as u64 {
        return None;
    }
    Some(sum as f32 / n as f32)
}

/// Median of `v` (sorted in place; the mean of the middle two for an even
/// length), `None` when empty.
pub(crate) fn median_in_place(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    v.sort_unstable_by(|a, b| a.total_cmp(b));
    let n = v.len();
    let m = if n % 2 == 1 {
        v.get(n / 2).copied()?
    } else {
        0.5 * (v.get(n / 2 - 1).copied()? + v.get(n / 2).copied()?)
    };
    Some(m)
}

/// Tukey's resistant line `d = a + b·t` through `(t, d)` points: the slope
/// joins the medians of the outer thirds (sorted by `t`), the intercept is
/// the median residual. `None` for fewer than 3 points; slope 0 when the
/// outer thirds share their median `t`.
pub fn resistant_line<const B: usize>(
    pts: &mut heapless::Vec<(f32, f32), B>,
) -> Option<(f32, f32)> {
    let n = pts.len();
    if n < 3 {
        return None;
    }
    pts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let third = n / 3;
    let mut wt = [0.0f32; B];
    let mut wd = [0.0f32; B];
    let group =
        |from: usize, to: usize, wt: &mut [f32; B], wd: &mut [f32; B]| -> Option<(f32, f32)> {
            let m = to - from;
            for (i, p) in pts.get(from..to)?.iter().enumerate() {
                *wt.get_mut(i)? = p.0;
                *wd.get_mut(i)? = p.1;
            }
            Some((
                median_in_place(wt.get_mut(..m)?)?,
                median_in_place(wd.get_mut(..m)?)?,
            ))
        };
    let (tl, dl) = group(0, third.max(1), &mut wt, &mut wd)?;
    let (tr, dr) = group(n - third.max(1), n, &mut wt, &mut wd)?;
    let b = if tr - tl > 1e-3 {
        (dr - dl) / (tr - tl)
    } else {
        0.0
    };
    for (i, p) in pts.iter().enumerate() {
        *wd.get_mut(i)? = p.1 - b * p.0;
    }
    let a = median_in_place(wd.get_mut(..n)?)?;
    Some((a, b))
}

fn unit_axis(obj: &Object) -> (f32, f32) {
    let a = obj.obb.angle;
    if a.is_finite() {
        (libm::cosf(a), libm::sinf(a))
    } else {
        (1.0, 0.0)
    }
}

/// True when a mask pixel (centre) of an object of `objs` other than
/// `skip` lies within `rad` pixels of `p`.
pub fn near_other_object<const N: usize, const R: usize>(
    objs: &Objects<N, R>,
    skip: usize,
    p: (f32, f32),
    rad: f32,
) -> bool {
    if !(p.0.is_finite() && p.1.is_finite() && rad > 0.0) {
        return false;
    }
    let r2 = rad * rad;
    for (k, o) in objs.items.iter().enumerate() {
        if k == skip {
            continue;
        }
        let b = o.bbox;
        if p.0 + rad < b.x as f32
            || p.0 - rad > b.right() as f32
            || p.1 + rad < b.y as f32
            || p.1 - rad > b.bottom() as f32
        {
            continue;
        }
        for r in objs.runs_of(o) {
            if r.is_empty() {
                continue;
            }
            let dy = r.y as f32 - p.1;
            if dy * dy > r2 {
                continue;
            }
            // the run's pixel nearest p: |x − p.x| is convex in x
            let xi = micromath::F32(p.0)
                .round()
                .0
                .clamp(r.x0 as f32, (r.x1 - 1) as f32);
            let dx = xi - p.0;
            if dx * dx + dy * dy <= r2 {
                return true;
            }
        }
    }
    false
}

/// Measures the 3-D length of one stereo pair (Section IV.D). `B` bounds the
/// number of refined blocks.
#[allow(clippy::too_many_arguments)]
pub fn measure_length<const N: usize, const R: usize, const B: usize>(
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: &Objects<N, R>,
    right: &Objects<N, R>,
    pair: &StereoPair,
    geom: &StereoGeometry,
    params: &Params,
    cfg: &LengthConfig,
) -> Result<FishLength, LengthError> {
    let lo = left
        .items
        .get(pair.left as usize)
        .ok_or(LengthError::BadPair)?;
    let ro = right
        .items
        .get(pair.right as usize)
        .ok_or(LengthError::BadPair)?;
    let (lruns, rruns) = (left.runs_of(lo), right.runs_of(ro));
    let mut out = FishLength::default();
    let (ux, uy) = unit_axis(lo);
    let (cx, cy) = (lo.obb.cx, lo.obb.cy);
    let (t_lo, t_hi) =
        axis_extent(lruns, cx, cy, ux, uy, end_rank(lo.area)).ok_or(LengthError::BadPair)?;
    // the outline lies half a pixel beyond the outermost pixel centres
    let (t_lo, t_hi) = (t_lo - END_HALF_PIXEL, t_hi + END_HALF_PIXEL);
    let (rux, ruy) = unit_axis(ro);
    let (rcx, rcy) = (ro.obb.cx, ro.obb.cy);
    let (rt_lo, rt_hi) =
        axis_extent(rruns, rcx, rcy, rux, ruy, end_rank(ro.area)).ok_or(LengthError::BadPair)?;
    let (rt_lo, rt_hi) = (rt_lo - END_HALF_PIXEL, rt_hi + END_HALF_PIXEL);
    let right_ends = [
        (rcx + rt_lo * rux, rcy + rt_lo * ruy, -1.0f32),
        (rcx + rt_hi * rux, rcy + rt_hi * ruy, 1.0f32),
    ];
    let h_o = (2.0 * lo.obb.half_h).clamp(2.0, 1024.0);
    let side = micromath::F32(h_o).round().0 as u32;
    let mu = pair.mu_sad.max(1.0);
    let mut ts = [t_lo, t_hi];
    let mut flagged_ends = [false; 2];
    let bg = background_level(left_img, lo.bbox, (h_o * 0.5) as u32);
    let rh_o = (2.0 * ro.obb.half_h).clamp(2.0, 1024.0);
    let rbg = background_level(right_img, ro.bbox, (rh_o * 0.5) as u32);
    // the taper rule's mask slabs, only when it decides anything
    let slabs = if params.tail_compensation && cfg.tail_by_taper {
        crate::fin::end_slabs(lruns, (cx, cy), (ux, uy), (t_lo, t_hi), 0.1)
    } else {
        (0, 0)
    };
    for (e, s) in [(0usize, -1.0f32), (1, 1.0)] {
        let t = ts[e];
        let end = (cx + t * ux, cy + t * uy);
        // the right end nearest to this one once shifted by d_o
        let mut best = (f32::INFINITY, right_ends[0]);
        for re in right_ends {
            let dx = re.0 + pair.d_o - end.0;
            let dy = re.1 - end.1;
            let dist = dx * dx + dy * dy;
            if dist < best.0 {
                best = (dist, re);
            }
        }
        let re = best.1;
        // outward direction of the right end, as a unit vector
        let (rox, roy) = (re.2 * rux, re.2 * ruy);
        let cl = (end.0 - s * ux * h_o * 0.5, end.1 - s * uy * h_o * 0.5);
        let cr = (re.0 - rox * h_o * 0.5, re.1 - roy * h_o * 0.5);
        let sad = end_square_sad(left_img, right_img, cl, cr, side, &mut out.sad_ops);
        let ratio = sad.map(|v| v / mu).unwrap_or(0.0);
        let mismatch = ratio * cfg.sad_ratio_scale > params.theta_sad;
        // does the right object reach further out than the left one?
        let ext = (re.0 + pair.d_o - end.0) * s * ux + (re.1 - end.1) * s * uy;
        let left_short = ext > 1.0;
        let fe = out.ends.get_mut(e).ok_or(LengthError::BadPair)?;
        fe.sad_ratio = ratio;
        fe.mismatch = mismatch;
        fe.mask_d = end.0 - re.0;
        let pside = ((h_o * 0.5) as u32).max(3);
        let pl = end_probe(left_img, end, (s * ux, s * uy), pside).map_or(0.0, |m| m - bg.0);
        let pr = end_probe(right_img, (re.0, re.1), (rox, roy), pside).map_or(0.0, |m| m - rbg.0);
        fe.probe = [pl, pr];
        fe.noise = bg.1;
        fe.contrast = lo.mean - bg.0;
        let flagged = mismatch && left_short;
        if let Some(f) = flagged_ends.get_mut(e) {
            *f = flagged;
        }
        let gate = (cfg.probe_noise_k * bg.1)
            .max(cfg.probe_body_fraction * fe.contrast)
            .max(1.0);
        let ceiling = cfg.probe_max_body_fraction * fe.contrast;
        let probed =
            !cfg.probe_gate || (pl >= gate && pr >= gate && pl <= ceiling && pr <= ceiling);
        if params.tail_compensation && (flagged || (cfg.snake_every_end && probed)) {
            let sn = tail_snake(
                left_img,
                end,
                (s * ux, s * uy),
                h_o,
                lo.mean,
                bg,
                if cfg.probe_gate && !flagged { pl } else { 0.0 },
                &cfg.snake,
            );
            // a caudal fin is a fraction of the body: a longer region is
            // not a missing tail (a neighbour, the mesh, glow)
            // the same tail must be found beside the right object's end
            // (not needed where eq. (15) flagged the end: there the right
            // object already holds the tail the left one lacks)
            let agree = if cfg.snake_both_views && sn.accepted && !flagged {
                let rs = tail_snake(
                    right_img,
                    (re.0, re.1),
                    (rox, roy),
                    rh_o,
                    ro.mean,
                    rbg,
                    if cfg.probe_gate && !flagged { pr } else { 0.0 },
                    &cfg.snake,
                );
                rs.accepted && (rs.far_t - sn.far_t).abs() <= (0.3 * sn.far_t).max(4.0)
            } else {
                true
            };
            // a fin is a fan about as tall as the body: a thin bright line
            // (the mesh) reaching far is not one
            let fan = sn.area * sn.inside_fraction >= cfg.min_fin_fill * sn.far_t * h_o;
            // an end eq. (15) did not flag is extended only at the tail:
            // the end whose last tenth holds fewer mask pixels
            let tail = flagged
                || !cfg.tail_by_taper
                || match e {
                    0 => slabs.0 < slabs.1,
                    _ => slabs.1 < slabs.0,
                };
            if sn.accepted
                && agree
                && fan
                && tail
                && sn.far_t <= cfg.max_tail_fraction * (t_hi - t_lo)
            {
                ts[e] = t + s * sn.far_t;
                fe.compensated = true;
            }
        }
    }
    // a fish has one tail: regions found beyond both ends are not a tail
    if out.ends.iter().all(|e| e.compensated) {
        ts = [t_lo, t_hi];
        for fe in out.ends.iter_mut() {
            fe.compensated = false;
        }
    }
    // disparity refinement and the robust disparity line along the axis
    let refined = refine_disparity::<B>(
        left_img,
        right_img,
        lruns,
        lo.bbox,
        pair.d_o,
        params.refine_block as u32,
        params.refine_range,
    )?;
    out.sad_ops += refined.sad_ops;
    let mut pts: heapless::Vec<(f32, f32), B> = heapless::Vec::new();
    for b in refined.blocks.iter() {
        let RefinedBlock { x, y, d, .. } = *b;
        let t = (x - cx) * ux + (y - cy) * uy;
        let _ = pts.push((t, d));
    }
    out.blocks = pts.len() as u16;
    let (a, b) = if pts.len() >= cfg.min_blocks.max(3) as usize {
        resistant_line(&mut pts).unwrap_or((pair.d_o, 0.0))
    } else if !pts.is_empty() {
        let mut ds = [0.0f32; B];
        for (w, p) in ds.iter_mut().zip(pts.iter()) {
            *w = p.1;
        }
        let m = median_in_place(ds.get_mut(..pts.len()).unwrap_or(&mut [])).unwrap_or(pair.d_o);
        (m, 0.0)
    } else {
        (pair.d_o, 0.0)
    };
    let (a, b) = if cfg.slant_fit {
        let axis = Axis {
            cx,
            cy,
            ux,
            uy,
            t0: t_lo,
            t1: t_hi,
        };
        let m = ((lo.obb.half_h * 0.5) as u32).max(4);
        let chord = match out.ends {
            [e0, e1] => (e0.mask_d, e1.mask_d),
        };
        let starts = [(a + b * t_lo, a + b * t_hi), chord, (pair.d_o, pair.d_o)];
        match fit_slant(
            left_img,
            right_img,
            lruns,
            m,
            &axis,
            &starts,
            &mut out.sad_ops,
        ) {
            Some(f) => f.line(&axis),
            None => (a, b),
        }
    } else {
        (a, b)
    };
    // a dim fin by its averaged profile, where no snake extended an end
    if params.tail_compensation && cfg.fin_profile && !out.ends.iter().any(|e| e.compensated) {
        let body = t_hi - t_lo;
        let len = ((cfg.max_tail_fraction * body) as u32).clamp(8, crate::fin::MAX_PROFILE as u32);
        let half = ((h_o / 3.0) as u32).max(2);
        let mut reach = [None::<f32>; 2];
        for (e, s) in [(0usize, -1.0f32), (1, 1.0)] {
            let t = ts[e];
            let probe = crate::fin::FinProbe {
                end: (cx + t * ux, cy + t * uy),
                dir: (s * ux, s * uy),
                half,
                len,
            };
            let contrast = lo.mean - bg.0;
            let rcontrast = ro.mean - rbg.0;
            let lr =
                crate::fin::fin_reach(left_img, &probe, |_| 0.0, bg.1, contrast, cfg.fin_noise_k);
            let rr = crate::fin::fin_reach(
                right_img,
                &probe,
                |k| a + b * (t + s * k),
                rbg.1,
                rcontrast,
                cfg.fin_noise_k,
            );
            if let (Some(rl), Some(rr)) = (lr, rr) {
                let lim = (len - 1) as f32;
                if rl >= 3.0
                    && rr >= 3.0
                    && rl < lim
                    && rr < lim
                    && (rl - rr).abs() <= (0.3 * rl).max(4.0)
                {
                    if let Some(r) = reach.get_mut(e) {
                        *r = Some(rl.min(rr));
                    }
                }
            }
        }
        let taper = !cfg.tail_by_taper;
        let one = match reach {
            [Some(r), None] if taper || slabs.0 < slabs.1 => Some((0usize, -1.0f32, r)),
            [None, Some(r)] if taper || slabs.1 < slabs.0 => Some((1, 1.0, r)),
            _ => None,
        };
        if let Some((e, s, r)) = one {
            if let (Some(t), Some(fe)) = (ts.get_mut(e), out.ends.get_mut(e)) {
                *t += s * r;
                fe.compensated = true;
            }
        }
    }
    out.slope = b;
    let mut xyz = [Vector3::zeros(); 2];
    let t_orig = [t_lo, t_hi];
    // the disparity of each unextended end: the mask ends' own where both
    // views' outlines agree with the line (not at an end eq. (15) flagged:
    // there the right mask holds the tail the left one lacks), else the line's
    let mut d_end = [0.0f32; 2];
    for e in 0..2 {
        let fe = out.ends.get_mut(e).ok_or(LengthError::BadPair)?;
        let d_at_end = a + b * t_orig[e];
        let dev = (fe.mask_d - d_at_end).abs();
        fe.mask_dev = dev / d_at_end.abs().max(1.0);
        let mask_ok = !(fe.compensated && flagged_ends[e]) && dev <= cfg.mask_end_tolerance;
        d_end[e] = if mask_ok { fe.mask_d } else { d_at_end };
    }
    // a fish is straight: its disparity is affine along the image axis, so
    // an extended end continues the chord through the two validated ends
    // rather than the block line's slope (a few px of slope error over a
    // long extrapolation moved a far tail by 300 mm)
    let span = t_hi - t_lo;
    let chord = if span > 1e-3 {
        (d_end[1] - d_end[0]) / span
    } else {
        b
    };
    out.consistent = true;
    for e in 0..2 {
        let t = ts[e];
        let (x, y) = (cx + t * ux, cy + t * uy);
        let fe = out.ends.get_mut(e).ok_or(LengthError::BadPair)?;
        let d = if !fe.compensated {
            d_end[e]
        } else if cfg.chord_extension {
            d_end[e] + chord * (t - t_orig[e])
        } else {
            a + b * t
        };
        let agrees = fe.mask_dev <= cfg.max_end_disagreement; // false for NaN
                                                              // an end extended by a snake beside both views' cut ends (not one
                                                              // eq. (15) flagged) must still have masks that agree there
        let gated = !fe.compensated || (cfg.gate_extended_ends && !flagged_ends[e]);
        if gated && !agrees {
            out.consistent = false;
        }
        // an end against another object may be an occluder's edge
        let te = t_orig[e];
        fe.touches_other = cfg.occlusion_radius_fraction > 0.0
            && near_other_object(
                left,
                pair.left as usize,
                (cx + te * ux, cy + te * uy),
                (cfg.occlusion_radius_fraction * h_o).clamp(3.0, 32.0),
            );
        if fe.touches_other {
            out.consistent = false;
        }
        let p = geom
            .triangulate(x, y, d)
            .ok_or(LengthError::Triangulation)?;
        xyz[e] = p;
        fe.px = (x, y);
        fe.d = d;
        fe.xyz = [p.x, p.y, p.z];
    }
    // a searched pair's right mask is its left one shifted
    // (crate::epipolar): the gate above had no second view to check
    if pair.searched {
        out.consistent = false;
    }
    out.length_mm = (xyz[1] - xyz[0]).norm();
    if let Some(c) = geom.triangulate(cx, cy, a) {
        out.centre = [c.x, c.y, c.z];
    }
    Ok(out)
}

/// True when both boxes keep at least `margin` (≥ 1) pixels from every
/// border of a `width × height` frame: the fish is wholly inside both views
/// and its length is measurable.
pub fn wholly_inside(left: &Roi, right: &Roi, width: u32, height: u32, margin: u32) -> bool {
    let frame = Roi::new(0, 0, width, height);
    wholly_inside_valid(left, right, &[frame, frame], margin)
}

/// True when each box keeps at least `margin` (≥ 1) pixels from every edge
/// of its view's valid rectangle (`valid[0]` left, `valid[1]` right): the
/// part of a rectified frame where every pixel has a raw source. Beyond
/// it the frame shows the rectification's fill (an `alpha > 0`
/// rectification keeps the raw view's edges), so a fish reaching it is cut
/// by the edge of the raw view. [`wholly_inside`] is the whole-frame case.
pub fn wholly_inside_valid(left: &Roi, right: &Roi, valid: &[Roi; 2], margin: u32) -> bool {
    let m = margin.max(1);
    let ok = |b: &Roi, v: &Roi| {
        !b.is_empty()
            && b.x >= v.x.saturating_add(m)
            && b.y >= v.y.saturating_add(m)
            && b.right().saturating_add(m) <= v.right()
            && b.bottom().saturating_add(m) <= v.bottom()
    };
    ok(left, &valid[0]) && ok(right, &valid[1])
}

/// A track's length estimate.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LengthEstimate {
    /// Median of the measurable frames' lengths, mm; `None`: no measurable frame.
    pub median_mm: Option<f32>,
    /// Robust SD, 1.4826 · MAD, mm (0 with fewer than 2 frames).
    pub robust_sd_mm: f32,
    /// Frames that contributed (every measured frame; see `agreeing`).
    pub measured: u32,
    /// Frames whose lengths the median was taken over: the agreeing group
    /// of [`LengthAccumulator::estimate_agreeing`] (all measured frames
    /// with the plain median; 0 when withheld).
    pub agreeing: u32,
    /// The measured frames disagree with no majority: no length
    /// (`median_mm` is `None` although `measured > 0`).
    pub inconsistent: bool,
    /// Frames offered.
    pub frames: u32,
}

/// Per-track accumulator of per-frame lengths (`F` frames kept).
#[derive(Debug, Clone, Default)]
pub struct LengthAccumulator<const F: usize> {
    lengths: heapless::Vec<f32, F>,
    /// Frames offered.
    pub frames: u32,
    /// Measurable lengths that did not fit in `F` (ignored).
    pub dropped: u32,
}

impl<const F: usize> LengthAccumulator<F> {
    /// An empty accumulator.
    pub const fn new() -> Self {
        LengthAccumulator {
            lengths: heapless::Vec::new(),
            frames: 0,
            dropped: 0,
        }
    }

    /// Offers one frame: its length (if measured) and whether the fish was
    /// wholly inside both views ([`wholly_inside`]). Only measured, wholly
    /// inside, finite, positive lengths count.
    pub fn push(&mut self, length_mm: Option<f32>, wholly_inside: bool) {
        self.frames = self.frames.saturating_add(1);
        if let (Some(l), true) = (length_mm, wholly_inside) {
            if l.is_finite() && l > 0.0 && self.lengths.push(l).is_err() {
                self.dropped = self.dropped.saturating_add(1);
            }
        }
    }

    /// Median and robust SD of the lengths so far (every frame).
    pub fn estimate(&self) -> LengthEstimate {
        self.estimate_agreeing(0.0)
    }

    /// The track's length from the frames that agree
    /// ([`LengthConfig::track_agreement`] `a`): with the lengths sorted,
    /// each one starts a group of the lengths up to `(1 + a)` times it; the
    /// groups of the largest size either overlap (a chain: the median is
    /// taken over their union) or two of them are disjoint, and then no
    /// majority of frames agrees and the length is withheld
    /// (`inconsistent`). The robust SD is over every measured frame (the
    /// spread the frames showed). `a` 0 or not finite: the plain median.
    /// Work O(F²) comparisons, F ≤ a few dozen.
    pub fn estimate_agreeing(&self, a: f32) -> LengthEstimate {
        let n = self.lengths.len();
        let mut w = [0.0f32; F];
        for (x, y) in w.iter_mut().zip(self.lengths.iter()) {
            *x = *y;
        }
        let sorted = w.get_mut(..n).unwrap_or(&mut []);
        sorted.sort_unstable_by(|x, y| x.total_cmp(y));
        let (lo, hi, inconsistent) = agreeing_span(sorted, a);
        let med = if inconsistent {
            None
        } else {
            median_in_place(w.get_mut(lo..hi).unwrap_or(&mut []))
        };
        let mut sd = 0.0;
        if n >= 2 {
            let mut all = [0.0f32; F];
            for (x, y) in all.iter_mut().zip(self.lengths.iter()) {
                *x = *y;
            }
            if let Some(m) = median_in_place(all.get_mut(..n).unwrap_or(&mut [])) {
                for (x, y) in all.iter_mut().zip(self.lengths.iter()) {
                    *x = (*y - m).abs();
                }
                sd = 1.4826 * median_in_place(all.get_mut(..n).unwrap_or(&mut [])).unwrap_or(0.0);
            }
        }
        LengthEstimate {
            median_mm: med,
            robust_sd_mm: if med.is_some() { sd } else { 0.0 },
            measured: n as u32,
            agreeing: if inconsistent { 0 } else { (hi - lo) as u32 },
            inconsistent,
            frames: self.frames,
        }
    }
}

/// The agreeing span `lo..hi` of ascending positive lengths `v` for
/// agreement `a` (see [`LengthAccumulator::estimate_agreeing`]), and
/// whether the largest groups are disjoint (no majority). The whole of `v`
/// when `a` is 0 or not finite.
fn agreeing_span(v: &[f32], a: f32) -> (usize, usize, bool) {
    let n = v.len();
    if !(a.is_finite() && a > 0.0) || n == 0 {
        return (0, n, false);
    }
    // end (exclusive) of the group starting at i
    let end = |i: usize| {
        let lim = v.get(i).map_or(0.0, |&x| x * (1.0 + a));
        let mut j = i;
        while v.get(j).is_some_and(|&x| x <= lim) {
            j += 1;
        }
        j
    };
    let mut size = 0;
    for i in 0..n {
        size = size.max(end(i) - i);
    }
    let first = (0..n).find(|&i| end(i) - i == size).unwrap_or(0);
    let last = (0..n).rev().find(|&i| end(i) - i == size).unwrap_or(0);
    let (first_end, last_end) = (end(first), end(last));
    // disjoint: the first largest group ends below the last one's start
    let disjoint = first_end <= last;
    (first, last_end, disjoint)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn resistant_line_ignores_outliers() {
        let mut v: heapless::Vec<(f32, f32), 64> = heapless::Vec::new();
        for i in 0..40 {
            let t = i as f32 * 3.0 - 60.0;
            let mut d = 50.0 + 0.1 * t;
            if i % 9 == 4 {
                d += 30.0; // bad blocks
            }
            v.push((t, d)).unwrap();
        }
        let (a, b) = resistant_line(&mut v).unwrap();
        assert!((a - 50.0).abs() < 0.2, "{a}");
        assert!((b - 0.1).abs() < 0.01, "{b}");
    }

    #[test]
    fn accumulator_median_and_mad() {
        let mut acc = LengthAccumulator::<16>::new();
        assert_eq!(acc.estimate().median_mm, None);
        for (l, inside) in [
            (100.0, true),
            (102.0, true),
            (98.0, true),
            (300.0, false),
            (101.0, true),
            (99.0, true),
        ] {
            acc.push(Some(l), inside);
        }
        acc.push(None, true);
        let e = acc.estimate();
        assert_eq!(e.median_mm, Some(100.0));
        assert_eq!(e.measured, 5);
        assert_eq!(e.frames, 7);
        // |dev| = 0,2,2,1,1 → MAD 1
        assert!((e.robust_sd_mm - 1.4826).abs() < 1e-4);
    }

    fn acc_of(ls: &[f32]) -> LengthAccumulator<16> {
        let mut acc = LengthAccumulator::<16>::new();
        for &l in ls {
            acc.push(Some(l), true);
        }
        acc
    }

    #[test]
    fn agreeing_frames_decide_the_track_length() {
        // a right frame and a merge with a neighbour: no majority
        let e = acc_of(&[289.7, 1091.6]).estimate_agreeing(0.25);
        assert_eq!(e.median_mm, None);
        assert!(e.inconsistent);
        assert_eq!((e.measured, e.agreeing), (2, 0));
        assert_eq!(e.robust_sd_mm, 0.0);
        // the plain median would report their mean
        let plain = acc_of(&[289.7, 1091.6]).estimate();
        assert!((plain.median_mm.unwrap() - 690.65).abs() < 1e-3);
        assert!(!plain.inconsistent);
        // two of three agree: their median, the SD over all three
        let e = acc_of(&[250.0, 100.0, 102.0]).estimate_agreeing(0.25);
        assert_eq!(e.median_mm, Some(101.0));
        assert_eq!((e.measured, e.agreeing), (3, 2));
        // median of all three 102, |dev| 2, 0, 148: MAD 2
        assert!(
            (e.robust_sd_mm - 2.0 * 1.4826).abs() < 1e-4,
            "{}",
            e.robust_sd_mm
        );
        // a chain of overlapping groups: the median of their union
        let e = acc_of(&[140.0, 100.0, 120.0]).estimate_agreeing(0.25);
        assert_eq!(e.median_mm, Some(120.0));
        assert_eq!(e.agreeing, 3);
        // two disjoint pairs: withheld
        let e = acc_of(&[100.0, 101.0, 200.0, 202.0]).estimate_agreeing(0.25);
        assert_eq!(e.median_mm, None);
        // 0 and non-finite agreement: the plain median
        for a in [0.0, f32::NAN, f32::INFINITY, -1.0] {
            let e = acc_of(&[100.0, 101.0, 200.0, 202.0]).estimate_agreeing(a);
            assert_eq!(e.median_mm, Some(150.5));
            assert_eq!(e.agreeing, 4);
        }
        // one frame, none
        assert_eq!(
            acc_of(&[321.0]).estimate_agreeing(0.25).median_mm,
            Some(321.0)
        );
        let e = acc_of(&[]).estimate_agreeing(0.25);
        assert_eq!((e.median_mm, e.inconsistent, e.measured), (None, false, 0));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(if cfg!(miri) { 8 } else { 256 }))]
        /// The agreeing estimate never panics, does not depend on the
        /// frames' order, lies within the frames' range, comes from a group
        /// no wider than `1 + a`, is the plain median when every frame
        /// agrees, and is never withheld when a strict majority of the
        /// frames agrees.
        #[test]
        fn agreeing_estimate_is_a_consensus(
            ls in proptest::collection::vec(1.0f32..2000.0, 0..16),
            a in 0.01f32..1.0,
            rot in 0usize..16,
        ) {
            let e = acc_of(&ls).estimate_agreeing(a);
            let mut r = ls.clone();
            if !r.is_empty() {
                let k = rot % r.len();
                r.rotate_left(k);
                r.reverse();
            }
            proptest::prop_assert_eq!(e, acc_of(&r).estimate_agreeing(a));
            proptest::prop_assert_eq!(e.measured as usize, ls.len());
            let lo = ls.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = ls.iter().copied().fold(0.0f32, f32::max);
            match e.median_mm {
                Some(m) => {
                    proptest::prop_assert!(m >= lo && m <= hi);
                    proptest::prop_assert!(!e.inconsistent);
                    proptest::prop_assert!(e.agreeing >= 1 && e.agreeing as usize <= ls.len());
                }
                None => proptest::prop_assert!(ls.is_empty() || e.inconsistent),
            }
            if !ls.is_empty() && hi <= lo * (1.0 + a) {
                proptest::prop_assert_eq!(e.median_mm, acc_of(&ls).estimate().median_mm);
            }
            // a strict majority within 1 + a is never withheld
            let mut s = ls.clone();
            s.sort_by(f32::total_cmp);
            let majority = (0..s.len()).any(|i| {
                2 * s.iter().filter(|&&x| x >= s[i] && x <= s[i] * (1.0 + a)).count() > s.len()
            });
            if majority {
                proptest::prop_assert!(e.median_mm.is_some());
            }
        }
    }

    #[test]
    fn axis_extent_of_a_rectangle() {
        let runs: Vec<Run> = (10..20).map(|y| Run { y, x0: 5, x1: 45 }).collect();
        let (lo, hi) = axis_extent(&runs, 24.5, 14.5, 1.0, 0.0, 1).unwrap();
        assert_eq!((lo, hi), (-19.5, 19.5));
        // rank 11: the 11th extreme pixel is in the next column
        let (lo, hi) = axis_extent(&runs, 24.5, 14.5, 1.0, 0.0, 11).unwrap();
        assert_eq!((lo, hi), (-18.5, 18.5));
    }

    #[test]
    fn axis_extent_counts_short_runs_once() {
        // a one-pixel-wide vertical line: every run is shorter than 2k
        let runs: Vec<Run> = (0..10).map(|y| Run { y, x0: 7, x1: 8 }).collect();
        // rank 3 from each end along +y: rows 2 and 7 (centre 4.5)
        let (lo, hi) = axis_extent(&runs, 7.0, 4.5, 0.0, 1.0, 3).unwrap();
        assert_eq!((lo, hi), (-2.5, 2.5));
    }

    proptest::proptest! {
        /// The row-sliced end-square SAD equals the pixel-by-pixel
        /// definition (pixels outside either image skipped), squares
        /// partly or wholly outside either image included.
        #[test]
        fn end_square_sad_matches_every_pixel(
            (lw, lh, rw, rh) in (1usize..50, 1usize..40, 1usize..50, 1usize..40),
            cl in (-30.0f32..80.0, -30.0f32..70.0),
            cr in (-30.0f32..80.0, -30.0f32..70.0),
            side in 0u32..40,
            seed in proptest::prelude::any::<u64>(),
        ) {
            let mut st = seed | 1;
            let mut px = || { st ^= st << 13; st ^= st >> 7; st ^= st << 17; (st >> 24) as u8 };
            let limg: Vec<u8> = (0..lw * lh).map(|_| px()).collect();
            let rimg: Vec<u8> = (0..rw * rh).map(|_| px()).collect();
            let lv = ImageView::packed(&limg, lw, lh).unwrap();
            let rv = ImageView::packed(&rimg, rw, rh).unwrap();
            let mut ops = 0u64;
            let got = end_square_sad(&lv, &rv, cl, cr, side, &mut ops);
            // the definition, pixel by pixel
            let sd = side.clamp(1, 1024) as i64;
            let hf = sd / 2;
            let rnd = |v: f32| micromath::F32(v).round().0 as i64;
            let (lx, ly, rx, ry) = (rnd(cl.0) - hf, rnd(cl.1) - hf, rnd(cr.0) - hf, rnd(cr.1) - hf);
            let (mut sum, mut n) = (0u64, 0u64);
            for j in 0..sd {
                for i in 0..sd {
                    let (xa, ya, xb, yb) = (lx + i, ly + j, rx + i, ry + j);
                    if xa < 0 || ya < 0 || xb < 0 || yb < 0 {
                        continue;
                    }
                    if let (Some(a), Some(b)) = (lv.get(xa as usize, ya as usize), rv.get(xb as usize, yb as usize)) {
                        sum += a.abs_diff(b) as u64;
                        n += 1;
                    }
                }
            }
            let want = if n == 0 || 4 * n < (sd * sd) as u64 { None } else { Some(sum as f32 / n as f32) };
            proptest::prop_assert_eq!(got, want);
            proptest::prop_assert_eq!(ops, n);
        }
    }

    proptest::proptest! {
        /// The rank-k extremes equal those of all mask pixels sorted (the
        /// float reference's definition, `reference::stereo::extent`).
        #[test]
        fn axis_extent_matches_sorting_every_pixel(
            rows in proptest::collection::vec((0u16..60, 1u16..40), 1..30),
            angle in -3.2f32..3.2,
            k in 1usize..=16,
        ) {
            let runs: Vec<Run> = rows
                .iter()
                .enumerate()
                .map(|(y, &(x0, n))| Run { y: y as u16, x0, x1: x0 + n })
                .collect();
            let (ux, uy) = (libm::cosf(angle), libm::sinf(angle));
            let (cx, cy) = (30.0f32, 12.0f32);
            let mut all: Vec<f32> = runs
                .iter()
                .flat_map(|r| (r.x0..r.x1).map(move |x| (x, r.y)))
                .map(|(x, y)| (y as f32 - cy) * uy - cx * ux + x as f32 * ux)
                .collect();
            all.sort_by(|a, b| a.total_cmp(b));
            let kk = k.min(all.len());
            let (lo, hi) = axis_extent(&runs, cx, cy, ux, uy, k).unwrap();
            proptest::prop_assert_eq!(lo, all[kk - 1]);
            proptest::prop_assert_eq!(hi, all[all.len() - kk]);
        }
    }

    proptest::proptest! {
        /// `near_other_object` agrees with checking every mask pixel of the
        /// other objects (the float reference's definition), and never
        /// counts the skipped object.
        #[test]
        fn near_other_object_matches_every_pixel(
            objs in proptest::collection::vec(
                (0u16..80, 0u16..80, proptest::collection::vec((0u16..20, 1u16..15), 1..8)),
                1..5,
            ),
            px in -5.0f32..100.0,
            py in -5.0f32..100.0,
            rad in 0.5f32..12.0,
            skip in 0usize..5,
        ) {
            let mut set = Objects::<8, 64>::new();
            for (ox, oy, rows) in &objs {
                let start = set.runs.len() as u32;
                let (mut x0m, mut x1m) = (u16::MAX, 0u16);
                for (k, &(dx, n)) in rows.iter().enumerate() {
                    let r = Run { y: oy + k as u16, x0: ox + dx, x1: ox + dx + n };
                    x0m = x0m.min(r.x0);
                    x1m = x1m.max(r.x1);
                    set.runs.push(r).unwrap();
                }
                let mut o = Object {
                    bbox: Roi::new(x0m as u32, *oy as u32, (x1m - x0m) as u32, rows.len() as u32),
                    ..Object::default()
                };
                o.runs.start = start;
                o.runs.len = rows.len() as u32;
                set.items.push(o).unwrap();
            }
            let brute = set.items.iter().enumerate().any(|(k, o)| {
                k != skip
                    && set.runs_of(o).iter().any(|r| {
                        (r.x0..r.x1).any(|x| {
                            let (dx, dy) = (x as f32 - px, r.y as f32 - py);
                            dx * dx + dy * dy <= rad * rad
                        })
                    })
            });
            proptest::prop_assert_eq!(near_other_object(&set, skip, (px, py), rad), brute);
        }
    }

    #[test]
    fn wholly_inside_needs_margin_in_both_views() {
        let a = Roi::new(10, 10, 50, 20);
        assert!(wholly_inside(&a, &a, 100, 100, 1));
        assert!(!wholly_inside(&a, &Roi::new(0, 10, 50, 20), 100, 100, 1));
        assert!(!wholly_inside(&a, &Roi::new(50, 10, 50, 20), 100, 100, 1));
    }
}
