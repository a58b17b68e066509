//! Automatic fish segmentation (Section III, Fig. 2; mesh removal of
//! Section V.A) on one rectified 8-bit frame.
//!
//! Stages, data flowing one way:
//! 1. [`coarse`]: trawl-mesh removal, morphological gradient (by default
//!    on the frame box-averaged 4 × 4, with a hysteresis threshold — beyond
//!    the paper; `coarse_scale = 1` is the paper's 7 × 7 gradient at full
//!    resolution with one global threshold), connected components →
//!    elliptic local regions (III.A).
//! 2. [`local`], per region: double local thresholding (eq. (1)), 3 × 3
//!    median, histogram backprojection (eq. (2)–(3)), area and variance
//!    rejection (eq. (4)–(6); by default the variance limit follows the
//!    frame's measured noise, [`local::variance_limit`]), closing then
//!    opening (III.D), and (beyond the paper) an elongation test and an
//!    edge test on the final objects ([`local::elongated_enough`],
//!    [`local::edge_sharp_enough`]); a τ_high at or below the water is
//!    raised 2 water σ above it (`Params::high_floor_sigmas`).
//!
//!    Between the final labelling and the objects' statistics (beyond the
//!    paper, `Params::split_merged`, default off), [`split`] cuts objects that are two
//!    touching fish where a higher threshold separates them into stable,
//!    elongated parts.
//!
//!    After a region's objects are found (beyond the paper,
//!    `Params::dim_level`, default on), its pixels within the disk's side of
//!    them are cleared and the region is thresholded again, once: the
//!    "dim level" finds the dim fish beside a bright one that eq. (1)'s
//!    τ_low, set between the two, left out ([`local`]).
//!
//! `Params { coarse_scale: 1, variance_literal: true, min_elongation: 1.0,
//! split_merged: false, dim_level: false, high_floor_sigmas: 0.0,
//! edge_step_ratio: 0.0, min_fill: 0.0, mesh_residue_ratio: 0.0, .. }` is the paper's Section III
//! exactly.
//! 3. Here: the objects of all regions are merged into one
//!    [`Objects`] set — duplicates removed, capacity enforced.
//!
//! **One fish, one object.** Elliptic regions of neighbouring fish overlap,
//! so a fish can be segmented in several regions (whole in its own, often
//! cut by the ellipse in a neighbour's). A new object whose mask shares
//! more than half of the smaller mask's pixels with an object already
//! emitted is the same fish: the one of the lower level is kept (a fish
//! thresholded in its own region over its dim-level copy from a
//! neighbour's), then the larger (on a tie the first), the other counted
//! in [`SegmentStats::duplicates`]. The cut-off partial copy is always the
//! smaller, so the whole fish survives.
//!
//! **Capacity.** `Objects<N, R>` holds `N` objects and `R` mask runs. When
//! either is full, the smallest objects go first (an incoming object smaller
//! than everything kept is itself dropped); every drop is counted in
//! `Objects::dropped` and [`SegmentStats::dropped`].
//!
//! **Memory.** All scratch lives in the caller's workspace of
//! [`workspace_size`]`(width, height, max_roi_pixels)` bytes: two frame
//! buffers (mesh-free frame, gradient), `O(width)` labelling tables, and
//! 8 bytes per pixel of the largest region of interest (plus 8 bytes per
//! frame row for the run table of eq. (4)'s first labelling,
//! [`crate::label::label_runs_in`]). A region whose
//! bounding box exceeds the ROI capacity is shrunk about its centre until it
//! fits ([`SegmentStats::regions_shrunk`]). Stack use per call is a few KiB
//! (five 256-entry `u32` histograms and a lookup table in the deepest frame;
//! the split step, [`split`], adds one 16-byte box per object of a region,
//! 4 KiB, and works in the region's own buffers: workspace size unchanged).
//!
//! For 2048 × 2048 frames and [`RECOMMENDED_MAX_ROI_PIXELS`] (1 Mpx):
//! `workspace_size(2048, 2048, 1 << 20)` = 18 125 140 bytes (17.3 MiB):
//! 8 MiB for the two frame buffers (the second one, the full-resolution
//! gradient, also holds the 4 × 4-downsampled frame, its gradient, labels
//! and masks: 2.5 MiB, so the reduced-resolution pass costs no memory), 1 MiB for the morphology ring (sized
//! for disks up to 31 × 31), about 0.3 MiB of labelling tables and region
//! records, 16 KiB of run-table rows, and 8 MiB of ROI buffers (measured by the
//! `full_size_frame_with_recommended_capacities` test). Recommended output
//! capacity: `Objects<64, 16384>` (106 264 bytes; one run per mask row, so
//! 16384 runs hold 64 fish of 256 rows on average).
//!
//! Pixels are integers throughout; f32 (via `libm`, explicitly) is used
//! only per component or per region (PCA, ellipse spans, ratio histogram).

pub mod coarse;
pub mod local;
pub mod split;
mod workspace;

pub use workspace::{
    fixed_size, lowres_size, workspace_size, BYTES_PER_ROI_PIXEL, MAX_REGIONS, MAX_ROI_COMPONENTS,
};

use crate::error::{ImageError, ParamError};
use crate::image::{ImageView, Roi};
use crate::label::Moments;
use crate::object::{Object, Objects, OrientedBox, Run, RunSpan, HIST_BINS};
use crate::params::Params;

/// The ROI capacity this crate recommends for 2048 × 2048 frames: 1 Mpx
/// (1024 × 1024), the bounding box of a 1.5×-enlarged ellipse around a fish
/// about 700 px long at any angle.
pub const RECOMMENDED_MAX_ROI_PIXELS: usize = 1 << 20;

/// An elliptic local region (Section III.A), frame coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Region {
    /// Centre x.
    pub cx: f32,
    /// Centre y.
    pub cy: f32,
    /// Semi-axis along the first principal axis (already enlarged).
    pub a: f32,
    /// Semi-axis along the second principal axis (already enlarged).
    pub b: f32,
    /// Angle of the first principal axis from +x, radians (y down).
    pub angle: f32,
    /// Pixels of the coarse component.
    pub coarse_area: u32,
}

/// Why a frame could not be segmented at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SegmentError {
    /// The parameters are invalid.
    Params(ParamError),
    /// The frame is unusable.
    Image(ImageError),
    /// The frame is wider or taller than 65535 pixels (mask runs are `u16`).
    FrameTooLarge,
    /// The workspace is smaller than [`fixed_size`] plus alignment.
    WorkspaceTooSmall,
}

impl core::fmt::Display for SegmentError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SegmentError::Params(e) => write!(f, "segmentation: {e}"),
            SegmentError::Image(e) => write!(f, "segmentation: {e}"),
            SegmentError::FrameTooLarge => write!(f, "segmentation: frame larger than 65535 px"),
            SegmentError::WorkspaceTooSmall => write!(f, "segmentation: workspace too small"),
        }
    }
}

impl core::error::Error for SegmentError {}

/// Per-step counters of one [`segment_frame`] call.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SegmentStats {
    /// Global threshold applied to the morphological gradient (the high,
    /// seed threshold of the hysteresis at reduced resolution). Grey
    /// levels at `coarse_scale` 1, sixteenths of a grey level otherwise.
    pub gradient_threshold: u16,
    /// The low (growing) threshold of the hysteresis; equals
    /// `gradient_threshold` at `coarse_scale` 1.
    pub gradient_threshold_low: u16,
    /// The frame's robust white-noise σ, sixteenths of a grey level
    /// ([`crate::noise::noise_sigma16`] on the rectified input frame).
    pub noise_sigma16: u32,
    /// The variance limit eq. (6) applied (θ_V, or θ_V scaled to the
    /// measured noise; see [`local`]).
    pub var_limit: f32,
    /// Connected components of the thresholded gradient.
    pub coarse_components: u32,
    /// Of those, skipped as smaller than `area_min / 4`.
    pub coarse_small: u32,
    /// Regions processed.
    pub regions: u32,
    /// Regions not kept because [`MAX_REGIONS`] was reached (smallest first).
    pub regions_dropped: u32,
    /// Regions shrunk to fit the ROI capacity.
    pub regions_shrunk: u32,
    /// Regions skipped: no pixel inside, or no ROI capacity at all.
    pub regions_empty: u32,
    /// Regions skipped because the ellipse holds fewer than `area_min`
    /// pixels (no object in it could pass eq. (4)).
    pub regions_small: u32,
    /// Components rejected by area, eq. (4) (speckle included).
    pub rejected_area: u32,
    /// Components rejected by variance, eq. (5)–(6).
    pub rejected_variance: u32,
    /// Final objects rejected by the elongation test
    /// ([`local::elongated_enough`]).
    pub rejected_shape: u32,
    /// Objects dropped by the fill test (`local::solid_enough`).
    pub rejected_fill: u32,
    /// Final objects rejected by the edge test
    /// ([`local::edge_sharp_enough`], `Params::edge_step_ratio`).
    pub rejected_edge: u32,
    /// Final objects rejected by the mesh-residue test
    /// ([`local::not_mesh_residue`], `Params::mesh_residue_ratio`).
    pub rejected_mesh: u32,
    /// Dim-level objects dropped as parts of a larger level-0 object they
    /// touch (`Params::dim_level`).
    pub rejected_fragment: u32,
    /// Regions thresholded at the dim level (`Params::dim_level`).
    pub dim_levels: u32,
    /// Components past [`MAX_ROI_COMPONENTS`] in one region (not examined).
    pub label_overflow: u32,
    /// Extra objects made by splitting merged objects ([`split`]).
    pub split: u32,
    /// Splits found but not made: a grown part failed the shape test.
    pub split_cancelled: u32,
    /// Objects of the same fish found in overlapping regions (removed).
    pub duplicates: u32,
    /// Objects dropped by the `N`/`R` capacity of [`Objects`].
    pub dropped: u32,
    /// Objects output.
    pub objects: u32,
}

/// One object candidate from a region, before it enters [`Objects`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Candidate {
    pub m: Moments,
    pub sum: u64,
    pub sumsq: u64,
    pub hist: [u32; HIST_BINS],
    /// Thresholding level ([`Object::level`]).
    pub level: u8,
}

/// The final components of a region, ROI coordinates: a run table
/// ([`crate::label::label_runs_in`]) or, after the split of merged objects
/// (which works on label rows), a packed label image `rw` wide.
pub(crate) enum Components<'a> {
    Runs {
        runs: &'a [[i32; 2]],
        row_start: &'a [u32],
    },
    Labels {
        labels: &'a [i32],
        rw: usize,
    },
}

impl Components<'_> {
    /// Calls `f(label, x0, x1)` for every maximal run `[x0, x1)` of one
    /// non-zero label in ROI row `j`, left to right (none past the ROI).
    pub(crate) fn for_row(&self, j: usize, mut f: impl FnMut(i32, usize, usize)) {
        match self {
            Components::Runs { runs, row_start } => {
                for run in crate::label::runs_of_row(runs, row_start, j) {
                    let r = crate::label::run_span(run[0]);
                    if run[1] != 0 {
                        f(run[1], r.start, r.end);
                    }
                }
            }
            Components::Labels { labels, rw } => {
                let row = labels.get(j * rw..(j + 1) * rw).unwrap_or(&[]);
                let mut i = 0;
                while i < row.len() {
                    let v = row[i];
                    let mut e = i + 1;
                    if v == 0 {
                        e = find_label(row, e, 0, false);
                    } else {
                        e = find_label(row, e, v, false);
                        f(v, i, e);
                    }
                    i = e;
                }
            }
        }
    }
}

/// Where a candidate's mask is: the pixels of label `label` of `comp`
/// (ROI `roi`).
pub(crate) struct MaskRef<'a> {
    pub comp: &'a Components<'a>,
    pub roi: Roi,
    pub label: i32,
}

impl MaskRef<'_> {
    /// Calls `f(x0, x1)` for every maximal run `[x0, x1)` (frame columns) of
    /// the mask in frame row `y` within columns `[xa, xb)`, left to right.
    fn for_runs(&self, y: u32, xa: u32, xb: u32, mut f: impl FnMut(u32, u32)) {
        if y < self.roi.y || y >= self.roi.bottom() {
            return;
        }
        let (rx, label) = (self.roi.x, self.label);
        self.comp.for_row((y - self.roi.y) as usize, |l, x0, x1| {
            let (a, b) = ((rx + x0 as u32).max(xa), (rx + x1 as u32).min(xb));
            if l == label && a < b {
                f(a, b);
            }
        });
    }
}

/// First index `≥ i` of `row` whose label equals `label` (`eq`) or differs
/// from it (`!eq`); `row.len()` when there is none. Stretches without one
/// are skipped 8 labels per test (a branch-free compare that vectorises).
fn find_label(row: &[i32], mut i: usize, label: i32, eq: bool) -> usize {
    while let Some(c) = row.get(i..i + 8) {
        if c.iter().fold(false, |a, &l| a | ((l == label) == eq)) {
            break;
        }
        i += 8;
    }
    while let Some(&l) = row.get(i) {
        if (l == label) == eq {
            return i;
        }
        i += 1;
    }
    row.len()
}

/// What happened in one region, for tracing and for `fishtrack compare`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RegionTrace {
    /// The region (after any shrinking to the ROI capacity).
    pub region: Region,
    /// Its bounding box.
    pub roi: Roi,
    /// 0: the region's thresholds; 1: its second, dim level
    /// (`Params::dim_level`), on the pixels level 0's objects leave.
    pub level: u8,
    /// Otsu's τ on the ellipse's pixels.
    pub tau: u8,
    /// ⌊τ_low⌋ of eq. (1).
    pub t_low: u8,
    /// ⌊τ_high⌋ of eq. (1).
    pub t_high: u8,
}

/// Segments `img` (a rectified 8-bit frame) into `out`.
///
/// `ws` must hold at least [`workspace_size`]`(width, height, m)` bytes;
/// whatever exceeds the frame part becomes ROI capacity `m`.
pub fn segment_frame<const N: usize, const R: usize>(
    img: ImageView<'_>,
    params: &Params,
    ws: &mut [u8],
    out: &mut Objects<N, R>,
) -> Result<SegmentStats, SegmentError> {
    segment_frame_traced(img, params, ws, out, &mut |_| {})
}

/// [`segment_frame`], calling `trace` for every region that reaches the
/// thresholding step.
pub fn segment_frame_traced<const N: usize, const R: usize>(
    img: ImageView<'_>,
    params: &Params,
    ws: &mut [u8],
    out: &mut Objects<N, R>,
    trace: &mut dyn FnMut(&RegionTrace),
) -> Result<SegmentStats, SegmentError> {
    out.clear();
    params.validate().map_err(SegmentError::Params)?;
    let (w, h) = (img.width(), img.height());
    if w > u16::MAX as usize || h > u16::MAX as usize {
        return Err(SegmentError::FrameTooLarge);
    }
    let mut ws = workspace::Ws::carve(ws, w, h).ok_or(SegmentError::WorkspaceTooSmall)?;
    // the noise estimate first: it reads a quarter of the frame's rows,
    // which the mesh removal then finds in cache (read after the coarse
    // pass, they had left it)
    let mut stats = SegmentStats {
        noise_sigma16: crate::noise::noise_sigma16(img),
        ..SegmentStats::default()
    };
    let n_regions = coarse::coarse_regions(img, params, &mut ws, &mut stats)?;
    let n = w * h;
    let frame = ImageView::packed(&ws.filtered[..n], w, h).map_err(SegmentError::Image)?;
    let bg = if params.background && n_regions > 0 {
        Some(coarse::background_grid(frame, params, ws.grad)?)
    } else {
        None
    };
    stats.var_limit = local::variance_limit(params, stats.noise_sigma16);
    for rw in ws.regions.iter().take(n_regions) {
        let region = coarse::decode_region(rw);
        stats.regions += 1;
        local::segment_region(
            img,
            frame,
            &region,
            bg.as_ref(),
            params,
            &mut ws.roi,
            ws.spans,
            ws.stats,
            ws.disk,
            out,
            &mut stats,
            trace,
        )?;
    }
    compact_runs(out);
    stats.objects = out.items.len() as u32;
    stats.dropped = out.dropped;
    Ok(stats)
}

/// Number of pixels of `obj` (runs in `pool`) that are in `mask`.
fn overlap(pool: &[Run], obj: &Object, mask: &MaskRef<'_>) -> u32 {
    let s = obj.runs.start as usize;
    let e = s.saturating_add(obj.runs.len as usize);
    let mut n = 0u32;
    for r in pool.get(s..e).unwrap_or(&[]) {
        mask.for_runs(r.y as u32, r.x0 as u32, r.x1 as u32, |a, b| n += b - a);
    }
    n
}

/// Moves the runs of the kept objects to the front of the pool.
pub(crate) fn compact_runs<const N: usize, const R: usize>(out: &mut Objects<N, R>) {
    out.items.sort_unstable_by_key(|o| o.runs.start);
    let mut next = 0usize;
    for o in out.items.iter_mut() {
        let s = o.runs.start as usize;
        let l = o.runs.len as usize;
        if s != next && s.saturating_add(l) <= out.runs.len() {
            out.runs.copy_within(s..s + l, next);
        }
        o.runs.start = next as u32;
        next += l;
    }
    out.runs.truncate(next.min(out.runs.len()));
}

fn smallest<const N: usize, const R: usize>(out: &Objects<N, R>) -> Option<(usize, u32)> {
    let mut best: Option<(usize, u32)> = None;
    for (i, o) in out.items.iter().enumerate() {
        if best.is_none_or(|(_, a)| o.area < a) {
            best = Some((i, o.area));
        }
    }
    best
}

/// Adds a candidate to `out`: duplicate rule, then capacity rule (see the
/// module documentation).
pub(crate) fn emit<const N: usize, const R: usize>(
    out: &mut Objects<N, R>,
    cand: &Candidate,
    mask: &MaskRef<'_>,
    stats: &mut SegmentStats,
) {
    let m = &cand.m;
    let area = m.area.min(u32::MAX as u64) as u32;
    if area == 0 {
        return;
    }
    let bbox = Roi::new(
        m.x_min,
        m.y_min,
        m.x_max - m.x_min + 1,
        m.y_max - m.y_min + 1,
    );
    // duplicates: remove smaller copies, give up if a larger one exists
    loop {
        let mut smaller_dup = None;
        for (i, o) in out.items.iter().enumerate() {
            if o.bbox.intersect(&bbox).is_empty() {
                continue;
            }
            let ov = overlap(&out.runs, o, mask) as u64;
            if 2 * ov > o.area.min(area) as u64 {
                // a lower level (a fish thresholded in its own region)
                // wins over a higher one, then the larger object
                if (o.level, area) <= (cand.level, o.area) {
                    stats.duplicates += 1;
                    return;
                }
                smaller_dup = Some(i);
                break;
            }
        }
        match smaller_dup {
            Some(i) => {
                out.items.swap_remove(i);
                stats.duplicates += 1;
            }
            None => break,
        }
    }
    // runs of the candidate
    let mut n_runs = 0usize;
    for y in bbox.y..bbox.bottom() {
        mask.for_runs(y, bbox.x, bbox.right(), |_, _| n_runs += 1);
    }
    // capacity: objects
    if out.items.len() >= N {
        match smallest(out) {
            Some((i, a)) if a < area => {
                out.items.swap_remove(i);
                out.dropped += 1;
            }
            _ => {
                out.dropped += 1;
                return;
            }
        }
    }
    // capacity: runs
    if out.runs.len() + n_runs > R {
        compact_runs(out);
        while out.runs.len() + n_runs > R {
            match smallest(out) {
                Some((i, a)) if a < area => {
                    out.items.swap_remove(i);
                    out.dropped += 1;
                    compact_runs(out);
                }
                _ => {
                    out.dropped += 1;
                    return;
                }
            }
        }
    }
    // append runs, measure the oriented box on them
    let (cx, cy) = m.centroid();
    let (angle, _, _) = m.principal_axes();
    let (c, s) = (libm::cosf(angle), libm::sinf(angle));
    let (mut umin, mut umax, mut vmin, mut vmax) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    let start = out.runs.len();
    for y in bbox.y..bbox.bottom() {
        let mut full = false;
        mask.for_runs(y, bbox.x, bbox.right(), |x0, x| {
            if full {
                return;
            }
            let run = Run {
                y: y as u16,
                x0: x0 as u16,
                x1: x as u16,
            };
            if out.runs.push(run).is_err() {
                full = true; // cannot happen: room was made above
                return;
            }
            for (px, py) in [
                (x0 as f32 - 0.5, y as f32 - 0.5),
                (x0 as f32 - 0.5, y as f32 + 0.5),
                (x as f32 - 0.5, y as f32 - 0.5),
                (x as f32 - 0.5, y as f32 + 0.5),
            ] {
                let (dx, dy) = (px - cx, py - cy);
                let u = dx * c + dy * s;
                let v = -dx * s + dy * c;
                umin = umin.min(u);
                umax = umax.max(u);
                vmin = vmin.min(v);
                vmax = vmax.max(v);
            }
        });
    }
    let (um, vm) = (0.5 * (umin + umax), 0.5 * (vmin + vmax));
    let obb = long_axis_first(OrientedBox {
        cx: cx + um * c - vm * s,
        cy: cy + um * s + vm * c,
        half_w: 0.5 * (umax - umin),
        half_h: 0.5 * (vmax - vmin),
        angle,
    });
    let n = m.area as f64;
    let mean = cand.sum as f64 / n;
    let variance = if m.area > 1 {
        ((cand.sumsq as f64 - cand.sum as f64 * mean) / (n - 1.0)).max(0.0)
    } else {
        0.0
    };
    let obj = Object {
        bbox,
        obb,
        area,
        mean: mean as f32,
        variance: variance as f32,
        hist: cand.hist,
        runs: RunSpan {
            start: start as u32,
            len: (out.runs.len() - start) as u32,
        },
        level: cand.level,
    };
    if out.items.push(obj).is_err() {
        out.dropped += 1;
    }
}

#[cfg(test)]
mod tests;

/// Makes the box's first axis the longer one (Fig. 3: the width w_o is the
/// fish's length). The variance-maximising PCA axis of a near-round or
/// oddly shaped mask can have the smaller extent; then the extents are
/// swapped and the angle turned by 90°, kept in `(-π/2, π/2]`.
pub(crate) fn long_axis_first(b: OrientedBox) -> OrientedBox {
    if b.half_w >= b.half_h {
        return b;
    }
    let half_pi = core::f32::consts::FRAC_PI_2;
    let mut angle = b.angle + half_pi;
    if angle > half_pi {
        angle -= core::f32::consts::PI;
    }
    OrientedBox {
        half_w: b.half_h,
        half_h: b.half_w,
        angle,
        ..b
    }
}

#[cfg(test)]
mod find_label_tests {
    use super::find_label;
    use proptest::prelude::*;

    proptest! {
        /// The blocked search equals a plain position scan, from any start.
        #[test]
        fn find_label_equals_position(
            row in proptest::collection::vec(0i32..3, 0..70),
            i in 0usize..75,
            label in 0i32..3,
            eq in any::<bool>(),
        ) {
            let want = row
                .get(i..)
                .and_then(|r| r.iter().position(|&l| (l == label) == eq))
                .map_or(row.len(), |k| i + k);
            prop_assert_eq!(find_label(&row, i, label, eq), want);
        }
    }
}
