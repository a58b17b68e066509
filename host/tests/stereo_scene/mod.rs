//! Rendered synthetic rectified stereo pairs for the stereo/length tests:
//! textured fish (elliptic body + fan tail, optionally dim) at known 3-D
//! head/tail points on a noisy background, and the segmentation masks a
//! segmenter would produce (body only, or body + tail).
#![allow(dead_code)]

use fishtrack_core::object::{Object, Objects, OrientedBox, Run, RunSpan, HIST_BINS};
use fishtrack_core::{Roi, StereoGeometry};

/// Capacity of test object lists.
pub const N: usize = 16;
/// Run capacity of test object lists.
pub const R: usize = 8192;

pub type Objs = Objects<N, R>;

/// One fish in 3-D (mm, rectified left camera frame).
#[derive(Debug, Clone, Copy)]
pub struct Fish {
    pub head: [f64; 3],
    pub tail: [f64; 3],
    /// Body height, mm.
    pub height: f64,
    /// Grey level of the tail fin (body ≈ 120, background ≈ 30).
    pub tail_grey: f64,
    /// Texture seed.
    pub seed: u32,
    /// Body texture amplitude, grey levels (35 by default; a few for the
    /// smooth, low-contrast bodies of the synthetic hauls).
    pub texture: f64,
}

impl Fish {
    pub fn length(&self) -> f64 {
        let d: Vec<f64> = (0..3).map(|i| self.head[i] - self.tail[i]).collect();
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }
}

pub struct Scene {
    pub w: usize,
    pub h: usize,
    pub f: f64,
    pub cx: f64,
    pub cy: f64,
    pub baseline: f64,
    pub noise: f64,
    pub seed: u64,
}

impl Scene {
    pub fn new(w: usize, h: usize) -> Self {
        Scene {
            w,
            h,
            f: 1000.0,
            cx: w as f64 / 2.0 - 0.5,
            cy: h as f64 / 2.0 - 0.5,
            baseline: 200.0,
            noise: 4.0,
            seed: 7,
        }
    }

    pub fn geometry(&self) -> StereoGeometry {
        StereoGeometry {
            f: self.f as f32,
            cx: self.cx as f32,
            cy: self.cy as f32,
            cx_right: self.cx as f32,
            baseline_mm: self.baseline as f32,
        }
    }

    /// Left-view pixel and disparity of a 3-D point.
    pub fn project(&self, p: [f64; 3]) -> (f64, f64, f64) {
        (
            self.f * p[0] / p[2] + self.cx,
            self.f * p[1] / p[2] + self.cy,
            self.f * self.baseline / p[2],
        )
    }
}

fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846ca68b);
    x ^= x >> 16;
    x
}

/// Value noise in [−1, 1] on a 3-pixel lattice of body coordinates.
fn texture(seed: u32, a: f64, b: f64) -> f64 {
    let (ga, gb) = (a / 3.0, b / 3.0);
    let (ia, ib) = (ga.floor(), gb.floor());
    let (fa, fb) = (ga - ia, gb - ib);
    let v = |i: i64, j: i64| -> f64 {
        let h = hash(
            seed ^ hash((i as u32).wrapping_mul(0x9e3779b9) ^ (j as u32).wrapping_mul(0x85ebca6b)),
        );
        (h & 0xffff) as f64 / 32767.5 - 1.0
    };
    let (i, j) = (ia as i64, ib as i64);
    let top = v(i, j) * (1.0 - fa) + v(i + 1, j) * fa;
    let bot = v(i, j + 1) * (1.0 - fa) + v(i + 1, j + 1) * fa;
    top * (1.0 - fb) + bot * fb
}

/// Gaussian-ish noise from a hash (sum of 4 uniforms).
fn noise(seed: u64, x: usize, y: usize, view: u32) -> f64 {
    let mut s = 0.0;
    for k in 0..4u32 {
        let h = hash((seed as u32) ^ hash(x as u32 ^ hash(y as u32 ^ hash(view * 7 + k))));
        s += (h & 0xffff) as f64 / 65535.0 - 0.5;
    }
    s * (12.0f64 / 4.0).sqrt()
}

/// Where a pixel lies on a fish in one view: (on body, on tail, grey).
fn shade(
    fish: &Fish,
    p0: (f64, f64),
    p1: (f64, f64),
    half_h: f64,
    len_px: f64,
    x: f64,
    y: f64,
) -> Option<(bool, f64)> {
    let (ax, ay) = (p1.0 - p0.0, p1.1 - p0.1);
    let l2 = ax * ax + ay * ay;
    if l2 < 1e-9 {
        return None;
    }
    let s = ((x - p0.0) * ax + (y - p0.1) * ay) / l2;
    let v = ((x - p0.0) * ay - (y - p0.1) * ax) / l2.sqrt() / half_h;
    if !(0.0..=1.0).contains(&s) {
        return None;
    }
    let tex = texture(fish.seed, s * len_px, v * half_h);
    // body: ellipse over s ∈ [0, 0.8]
    let e = (s - 0.4) / 0.4;
    if e.abs() <= 1.0 && v.abs() <= (1.0 - e * e).sqrt() {
        return Some((true, 120.0 + fish.texture * tex - 25.0 * v.abs()));
    }
    // tail fan over s ∈ [0.78, 1]
    if s >= 0.78 && v.abs() <= 0.15 + 0.55 * (s - 0.78) / 0.22 {
        let c = fish.tail_grey;
        return Some((false, c + (c - 30.0) * 0.25 * tex));
    }
    None
}

pub struct Rendered {
    pub left: Vec<u8>,
    pub right: Vec<u8>,
    /// Per fish: (left body mask, left full mask, right body mask, right full mask).
    pub masks: Vec<[Vec<bool>; 4]>,
}

pub fn render(sc: &Scene, fish: &[Fish]) -> Rendered {
    let (w, h) = (sc.w, sc.h);
    let mut img = [vec![0f64; w * h], vec![0f64; w * h]];
    for (v, im) in img.iter_mut().enumerate() {
        for y in 0..h {
            for x in 0..w {
                im[y * w + x] = 30.0 + 3.0 * ((x as f64 * 0.02).sin() + (y as f64 * 0.015).cos());
                let _ = v;
            }
        }
    }
    let mut masks = Vec::new();
    // far fish first
    let mut order: Vec<usize> = (0..fish.len()).collect();
    order.sort_by(|&a, &b| {
        let za = fish[a].head[2] + fish[a].tail[2];
        let zb = fish[b].head[2] + fish[b].tail[2];
        zb.partial_cmp(&za).unwrap()
    });
    let mut all: Vec<Option<[Vec<bool>; 4]>> = vec![None; fish.len()];
    for &k in &order {
        let fsh = &fish[k];
        let (hx, hy, hd) = sc.project(fsh.head);
        let (tx, ty, td) = sc.project(fsh.tail);
        let zm = 0.5 * (fsh.head[2] + fsh.tail[2]);
        let half_h = sc.f * fsh.height * 0.5 / zm;
        let mut m: [Vec<bool>; 4] = [
            vec![false; w * h],
            vec![false; w * h],
            vec![false; w * h],
            vec![false; w * h],
        ];
        for view in 0..2 {
            let (p0, p1) = if view == 0 {
                ((hx, hy), (tx, ty))
            } else {
                ((hx - hd, hy), (tx - td, ty))
            };
            // texture coordinates from the left view's length, so a physical
            // point carries the same texture in both views
            let len_px = ((tx - hx).powi(2) + (ty - hy).powi(2)).sqrt();
            let x0 = (p0.0.min(p1.0) - half_h - 2.0).floor().max(0.0) as usize;
            let x1 = (p0.0.max(p1.0) + half_h + 2.0)
                .ceil()
                .min(w as f64 - 1.0)
                .max(0.0) as usize;
            let y0 = (p0.1.min(p1.1) - half_h - 2.0).floor().max(0.0) as usize;
            let y1 = (p0.1.max(p1.1) + half_h + 2.0)
                .ceil()
                .min(h as f64 - 1.0)
                .max(0.0) as usize;
            if x0 >= w || y0 >= h {
                continue;
            }
            for y in y0..=y1 {
                for x in x0..=x1 {
                    if let Some((body, g)) = shade(fsh, p0, p1, half_h, len_px, x as f64, y as f64)
                    {
                        img[view][y * w + x] = g;
                        m[view * 2 + 1][y * w + x] = true;
                        if body {
                            m[view * 2][y * w + x] = true;
                        }
                    }
                }
            }
        }
        all[k] = Some(m);
    }
    // nearer fish hide farther ones: remove occluded mask pixels
    for (i, &k) in order.iter().enumerate() {
        for &k2 in &order[i + 1..] {
            let (a, b) = (all[k].clone().unwrap(), all[k2].as_ref().unwrap());
            let mut a = a;
            for view in 0..2 {
                for p in 0..w * h {
                    if b[view * 2 + 1][p] {
                        a[view * 2][p] = false;
                        a[view * 2 + 1][p] = false;
                    }
                }
            }
            all[k] = Some(a);
        }
    }
    for m in all {
        masks.push(m.unwrap());
    }
    let to_u8 = |im: &Vec<f64>, view: u32| -> Vec<u8> {
        im.iter()
            .enumerate()
            .map(|(p, v)| {
                (v + sc.noise * noise(sc.seed, p % w, p / w, view))
                    .round()
                    .clamp(0.0, 255.0) as u8
            })
            .collect()
    };
    Rendered {
        left: to_u8(&img[0], 0),
        right: to_u8(&img[1], 1),
        masks,
    }
}

/// Adds one object (statistics as segmentation computes them) from a mask.
pub fn push_object(objs: &mut Objs, img: &[u8], mask: &[bool], w: usize, h: usize) {
    let start = objs.runs.len() as u32;
    let (mut n, mut sx, mut sy) = (0f64, 0f64, 0f64);
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    let mut sum = 0f64;
    let mut sum2 = 0f64;
    let mut hist = [0u32; HIST_BINS];
    for y in 0..h {
        let mut x = 0;
        while x < w {
            if mask[y * w + x] {
                let a = x;
                while x < w && mask[y * w + x] {
                    let g = img[y * w + x] as f64;
                    n += 1.0;
                    sx += x as f64;
                    sy += y as f64;
                    sum += g;
                    sum2 += g * g;
                    hist[img[y * w + x] as usize >> 4] += 1;
                    x += 1;
                }
                objs.runs
                    .push(Run {
                        y: y as u16,
                        x0: a as u16,
                        x1: x as u16,
                    })
                    .unwrap();
                x0 = x0.min(a);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y + 1);
            } else {
                x += 1;
            }
        }
    }
    if n == 0.0 {
        return;
    }
    let (mx, my) = (sx / n, sy / n);
    let (mut c20, mut c02, mut c11) = (0.0, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            if mask[y * w + x] {
                let (dx, dy) = (x as f64 - mx, y as f64 - my);
                c20 += dx * dx;
                c02 += dy * dy;
                c11 += dx * dy;
            }
        }
    }
    let ang = 0.5 * (2.0 * c11).atan2(c20 - c02);
    let (ux, uy) = (ang.cos(), ang.sin());
    let (mut tmin, mut tmax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for y in 0..h {
        for x in 0..w {
            if mask[y * w + x] {
                let (dx, dy) = (x as f64 - mx, y as f64 - my);
                let t = dx * ux + dy * uy;
                let v = -dx * uy + dy * ux;
                tmin = tmin.min(t);
                tmax = tmax.max(t);
                vmin = vmin.min(v);
                vmax = vmax.max(v);
            }
        }
    }
    let tc = 0.5 * (tmin + tmax);
    let vc = 0.5 * (vmin + vmax);
    let obb = OrientedBox {
        cx: (mx + tc * ux - vc * uy) as f32,
        cy: (my + tc * uy + vc * ux) as f32,
        half_w: (0.5 * (tmax - tmin) + 0.5) as f32,
        half_h: (0.5 * (vmax - vmin) + 0.5) as f32,
        angle: ang as f32,
    };
    let mean = sum / n;
    let var = (sum2 - n * mean * mean) / (n - 1.0).max(1.0);
    let o = Object {
        bbox: Roi::new(x0 as u32, y0 as u32, (x1 - x0) as u32, (y1 - y0) as u32),
        obb,
        area: n as u32,
        mean: mean as f32,
        variance: var as f32,
        hist,
        runs: RunSpan {
            start,
            len: objs.runs.len() as u32 - start,
        },
        level: 0,
    };
    objs.items.push(o).unwrap();
}

/// Fish with head at `(x, y, z)` mm, pointing along `dir` (unit-ish), of 3-D length `len`.
pub fn fish_at(x: f64, y: f64, z: f64, dir: [f64; 3], len: f64, tail_grey: f64, seed: u32) -> Fish {
    let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    Fish {
        head: [x, y, z],
        tail: [
            x + len * dir[0] / n,
            y + len * dir[1] / n,
            z + len * dir[2] / n,
        ],
        height: len * 0.22,
        tail_grey,
        seed,
        texture: 35.0,
    }
}
