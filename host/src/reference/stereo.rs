//! Float reference of stereo pairing (Section IV.A) and 3-D fish length
//! (Section IV.D): the same stages as `fishtrack_core::{stereo, refine,
//! snake, length}`, re-written independently in plain `f64` with `Vec`s,
//! for clarity rather than speed. It is the yardstick of `fishtrack
//! compare`: pairs must be identical and lengths agree within 0.5 %
//! ([`compare`]).
//!
//! Differences in *how* (not what) it computes, on purpose:
//! - the one-to-one assignment is an exhaustive branch-and-bound search
//!   (most pairs first, then least summed cost) instead of shortest
//!   augmenting paths;
//! - mask pixels are expanded into a pixel list; end points come from a
//!   full sort of the projections;
//! - the snake keeps its contour in `f64`.
//!
//! Memory: allocates freely (pixel lists, cost matrices).

use crate::stats::median;
use fishtrack_core::object::Objects;
use fishtrack_core::{Params, StereoGeometry};
use nalgebra::{Matrix4, Vector3, Vector4};

/// A borrowed 8-bit image, packed rows.
#[derive(Clone, Copy)]
pub struct Gray<'a> {
    /// Pixels, row-major.
    pub data: &'a [u8],
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
}

impl Gray<'_> {
    pub(crate) fn at(&self, x: i64, y: i64) -> Option<f64> {
        if x < 0 || y < 0 || x as usize >= self.w || y as usize >= self.h {
            return None;
        }
        self.data
            .get(y as usize * self.w + x as usize)
            .map(|&v| v as f64)
    }

    fn clamped(&self, x: i64, y: i64) -> f64 {
        let x = x.clamp(0, self.w as i64 - 1);
        let y = y.clamp(0, self.h as i64 - 1);
        self.at(x, y).unwrap_or(0.0)
    }
}

/// Rectified geometry in `f64` (OpenCV Q convention, see `core::geometry`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Focal length, px.
    pub f: f64,
    /// Left principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
    /// Right principal point x.
    pub cx_right: f64,
    /// Baseline, mm.
    pub baseline: f64,
}

impl Geometry {
    /// From the core's geometry.
    pub fn from_core(g: &StereoGeometry) -> Self {
        Geometry {
            f: g.f as f64,
            cx: g.cx as f64,
            cy: g.cy as f64,
            cx_right: g.cx_right as f64,
            baseline: g.baseline_mm as f64,
        }
    }

    /// From an OpenCV Q matrix.
    pub fn from_q(q: &Matrix4<f64>) -> Self {
        let tx = -1.0 / q[(3, 2)];
        let cx = -q[(0, 3)];
        Geometry {
            f: q[(2, 3)],
            cx,
            cy: -q[(1, 3)],
            cx_right: cx - q[(3, 3)] * tx,
            baseline: -tx,
        }
    }

    /// OpenCV's Q.
    pub fn q(&self) -> Matrix4<f64> {
        let tx = -self.baseline;
        Matrix4::new(
            1.0,
            0.0,
            0.0,
            -self.cx, //
            0.0,
            1.0,
            0.0,
            -self.cy, //
            0.0,
            0.0,
            0.0,
            self.f, //
            0.0,
            0.0,
            -1.0 / tx,
            (self.cx - self.cx_right) / tx,
        )
    }

    /// `Q·[x y d 1]ᵀ`, dehomogenised; `None` at or beyond infinity.
    pub fn triangulate(&self, x: f64, y: f64, d: f64) -> Option<Vector3<f64>> {
        let h = self.q() * Vector4::new(x, y, d, 1.0);
        if h[3].is_nan() || h[3] <= 0.0 {
            return None;
        }
        Some(Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]))
    }

    pub(crate) fn disparity_at_depth(&self, z: f64) -> f64 {
        self.f * self.baseline / z + (self.cx - self.cx_right)
    }
}

/// An object as the reference sees it: box, oriented-box axis and pixels.
#[derive(Debug, Clone)]
pub struct RefObject {
    /// Upright box `(x, y, w, h)`.
    pub bbox: (i64, i64, i64, i64),
    /// Oriented-box centre.
    pub centre: (f64, f64),
    /// Axis angle, radians.
    pub angle: f64,
    /// Oriented-box height h_o.
    pub h_o: f64,
    /// Mean grey level.
    pub mean: f64,
    /// Mask pixels.
    pub pixels: Vec<(i64, i64)>,
}

/// Converts the core's objects (segmentation output) into reference objects.
pub fn ref_objects<const N: usize, const R: usize>(objs: &Objects<N, R>) -> Vec<RefObject> {
    objs.items
        .iter()
        .map(|o| {
            let mut pixels = Vec::new();
            for r in objs.runs_of(o) {
                for x in r.x0..r.x1 {
                    pixels.push((x as i64, r.y as i64));
                }
            }
            RefObject {
                bbox: (
                    o.bbox.x as i64,
                    o.bbox.y as i64,
                    o.bbox.w as i64,
                    o.bbox.h as i64,
                ),
                centre: (o.obb.cx as f64, o.obb.cy as f64),
                angle: o.obb.angle as f64,
                h_o: 2.0 * o.obb.half_h as f64,
                mean: o.mean as f64,
                pixels,
            }
        })
        .collect()
}

/// Plausibility gate (same meaning as `core::stereo::PairingLimits`).
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Nearest range, mm.
    pub min_range: f64,
    /// Farthest range, mm.
    pub max_range: f64,
    /// Disparity slack, px.
    pub slack: f64,
    /// Minimum row overlap fraction.
    pub min_row_overlap: f64,
    /// Minimum size ratio.
    pub min_size_ratio: f64,
    /// Maximum μ_SAD per pixel.
    pub max_sad: f64,
    /// d_o by the zero-mean whole-box SAD.
    pub zero_mean_d_o: bool,
    /// d_o scored on the left object's widened mask (core: `masked_d_o`).
    pub masked_d_o: bool,
    /// Epipolar search: best cost at most this share of the scan's median.
    pub search_max_ratio: f64,
    /// Epipolar search: best cost at most this share of the runner-up.
    pub search_max_runner_up: f64,
    /// Whole disparities scanned on each side of the chosen d_o on the
    /// widened mask (core: `PairingLimits::d_o_scan`, `stereo::scan_d_o`).
    pub d_o_scan: i64,
}

impl From<&fishtrack_core::stereo::PairingLimits> for Limits {
    fn from(l: &fishtrack_core::stereo::PairingLimits) -> Self {
        Limits {
            min_range: l.min_range_mm as f64,
            max_range: l.max_range_mm as f64,
            slack: l.disparity_slack as f64,
            min_row_overlap: l.min_row_overlap as f64,
            min_size_ratio: l.min_size_ratio as f64,
            max_sad: l.max_sad_per_pixel as f64,
            zero_mean_d_o: l.zero_mean_d_o,
            masked_d_o: l.masked_d_o,
            search_max_ratio: l.search_max_ratio as f64,
            search_max_runner_up: l.search_max_runner_up as f64,
            d_o_scan: l.d_o_scan as i64,
        }
    }
}

/// A reference stereo pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefPair {
    /// Left object index.
    pub left: usize,
    /// Right object index.
    pub right: usize,
    /// Coarse disparity d_o.
    pub d_o: f64,
    /// μ_SAD per pixel.
    pub mu_sad: f64,
    /// Shares its right object (occlusion).
    pub occluded: bool,
    /// Its right object was found by the epipolar search ([`super::epipolar`]).
    pub searched: bool,
}

/// Mean absolute difference of left columns `x0..x1`, rows `y0..y1`
/// against the right image `d` pixels to the left; `None` when fewer than
/// half of the pixels have a right counterpart.
pub(crate) fn sad(l: &Gray, r: &Gray, x0: i64, x1: i64, y0: i64, y1: i64, d: i64) -> Option<f64> {
    box_sad(l, r, x0, x1, y0, y1, d, usize::MAX, false)
}

/// The differences `a − b` of the left pixels `x0..x1` × `y0..y1` whose
/// right counterpart `d` pixels to the left lies in the image; `None`
/// when fewer than half of `min(box pixels, need)` are compared: `need`
/// is the right box's pixels in the shared rows, all the right camera
/// shows of an object the left image's left border cuts (core:
/// `stereo::zsad_whole`).
#[allow(clippy::too_many_arguments)]
fn diffs(
    l: &Gray,
    r: &Gray,
    x0: i64,
    x1: i64,
    y0: i64,
    y1: i64,
    d: i64,
    need: usize,
) -> Option<Vec<f64>> {
    let x1 = x1.min(l.w as i64);
    let y1 = y1.min(l.h as i64);
    if x1 <= x0 || y1 <= y0 {
        return None;
    }
    let mut out = Vec::new();
    for y in y0..y1 {
        for x in x0..x1 {
            if let (Some(a), Some(b)) = (l.at(x, y), r.at(x - d, y)) {
                out.push(a - b);
            }
        }
    }
    let total = (((x1 - x0) * (y1 - y0)) as usize).min(need);
    (!out.is_empty() && 2 * out.len() >= total).then_some(out)
}

/// SAD per pixel over the pixels [`diffs`] accepts; with `zero_mean`
/// the mean difference of the two windows is taken out first (core:
/// `stereo::zsad_per_pixel`).
#[allow(clippy::too_many_arguments)]
fn box_sad(
    l: &Gray,
    r: &Gray,
    x0: i64,
    x1: i64,
    y0: i64,
    y1: i64,
    d: i64,
    need: usize,
    zero_mean: bool,
) -> Option<f64> {
    let v = diffs(l, r, x0, x1, y0, y1, d, need)?;
    let n = v.len() as f64;
    let mean = if zero_mean {
        v.iter().sum::<f64>() / n
    } else {
        0.0
    };
    Some(v.iter().map(|x| (x - mean).abs()).sum::<f64>() / n)
}

fn blocks(b: (i64, i64, i64, i64)) -> Vec<(i64, i64)> {
    (0..4)
        .map(|k| (b.0 + k * b.2 / 4, b.0 + (k + 1) * b.2 / 4))
        .collect()
}

/// Best match of a left box against a right box: (μ_SAD, d_o).
#[allow(clippy::too_many_arguments)]
fn match_boxes(
    l: &Gray,
    r: &Gray,
    lb: (i64, i64, i64, i64),
    rb: (i64, i64, i64, i64),
    dlo: f64,
    dhi: f64,
    zero_mean: bool,
    masked: Option<(&[(i64, i64)], usize)>,
    scan: i64,
) -> Option<(f64, f64)> {
    let y0 = lb.1.max(rb.1);
    let y1 = (lb.1 + lb.3).min(rb.1 + rb.3);
    if y1 <= y0 {
        return None;
    }
    let mut mins = Vec::new();
    let mut disps = Vec::new();
    let mut per_block: Vec<Option<f64>> = Vec::new();
    for (lx0, lx1) in blocks(lb) {
        let mut best: Option<(f64, f64)> = None;
        if lx1 > lx0 {
            for (rx0, rx1) in blocks(rb) {
                if rx1 <= rx0 {
                    continue;
                }
                let d = lx0 - rx0;
                if (d as f64) < dlo || (d as f64) > dhi {
                    continue;
                }
                if let Some(s) = sad(l, r, lx0, lx1, y0, y1, d) {
                    if best.is_none_or(|(bs, _)| s < bs) {
                        best = Some((s, d as f64));
                    }
                }
            }
        }
        if let Some((s, d)) = best {
            mins.push(s);
            disps.push(d);
        }
        per_block.push(best.map(|b| b.1));
    }
    if mins.is_empty() {
        return None;
    }
    let mu = mins.iter().sum::<f64>() / mins.len() as f64;
    let dmean = disps.iter().sum::<f64>() / disps.len() as f64;
    let mut cands: Vec<f64> = per_block.iter().map(|d| d.unwrap_or(dmean)).collect();
    cands.push((lb.0 - rb.0) as f64);
    cands.push((lb.0 + lb.2 - rb.0 - rb.2) as f64);
    // the right box's pixels in the shared rows: what the right camera
    // shows of an object (all of it the left border leaves, see `diffs`)
    let rows = (y1.min(l.h as i64).min(r.h as i64) - y0).max(0);
    let need = (((rb.0 + rb.2).min(r.w as i64) - rb.0).max(0) * rows) as usize;
    let mut best = (f64::INFINITY, dmean);
    for c in cands {
        if c < dlo || c > dhi {
            continue;
        }
        // the core truncates toward zero when it turns a candidate into a shift
        let d = c.trunc() as i64;
        let sc = match masked {
            // on the left object's widened mask (core: `stereo::masked_d_o`)
            Some((t, area)) if zero_mean => {
                super::epipolar::cost_need(l, r, t, d, (1, 1), (0.5, area))
            }
            _ => box_sad(l, r, lb.0, lb.0 + lb.2, y0, y1, d, need, zero_mean),
        };
        if let Some(s) = sc {
            if s < best.0 {
                best = (s, c);
            }
        }
    }
    // then every whole disparity near it on the mask: the candidates are
    // where blocks and box edges put the fish, the true shift can lie
    // between them (a view the border cuts)
    if let (Some((t, area)), true, true) = (masked, zero_mean, scan > 0) {
        let c0 = best.1.trunc() as i64;
        let mut found: Option<(f64, i64)> = None;
        for d in (c0 - scan)..=(c0 + scan) {
            if (d as f64) < dlo || (d as f64) > dhi {
                continue;
            }
            if let Some(s) = super::epipolar::cost_need(l, r, t, d, (1, 1), (0.5, area)) {
                if found.is_none_or(|(b, _)| s < b) {
                    found = Some((s, d));
                }
            }
        }
        if let Some((_, d)) = found {
            best.1 = d as f64;
        }
    }
    Some((mu, best.1))
}

fn plausible_shapes(
    lb: (i64, i64, i64, i64),
    rb: (i64, i64, i64, i64),
    w: i64,
    h: i64,
    lim: &Limits,
) -> bool {
    let overlap = (lb.1 + lb.3).min(rb.1 + rb.3) - lb.1.max(rb.1);
    if overlap <= 0 || (overlap as f64) < lim.min_row_overlap * lb.3.min(rb.3).max(1) as f64 {
        return false;
    }
    let cut_x = |b: (i64, i64, i64, i64)| b.0 == 0 || b.0 + b.2 >= w;
    let cut_y = |b: (i64, i64, i64, i64)| b.1 == 0 || b.1 + b.3 >= h;
    let ratio = |a: i64, b: i64| a.min(b) as f64 / a.max(b).max(1) as f64;
    if !(cut_x(lb) || cut_x(rb)) && ratio(lb.2, rb.2) < lim.min_size_ratio {
        return false;
    }
    if !(cut_y(lb) || cut_y(rb)) && ratio(lb.3, rb.3) < lim.min_size_ratio {
        return false;
    }
    true
}

/// Pairs left and right objects: plausible candidates by object-height
/// blocks, then the assignment with the most pairs and least summed μ_SAD,
/// then the occlusion exception.
pub fn pair(
    l: &Gray,
    r: &Gray,
    left: &[RefObject],
    right: &[RefObject],
    geom: &Geometry,
    lim: &Limits,
) -> Vec<RefPair> {
    let dlo = geom.disparity_at_depth(lim.max_range) - lim.slack;
    let dhi = geom.disparity_at_depth(lim.min_range) + lim.slack;
    // cand[i] = plausible (j, μ, d_o), cheapest first
    let mut cand: Vec<Vec<(usize, f64, f64)>> = vec![Vec::new(); left.len()];
    for (i, lo) in left.iter().enumerate() {
        // the widened mask the d_o candidates are scored on
        // (an object without mask pixels is scored on its box)
        let tmpl = (lim.masked_d_o && !lo.pixels.is_empty()).then(|| {
            super::epipolar::template(lo, ((lo.h_o / 4.0).floor() as i64).max(4), l.w as i64)
        });
        for (j, ro) in right.iter().enumerate() {
            let (lb, rb) = (lo.bbox, ro.bbox);
            if lb.2 == 0 || lb.3 == 0 || rb.2 == 0 || rb.3 == 0 {
                continue;
            }
            if !plausible_shapes(lb, rb, l.w as i64, l.h as i64, lim) {
                continue;
            }
            if ((lb.0 + lb.2 - rb.0) as f64) < dlo || ((lb.0 - rb.0 - rb.2) as f64) > dhi {
                continue;
            }
            let masked = tmpl.as_deref().map(|t| (t, ro.pixels.len()));
            if let Some((mu, d)) = match_boxes(
                l,
                r,
                lb,
                rb,
                dlo,
                dhi,
                lim.zero_mean_d_o,
                masked,
                lim.d_o_scan,
            ) {
                if mu <= lim.max_sad {
                    cand[i].push((j, mu, d));
                }
            }
        }
        cand[i].sort_by(|a, b| a.1.total_cmp(&b.1));
    }
    // exhaustive search: maximise the number of pairs, then minimise the cost
    fn search(
        i: usize,
        cand: &[Vec<(usize, f64, f64)>],
        used: &mut Vec<bool>,
        cur: &mut Vec<Option<usize>>,
        cost: f64,
        best: &mut (usize, f64, Vec<Option<usize>>),
    ) {
        if i == cand.len() {
            let n = cur.iter().filter(|c| c.is_some()).count();
            if n > best.0 || (n == best.0 && cost < best.1 - 1e-9) {
                *best = (n, cost, cur.clone());
            }
            return;
        }
        let remaining_possible = cur.iter().filter(|c| c.is_some()).count() + (cand.len() - i);
        if remaining_possible < best.0 {
            return;
        }
        for &(j, mu, _) in &cand[i] {
            if !used[j] {
                used[j] = true;
                cur.push(Some(j));
                search(i + 1, cand, used, cur, cost + mu, best);
                cur.pop();
                used[j] = false;
            }
        }
        cur.push(None);
        search(i + 1, cand, used, cur, cost, best);
        cur.pop();
    }
    let mut best = (0usize, f64::INFINITY, vec![None; left.len()]);
    search(
        0,
        &cand,
        &mut vec![false; right.len()],
        &mut Vec::new(),
        0.0,
        &mut best,
    );
    let mut pairs: Vec<RefPair> = Vec::new();
    for (i, a) in best.2.iter().enumerate() {
        if let Some(j) = a {
            let &(_, mu, d) = cand[i]
                .iter()
                .find(|c| c.0 == *j)
                .expect("assigned candidate exists");
            pairs.push(RefPair {
                left: i,
                right: *j,
                d_o: d,
                mu_sad: mu,
                occluded: false,
                searched: false,
            });
        }
    }
    // occlusion exception
    let covered = |b: (i64, i64, i64, i64), d: f64, by: (i64, i64, i64, i64)| -> f64 {
        let x = (b.0 as f64 - d).max(0.0).trunc() as i64;
        let ix = ((x + b.2).min(by.0 + by.2) - x.max(by.0)).max(0);
        let iy = ((b.1 + b.3).min(by.1 + by.3) - b.1.max(by.1)).max(0);
        (ix * iy) as f64 / (b.2 * b.3).max(1) as f64
    };
    let assigned = pairs.clone();
    for (i, c) in cand.iter().enumerate() {
        if assigned.iter().any(|p| p.left == i) {
            continue;
        }
        let Some(&(j, mu, d)) = c.first() else {
            continue;
        };
        if let Some(other) = assigned.iter().find(|p| p.right == j) {
            let rb = right[j].bbox;
            if covered(left[i].bbox, d, rb) >= 0.9
                && covered(left[other.left].bbox, other.d_o, rb) >= 0.9
            {
                pairs.push(RefPair {
                    left: i,
                    right: j,
                    d_o: d,
                    mu_sad: mu,
                    occluded: true,
                    searched: false,
                });
            }
        }
    }
    pairs.sort_by_key(|p| p.left);
    pairs
}

/// The k-th extreme projections of an object's pixel centres on its axis.
fn extent(o: &RefObject) -> (f64, f64) {
    let (ux, uy) = (o.angle.cos(), o.angle.sin());
    let mut t: Vec<f64> = o
        .pixels
        .iter()
        .map(|&(x, y)| (x as f64 - o.centre.0) * ux + (y as f64 - o.centre.1) * uy)
        .collect();
    t.sort_by(|a, b| a.total_cmp(b));
    let k = (1 + o.pixels.len() / 4096).min(16).min(t.len()).max(1);
    (t[k - 1], t[t.len() - k])
}

fn box_mean(img: &Gray, x: i64, y: i64) -> f64 {
    let mut s = 0.0;
    for dy in -2..=2 {
        for dx in -2..=2 {
            s += img.clamped(x + dx, y + dy);
        }
    }
    s / 25.0
}

/// Background median and robust SD on a ring around the box.
pub(crate) fn background(img: &Gray, b: (i64, i64, i64, i64), margin: i64) -> (f64, f64) {
    let x0 = (b.0 - margin).max(0);
    let y0 = (b.1 - margin).max(0);
    let x1 = (b.0 + b.2 + margin).min(img.w as i64);
    let y1 = (b.1 + b.3 + margin).min(img.h as i64);
    let (w, h) = (x1 - x0, y1 - y0);
    if w <= 0 || h <= 0 {
        return (0.0, 0.0);
    }
    let per = 2 * (w + h);
    let step = ((per + 511) / 512).max(1);
    let mut v = Vec::new();
    let mut k = 0;
    while k < per && v.len() < 512 {
        let (x, y) = if k < w {
            (x0 + k, y0)
        } else if k < 2 * w {
            (x0 + k - w, y1 - 1)
        } else if k < 2 * w + h {
            (x0, y0 + k - 2 * w)
        } else {
            (x1 - 1, y0 + k - 2 * w - h)
        };
        if let Some(p) = img.at(x, y) {
            v.push(p);
        }
        k += step;
    }
    if v.is_empty() {
        return (0.0, 0.0);
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let med = v[v.len() / 2];
    let mut dev: Vec<f64> = v.iter().map(|p| (p - med).abs()).collect();
    dev.sort_by(|a, b| a.total_cmp(b));
    (med, 1.4826 * dev[dev.len() / 2])
}

/// The tail snake: how far beyond the end (along `u`) an accepted region
/// reaches, and its filled area (contour area × fraction above the level).
#[allow(clippy::too_many_arguments)]
fn snake(
    img: &Gray,
    end: (f64, f64),
    u: (f64, f64),
    h_o: f64,
    body_mean: f64,
    bg: (f64, f64),
    fin: f64,
    p: &fishtrack_core::snake::SnakeParams,
) -> Option<(f64, f64)> {
    const K: usize = fishtrack_core::snake::SNAKE_POINTS;
    let h_o = h_o.clamp(4.0, 4096.0);
    let radius = h_o / 4.0;
    let centre = (end.0 + u.0 * radius, end.1 + u.1 * radius);
    let mut above = p.level_fraction as f64 * (body_mean - bg.0).max(0.0);
    if fin > 0.0 {
        above = above.min(p.fin_level_fraction as f64 * fin);
    }
    let level = (2.0 * (bg.0 + above.max(3.0 * bg.1 / 5.0 + 1.0))).round() * 0.5;
    let mut pts: Vec<(f64, f64)> = (0..K)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / K as f64;
            // on whole pixels (core: `snake::tail_snake`)
            (
                (centre.0 + radius * a.cos()).round(),
                (centre.1 + radius * a.sin()).round(),
            )
        })
        .collect();
    let reach = p.reach.clamp(1, 4) as i64;
    let grad = |x: i64, y: i64| {
        let gx = box_mean(img, x + 1, y) - box_mean(img, x - 1, y);
        let gy = box_mean(img, x, y + 1) - box_mean(img, x, y - 1);
        (gx * gx + gy * gy).sqrt()
    };
    for _ in 0..p.iterations.min(1000) {
        let mut moved = false;
        let dbar =
            ((0..K).map(|i| dist(pts[i], pts[(i + 1) % K])).sum::<f64>() / K as f64).max(0.5);
        let g = (
            pts.iter().map(|q| q.0).sum::<f64>() / K as f64,
            pts.iter().map(|q| q.1).sum::<f64>() / K as f64,
        );
        for i in 0..K {
            let (prev, cur, next) = (pts[(i + K - 1) % K], pts[i], pts[(i + 1) % K]);
            let mut n = (next.1 - prev.1, -(next.0 - prev.0));
            if n.0 * (cur.0 - g.0) + n.1 * (cur.1 - g.1) < 0.0 {
                n = (-n.0, -n.1);
            }
            let nn = (n.0 * n.0 + n.1 * n.1).sqrt();
            if nn > 1e-6 {
                n = (n.0 / nn, n.1 / nn);
            }
            let mut cands = Vec::new();
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let q = (cur.0 + dx as f64, cur.1 + dy as f64);
                    if q.0 < 0.0
                        || q.1 < 0.0
                        || q.0 > img.w as f64 - 1.0
                        || q.1 > img.h as f64 - 1.0
                    {
                        continue;
                    }
                    if (q.0 - end.0) * u.0 + (q.1 - end.1) * u.1 < 0.0 {
                        continue;
                    }
                    let (qx, qy) = (q.0 as i64, q.1 as i64);
                    let inside = if box_mean(img, qx, qy) >= level {
                        1.0
                    } else {
                        -1.0
                    };
                    let push = (dx as f64 * n.0 + dy as f64 * n.1) / reach as f64;
                    let cont = (dbar - dist(q, prev)).abs() / dbar;
                    let curv = ((prev.0 - 2.0 * q.0 + next.0).powi(2)
                        + (prev.1 - 2.0 * q.1 + next.1).powi(2))
                        / (dbar * dbar);
                    let internal = p.alpha as f64 * cont + p.beta as f64 * curv;
                    cands.push((q, internal, grad(qx, qy), -(p.kappa as f64) * inside * push));
                }
            }
            let gmax = cands.iter().map(|c| c.2).fold(1e-3, f64::max);
            let best = cands
                .iter()
                .map(|c| (c.1 - p.gamma as f64 * c.2 / gmax + c.3, c.0))
                .fold((f64::INFINITY, cur), |b, c| if c.0 < b.0 { c } else { b });
            if best.1 != cur {
                pts[i] = best.1;
                moved = true;
            }
        }
        if !moved {
            break;
        }
    }
    let area = 0.5
        * (0..K)
            .map(|i| pts[i].0 * pts[(i + 1) % K].1 - pts[(i + 1) % K].0 * pts[i].1)
            .sum::<f64>()
            .abs();
    let (x0, x1) = pts
        .iter()
        .fold((f64::MAX, f64::MIN), |a, q| (a.0.min(q.0), a.1.max(q.0)));
    let (y0, y1) = pts
        .iter()
        .fold((f64::MAX, f64::MIN), |a, q| (a.0.min(q.1), a.1.max(q.1)));
    let (mut n_in, mut n_hi, mut far, mut near) = (0usize, 0usize, f64::MIN, f64::MAX);
    for y in (y0.max(0.0) as i64)..=(y1.min(img.h as f64 - 1.0) as i64) {
        for x in (x0.max(0.0) as i64)..=(x1.min(img.w as f64 - 1.0) as i64) {
            if !inside_polygon(&pts, x as f64, y as f64) {
                continue;
            }
            n_in += 1;
            if box_mean(img, x, y) >= level {
                n_hi += 1;
                let t = (x as f64 - end.0) * u.0 + (y as f64 - end.1) * u.1;
                far = far.max(t);
                near = near.min(t);
            }
        }
    }
    let accepted = n_in > 0
        && area >= 0.25 * radius * radius * std::f64::consts::PI
        && n_hi as f64 / n_in as f64 >= 0.6
        && near <= radius
        && far > 1.0;
    accepted.then_some((far, area * (n_hi as f64 / n_in as f64)))
}

/// Mean of the `side × side` square centred `side/2 + 1` pixels beyond
/// `end` along `u` (as `core::snake::end_probe`), as the core rounds it
/// (`sum as f32 / n as f32`; the sum of ≤ 256² bytes is exact in f32), so
/// the probe gate decides on the same numbers in both implementations.
fn probe(img: &Gray, end: (f64, f64), u: (f64, f64), side: i64) -> Option<f32> {
    let side = side.clamp(1, 256);
    let off = side as f64 * 0.5 + 1.0;
    let x0 = (end.0 + u.0 * off).round() as i64 - side / 2;
    let y0 = (end.1 + u.1 * off).round() as i64 - side / 2;
    let (mut sum, mut n) = (0.0, 0i64);
    for y in y0..y0 + side {
        for x in x0..x0 + side {
            if let Some(v) = img.at(x, y) {
                sum += v;
                n += 1;
            }
        }
    }
    (n > 0 && 2 * n >= side * side).then(|| sum as f32 / n as f32)
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt()
}

fn inside_polygon(p: &[(f64, f64)], x: f64, y: f64) -> bool {
    let mut inside = false;
    let mut j = p.len() - 1;
    for i in 0..p.len() {
        if (p[i].1 > y) != (p[j].1 > y)
            && x < p[j].0 + (y - p[j].1) * (p[i].0 - p[j].0) / (p[i].1 - p[j].1)
        {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// A reference length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefLength {
    /// `L = ‖x_H − x_T‖`, mm.
    pub length: f64,
    /// The two 3-D end points.
    pub ends: [Vector3<f64>; 2],
    /// Which ends the snake extended.
    pub compensated: [bool; 2],
    /// Both views' masks agree at every uncompensated end (the length is usable).
    pub consistent: bool,
}

/// Options as in `core::length::LengthConfig`.
pub type LengthConfig = fishtrack_core::length::LengthConfig;

/// 3-D length of one pair (Section IV.D).
#[allow(clippy::too_many_arguments)]
pub fn length(
    l: &Gray,
    r: &Gray,
    left: &[RefObject],
    right: &[RefObject],
    p: &RefPair,
    geom: &Geometry,
    params: &Params,
    cfg: &LengthConfig,
) -> Option<RefLength> {
    let lo = left.get(p.left)?;
    let ro = right.get(p.right)?;
    if lo.pixels.is_empty() || ro.pixels.is_empty() {
        return None;
    }
    let u = (lo.angle.cos(), lo.angle.sin());
    let (t_lo, t_hi) = extent(lo);
    let (t_lo, t_hi) = (t_lo - 0.5, t_hi + 0.5);
    let ru = (ro.angle.cos(), ro.angle.sin());
    let (rt_lo, rt_hi) = extent(ro);
    let (rt_lo, rt_hi) = (rt_lo - 0.5, rt_hi + 0.5);
    let rends = [
        (
            (ro.centre.0 + rt_lo * ru.0, ro.centre.1 + rt_lo * ru.1),
            -1.0,
        ),
        (
            (ro.centre.0 + rt_hi * ru.0, ro.centre.1 + rt_hi * ru.1),
            1.0,
        ),
    ];
    let h_o = lo.h_o.clamp(2.0, 1024.0);
    let side = h_o.round() as i64;
    let mu = p.mu_sad.max(1.0);
    let bg = background(l, lo.bbox, (h_o * 0.5) as i64);
    let rh_o = ro.h_o.clamp(2.0, 1024.0);
    let rbg = background(r, ro.bbox, (rh_o * 0.5) as i64);
    let mut ts = [t_lo, t_hi];
    let mut comp = [false; 2];
    let mut mask_d = [0.0f64; 2];
    let mut flagged_ends = [false; 2];
    // mask pixels in the last tenth of each end (core: `fin::end_slabs`):
    // a fish tapers to its tail and is blunt at its head
    let span = t_hi - t_lo;
    let t_of =
        |&(x, y): &(i64, i64)| (x as f64 - lo.centre.0) * u.0 + (y as f64 - lo.centre.1) * u.1;
    let slab0 = lo
        .pixels
        .iter()
        .filter(|q| t_of(q) <= t_lo + 0.1 * span)
        .count();
    let slab1 = lo
        .pixels
        .iter()
        .filter(|q| t_of(q) >= t_hi - 0.1 * span)
        .count();
    for (e, s) in [(0usize, -1.0f64), (1, 1.0)] {
        let end = (lo.centre.0 + ts[e] * u.0, lo.centre.1 + ts[e] * u.1);
        let &(re, rs) = rends.iter().min_by(|a, b| {
            let da = (a.0 .0 + p.d_o - end.0).powi(2) + (a.0 .1 - end.1).powi(2);
            let db = (b.0 .0 + p.d_o - end.0).powi(2) + (b.0 .1 - end.1).powi(2);
            da.total_cmp(&db)
        })?;
        mask_d[e] = end.0 - re.0;
        // eq. (15): end squares inside each object's end, SAD ratio to μ_SAD
        let cl = (end.0 - s * u.0 * h_o / 2.0, end.1 - s * u.1 * h_o / 2.0);
        let cr = (re.0 - rs * ru.0 * h_o / 2.0, re.1 - rs * ru.1 * h_o / 2.0);
        let (lx, ly) = (
            cl.0.round() as i64 - side / 2,
            cl.1.round() as i64 - side / 2,
        );
        let (rx, ry) = (
            cr.0.round() as i64 - side / 2,
            cr.1.round() as i64 - side / 2,
        );
        let (mut sum, mut n) = (0.0, 0i64);
        for j in 0..side {
            for i in 0..side {
                if let (Some(a), Some(b)) = (l.at(lx + i, ly + j), r.at(rx + i, ry + j)) {
                    sum += (a - b).abs();
                    n += 1;
                }
            }
        }
        let ratio = if n > 0 && 4 * n >= side * side {
            sum / n as f64 / mu
        } else {
            0.0
        };
        let mismatch = ratio * cfg.sad_ratio_scale as f64 > params.theta_sad as f64;
        let left_short = (re.0 + p.d_o - end.0) * s * u.0 + (re.1 - end.1) * s * u.1 > 1.0;
        let flagged = mismatch && left_short;
        flagged_ends[e] = flagged;
        // the probe gate: something brighter than the background continues
        // past the end in both views
        let pside = ((h_o * 0.5) as i64).max(3);
        // a threshold decision, so in the core's f32 arithmetic on the same
        // integers (median, MAD, probe sum) and the same f32 body mean: a
        // probe a rounding error from the gate goes the same way in both
        let sigma = 1.4826f32 * (bg.1 / 1.4826).round() as f32;
        let contrast = lo.mean as f32 - bg.0 as f32;
        let pl = probe(l, end, (s * u.0, s * u.1), pside).map_or(0.0, |m| m - bg.0 as f32);
        let pr = probe(r, re, (rs * ru.0, rs * ru.1), pside).map_or(0.0, |m| m - rbg.0 as f32);
        let gate = (cfg.probe_noise_k * sigma)
            .max(cfg.probe_body_fraction * contrast)
            .max(1.0);
        let ceiling = cfg.probe_max_body_fraction * contrast;
        let probed =
            !cfg.probe_gate || (pl >= gate && pr >= gate && pl <= ceiling && pr <= ceiling);
        let (pl, pr) = (pl as f64, pr as f64);
        let (fl, fr) = if cfg.probe_gate && !flagged {
            (pl, pr)
        } else {
            (0.0, 0.0)
        };
        if params.tail_compensation && (flagged || (cfg.snake_every_end && probed)) {
            if let Some((far, filled)) =
                snake(l, end, (s * u.0, s * u.1), h_o, lo.mean, bg, fl, &cfg.snake)
            {
                // the right view must show the same tail (unless eq. 15 flagged the end)
                let agree = !cfg.snake_both_views
                    || flagged
                    || snake(
                        r,
                        re,
                        (rs * ru.0, rs * ru.1),
                        rh_o,
                        ro.mean,
                        rbg,
                        fr,
                        &cfg.snake,
                    )
                    .is_some_and(|(rfar, _)| (rfar - far).abs() <= (0.3 * far).max(4.0));
                let fan = filled >= cfg.min_fin_fill as f64 * far * h_o;
                // an end eq. (15) did not flag: only the tail (the smaller slab)
                let tail = flagged
                    || !cfg.tail_by_taper
                    || if e == 0 { slab0 < slab1 } else { slab1 < slab0 };
                if agree && fan && tail && far <= cfg.max_tail_fraction as f64 * (t_hi - t_lo) {
                    ts[e] += s * far;
                    comp[e] = true;
                }
            }
        }
    }
    if comp[0] && comp[1] {
        ts = [t_lo, t_hi];
        comp = [false; 2];
    }
    // refinement on the dense grid, then the resistant line d(t)
    let blocks = refine(
        l,
        r,
        lo,
        p.d_o,
        params.refine_block as i64,
        params.refine_range as i64,
    );
    let mut td: Vec<(f64, f64)> = blocks
        .iter()
        .map(|&(x, y, d)| ((x - lo.centre.0) * u.0 + (y - lo.centre.1) * u.1, d))
        .collect();
    let (a, b) = if td.len() >= (cfg.min_blocks.max(3)) as usize {
        td.sort_by(|p, q| p.0.total_cmp(&q.0));
        let g = (td.len() / 3).max(1);
        let (mut tl, mut dl): (Vec<f64>, Vec<f64>) = td[..g].iter().cloned().unzip();
        let (mut tr, mut dr): (Vec<f64>, Vec<f64>) = td[td.len() - g..].iter().cloned().unzip();
        let (tl, dl, tr, dr) = (
            median(&mut tl),
            median(&mut dl),
            median(&mut tr),
            median(&mut dr),
        );
        let b = if tr - tl > 1e-3 {
            (dr - dl) / (tr - tl)
        } else {
            0.0
        };
        let mut res: Vec<f64> = td.iter().map(|q| q.1 - b * q.0).collect();
        (median(&mut res), b)
    } else if !td.is_empty() {
        let mut d: Vec<f64> = td.iter().map(|q| q.1).collect();
        (median(&mut d), 0.0)
    } else {
        (p.d_o, 0.0)
    };
    // the slanted fit on the whole widened mask (core: `slant::fit_slant`)
    let (a, b) = if cfg.slant_fit {
        let ax = super::slant::Axis {
            c: lo.centre,
            u,
            t: (t_lo, t_hi),
        };
        let m = ((lo.h_o / 4.0).floor() as i64).max(4);
        let starts = [
            (a + b * t_lo, a + b * t_hi),
            (mask_d[0], mask_d[1]),
            (p.d_o, p.d_o),
        ];
        match super::slant::fit(l, r, lo, m, &ax, &starts) {
            Some((d0, d1)) => {
                let span = t_hi - t_lo;
                let b = if span > 1e-3 { (d1 - d0) / span } else { 0.0 };
                (d0 - b * t_lo, b)
            }
            None => (a, b),
        }
    } else {
        (a, b)
    };
    // a dim fin by its averaged profile where no snake extended an end
    // (core: `fin::fin_reach` in `length::measure_length`)
    if params.tail_compensation && cfg.fin_profile && !comp[0] && !comp[1] {
        let len = ((cfg.max_tail_fraction as f64 * (t_hi - t_lo)) as usize).clamp(8, 1024);
        let half = ((h_o / 3.0) as i64).max(2);
        let k = cfg.fin_noise_k as f64;
        let mut reach = [None::<f64>; 2];
        for (e, s) in [(0usize, -1.0f64), (1, 1.0)] {
            let t = ts[e];
            let end = (lo.centre.0 + t * u.0, lo.centre.1 + t * u.1);
            let dir = (s * u.0, s * u.1);
            let lr = super::fin::reach(l, end, dir, half, len, |_| 0.0, bg.1, lo.mean - bg.0, k);
            let rr = super::fin::reach(
                r,
                end,
                dir,
                half,
                len,
                |q| a + b * (t + s * q),
                rbg.1,
                ro.mean - rbg.0,
                k,
            );
            if let (Some(rl), Some(rr)) = (lr, rr) {
                let lim = (len - 1) as f64;
                if rl >= 3.0
                    && rr >= 3.0
                    && rl < lim
                    && rr < lim
                    && (rl - rr).abs() <= (0.3 * rl).max(4.0)
                {
                    reach[e] = Some(rl.min(rr));
                }
            }
        }
        // only at the tail: the end whose last tenth holds fewer pixels
        match reach {
            [Some(q), None] if !cfg.tail_by_taper || slab0 < slab1 => {
                ts[0] -= q;
                comp[0] = true;
            }
            [None, Some(q)] if !cfg.tail_by_taper || slab1 < slab0 => {
                ts[1] += q;
                comp[1] = true;
            }
            _ => {}
        }
    }
    let mut ends = [Vector3::zeros(); 2];
    let mut consistent = true;
    let t_orig = [t_lo, t_hi];
    // each unextended end: the masks' own disparity where it agrees with
    // the line (not at an end eq. 15 flagged), else the line's
    let mut d_end = [0.0f64; 2];
    let mut dev = [0.0f64; 2];
    for e in 0..2 {
        let d_line = a + b * t_orig[e];
        dev[e] = (mask_d[e] - d_line).abs() / d_line.abs().max(1.0);
        let mask_ok = !(comp[e] && flagged_ends[e])
            && (mask_d[e] - d_line).abs() <= cfg.mask_end_tolerance as f64;
        d_end[e] = if mask_ok { mask_d[e] } else { d_line };
    }
    // an extended end continues the chord through the two unextended ends
    let chord = if t_hi - t_lo > 1e-3 {
        (d_end[1] - d_end[0]) / (t_hi - t_lo)
    } else {
        b
    };
    for e in 0..2 {
        let (x, y) = (lo.centre.0 + ts[e] * u.0, lo.centre.1 + ts[e] * u.1);
        let d = if !comp[e] {
            d_end[e]
        } else if cfg.chord_extension {
            d_end[e] + chord * (ts[e] - t_orig[e])
        } else {
            a + b * ts[e]
        };
        // an end against another left object may be an occluder's edge
        if cfg.occlusion_radius_fraction > 0.0 {
            let te = t_orig[e];
            let pe = (lo.centre.0 + te * u.0, lo.centre.1 + te * u.1);
            let rad = (cfg.occlusion_radius_fraction as f64 * h_o).clamp(3.0, 32.0);
            let near = left.iter().enumerate().any(|(k, o)| {
                k != p.left
                    && o.pixels.iter().any(|&(px, py)| {
                        (px as f64 - pe.0).powi(2) + (py as f64 - pe.1).powi(2) <= rad * rad
                    })
            });
            if near {
                consistent = false;
            }
        }
        let gated = !comp[e] || (cfg.gate_extended_ends && !flagged_ends[e]);
        let agrees = dev[e] <= cfg.max_end_disagreement as f64; // false for NaN
        if gated && !agrees {
            consistent = false;
        }
        ends[e] = geom.triangulate(x, y, d)?;
    }
    Some(RefLength {
        length: (ends[1] - ends[0]).norm(),
        ends,
        compensated: comp,
        // a searched pair's right mask is its left one shifted: withheld
        consistent: consistent && !p.searched,
    })
}

/// Dense-grid disparity refinement: `(centre x, centre y, disparity)` of the
/// blocks at least half inside the mask whose SAD minimum is inside the range.
fn refine(
    l: &Gray,
    r: &Gray,
    o: &RefObject,
    d_o: f64,
    block: i64,
    range: i64,
) -> Vec<(f64, f64, f64)> {
    let (bx, by, bw, bh) = o.bbox;
    let bx1 = (bx + bw).min(l.w as i64);
    let by1 = (by + bh).min(l.h as i64);
    let (bx, by) = (bx.max(0), by.max(0));
    let (bw, bh) = (bx1 - bx, by1 - by);
    if bw <= 0 || bh <= 0 || block <= 0 {
        return Vec::new();
    }
    // the core's grid holds at most REFINE_BLOCKS blocks: the same spacing
    let cap = fishtrack_core::pipeline::REFINE_BLOCKS as i64;
    let mut s_cap = ((bw * bh) as f64 / cap as f64).sqrt().floor().max(1.0) as i64;
    while s_cap * s_cap * cap < bw * bh {
        s_cap += 1;
    }
    while (bw / s_cap) * (bh / s_cap) > cap {
        s_cap += 1;
    }
    let step = block.max((bw + 255) / 256).max(s_cap);
    let bs = block.min(step);
    let (cols, rows) = (bw / step, bh / step);
    let (x_off, y_off) = (bx + (bw - cols * step) / 2, by + (bh - rows * step) / 2);
    let mask: std::collections::HashSet<(i64, i64)> = o.pixels.iter().cloned().collect();
    let d0 = d_o.round() as i64;
    let mut out = Vec::new();
    for gy in 0..rows {
        for gx in 0..cols {
            let (x0, y0) = (x_off + gx * step, y_off + gy * step);
            let inside = (y0..y0 + bs)
                .flat_map(|y| (x0..x0 + bs).map(move |x| (x, y)))
                .filter(|q| mask.contains(q))
                .count();
            if 2 * inside < (bs * bs) as usize {
                continue;
            }
            let costs: Vec<(i64, f64)> = (d0 - range..=d0 + range)
                .map(|d| {
                    (
                        d,
                        sad(l, r, x0, x0 + bs, y0, y0 + bs, d).unwrap_or(f64::INFINITY),
                    )
                })
                .collect();
            let (bi, &(bd, bc)) = costs.iter().enumerate().fold((0, &costs[0]), |b, (i, c)| {
                if c.1 < b.1 .1 {
                    (i, c)
                } else {
                    b
                }
            });
            if !bc.is_finite() || bd == d0 - range || bd == d0 + range {
                continue;
            }
            let (a, c) = (costs[bi - 1].1, costs[bi + 1].1);
            let mut frac = 0.0;
            if a.is_finite() && c.is_finite() {
                let den = if a < c { c - bc } else { a - bc };
                if den > 1e-6 {
                    frac = (0.5 * (a - c) / den).clamp(-0.5, 0.5);
                }
            }
            out.push((
                x0 as f64 + bs as f64 / 2.0 - 0.5,
                y0 as f64 + bs as f64 / 2.0 - 0.5,
                bd as f64 + frac,
            ));
        }
    }
    out
}

/// Agreement of the core with the reference on one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Agreement {
    /// The (left, right) pair sets are identical.
    pub pairs_identical: bool,
    /// Largest relative length difference over pairs measured by both.
    pub max_length_rel_diff: f64,
    /// Pairs measured by exactly one of the two.
    pub measured_by_one: usize,
}

impl Agreement {
    /// The `fishtrack compare` criterion: identical pairs, lengths within 0.5 %.
    pub fn ok(&self) -> bool {
        self.pairs_identical && self.measured_by_one == 0 && self.max_length_rel_diff <= 0.005
    }
}

/// Compares the core's pairs and lengths (`(left, right, length_mm)`) with
/// the reference's.
pub fn compare(
    core: &[(usize, usize, Option<f64>)],
    reference: &[(usize, usize, Option<f64>)],
) -> Agreement {
    let mut a: Vec<(usize, usize)> = core.iter().map(|c| (c.0, c.1)).collect();
    let mut b: Vec<(usize, usize)> = reference.iter().map(|c| (c.0, c.1)).collect();
    a.sort();
    b.sort();
    let mut worst = 0.0f64;
    let mut one = 0;
    for c in core {
        if let Some(r) = reference.iter().find(|r| r.0 == c.0 && r.1 == c.1) {
            match (c.2, r.2) {
                (Some(x), Some(y)) => worst = worst.max((x - y).abs() / y.abs().max(1e-9)),
                (None, None) => {}
                _ => one += 1,
            }
        }
    }
    Agreement {
        pairs_identical: a == b,
        max_length_rel_diff: worst,
        measured_by_one: one,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn q_roundtrip_and_triangulation() {
        let g = Geometry {
            f: 1400.0,
            cx: 1000.0,
            cy: 990.0,
            cx_right: 1010.0,
            baseline: 150.0,
        };
        let back = Geometry::from_q(&g.q());
        assert!(
            (back.cx_right - g.cx_right).abs() < 1e-9 && (back.baseline - g.baseline).abs() < 1e-9
        );
        let p = g.triangulate(1200.0, 800.0, 90.0).unwrap();
        // Z = f·B / (d − (cx − cx'))
        assert!((p.z - 1400.0 * 150.0 / 100.0).abs() < 1e-9);
        assert!(g.triangulate(0.0, 0.0, -10.0).is_none());
    }

    #[test]
    fn compare_flags_differences() {
        let c = [(0, 1, Some(100.0)), (1, 0, Some(200.0))];
        let r = [(0, 1, Some(100.2)), (1, 0, Some(200.0))];
        assert!(compare(&c, &r).ok());
        let r2 = [(0, 1, Some(101.0)), (1, 0, Some(200.0))];
        assert!(!compare(&c, &r2).ok());
        let r3 = [(0, 0, Some(100.0))];
        assert!(!compare(&c, &r3).pairs_identical);
    }
}
