//! Float reference of the epipolar search for unpaired left objects
//! (`fishtrack_core::epipolar`, beyond Section IV.A), written for clarity:
//! the template as a per-row pixel mask, the zero-mean SAD from the list of
//! differences, the median by sorting.
//!
//! Differs from the core only where the core is bounded: the core adds no
//! right object beyond its object and run capacities (the reference has
//! none), and scans at most 1024 disparities (the step grows alike here).

use super::stereo::{sad, Geometry, Gray, Limits, RefObject, RefPair};

/// Least share of the template's pixels that must be compared.
const MIN_COMPARED: f64 = 0.9;

/// Most scan disparities (core: `epipolar::MAX_SCAN`).
const MAX_SCAN: i64 = 1024;

/// The widened template of `obj`: pixels `(x, y)` within `m` columns of a
/// mask pixel on the same row, inside `0..w`.
pub(super) fn template(obj: &RefObject, m: i64, w: i64) -> Vec<(i64, i64)> {
    let mut rows: std::collections::BTreeMap<i64, Vec<i64>> = Default::default();
    for &(x, y) in &obj.pixels {
        rows.entry(y).or_default().push(x);
    }
    let mut out = Vec::new();
    for (y, xs) in rows {
        let lo = (xs.iter().min().unwrap() - m).max(0);
        let hi = (xs.iter().max().unwrap() + m).min(w - 1);
        let mut inside = vec![false; (hi - lo + 1).max(0) as usize];
        for x in xs {
            for t in (x - m).max(lo)..=(x + m).min(hi) {
                inside[(t - lo) as usize] = true;
            }
        }
        out.extend(
            inside
                .iter()
                .enumerate()
                .filter(|(_, &v)| v)
                .map(|(k, _)| (lo + k as i64, y)),
        );
    }
    out
}

/// Zero-mean SAD per pixel of the template's pixels with `x % step.0 ==
/// 0` and `y % step.1 == 0` against the right image `d` pixels to the left.
fn cost(l: &Gray, r: &Gray, t: &[(i64, i64)], d: i64, step: (i64, i64)) -> Option<f64> {
    cost_need(l, r, t, d, step, (MIN_COMPARED, usize::MAX))
}

/// [`cost`] accepting `d` when at least `need.0` of `min(template pixels,
/// need.1)` pixels are compared (core: `epipolar::template_cost`).
pub(super) fn cost_need(
    l: &Gray,
    r: &Gray,
    t: &[(i64, i64)],
    d: i64,
    step: (i64, i64),
    need: (f64, usize),
) -> Option<f64> {
    let rows: Vec<&(i64, i64)> = t
        .iter()
        .filter(|p| p.0 % step.0 == 0 && p.1 % step.1 == 0)
        .collect();
    let diffs: Vec<f64> = rows
        .iter()
        .filter_map(|&&(x, y)| Some(l.at(x, y)? - r.at(x - d, y)?))
        .collect();
    if diffs.is_empty() || (diffs.len() as f64) < need.0 * rows.len().min(need.1) as f64 {
        return None;
    }
    let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
    Some(diffs.iter().map(|v| (v - mean).abs()).sum::<f64>() / diffs.len() as f64)
}

/// How the search for one object came out: `(d, best, median, runner-up)`.
pub fn search_object(
    l: &Gray,
    r: &Gray,
    obj: &RefObject,
    geom: &Geometry,
    lim: &Limits,
) -> Option<(i64, f64, f64, f64)> {
    let d_lo = geom.disparity_at_depth(lim.max_range) - lim.slack;
    let d_hi = geom.disparity_at_depth(lim.min_range) + lim.slack;
    let (lo, hi) = (
        (d_lo.ceil() as i64).max(0),
        (d_hi.floor() as i64).min(l.w as i64),
    );
    if hi < lo || obj.pixels.is_empty() {
        return None;
    }
    let m = ((obj.h_o / 4.0).floor() as i64).max(4);
    let t = template(obj, m, l.w as i64);
    // the scan's rows: every 4th, every 4k-th for templates over 8 · 16384 pixels
    let rows = 4 * ((t.len() as i64 + 8 * 16_384 - 1) / (8 * 16_384)).max(1);
    let span = hi - lo + 1;
    let step = ((span + MAX_SCAN - 1) / MAX_SCAN).max(1);
    let scan: Vec<(i64, f64)> = (lo..=hi)
        .step_by(step as usize)
        .filter_map(|d| Some((d, cost(l, r, &t, d, (2, rows))?)))
        .collect();
    // the first of equal minima
    let mut coarse = *scan.first()?;
    for &s in &scan {
        if s.1 < coarse.1 {
            coarse = s;
        }
    }
    let far = (obj.bbox.2 / 2).max(step);
    let runner_up = scan
        .iter()
        .filter(|s| (s.0 - coarse.0).abs() > far)
        .map(|s| s.1)
        .fold(f64::INFINITY, f64::min);
    let mut sorted: Vec<f64> = scan.iter().map(|s| s.1).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let mut fine: Option<(i64, f64)> = None;
    for d in (coarse.0 - step).max(lo)..=(coarse.0 + step).min(hi) {
        if let Some(c) = cost(l, r, &t, d, (1, 1)) {
            if fine.is_none_or(|f| c < f.1) {
                fine = Some((d, c));
            }
        }
    }
    let (d, best) = fine?;
    Some((d, best, median, runner_up))
}

fn iou(a: (i64, i64, i64, i64), b: (i64, i64, i64, i64)) -> f64 {
    let ix = ((a.0 + a.2).min(b.0 + b.2) - a.0.max(b.0)).max(0);
    let iy = ((a.1 + a.3).min(b.1 + b.3) - a.1.max(b.1)).max(0);
    let inter = (ix * iy) as f64;
    let union = (a.2 * a.3 + b.2 * b.3) as f64 - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Looks for every unpaired left object in the right image; appends the
/// right objects and pairs found (pairs sorted by left index).
pub fn search_unpaired(
    l: &Gray,
    r: &Gray,
    left: &[RefObject],
    right: &mut Vec<RefObject>,
    pairs: &mut Vec<RefPair>,
    geom: &Geometry,
    lim: &Limits,
) {
    let segmented = right.len();
    for (i, lo) in left.iter().enumerate() {
        if pairs.iter().any(|p| p.left == i) {
            continue;
        }
        let Some((d, best, median, runner_up)) = search_object(l, r, lo, geom, lim) else {
            continue;
        };
        if !(best.is_finite()
            && best <= lim.search_max_ratio * median
            && best <= lim.search_max_runner_up * runner_up)
        {
            continue;
        }
        let found = ((lo.bbox.0 - d).max(0), lo.bbox.1, lo.bbox.2, lo.bbox.3);
        if pairs
            .iter()
            .any(|p| p.right < segmented && iou(right[p.right].bbox, found) >= 0.5)
        {
            continue;
        }
        let pixels: Vec<(i64, i64)> = lo
            .pixels
            .iter()
            .map(|&(x, y)| (x - d, y))
            .filter(|&(x, _)| x >= 0 && x < r.w as i64)
            .collect();
        if pixels.is_empty() {
            continue;
        }
        let x0 = pixels.iter().map(|p| p.0).min().unwrap();
        let x1 = pixels.iter().map(|p| p.0).max().unwrap();
        let y0 = pixels.iter().map(|p| p.1).min().unwrap();
        let y1 = pixels.iter().map(|p| p.1).max().unwrap();
        let mean =
            pixels.iter().filter_map(|&(x, y)| r.at(x, y)).sum::<f64>() / pixels.len() as f64;
        // μ_SAD: the object-height blocks at d
        let (bx, by, bw, bh) = lo.bbox;
        let blocks: Vec<f64> = (0..4)
            .filter_map(|k| {
                let (a, b) = (bx + k * bw / 4, bx + (k + 1) * bw / 4);
                (b > a).then(|| sad(l, r, a, b, by, by + bh, d)).flatten()
            })
            .collect();
        let mu_sad = if blocks.is_empty() {
            f64::INFINITY
        } else {
            blocks.iter().sum::<f64>() / blocks.len() as f64
        };
        right.push(RefObject {
            bbox: (x0, y0, x1 - x0 + 1, y1 - y0 + 1),
            centre: (lo.centre.0 - d as f64, lo.centre.1),
            angle: lo.angle,
            h_o: lo.h_o,
            mean,
            pixels,
        });
        pairs.push(RefPair {
            left: i,
            right: right.len() - 1,
            d_o: d as f64,
            mu_sad,
            occluded: false,
            searched: true,
        });
    }
    pairs.sort_by_key(|p| p.left);
}
