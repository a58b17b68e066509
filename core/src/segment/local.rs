//! Segmentation inside one elliptic local region (Section III.A–D).
//!
//! Conventions (the reference in `host/src/reference/segment.rs` follows
//! the same ones):
//! - The region is the ellipse `(p·u)²/a² + (p·v)²/b² ≤ 1` around the
//!   coarse component's centroid, pixel centres at integer coordinates;
//!   its pixels are found per row as one span. Everything outside the
//!   ellipse is background and takes no part in any histogram.
//! - The thresholds and masks of eq. (1)–(3) see the region's pixels
//!   box-averaged `local_smooth × local_smooth` ([`crate::smooth`]; beyond
//!   the paper, 1 turns it off): the noise σ drops by the box side, so a
//!   fish a few grey levels above the water thresholds as one body. The
//!   objects' statistics (mean, variance, histogram) use the unsmoothed
//!   pixels.
//! - Otsu's τ on the ellipse's 256-bin histogram; τ_low, τ_high by eq. (1)
//!   ([`crate::threshold::shifted_threshold`]); `M_x = {p > ⌊τ_x⌋}` (the
//!   OpenCV/imageproc "foreground is p > t" convention). The high floor
//!   (beyond the paper, `Params::high_floor_sigmas`, default 2): a
//!   ⌊τ_high⌋ at or below the water's median (Otsu's lower class,
//!   [`water_level`]) is raised to that many water σ above it. On a fish
//!   3–5 σ above the water, Otsu's τ falls in the water's noise and eq.
//!   (1) puts both thresholds there, so M_high holds half the water as
//!   M_low does, eq. (2)'s ratio is about 1 on every bin and the fish
//!   floods into a water-sized object that the contrast test rejects
//!   (measured on seeds 1–12: seg recall 0.757 → 0.780 with the floor
//!   alone; README, session 18).
//! - Both masks get the 3 × 3 median (replicated ROI border, as
//!   `cv2.medianBlur`), then are restricted to the ellipse again.
//! - `H_low`, `H_high`: `hist_bins`-bin histograms of the pixels under the
//!   two masks, the bins spanning the region's grey-level range
//!   `[⌊τ_low⌋, p99]` ([`crate::hist::range_bin`]: levels outside are
//!   clamped into the end bins); the ratio histogram of eq. (2)
//!   backprojected on the ellipse and thresholded by θ_bp, eq. (3), gives B.
//!   Ablations: `double_threshold = false` → B = median(M_τ);
//!   `backprojection = false` → B = median(M_high).
//! - Components of B (8-connected): eq. (4) keeps `area_min ≤ A ≤ area_max`,
//!   eq. (5)–(6) keeps unbiased variance `σ² ≥` [`variance_limit`]: θ_V
//!   (`var_min`) with `variance_literal`, by default θ_V scaled down to the
//!   frame's measured noise on quiet frames (beyond the paper).
//! - Closing then opening with the `disk_size` disk (Section III.D), OpenCV
//!   border convention, then components again; eq. (4) is applied once
//!   more so that fragments split off by the opening are not output, and
//!   (beyond the paper) objects less elongated than `min_elongation` are
//!   dropped ([`elongated_enough`]) unless the frame border cuts them
//!   ([`cut_by_border`]), and (beyond the paper, `Params::edge_step_ratio`)
//!   objects whose outline is not a step are dropped
//!   ([`edge_sharp_enough`]): a fish's outline is sharp, a glow of
//!   backscatter or strobe haze thresholded near the water rises smoothly
//!   (seeds 1–12 with the high floor: seg precision 0.900 → 0.936 at
//!   recall 0.780 → 0.776); an object of under `weak_contrast_sigmas`
//!   water σ of contrast needs the higher `weak_edge_step_ratio`
//!   ([`required_edge_ratio`]: the top of a smooth debris blob clears the
//!   contrast rescue and the plain edge test by a hair; seeds 1–30 seg
//!   precision 0.950 → 0.957 at recall 0.799 → 0.797, session 37); and
//!   (beyond the paper, `Params::mesh_residue_ratio`) objects that are
//!   mostly what the mesh removal took away are dropped
//!   ([`not_mesh_residue`]: the line openings leave a faint copy of the
//!   net, a few grey levels above the water, in the mesh-free frame;
//!   session 38).
//! - The dim level (beyond the paper, `Params::dim_level`): Otsu's τ of a
//!   region holding a bright fish and a dim one falls between them and
//!   eq. (1)'s τ_low above the dim one, which is lost. So once level 0
//!   (all of the above) has emitted objects, the pixels within Chebyshev
//!   distance `disk_size` of them are set to 0 ([`clear_grown`]: the
//!   blurred rims of a bright fish would ring it) and taken out of the
//!   histogram, and the region runs once more (level 1) on what is left —
//!   a final component the tests refused is not cleared: it is no fish
//!   found, and it may be a fish whose level-0 mask was only its brightest
//!   texture (seed 5, frame 13: a fish beside a brighter one, its ragged
//!   mask refused by the edge test, now whole at level 1; seeds 1–30 seg
//!   recall 0.746 → 0.748, success 581 → 582) —
//!   only if its τ is below level 0's and at least half an object's area
//!   stands [`DIM_LEVEL_SIGMAS`] water σ above the remainder's water
//!   (Otsu's lower class; the gate costs one histogram). Its τ_low, τ_high
//!   are kept [`DIM_LEVEL_FLOOR`] σ above the water, its objects must pass
//!   the contrast test at `DIM_LEVEL_SIGMAS` (the variance limit is no
//!   test there: the remainder's water has no fish to set it apart), and a
//!   level-1 object touching the cleared pixels and under half the largest
//!   level-0 object is that object's dim tail or fin, not a fish
//!   (`SegmentStats::rejected_fragment`). Level-0 objects win duplicates
//!   ([`super::emit`]).
//!
//! Both labellings (eq. (4)'s and the final one) are run tables in the
//! label buffer ([`crate::label::label_runs_in`]: the same components and
//! numbers as a label image; the final one is a label image only with
//! `split_merged`, whose split works on label rows).
//!
//! Memory bound: the ROI buffers of the workspace (8 bytes per ROI pixel),
//! one span and one run-table row start per ROI row (the label buffer has
//! one extra word per frame row, so the run table always fits),
//! [`super::MAX_ROI_COMPONENTS`] statistics records;
//! on the stack two 256-bin histograms and a 256-entry table.

use super::workspace::{RoiBufs, STAT_WORDS};
use super::{
    emit, Candidate, Components, MaskRef, Region, RegionTrace, SegmentError, SegmentStats,
};
use crate::background::BgGrid;
use crate::hist::{
    add_masked_pair_256, add_row_256, bin_of, fold_bins_range, median_mad, percentile_256,
    ratio_backprojection_lut_range, sum_sumsq,
};
use crate::image::{ImageView, Roi};
use crate::label::{
    as_run_table, label_components_in, label_runs_in, run_span, runs_of_row, Moments,
};
use crate::morph::{close_disk_in_place, median3_binary_in, open_disk_in_place, Disk};
use crate::object::{Objects, HIST_BINS};
use crate::params::Params;
use crate::smooth::box_mean_roi;
use crate::threshold::{lower_class_mean, otsu, shifted_threshold};

/// Upper end of the backprojection histograms' grey-level range: this
/// percentile of the ellipse's pixels ([`crate::hist::range_bin`]).
pub const BP_RANGE_PERCENTILE: u32 = 99;

/// Reference noise variance (grey levels², of the rectified input frame)
/// of the noise-relative variance test: θ_V applies unchanged to frames at
/// least this noisy and is scaled down in proportion to the measured
/// noise variance on quieter ones.
pub const NOISE_REF_VAR: f32 = 9.0;

/// Least contrast, in water σ, of an object of the dim level
/// (`Params::dim_level`).
pub const DIM_LEVEL_SIGMAS: f32 = 4.0;

/// Least τ_low and τ_high of the dim level above the water, in water σ.
pub const DIM_LEVEL_FLOOR: [f32; 2] = [1.0, 2.0];

/// The limit of eq. (6). Paper-faithful (`variance_literal`): θ_V. By
/// default (beyond the paper) `θ_V · min(1, σ_n² / NOISE_REF_VAR)`, σ_n
/// the frame's measured white-noise σ (`noise_sigma16 / 16`,
/// [`crate::noise::noise_sigma16`]).
///
/// Why: an object's pixel variance is its texture and shading plus the
/// sensor noise, and the pieces of pure noise that Otsu splits off an
/// empty region have a variance that is a fraction of the noise variance.
/// On footage as noisy as the paper's, θ_V = 30 separates the two; on a
/// quiet frame (σ_n² ≈ 1–2 here) the same fixed 30 also rejects every
/// dim, low-texture fish (contrast 7–15 grey levels, variance 5–30) while
/// noise pieces there have variances of 1–4, so the limit follows the
/// noise down. It never rises above θ_V, so a noisy frame keeps the
/// paper's rule. [`NOISE_REF_VAR`] was chosen on seeds 1–4 of the
/// synthetic hauls and checked on seeds 5–8 (README, "Where FishTrack
/// stands").
pub fn variance_limit(params: &Params, noise_sigma16: u32) -> f32 {
    if params.variance_literal {
        return params.var_min;
    }
    let s = (noise_sigma16 as f32 / 16.0).max(params.noise_floor);
    params.var_min * (s * s / NOISE_REF_VAR).min(1.0)
}

/// The shape test (beyond the paper): `√(λ₁/λ₂) ≥ e` on the final
/// object's coordinate covariance (for a filled rectangle √(λ₁/λ₂) is its
/// aspect ratio). Fish are elongated bodies — the paper's oriented box
/// measures their length along the first principal axis — while the
/// pieces of noise, glow and round debris that pass eq. (4)–(6) are not.
/// `e ≤ 1` turns the test off (the paper's pipeline).
pub fn elongated_enough(m: &Moments, e: f32) -> bool {
    if e <= 1.0 {
        return true;
    }
    let (_, l1, l2) = m.principal_axes();
    l1 >= e * e * l2
}

/// The fill test (beyond the paper, `Params::min_fill`): the object's
/// pixels cover at least `f` of its equivalent ellipse, whose area is
/// `π · 2√λ₁ · 2√λ₂` (the ellipse with the object's second moments: a
/// filled ellipse fills it exactly, a filled rectangle to 3/π). A sparse
/// net of mesh strands spreads its moments over the patch it spans while
/// covering a fraction of it (seed 42's mesh band objects: 0.13–0.3;
/// matched fish on seeds 1–10: 1st percentile 0.45). `f ≤ 0` turns the
/// test off; a degenerate (one-line) object passes it.
pub fn solid_enough(m: &Moments, f: f32) -> bool {
    let ellipse = ellipse_area(m);
    f <= 0.0 || ellipse <= 0.0 || m.area as f32 >= f * ellipse
}

/// The area `π · 2√λ₁ · 2√λ₂` of the object's equivalent ellipse
/// ([`solid_enough`]); 0 for a degenerate (one-line or empty) object.
pub fn ellipse_area(m: &Moments) -> f32 {
    let (_, l1, l2) = m.principal_axes();
    4.0 * core::f32::consts::PI * libm::sqrtf(l1 * l2)
}

/// Whether an object reaches within `margin / 4` pixels of the frame
/// border (beyond the paper): such a fish is cut by the frame (or by the
/// unmapped edge of the rectified frame), so its visible part need not be
/// elongated, and [`elongated_enough`] is not applied to it.
pub fn cut_by_border(m: &Moments, width: usize, height: usize, params: &Params) -> bool {
    let e = params.margin / 4;
    m.x_min <= e
        || m.y_min <= e
        || (m.x_max as usize).saturating_add(e as usize) >= width.saturating_sub(1)
        || (m.y_max as usize).saturating_add(e as usize) >= height.saturating_sub(1)
}

/// Bounding box (clipped to the frame) of an ellipse.
pub fn ellipse_roi(r: &Region, width: usize, height: usize) -> Roi {
    let (c, s) = (libm::cosf(r.angle), libm::sinf(r.angle));
    let ex = libm::sqrtf(r.a * r.a * c * c + r.b * r.b * s * s);
    let ey = libm::sqrtf(r.a * r.a * s * s + r.b * r.b * c * c);
    let clip = |v: f32, hi: usize| -> u32 {
        if !v.is_finite() || v < 0.0 {
            0
        } else if v > hi as f32 {
            hi as u32
        } else {
            v as u32
        }
    };
    let x0 = clip(libm::ceilf(r.cx - ex), width);
    let x1 = clip(libm::floorf(r.cx + ex) + 1.0, width);
    let y0 = clip(libm::ceilf(r.cy - ey), height);
    let y1 = clip(libm::floorf(r.cy + ey) + 1.0, height);
    if x1 <= x0 || y1 <= y0 {
        Roi::default()
    } else {
        Roi::new(x0, y0, x1 - x0, y1 - y0)
    }
}

/// Columns `[x0, x1)` (ROI coordinates) of the ellipse on each ROI row.
fn ellipse_spans(r: &Region, roi: Roi, spans: &mut [[i32; 2]]) {
    let (c, s) = (libm::cosf(r.angle), libm::sinf(r.angle));
    let (ia2, ib2) = (1.0 / (r.a * r.a), 1.0 / (r.b * r.b));
    let qa = c * c * ia2 + s * s * ib2;
    for (j, sp) in spans.iter_mut().enumerate().take(roi.h as usize) {
        *sp = [0, 0];
        let dy = (roi.y as usize + j) as f32 - r.cy;
        let qb = 2.0 * dy * c * s * (ia2 - ib2);
        let qc = dy * dy * (s * s * ia2 + c * c * ib2) - 1.0;
        let disc = qb * qb - 4.0 * qa * qc;
        if disc.is_nan() || disc < 0.0 || qa.is_nan() || qa <= 0.0 {
            continue;
        }
        let sq = libm::sqrtf(disc);
        let d1 = (-qb - sq) / (2.0 * qa);
        let d2 = (-qb + sq) / (2.0 * qa);
        let xl = libm::ceilf(r.cx + d1) - roi.x as f32;
        let xr = libm::floorf(r.cx + d2) - roi.x as f32 + 1.0;
        let xl = xl.clamp(0.0, roi.w as f32) as i32;
        let xr = xr.clamp(0.0, roi.w as f32) as i32;
        if xr > xl {
            *sp = [xl, xr];
        }
    }
}

fn view(buf: &[u8], rw: usize, rh: usize) -> Result<ImageView<'_>, SegmentError> {
    ImageView::packed(buf, rw, rh).map_err(SegmentError::Image)
}

/// Median and robust σ (1.4826 · MAD, at least 1) of the levels `0..=tau`
/// of `h` — the water, Otsu's lower class (eq. (1)).
pub fn water_level(h: &[u32; 256], tau: u8) -> (u8, f32) {
    let lower = h.get(..=tau as usize).unwrap_or(&[]);
    if lower.iter().all(|&v| v == 0) {
        return (tau, 1.0);
    }
    let (med, mad) = median_mad(lower, &mut [0u32; 256]);
    (med as u8, (1.4826 * mad as f32).max(1.0))
}

/// Section III.D's closing then opening by `disk` of the packed
/// `rw × rh` mask `a`, computed on the window of `a` that holds its
/// nonzero pixels' box `bbox` (`[x0, y0, x1, y1)`) grown by `2r + 2` (r the
/// disk's radius) and clipped to the mask: outside that window both results
/// are 0 (a closing then opening never reaches farther than 2r from the
/// mask), and inside it every neighbourhood the two operations read lies in
/// the window or beyond the mask's border, where the window's border is the
/// mask's. So the result equals the operations on the whole mask, for the
/// cost of the window (a region's ellipse box is several times its
/// objects'). `win` holds the window packed, `tmp` is the operations'
/// scratch; both at least `rw · rh` bytes. Returns the window `[x0, y0,
/// x1, y1)` (empty for an empty mask): the result is 0 outside it.
fn close_open_window(
    a: &mut [u8],
    (rw, rh): (usize, usize),
    bbox: [usize; 4],
    disk: &Disk,
    win: &mut [u8],
    tmp: &mut [u8],
    disk_scratch: &mut [u8],
) -> Result<[usize; 4], SegmentError> {
    if bbox[0] >= bbox[2] || bbox[1] >= bbox[3] {
        return Ok([0; 4]); // an empty mask stays empty
    }
    let m = 2 * disk.radius + 2;
    let (x0, y0) = (bbox[0].saturating_sub(m), bbox[1].saturating_sub(m));
    let (x1, y1) = ((bbox[2] + m).min(rw), (bbox[3] + m).min(rh));
    let (ww, wh) = (x1 - x0, y1 - y0);
    let n = ww * wh;
    let win = win.get_mut(..n).ok_or(SegmentError::WorkspaceTooSmall)?;
    for (j, wrow) in win.chunks_exact_mut(ww).enumerate() {
        let src = a
            .get((y0 + j) * rw + x0..(y0 + j) * rw + x1)
            .ok_or(SegmentError::WorkspaceTooSmall)?;
        wrow.copy_from_slice(src);
    }
    close_disk_in_place(win, ww, wh, disk, tmp, disk_scratch)
        .map_err(|_| SegmentError::WorkspaceTooSmall)?;
    open_disk_in_place(win, ww, wh, disk, tmp, disk_scratch)
        .map_err(|_| SegmentError::WorkspaceTooSmall)?;
    for (j, wrow) in win.chunks_exact(ww).enumerate() {
        let dst = a
            .get_mut((y0 + j) * rw + x0..(y0 + j) * rw + x1)
            .ok_or(SegmentError::WorkspaceTooSmall)?;
        dst.copy_from_slice(wrow);
    }
    Ok([x0, y0, x1, y1])
}

/// Clears to 0 the pixels of the packed `rw × rh` buffer `d` within
/// Chebyshev distance `r` of a pixel of a final component of `comp`
/// whose label `l > 0` is kept (`keep[l − 1]`: the components emitted as
/// objects; all inside the window `win` = `[x0, y0, x1, y1)`): the
/// square dilation by `2r + 1`, separable — each run grown by `r` on both
/// sides into `marks`, then a running per-column count of the marked rows
/// within `r` (`count`, one row). `marks`, `count`: scratch of `rw · rh`
/// and `rw` bytes. Each cleared nonzero pixel inside the ellipse (`spans`,
/// row `j`'s columns `[s0, s1)`) is taken out of its histogram `h`, which
/// so stays the histogram of the ellipse's pixels without a second pass.
#[allow(clippy::too_many_arguments)]
fn clear_grown(
    comp: &Components<'_>,
    keep: &[bool],
    d: &mut [u8],
    (marks, count): (&mut [u8], &mut [u8]),
    (rw, rh): (usize, usize),
    win: [usize; 4],
    r: usize,
    spans: &[[i32; 2]],
    h: &mut [u32; 256],
) -> Result<(), SegmentError> {
    let (y0, y1) = (win[1], win[3].min(rh));
    if y0 >= y1 || r > 127 {
        return Ok(());
    }
    let (x0, x1) = (win[0].saturating_sub(r), (win[2] + r).min(rw));
    let marks = marks
        .get_mut(..rw * rh)
        .ok_or(SegmentError::WorkspaceTooSmall)?;
    let count = count.get_mut(..rw).ok_or(SegmentError::WorkspaceTooSmall)?;
    for j in y0..y1 {
        let row = marks
            .get_mut(j * rw..(j + 1) * rw)
            .ok_or(SegmentError::WorkspaceTooSmall)?;
        row.fill(0);
        comp.for_row(j, |l, i0, i1| {
            let kept = usize::try_from(l - 1).is_ok_and(|k| keep.get(k).copied().unwrap_or(false));
            if kept {
                if let Some(part) = row.get_mut(i0.saturating_sub(r)..(i1 + r).min(rw)) {
                    part.fill(1);
                }
            }
        });
    }
    let marks = &*marks;
    let row_of = |j: usize| marks.get(j * rw + x0..j * rw + x1).unwrap_or(&[]);
    let count = count.get_mut(x0..x1).unwrap_or(&mut []);
    count.fill(0);
    let jo0 = y0.saturating_sub(r);
    for j in y0..(jo0 + r).min(y1) {
        count.iter_mut().zip(row_of(j)).for_each(|(c, &m)| *c += m);
    }
    for jo in jo0..(y1 + r).min(rh) {
        // the marked rows within r of row jo: add jo + r, drop jo − r − 1
        if jo + r < y1 {
            count
                .iter_mut()
                .zip(row_of(jo + r))
                .for_each(|(c, &m)| *c += m);
        }
        if let Some(old) = jo.checked_sub(r + 1).filter(|&o| o >= y0 && o < y1) {
            count
                .iter_mut()
                .zip(row_of(old))
                .for_each(|(c, &m)| *c -= m);
        }
        let sp = spans.get(jo).copied().unwrap_or([0, 0]);
        let (s0, s1) = (sp[0].max(0) as usize, sp[1].max(0) as usize);
        if let Some(drow) = d.get_mut(jo * rw + x0..jo * rw + x1) {
            for (x, (p, &c)) in (x0..).zip(drow.iter_mut().zip(count.iter())) {
                if c > 0 {
                    if *p != 0 && x >= s0 && x < s1 {
                        let v = &mut h[*p as usize];
                        *v = v.saturating_sub(1);
                    }
                    *p = 0;
                }
            }
        }
    }
    Ok(())
}

/// Clears `rec` to an empty statistics record.
fn clear_rec(rec: &mut [u64; STAT_WORDS]) {
    *rec = [0; STAT_WORDS];
    Moments::EMPTY.to_words(&mut rec[..10]);
}

/// Segments one region and emits its objects into `out`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn segment_region<const N: usize, const R: usize>(
    raw: ImageView<'_>,
    frame: ImageView<'_>,
    region: &Region,
    bg: Option<&BgGrid<'_>>,
    params: &Params,
    bufs: &mut RoiBufs<'_>,
    spans: &mut [[i32; 2]],
    recs: &mut [[u64; STAT_WORDS]],
    disk_scratch: &mut [u8],
    out: &mut Objects<N, R>,
    stats: &mut SegmentStats,
    trace: &mut dyn FnMut(&RegionTrace),
) -> Result<(), SegmentError> {
    let (fw, fh) = (frame.width(), frame.height());
    let mut reg = *region;
    let mut roi = ellipse_roi(&reg, fw, fh);
    let mut tries = 0;
    while roi.area() as usize > bufs.max_pixels && tries < 8 {
        let f = libm::sqrtf(bufs.max_pixels as f32 / roi.area() as f32) * 0.98;
        reg.a *= f;
        reg.b *= f;
        roi = ellipse_roi(&reg, fw, fh);
        tries += 1;
    }
    if tries > 0 {
        stats.regions_shrunk += 1;
    }
    let n = roi.area() as usize;
    if roi.is_empty() || n > bufs.max_pixels {
        stats.regions_empty += 1;
        return Ok(());
    }
    let (rw, rh) = (roi.w as usize, roi.h as usize);
    let spans = spans.get_mut(..rh).ok_or(SegmentError::WorkspaceTooSmall)?;
    ellipse_spans(&reg, roi, spans);
    let pv = frame.sub(roi).map_err(SegmentError::Image)?;
    // the frame before the mesh removal, for the mesh-residue test
    let mesh_test = params.mesh_residue_ratio > 0.0 && params.mesh_line_len >= 3;
    let rv = raw.sub(roi).map_err(SegmentError::Image)?;
    // the columns of row j inside the ellipse (spans are within the ROI)
    let span = |sp: &[i32; 2]| (sp[0].max(0) as usize).min(rw)..(sp[1].max(0) as usize).min(rw);
    let a = bufs.a.get_mut(..n).ok_or(SegmentError::WorkspaceTooSmall)?;
    let b = bufs.b.get_mut(..n).ok_or(SegmentError::WorkspaceTooSmall)?;
    let c = bufs.c.get_mut(..n).ok_or(SegmentError::WorkspaceTooSmall)?;
    let d = bufs.d.get_mut(..n).ok_or(SegmentError::WorkspaceTooSmall)?;

    // --- the pixels the thresholds see: box mean (beyond the paper) into `d` ---
    // (the column sums borrow the label buffer, unused until eq. (4))
    let colsum: &mut [u32] = bytemuck::cast_slice_mut(&mut bufs.labels[..]);
    if colsum.len() < rw + params.local_smooth as usize {
        stats.regions_small += 1; // a one-row sliver: no fish fits
        return Ok(());
    }
    box_mean_roi(frame, roi, params.local_smooth, colsum, d)
        .map_err(|_| SegmentError::WorkspaceTooSmall)?;
    // (all of it: the run table of eq. (4) may need more words than n)
    let labels = &mut *bufs.labels;
    if labels.len() < n {
        return Err(SegmentError::WorkspaceTooSmall);
    }
    // the frame minus its smooth background (beyond the paper), in every
    // region (`Params::background`: until session 26 only in regions whose
    // coarse object was thinner than the opening square)
    if let Some(g) = bg {
        // the thresholds read only the ellipse's pixels of `d`; the split
        // of merged objects reads every object pixel, and closing can add
        // a few outside the ellipse, so then whole rows
        for (j, (row, sp)) in d.chunks_exact_mut(rw).zip(spans.iter()).enumerate() {
            let r = if params.split_merged { 0..rw } else { span(sp) };
            let x0 = roi.x as usize + r.start;
            if let Some(part) = row.get_mut(r) {
                g.subtract_row(roi.y as usize + j, x0, part);
            }
        }
    }
    // level 0 is the paper's; level 1 (`dim_level`) the region again
    // without level 0's objects, which are cleared to 0 in `d`
    let levels = 1 + params.dim_level as usize;
    let mut tau_above = u8::MAX;
    // the largest level-0 object, and which level-1 components touch the
    // pixels level 0 cleared
    let mut area0 = 0u64;
    let mut touches = [false; super::MAX_ROI_COMPONENTS];
    // the ellipse's histogram: level 0 counts it, level 1 takes the cleared
    // pixels out (`clear_grown`)
    let mut h256 = [0u32; 256];
    for level in 0..levels {
        let sv = view(d, rw, rh)?;

        // --- double local thresholding, eq. (1) ---
        if level == 0 {
            for (j, sp) in spans.iter().enumerate() {
                add_row_256(&mut h256, sv.row(j).get(span(sp)).unwrap_or(&[]));
            }
        } else {
            // the cleared pixels (and level 0's own zeros) are out
            h256[0] = 0;
        }
        let total: u64 = h256.iter().map(|&v| v as u64).sum();
        if total == 0 {
            stats.regions_empty += (level == 0) as u32;
            return Ok(());
        }
        if total < params.area_min as u64 {
            // no object inside the ellipse can pass eq. (4)
            stats.regions_small += (level == 0) as u32;
            return Ok(());
        }
        let tau = otsu(&h256);
        if level > 0 && tau >= tau_above {
            // the remainder splits no lower than the first pass did
            return Ok(());
        }
        tau_above = tau;
        let (t_low, t_high) = if params.double_threshold {
            let mu = lower_class_mean(&h256, tau);
            (
                shifted_threshold(tau, mu, params.p_low),
                shifted_threshold(tau, mu, params.p_high),
            )
        } else {
            (tau, tau)
        };
        // the water of eq. (1)'s lower class, for the contrast test
        let (w_med, w_sigma) = water_level(&h256, tau);
        let (t_low, t_high) = if level > 0 {
            let s = w_sigma.max(params.noise_floor);
            // no dim fish unless half an object's area stands out of the water
            // as its mean must (the contrast test below)
            let t = w_med as f32 + DIM_LEVEL_SIGMAS * s;
            let from = (libm::ceilf(t).min(256.0)) as usize;
            let bright: u64 = h256
                .get(from..)
                .unwrap_or(&[])
                .iter()
                .map(|&v| v as u64)
                .sum();
            if 2 * bright < params.area_min as u64 {
                return Ok(());
            }
            stats.dim_levels += 1;
            // the dim level's τ may fall in the water itself (a small dim fish,
            // or none): its thresholds stay DIM_LEVEL_FLOOR water σ above it
            let floor = |k: f32| (w_med as f32 + k * s).min(255.0) as u8;
            (
                t_low.max(floor(DIM_LEVEL_FLOOR[0])),
                t_high.max(floor(DIM_LEVEL_FLOOR[1])),
            )
        } else if params.high_floor_sigmas > 0.0 && t_high <= w_med {
            // the high floor (beyond the paper): eq. (1)'s M_high took half
            // the water; it stays out of it
            let s = w_sigma.max(params.noise_floor);
            let fl = (w_med as f32 + params.high_floor_sigmas * s).min(255.0) as u8;
            (t_low, t_high.max(fl))
        } else {
            (t_low, t_high)
        };
        trace(&RegionTrace {
            region: reg,
            roi,
            level: level as u8,
            tau,
            t_low,
            t_high,
        });
        for (j, sp) in spans.iter().enumerate() {
            let r = span(sp);
            let row = sv.row(j).get(r.clone()).unwrap_or(&[]);
            let (ra, rb) = (&mut a[j * rw..(j + 1) * rw], &mut b[j * rw..(j + 1) * rw]);
            ra.fill(0);
            rb.fill(0);
            let (ra, rb) = (&mut ra[r.clone()], &mut rb[r]);
            for ((&p, va), vb) in row.iter().zip(ra.iter_mut()).zip(rb.iter_mut()) {
                *va = if p > t_low { 255 } else { 0 };
                *vb = if p > t_high { 255 } else { 0 };
            }
        }
        // 3 × 3 median on both masks (M_low into `c`, M_high into `a`),
        // restricted to the ellipse again
        let cols = |j: usize| spans.get(j).map_or(0..0, span);
        median3_binary_in(view(a, rw, rh)?, c, cols)
            .map_err(|_| SegmentError::WorkspaceTooSmall)?;
        median3_binary_in(view(b, rw, rh)?, a, cols)
            .map_err(|_| SegmentError::WorkspaceTooSmall)?;

        // --- histogram backprojection, eq. (2)–(3): B into `b` ---
        if params.double_threshold && params.backprojection {
            let (mut hl, mut hh) = ([0u32; 256], [0u32; 256]);
            // (both masks are 0 outside the ellipse)
            for (j, sp) in spans.iter().enumerate() {
                let r = span(sp);
                let row = sv.row(j).get(r.clone()).unwrap_or(&[]);
                let (rc, ra) = (
                    &c[j * rw..(j + 1) * rw][r.clone()],
                    &a[j * rw..(j + 1) * rw][r],
                );
                add_masked_pair_256(&mut hl, &mut hh, row, rc, ra);
            }
            let bins = (params.hist_bins as usize).clamp(1, 256);
            let (mut bl, mut bh) = ([0u32; 256], [0u32; 256]);
            // bins over the region's range [⌊τ_low⌋, p99] (crate::hist::range_bin)
            let (lo, hi) = (t_low, percentile_256(&h256, BP_RANGE_PERCENTILE).max(t_low));
            fold_bins_range(&hl, lo, hi, &mut bl[..bins]);
            fold_bins_range(&hh, lo, hi, &mut bh[..bins]);
            let lut =
                ratio_backprojection_lut_range(&bh[..bins], &bl[..bins], lo, hi, params.theta_bp);
            let lut = lut.map(|v| if v { 255u8 } else { 0 });
            for (j, sp) in spans.iter().enumerate() {
                let r = span(sp);
                let row = sv.row(j).get(r.clone()).unwrap_or(&[]);
                let rb = &mut b[j * rw..(j + 1) * rw];
                rb.fill(0);
                for (&p, vb) in row.iter().zip(&mut rb[r]) {
                    *vb = lut[p as usize];
                }
            }
        } else {
            b.copy_from_slice(a);
        }

        // --- area and variance rejection, eq. (4)–(6): accepted mask into `a` ---
        let (amin, amax) = (params.area_min, params.area_max);
        let mut rej_area = 0u32;
        // (B is 0 outside the ellipse; labelled as a run table in the label
        // buffer, crate::label::label_runs_in: the statistics and the accepted
        // mask below need the components only run by run)
        let runs = as_run_table(labels);
        let (n1, _) = label_runs_in(view(b, rw, rh)?, cols, runs, bufs.row_runs, |ar| {
            let ok = ar >= amin && ar <= amax;
            rej_area += !ok as u32;
            ok
        })
        .map_err(|_| SegmentError::WorkspaceTooSmall)?;
        stats.rejected_area += rej_area;
        let row_runs = &*bufs.row_runs;
        let runs = &*runs;
        let runs_of = |j: usize| runs_of_row(runs, row_runs, j);

        let cap = recs.len().min(super::MAX_ROI_COMPONENTS);
        let n1s = (n1 as usize).min(cap);
        stats.label_overflow += n1 - n1s as u32;
        for rec in recs.iter_mut().take(n1s) {
            clear_rec(rec);
        }
        for j in 0..rh {
            let (row, srow) = (pv.row(j), sv.row(j));
            for run in runs_of(j) {
                let l = run[1];
                if l <= 0 || l as usize > n1s {
                    continue;
                }
                let Some(rec) = recs.get_mut(l as usize - 1) else {
                    continue;
                };
                let r = run_span(run[0]);
                let (s1, s2) = sum_sumsq(row.get(r.clone()).unwrap_or(&[]));
                let (q1, _) = sum_sumsq(srow.get(r.clone()).unwrap_or(&[]));
                rec[0] += r.len() as u64;
                rec[10] += s1;
                rec[11] += s2;
                rec[12] += q1;
            }
        }
        // accepted flag in word 27
        for rec in recs.iter_mut().take(n1s) {
            let (cnt, s1, s2) = (rec[0] as f64, rec[10] as f64, rec[11] as f64);
            let var = if cnt > 1.0 {
                (s2 - s1 * s1 / cnt) / (cnt - 1.0)
            } else {
                0.0
            };
            let contrast = if cnt > 0.0 {
                rec[12] as f64 / cnt - w_med as f64
            } else {
                0.0
            };
            let k = if level > 0 {
                DIM_LEVEL_SIGMAS
            } else {
                params.contrast_sigmas
            };
            let stands_out = contrast >= k as f64 * w_sigma.max(params.noise_floor) as f64;
            let ok = if level > 0 {
                // the dim level's water has no bright fish to set τ apart:
                // its objects must stand out from it
                stands_out
            } else {
                !params.variance_rejection
                    || var >= stats.var_limit as f64
                    || (params.contrast_sigmas > 0.0 && stands_out)
            };
            if !ok {
                stats.rejected_variance += 1;
            }
            rec[STAT_WORDS - 1] = ok as u64;
        }
        // accepted labels as a table (index = label; 0 and overflow rejected)
        let mut acc = [0u8; super::MAX_ROI_COMPONENTS + 1];
        for (k, rec) in recs.iter().enumerate().take(n1s) {
            if let Some(v) = acc.get_mut(k + 1) {
                *v = if rec[STAT_WORDS - 1] == 1 { 255 } else { 0 };
            }
        }
        if !acc.iter().any(|&v| v != 0) {
            return Ok(());
        }
        // the accepted pixels' bounding box [x0, x1) × [y0, y1), ROI coordinates
        let mut bbox = [usize::MAX, usize::MAX, 0usize, 0usize];
        for j in 0..rh {
            let Some(ra) = a.get_mut(j * rw..(j + 1) * rw) else {
                break;
            };
            ra.fill(0);
            for run in runs_of(j) {
                let v = acc.get(run[1].max(0) as usize).copied().unwrap_or(0);
                if v == 0 {
                    continue;
                }
                let r = run_span(run[0]);
                bbox = [
                    bbox[0].min(r.start),
                    bbox[1].min(j),
                    bbox[2].max(r.end),
                    bbox[3].max(j + 1),
                ];
                if let Some(part) = ra.get_mut(r) {
                    part.fill(v);
                }
            }
        }

        // --- post-processing, Section III.D: closing then opening ---
        let disk = Disk::opencv_ellipse(params.disk_size);
        let win = close_open_window(a, (rw, rh), bbox, &disk, b, c, disk_scratch)?;

        // --- final components and their statistics ---
        // (labelled on the window only, outside which the mask is 0: as a run
        // table, or — for the split of merged objects, which reads and rewrites
        // whole label rows — as a label image of the whole box)
        let win = if params.split_merged {
            [0, 0, rw, rh]
        } else {
            win
        };
        let wcols = |j: usize| {
            if j >= win[1] && j < win[3] {
                win[0]..win[2]
            } else {
                0..0
            }
        };
        let keep = |ar: u32| ar >= amin && ar <= amax;
        let (n2, comp) = if params.split_merged {
            let labels = labels.get_mut(..n).ok_or(SegmentError::WorkspaceTooSmall)?;
            let n2 = label_components_in(view(a, rw, rh)?, labels, wcols, keep)
                .map_err(|_| SegmentError::WorkspaceTooSmall)?;
            let bufs = super::split::SplitBufs {
                lab8: a,
                level: b,
                part: c,
            };
            let n2 = super::split::split_merged(
                sv,
                roi,
                (fw, fh),
                labels,
                n2,
                t_low,
                params,
                bufs,
                stats,
            );
            (n2, Components::Labels { labels, rw })
        } else {
            let runs = as_run_table(labels);
            let (n2, _) = label_runs_in(view(a, rw, rh)?, wcols, runs, bufs.row_runs, keep)
                .map_err(|_| SegmentError::WorkspaceTooSmall)?;
            (
                n2,
                Components::Runs {
                    runs,
                    row_start: bufs.row_runs,
                },
            )
        };
        // the edge test reads the final mask `a`, which the split reuses
        let edge_test = params.edge_step_ratio > 0.0 && !params.split_merged;
        // both tests judge an object against its contrast (`EdgeSteps::seen`)
        let contrast_needed = edge_test || mesh_test;
        let n2s = (n2 as usize).min(cap);
        stats.label_overflow += n2 - n2s as u32;
        for rec in recs.iter_mut().take(n2s) {
            clear_rec(rec);
        }
        touches.fill(false);
        for j in win[1]..win[3] {
            let row = pv.row(j);
            let y = roi.y + j as u32;
            comp.for_row(j, |l, i0, i1| {
                if l <= 0 || l as usize > n2s {
                    return;
                }
                if level > 0 {
                    // a pixel of the run or of its 8-neighbours cleared
                    let (x0, x1) = (i0.saturating_sub(1), (i1 + 1).min(rw));
                    let hit = (j.saturating_sub(1)..(j + 2).min(rh))
                        .any(|jj| sv.row(jj).get(x0..x1).is_some_and(|r| r.contains(&0)));
                    if let Some(t) = touches.get_mut(l as usize - 1) {
                        *t |= hit;
                    }
                }
                let Some(rec) = recs.get_mut(l as usize - 1) else {
                    return;
                };
                let px = row.get(i0..i1).unwrap_or(&[]);
                if mesh_test {
                    let rp = rv.row(j).get(i0..i1).unwrap_or(&[]);
                    rec[32] += removed_sum(rp, px);
                }
                let (s1, s2) = sum_sumsq(px);
                rec[10] += s1;
                rec[11] += s2;
                // (two u32 sub-histograms in turn: a run of equal levels does
                // not chain every increment on one counter's store)
                let mut hs = [[0u32; HIST_BINS]; 2];
                let pairs = px.chunks_exact(2);
                let rest = pairs.remainder();
                for q in pairs {
                    hs[0][bin_of(q[0], HIST_BINS)] += 1;
                    hs[1][bin_of(q[1], HIST_BINS)] += 1;
                }
                for &p in rest {
                    hs[0][bin_of(p, HIST_BINS)] += 1;
                }
                for ((r, &a), &b) in rec[12..12 + HIST_BINS].iter_mut().zip(&hs[0]).zip(&hs[1]) {
                    *r += (a + b) as u64;
                }
                let mut m = Moments::from_words(&rec[..10]);
                m.add_run(y, roi.x + i0 as u32, roi.x + i1 as u32);
                m.to_words(&mut rec[..10]);
                if contrast_needed {
                    let (seen, seen_count) = seen_in_span(sv, spans, j, i0..i1);
                    rec[30] += seen;
                    rec[31] += seen_count;
                }
                if edge_test {
                    let e = edge_steps(sv, a, spans, (rw, rh), j, i0..i1, params.edge_gap as usize);
                    rec[28] = rec[28].wrapping_add(e.sum as u64);
                    rec[29] += e.count;
                }
            });
        }
        // the components emitted as objects: level 1 clears these only
        let mut emitted = [false; super::MAX_ROI_COMPONENTS];
        for k in 0..n2s {
            let Some(rec) = recs.get(k) else { break };
            let mut hist = [0u32; HIST_BINS];
            for (hv, &r) in hist.iter_mut().zip(&rec[12..12 + HIST_BINS]) {
                *hv = r as u32;
            }
            let m = Moments::from_words(&rec[..10]);
            if !elongated_enough(&m, params.min_elongation) && !cut_by_border(&m, fw, fh, params) {
                stats.rejected_shape += 1;
                continue;
            }
            if !solid_enough(&m, params.min_fill) {
                stats.rejected_fill += 1;
                continue;
            }
            let steps = EdgeSteps {
                sum: rec[28] as i64,
                count: rec[29],
                seen: rec[30],
                seen_count: rec[31],
            };
            if edge_test
                && !edge_sharp_enough(
                    &steps,
                    w_med,
                    required_edge_ratio(&steps, w_med, w_sigma.max(params.noise_floor), params),
                )
            {
                stats.rejected_edge += 1;
                continue;
            }
            if mesh_test
                && !not_mesh_residue(rec[32], m.area, &steps, w_med, params.mesh_residue_ratio)
            {
                stats.rejected_mesh += 1;
                continue;
            }
            if level == 0 {
                area0 = area0.max(m.area);
            } else if touches.get(k).copied().unwrap_or(false) && 2 * m.area < area0 {
                // a dim part of a level-0 fish (its tail, a fin), not a fish
                stats.rejected_fragment += 1;
                continue;
            }
            let cand = Candidate {
                m,
                sum: rec[10],
                sumsq: rec[11],
                hist,
                level: level as u8,
            };
            let mask = MaskRef {
                comp: &comp,
                roi,
                label: k as i32 + 1,
            };
            emit(out, &cand, &mask, stats);
            if let Some(e) = emitted.get_mut(k) {
                *e = true;
            }
        }
        if !emitted.contains(&true) {
            // nothing to clear: level 1 would split the region as level 0 did
            break;
        }
        if level + 1 < levels {
            // level 1 sees the region without the emitted objects grown by
            // the disk's side (their blurred rims would ring them)
            clear_grown(
                &comp,
                &emitted,
                d,
                (a, c),
                (rw, rh),
                win,
                params.disk_size as usize,
                spans,
                &mut h256,
            )?;
        }
    }
    Ok(())
}

/// How far inside and outside the outline the edge test samples, pixels:
/// the inner sample is `EDGE_GAP` pixels in from the outline pixel, the
/// outer one `EDGE_GAP` pixels beyond the first pixel out, so that the
/// step spans a blurred edge (`2·EDGE_GAP + 2` pixels). The default at
/// 2048 px wide; `Params::edge_gap` scales it with the frame.
pub const EDGE_GAP: usize = 2;

/// Fewest outline samples for the edge test to judge an object (fewer:
/// it passes).
pub const EDGE_MIN_SAMPLES: u64 = 16;

/// An object's outline samples ([`edge_steps`], summed over its runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EdgeSteps {
    /// Σ (inner − outer) over the samples, grey levels.
    pub sum: i64,
    /// Samples.
    pub count: u64,
    /// Σ of the object's thresholded pixels (the values eq. (1) saw)
    /// inside the ellipse.
    pub seen: u64,
    /// The object's pixels inside the ellipse (closing can add a few
    /// outside it, where eq. (1) saw nothing).
    pub seen_count: u64,
}

impl EdgeSteps {
    /// The object's contrast the edge test judges against: its thresholded
    /// mean inside the ellipse minus the water's median `w_med`. Callers
    /// check `seen_count > 0` first.
    fn contrast(&self, w_med: u8) -> f64 {
        self.seen as f64 / self.seen_count as f64 - w_med as f64
    }
}

/// The edge test (beyond the paper, `Params::edge_step_ratio`): the mean
/// step across the outline must be at least `ratio` times the object's
/// contrast, its thresholded mean (inside the ellipse) minus the water's
/// median `w_med` (the water of eq. (1)'s lower class). Objects with fewer than
/// [`EDGE_MIN_SAMPLES`] samples, or no contrast, pass. In `f64`, in the
/// order the reference computes it.
pub fn edge_sharp_enough(e: &EdgeSteps, w_med: u8, ratio: f32) -> bool {
    if ratio <= 0.0 || e.count < EDGE_MIN_SAMPLES || e.seen_count == 0 {
        return true;
    }
    let step = e.sum as f64 / e.count as f64;
    let contrast = e.contrast(w_med);
    contrast <= 0.0 || step >= ratio as f64 * contrast
}

/// The edge test's ratio for one object (beyond the paper,
/// `Params::weak_contrast_sigmas`): `edge_step_ratio`, raised to
/// `weak_edge_step_ratio` when the object's contrast, measured as
/// [`edge_sharp_enough`] measures it, is under `weak_contrast_sigmas` water
/// σ (`s_w`, the region's water σ at least `noise_floor`). Why: the top of a
/// smooth debris blob that Otsu splits off its region stands about 3 σ
/// above the water and its thresholded outline sits on the blob's slope
/// (steps of 0.31–0.38 of its contrast on seeds 1–12), while fish that dim
/// still have a step of 0.4 or more (35 of 36 detected fish under 3.5 σ).
/// In `f64`, in the order the reference computes it.
pub fn required_edge_ratio(e: &EdgeSteps, w_med: u8, s_w: f32, params: &Params) -> f32 {
    let base = params.edge_step_ratio;
    if params.weak_contrast_sigmas <= 0.0 || e.seen_count == 0 {
        return base;
    }
    if e.contrast(w_med) < params.weak_contrast_sigmas as f64 * s_w as f64 {
        base.max(params.weak_edge_step_ratio)
    } else {
        base
    }
}

/// The outline samples of one run (row `j`, columns `cols`) of an object
/// of the final mask `mask` (ROI `rw × rh`, non-zero = object), on the
/// thresholded pixels `sv`.
///
/// A sample pairs an object pixel (inner) with a pixel outside every
/// object (outer) across one outline pixel, along a row or a column:
/// - the run's first pixel `x`: inner `x + g`, outer `x − 1 − g`, when the
///   run is longer than `g` (inner on the run);
/// - its last pixel `x`: inner `x − g`, outer `x + 1 + g`, likewise;
/// - each pixel `(x, j)` whose pixel below is outside the mask: inner
///   `(x, j − g)`, outer `(x, j + 1 + g)`; above, mirrored;
///
/// with `g` = `Params::edge_gap` ([`EDGE_GAP`] at 2048 px); both pixels inside the ellipse (`spans`: the
/// thresholded pixels are defined there), the inner one in the mask, the
/// outer one outside it and above 0 (0 is what the dim level cleared:
/// another fish, not water).
fn edge_steps(
    sv: ImageView<'_>,
    mask: &[u8],
    spans: &[[i32; 2]],
    (rw, rh): (usize, usize),
    j: usize,
    cols: core::ops::Range<usize>,
    g: usize,
) -> EdgeSteps {
    let (i0, i1) = (cols.start, cols.end);
    let inside = |jj: usize, x: usize| mask.get(jj * rw + x).is_some_and(|&v| v != 0);
    let in_span = |jj: usize, x: usize| {
        spans
            .get(jj)
            .is_some_and(|sp| x as i64 >= sp[0] as i64 && (x as i64) < sp[1] as i64)
    };
    let px = |jj: usize, x: usize| sv.row(jj).get(x).copied().unwrap_or(0);
    let mut e = EdgeSteps::default();
    let mut sample = |(ji, xi): (usize, usize), (jo, xo): (usize, usize)| {
        if xo < rw
            && jo < rh
            && inside(ji, xi)
            && in_span(ji, xi)
            && !inside(jo, xo)
            && in_span(jo, xo)
        {
            let o = px(jo, xo);
            if o > 0 {
                e.sum += px(ji, xi) as i64 - o as i64;
                e.count += 1;
            }
        }
    };
    if i1 > i0 + g {
        if i0 > g {
            sample((j, i0 + g), (j, i0 - 1 - g));
        }
        sample((j, i1 - 1 - g), (j, i1 + g));
    }
    for x in i0..i1 {
        if j >= g && !inside(j + 1, x) {
            sample((j - g, x), (j + 1 + g, x));
        }
        if j > g && !inside(j - 1, x) {
            sample((j + g, x), (j - 1 - g, x));
        }
    }
    e
}

/// The thresholded pixels `sv` of an object's run (row `j`, columns
/// `cols`) inside the ellipse (`spans`): their sum and number, the parts of
/// [`EdgeSteps::seen`] and [`EdgeSteps::seen_count`].
fn seen_in_span(
    sv: ImageView<'_>,
    spans: &[[i32; 2]],
    j: usize,
    cols: core::ops::Range<usize>,
) -> (u64, u64) {
    let Some(sp) = spans.get(j) else {
        return (0, 0);
    };
    let x0 = (sp[0].max(0) as usize).clamp(cols.start, cols.end);
    let x1 = (sp[1].max(0) as usize).clamp(x0, cols.end);
    let px = sv.row(j).get(x0..x1).unwrap_or(&[]);
    (px.iter().map(|&p| p as u64).sum(), px.len() as u64)
}

/// Σ (raw − mesh-free) over one run's pixels: the grey levels the mesh
/// removal took from them (it is anti-extensive, so no term is negative;
/// a negative one would count 0).
pub fn removed_sum(raw: &[u8], filtered: &[u8]) -> u64 {
    // 1024 · 255 < 2³²: each block's sum fits u32 (and vectorises)
    raw.chunks(1024)
        .zip(filtered.chunks(1024))
        .map(|(r, f)| {
            r.iter()
                .zip(f)
                .map(|(&r, &f)| r.saturating_sub(f) as u32)
                .sum::<u32>() as u64
        })
        .sum()
}

/// The mesh-residue test (beyond the paper, `Params::mesh_residue_ratio`):
/// `true` (the object stays) unless the mean of what the mesh removal took
/// from the object's `area` pixels (`removed`, [`removed_sum`]) reaches
/// `ratio` times its contrast, measured as [`edge_sharp_enough`] measures
/// it (thresholded mean inside the ellipse above the water's median
/// `w_med`). An object with no pixel inside the ellipse, or no contrast,
/// stays. Why: the line openings of Section V.A leave a faint copy of the
/// trawl mesh in the mesh-free frame; a patch of it is what the removal
/// took most of, while a fish, hiding the net behind it, loses only its
/// texture's peaks and its noise. In `f64`, in the order the reference
/// computes it.
pub fn not_mesh_residue(removed: u64, area: u64, e: &EdgeSteps, w_med: u8, ratio: f32) -> bool {
    if ratio <= 0.0 || area == 0 || e.seen_count == 0 {
        return true;
    }
    let contrast = e.contrast(w_med);
    contrast <= 0.0 || (removed as f64 / area as f64) < ratio as f64 * contrast
}

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;

    /// The moments of the pixels `(x, y)` for which `inside` holds, in a
    /// `w × h` window.
    fn moments_of(w: u32, h: u32, inside: impl Fn(f32, f32) -> bool) -> Moments {
        let mut m = Moments::EMPTY;
        for y in 0..h {
            for x in 0..w {
                if inside(x as f32, y as f32) {
                    m.add_run(y, x, x + 1);
                }
            }
        }
        m
    }

    /// Filled bodies fill their equivalent ellipse (ellipse ≈ 1, rectangle
    /// 3/π, a half ellipse cut by the frame ≈ 0.9); a net of strands does
    /// not (2-px strands every 24 px fill about a sixth of it; 8-px strands
    /// every 40 px, the thick mesh of seed 42, about 0.36); a one-pixel
    /// line and `f = 0` pass.
    #[test]
    fn solid_bodies_pass_the_fill_test_and_a_net_of_strands_does_not() {
        let fill = |m: &Moments| m.area as f32 / ellipse_area(m);
        let ellipse = moments_of(300, 120, |x, y| {
            let (u, v) = ((x - 150.0) / 140.0, (y - 60.0) / 40.0);
            u * u + v * v <= 1.0
        });
        let half = moments_of(300, 120, |x, y| {
            let (u, v) = ((x - 150.0) / 140.0, (y - 60.0) / 40.0);
            u * u + v * v <= 1.0 && x < 150.0
        });
        let rect = moments_of(200, 50, |_, _| true);
        let net = |pitch: f32, width: f32| {
            moments_of(240, 200, move |x, y| {
                (x + y).rem_euclid(pitch) < width || (x - y).rem_euclid(pitch) < width
            })
        };
        assert!((fill(&ellipse) - 1.0).abs() < 0.02, "{}", fill(&ellipse));
        assert!((fill(&rect) - 3.0 / core::f32::consts::PI).abs() < 0.02);
        assert!(fill(&half) > 0.85, "{}", fill(&half));
        for m in [&ellipse, &half, &rect] {
            assert!(solid_enough(m, 0.4));
        }
        let (thin, thick) = (net(24.0, 2.0), net(40.0, 8.0));
        assert!(
            fill(&thin) < 0.2 && fill(&thick) < 0.4,
            "{} {}",
            fill(&thin),
            fill(&thick)
        );
        assert!(!solid_enough(&thin, 0.4) && !solid_enough(&thick, 0.4));
        assert!(solid_enough(&thin, 0.0), "0 turns the test off");
        let line = moments_of(100, 3, |_, y| y == 1.0);
        assert_eq!(ellipse_area(&line), 0.0);
        assert!(solid_enough(&line, 0.4));
        assert!(solid_enough(&Moments::EMPTY, 0.4));
    }

    proptest::proptest! {
        /// Closing then opening on the window around the mask's box equals
        /// both operations on the whole mask, whatever the box's place
        /// (against the ROI border or not) and the disk.
        #[test]
        fn close_open_window_equals_whole_mask(w in 1usize..90, h in 1usize..70,
                                               bx in 0usize..90, by in 0usize..70,
                                               bw in 1usize..40, bh in 1usize..40,
                                               size in proptest::sample::select(std::vec![3u8, 5, 7, 9]),
                                               seed in proptest::prelude::any::<u64>()) {
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            // a random blob inside the box (clipped to the mask)
            let (x0, y0) = (bx.min(w - 1), by.min(h - 1));
            let (x1, y1) = ((x0 + bw).min(w), (y0 + bh).min(h));
            let mut a = std::vec![0u8; w * h];
            let mut bbox = [usize::MAX, usize::MAX, 0, 0];
            for y in y0..y1 {
                for x in x0..x1 {
                    if next() % 3 != 0 {
                        a[y * w + x] = 255;
                        bbox = [bbox[0].min(x), bbox[1].min(y), bbox[2].max(x + 1), bbox[3].max(y + 1)];
                    }
                }
            }
            let disk = Disk::opencv_ellipse(size);
            let mut tmp = std::vec![0u8; w * h];
            let mut scratch = std::vec![0u8; crate::morph::disk_scratch_len(w, disk.radius)];
            let mut whole = a.clone();
            close_disk_in_place(&mut whole, w, h, &disk, &mut tmp, &mut scratch).unwrap();
            open_disk_in_place(&mut whole, w, h, &disk, &mut tmp, &mut scratch).unwrap();
            let mut win = std::vec![0u8; w * h];
            close_open_window(&mut a, (w, h), bbox, &disk, &mut win, &mut tmp, &mut scratch).unwrap();
            proptest::prop_assert_eq!(a, whole);
        }

        /// `clear_grown` clears exactly the pixels within Chebyshev distance
        /// r of a pixel of a kept label, and takes exactly the cleared nonzero
        /// pixels inside the spans out of the histogram.
        #[test]
        fn clear_grown_equals_naive_dilation(w in 1usize..60, h in 1usize..50,
                                             r in 0usize..9, dens in 0u64..6,
                                             seed in proptest::prelude::any::<u64>()) {
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let labels: std::vec::Vec<i32> = (0..w * h)
                .map(|_| if next() % 64 < dens { (next() % 3) as i32 + 1 } else { 0 })
                .collect();
            let keep = [next() % 2 == 0, next() % 2 == 0, next() % 2 == 0];
            let d0: std::vec::Vec<u8> = (0..w * h).map(|_| (next() % 8) as u8).collect();
            let spans: std::vec::Vec<[i32; 2]> = (0..h)
                .map(|_| { let a = (next() % (w as u64 + 2)) as i32 - 1; [a, a + (next() % (w as u64 + 1)) as i32] })
                .collect();
            let mut h0 = [0u32; 256];
            for (j, sp) in spans.iter().enumerate() {
                for x in (sp[0].max(0) as usize).min(w)..(sp[1].max(0) as usize).min(w) {
                    h0[d0[j * w + x] as usize] += 1;
                }
            }
            // naive: every pixel against every labelled pixel
            let (mut want, mut want_h) = (d0.clone(), h0);
            for y in 0..h {
                for x in 0..w {
                    let near = (y.saturating_sub(r)..(y + r + 1).min(h)).any(|yy| {
                        (x.saturating_sub(r)..(x + r + 1).min(w)).any(|xx| {
                            let l = labels[yy * w + xx];
                            l > 0 && keep[l as usize - 1]
                        })
                    });
                    if near {
                        let sp = spans[y];
                        if want[y * w + x] != 0 && (x as i32) >= sp[0] && (x as i32) < sp[1] {
                            want_h[want[y * w + x] as usize] -= 1;
                        }
                        want[y * w + x] = 0;
                    }
                }
            }
            let comp = Components::Labels { labels: &labels, rw: w };
            let (mut d, mut got_h) = (d0.clone(), h0);
            let (mut marks, mut count) = (std::vec![9u8; w * h], std::vec![9u8; w]);
            clear_grown(&comp, &keep, &mut d, (&mut marks, &mut count), (w, h), [0, 0, w, h], r, &spans, &mut got_h).unwrap();
            proptest::prop_assert_eq!(d, want);
            proptest::prop_assert_eq!(got_h, want_h);
        }
    }
}
