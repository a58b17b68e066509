//! Everything in a synthetic frame that is not a fish: LED strobe
//! illumination with distance fall-off and water attenuation, backscatter
//! glow, lens vignetting, the drifting trawl mesh in the top and bottom
//! bands (paper Section V.A: "white diagonal grids spreading over the top
//! and bottom regions … its drift with the current makes background
//! modelling ineffective"), smooth low-variance debris blobs, marine snow,
//! sensor noise levels and per-frame strobe flicker. All randomised per
//! haul ([`Look::random`]).

use nalgebra::Vector3;
use rand::Rng;

use super::rig::Rig;
use super::seed::{normal, poisson, rng, Stream};

/// One LED strobe.
#[derive(Debug, Clone, PartialEq)]
pub struct Strobe {
    /// Position, left frame, mm.
    pub pos: Vector3<f64>,
    /// Unit beam axis.
    pub dir: Vector3<f64>,
    /// Relative power.
    pub power: f64,
    /// Beam exponent: intensity ∝ cos^m of the off-axis angle.
    pub exponent: f64,
}

/// The trawl mesh: a net panel on a plane `Z = z_net` behind the fish,
/// seen in bands at the top and bottom of the frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshLook {
    /// Depth of the net plane, mm.
    pub z_net: f64,
    /// Mesh spacing, mm.
    pub spacing_mm: f64,
    /// Twine half width, mm.
    pub twine_mm: f64,
    /// Grey-level brightness of a twine.
    pub amp: f64,
    /// Angle of the first line family (≈ 45°: diagonal lines).
    pub angle: f64,
    /// Top and bottom band heights, fractions of the frame height.
    pub bands: (f64, f64),
    /// Band-edge wobble amplitude (fraction of the half height) and wavelength (of the half width).
    pub edge_wave: (f64, f64),
    /// Band-edge curvature (sagging net).
    pub curvature: f64,
    /// Mean drift per frame, mm, in the two line coordinates.
    pub drift: (f64, f64),
    /// Wave on the net: amplitude and wavelength, mm, and phase speed per frame.
    pub wave: (f64, f64, f64),
}

/// The mesh's state in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshFrame {
    /// Offsets of the two line families, mm.
    pub off: (f64, f64),
    /// Phase of the wave on the net.
    pub wave_phase: f64,
    /// Phase of the band-edge wobble.
    pub edge_phase: f64,
    /// Strobe gain of the frame (flicker).
    pub gain: f64,
}

/// The haul-wide look: lights, water, noise, mesh, debris and snow levels.
#[derive(Debug, Clone, PartialEq)]
pub struct Look {
    /// Dark level of the sensor, grey levels.
    pub dark: f64,
    /// Backscatter glow at its brightest, grey levels.
    pub backscatter: f64,
    /// Exponent applied to the normalised glow (> 1: a more uneven light).
    pub glow_gamma: f64,
    /// The strobes.
    pub strobes: Vec<Strobe>,
    /// Water attenuation, per metre.
    pub attenuation: f64,
    /// Vignetting exponent: cos^n of the ray angle.
    pub vignette: f64,
    /// Read noise σ, grey levels.
    pub read_noise: f64,
    /// Shot noise: variance per grey level of signal.
    pub shot_noise: f64,
    /// Optical blur σ in pixels of a 2048 frame.
    pub blur_2048: f64,
    /// Marine-snow particles per frame and their brightness.
    pub snow: (f64, f64),
    /// Debris blobs entering per frame, and their contrast range.
    pub debris: (f64, (f64, f64)),
    /// Per-frame strobe flicker, σ of the log gain.
    pub flicker: f64,
    /// The trawl mesh.
    pub mesh: MeshLook,
    /// Normaliser: light at 1.5 m on the axis becomes 1.
    light_ref: f64,
}

impl Look {
    /// A random look for a rig.
    pub fn random<R: Rng>(rng: &mut R, rig: &Rig) -> Look {
        let n_strobes = if rng.random_bool(0.7) { 2 } else { 3 };
        let mut strobes = Vec::new();
        for k in 0..n_strobes {
            let side = if k % 2 == 0 { -1.0 } else { 1.0 };
            let pos = Vector3::new(
                side * rng.random_range(250.0..700.0) + rig.baseline() * 0.5,
                rng.random_range(-450.0..450.0),
                rng.random_range(-100.0..200.0),
            );
            let dir = Vector3::new(
                rng.random_range(-0.3..0.3) - side * 0.1,
                rng.random_range(-0.3..0.3),
                1.0,
            )
            .normalize();
            strobes.push(Strobe {
                pos,
                dir,
                power: rng.random_range(0.5..1.4),
                exponent: rng.random_range(1.5..7.0),
            });
        }
        let f2048 = rig.left.fx * 2048.0 / rig.width as f64;
        let z_net = rng.random_range(3500.0..5500.0);
        let px_to_mm = z_net / f2048;
        let spacing_mm = rng.random_range(45.0..130.0) * px_to_mm;
        let mesh = MeshLook {
            z_net,
            spacing_mm,
            twine_mm: (rng.random_range(0.8..1.8) * rig.width as f64 / 2048.0).max(0.6) * z_net
                / rig.left.fx,
            amp: rng.random_range(40.0..110.0),
            angle: std::f64::consts::FRAC_PI_4 + rng.random_range(-0.2..0.2),
            bands: (rng.random_range(0.1..0.22), rng.random_range(0.1..0.22)),
            edge_wave: (rng.random_range(0.0..0.08), rng.random_range(0.5..2.0)),
            curvature: rng.random_range(-0.15..0.25),
            drift: (
                rng.random_range(-0.4..0.4) * spacing_mm,
                rng.random_range(-0.4..0.4) * spacing_mm,
            ),
            wave: (
                rng.random_range(0.0..0.12) * spacing_mm,
                rng.random_range(3.0..10.0) * spacing_mm,
                rng.random_range(0.3..1.5),
            ),
        };
        let mut look = Look {
            dark: rng.random_range(5.0..14.0),
            backscatter: rng.random_range(30.0..75.0),
            glow_gamma: rng.random_range(1.2..2.5),
            strobes,
            attenuation: rng.random_range(0.15..0.5),
            vignette: rng.random_range(1.0..3.0),
            read_noise: rng.random_range(1.2..3.2),
            shot_noise: rng.random_range(0.03..0.15),
            blur_2048: rng.random_range(0.6..1.1),
            snow: (rng.random_range(150.0..900.0), rng.random_range(20.0..70.0)),
            debris: (
                rng.random_range(0.3..1.0),
                (4.0, rng.random_range(8.0..14.0)),
            ),
            flicker: rng.random_range(0.02..0.08),
            mesh,
            light_ref: 1.0,
        };
        look.light_ref = look.raw_light(&Vector3::new(0.0, 0.0, 1500.0));
        look
    }

    fn irradiance(&self, p: &Vector3<f64>) -> f64 {
        let mut e = 0.0;
        for s in &self.strobes {
            let d = p - s.pos;
            let dist = d.norm().max(50.0);
            let c = (d.dot(&s.dir) / dist).max(0.0);
            e += s.power * c.powf(s.exponent) / (dist * dist * 1e-6)
                * (-self.attenuation * dist * 1e-3).exp();
        }
        e
    }

    fn raw_light(&self, p: &Vector3<f64>) -> f64 {
        self.irradiance(p) * (-self.attenuation * p.norm() * 1e-3).exp()
    }

    /// Light returned to the camera by a unit reflector at `p` (left
    /// frame), relative to one at 1.5 m on the axis; capped at 6.
    pub fn light(&self, p: &Vector3<f64>) -> f64 {
        (self.raw_light(p) / self.light_ref).min(6.0)
    }

    /// Backscatter along a camera ray from `origin` in unit direction `d`
    /// (unnormalised; the caller normalises over the frame).
    pub fn backscatter_along(&self, origin: &Vector3<f64>, d: &Vector3<f64>) -> f64 {
        let mut sum = 0.0;
        let n = 24;
        let (a, b) = (150.0f64.ln(), 6000.0f64.ln());
        let mut prev = 150.0;
        for i in 1..=n {
            let lam = (a + (b - a) * i as f64 / n as f64).exp();
            let p = origin + d * lam;
            sum += (self.irradiance(&p) / self.light_ref).min(40.0)
                * (-self.attenuation * lam * 1e-3).exp()
                * (lam - prev)
                * 1e-3;
            prev = lam;
        }
        sum
    }

    /// The mesh's states for frames `1..=frames` (index 0 is frame 1).
    pub fn mesh_frames(&self, seed: u64, frames: u32) -> Vec<MeshFrame> {
        let m = &self.mesh;
        let mut r0 = rng(seed, Stream::Frame, 0, 0);
        let mut off = (
            r0.random_range(0.0..m.spacing_mm),
            r0.random_range(0.0..m.spacing_mm),
        );
        let mut wave_phase = r0.random_range(0.0..std::f64::consts::TAU);
        let mut edge_phase = r0.random_range(0.0..std::f64::consts::TAU);
        (1..=frames)
            .map(|t| {
                let mut r = rng(seed, Stream::Frame, t as u64, 0);
                off.0 += m.drift.0 + 0.25 * m.spacing_mm * normal(&mut r);
                off.1 += m.drift.1 + 0.25 * m.spacing_mm * normal(&mut r);
                wave_phase += m.wave.2 * (1.0 + 0.3 * normal(&mut r));
                edge_phase += 0.3 * normal(&mut r);
                MeshFrame {
                    off,
                    wave_phase,
                    edge_phase,
                    gain: (self.flicker * normal(&mut r)).exp(),
                }
            })
            .collect()
    }
}

impl MeshLook {
    /// Brightness of the mesh at plane point `(x, y)` (mm) given the
    /// normalised half extents `tx`, `ty` of the view.
    pub fn value(&self, mf: &MeshFrame, x: f64, y: f64, tx: f64, ty: f64) -> f32 {
        let xn = x / (self.z_net * tx);
        let yn = y / (self.z_net * ty);
        let wob = self.edge_wave.0
            * (std::f64::consts::TAU * xn / self.edge_wave.1 + mf.edge_phase).sin()
            + self.curvature * xn * xn;
        let soft = 0.05;
        let e_top = -1.0 + 2.0 * self.bands.0 + wob;
        let e_bot = 1.0 - 2.0 * self.bands.1 + wob;
        let w = smooth((e_top - yn) / soft) + smooth((yn - e_bot) / soft);
        if w <= 0.0 {
            return 0.0;
        }
        let (s, c) = self.angle.sin_cos();
        let b = -x * s + y * c + mf.off.1;
        let a = x * c
            + y * s
            + mf.off.0
            + self.wave.0 * (std::f64::consts::TAU * b / self.wave.1 + mf.wave_phase).sin();
        let line = |v: f64| {
            let d = v - self.spacing_mm * (v / self.spacing_mm).round();
            let q = d / self.twine_mm;
            (-q * q).exp()
        };
        let v = (line(a) + line(b)).min(1.4);
        (self.amp * v * w.min(1.0)) as f32
    }
}

fn smooth(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A smooth, low-variance debris blob drifting with the water.
#[derive(Debug, Clone, PartialEq)]
pub struct Debris {
    /// Simulation frame of the first position.
    pub first_frame: i64,
    /// Centre per frame, left frame, mm.
    pub positions: Vec<Vector3<f64>>,
    /// Radius (σ of the Gaussian profile), mm.
    pub radius_mm: f64,
    /// Elongation (major/minor) and angle in the image.
    pub shape: (f64, f64),
    /// Peak grey-level contrast.
    pub contrast: f64,
}

impl Debris {
    /// The centre at `frame`, if the blob exists then.
    pub fn at(&self, frame: i64) -> Option<&Vector3<f64>> {
        let i = frame - self.first_frame;
        if i < 0 {
            return None;
        }
        self.positions.get(i as usize)
    }
}

/// Simulates the debris of a haul for frames up to `frames`.
pub fn simulate_debris(seed: u64, look: &Look, rig: &Rig, frames: u32) -> Vec<Debris> {
    let mut r = rng(seed, Stream::Debris, 0, 0);
    let tx = rig.half_fov_tan();
    let ty = 0.5 * rig.height as f64 / rig.left.fy;
    let warm = 25i64;
    let mut out = Vec::new();
    for t in (1 - warm)..=frames as i64 {
        let n = poisson(&mut r, look.debris.0);
        for _ in 0..n {
            let z = r.random_range(900.0..3500.0);
            let w = 2.0 * z * tx;
            let v = Vector3::new(
                -r.random_range(0.04..0.14) * w,
                0.02 * w * normal(&mut r),
                0.0,
            );
            let mut p = Vector3::new((tx + 0.25) * z, r.random_range(-1.1..1.1) * ty * z, z);
            let mut positions = Vec::new();
            while p.x / p.z > -tx - 0.4 && positions.len() < 200 {
                positions.push(p);
                p += v + Vector3::new(0.0, 0.01 * w * normal(&mut r), 0.0);
            }
            out.push(Debris {
                first_frame: t,
                positions,
                radius_mm: r.random_range(15.0..70.0),
                shape: (
                    r.random_range(1.0..2.5),
                    r.random_range(0.0..std::f64::consts::PI),
                ),
                contrast: r.random_range(look.debris.1 .0..look.debris.1 .1),
            });
        }
    }
    out
}

/// One marine-snow particle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Particle {
    /// Position, left frame, mm.
    pub p: Vector3<f64>,
    /// Radius, mm.
    pub radius_mm: f64,
    /// Relative brightness.
    pub brightness: f64,
}

/// The marine snow of one frame (fresh each frame: at 5 fps particles
/// move too far to be followed).
pub fn snow(seed: u64, look: &Look, rig: &Rig, frame: u32) -> Vec<Particle> {
    let mut r = rng(seed, Stream::Snow, frame as u64, 0);
    let tx = rig.half_fov_tan();
    let ty = 0.5 * rig.height as f64 / rig.left.fy;
    let n = (look.snow.0 * r.random_range(0.85..1.15)) as usize;
    (0..n)
        .map(|_| {
            let z = 250.0 + 3250.0 * r.random::<f64>().sqrt();
            let xn = r.random_range(-1.2..1.2) * tx + 0.5 * rig.baseline() / z;
            let yn = r.random_range(-1.2..1.2) * ty;
            Particle {
                p: Vector3::new(xn * z, yn * z, z),
                radius_mm: r.random_range(0.3..2.0),
                brightness: r.random_range(0.2..1.0),
            }
        })
        .collect()
}
