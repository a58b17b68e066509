//! Rendering one raw (distorted, unrectified) view of one frame.
//!
//! Fish are drawn by projecting the 3-D body through the distorted camera
//! model, so both views are geometrically consistent: the bent midline is
//! sampled ([`SPINE_SAMPLES`] points); each sample carries a small 3-D
//! ellipsoid (semi-axes along the tangent, dorsal and lateral directions);
//! its outline is projected with the local Jacobian of the camera model
//! (an exact affine projection of the ellipsoid, accurate because each
//! ellipsoid is small against its range), and the union of the projected
//! ellipses is the silhouette. A depth buffer (front-surface depth) decides
//! which fish owns a pixel, so crossing fish occlude each other and the
//! truth's visible area is what is really drawn.
//!
//! Pixel value: dark level, plus strobe gain × vignetting × (backscatter
//! glow, plus either the fish's shaded, textured body or the trawl mesh
//! behind it), plus debris and marine snow; then optical blur, then shot
//! and read noise, rounded to 8 bits.

use nalgebra::Vector3;
use rand::RngCore;

use super::fish::{FishPose, FishSpec, SPINE_SAMPLES};
use super::rig::Cam;
use super::scene::{snow, MeshFrame};
use super::seed::{rng, value_noise, Stream};
use super::Haul;

/// What one fish looks like in one rendered view.
#[derive(Debug, Clone, PartialEq)]
pub struct FishView {
    /// Index of the fish in [`Haul::fish`].
    pub fish: usize,
    /// Visible (unoccluded, inside the frame) area, pixels.
    pub area: u64,
    /// Pixel box of the visible part, `[x0, y0, x1, y1]` inclusive.
    pub bbox: Option<[u32; 4]>,
    /// Area of the whole silhouette, ignoring occlusion and the frame border.
    pub full_area: u64,
    /// The whole silhouette lies inside the frame.
    pub inside: bool,
}

/// A rendered view.
#[derive(Debug, Clone)]
pub struct View {
    /// 8-bit grey pixels, row-major, `width × height`.
    pub pixels: Vec<u8>,
    /// Every fish whose silhouette touched the view (area may be 0 when it
    /// is wholly outside or occluded).
    pub fish: Vec<FishView>,
}

/// Per-camera smooth fields on a coarse grid of nodes, bilinearly
/// interpolated per pixel: backscatter glow, vignetting, and the point of
/// the mesh plane seen through the pixel.
#[derive(Debug, Clone)]
pub struct CamGrid {
    step: usize,
    nx: usize,
    nodes: Vec<[f32; 4]>,
}

impl CamGrid {
    /// Builds the grid of `cam` (backscatter not yet normalised).
    pub fn new(haul_rig: &super::rig::Rig, look: &super::scene::Look, cam: Cam) -> CamGrid {
        let w = haul_rig.width as usize;
        let h = haul_rig.height as usize;
        let step = if w >= 1024 { 16 } else { (w / 64).max(4) };
        let nx = w.div_ceil(step) + 1;
        let ny = h.div_ceil(step) + 1;
        let camera = haul_rig.camera(cam);
        let origin = haul_rig.centre(cam);
        let z_net = look.mesh.z_net;
        let mut nodes = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = camera.undistort((i * step) as f64, (j * step) as f64);
                let d = haul_rig.ray_dir(cam, x, y);
                let vig = (1.0 / (1.0 + x * x + y * y)).powf(0.5 * look.vignette);
                let bs = look.backscatter_along(&origin, &d.normalize());
                let lam = (z_net - origin.z) / d.z;
                nodes.push([
                    bs as f32,
                    vig as f32,
                    (origin.x + lam * d.x) as f32,
                    (origin.y + lam * d.y) as f32,
                ]);
            }
        }
        CamGrid { step, nx, nodes }
    }

    /// Largest backscatter value on the grid.
    pub fn max_backscatter(&self) -> f32 {
        self.nodes.iter().map(|n| n[0]).fold(0.0, f32::max)
    }

    /// Divides the backscatter channel by `m` and raises it to `gamma`.
    pub fn normalise_backscatter(&mut self, m: f32, gamma: f32) {
        for n in &mut self.nodes {
            n[0] = (n[0] / m.max(1e-12)).powf(gamma);
        }
    }

    #[inline]
    fn sample(&self, i: usize, j: usize) -> [f32; 4] {
        let (gi, gj) = (i / self.step, j / self.step);
        let fx = (i % self.step) as f32 / self.step as f32;
        let fy = (j % self.step) as f32 / self.step as f32;
        let k = gj * self.nx + gi;
        let (a, b, c, d) = (
            self.nodes[k],
            self.nodes[k + 1],
            self.nodes[k + self.nx],
            self.nodes[k + self.nx + 1],
        );
        let mut out = [0.0; 4];
        for ch in 0..4 {
            let top = a[ch] + (b[ch] - a[ch]) * fx;
            let bot = c[ch] + (d[ch] - c[ch]) * fx;
            out[ch] = top + (bot - top) * fy;
        }
        out
    }
}

/// One projected body ellipse.
struct Ell {
    px: f64,
    py: f64,
    inv: [f64; 3],
    binv: Option<[f64; 4]>,
    hx: f64,
    hy: f64,
    z: f64,
    w: f64,
    s: f64,
    a: f64,
}

/// Per-pixel fish ownership of a view.
struct Owners {
    depth: Vec<f32>,
    owner: Vec<u16>,
    s: Vec<f32>,
    q: Vec<f32>,
    un: Vec<f32>,
}

fn ellipses(haul: &Haul, cam: Cam, spec: &FishSpec, pose: &FishPose) -> Vec<Ell> {
    let rig = &haul.rig;
    let camera = rig.camera(cam);
    let l = spec.length_mm;
    let sp = pose.spine(spec, SPINE_SAMPLES);
    let ds = l / (SPINE_SAMPLES - 1) as f64;
    let a_nom = 3.5 * ds;
    let mut out = Vec::with_capacity(sp.len());
    for smp in &sp {
        let x = smp.s / l;
        let h = spec.half_depth(x);
        let w = spec.half_width(x);
        let a = a_nom.min(smp.s).min(l - smp.s);
        let pc = rig.to_cam(cam, &smp.p);
        if pc.z < 100.0 {
            continue;
        }
        let Some((px, py)) = camera.project(&pc) else {
            continue;
        };
        let delta = 0.5;
        let jac = |e: &Vector3<f64>| -> Option<(f64, f64)> {
            let p1 = rig.project(cam, &(smp.p + e * delta))?;
            let p0 = rig.project(cam, &(smp.p - e * delta))?;
            Some(((p1.0 - p0.0) / (2.0 * delta), (p1.1 - p0.1) / (2.0 * delta)))
        };
        let lat = smp.tangent.cross(&smp.dorsal);
        let (Some(jt), Some(jd), Some(jl)) = (jac(&smp.tangent), jac(&smp.dorsal), jac(&lat))
        else {
            continue;
        };
        let c1 = (jt.0 * a, jt.1 * a);
        let c2 = (jd.0 * h, jd.1 * h);
        let c3 = (jl.0 * w, jl.1 * w);
        let s00 = c1.0 * c1.0 + c2.0 * c2.0 + c3.0 * c3.0;
        let s01 = c1.0 * c1.1 + c2.0 * c2.1 + c3.0 * c3.1;
        let s11 = c1.1 * c1.1 + c2.1 * c2.1 + c3.1 * c3.1;
        let det = s00 * s11 - s01 * s01;
        if det < 1e-6 {
            continue;
        }
        let detb = c1.0 * c2.1 - c2.0 * c1.1;
        let binv = if detb.abs() > 1e-9 {
            Some([c2.1 / detb, -c2.0 / detb, -c1.1 / detb, c1.0 / detb])
        } else {
            None
        };
        out.push(Ell {
            px,
            py,
            inv: [s11 / det, -s01 / det, s00 / det],
            binv,
            hx: s00.sqrt(),
            hy: s11.sqrt(),
            z: pc.z,
            w,
            s: smp.s,
            a,
        });
    }
    out
}

/// Rasterises one fish into the owner buffers; returns its whole
/// silhouette's area and whether it lies inside the frame.
fn rasterise(
    ells: &[Ell],
    k: u16,
    l: f64,
    width: usize,
    height: usize,
    own: &mut Owners,
) -> (u64, bool) {
    if ells.is_empty() {
        return (0, false);
    }
    let mut bx0 = i64::MAX;
    let mut by0 = i64::MAX;
    let mut bx1 = i64::MIN;
    let mut by1 = i64::MIN;
    for e in ells {
        bx0 = bx0.min((e.px - e.hx).ceil() as i64);
        bx1 = bx1.max((e.px + e.hx).floor() as i64);
        by0 = by0.min((e.py - e.hy).ceil() as i64);
        by1 = by1.max((e.py + e.hy).floor() as i64);
    }
    if bx1 < bx0 || by1 < by0 {
        return (0, false);
    }
    let mw = (bx1 - bx0 + 1) as usize;
    let mh = (by1 - by0 + 1) as usize;
    // A fish cannot be larger than a few frames; refuse absurd boxes.
    if mw > 8 * width || mh > 8 * height {
        return (0, false);
    }
    let mut mask = vec![false; mw * mh];
    for e in ells {
        let x0 = (e.px - e.hx).ceil() as i64;
        let x1 = (e.px + e.hx).floor() as i64;
        let y0 = (e.py - e.hy).ceil() as i64;
        let y1 = (e.py + e.hy).floor() as i64;
        for y in y0..=y1 {
            let dy = y as f64 - e.py;
            let in_rows = y >= 0 && (y as usize) < height;
            let mrow = ((y - by0) as usize) * mw;
            for x in x0..=x1 {
                let dx = x as f64 - e.px;
                let q = e.inv[0] * dx * dx + 2.0 * e.inv[1] * dx * dy + e.inv[2] * dy * dy;
                if q > 1.0 {
                    continue;
                }
                mask[mrow + (x - bx0) as usize] = true;
                if !in_rows || x < 0 || x as usize >= width {
                    continue;
                }
                let idx = y as usize * width + x as usize;
                let depth = (e.z - e.w * (1.0 - q).sqrt()) as f32;
                if depth < own.depth[idx] {
                    let (ut, un) = match e.binv {
                        Some(b) => (b[0] * dx + b[1] * dy, b[2] * dx + b[3] * dy),
                        None => (0.0, 0.0),
                    };
                    own.depth[idx] = depth;
                    own.owner[idx] = k;
                    own.s[idx] = (e.s - ut * e.a).clamp(0.0, l) as f32;
                    own.q[idx] = q as f32;
                    own.un[idx] = un.clamp(-1.0, 1.0) as f32;
                }
            }
        }
    }
    let full = mask.iter().filter(|&&m| m).count() as u64;
    let inside = bx0 >= 0 && by0 >= 0 && bx1 < width as i64 && by1 < height as i64;
    (full, inside)
}

/// What a fish needs for shading in one view.
struct Shader<'a> {
    spec: &'a FishSpec,
    light: Vec<f32>,
    gain: f32,
}

impl Shader<'_> {
    fn signal(&self, s: f32, q: f32, un: f32) -> f32 {
        let spec = self.spec;
        let l = spec.length_mm as f32;
        let x = (s / l).clamp(0.0, 1.0);
        let fi = x * (self.light.len() - 1) as f32;
        let i0 = (fi as usize).min(self.light.len() - 2);
        let t = fi - i0 as f32;
        let light = self.light[i0] * (1.0 - t) + self.light[i0 + 1] * t;
        let fin = x >= spec.fin_start as f32;
        let edge = if fin {
            0.8
        } else {
            0.45 + 0.55 * (1.0 - q).max(0.0).sqrt()
        };
        let hd = spec.half_depth_mm as f32;
        let tm = spec.texture_mm as f32;
        let seed = spec.texture_seed;
        let amp = spec.texture_amp as f32;
        let v = un * hd;
        let mut tex = 1.0
            + amp * (2.0 * value_noise(seed, s / tm, v / tm) - 1.0)
            + 0.5 * amp * (2.0 * value_noise(seed ^ 0x55, 2.5 * s / tm, 2.5 * v / tm) - 1.0);
        if spec.bars.0 > 0.0 {
            tex += spec.bars.0 as f32 * (std::f32::consts::TAU * s / spec.bars.1 as f32).sin();
        }
        // Eye: a dark spot behind the snout, above the midline.
        let ex = (x - 0.06) * l;
        let ey = v - 0.25 * hd;
        let er = 0.14 * hd;
        if ex * ex + ey * ey < er * er {
            tex *= 0.6;
        }
        let shade = 1.0 - spec.countershade as f32 * un;
        self.gain * light * edge * shade * tex.max(0.1) * spec.reflectivity(x as f64) as f32
    }
}

/// Inverse standard normal CDF (Acklam's rational approximation).
#[allow(clippy::excessive_precision)]
fn inv_normal(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let pl = 0.02425;
    if p < pl {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - pl {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        let q = (-2.0 * (1.0 - p).ln()).sqrt();
        -(((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    }
}

/// 4096 quantiles of the standard normal: noise samples by table look-up.
fn normal_table() -> &'static [f32; 4096] {
    static TABLE: std::sync::OnceLock<[f32; 4096]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0.0f32; 4096];
        for (i, v) in t.iter_mut().enumerate() {
            *v = inv_normal((i as f64 + 0.5) / 4096.0) as f32;
        }
        t
    })
}

/// Adds a rotated Gaussian blob, depth-tested against the fish.
#[allow(clippy::too_many_arguments)]
fn splat(
    img: &mut [f32],
    own: &Owners,
    width: usize,
    height: usize,
    (cx, cy): (f64, f64),
    (s_major, s_minor, angle): (f64, f64, f64),
    amp: f32,
    z: f32,
) {
    let r = 3.0 * s_major.max(s_minor);
    let x0 = ((cx - r).floor().max(0.0)) as usize;
    let y0 = ((cy - r).floor().max(0.0)) as usize;
    let x1 = (cx + r).ceil().min(width as f64 - 1.0);
    let y1 = (cy + r).ceil().min(height as f64 - 1.0);
    if x1 < 0.0 || y1 < 0.0 || x0 as f64 > x1 || y0 as f64 > y1 {
        return;
    }
    let (sn, cs) = angle.sin_cos();
    let (ia, ib) = (1.0 / (s_major * s_major), 1.0 / (s_minor * s_minor));
    for y in y0..=(y1 as usize) {
        let dy = y as f64 - cy;
        for x in x0..=(x1 as usize) {
            let dx = x as f64 - cx;
            let u = dx * cs + dy * sn;
            let v = -dx * sn + dy * cs;
            let e = 0.5 * (u * u * ia + v * v * ib);
            if e > 4.5 {
                continue;
            }
            let idx = y * width + x;
            if own.depth[idx] > z {
                img[idx] += amp * (-e as f32).exp();
            }
        }
    }
}

/// Separable Gaussian blur of σ pixels, in place.
fn blur(img: &mut [f32], width: usize, height: usize, sigma: f64) {
    if sigma < 0.3 {
        return;
    }
    let r = (2.5 * sigma).ceil() as usize;
    let mut k: Vec<f32> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-0.5 * d * d / (sigma * sigma)).exp() as f32
        })
        .collect();
    let sum: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= sum);
    let mut tmp = vec![0.0f32; img.len()];
    for y in 0..height {
        let row = &img[y * width..(y + 1) * width];
        let out = &mut tmp[y * width..(y + 1) * width];
        for (x, o) in out.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (i, kv) in k.iter().enumerate() {
                let xx = (x + i).saturating_sub(r).min(width - 1);
                acc += kv * row[xx];
            }
            *o = acc;
        }
    }
    for y in 0..height {
        for x in 0..width {
            let mut acc = 0.0;
            for (i, kv) in k.iter().enumerate() {
                let yy = (y + i).saturating_sub(r).min(height - 1);
                acc += kv * tmp[yy * width + x];
            }
            img[y * width + x] = acc;
        }
    }
}

/// Renders `cam`'s view of `frame` (1-based).
pub fn render_view(haul: &Haul, frame: u32, cam: Cam) -> View {
    let rig = &haul.rig;
    let look = &haul.look;
    let width = rig.width as usize;
    let height = rig.height as usize;
    let n = width * height;
    let sc = width as f64 / 2048.0;
    let mf: &MeshFrame = &haul.mesh_frames[(frame - 1) as usize];
    let g = mf.gain as f32;
    let camera = rig.camera(cam);

    let mut own = Owners {
        depth: vec![f32::INFINITY; n],
        owner: vec![0; n],
        s: vec![0.0; n],
        q: vec![0.0; n],
        un: vec![0.0; n],
    };
    // Fish, in haul order (deterministic ties).
    let mut views = Vec::new();
    let mut shaders = Vec::new();
    for (fi, life) in haul.fish.iter().enumerate() {
        let Some(pose) = life.pose(frame as i64) else {
            continue;
        };
        let ells = ellipses(haul, cam, &life.spec, pose);
        let k = (views.len() + 1) as u16;
        let (full, inside) = rasterise(&ells, k, life.spec.length_mm, width, height, &mut own);
        let sp = pose.spine(&life.spec, 33);
        shaders.push(Shader {
            spec: &life.spec,
            light: sp.iter().map(|s| look.light(&s.p) as f32).collect(),
            gain: haul.fish_gain[fi] as f32,
        });
        views.push(FishView {
            fish: fi,
            area: 0,
            bbox: None,
            full_area: full,
            inside,
        });
    }

    // Base image.
    let grid = &haul.grids[cam.index()];
    let tx = rig.half_fov_tan();
    let ty = 0.5 * rig.height as f64 / rig.left.fy;
    let mut img = vec![0.0f32; n];
    let mut vig_img = vec![0.0f32; n];
    for y in 0..height {
        for x in 0..width {
            let idx = y * width + x;
            let [bs, vig, mx, my] = grid.sample(x, y);
            let o = own.owner[idx];
            let content = if o > 0 {
                let v = &mut views[(o - 1) as usize];
                v.area += 1;
                v.bbox = Some(match v.bbox {
                    None => [x as u32, y as u32, x as u32, y as u32],
                    Some([a, b, c, d]) => [
                        a.min(x as u32),
                        b.min(y as u32),
                        c.max(x as u32),
                        d.max(y as u32),
                    ],
                });
                shaders[(o - 1) as usize].signal(own.s[idx], own.q[idx], own.un[idx])
            } else {
                look.mesh.value(mf, mx as f64, my as f64, tx, ty) * (0.6 + 0.4 * bs.min(1.0))
            };
            img[idx] = g * vig * (look.backscatter as f32 * bs + content);
            vig_img[idx] = vig;
        }
    }

    // Debris blobs.
    let f = camera.fx;
    for d in &haul.debris {
        let Some(p) = d.at(frame as i64) else {
            continue;
        };
        let pc = rig.to_cam(cam, p);
        let Some(c) = camera.project(&pc) else {
            continue;
        };
        let s_minor = f * d.radius_mm / pc.z;
        let amp = d.contrast as f32 * g * vig_at(&vig_img, width, height, c);
        splat(
            &mut img,
            &own,
            width,
            height,
            c,
            (s_minor * d.shape.0, s_minor, d.shape.1),
            amp,
            pc.z as f32,
        );
    }
    // Marine snow.
    for pt in snow(haul.config.seed, look, rig, frame) {
        let pc = rig.to_cam(cam, &pt.p);
        let Some(c) = camera.project(&pc) else {
            continue;
        };
        let focus = (f * pt.radius_mm / pc.z).max(0.5 * sc);
        let defocus = (6.0 * sc * (2000.0 / pc.z - 1.0).abs()).min(25.0 * sc);
        let sigma = focus + defocus;
        let amp = (look.snow.1 * pt.brightness * look.light(&pt.p) * (focus / sigma).powi(2))
            .min(120.0) as f32
            * g
            * vig_at(&vig_img, width, height, c);
        splat(
            &mut img,
            &own,
            width,
            height,
            c,
            (sigma, sigma, 0.0),
            amp,
            pc.z as f32,
        );
    }

    blur(&mut img, width, height, look.blur_2048 * sc);

    // Noise and quantisation, one generator per row.
    let table = normal_table();
    let mut pixels = vec![0u8; n];
    let dark = look.dark as f32;
    let read2 = (look.read_noise * look.read_noise) as f32;
    let shot = look.shot_noise as f32;
    for y in 0..height {
        let mut r = rng(
            haul.config.seed,
            Stream::Noise,
            frame as u64 * 2 + cam.index() as u64,
            y as u64,
        );
        for x in 0..width {
            let idx = y * width + x;
            let signal = img[idx].max(0.0);
            let sd = (read2 + shot * signal).sqrt();
            let z = table[(r.next_u32() >> 20) as usize];
            pixels[idx] = (dark + signal + sd * z).round().clamp(0.0, 255.0) as u8;
        }
    }
    View {
        pixels,
        fish: views,
    }
}

fn vig_at(vig: &[f32], width: usize, height: usize, (x, y): (f64, f64)) -> f32 {
    let xi = (x.round().max(0.0) as usize).min(width - 1);
    let yi = (y.round().max(0.0) as usize).min(height - 1);
    vig[yi * width + xi]
}
