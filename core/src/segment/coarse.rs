//! Coarse localisation on the whole frame (Section III.A, V.A): trawl-mesh
//! removal, grey morphological gradient with the 7 × 7 disk, a global
//! threshold, streaming connected components, and per component the
//! enlarged inscribed ellipse of its PCA oriented box as the local region.
//!
//! **Threshold choice.** `t = med(G) + K·max(MAD(G), 1)` on the gradient
//! histogram G (256 bins, K = 4, about 2.7 robust standard deviations).
//! Flat water fills most of the frame, so the gradient histogram is one
//! noise mode (for a 7 × 7 disk the local range of 37 noisy pixels, about
//! 4σ) and fish edges are its outliers: a robust outlier threshold adapts to
//! the noise level and does not depend on how many fish there are. Otsu on
//! G, the other candidate, does: with a few small fish the classes are so
//! unbalanced that its cut lands inside the noise mode (flooding the frame
//! with noise components; always on a frame without fish) or jumps up to
//! the strongest edges and loses dim fish (measured on the test frames:
//! Otsu 49 lost a fish of contrast 40 at σ = 6 that the floor, 38, keeps).
//! Foreground is `G > t`.
//!
//! **Box and ellipse.** Components are labelled row by row without a label
//! image ([`crate::label::StreamLabeler`]), so only their moments are
//! known: the oriented box is that of the equivalent ellipse (semi-axes
//! `2√λ₁`, `2√λ₂` of the coordinate covariance — exact for a filled
//! ellipse), its inscribed ellipse has the same semi-axes, and the local
//! region enlarges both by `ellipse_scale` (1.5). Components smaller than
//! `area_min / 4` pixels are skipped (gradient speckle; the gradient band
//! of the smallest admissible fish is larger than that).
//!
//! Memory bound: two frame buffers, one row, the disk ring and the
//! labeler's `O(width)` tables; [`super::MAX_REGIONS`] region records.

use super::workspace::{Ws, MAX_REGIONS, REGION_WORDS};
use super::{Region, SegmentError, SegmentStats};
use crate::hist::add_row_256;
use crate::image::ImageView;
use crate::label::{Moments, StreamLabeler};
use crate::morph::{gradient_disk, remove_mesh, Disk};
use crate::params::Params;

/// The robust floor's MAD multiplier.
pub const GRAD_MAD_K: u32 = 4;

/// `median + K·max(MAD, 1)` of a 256-bin histogram (see the module doc).
pub fn gradient_threshold(hist: &[u32; 256]) -> u8 {
    let total: u64 = hist.iter().map(|&h| h as u64).sum();
    if total == 0 {
        return 0;
    }
    let median = |h: &[u32; 256]| -> u32 {
        let half = total.div_ceil(2);
        let mut acc = 0u64;
        for (i, &c) in h.iter().enumerate() {
            acc += c as u64;
            if acc >= half {
                return i as u32;
            }
        }
        255
    };
    let med = median(hist);
    let mut dev = [0u32; 256];
    for (i, &c) in hist.iter().enumerate() {
        let d = (i as i32 - med as i32).unsigned_abs() as usize;
        if let Some(v) = dev.get_mut(d) {
            *v = v.saturating_add(c);
        }
    }
    let mad = median(&dev).max(1);
    (med + GRAD_MAD_K * mad).min(255) as u8
}

/// The local region of a coarse component from its moments.
pub fn region_of(m: &Moments, ellipse_scale: f32) -> Region {
    let (cx, cy) = m.centroid();
    let (angle, l1, l2) = m.principal_axes();
    // semi-axes of the equivalent ellipse, at least half a pixel
    let a = (2.0 * libm::sqrtf(l1)).max(0.5);
    let b = (2.0 * libm::sqrtf(l2)).max(0.5);
    Region {
        cx,
        cy,
        a: a * ellipse_scale,
        b: b * ellipse_scale,
        angle,
        coarse_area: m.area.min(u32::MAX as u64) as u32,
    }
}

pub(crate) fn encode_region(r: &Region) -> [f32; REGION_WORDS] {
    [
        r.cx,
        r.cy,
        r.a,
        r.b,
        r.angle,
        r.coarse_area as f32,
        0.0,
        0.0,
    ]
}

pub(crate) fn decode_region(w: &[f32; REGION_WORDS]) -> Region {
    Region {
        cx: w[0],
        cy: w[1],
        a: w[2],
        b: w[3],
        angle: w[4],
        coarse_area: w[5] as u32,
    }
}

/// Runs mesh removal, gradient, threshold and labelling; fills
/// `ws.regions[..n]` and returns `n`.
pub(crate) fn coarse_regions(
    img: ImageView<'_>,
    params: &Params,
    ws: &mut Ws<'_>,
    stats: &mut SegmentStats,
) -> Result<usize, SegmentError> {
    let (w, h) = (img.width(), img.height());
    let n = w * h;
    let scratch_err = |_| SegmentError::WorkspaceTooSmall;
    // 1. trawl-mesh removal (Section V.A) into `filtered`
    let len = params.mesh_line_len as usize;
    if len >= 3 {
        remove_mesh(img, len, ws.grad, ws.filtered).map_err(scratch_err)?;
    } else {
        for (y, o) in ws.filtered.chunks_exact_mut(w).take(h).enumerate() {
            o.copy_from_slice(img.row(y));
        }
    }
    // 2. morphological gradient with the disk
    let disk = Disk::opencv_ellipse(params.disk_size);
    let fv =
        ImageView::packed(&ws.filtered[..n], w, h).map_err(|_| SegmentError::WorkspaceTooSmall)?;
    gradient_disk(fv, &disk, ws.grad, ws.disk).map_err(scratch_err)?;
    // 3. global threshold
    let mut hist = [0u32; 256];
    for row in ws.grad.chunks_exact(w).take(h) {
        add_row_256(&mut hist, row);
    }
    let t = gradient_threshold(&hist);
    stats.gradient_threshold = t;
    // 4. components → regions
    let min_area = (params.area_min / 4).max(1) as u64;
    let mut labeler = StreamLabeler::new(w, ws.slots, ws.free, ws.prev, ws.cur)
        .map_err(|_| SegmentError::WorkspaceTooSmall)?;
    let regions = &mut *ws.regions;
    let mut count = 0usize;
    let mut on_done = |m: &Moments| {
        stats.coarse_components += 1;
        if m.area < min_area {
            stats.coarse_small += 1;
            return;
        }
        let r = region_of(m, params.ellipse_scale);
        if count < MAX_REGIONS.min(regions.len()) {
            if let Some(slot) = regions.get_mut(count) {
                *slot = encode_region(&r);
            }
            count += 1;
        } else {
            // keep the largest: replace the smallest if this one is larger
            stats.regions_dropped += 1;
            let mut smallest: Option<(usize, u32)> = None;
            for (i, rw) in regions.iter().enumerate().take(count) {
                let a = decode_region(rw).coarse_area;
                if smallest.is_none_or(|(_, sa)| a < sa) {
                    smallest = Some((i, a));
                }
            }
            if let Some((i, a)) = smallest {
                if r.coarse_area > a {
                    if let Some(slot) = regions.get_mut(i) {
                        *slot = encode_region(&r);
                    }
                }
            }
        }
    };
    for row in ws.grad.chunks_exact(w).take(h) {
        labeler.push_row_above(row, t, &mut on_done);
    }
    labeler.finish(&mut on_done);
    Ok(count)
}
