//! Bouguet stereo rectification, undistort-rectify maps and point mapping.
//!
//! Paper Section IV.A: before stereo matching every frame pair is
//! undistorted and rectified, so that corresponding epipolar lines are
//! horizontal and at the same height (and an object has the same height in
//! both views). A vertical rig is rectified too (`vertical`): its epipolar
//! lines are then columns.
//!
//! [`stereo_rectify`] equals OpenCV's `cv2.stereoRectify(M1, D1, M2, D2,
//! (w, h), R, T, flags=CALIB_ZERO_DISPARITY, alpha=0)` step for step
//! (OpenCV 5 `stereo_geom.cpp` / 4.x `cvStereoRectify`): each camera is
//! rotated half-way (`r_r = Rodrigues(−½·Rodrigues(R))`), then both by the
//! rotation taking the baseline onto the x axis (horizontal pair) or the y
//! axis (vertical pair); the new focal length is the mean of the two
//! cameras' focal lengths across the baseline, the principal point centres
//! the undistorted image corners, and `alpha = 0` scales so that only valid
//! pixels remain (the inner rectangle of the undistorted image border,
//! OpenCV's `getUndistortRectangles`). OpenCV's own precision is kept where
//! it shows in the results: its 5-iteration undistortion and the `float`
//! points used for the principal point.
//!
//! The maps follow `cv2.initUndistortRectifyMap`: rectified pixel →
//! `(P[:, :3]·Rᵢ)⁻¹` → normalized ray → distortion → raw pixel. Raw →
//! rectified ([`RectifiedCamera::raw_to_rect`]) inverts the distortion
//! iteratively to 1e-14 (not OpenCV's 5 fixed-point steps); rectified → raw
//! is closed form. FishTrack reports boxes in raw left pixels (DESIGN.md
//! "Output"), hence [`RectifiedCamera::rect_box_to_raw`].
//!
//! [`Rectifier`] applies the maps to frame pairs through the core's
//! fixed-point remap ([`fishtrack_core::remap`]), the form the device runs.

use image::GrayImage;
use nalgebra::{Matrix3, Matrix3x4, Matrix4, Vector3};

use fishtrack_core::remap::{self, RemapError, RemapTable};
use fishtrack_core::{ImageView, ImageViewMut};

use crate::calib::StereoCalib;

/// Distortion coefficients padded to the rational model:
/// `k1 k2 p1 p2 k3 k4 k5 k6`.
pub type Dist8 = [f64; 8];

/// Applies the lens distortion to a normalized point (OpenCV model).
pub fn distort(k: &Dist8, x: f64, y: f64) -> (f64, f64) {
    let [k1, k2, p1, p2, k3, k4, k5, k6] = *k;
    let x2 = x * x;
    let y2 = y * y;
    let r2 = x2 + y2;
    let xy2 = 2.0 * x * y;
    let kr = (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2) / (1.0 + ((k6 * r2 + k5) * r2 + k4) * r2);
    (
        x * kr + p1 * xy2 + p2 * (r2 + 2.0 * x2),
        y * kr + p1 * (r2 + 2.0 * y2) + p2 * xy2,
    )
}

/// OpenCV's fixed-point undistortion (`undistortPoints` with
/// `TermCriteria(COUNT, iters)`): kept to reproduce `stereoRectify`.
pub fn undistort_opencv(k: &Dist8, xd: f64, yd: f64, iters: usize) -> (f64, f64) {
    let (mut x, mut y) = (xd, yd);
    for _ in 0..iters {
        let r2 = x * x + y * y;
        let icdist = (1.0 + ((k[7] * r2 + k[6]) * r2 + k[5]) * r2)
            / (1.0 + ((k[4] * r2 + k[1]) * r2 + k[0]) * r2);
        if icdist < 0.0 {
            return (xd, yd);
        }
        let dx = 2.0 * k[2] * x * y + k[3] * (r2 + 2.0 * x * x);
        let dy = k[2] * (r2 + 2.0 * y * y) + 2.0 * k[3] * x * y;
        x = (xd - dx) * icdist;
        y = (yd - dy) * icdist;
    }
    (x, y)
}

/// Tight undistortion of a normalized point: fixed-point start, then Newton
/// steps until the distortion reproduces `(xd, yd)` to 1e-14. `None` when
/// it does not converge (a point outside the lens model's valid region).
pub fn undistort_exact(k: &Dist8, xd: f64, yd: f64) -> Option<(f64, f64)> {
    let (mut x, mut y) = undistort_opencv(k, xd, yd, 20);
    for _ in 0..100 {
        let (fx, fy) = distort(k, x, y);
        let (ex, ey) = (fx - xd, fy - yd);
        if ex.abs().max(ey.abs()) < 1e-14 {
            return Some((x, y));
        }
        let h = 1e-7;
        let (ax, ay) = distort(k, x + h, y);
        let (bx, by) = distort(k, x - h, y);
        let (cx, cy) = distort(k, x, y + h);
        let (dx, dy) = distort(k, x, y - h);
        let j = [
            (ax - bx) / (2.0 * h),
            (cx - dx) / (2.0 * h),
            (ay - by) / (2.0 * h),
            (cy - dy) / (2.0 * h),
        ];
        let det = j[0] * j[3] - j[1] * j[2];
        if !det.is_finite() || det.abs() < 1e-12 {
            return None;
        }
        x -= (j[3] * ex - j[1] * ey) / det;
        y -= (-j[2] * ex + j[0] * ey) / det;
        if !x.is_finite() || !y.is_finite() {
            return None;
        }
    }
    let (fx, fy) = distort(k, x, y);
    ((fx - xd).abs().max((fy - yd).abs()) < 1e-9).then_some((x, y))
}

/// Rotation vector → matrix (OpenCV `Rodrigues`).
pub fn rodrigues_vec_to_mat(r: &Vector3<f64>) -> Matrix3<f64> {
    let theta = r.norm();
    if theta < f64::EPSILON {
        return Matrix3::identity();
    }
    let (s, c) = theta.sin_cos();
    let c1 = 1.0 - c;
    let n = r / theta;
    let rrt = n * n.transpose();
    let rx = Matrix3::new(0.0, -n.z, n.y, n.z, 0.0, -n.x, -n.y, n.x, 0.0);
    Matrix3::identity() * c + rrt * c1 + rx * s
}

/// Rotation matrix → vector (OpenCV `Rodrigues`: the matrix is first made
/// orthonormal through its SVD, `R ← U·Vᵀ`).
pub fn rodrigues_mat_to_vec(m: &Matrix3<f64>) -> Vector3<f64> {
    let svd = m.svd(true, true);
    let r = match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => u * vt,
        _ => *m,
    };
    let mut v = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    );
    let s = ((v.x * v.x + v.y * v.y + v.z * v.z) * 0.25).sqrt();
    let c = ((r[(0, 0)] + r[(1, 1)] + r[(2, 2)] - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = c.acos();
    if s < 1e-5 {
        if c > 0.0 {
            return Vector3::zeros();
        }
        let t = (r[(0, 0)] + 1.0) * 0.5;
        v.x = t.max(0.0).sqrt();
        let t = (r[(1, 1)] + 1.0) * 0.5;
        v.y = t.max(0.0).sqrt() * if r[(0, 1)] < 0.0 { -1.0 } else { 1.0 };
        let t = (r[(2, 2)] + 1.0) * 0.5;
        v.z = t.max(0.0).sqrt() * if r[(0, 2)] < 0.0 { -1.0 } else { 1.0 };
        if v.x.abs() < v.y.abs() && v.x.abs() < v.z.abs() && (r[(1, 2)] > 0.0) != (v.y * v.z > 0.0)
        {
            v.z = -v.z;
        }
        let n = v.norm();
        return v * (theta / n);
    }
    v * (theta / (2.0 * s))
}

/// The rectification's free scaling (OpenCV `alpha`) whose scale the
/// default [`Scaling::Canvas`] keeps (and `--rect-alpha auto` starts from).
/// DESIGN.md asks for `alpha = 0` (only valid pixels), which
/// crops a 5–260 px strip of the raw views away, and with it the fish
/// entering and leaving there; 0.25 keeps part of that strip at a 3–5 %
/// smaller focal length and was the only value of 0, 0.25, 0.5, 0.75, 1, −1
/// that improved segmentation, tracking and both 3-D length figures on
/// seeds 1–8 pooled (README "Input: a haul directory").
pub const DEFAULT_ALPHA: f64 = 0.25;

/// How the rectified views are scaled: OpenCV's free scaling `alpha`, given
/// or chosen per rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scaling {
    /// OpenCV's `alpha` as given ([`stereo_rectify_alpha`]).
    Alpha(f64),
    /// `--rect-alpha auto`: [`DEFAULT_ALPHA`], unless at that alpha the
    /// rectified views would *magnify* the raw ones (rectified focal length
    /// above the mean raw focal length, OpenCV's "default scaling" `s = 1`).
    /// Magnifying invents no detail and crops the raw view's edges — where
    /// the fish enter and leave — so the scale is then lowered to
    /// `max(1, s₁)`, `s₁` the scale that keeps every raw pixel: no
    /// magnification, and the whole view where even that fits. On seeds
    /// 3–8 of the synthetic generator `alpha = 0.25` magnifies by 1.7–7.3 %
    /// and crops 0.5–14 % of the raw left view; the rule keeps 89–100 % of
    /// it (README "Input: a haul directory").
    NoMagnification,
    /// `--rect-alpha canvas`: the scale of [`DEFAULT_ALPHA`] on a canvas
    /// that holds every raw pixel ([`stereo_rectify_canvas`]).
    Canvas,
}

impl Default for Scaling {
    /// `Canvas` (session 33): alpha 0.25's scale on a frame that keeps
    /// every raw pixel. Measured against `Alpha(0.25)` on a 2048² frame
    /// (seeds 1–30 / 31–60 pooled): segmentation P / R 0.936 / 0.759 →
    /// 0.950 / 0.799 and 0.914 / 0.746 → 0.939 / 0.792; per-frame 3-D MAPE
    /// 3.06 → 2.91 % and 3.09 → 2.90 %; per-fish 3.10 → 2.23 % and 3.61
    /// → 3.43 %; tracking success 598 → 594 and 588 → 600; and the count
    /// of the re-rendered hauls (`blur` +28 → +10 %, `gamma` +21 → +7 %,
    /// `dark` −19 → −11 %). Until session 33 (older tracker and length
    /// stages) `Alpha(0.25)` measured the lengths better (README "Input:
    /// a haul directory").
    fn default() -> Self {
        Scaling::Canvas
    }
}

impl Scaling {
    /// The `alpha` this scaling gives for `c` (in `[0, 1]`, or −1 for
    /// OpenCV's default scaling).
    pub fn alpha(self, c: &StereoCalib) -> f64 {
        match self {
            Scaling::Alpha(a) => a,
            Scaling::NoMagnification => no_magnification_alpha(c, DEFAULT_ALPHA),
            Scaling::Canvas => DEFAULT_ALPHA,
        }
    }
}

/// The smallest `alpha ≥ alpha_min` whose scale does not magnify the raw
/// views (see [`Scaling::NoMagnification`]). The rectification's scale is
/// linear in `alpha` between `s₀` (`alpha = 0`) and `s₁` (`alpha = 1`).
pub fn no_magnification_alpha(c: &StereoCalib, alpha_min: f64) -> f64 {
    let scale = |a: f64| {
        let r = stereo_rectify_alpha(c, a);
        let j = if r.vertical { 0 } else { 1 };
        r.p1[(j, j)] / ((c.m1[(j, j)] + c.m2[(j, j)]) * 0.5)
    };
    let (s0, s1) = (scale(0.0), scale(1.0));
    let s_min = s0 * (1.0 - alpha_min) + s1 * alpha_min;
    // (NaN scales, from a degenerate calibration, keep alpha_min too)
    let magnifies = s_min.partial_cmp(&1.0) == Some(core::cmp::Ordering::Greater);
    let spans = s0.partial_cmp(&s1) == Some(core::cmp::Ordering::Greater);
    if !magnifies || !spans {
        return alpha_min;
    }
    let target = s1.max(1.0);
    ((s0 - target) / (s0 - s1)).clamp(alpha_min, 1.0)
}

/// The fill of the [`Rectifier`]'s tables.
pub const RECTIFIER_FILL: Fill = Fill::Reflect101;

/// Result of [`stereo_rectify`]: OpenCV's `R1 R2 P1 P2 Q`.
#[derive(Debug, Clone, PartialEq)]
pub struct Rectification {
    /// Rotation of the left camera into the rectified frame.
    pub r1: Matrix3<f64>,
    /// Rotation of the right camera into the rectified frame.
    pub r2: Matrix3<f64>,
    /// Left rectified projection `[f 0 cx 0; 0 f cy 0; 0 0 1 0]`.
    pub p1: Matrix3x4<f64>,
    /// Right rectified projection (baseline·f in column 3, row 0 or 1).
    pub p2: Matrix3x4<f64>,
    /// Disparity-to-depth matrix.
    pub q: Matrix4<f64>,
    /// True when the baseline is vertical (OpenCV `idx == 1`): disparity
    /// is then along y.
    pub vertical: bool,
    /// OpenCV's `validPixROI1` `(x, y, w, h)`: the left rectified image's
    /// rectangle where every pixel has a source (the whole frame at
    /// `alpha = 0`).
    pub roi1: [u32; 4],
    /// OpenCV's `validPixROI2`, the same for the right image.
    pub roi2: [u32; 4],
    /// The rectified frames' size `(width, height)`: the raw size, except
    /// for [`stereo_rectify_canvas`].
    pub size: (u32, u32),
    /// The left and right raw views' outer rectangles on the canvas of
    /// [`stereo_rectify_canvas`] (every raw pixel lies inside); `None` for
    /// the other rectifications.
    pub outer: Option<[[u32; 4]; 2]>,
}

/// OpenCV's `getUndistortRectangles`: the border points of a 9×9 grid over
/// the raw image, corners included (this is what the OpenCV 5.0.0 wheel
/// computes; some OpenCV sources skip the corners, which changes `alpha = 0`
/// results whenever a corner bounds the inner rectangle; the interior grid
/// points cannot change it), undistorted with 5 iterations and mapped by
/// `P[:, :3]·R`. Returns the inner and outer rectangles as `(x, y, w, h)`.
fn undistort_rectangles(
    m: &Matrix3<f64>,
    k: &Dist8,
    r: &Matrix3<f64>,
    p: &Matrix3x4<f64>,
    w: u32,
    h: u32,
) -> ([f64; 4], [f64; 4]) {
    const N: usize = 9;
    let rr = p.fixed_view::<3, 3>(0, 0) * r;
    let step_x = (w as f64 - 1.0) / (N - 1) as f64;
    let step_y = (h as f64 - 1.0) / (N - 1) as f64;
    let (fx, fy, cx, cy) = (m[(0, 0)], m[(1, 1)], m[(0, 2)], m[(1, 2)]);
    let (ifx, ify) = (1.0 / fx, 1.0 / fy);
    let (mut ix0, mut ix1, mut iy0, mut iy1) = (
        -f32::MAX as f64,
        f32::MAX as f64,
        -f32::MAX as f64,
        f32::MAX as f64,
    );
    let (mut ox0, mut ox1, mut oy0, mut oy1) = (
        f32::MAX as f64,
        -f32::MAX as f64,
        f32::MAX as f64,
        -f32::MAX as f64,
    );
    for yi in 0..N {
        for xi in 0..N {
            let border = xi == 0 || xi == N - 1 || yi == 0 || yi == N - 1;
            if !border {
                continue;
            }
            let (u, v) = (xi as f64 * step_x, yi as f64 * step_y);
            let (x, y) = undistort_opencv(k, (u - cx) * ifx, (v - cy) * ify, 5);
            let xx = rr[(0, 0)] * x + rr[(0, 1)] * y + rr[(0, 2)];
            let yy = rr[(1, 0)] * x + rr[(1, 1)] * y + rr[(1, 2)];
            let ww = 1.0 / (rr[(2, 0)] * x + rr[(2, 1)] * y + rr[(2, 2)]);
            let (px, py) = (xx * ww, yy * ww);
            ox0 = ox0.min(px);
            ox1 = ox1.max(px);
            oy0 = oy0.min(py);
            oy1 = oy1.max(py);
            if xi == 0 {
                ix0 = ix0.max(px);
            }
            if xi == N - 1 {
                ix1 = ix1.min(px);
            }
            if yi == 0 {
                iy0 = iy0.max(py);
            }
            if yi == N - 1 {
                iy1 = iy1.min(py);
            }
        }
    }
    (
        [ix0, iy0, ix1 - ix0, iy1 - iy0],
        [ox0, oy0, ox1 - ox0, oy1 - oy0],
    )
}

/// Bouguet rectification, equal to OpenCV `stereoRectify` with
/// `flags = CALIB_ZERO_DISPARITY`, `alpha = 0`, `newImageSize = imageSize`.
pub fn stereo_rectify(c: &StereoCalib) -> Rectification {
    stereo_rectify_alpha(c, 0.0)
}

/// Bouguet rectification, equal to OpenCV `stereoRectify` with
/// `flags = CALIB_ZERO_DISPARITY`, `newImageSize = imageSize` and the free
/// scaling `alpha`: 0 keeps only valid pixels (the inner rectangles of both
/// undistorted images fill the frame), 1 keeps every source pixel of both
/// cameras (the outer rectangles fit in the frame; the corners then hold
/// pixels with no source), values between interpolate the scale linearly,
/// and a negative `alpha` is OpenCV's "default scaling" (the mean focal
/// length, unscaled).
pub fn stereo_rectify_alpha(c: &StereoCalib, alpha: f64) -> Rectification {
    let k1 = StereoCalib::dist8(&c.d1);
    let k2 = StereoCalib::dist8(&c.d2);
    let (nx, ny) = (c.width as f64, c.height as f64);

    let om = rodrigues_mat_to_vec(&c.r) * -0.5;
    let r_r = rodrigues_vec_to_mat(&om);
    let t = r_r * c.t;
    let idx = if t.x.abs() > t.y.abs() { 0 } else { 1 };
    let cc = t[idx];
    let nt = t.norm();
    let mut uu = Vector3::zeros();
    uu[idx] = if cc > 0.0 { 1.0 } else { -1.0 };
    let mut ww = t.cross(&uu);
    let nw = ww.norm();
    if nw > 0.0 {
        ww *= (cc.abs() / nt).acos() / nw;
    }
    let w_r = rodrigues_vec_to_mat(&ww);
    let r1 = w_r * r_r.transpose();
    let r2 = w_r * r_r;
    let t = r2 * c.t;

    let j = idx ^ 1;
    let mut fc_new = (c.m1[(j, j)] + c.m2[(j, j)]) * 0.5;

    // principal points: mean of the projected undistorted image corners
    let mut cc_new = [(0.0f64, 0.0f64); 2];
    for (kk, (m, d, r)) in [(&c.m1, &k1, &r1), (&c.m2, &k2, &r2)]
        .into_iter()
        .enumerate()
    {
        let (fx, fy, cx, cy) = (m[(0, 0)], m[(1, 1)], m[(0, 2)], m[(1, 2)]);
        let mut sum = (0.0f64, 0.0f64);
        for i in 0..4 {
            let u = ((i % 2) as f64 * (nx - 1.0)) as f32 as f64;
            let v = ((if i < 2 { 0.0 } else { 1.0 }) * (ny - 1.0)) as f32 as f64;
            let (x, y) = undistort_opencv(d, (u - cx) * (1.0 / fx), (v - cy) * (1.0 / fy), 5);
            let p = Vector3::new(x as f32 as f64, y as f32 as f64, 1.0);
            let q = r * p;
            let iz = if q.z != 0.0 { 1.0 / q.z } else { 1.0 };
            let px = (q.x * iz * fc_new) as f32 as f64;
            let py = (q.y * iz * fc_new) as f32 as f64;
            sum.0 += px;
            sum.1 += py;
        }
        cc_new[kk] = (
            (nx - 1.0) / 2.0 - sum.0 / 4.0,
            (ny - 1.0) / 2.0 - sum.1 / 4.0,
        );
    }
    // CALIB_ZERO_DISPARITY: both principal points the same
    let ccx = (cc_new[0].0 + cc_new[1].0) * 0.5;
    let ccy = (cc_new[0].1 + cc_new[1].1) * 0.5;
    cc_new = [(ccx, ccy), (ccx, ccy)];

    let t_idx = t[idx];
    let mut p1 = Matrix3x4::zeros();
    p1[(0, 0)] = fc_new;
    p1[(1, 1)] = fc_new;
    p1[(0, 2)] = cc_new[0].0;
    p1[(1, 2)] = cc_new[0].1;
    p1[(2, 2)] = 1.0;
    let mut p2 = p1;
    p2[(0, 2)] = cc_new[1].0;
    p2[(1, 2)] = cc_new[1].1;
    p2[(idx, 3)] = t_idx * fc_new;

    // alpha = 0: scale so that the whole rectified image holds valid
    // pixels (s0, inner rectangles); alpha = 1: so that every source pixel
    // is kept (s1, outer rectangles); OpenCV interpolates the two scales
    let (in1, out1) = undistort_rectangles(&c.m1, &k1, &r1, &p1, c.width, c.height);
    let (in2, out2) = undistort_rectangles(&c.m2, &k2, &r2, &p2, c.width, c.height);
    let (wn, hn) = (nx, ny);
    let (cx1_0, cy1_0, cx2_0, cy2_0) = (cc_new[0].0, cc_new[0].1, cc_new[1].0, cc_new[1].1);
    let cx1 = wn * cx1_0 / nx;
    let cy1 = hn * cy1_0 / ny;
    let cx2 = wn * cx2_0 / nx;
    let cy2 = hn * cy2_0 / ny;
    let s_of = |cx: f64, cy: f64, cx0: f64, cy0: f64, r: &[f64; 4]| {
        (cx / (cx0 - r[0]))
            .max(cy / (cy0 - r[1]))
            .max((wn - 1.0 - cx) / (r[0] + r[2] - cx0))
            .max((hn - 1.0 - cy) / (r[1] + r[3] - cy0))
    };
    let s1_of = |cx: f64, cy: f64, cx0: f64, cy0: f64, r: &[f64; 4]| {
        (cx / (cx0 - r[0]))
            .min(cy / (cy0 - r[1]))
            .min((wn - 1.0 - cx) / (r[0] + r[2] - cx0))
            .min((hn - 1.0 - cy) / (r[1] + r[3] - cy0))
    };
    let s0 = s_of(cx2, cy2, cx2_0, cy2_0, &in2).max(s_of(cx1, cy1, cx1_0, cy1_0, &in1));
    let s1 = s1_of(cx2, cy2, cx2_0, cy2_0, &out2).min(s1_of(cx1, cy1, cx1_0, cy1_0, &out1));
    let s = if alpha >= 0.0 {
        s0 * (1.0 - alpha) + s1 * alpha
    } else {
        1.0
    };

    fc_new *= s;
    p2[(0, 0)] = fc_new;
    p2[(1, 1)] = fc_new;
    p2[(0, 2)] = cx2;
    p2[(1, 2)] = cy2;
    p2[(idx, 3)] *= s;
    p1[(0, 0)] = fc_new;
    p1[(1, 1)] = fc_new;
    p1[(0, 2)] = cx1;
    p1[(1, 2)] = cy1;
    p1[(idx, 3)] = 0.0;

    // OpenCV's valid-pixel rectangles: the inner rectangles, scaled,
    // intersected with the frame (`alpha = 0` puts a side exactly on the
    // frame edge: 1e-7 px of slack keeps round-off from moving it by one)
    let roi = |r: &[f64; 4], cx0: f64, cy0: f64, cx: f64, cy: f64| -> [u32; 4] {
        const EPS: f64 = 1e-7;
        let x0 = ((r[0] - cx0) * s + cx - EPS).ceil();
        let y0 = ((r[1] - cy0) * s + cy - EPS).ceil();
        let (x1, y1) = (x0 + (r[2] * s + EPS).floor(), y0 + (r[3] * s + EPS).floor());
        let (ax, ay) = (x0.clamp(0.0, wn), y0.clamp(0.0, hn));
        let (bx, by) = (x1.clamp(0.0, wn), y1.clamp(0.0, hn));
        if bx <= ax || by <= ay {
            return [0; 4];
        }
        [ax as u32, ay as u32, (bx - ax) as u32, (by - ay) as u32]
    };
    let roi1 = roi(&in1, cx1_0, cy1_0, cx1, cy1);
    let roi2 = roi(&in2, cx2_0, cy2_0, cx2, cy2);

    let dcc = if idx == 0 { cx1 - cx2 } else { cy1 - cy2 };
    let q = Matrix4::new(
        1.0,
        0.0,
        0.0,
        -cx1,
        0.0,
        1.0,
        0.0,
        -cy1,
        0.0,
        0.0,
        0.0,
        fc_new,
        0.0,
        0.0,
        -1.0 / t_idx,
        dcc / t_idx,
    );
    Rectification {
        r1,
        r2,
        p1,
        p2,
        q,
        vertical: idx == 1,
        roi1,
        roi2,
        size: (c.width, c.height),
        outer: None,
    }
}

/// Extra rectified pixels around the canvas of [`stereo_rectify_canvas`]:
/// the raw border is found on a 9 × 9 grid of its points
/// ([`undistort_rectangles`]) and may bulge a little between them.
pub const CANVAS_MARGIN: f64 = 4.0;

/// Largest canvas side of [`stereo_rectify_canvas`] as a multiple of the
/// raw side: the synthetic rigs need 1.07–1.23 ×; a calibration whose
/// views spread further (a wild distortion model, a large rotation) keeps
/// the raw size instead of allocating frames of many times the pixels.
pub const CANVAS_MAX_FACTOR: f64 = 2.0;

/// [`stereo_rectify_alpha`]'s rectification at the scale of `alpha`, drawn
/// on a canvas large enough to hold every raw pixel of both cameras (beyond
/// OpenCV, which fits the views to the raw size): the principal point
/// moves by the canvas's offset and the frame grows to the union of both
/// views' outer rectangles (plus [`CANVAS_MARGIN`]). Nothing of the raw
/// views is cropped and nothing is shrunk: `alpha = 1` keeps every pixel
/// by scaling the views down (fish smaller, some below θ_A^L), `alpha = 0`
/// keeps the scale by cropping the views' edges, where fish enter and
/// leave. `roi1`, `roi2` are the inner (every pixel valid) rectangles on
/// the canvas.
pub fn stereo_rectify_canvas(c: &StereoCalib, alpha: f64) -> Rectification {
    let mut r = stereo_rectify_alpha(c, alpha);
    let k1 = StereoCalib::dist8(&c.d1);
    let k2 = StereoCalib::dist8(&c.d2);
    let (in1, out1) = undistort_rectangles(&c.m1, &k1, &r.r1, &r.p1, c.width, c.height);
    let (in2, out2) = undistort_rectangles(&c.m2, &k2, &r.r2, &r.p2, c.width, c.height);
    let x0 = (out1[0].min(out2[0]) - CANVAS_MARGIN).floor();
    let y0 = (out1[1].min(out2[1]) - CANVAS_MARGIN).floor();
    let x1 = ((out1[0] + out1[2]).max(out2[0] + out2[2]) + CANVAS_MARGIN).ceil();
    let y1 = ((out1[1] + out1[3]).max(out2[1] + out2[3]) + CANVAS_MARGIN).ceil();
    // (a degenerate calibration gives NaN or huge bounds: keep the raw size)
    let ok = |v: f64| v.is_finite() && v.abs() < 65_535.0;
    if ![x0, y0, x1, y1].into_iter().all(ok) || x1 <= x0 || y1 <= y0 {
        return r;
    }
    if x1 - x0 > CANVAS_MAX_FACTOR * c.width as f64 || y1 - y0 > CANVAS_MAX_FACTOR * c.height as f64
    {
        log::warn!(
            "rectification: a canvas holding every raw pixel would be {} x {} for {} x {} views; keeping the raw size",
            x1 - x0,
            y1 - y0,
            c.width,
            c.height
        );
        return r;
    }
    let (w, h) = ((x1 - x0) as u32, (y1 - y0) as u32);
    for p in [&mut r.p1, &mut r.p2] {
        p[(0, 2)] -= x0;
        p[(1, 2)] -= y0;
    }
    r.q[(0, 3)] = -r.p1[(0, 2)];
    r.q[(1, 3)] = -r.p1[(1, 2)];
    let inner = |i: &[f64; 4]| -> [u32; 4] {
        const EPS: f64 = 1e-7;
        let ax = (i[0] - x0 - EPS).ceil().clamp(0.0, w as f64);
        let ay = (i[1] - y0 - EPS).ceil().clamp(0.0, h as f64);
        let bx = (i[0] + i[2] - x0 + EPS).floor().clamp(0.0, w as f64);
        let by = (i[1] + i[3] - y0 + EPS).floor().clamp(0.0, h as f64);
        if bx <= ax || by <= ay {
            return [0; 4];
        }
        [ax as u32, ay as u32, (bx - ax) as u32, (by - ay) as u32]
    };
    r.roi1 = inner(&in1);
    r.roi2 = inner(&in2);
    let outer = |o: &[f64; 4]| {
        let m = CANVAS_MARGIN;
        inner(&[o[0] - m, o[1] - m, o[2] + 2.0 * m, o[3] + 2.0 * m])
    };
    r.outer = Some([outer(&out1), outer(&out2)]);
    r.size = (w, h);
    r
}

/// One camera of a rectified pair: what maps its raw pixels to rectified
/// pixels and back.
#[derive(Debug, Clone, PartialEq)]
pub struct RectifiedCamera {
    /// Raw camera matrix.
    pub m: Matrix3<f64>,
    /// Distortion, padded to 8 coefficients.
    pub k: Dist8,
    /// Rectifying rotation (`R1` or `R2`).
    pub r: Matrix3<f64>,
    /// Rectified projection (`P1` or `P2`).
    pub p: Matrix3x4<f64>,
    /// `(P[:, :3]·R)⁻¹`: rectified pixel → normalized ray of the raw camera.
    pub ir: Matrix3<f64>,
    /// Rectified image width.
    pub width: u32,
    /// Rectified image height.
    pub height: u32,
    /// Raw image width.
    pub raw_width: u32,
    /// Raw image height.
    pub raw_height: u32,
}

/// Whether a raw box from [`RectifiedCamera::raw_box`] holds any of the raw
/// view (a box wholly in the fill of an `alpha > 0` rectification clips to
/// zero width or height).
pub fn in_raw_view(b: &[f64; 4]) -> bool {
    b[2] > 0.0 && b[3] > 0.0
}

/// Float undistort-rectify maps (`cv2.initUndistortRectifyMap`, `CV_32FC1`):
/// rectified pixel `(x, y)` samples the raw image at
/// `(map_x[y·w + x], map_y[y·w + x])`.
#[derive(Debug, Clone, PartialEq)]
pub struct RectifyMap {
    /// Width of the rectified image.
    pub width: u32,
    /// Height of the rectified image.
    pub height: u32,
    /// Raw x per rectified pixel, row-major.
    pub map_x: Vec<f32>,
    /// Raw y per rectified pixel, row-major.
    pub map_y: Vec<f32>,
}

impl RectifiedCamera {
    /// The camera from its raw model and rectification.
    pub fn new(
        m: Matrix3<f64>,
        d: &[f64],
        r: Matrix3<f64>,
        p: Matrix3x4<f64>,
        width: u32,
        height: u32,
    ) -> Self {
        let a = p.fixed_view::<3, 3>(0, 0) * r;
        let ir = a.try_inverse().unwrap_or_else(Matrix3::zeros);
        RectifiedCamera {
            m,
            k: StereoCalib::dist8(d),
            r,
            p,
            ir,
            width,
            height,
            raw_width: width,
            raw_height: height,
        }
    }

    /// Left and right cameras of a calibration and its rectification.
    pub fn pair(c: &StereoCalib, rect: &Rectification) -> (Self, Self) {
        let on_canvas = |mut cam: Self| {
            (cam.width, cam.height) = rect.size;
            cam
        };
        (
            on_canvas(Self::new(c.m1, &c.d1, rect.r1, rect.p1, c.width, c.height)),
            on_canvas(Self::new(c.m2, &c.d2, rect.r2, rect.p2, c.width, c.height)),
        )
    }

    /// Rectified pixel → raw pixel (closed form, as the remap maps).
    pub fn rect_to_raw(&self, u: f64, v: f64) -> (f64, f64) {
        let ir = &self.ir;
        let x = ir[(0, 0)] * u + ir[(0, 1)] * v + ir[(0, 2)];
        let y = ir[(1, 0)] * u + ir[(1, 1)] * v + ir[(1, 2)];
        let w = ir[(2, 0)] * u + ir[(2, 1)] * v + ir[(2, 2)];
        let (xd, yd) = distort(&self.k, x / w, y / w);
        (
            self.m[(0, 0)] * xd + self.m[(0, 2)],
            self.m[(1, 1)] * yd + self.m[(1, 2)],
        )
    }

    /// A rectified upright box (pixel indices) → `[x, y, w, h]` in this
    /// camera's raw pixels, in the pixel-edge convention of `truth.json`
    /// (pixel centres at integer + 0.5), clipped to the raw frame. A box
    /// wholly in the fill of an `alpha > 0` rectification clips to zero
    /// width or height ([`in_raw_view`]).
    pub fn raw_box(&self, b: &fishtrack_core::Roi) -> [f64; 4] {
        // pixel indices x..x+w−1: outline x−½ .. x+w−½
        let (x0, y0) = (b.x as f64 - 0.5, b.y as f64 - 0.5);
        let (x1, y1) = (x0 + b.w as f64, y0 + b.h as f64);
        let (a, c, d, e) = self.rect_box_to_raw_clipped(x0, y0, x1, y1);
        [a + 0.5, c + 0.5, (d - a).max(0.0), (e - c).max(0.0)]
    }

    /// Raw-pixel length of an oriented box's long axis (the segmentation's
    /// 2-D fish length), `None` when it is not a positive finite length.
    pub fn raw_axis_length(&self, ob: &fishtrack_core::object::OrientedBox) -> Option<f64> {
        let (c, s) = ((ob.angle as f64).cos(), (ob.angle as f64).sin());
        let hw = ob.half_w as f64;
        let (cx, cy) = (ob.cx as f64, ob.cy as f64);
        let p = self.rect_to_raw(cx - hw * c, cy - hw * s);
        let q = self.rect_to_raw(cx + hw * c, cy + hw * s);
        let len = ((p.0 - q.0).powi(2) + (p.1 - q.1).powi(2)).sqrt();
        (len.is_finite() && len > 0.0).then_some(len)
    }

    /// Raw pixel → rectified pixel, the distortion inverted to 1e-14
    /// (normalized units). `None` when the inversion does not converge.
    pub fn raw_to_rect(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let xd = (u - self.m[(0, 2)]) / self.m[(0, 0)];
        let yd = (v - self.m[(1, 2)]) / self.m[(1, 1)];
        let (x, y) = undistort_exact(&self.k, xd, yd)?;
        let a = self.p.fixed_view::<3, 3>(0, 0) * self.r;
        let q = a * Vector3::new(x, y, 1.0);
        Some((q.x / q.z, q.y / q.z))
    }

    /// A rectified box `[x0, x1] × [y0, y1]` (pixel coordinates) → the
    /// upright box holding its outline in the raw image, found by mapping
    /// outline points at most a pixel apart. Returns `(x0, y0, x1, y1)`.
    pub fn rect_box_to_raw(&self, x0: f64, y0: f64, x1: f64, y1: f64) -> (f64, f64, f64, f64) {
        let (x0, x1) = (x0.min(x1), x0.max(x1));
        let (y0, y1) = (y0.min(y1), y0.max(y1));
        let nx = ((x1 - x0).ceil() as usize).clamp(1, 1 << 16);
        let ny = ((y1 - y0).ceil() as usize).clamp(1, 1 << 16);
        let mut b = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        let mut add = |u: f64, v: f64| {
            let (x, y) = self.rect_to_raw(u, v);
            b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
        };
        for i in 0..=nx {
            let u = x0 + (x1 - x0) * i as f64 / nx as f64;
            add(u, y0);
            add(u, y1);
        }
        for i in 0..=ny {
            let v = y0 + (y1 - y0) * i as f64 / ny as f64;
            add(x0, v);
            add(x1, v);
        }
        b
    }

    /// [`RectifiedCamera::rect_box_to_raw`] clipped to the raw image
    /// (`[−½, w − ½] × [−½, h − ½]` in pixel-centre coordinates): the part
    /// of a rectified box beyond the raw frame shows the [`Fill`], not the
    /// scene.
    pub fn rect_box_to_raw_clipped(
        &self,
        x0: f64,
        y0: f64,
        x1: f64,
        y1: f64,
    ) -> (f64, f64, f64, f64) {
        let (a, b, c, d) = self.rect_box_to_raw(x0, y0, x1, y1);
        let (w, h) = (self.raw_width as f64 - 0.5, self.raw_height as f64 - 0.5);
        let cx = |v: f64| v.clamp(-0.5, w);
        let cy = |v: f64| v.clamp(-0.5, h);
        (cx(a), cy(b), cx(c), cy(d))
    }

    /// The float maps of `cv2.initUndistortRectifyMap(M, D, R, P, size, CV_32FC1)`.
    pub fn float_map(&self) -> RectifyMap {
        use rayon::prelude::*;
        let (w, h) = (self.width as usize, self.height as usize);
        let mut map_x = vec![0f32; w * h];
        let mut map_y = vec![0f32; w * h];
        // rows in parallel (the same per-pixel arithmetic, so the same maps)
        map_x
            .par_chunks_mut(w.max(1))
            .zip(map_y.par_chunks_mut(w.max(1)))
            .enumerate()
            .for_each(|(y, (mx, my))| {
                for (x, (px, py)) in mx.iter_mut().zip(my.iter_mut()).enumerate() {
                    let (u, v) = self.rect_to_raw(x as f64, y as f64);
                    *px = u as f32;
                    *py = v as f32;
                }
            });
        RectifyMap {
            width: self.width,
            height: self.height,
            map_x,
            map_y,
        }
    }
}

/// Bilinear remap of an 8-bit image through float maps, in `f64`, with
/// out-of-image neighbours read as 0 (OpenCV `BORDER_CONSTANT`), rounded
/// to nearest. The host-side yardstick for the core's fixed-point remap.
pub fn remap_float(src: &GrayImage, map: &RectifyMap) -> GrayImage {
    let (sw, sh) = (src.width() as i64, src.height() as i64);
    let px = |x: i64, y: i64| -> f64 {
        if x >= 0 && y >= 0 && x < sw && y < sh {
            src.get_pixel(x as u32, y as u32)[0] as f64
        } else {
            0.0
        }
    };
    let mut out = GrayImage::new(map.width, map.height);
    for (i, p) in out.pixels_mut().enumerate() {
        let (x, y) = (map.map_x[i] as f64, map.map_y[i] as f64);
        if !x.is_finite() || !y.is_finite() {
            p[0] = 0;
            continue;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (a, b) = (x - x0, y - y0);
        let (xi, yi) = (x0 as i64, y0 as i64);
        let v = px(xi, yi) * (1.0 - a) * (1.0 - b)
            + px(xi + 1, yi) * a * (1.0 - b)
            + px(xi, yi + 1) * (1.0 - a) * b
            + px(xi + 1, yi + 1) * a * b;
        p[0] = v.round().clamp(0.0, 255.0) as u8;
    }
    out
}

/// The core's fixed-point table for a float map (OpenCV `convertMaps` to
/// `CV_16SC2` + `CV_16UC1`: coordinates rounded to 1/32 pixel, half to even).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedMap {
    /// Width of the rectified image.
    pub width: u32,
    /// Height of the rectified image.
    pub height: u32,
    /// Integer source `(x, y)` per output pixel, interleaved.
    pub xy: Vec<i16>,
    /// `fy·32 + fx` fractions per output pixel.
    pub frac: Vec<u16>,
}

impl FixedMap {
    /// Output rows per parallel band of [`FixedMap::apply`].
    pub const BAND_ROWS: usize = 64;

    /// Quantizes float maps (neighbours outside the source read as 0, as
    /// `cv2.remap(..., BORDER_CONSTANT)`).
    pub fn from_float(map: &RectifyMap) -> Self {
        Self::from_float_fill(map, Fill::Constant, 0, 0)
    }

    /// Quantizes float maps with the fill `fill` for rectified pixels
    /// whose source lies outside the `src_w × src_h` raw image (see
    /// [`Fill`]): the source coordinates are folded into the image before
    /// quantizing, so the core's remap is unchanged.
    pub fn from_float_fill(map: &RectifyMap, fill: Fill, src_w: u32, src_h: u32) -> Self {
        let n = map.map_x.len();
        let fold = |v: f32, side: u32| -> f32 { fill.fold(v, side) };
        let (cw, ch) = (src_w, src_h);
        let clamp = |v: f32, side: u32| -> f32 {
            if v.is_nan() {
                v // NaN stays NaN (`OUTSIDE`)
            } else {
                fold(v, side)
            }
        };
        let mut xy = vec![0i16; 2 * n];
        let mut frac = vec![0u16; n];
        let q = |v: f32| -> i32 {
            let s = (v * remap::INTER_TAB_SIZE as f32) as f64;
            if s.is_nan() {
                i32::MIN
            } else {
                s.round_ties_even().clamp(i32::MIN as f64, i32::MAX as f64) as i32
            }
        };
        for i in 0..n {
            let (x, y) = (clamp(map.map_x[i], cw), clamp(map.map_y[i], ch));
            let (p, f) = remap::pack(q(x), q(y));
            xy[2 * i] = p[0];
            xy[2 * i + 1] = p[1];
            frac[i] = f;
        }
        FixedMap {
            width: map.width,
            height: map.height,
            xy,
            frac,
        }
    }

    /// The table as the core reads it.
    pub fn table(&self) -> Result<RemapTable<'_>, RemapError> {
        RemapTable::new(
            self.width as usize,
            self.height as usize,
            &self.xy,
            &self.frac,
        )
    }

    /// Remaps `src` with the core's fixed-point bilinear remap.
    pub fn apply(&self, src: &GrayImage) -> Result<GrayImage, RemapError> {
        let view = ImageView::packed(src.as_raw(), src.width() as usize, src.height() as usize)
            .map_err(RemapError::Image)?;
        use rayon::prelude::*;
        let mut out = GrayImage::new(self.width, self.height);
        let (w, h) = (self.width as usize, self.height as usize);
        self.table()?; // size check
                       // row bands remapped in parallel: each band is the table's rows
                       // and the output's rows of that band (the source is shared)
        let band = Self::BAND_ROWS;
        let buf: &mut [u8] = &mut out;
        buf.par_chunks_mut((band * w).max(1))
            .enumerate()
            .try_for_each(|(i, chunk)| {
                let (y0, rows) = (i * band, chunk.len() / w.max(1));
                let t = RemapTable::new(
                    w,
                    rows,
                    self.xy.get(2 * y0 * w..).unwrap_or(&[]),
                    self.frac.get(y0 * w..).unwrap_or(&[]),
                )?;
                let mut dst = ImageViewMut::packed(chunk, w, rows).map_err(RemapError::Image)?;
                remap::remap_bilinear(&view, &t, &mut dst)
            })?;
        debug_assert_eq!(h * w, buf.len());
        Ok(out)
    }
}

/// What a rectified pixel whose source lies outside the raw image shows.
/// The rectification keeps only valid pixels at `alpha = 0`; at `alpha > 0`
/// the frame's corners and edge wedges have no source.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fill {
    /// 0 (`cv2.BORDER_CONSTANT`): the fill's edge against the water is an
    /// edge the segmentation picks up.
    Constant,
    /// The nearest edge pixel (`cv2.BORDER_REPLICATE`; bilinear
    /// interpolation of a replicated border at `x` equals that at
    /// `clamp(x, 0, w − 1)`): the edge pixels' noise is drawn out into
    /// streaks perpendicular to the edge, which segment as elongated
    /// objects.
    Replicate,
    /// The raw image mirrored about its edge pixels
    /// (`cv2.BORDER_REFLECT_101`; bilinear interpolation of that border at
    /// `x < 0` equals that at `−x`, and at `x > w − 1` that at
    /// `2(w − 1) − x`): the water's texture, noise and glow continue
    /// across the edge without a step or streaks; a fish cut by the edge
    /// meets its mirror image, so its box is clipped to the raw frame when
    /// mapped back ([`RectifiedCamera::rect_box_to_raw_clipped`]).
    Reflect101,
}

impl Fill {
    /// The raw coordinate a source coordinate `v` on a side of `n` pixels
    /// reads under this fill (unchanged for `Constant`).
    pub fn fold(self, v: f32, n: u32) -> f32 {
        let hi = n.saturating_sub(1) as f32;
        match self {
            Fill::Constant => v,
            Fill::Replicate => v.max(0.0).min(hi),
            Fill::Reflect101 => {
                if hi <= 0.0 {
                    return 0.0;
                }
                // period 2(n − 1); one fold covers any |v| < 2(n − 1)
                let p = 2.0 * hi;
                let r = v.rem_euclid(p);
                if r > hi {
                    p - r
                } else {
                    r
                }
            }
        }
    }
}

/// The water fill of a canvas rectification ([`stereo_rectify_canvas`]):
/// the rectified pixels with no raw source show the water's local level
/// instead of the mirrored raw image ([`Fill::Reflect101`]), so a fish
/// near the raw border has no mirror twin beyond it and the border is no
/// edge. The level of a pixel is the median of the valid pixels within
/// [`WaterFill::BAND`] px of the fill in its [`WaterFill::CELL`]-px cell
/// (the nearest cell that has some, else the whole band's).
#[derive(Debug, Clone)]
pub struct WaterFill {
    width: usize,
    height: usize,
    /// Pixels (row-major indices) with no raw source.
    invalid: Vec<u32>,
    /// Each invalid pixel's unit noise sample (a fixed pseudo-random
    /// pattern, made once: [`WaterFill::unit_noise`]).
    noise: Vec<f32>,
    /// Valid pixels near the fill, with their cell's slot (the cells that
    /// hold band pixels, numbered densely: one histogram each per frame).
    band: Vec<(u32, u32)>,
    /// Slots in use.
    slots: usize,
    /// Per cell, the slot whose band median it takes (`u32::MAX`: the
    /// whole band's).
    source_cell: Vec<u32>,
    cells: usize,
    cells_x: usize,
}

impl WaterFill {
    /// Width of the band of valid pixels sampled, px.
    pub const BAND: usize = 8;
    /// Cell side, px.
    pub const CELL: usize = 64;

    /// From a rectified view's float map and the raw size.
    pub fn new(map: &RectifyMap, raw_w: u32, raw_h: u32) -> Self {
        let (w, h) = (map.width as usize, map.height as usize);
        let (rw, rh) = (raw_w as f32 - 1.0, raw_h as f32 - 1.0);
        let bad: Vec<bool> = map
            .map_x
            .iter()
            .zip(&map.map_y)
            .map(|(&x, &y)| !(x >= 0.0 && y >= 0.0 && x <= rw && y <= rh))
            .collect();
        // distance ≤ BAND to an invalid pixel (Chebyshev): separable max
        let r = Self::BAND;
        let mut rows = vec![false; w * h];
        for y in 0..h {
            let row = &bad[y * w..(y + 1) * w];
            let mut last: Option<usize> = None;
            let mut next = vec![usize::MAX; w];
            for x in (0..w).rev() {
                if row[x] {
                    last = Some(x);
                }
                next[x] = last.unwrap_or(usize::MAX);
            }
            let mut prev: Option<usize> = None;
            for x in 0..w {
                if row[x] {
                    prev = Some(x);
                }
                let near = prev.is_some_and(|p| x - p <= r) || next[x].saturating_sub(x) <= r;
                rows[y * w + x] = near;
            }
        }
        let mut near = vec![false; w * h];
        for x in 0..w {
            for y in 0..h {
                let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
                near[y * w + x] = (a..=b).any(|yy| rows[yy * w + x]);
            }
        }
        let (cw, ch) = (w.div_ceil(Self::CELL), h.div_ceil(Self::CELL));
        let cell = |i: usize| ((i / w) / Self::CELL * cw + (i % w) / Self::CELL) as u32;
        let mut invalid = Vec::new();
        let mut band = Vec::new();
        let mut has = vec![false; cw * ch];
        for i in 0..w * h {
            if bad[i] {
                invalid.push(i as u32);
            } else if near[i] {
                band.push((i as u32, cell(i)));
                has[cell(i) as usize] = true;
            }
        }
        // dense slots for the cells that have band pixels
        let mut slot = vec![u32::MAX; cw * ch];
        let mut slots = 0usize;
        for (c, &hc) in has.iter().enumerate() {
            if hc {
                slot[c] = slots as u32;
                slots += 1;
            }
        }
        for b in band.iter_mut() {
            b.1 = slot[b.1 as usize];
        }
        let source_cell = (0..cw * ch)
            .map(|c| {
                let (cx, cy) = ((c % cw) as i64, (c / cw) as i64);
                let mut best: Option<(i64, u32)> = None;
                for (k, &hk) in has.iter().enumerate() {
                    if !hk {
                        continue;
                    }
                    let (kx, ky) = ((k % cw) as i64, (k / cw) as i64);
                    let d = (kx - cx).pow(2) + (ky - cy).pow(2);
                    if best.is_none_or(|b| d < b.0) {
                        best = Some((d, k as u32));
                    }
                }
                best.map_or(u32::MAX, |b| slot[b.1 as usize])
            })
            .collect();
        let noise = invalid.iter().map(|&i| Self::unit_noise(i)).collect();
        WaterFill {
            width: w,
            height: h,
            invalid,
            noise,
            band,
            slots,
            source_cell,
            cells: cw * ch,
            cells_x: cw,
        }
    }

    /// Water noise of unit σ for pixel `i`: a fixed pseudo-random pattern
    /// (xorshift of the index; the sum of 4 uniforms, mean 2, variance 1/3,
    /// centred and scaled), so the frame's noise and gradient statistics
    /// see water in the fill.
    fn unit_noise(i: u32) -> f32 {
        let mut x = i.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
        let mut g = 0.0f32;
        for _ in 0..4 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            g += (x & 0xFFFF) as f32 / 65535.0;
        }
        (g - 2.0) * 3f32.sqrt()
    }

    /// Overwrites the fill of a rectified frame with the water level.
    pub fn apply(&self, img: &mut GrayImage) {
        let size = (img.width() as usize, img.height() as usize);
        if self.invalid.is_empty() || size != (self.width, self.height) {
            return;
        }
        let buf: &mut [u8] = img;
        let mut hist = vec![[0u32; 256]; self.slots];
        let mut all = [0u32; 256];
        for &(i, c) in &self.band {
            let v = buf[i as usize] as usize;
            hist[c as usize][v] += 1;
            all[v] += 1;
        }
        // the median of a histogram (0 when empty)
        let median = |h: &[u32; 256]| -> f32 {
            let n: u32 = h.iter().sum();
            let mut acc = 0;
            for (v, &k) in h.iter().enumerate() {
                acc += k;
                if 2 * acc >= n && n > 0 {
                    return v as f32;
                }
            }
            0.0
        };
        // one noise σ for the whole fill, the frame's own (the core's
        // estimate, on the frame as remapped: the strands of the mesh and
        // the cells' level differences inflate the band's spread), levels
        // per cell interpolated bilinearly between cell centres (no steps
        // at the cells' edges)
        let s = fishtrack_core::ImageView::packed(buf, self.width, self.height).map_or(0.0, |v| {
            fishtrack_core::noise::noise_sigma16(v) as f32 / 16.0
        });
        let global = median(&all);
        let level: Vec<f32> = (0..self.cells)
            .map(|c| match self.source_cell[c] {
                u32::MAX => global,
                k => median(&hist[k as usize]),
            })
            .collect();
        let (cw, ch) = (self.cells_x, self.cells / self.cells_x.max(1));
        let at = |x: usize, y: usize| level[y.min(ch - 1) * cw + x.min(cw - 1)];
        let half = Self::CELL as f32 / 2.0;
        // (the invalid pixels are in ascending order: each row's vertical
        // position once, no division per pixel)
        let (mut row_start, mut row_end) = (0usize, 0usize);
        let (mut y0, mut ay) = (0usize, 0.0f32);
        for (&i, &z) in self.invalid.iter().zip(&self.noise) {
            let i = i as usize;
            if i >= row_end {
                let y = i / self.width;
                row_start = y * self.width;
                row_end = row_start + self.width;
                let fy = ((y as f32 - half) / Self::CELL as f32).max(0.0);
                y0 = fy as usize;
                ay = fy - y0 as f32;
            }
            let px = (i - row_start) as f32;
            let fx = ((px - half) / Self::CELL as f32).max(0.0);
            let x0 = fx as usize;
            let ax = fx - x0 as f32;
            let m = (1.0 - ay) * ((1.0 - ax) * at(x0, y0) + ax * at(x0 + 1, y0))
                + ay * ((1.0 - ax) * at(x0, y0 + 1) + ax * at(x0 + 1, y0 + 1));
            if let Some(b) = buf.get_mut(i) {
                *b = (m + s * z).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}

/// The raw view's border on the rectified frame: the raw frame's four
/// edges (pixel-edge convention, `−½` and `w − ½`) mapped point by point
/// ([`RectifiedCamera::raw_to_rect`], 1 px apart), each side resampled at
/// [`fishtrack_core::track::outline::OUTLINE_POINTS`] even positions along
/// its own span (a sample that does not map takes its neighbour's value).
pub fn outline(cam: &RectifiedCamera) -> fishtrack_core::track::ViewOutline {
    use fishtrack_core::track::outline::{Side, OUTLINE_POINTS};
    let (w, h) = (cam.raw_width as f64, cam.raw_height as f64);
    // points along one raw edge, as (along, across) in rectified pixels
    let edge = |horizontal: bool, fixed: f64| -> Vec<(f64, f64)> {
        let n = if horizontal { w } else { h } as usize;
        (0..=n)
            .filter_map(|i| {
                let t = i as f64 - 0.5;
                let (u, v) = if horizontal { (t, fixed) } else { (fixed, t) };
                // the edge in pixel-centre coordinates, + ½: the outline's
                // sides are the first row / column inside (top, left) and
                // the first outside (bottom, right), as `ViewOutline::rect`
                let (x, y) = cam.raw_to_rect(u, v)?;
                Some(if horizontal {
                    (x, y + 0.5)
                } else {
                    (y, x + 0.5)
                })
            })
            .collect()
    };
    let side = |pts: Vec<(f64, f64)>, fallback: f64| -> Side {
        let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
            return Side::straight(0.0, 0.0, fallback as f32);
        };
        let (from, to) = (first.0.min(last.0), first.0.max(last.0));
        let mut at = [fallback as f32; OUTLINE_POINTS];
        for (k, a) in at.iter_mut().enumerate() {
            let t = from + (to - from) * k as f64 / (OUTLINE_POINTS - 1) as f64;
            // the nearest mapped point at or around t (1 px apart)
            if let Some(p) = pts
                .iter()
                .min_by(|p, q| (p.0 - t).abs().total_cmp(&(q.0 - t).abs()))
            {
                *a = p.1 as f32;
            }
        }
        Side {
            from: from as f32,
            to: to as f32,
            at,
        }
    };
    let (cw, ch) = (cam.width as f64, cam.height as f64);
    fishtrack_core::track::ViewOutline {
        top: side(edge(true, -0.5), 0.0),
        bottom: side(edge(true, h - 0.5), ch),
        left: side(edge(false, -0.5), 0.0),
        right: side(edge(false, w - 0.5), cw),
    }
}

/// Rectifies raw left/right frame pairs of one calibration with the core's
/// fixed-point remap.
#[derive(Debug, Clone)]
pub struct Rectifier {
    /// The calibration.
    pub calib: StereoCalib,
    /// Its rectification.
    pub rect: Rectification,
    /// Left camera mapping.
    pub left: RectifiedCamera,
    /// Right camera mapping.
    pub right: RectifiedCamera,
    /// Left fixed-point table.
    pub left_map: FixedMap,
    /// Right fixed-point table.
    pub right_map: FixedMap,
    /// The free scaling the rectification was computed with.
    pub alpha: f64,
    /// The water fill of both views (canvas rectifications only).
    pub water: Option<Box<[WaterFill; 2]>>,
}

impl Rectifier {
    /// Computes the rectification with FishTrack's default scaling
    /// ([`Scaling::default`]: [`DEFAULT_ALPHA`]'s scale on a canvas) and
    /// both remap tables.
    pub fn new(calib: &StereoCalib) -> Self {
        Self::with_scaling(calib, Scaling::default())
    }

    /// Computes the rectification with `scaling` (see [`Scaling`]) and both
    /// remap tables.
    pub fn with_scaling(calib: &StereoCalib, scaling: Scaling) -> Self {
        let alpha = scaling.alpha(calib);
        if scaling == Scaling::Canvas {
            return Self::with_rectification(calib, stereo_rectify_canvas(calib, alpha), alpha);
        }
        Self::with_alpha(calib, alpha)
    }

    /// Computes the rectification with OpenCV's free scaling `alpha` (see
    /// [`stereo_rectify_alpha`]) and both remap tables; rectified pixels
    /// with no source show the raw image mirrored about its edge
    /// ([`Fill::Reflect101`]).
    pub fn with_alpha(calib: &StereoCalib, alpha: f64) -> Self {
        Self::with_rectification(calib, stereo_rectify_alpha(calib, alpha), alpha)
    }

    /// The remap tables of `rect` (computed with the free scaling `alpha`).
    fn with_rectification(calib: &StereoCalib, rect: Rectification, alpha: f64) -> Self {
        let (left, right) = RectifiedCamera::pair(calib, &rect);
        let (w, h) = (calib.width, calib.height);
        let canvas = rect.outer.is_some();
        // a camera's fixed-point table and, on a canvas, its water fill
        let tables = |cam: &RectifiedCamera| {
            let m = cam.float_map();
            let water = canvas.then(|| WaterFill::new(&m, w, h));
            (FixedMap::from_float_fill(&m, RECTIFIER_FILL, w, h), water)
        };
        let ((left_map, lw), (right_map, rw)) = rayon::join(|| tables(&left), || tables(&right));
        let water = match (lw, rw) {
            (Some(a), Some(b)) => Some(Box::new([a, b])),
            _ => None,
        };
        Rectifier {
            calib: calib.clone(),
            rect,
            left,
            right,
            left_map,
            right_map,
            alpha,
            water,
        }
    }

    /// The left and right rectangles of the rectified frames where every
    /// pixel has a raw source, as core rectangles: OpenCV's `roi1`, `roi2`
    /// when `alpha ≠ 0`, the whole frame at `alpha = 0` (every pixel has a
    /// source by construction; OpenCV's rounding may drop the last row).
    pub fn valid_rois(&self) -> [fishtrack_core::Roi; 2] {
        let (w, h) = self.rect.size;
        let r = |v: [u32; 4]| {
            if self.alpha == 0.0 {
                fishtrack_core::Roi::new(0, 0, w, h)
            } else {
                fishtrack_core::Roi::new(v[0], v[1], v[2], v[3])
            }
        };
        [r(self.rect.roi1), r(self.rect.roi2)]
    }

    /// The left and right rectangles of the rectified frames that hold the
    /// raw views: on a canvas ([`stereo_rectify_canvas`]) their outer
    /// rectangles, else [`Rectifier::valid_rois`].
    pub fn view_rois(&self) -> [fishtrack_core::Roi; 2] {
        match self.rect.outer {
            Some(o) => o.map(|v| fishtrack_core::Roi::new(v[0], v[1], v[2], v[3])),
            None => self.valid_rois(),
        }
    }

    /// The left and right raw views' borders on a canvas
    /// ([`stereo_rectify_canvas`]; `None` for the other rectifications,
    /// whose views are [`Rectifier::view_rois`]).
    pub fn view_outlines(&self) -> Option<[fishtrack_core::track::ViewOutline; 2]> {
        self.rect.outer?;
        Some([outline(&self.left), outline(&self.right)])
    }

    /// The rectified frames' size `(width, height)`.
    pub fn size(&self) -> (u32, u32) {
        self.rect.size
    }

    /// Rectifies a raw left frame (of the calibration's size), the water
    /// fill included: what the segmentation of the left view sees.
    pub fn rectify_left(&self, left: &GrayImage) -> Result<GrayImage, RemapError> {
        if left.dimensions() != (self.calib.width, self.calib.height) {
            return Err(RemapError::SizeMismatch);
        }
        let mut l = self.left_map.apply(left)?;
        if let Some(wf) = &self.water {
            wf[0].apply(&mut l);
        }
        Ok(l)
    }

    /// Rectifies a raw frame pair (each must have the calibration's size).
    pub fn rectify_pair(
        &self,
        left: &GrayImage,
        right: &GrayImage,
    ) -> Result<(GrayImage, GrayImage), RemapError> {
        let size = (self.calib.width, self.calib.height);
        if left.dimensions() != size || right.dimensions() != size {
            return Err(RemapError::SizeMismatch);
        }
        // each view remapped and filled on its own thread
        let view = |map: &FixedMap, img: &GrayImage, k: usize| {
            let mut out = map.apply(img)?;
            if let Some(wf) = &self.water {
                wf[k].apply(&mut out);
            }
            Ok::<_, RemapError>(out)
        };
        let (l, r) = rayon::join(
            || view(&self.left_map, left, 0),
            || view(&self.right_map, right, 1),
        );
        Ok((l?, r?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rodrigues_round_trips() {
        for v in [
            Vector3::new(0.1, -0.2, 0.05),
            Vector3::new(2e-5, 0.0, 0.0),
            Vector3::new(0.0, 3.0, 0.1),
        ] {
            let m = rodrigues_vec_to_mat(&v);
            assert!((rodrigues_mat_to_vec(&m) - v).norm() < 1e-9, "{v}");
        }
        // like OpenCV, rotations below ~1e-5 rad read back as none
        let m = rodrigues_vec_to_mat(&Vector3::new(1e-9, 0.0, 0.0));
        assert_eq!(rodrigues_mat_to_vec(&m), Vector3::zeros());
        // 180 degrees
        let v = Vector3::new(0.0, std::f64::consts::PI, 0.0);
        let back = rodrigues_mat_to_vec(&rodrigues_vec_to_mat(&v));
        assert!((back.norm() - std::f64::consts::PI).abs() < 1e-9);
    }

    fn rig() -> StereoCalib {
        StereoCalib {
            width: 160,
            height: 120,
            m1: Matrix3::new(150.0, 0.0, 79.0, 0.0, 151.0, 60.5, 0.0, 0.0, 1.0),
            d1: vec![-0.25, 0.08, 0.001, -0.0005, 0.0],
            m2: Matrix3::new(152.0, 0.0, 81.0, 0.0, 150.0, 59.0, 0.0, 0.0, 1.0),
            d2: vec![-0.22, 0.06, 0.0, 0.0],
            r: *nalgebra::Rotation3::from_euler_angles(0.01, -0.05, 0.004).matrix(),
            t: Vector3::new(-100.0, 1.0, 2.0),
        }
    }

    /// Rectified focal length over the mean raw one (OpenCV's scale `s`).
    fn scale(c: &StereoCalib, alpha: f64) -> f64 {
        stereo_rectify_alpha(c, alpha).p1[(1, 1)] / ((c.m1[(1, 1)] + c.m2[(1, 1)]) * 0.5)
    }

    /// Raw left pixels (every 4th) that land inside the rectified frame.
    fn raw_kept(c: &StereoCalib, alpha: f64) -> usize {
        let (l, _) = RectifiedCamera::pair(c, &stereo_rectify_alpha(c, alpha));
        let (w, h) = (c.width as f64, c.height as f64);
        let mut n = 0;
        for v in (0..c.height).step_by(4) {
            for u in (0..c.width).step_by(4) {
                if let Some((x, y)) = l.raw_to_rect(u as f64, v as f64) {
                    n += usize::from(x >= -0.5 && y >= -0.5 && x < w - 0.5 && y < h - 0.5);
                }
            }
        }
        n
    }

    #[test]
    fn no_magnification_lowers_the_scale_to_the_raw_focal_length() {
        // pincushion distortion: alpha = 0.25 magnifies and crops the raw view
        let mut c = rig();
        c.d1 = vec![0.1, 0.0, 0.0, 0.0, 0.0];
        c.d2 = vec![0.1, 0.0, 0.0, 0.0];
        assert!(
            scale(&c, DEFAULT_ALPHA) > 1.02,
            "{}",
            scale(&c, DEFAULT_ALPHA)
        );
        let a = no_magnification_alpha(&c, DEFAULT_ALPHA);
        assert_eq!(Scaling::NoMagnification.alpha(&c), a);
        assert!(a > DEFAULT_ALPHA && a <= 1.0, "{a}");
        let target = scale(&c, 1.0).max(1.0);
        assert!(
            (scale(&c, a) - target).abs() < 1e-9,
            "{} {target}",
            scale(&c, a)
        );
        assert!(raw_kept(&c, a) > raw_kept(&c, DEFAULT_ALPHA));
        // a rig whose 0.25 scale is below 1 (barrel distortion) keeps
        // alpha_min; so does a minimum above the crossing
        let p = rig();
        assert!(
            scale(&p, DEFAULT_ALPHA) <= 1.0,
            "{}",
            scale(&p, DEFAULT_ALPHA)
        );
        assert_eq!(no_magnification_alpha(&p, DEFAULT_ALPHA), DEFAULT_ALPHA);
        assert_eq!(no_magnification_alpha(&c, 0.99), 0.99);
        // the default scaling is the canvas at the fixed alpha's scale
        assert_eq!(Scaling::default(), Scaling::Canvas);
        assert_eq!(Scaling::default().alpha(&c), DEFAULT_ALPHA);
        assert_eq!(Scaling::Alpha(0.5).alpha(&c), 0.5);
    }

    #[test]
    fn alpha_one_keeps_every_source_pixel_and_fills_the_rest_without_edges() {
        let c = rig();
        let (w, h) = (c.width, c.height);
        let r0 = stereo_rectify_alpha(&c, 0.0);
        let r1 = stereo_rectify_alpha(&c, 1.0);
        assert_eq!(r0, stereo_rectify(&c));
        // alpha = 1 zooms out: a smaller focal length
        assert!(r1.p1[(0, 0)] < r0.p1[(0, 0)] * 0.98, "{} {}", r1.p1, r0.p1);
        let (l0, _) = RectifiedCamera::pair(&c, &r0);
        let (l1, _) = RectifiedCamera::pair(&c, &r1);
        // the raw frame's edge midpoints lie outside the alpha-0 frame and
        // inside the alpha-1 frame
        for (u, v) in [(0.0, 59.5), (159.0, 59.5), (79.5, 0.0), (79.5, 119.0)] {
            let (x0, y0) = l0.raw_to_rect(u, v).unwrap();
            let (x1, y1) = l1.raw_to_rect(u, v).unwrap();
            let inside = |x: f64, y: f64| x >= 0.0 && y >= 0.0 && x <= 159.0 && y <= 119.0;
            assert!(!inside(x0, y0), "({u}, {v}) -> ({x0}, {y0}) at alpha 0");
            assert!(inside(x1, y1), "({u}, {v}) -> ({x1}, {y1}) at alpha 1");
        }
        // a uniform raw frame rectifies to a uniform frame with the
        // replicated fill, to black corners without it
        let flat = GrayImage::from_pixel(w, h, image::Luma([37]));
        let map = l1.float_map();
        for fill in [Fill::Replicate, Fill::Reflect101] {
            let rep = FixedMap::from_float_fill(&map, fill, w, h)
                .apply(&flat)
                .unwrap();
            assert!(rep.pixels().all(|p| p[0] == 37), "{fill:?}");
        }
        let cst = FixedMap::from_float(&map).apply(&flat).unwrap();
        assert!(cst.pixels().filter(|p| p[0] < 37).count() > 100);
        // the valid-pixel rectangle is strictly inside at alpha 1, the whole
        // frame at alpha 0 (OpenCV's floor can lose the last row or column)
        let [x, y, rw, rh] = r0.roi1;
        assert!(
            x == 0 && y == 0 && rw + 1 >= w && rh + 1 >= h,
            "{:?}",
            r0.roi1
        );
        let [x, y, rw, rh] = r1.roi1;
        assert!(x > 0 && y > 0 && x + rw < w && y + rh < h, "{:?}", r1.roi1);
        // every pixel of it has a source
        for yy in y..y + rh {
            for xx in x..x + rw {
                let i = (yy * w + xx) as usize;
                let (sx, sy) = (map.map_x[i], map.map_y[i]);
                assert!(sx >= -0.5 && sy >= -0.5 && sx <= 159.5 && sy <= 119.5);
            }
        }
    }

    #[test]
    fn valid_rectangles_make_boxes_in_the_fill_cut() {
        use fishtrack_core::length::wholly_inside_valid;
        use fishtrack_core::Roi;
        let c = rig();
        let (w, h) = (c.width, c.height);
        let full = Roi::new(0, 0, w, h);
        assert_eq!(Rectifier::with_alpha(&c, 0.0).valid_rois(), [full, full]);
        let v = Rectifier::with_alpha(&c, 1.0).valid_rois();
        for r in v {
            assert!(
                r.x > 0 && r.y > 0 && r.right() < w && r.bottom() < h,
                "{r:?}"
            );
        }
        // a box inside the frame but reaching the left fill is cut; the
        // same box moved inside the valid rectangles is not
        let b = Roi::new(v[0].x.max(v[1].x) / 2, 50, 20, 10);
        assert!(wholly_inside_valid(&b, &b, &[full, full], 2));
        assert!(!wholly_inside_valid(&b, &b, &v, 2));
        let b2 = Roi::new(v[0].x.max(v[1].x) + 5, 50, 20, 10);
        assert!(wholly_inside_valid(&b2, &b2, &v, 2));
    }

    #[test]
    fn canvas_keeps_every_raw_pixel_at_the_scale_of_its_alpha() {
        for c in [rig(), {
            // pincushion: the raw edges bow the other way
            let mut c = rig();
            c.d1 = vec![0.1, 0.0, 0.0, 0.0, 0.0];
            c.d2 = vec![0.1, 0.0, 0.0, 0.0];
            c
        }] {
            let a = stereo_rectify_alpha(&c, DEFAULT_ALPHA);
            let r = stereo_rectify_canvas(&c, DEFAULT_ALPHA);
            // same scale and rotations, principal points moved by whole pixels
            assert_eq!((r.p1[(0, 0)], r.r1, r.r2), (a.p1[(0, 0)], a.r1, a.r2));
            assert_eq!(r.p2[(0, 3)], a.p2[(0, 3)]);
            for (p, q) in [(&r.p1, &a.p1), (&r.p2, &a.p2)] {
                let (dx, dy) = (q[(0, 2)] - p[(0, 2)], q[(1, 2)] - p[(1, 2)]);
                assert!(dx == dx.round() && dy == dy.round(), "{dx} {dy}");
            }
            assert_eq!((r.q[(0, 3)], r.q[(1, 3)]), (-r.p1[(0, 2)], -r.p1[(1, 2)]));
            assert_eq!((r.q[(2, 3)], r.q[(3, 2)]), (a.q[(2, 3)], a.q[(3, 2)]));
            let (w, h) = r.size;
            assert!(w > c.width && h > c.height, "{:?}", r.size);
            // every raw pixel of both cameras lands on the canvas, well inside
            let (l, rr) = RectifiedCamera::pair(&c, &r);
            assert_eq!((l.width, l.height, l.raw_width), (w, h, c.width));
            for cam in [&l, &rr] {
                for v in 0..c.height {
                    for u in 0..c.width {
                        let (x, y) = cam.raw_to_rect(u as f64, v as f64).unwrap();
                        assert!(
                            x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64,
                            "({u}, {v}) -> ({x}, {y}) on {w} x {h}"
                        );
                    }
                }
            }
            // the outer rectangles hold the views; the inner ones lie in them
            let o = r.outer.unwrap();
            for (k, cam) in [&l, &rr].into_iter().enumerate() {
                let [ox, oy, ow, oh] = o[k];
                let [ix, iy, iw, ih] = if k == 0 { r.roi1 } else { r.roi2 };
                assert!(ix >= ox && iy >= oy && ix + iw <= ox + ow && iy + ih <= oy + oh);
                // the outline follows the raw edges: their midpoints are on it
                let ol = outline(cam);
                let (x, y) = cam
                    .raw_to_rect(-0.5, (c.height as f64 - 1.0) / 2.0)
                    .unwrap();
                // (+ ½: the first column inside, the first row outside)
                assert!((ol.left.value(y as f32) - (x + 0.5) as f32).abs() < 0.4);
                let (x, y) = cam
                    .raw_to_rect((c.width as f64 - 1.0) / 2.0, c.height as f64 - 0.5)
                    .unwrap();
                assert!((ol.bottom.value(x as f32) - (y + 0.5) as f32).abs() < 0.4);
            }
            // a rectifier on the canvas maps boxes back into the raw frame
            let rect = Rectifier::with_scaling(&c, Scaling::Canvas);
            assert_eq!(rect.size(), (w, h));
            assert!(rect.view_outlines().is_some());
            assert!(Rectifier::new(&c).view_outlines().is_some());
            assert!(Rectifier::with_alpha(&c, DEFAULT_ALPHA)
                .view_outlines()
                .is_none());
            let b = rect.left.raw_box(&fishtrack_core::Roi::new(0, 0, w, h));
            assert!(
                b[0] >= 0.0
                    && b[1] >= 0.0
                    && b[0] + b[2] <= c.width as f64
                    && b[1] + b[3] <= c.height as f64,
                "{b:?}"
            );
        }
    }

    #[test]
    fn a_canvas_many_times_the_raw_view_keeps_the_raw_size() {
        // a strong pincushion: the raw corners map far outside the view
        let mut c = rig();
        c.d1 = vec![2.5, 4.0, 0.0, 0.0, 0.0];
        let r = stereo_rectify_canvas(&c, DEFAULT_ALPHA);
        assert_eq!(r.size, (c.width, c.height));
        assert!(r.outer.is_none());
        // the plain rig's canvas is larger than its raw view
        let (w, _) = stereo_rectify_canvas(&rig(), DEFAULT_ALPHA).size;
        assert!(w > rig().width && w as f64 <= CANVAS_MAX_FACTOR * rig().width as f64);
    }

    #[test]
    fn water_fill_shows_water_not_the_mirrored_view() {
        let c = rig();
        let (w, h) = (c.width, c.height);
        let rect = Rectifier::with_scaling(&c, Scaling::Canvas);
        // water at 40 with noise of σ ≈ 2 and a bright fish at the raw left edge
        let mut seed = 7u32;
        let raw = GrayImage::from_fn(w, h, |x, y| {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            let n = (seed % 7) as i32 - 3;
            let fish = x < 12 && (50..70).contains(&y);
            image::Luma([if fish { 200 } else { (40 + n) as u8 }])
        });
        let (l, _) = rect.rectify_pair(&raw, &raw).unwrap();
        let mirrored = rect.left_map.apply(&raw).unwrap();
        let map = rect.left.float_map();
        let (mut fill, mut sum, mut same) = (0usize, 0f64, 0usize);
        for (i, p) in l.pixels().enumerate() {
            let (sx, sy) = (map.map_x[i], map.map_y[i]);
            let has_source = sx >= 0.0 && sy >= 0.0 && sx <= (w - 1) as f32 && sy <= (h - 1) as f32;
            if has_source {
                same += usize::from(p[0] == mirrored.as_raw()[i]);
                continue;
            }
            fill += 1;
            sum += p[0] as f64;
            assert!(
                p[0] < 60,
                "the fish is mirrored into the fill at {i}: {}",
                p[0]
            );
        }
        // the sourced pixels are the remap's; the fill is water
        assert_eq!(same, (l.width() * l.height()) as usize - fill);
        assert!(fill > 1000, "{fill}");
        let mean = sum / fill as f64;
        assert!((mean - 40.0).abs() < 2.0, "{mean}");
        // the mirror put the fish into the fill
        assert!((0..mirrored.as_raw().len()).any(|i| {
            let (sx, sy) = (map.map_x[i], map.map_y[i]);
            !(sx >= 0.0 && sy >= 0.0 && sx <= (w - 1) as f32 && sy <= (h - 1) as f32)
                && mirrored.as_raw()[i] > 100
        }));
    }

    #[test]
    fn exact_undistortion_inverts_distortion() {
        let k = [-0.3, 0.12, 0.0015, -0.0007, -0.02, -0.1, 0.03, 0.002];
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4), (0.1, 0.6)] {
            let (xd, yd) = distort(&k, x, y);
            let (ux, uy) = undistort_exact(&k, xd, yd).unwrap();
            assert!((ux - x).abs() < 1e-12 && (uy - y).abs() < 1e-12);
        }
    }
}
