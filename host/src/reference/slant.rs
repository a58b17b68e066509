//! Float reference of the slanted disparity fit (`fishtrack_core::slant`,
//! Section IV.D.2 beyond the paper's blocks), written for clarity: the
//! template as a list of pixels, the cost from the list of differences.
//!
//! The right image is sampled on the same 1/1024-pixel grid as the core
//! (linear interpolation in integers), so the costs agree exactly wherever
//! the sample positions round alike; the search visits the same grids.

use super::epipolar::template;
use super::stereo::{Gray, RefObject};

/// Most template pixels per hypothesis (core: `slant::SLANT_BUDGET`).
const BUDGET: usize = 4096;

/// Sub-pixel grid of the right image's interpolation (core: `slant::SUB`).
const SUB: f64 = 1024.0;

/// Least share of the template's pixels with a right sample in the image.
const MIN_COMPARED: f64 = 0.9;

/// The axis: centre, unit direction, and the two end positions.
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    /// Centre (left view).
    pub c: (f64, f64),
    /// Unit direction.
    pub u: (f64, f64),
    /// End positions along the axis, `t0 < t1`.
    pub t: (f64, f64),
}

/// Zero-mean SAD per pixel (grey levels) of the template pixels on the
/// lattice `step` against the right image at the disparity that runs
/// linearly from `d.0` at `t0` to `d.1` at `t1`.
fn cost(
    l: &Gray,
    r: &Gray,
    tmpl: &[(i64, i64)],
    step: (i64, i64),
    ax: &Axis,
    d: (f64, f64),
) -> Option<f64> {
    let w = l.w.min(r.w) as i64;
    let span = ax.t.1 - ax.t.0;
    let slope = if span > 1e-3 { (d.1 - d.0) / span } else { 0.0 };
    let lattice: Vec<(i64, i64)> = tmpl
        .iter()
        .filter(|(x, y)| x % step.0 == 0 && y % step.1 == 0)
        .take(BUDGET)
        .copied()
        .collect();
    let mut diffs = Vec::new();
    for &(x, y) in &lattice {
        let t = (x as f64 - ax.c.0) * ax.u.0 + (y as f64 - ax.c.1) * ax.u.1;
        let q = ((x as f64 - (d.0 + slope * (t - ax.t.0))) * SUB).round();
        if !(q >= 0.0 && q < (w - 1) as f64 * SUB) {
            continue;
        }
        let s = SUB as i64;
        let (i, f) = (q as i64 / s, (q as i64 % s) as f64);
        let (Some(a), Some(r0), Some(r1)) = (l.at(x, y), r.at(i, y), r.at(i + 1, y)) else {
            continue;
        };
        diffs.push(a * SUB - (r0 * (SUB - f) + r1 * f));
    }
    let n = diffs.len();
    if n == 0 || (n as f64) < MIN_COMPARED * lattice.len() as f64 {
        return None;
    }
    let mean = diffs.iter().sum::<f64>() / n as f64;
    Some(diffs.iter().map(|v| (v - mean).abs()).sum::<f64>() / n as f64 / SUB)
}

/// The fitted end disparities `(d0, d1)` of `obj` (template widened by `m`)
/// from the starting hypotheses `starts`, as the core's `slant::fit_slant`:
/// the best start, then grids of ±4 steps of 2, ±3 of ½, ±2 of ⅛ around the
/// best so far, the first of equal costs kept; then the vertex of a
/// parabola through the best and its ±⅛ neighbours in each end's disparity.
pub fn fit(
    l: &Gray,
    r: &Gray,
    obj: &RefObject,
    m: i64,
    ax: &Axis,
    starts: &[(f64, f64)],
) -> Option<(f64, f64)> {
    let w = l.w.min(r.w) as i64;
    let tmpl = template(obj, m, w);
    let k = (tmpl.len() as u64).div_ceil(BUDGET as u64 / 2).max(1) as i64;
    let step = if k == 1 { (1, 1) } else { (2, (k + 1) / 2) };
    let mut best: Option<((f64, f64), f64)> = None;
    let consider = |d: (f64, f64), best: &mut Option<((f64, f64), f64)>| {
        if let Some(c) = cost(l, r, &tmpl, step, ax, d) {
            if best.is_none_or(|b| c < b.1) {
                *best = Some((d, c));
            }
        }
    };
    for &d in starts.iter().take(4) {
        if d.0.is_finite() && d.1.is_finite() {
            consider(d, &mut best);
        }
    }
    for (radius, h) in [(4i64, 2.0f64), (3, 0.5), (2, 0.125)] {
        let (c, _) = best?;
        for i in -radius..=radius {
            for j in -radius..=radius {
                if i != 0 || j != 0 {
                    consider((c.0 + i as f64 * h, c.1 + j as f64 * h), &mut best);
                }
            }
        }
    }
    // the sub-step parabola through the best and its ±⅛ neighbours
    let ((c0, c1), cb) = best?;
    let h = 0.125;
    let at = |d: (f64, f64)| cost(l, r, &tmpl, step, ax, d);
    let vertex = |m: Option<f64>, p: Option<f64>| match (m, p) {
        (Some(m), Some(p)) if m - 2.0 * cb + p > 1e-9 => {
            (0.5 * h * (m - p) / (m - 2.0 * cb + p)).clamp(-h, h)
        }
        _ => 0.0,
    };
    let v0 = vertex(at((c0 - h, c1)), at((c0 + h, c1)));
    let v1 = vertex(at((c0, c1 - h)), at((c0, c1 + h)));
    Some((c0 + v0, c1 + v1))
}
