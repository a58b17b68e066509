//! Reference automatic fish segmentation (paper Section III, V.A) in `f64`.
//!
//! Same stages and conventions as `fishtrack_core::segment` (see its module
//! docs), built independently:
//! - morphology: `imageproc::morphology::grayscale_{erode,dilate}` with
//!   masks built from OpenCV's `MORPH_ELLIPSE` formula evaluated in `f64`
//!   and from `np.eye`-style diagonal lines; pixels outside the image are
//!   ignored (imageproc's and OpenCV's convention);
//! - Otsu: `imageproc::contrast::otsu_level` (foreground `p > t`);
//! - eq. (1) thresholds compared as real numbers: `p > τ_x`;
//! - median: `imageproc::filter::median_filter` (replicated border);
//! - components: `imageproc::region_labelling::connected_components`,
//!   8-connectivity; moments, PCA and variances in `f64`;
//! - the elliptic region tested pixel by pixel in `f64`.
//!
//! Not modelled: the core's capacity limits (regions, ROI pixels,
//! components per region, objects, runs). Compare only frames where the
//! core reports no drops, shrinks or overflows.

use super::background::Background;
use fishtrack_core::Params;
use image::{GrayImage, Luma};
use imageproc::contrast::otsu_level;
use imageproc::distance_transform::Norm;
use imageproc::filter::median_filter;
use imageproc::morphology::{dilate, grayscale_dilate, grayscale_erode, Mask};
use imageproc::region_labelling::{connected_components, Connectivity};
use std::collections::{HashMap, HashSet};

/// Core: `local::DIM_LEVEL_SIGMAS`, `local::DIM_LEVEL_FLOOR`.
const DIM_K: f64 = fishtrack_core::segment::local::DIM_LEVEL_SIGMAS as f64;
const DIM_FLOOR: [f32; 2] = fishtrack_core::segment::local::DIM_LEVEL_FLOOR;

/// An elliptic local region of the reference, with its thresholds.
#[derive(Debug, Clone, PartialEq)]
pub struct RefRegion {
    /// Centre x.
    pub cx: f64,
    /// Centre y.
    pub cy: f64,
    /// Enlarged semi-axis along the first principal axis.
    pub a: f64,
    /// Enlarged semi-axis along the second principal axis.
    pub b: f64,
    /// First principal axis angle, radians (y down).
    pub angle: f64,
    /// Otsu's τ on the ellipse (None when the region was skipped first).
    pub tau: Option<u8>,
    /// τ_low of eq. (1), real.
    pub t_low: f64,
    /// τ_high of eq. (1), real.
    pub t_high: f64,
    /// 0: the region's own thresholds; 1: the dim level (core:
    /// `Params::dim_level`), the region again without level 0's objects.
    pub level: u8,
}

/// A segmented object of the reference.
#[derive(Debug, Clone, PartialEq)]
pub struct RefObject {
    /// Mask pixels `(x, y)`, frame coordinates.
    pub pixels: HashSet<(u32, u32)>,
    /// Index of the region that produced it.
    pub region: usize,
    /// Upright box `(x0, y0, x1, y1)`, inclusive.
    pub bbox: (u32, u32, u32, u32),
    /// Mean grey level.
    pub mean: f64,
    /// Unbiased variance, eq. (5).
    pub variance: f64,
    /// Oriented box: centre x, centre y, half width, half height, angle.
    pub obb: (f64, f64, f64, f64, f64),
    /// The level of its region that found it (`RefRegion::level`).
    pub level: u8,
}

/// Everything the reference computed for one frame.
#[derive(Debug, Clone, Default)]
pub struct RefResult {
    /// Threshold on the morphological gradient (the seed threshold of the
    /// hysteresis at reduced resolution, in 1/16 grey levels there).
    pub gradient_threshold: u16,
    /// The hysteresis' low threshold (= `gradient_threshold` at scale 1).
    pub gradient_threshold_low: u16,
    /// Measured white-noise σ of the input frame, 1/16 grey levels.
    pub noise_sigma16: u32,
    /// The variance limit of eq. (6) used.
    pub var_limit: f64,
    /// Local regions, in processing order.
    pub regions: Vec<RefRegion>,
    /// Objects after duplicate removal.
    pub objects: Vec<RefObject>,
}

/// OpenCV's `MORPH_ELLIPSE` of `size × size`, from its formula in f64:
/// row `dy` spans `±round(c·√((r² − dy²)/r²))`, `c = r = size/2`.
pub fn opencv_ellipse_mask(size: u8) -> Mask {
    let s = size.max(1) as u32;
    let r = (s / 2) as f64;
    let mut img = GrayImage::new(s, s);
    for i in 0..s {
        let dy = i as f64 - r;
        let dx = if r > 0.0 {
            (r * ((r * r - dy * dy) / (r * r)).max(0.0).sqrt()).round()
        } else {
            0.0
        };
        for j in 0..s {
            if (j as f64 - r).abs() <= dx {
                img.put_pixel(j, i, Luma([255]));
            }
        }
    }
    Mask::from_image(&img, (s / 2) as u8, (s / 2) as u8)
}

/// A diagonal line of `len` pixels: main (`np.eye`) or anti (mirrored).
pub fn line_mask(len: u8, anti: bool) -> Mask {
    let l = len.max(1) as u32;
    let mut img = GrayImage::new(l, l);
    for i in 0..l {
        let x = if anti { l - 1 - i } else { i };
        img.put_pixel(x, i, Luma([255]));
    }
    Mask::from_image(&img, (l / 2) as u8, (l / 2) as u8)
}

fn open(img: &GrayImage, m: &Mask) -> GrayImage {
    grayscale_dilate(&grayscale_erode(img, m), m)
}

fn close(img: &GrayImage, m: &Mask) -> GrayImage {
    grayscale_erode(&grayscale_dilate(img, m), m)
}

/// Section V.A mesh removal: opening by the main diagonal, then by the anti-diagonal.
pub fn remove_mesh(img: &GrayImage, len: u8) -> GrayImage {
    if len < 3 {
        return img.clone();
    }
    open(&open(img, &line_mask(len, false)), &line_mask(len, true))
}

/// Morphological gradient `dilate − erode` with the disk.
pub fn gradient(img: &GrayImage, disk: &Mask) -> GrayImage {
    let d = grayscale_dilate(img, disk);
    let e = grayscale_erode(img, disk);
    let mut g = GrayImage::new(img.width(), img.height());
    for (o, (a, b)) in g.pixels_mut().zip(d.pixels().zip(e.pixels())) {
        o.0[0] = a.0[0] - b.0[0];
    }
    g
}

/// `k × k` box mean with replicated border, halves rounded up (core:
/// `smooth::box_mean_roi`); `k = 1` is the image itself.
pub fn box_mean(img: &GrayImage, k: u32) -> GrayImage {
    if k <= 1 {
        return img.clone();
    }
    let (w, h) = img.dimensions();
    let r = (k / 2) as i64;
    let d = (k * k) as f64;
    GrayImage::from_fn(w, h, |x, y| {
        let mut s = 0u32;
        for dy in -r..=r {
            for dx in -r..=r {
                let xx = (x as i64 + dx).clamp(0, w as i64 - 1) as u32;
                let yy = (y as i64 + dy).clamp(0, h as i64 - 1) as u32;
                s += img.get_pixel(xx, yy).0[0] as u32;
            }
        }
        Luma([(s as f64 / d + 0.5).floor() as u8])
    })
}

/// `[cx, cy, cov_xx, cov_yy, cov_xy]` of a non-empty pixel set (population
/// covariance).
fn centroid_cov(comp: &[(u32, u32)]) -> [f64; 5] {
    let n = comp.len() as f64;
    let mx = comp.iter().map(|q| q.0 as f64).sum::<f64>() / n;
    let my = comp.iter().map(|q| q.1 as f64).sum::<f64>() / n;
    let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
    for &(x, y) in comp {
        let (dx, dy) = (x as f64 - mx, y as f64 - my);
        a += dx * dx;
        b += dy * dy;
        c += dx * dy;
    }
    [mx, my, a / n, b / n, c / n]
}

/// Lower median of values (the ⌈n/2⌉-th smallest).
fn lower_median(v: &mut [u32]) -> u32 {
    if v.is_empty() {
        return 0;
    }
    v.sort_unstable();
    v[v.len().div_ceil(2) - 1]
}

/// `med + 4·max(MAD, 1)` of the gradient values.
pub fn gradient_threshold(g: &GrayImage) -> u8 {
    let mut v: Vec<u32> = g.pixels().map(|p| p.0[0] as u32).collect();
    let med = lower_median(&mut v);
    let mut dev: Vec<u32> = v.iter().map(|&x| x.abs_diff(med)).collect();
    let mad = lower_median(&mut dev).max(1);
    (med + 4 * mad).min(255) as u8
}

/// PCA of a covariance: angle of the first axis in (−π/2, π/2], λ₁, λ₂.
fn pca_of(a: f64, b: f64, c: f64) -> (f64, f64, f64) {
    let d = (0.25 * (a - b) * (a - b) + c * c).sqrt();
    let l1 = 0.5 * (a + b) + d;
    let l2 = (0.5 * (a + b) - d).max(0.0);
    let mut angle = 0.5 * (2.0 * c).atan2(a - b);
    if angle <= -std::f64::consts::FRAC_PI_2 {
        angle += std::f64::consts::PI;
    }
    (angle, l1, l2)
}

/// PCA of a pixel set: centroid, angle, λ₁, λ₂ (population covariance).
pub(super) fn pca(px: &[(u32, u32)]) -> (f64, f64, f64, f64, f64) {
    let [mx, my, a, b, c] = centroid_cov(px);
    let (angle, l1, l2) = pca_of(a, b, c);
    (mx, my, angle, l1, l2)
}

/// Components of the nonzero pixels of `mask`: pixel lists in raster order
/// of first pixel.
pub(super) fn components(mask: &GrayImage) -> Vec<Vec<(u32, u32)>> {
    let lab = connected_components(mask, Connectivity::Eight, Luma([0u8]));
    let mut by: HashMap<u32, usize> = HashMap::new();
    let mut out: Vec<Vec<(u32, u32)>> = Vec::new();
    for (x, y, p) in lab.enumerate_pixels() {
        let l = p.0[0];
        if l == 0 {
            continue;
        }
        let k = *by.entry(l).or_insert_with(|| {
            out.push(Vec::new());
            out.len() - 1
        });
        out[k].push((x, y));
    }
    out
}

fn mean_var(img: &GrayImage, px: &[(u32, u32)]) -> (f64, f64) {
    let n = px.len() as f64;
    let m = px
        .iter()
        .map(|&(x, y)| img.get_pixel(x, y).0[0] as f64)
        .sum::<f64>()
        / n;
    let v = if px.len() > 1 {
        px.iter()
            .map(|&(x, y)| (img.get_pixel(x, y).0[0] as f64 - m).powi(2))
            .sum::<f64>()
            / (n - 1.0)
    } else {
        0.0
    };
    (m, v)
}

/// Oriented box by projecting the corners of every pixel on the PCA axes.
fn oriented_box(px: &[(u32, u32)]) -> (f64, f64, f64, f64, f64) {
    let (mx, my, angle, _, _) = pca(px);
    let (c, s) = (angle.cos(), angle.sin());
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in px {
        for (ox, oy) in [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)] {
            let (dx, dy) = (x as f64 + ox - mx, y as f64 + oy - my);
            let u = dx * c + dy * s;
            let v = -dx * s + dy * c;
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
    }
    let (um, vm) = (0.5 * (umin + umax), 0.5 * (vmin + vmax));
    let (hw, hh) = (0.5 * (umax - umin), 0.5 * (vmax - vmin));
    let (cx, cy) = (mx + um * c - vm * s, my + um * s + vm * c);
    if hw >= hh {
        (cx, cy, hw, hh, angle)
    } else {
        // the longer extent is the width (Fig. 3); turn the angle by 90°
        let a = angle + std::f64::consts::FRAC_PI_2;
        let a = if a > std::f64::consts::FRAC_PI_2 {
            a - std::f64::consts::PI
        } else {
            a
        };
        (cx, cy, hh, hw, a)
    }
}

/// Reduced-resolution coarse pass (core: `segment::coarse`, beyond the
/// paper): `f × f` block means × 16 rounded half up (partial border blocks
/// average what they have), gradient by the `COARSE_LOW_DISK` ellipse on
/// those values, hysteresis `med + K·max(MAD, 1)` with lower medians.
/// Returns the kept components as full-resolution regions' pixel
/// statistics `(cx, cy, cov_xx, cov_yy, cov_xy)` and the two thresholds.
pub fn coarse_low(filtered: &GrayImage, p: &Params) -> (Vec<[f64; 5]>, u16, u16) {
    use fishtrack_core::segment::coarse::{COARSE_K_HIGH, COARSE_K_LOW, COARSE_LOW_DISK};
    let f = p.coarse_scale as u32;
    let (w, h) = filtered.dimensions();
    let (lw, lh) = (w.div_ceil(f), h.div_ceil(f));
    let mut low = vec![0.0f64; (lw * lh) as usize];
    for ly in 0..lh {
        for lx in 0..lw {
            let (mut sum, mut cnt) = (0.0, 0.0);
            for y in ly * f..((ly + 1) * f).min(h) {
                for x in lx * f..((lx + 1) * f).min(w) {
                    sum += filtered.get_pixel(x, y).0[0] as f64;
                    cnt += 1.0;
                }
            }
            low[(ly * lw + lx) as usize] = (16.0 * sum / cnt + 0.5).floor();
        }
    }
    // the disk's offsets from OpenCV's MORPH_ELLIPSE formula
    let r = (COARSE_LOW_DISK / 2) as i64;
    let rf = r as f64;
    let mut offs = Vec::new();
    for dy in -r..=r {
        let hw = if r > 0 {
            (rf * ((rf * rf - (dy * dy) as f64) / (rf * rf)).max(0.0).sqrt()).round() as i64
        } else {
            0
        };
        for dx in -hw..=hw {
            offs.push((dx, dy));
        }
    }
    let mut g = vec![0u32; low.len()];
    for y in 0..lh as i64 {
        for x in 0..lw as i64 {
            let vals: Vec<f64> = offs
                .iter()
                .filter_map(|&(dx, dy)| {
                    let (xx, yy) = (x + dx, y + dy);
                    (xx >= 0 && yy >= 0 && xx < lw as i64 && yy < lh as i64)
                        .then(|| low[(yy * lw as i64 + xx) as usize])
                })
                .collect();
            let mx = vals.iter().cloned().fold(f64::MIN, f64::max);
            let mn = vals.iter().cloned().fold(f64::MAX, f64::min);
            g[(y * lw as i64 + x) as usize] = (mx - mn) as u32;
        }
    }
    let mut v = g.clone();
    let med = lower_median(&mut v);
    let mut dev: Vec<u32> = g.iter().map(|&x| x.abs_diff(med)).collect();
    let mad = lower_median(&mut dev).max(1);
    let t_low = (med + COARSE_K_LOW * mad).min(u16::MAX as u32) as u16;
    let t_high = (med + COARSE_K_HIGH * mad).min(u16::MAX as u32) as u16;
    let mask = GrayImage::from_fn(lw, lh, |x, y| {
        Luma([if g[(y * lw + x) as usize] > t_low as u32 {
            255
        } else {
            0
        }])
    });
    let min_coarse = (p.area_min / 4).max(1) as f64;
    let ff = f as f64;
    let mut out = Vec::new();
    for comp in components(&mask) {
        if (comp.len() as f64) * ff * ff < min_coarse {
            continue;
        }
        if !comp
            .iter()
            .any(|&(x, y)| g[(y * lw + x) as usize] > t_high as u32)
        {
            continue;
        }
        let [mx, my, a, b, c] = centroid_cov(&comp);
        // a low pixel X covers full pixels f·X .. f·X + f − 1
        let extra = (ff * ff - 1.0) / 12.0;
        out.push([
            ff * mx + 0.5 * (ff - 1.0),
            ff * my + 0.5 * (ff - 1.0),
            ff * ff * a + extra,
            ff * ff * b + extra,
            ff * ff * c,
        ]);
    }
    (out, t_low, t_high)
}

/// Robust per-pixel noise σ of `img` in 1/16 grey levels (core:
/// `noise::noise_sigma16`): d = p(x, y) − p(x + L, y) − p(x, y + L) +
/// p(x + L, y + L), L = `NOISE_LAG`, at rows y = 0, 2L, … and columns
/// x = 0, L, … (all four pixels inside the frame),
/// σ = 1.4826 · median|d| / 2 with the median of the integer |d| taken as
/// the grouped-data median (values of k spread over [k − ½, k + ½), 0
/// over [0, ½)).
pub fn noise_sigma16(img: &GrayImage) -> u32 {
    let (w, h) = img.dimensions();
    let px = |x: u32, y: u32| img.get_pixel(x, y).0[0] as i64;
    let lag = fishtrack_core::noise::NOISE_LAG as u32;
    let mut d: Vec<u64> = Vec::new();
    for y in (0..h).step_by(2 * lag as usize).filter(|y| y + lag < h) {
        for x in (0..w).step_by(lag as usize).filter(|x| x + lag < w) {
            d.push(
                (px(x, y) - px(x + lag, y) - px(x, y + lag) + px(x + lag, y + lag)).unsigned_abs(),
            );
        }
    }
    if d.is_empty() {
        return 0;
    }
    d.sort_unstable();
    let half = d.len() as f64 / 2.0;
    // the group holding the half-way point: the smallest k with
    // #(|d| ≤ k) ≥ n/2
    let below = |k: u64| d.partition_point(|&v| v < k) as f64;
    let k = d[d.len().div_ceil(2) - 1];
    let cnt = below(k + 1) - below(k);
    let (lo, width) = if k == 0 {
        (0.0, 0.5)
    } else {
        (k as f64 - 0.5, 1.0)
    };
    let med = if cnt > 0.0 {
        lo + width * (half - below(k)) / cnt
    } else {
        lo
    };
    let s = 16.0 * 1.4826 * med / 2.0;
    if s.is_finite() && s > 0.0 {
        (s + 0.5) as u32
    } else {
        0
    }
}

/// Segments one frame.
pub fn segment(img: &GrayImage, p: &Params) -> RefResult {
    let (w, h) = img.dimensions();
    let disk = opencv_ellipse_mask(p.disk_size);
    let filtered = remove_mesh(img, p.mesh_line_len);
    let noise16 = noise_sigma16(img);
    let var_limit = if p.variance_literal {
        p.var_min as f64
    } else {
        let s = (noise16 as f64 / 16.0).max(p.noise_floor as f64);
        p.var_min as f64 * (s * s / fishtrack_core::segment::local::NOISE_REF_VAR as f64).min(1.0)
    };
    let mut res = RefResult {
        noise_sigma16: noise16,
        var_limit,
        ..RefResult::default()
    };
    // coarse components as (cx, cy, cov_xx, cov_yy, cov_xy)
    let coarse: Vec<[f64; 5]> = if p.coarse_scale > 1 {
        let (c, tl, th) = coarse_low(&filtered, p);
        res.gradient_threshold = th;
        res.gradient_threshold_low = tl;
        c
    } else {
        let g = gradient(&filtered, &disk);
        let t = gradient_threshold(&g);
        res.gradient_threshold = t as u16;
        res.gradient_threshold_low = t as u16;
        let mut fg = GrayImage::new(w, h);
        for (o, q) in fg.pixels_mut().zip(g.pixels()) {
            o.0[0] = if q.0[0] > t { 255 } else { 0 };
        }
        let min_coarse = (p.area_min / 4).max(1) as usize;
        components(&fg)
            .into_iter()
            .filter(|c| c.len() >= min_coarse)
            .map(|comp| centroid_cov(&comp))
            .collect()
    };
    let (amin, amax) = (p.area_min as usize, p.area_max as usize);
    let smoothed = box_mean(&filtered, p.local_smooth as u32);
    // core: `Params::background` (the frame minus its smooth background)
    let bg = p
        .background
        .then(|| Background::estimate(&filtered, p.background_radius as usize));
    for &[cx, cy, ca, cb, cc] in &coarse {
        let (angle, l1, l2) = pca_of(ca, cb, cc);
        let s = p.ellipse_scale as f64;
        let a = (2.0 * l1.sqrt()).max(0.5) * s;
        let b = (2.0 * l2.sqrt()).max(0.5) * s;
        let ri = res.regions.len();
        res.regions.push(RefRegion {
            cx,
            cy,
            a,
            b,
            angle,
            tau: None,
            t_low: 0.0,
            t_high: 0.0,
            level: 0,
        });
        // pixels of the ellipse
        let (c, sn) = (angle.cos(), angle.sin());
        let inside = |x: u32, y: u32| {
            let (dx, dy) = (x as f64 - cx, y as f64 - cy);
            let u = dx * c + dy * sn;
            let v = -dx * sn + dy * c;
            u * u / (a * a) + v * v / (b * b) <= 1.0
        };
        let ex = (a * a * c * c + b * b * sn * sn).sqrt();
        let ey = (a * a * sn * sn + b * b * c * c).sqrt();
        let x0 = (cx - ex).ceil().clamp(0.0, w as f64) as u32;
        let x1 = ((cx + ex).floor() + 1.0).clamp(0.0, w as f64) as u32;
        let y0 = (cy - ey).ceil().clamp(0.0, h as f64) as u32;
        let y1 = ((cy + ey).floor() + 1.0).clamp(0.0, h as f64) as u32;
        if x1 <= x0 || y1 <= y0 {
            continue;
        }
        let (rw, rh) = (x1 - x0, y1 - y0);
        let ins: Vec<bool> = (0..rw * rh)
            .map(|i| inside(x0 + i % rw, y0 + i / rw))
            .collect();
        // the pixels the thresholds see (core: `local_smooth`, then the
        // background subtracted)
        let sub = bg.as_ref();
        // level 1 (core: `Params::dim_level`): the region again, its pixels
        // within the disk's side (Chebyshev) of level 0's objects set to 0
        // and out of its histogram
        let levels = 1 + p.dim_level as usize;
        let mut cleared = vec![false; (rw * rh) as usize];
        let (mut tau_above, mut area0) = (u8::MAX, 0usize);
        for level in 0..levels {
            let at = |i: u32| {
                if cleared[i as usize] {
                    return 0;
                }
                let (x, y) = (x0 + i % rw, y0 + i / rw);
                let v = smoothed.get_pixel(x, y).0[0];
                sub.map_or(v, |g| g.subtract(v, x, y))
            };
            let vals: Vec<u8> = (0..rw * rh)
                .filter(|&i| ins[i as usize])
                .map(at)
                .filter(|&v| level == 0 || v > 0)
                .collect();
            if vals.is_empty() || vals.len() < amin {
                break;
            }
            // eq. (1)
            let tau = otsu_level(
                &GrayImage::from_raw(vals.len() as u32, 1, vals.clone()).unwrap_or_default(),
            );
            if level > 0 && tau >= tau_above {
                break; // the remainder splits no lower than level 0 did
            }
            tau_above = tau;
            let low: Vec<f64> = vals
                .iter()
                .filter(|&&v| v <= tau)
                .map(|&v| v as f64)
                .collect();
            let mu_l = if low.is_empty() {
                tau as f64
            } else {
                low.iter().sum::<f64>() / low.len() as f64
            };
            let (t_low, t_high) = if p.double_threshold {
                (
                    tau as f64 - p.p_low as f64 * (tau as f64 - mu_l),
                    tau as f64 - p.p_high as f64 * (tau as f64 - mu_l),
                )
            } else {
                (tau as f64, tau as f64)
            };
            // the water (Otsu's lower class): lower median and 1.4826 · MAD
            // (core: `local::water_level`)
            let mut water: Vec<u32> = vals
                .iter()
                .filter(|&&v| v <= tau)
                .map(|&v| v as u32)
                .collect();
            let (w_med, w_sigma) = if water.is_empty() {
                (tau as f64, 1.0)
            } else {
                let med = lower_median(&mut water);
                let mut dev: Vec<u32> = water.iter().map(|&v| v.abs_diff(med)).collect();
                (
                    med as f64,
                    (1.4826 * lower_median(&mut dev) as f64).max(1.0),
                )
            };
            let s_w = w_sigma.max(p.noise_floor as f64);
            let ri = if level == 0 {
                ri
            } else {
                // a dim fish must stand out of the water as the contrast test
                // asks, over half an object's area; the thresholds stay
                // DIM_LEVEL_FLOOR water σ above it
                let bright = vals
                    .iter()
                    .filter(|&&v| v as f64 >= w_med + DIM_K * s_w)
                    .count();
                if 2 * bright < amin {
                    break;
                }
                res.regions.push(RefRegion {
                    level: level as u8,
                    ..res.regions[ri].clone()
                });
                res.regions.len() - 1
            };
            let (t_low, t_high) = if level == 0 {
                // the high floor (core: `Params::high_floor_sigmas`)
                let hf = p.high_floor_sigmas as f64;
                let fl = (w_med + hf * s_w).min(255.0).floor();
                // only where eq. (1)'s ⌊τ_high⌋ is at or below the water median
                let collapsed = t_high.floor() <= w_med;
                (
                    t_low,
                    if hf > 0.0 && collapsed {
                        t_high.max(fl)
                    } else {
                        t_high
                    },
                )
            } else {
                let fl = |k: f32| (w_med + k as f64 * s_w).min(255.0).floor();
                (t_low.max(fl(DIM_FLOOR[0])), t_high.max(fl(DIM_FLOOR[1])))
            };
            {
                let r = &mut res.regions[ri];
                r.tau = Some(tau);
                r.t_low = t_low;
                r.t_high = t_high;
            }
            let mask_of = |t: f64| {
                GrayImage::from_fn(rw, rh, |x, y| {
                    let i = y * rw + x;
                    Luma([if ins[i as usize] && at(i) as f64 > t {
                        255
                    } else {
                        0
                    }])
                })
            };
            let restrict = |m: GrayImage| {
                GrayImage::from_fn(rw, rh, |x, y| {
                    let i = (y * rw + x) as usize;
                    Luma([if ins[i] { m.get_pixel(x, y).0[0] } else { 0 }])
                })
            };
            let m_low = restrict(median_filter(&mask_of(t_low), 1, 1));
            let m_high = restrict(median_filter(&mask_of(t_high), 1, 1));
            // eq. (2)–(3)
            let bmask = if p.double_threshold && p.backprojection {
                let bins = p.hist_bins as usize;
                // bins spanning [⌊τ_low⌋, 99th percentile of the ellipse]
                let mut sorted = vals.clone();
                sorted.sort_unstable();
                let need = (sorted.len() * 99).div_ceil(100).max(1);
                let lo = t_low.floor().clamp(0.0, 255.0) as usize;
                let hi = (sorted[need - 1] as usize).max(lo);
                let bin_of =
                    |v: u8| (v as usize).clamp(lo, hi).saturating_sub(lo) * bins / (hi - lo + 1);
                let (mut hl, mut hh) = (vec![0f64; bins], vec![0f64; bins]);
                for i in 0..rw * rh {
                    let (x, y) = (i % rw, i / rw);
                    let bin = bin_of(at(i));
                    if m_low.get_pixel(x, y).0[0] > 0 {
                        hl[bin] += 1.0;
                    }
                    if m_high.get_pixel(x, y).0[0] > 0 {
                        hh[bin] += 1.0;
                    }
                }
                let ratio: Vec<f64> = hl
                    .iter()
                    .zip(&hh)
                    .map(|(&l, &hv)| if l > 0.0 { (hv / l).min(1.0) } else { 0.0 })
                    .collect();
                GrayImage::from_fn(rw, rh, |x, y| {
                    let i = y * rw + x;
                    let bp = ratio[bin_of(at(i))];
                    Luma([if ins[i as usize] && bp > p.theta_bp as f64 {
                        255
                    } else {
                        0
                    }])
                })
            } else {
                m_high
            };
            // eq. (4)–(6)
            let roi_img = GrayImage::from_fn(rw, rh, |x, y| *filtered.get_pixel(x0 + x, y0 + y));
            let seen = GrayImage::from_fn(rw, rh, |x, y| Luma([at(y * rw + x)]));
            let mut kept = GrayImage::new(rw, rh);
            for comp in components(&bmask) {
                if comp.len() < amin || comp.len() > amax {
                    continue;
                }
                let (_, var) = mean_var(&roi_img, &comp);
                let (seen_mean, _) = mean_var(&seen, &comp);
                let k = if level == 0 {
                    p.contrast_sigmas as f64
                } else {
                    DIM_K
                };
                let stands_out = seen_mean - w_med >= k * s_w;
                if level > 0 {
                    // the dim level's objects must stand out from its water
                    if !stands_out {
                        continue;
                    }
                } else if p.variance_rejection
                    && var < var_limit
                    && !(p.contrast_sigmas > 0.0 && stands_out)
                {
                    continue;
                }
                for &(x, y) in &comp {
                    kept.put_pixel(x, y, Luma([255]));
                }
            }
            // Section III.D
            let post = open(&close(&kept, &disk), &disk);
            let comps: Vec<Vec<(u32, u32)>> = components(&post)
                .into_iter()
                .filter(|c| c.len() >= amin && c.len() <= amax)
                .collect();
            // split of merged objects (core: `segment::split`): each object's
            // first part keeps its place, further parts follow all objects
            let comps = if p.split_merged {
                let t_fl = t_low.floor().clamp(0.0, 255.0) as u8;
                let m = p.margin / 4;
                let cut = |c: &[(u32, u32)]| {
                    c.iter().any(|&(x, y)| {
                        let (fx, fy) = (x + x0, y + y0);
                        fx <= m || fy <= m || fx + m + 1 >= w || fy + m + 1 >= h
                    })
                };
                let split: Vec<_> = comps
                    .iter()
                    .map(|c| super::split::split_object(c, &seen, t_fl, p, cut))
                    .collect();
                let mut firsts: Vec<_> = split.iter().map(|s| s[0].clone()).collect();
                firsts.extend(split.into_iter().flat_map(|s| s.into_iter().skip(1)));
                firsts
            } else {
                comps
            };
            let comps_all = comps;
            // a component of the level-1 mask or an 8-neighbour at 0: next to
            // what level 0 cleared (core: the fragment rule of `segment_region`)
            let touches_cleared = |c: &[(u32, u32)]| {
                c.iter().any(|&(x, y)| {
                    (y.saturating_sub(1)..(y + 2).min(rh)).any(|yy| {
                        (x.saturating_sub(1)..(x + 2).min(rw)).any(|xx| at(yy * rw + xx) == 0)
                    })
                })
            };
            let mut emitted: Vec<&Vec<(u32, u32)>> = Vec::new();
            for comp in comps_all.iter() {
                // elongation test (core: `local::elongated_enough`)
                let e = p.min_elongation as f64;
                let (_, _, _, l1, l2) = pca(comp);
                // (core: `local::cut_by_border` exempts fish cut by the frame)
                let m = p.margin / 4;
                let cut = comp.iter().any(|&(x, y)| {
                    let (fx, fy) = (x + x0, y + y0);
                    fx <= m || fy <= m || fx + m + 1 >= w || fy + m + 1 >= h
                });
                if e > 1.0 && l1 < e * e * l2 && !cut {
                    continue;
                }
                // fill test (core: `local::solid_enough`), cut objects too
                let ellipse = 4.0 * std::f64::consts::PI * (l1 * l2).sqrt();
                if p.min_fill > 0.0
                    && ellipse > 0.0
                    && (comp.len() as f64) < p.min_fill as f64 * ellipse
                {
                    continue;
                }
                if p.edge_step_ratio > 0.0
                    && !p.split_merged
                    && !edge_sharp(
                        comp,
                        &post,
                        &ins,
                        &at,
                        (rw, rh),
                        w_med,
                        (edge_ratio_for(p, s_w), p.edge_gap),
                    )
                {
                    continue;
                }
                if p.mesh_residue_ratio > 0.0
                    && p.mesh_line_len >= 3
                    && is_mesh_residue(
                        comp,
                        (img, &filtered),
                        (x0, y0),
                        &ins,
                        &at,
                        rw,
                        w_med,
                        p.mesh_residue_ratio,
                    )
                {
                    continue;
                }
                if level == 0 {
                    area0 = area0.max(comp.len());
                } else if 2 * comp.len() < area0 && touches_cleared(comp) {
                    // a dim part of a level-0 fish (its tail, a fin), not a fish
                    continue;
                }
                let (mean, variance) = mean_var(&roi_img, comp);
                let frame_px: Vec<(u32, u32)> =
                    comp.iter().map(|&(x, y)| (x + x0, y + y0)).collect();
                let bbox = (
                    frame_px.iter().map(|p| p.0).min().unwrap_or(0),
                    frame_px.iter().map(|p| p.1).min().unwrap_or(0),
                    frame_px.iter().map(|p| p.0).max().unwrap_or(0),
                    frame_px.iter().map(|p| p.1).max().unwrap_or(0),
                );
                let obj = RefObject {
                    obb: oriented_box(&frame_px),
                    pixels: frame_px.into_iter().collect(),
                    region: ri,
                    bbox,
                    mean,
                    variance,
                    level: level as u8,
                };
                add_dedup(&mut res.objects, obj);
                emitted.push(comp);
            }
            if emitted.is_empty() {
                break; // nothing to clear: level 1 would be level 0 again
            }
            if level + 1 < levels {
                // only the objects found are cleared: a component the tests
                // refused is no bright fish to set aside
                let mut grown = GrayImage::new(rw, rh);
                for &(x, y) in emitted.iter().copied().flatten() {
                    grown.put_pixel(x, y, Luma([255]));
                }
                let grown = dilate(&grown, Norm::LInf, p.disk_size);
                for (c, q) in cleared.iter_mut().zip(grown.pixels()) {
                    *c |= q.0[0] > 0;
                }
            }
        }
    }
    res
}

/// The edge test (core: `segment::local::edge_sharp_enough`): over the
/// object's outline, pixel by pixel, the step from the pixel `gap`
/// (`Params::edge_gap`) inside to the one `gap` beyond the first pixel
/// outside, along rows (at a row's first and last object pixel, when the
/// object's run there is longer than `gap`) and columns (each object pixel whose
/// pixel below, or above, is not in the mask); both inside the ellipse,
/// the inner pixel in `mask`, the outer one outside it and above 0
/// (cleared by the dim level). The mean step must reach `ratio` times the
/// object's thresholded mean (inside the ellipse) above the water median;
/// fewer than `EDGE_MIN_SAMPLES` samples pass.
fn edge_sharp(
    comp: &[(u32, u32)],
    mask: &GrayImage,
    ins: &[bool],
    at: &dyn Fn(u32) -> u8,
    (rw, rh): (u32, u32),
    w_med: f64,
    (ratio, gap): (impl Fn(f64) -> f32, u8),
) -> bool {
    use fishtrack_core::segment::local::EDGE_MIN_SAMPLES;
    let g = gap as i64;
    let (w, h) = (rw as i64, rh as i64);
    let in_mask = |x: i64, y: i64| {
        x >= 0 && y >= 0 && x < w && y < h && mask.get_pixel(x as u32, y as u32).0[0] > 0
    };
    let val = |x: i64, y: i64| at((y * w + x) as u32) as f64;
    let (mut sum, mut n) = (0.0f64, 0u64);
    let mut sample = |(xi, yi): (i64, i64), (xo, yo): (i64, i64)| {
        if xo < 0 || yo < 0 || xo >= w || yo >= h {
            return;
        }
        if xi < 0 || yi < 0 || xi >= w || yi >= h {
            return;
        }
        let (ii, io) = ((yi * w + xi) as usize, (yo * w + xo) as usize);
        if in_mask(xi, yi) && ins[ii] && !in_mask(xo, yo) && ins[io] {
            let o = val(xo, yo);
            if o > 0.0 {
                sum += val(xi, yi) - o;
                n += 1;
            }
        }
    };
    for &(x, y) in comp {
        let (x, y) = (x as i64, y as i64);
        // the run through (x, y) starts here / ends here, and is longer than g
        if !in_mask(x - 1, y) && (0..=g).all(|k| in_mask(x + k, y)) {
            sample((x + g, y), (x - 1 - g, y));
        }
        if !in_mask(x + 1, y) && (0..=g).all(|k| in_mask(x - k, y)) {
            sample((x - g, y), (x + 1 + g, y));
        }
        if !in_mask(x, y + 1) {
            sample((x, y - g), (x, y + 1 + g));
        }
        if !in_mask(x, y - 1) {
            sample((x, y + g), (x, y - 1 - g));
        }
    }
    let Some(contrast) = contrast_of(comp, ins, at, rw, w_med) else {
        return true;
    };
    if n < EDGE_MIN_SAMPLES {
        return true;
    }
    let step = sum / n as f64;
    let ratio = ratio(contrast);
    contrast <= 0.0 || step >= ratio as f64 * contrast
}

/// The mesh-residue test (core: `segment::local::not_mesh_residue`): the
/// object (pixels `comp` in the region's box at `(x0, y0)`, `rw` wide) is a
/// residue of the trawl mesh when the mean of raw − mesh-free over its
/// pixels reaches `ratio` times its contrast: its thresholded mean inside
/// the ellipse (`ins`, values `at`) above the water median `w_med`. An
/// object with no pixel inside the ellipse or no contrast is no residue.
#[allow(clippy::too_many_arguments)]
fn is_mesh_residue(
    comp: &[(u32, u32)],
    (raw, filtered): (&GrayImage, &GrayImage),
    (x0, y0): (u32, u32),
    ins: &[bool],
    at: &dyn Fn(u32) -> u8,
    rw: u32,
    w_med: f64,
    ratio: f32,
) -> bool {
    let Some(contrast) = contrast_of(comp, ins, at, rw, w_med) else {
        return false;
    };
    let removed: u64 = comp
        .iter()
        .map(|&(x, y)| {
            let (fx, fy) = (x + x0, y + y0);
            let r = raw.get_pixel(fx, fy).0[0] as i64;
            let f = filtered.get_pixel(fx, fy).0[0] as i64;
            (r - f).max(0) as u64
        })
        .sum();
    contrast > 0.0 && removed as f64 / comp.len() as f64 >= ratio as f64 * contrast
}

/// The contrast the edge and mesh-residue tests judge an object by (core:
/// `local::EdgeSteps::contrast`): the mean of its thresholded values `at`
/// over its pixels inside the ellipse (`ins`; region box `rw` wide) minus
/// the water median `w_med`; `None` when no pixel is inside.
fn contrast_of(
    comp: &[(u32, u32)],
    ins: &[bool],
    at: &dyn Fn(u32) -> u8,
    rw: u32,
    w_med: f64,
) -> Option<f64> {
    let (mut seen, mut n) = (0u64, 0u64);
    for &(x, y) in comp {
        let i = y * rw + x;
        if ins[i as usize] {
            seen += at(i) as u64;
            n += 1;
        }
    }
    (n > 0).then(|| seen as f64 / n as f64 - w_med)
}

/// The edge ratio an object of contrast `c` (grey levels above the water)
/// must reach (core: `local::required_edge_ratio`): `weak_edge_step_ratio`
/// (at least `edge_step_ratio`) under `weak_contrast_sigmas` water σ `s_w`.
fn edge_ratio_for(p: &Params, s_w: f64) -> impl Fn(f64) -> f32 + '_ {
    move |c: f64| {
        if p.weak_contrast_sigmas > 0.0 && c < p.weak_contrast_sigmas as f64 * s_w {
            p.edge_step_ratio.max(p.weak_edge_step_ratio)
        } else {
            p.edge_step_ratio
        }
    }
}

/// One fish, one object: an object sharing more than half of the smaller
/// mask with another is the same fish; the lower level is kept, then the
/// larger (first on a tie).
fn add_dedup(objs: &mut Vec<RefObject>, o: RefObject) {
    let mut i = 0;
    while i < objs.len() {
        let ov = objs[i].pixels.intersection(&o.pixels).count();
        if 2 * ov > objs[i].pixels.len().min(o.pixels.len()) {
            // a lower level wins, then the larger
            if (objs[i].level, o.pixels.len()) <= (o.level, objs[i].pixels.len()) {
                return;
            }
            objs.swap_remove(i);
            continue;
        }
        i += 1;
    }
    objs.push(o);
}
