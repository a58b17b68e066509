//! Synthetic fish: body shape, appearance and low-frame-rate motion.
//!
//! Shape: a laterally compressed spindle around a bent midline (spine).
//! The midline has arc length `length_mm` from snout (s = 0) to tail tip
//! (s = L) in every frame; bending only curls it, so the straight
//! snout-to-tail distance (what a stereo system measures, paper Section
//! IV.D.2) is `length_mm` for an unbent fish and between 0.98·L and L for a
//! bent one ([`MAX_BEND`] bounds the curl). `truth.json`'s `length_mm` is
//! this arc length; its `head_mm`/`tail_mm` are the bent fish's end points.
//!
//! Motion (paper Section II: 5 fps, ≈ 4 frames of life in view; the
//! camera sits in the aft end of a trawl, so the fish are carried through
//! the view by the flow, mostly head first towards −x): fish arrive in
//! small schools ([`School`]: shared entry border and place, heading,
//! range, speed and size class) and enter across a border (mostly the
//! right one, heading −x; 18 % swim +x; 38 % enter across the top or
//! bottom). Each frame they step by 15–30 % of the view's width at their
//! range, hundreds of pixels, so frame-to-frame association is hard for
//! nearest neighbour where fish enter close together. The step is smooth
//! in the way a carried fish's is: per fish, independent per-frame heading
//! jitter of σ 2–7° and speed jitter of log-σ 0.04–0.12 around its own
//! speed, a slowly wandering mean heading (σ 1.7° per frame), an
//! occasional lasting turn (4 % of frames, 10–35°), a slow drift in range,
//! and fish are dropped once well outside both views. Bodies point along
//! the displacement but lean towards the trawl axis; 7 % drift tail first.
//!
//! (Until session 2 the jitter was σ 22° and log-σ 0.45 per frame with
//! 15 % of frames turning by 30–85°: a prediction from each fish's true
//! previous velocity then missed by a median of ~250 px at 2048², and
//! even the paper's cues could not follow it, whereas the paper's
//! vicinity cue — a prediction from the velocity — is its strongest cue
//! on real footage, Fig. 15.)

use nalgebra::{Rotation3, Unit, Vector3};
use rand::Rng;

use super::rig::Rig;
use super::seed::normal;

/// Largest amplitude of the midline's tangent angle, radians.
pub const MAX_BEND: f64 = 0.22;
/// Number of midline samples used to draw a fish.
pub const SPINE_SAMPLES: usize = 81;
/// Nearest and farthest range of a fish's centre, mm.
pub const RANGE_MM: (f64, f64) = (1200.0, 3000.0);

/// The fixed properties of one fish.
#[derive(Debug, Clone, PartialEq)]
pub struct FishSpec {
    /// Arc length of the midline, snout to tail tip, mm.
    pub length_mm: f64,
    /// Largest half body depth (dorso-ventral), mm.
    pub half_depth_mm: f64,
    /// Half width (lateral) over half depth.
    pub width_ratio: f64,
    /// Half depth of the caudal peduncle relative to the largest half depth.
    pub peduncle: f64,
    /// Half height of the caudal fin at the tail tip, relative.
    pub fin_height: f64,
    /// Where the caudal fin starts, as a fraction of the length.
    pub fin_start: f64,
    /// Grey-level contrast of the body over the background at the fish's
    /// mean position, before texture and shading.
    pub contrast: f64,
    /// Reflectivity of the caudal fin relative to the body.
    pub tail_reflectivity: f64,
    /// Counter-shading: belly brighter than back by this fraction.
    pub countershade: f64,
    /// Texture: value-noise amplitude and scale (mm).
    pub texture_amp: f64,
    /// Texture scale, mm.
    pub texture_mm: f64,
    /// Amplitude of vertical bars (0 for none) and their spacing in mm.
    pub bars: (f64, f64),
    /// Seed of the body texture.
    pub texture_seed: u64,
}

impl FishSpec {
    /// A random fish.
    pub fn random<R: Rng>(rng: &mut R) -> FishSpec {
        // Two size classes, as in a mixed-species haul.
        let length_mm = if rng.random_bool(0.6) {
            rng.random_range(200.0..450.0)
        } else {
            rng.random_range(350.0..700.0)
        };
        let contrast = if rng.random_bool(0.3) {
            rng.random_range(7.0..15.0) // dim fish, close to the background
        } else {
            rng.random_range(18.0..90.0)
        };
        FishSpec {
            length_mm,
            half_depth_mm: length_mm * rng.random_range(0.085..0.13),
            width_ratio: rng.random_range(0.35..0.55),
            peduncle: rng.random_range(0.18..0.3),
            fin_height: rng.random_range(0.5..0.85),
            fin_start: rng.random_range(0.8..0.86),
            contrast,
            tail_reflectivity: rng.random_range(0.1..0.55),
            countershade: rng.random_range(0.0..0.5),
            texture_amp: rng.random_range(0.1..0.4),
            texture_mm: rng.random_range(8.0..35.0),
            bars: if rng.random_bool(0.3) {
                (rng.random_range(0.1..0.35), rng.random_range(30.0..90.0))
            } else {
                (0.0, 50.0)
            },
            texture_seed: rng.random(),
        }
    }

    /// Half depth at fraction `x = s / L` of the length, mm.
    pub fn half_depth(&self, x: f64) -> f64 {
        let x = x.clamp(0.0, 1.0);
        let f = if x < 0.22 {
            let t = (0.22 - x) / 0.22;
            (1.0 - t * t).max(0.0).sqrt()
        } else if x < self.fin_start {
            let t = (x - 0.22) / (self.fin_start - 0.22);
            1.0 - (1.0 - self.peduncle) * t.powf(1.6)
        } else {
            let t = (x - self.fin_start) / (1.0 - self.fin_start);
            self.peduncle + (self.fin_height - self.peduncle) * t.powf(0.8)
        };
        self.half_depth_mm * f
    }

    /// Half width at fraction `x`, mm (fins are thin).
    pub fn half_width(&self, x: f64) -> f64 {
        if x >= self.fin_start {
            (self.half_depth_mm * 0.04).max(2.0)
        } else {
            self.half_depth(x) * self.width_ratio
        }
    }

    /// Reflectivity factor along the body: 1 on the body, falling to
    /// `tail_reflectivity` over the caudal fin.
    pub fn reflectivity(&self, x: f64) -> f64 {
        let a = self.fin_start - 0.03;
        let b = self.fin_start + 0.04;
        let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
        let t = t * t * (3.0 - 2.0 * t);
        1.0 + (self.tail_reflectivity - 1.0) * t
    }
}

/// A fish's pose in one frame (left camera frame, mm).
#[derive(Debug, Clone, PartialEq)]
pub struct FishPose {
    /// Midpoint of the midline (s = L/2).
    pub centre: Vector3<f64>,
    /// Unit vector from tail to snout of the unbent body.
    pub axis: Vector3<f64>,
    /// Unit dorsal direction, perpendicular to `axis`.
    pub dorsal: Vector3<f64>,
    /// Bending: amplitude (rad, ≤ [`MAX_BEND`]), waves along the body,
    /// phase, and the bend plane's angle from lateral towards dorsal.
    pub bend: (f64, f64, f64, f64),
}

/// One sample of the midline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpineSample {
    /// Arc length from the snout, mm.
    pub s: f64,
    /// Position, left frame, mm.
    pub p: Vector3<f64>,
    /// Unit tangent, pointing to the snout.
    pub tangent: Vector3<f64>,
    /// Unit dorsal direction at this sample.
    pub dorsal: Vector3<f64>,
}

impl FishPose {
    fn bend_angle(&self, x: f64) -> f64 {
        let (amp, waves, phase, _) = self.bend;
        amp * (0.35 + 0.65 * x) * (std::f64::consts::TAU * waves * x + phase).sin()
    }

    /// The midline sampled at `n ≥ 3` (odd) points from snout to tail tip.
    /// Exact arc length `L` by construction (unit-speed integration).
    pub fn spine(&self, spec: &FishSpec, n: usize) -> Vec<SpineSample> {
        let n = n.max(3) | 1;
        let l = spec.length_mm;
        let lateral = self.axis.cross(&self.dorsal);
        let beta = self.bend.3;
        let bdir = lateral * beta.cos() + self.dorsal * beta.sin();
        let ds = l / (n - 1) as f64;
        // Integrate from the snout towards the tail (direction −tangent).
        let tangent_at = |x: f64| {
            let th = self.bend_angle(x);
            self.axis * th.cos() + bdir * th.sin()
        };
        let mut pts = Vec::with_capacity(n);
        let mut q = Vector3::zeros();
        pts.push(q);
        for i in 1..n {
            let xm = (i as f64 - 0.5) / (n - 1) as f64;
            q -= tangent_at(xm) * ds;
            pts.push(q);
        }
        let mid = pts[n / 2];
        (0..n)
            .map(|i| {
                let x = i as f64 / (n - 1) as f64;
                let t = tangent_at(x);
                let d = (self.dorsal - t * self.dorsal.dot(&t)).normalize();
                SpineSample {
                    s: x * l,
                    p: self.centre + pts[i] - mid,
                    tangent: t,
                    dorsal: d,
                }
            })
            .collect()
    }

    /// Snout and tail tip, mm, left frame.
    pub fn ends(&self, spec: &FishSpec) -> (Vector3<f64>, Vector3<f64>) {
        let sp = self.spine(spec, SPINE_SAMPLES);
        (sp[0].p, sp[sp.len() - 1].p)
    }
}

/// Body axis and dorsal direction for a heading `phi` in the image plane
/// (angle of (x, y), y down), a yaw `psi` out of it, and a roll.
fn orientation(phi: f64, psi: f64, roll: f64) -> (Vector3<f64>, Vector3<f64>) {
    let axis = Vector3::new(psi.cos() * phi.cos(), psi.cos() * phi.sin(), psi.sin());
    let mut perp = Vector3::new(-phi.sin(), phi.cos(), 0.0);
    if perp.y > 0.0 {
        perp = -perp;
    }
    let dorsal = (perp - axis * perp.dot(&axis)).normalize();
    let rot = Rotation3::from_axis_angle(&Unit::new_normalize(axis), roll);
    (axis, rot * dorsal)
}

/// Where a fish (or a school of fish) enters the view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Border {
    /// The upstream side: right for fish heading −x, left for +x.
    Side,
    /// The top border, heading down.
    Top,
    /// The bottom border, heading up.
    Bottom,
}

/// What the fish arriving together share: direction, entry border and
/// place, range, speed and size class. Schools make several fish enter
/// close together, which is what defeats nearest-neighbour association at
/// 5 fps.
#[derive(Debug, Clone, PartialEq)]
pub struct School {
    /// Heading −x (most fish) or +x.
    pub towards_minus_x: bool,
    /// Entry border.
    pub border: Border,
    /// Entry place along the border, −1 … 1.
    pub along: f64,
    /// Mean heading in the image plane, radians (x right, y down).
    pub phi: f64,
    /// Mean range, mm.
    pub z: f64,
    /// Mean step per frame as a fraction of the view's width at the fish's range.
    pub v_frac: f64,
    /// Mean length, mm.
    pub length_mm: f64,
}

impl School {
    /// A random school.
    pub fn random<R: Rng>(rng: &mut R) -> School {
        let towards_minus_x = rng.random_bool(0.82);
        let (sx, base) = if towards_minus_x {
            (-1.0, std::f64::consts::PI)
        } else {
            (1.0, 0.0)
        };
        let u: f64 = rng.random();
        let border = if u < 0.62 {
            Border::Side
        } else if u < 0.81 {
            Border::Top
        } else {
            Border::Bottom
        };
        let a = rng.random_range(0.35..1.1);
        let (phi, along) = match border {
            Border::Side => (base + 0.3 * normal(rng), rng.random_range(-0.9..0.9)),
            Border::Top => (base - sx * a, rng.random_range(-0.85..0.95) * -sx),
            Border::Bottom => (base + sx * a, rng.random_range(-0.85..0.95) * -sx),
        };
        School {
            towards_minus_x,
            border,
            along,
            phi,
            z: rng.random_range(RANGE_MM.0..RANGE_MM.1),
            v_frac: rng.random_range(0.15..0.3),
            length_mm: if rng.random_bool(0.6) {
                rng.random_range(200.0..450.0)
            } else {
                rng.random_range(350.0..700.0)
            },
        }
    }
}

/// One fish's whole life: its spec and its pose per simulation frame.
#[derive(Debug, Clone)]
pub struct FishLife {
    /// Shape and appearance.
    pub spec: FishSpec,
    /// Simulation frame of the first pose (may be before frame 1).
    pub first_frame: i64,
    /// Poses for `first_frame, first_frame + 1, …`.
    pub poses: Vec<FishPose>,
}

impl FishLife {
    /// The pose at `frame`, if the fish exists then.
    pub fn pose(&self, frame: i64) -> Option<&FishPose> {
        let i = frame - self.first_frame;
        if i < 0 {
            return None;
        }
        self.poses.get(i as usize)
    }

    /// Simulates a fish of `school` that spawns outside the view at `first_frame`.
    pub fn simulate<R: Rng>(rng: &mut R, rig: &Rig, school: &School, first_frame: i64) -> FishLife {
        let mut spec = FishSpec::random(rng);
        // School mates have similar sizes.
        let depth_ratio = spec.half_depth_mm / spec.length_mm;
        spec.length_mm = (school.length_mm * (0.12 * normal(rng)).exp()).clamp(200.0, 700.0);
        spec.half_depth_mm = depth_ratio * spec.length_mm;
        let tx = rig.half_fov_tan();
        let ty = 0.5 * rig.height as f64 / rig.left.fy;
        let l = spec.length_mm;
        let mut z = (school.z + 350.0 * normal(rng)).clamp(RANGE_MM.0, RANGE_MM.1);
        let sx = if school.towards_minus_x { -1.0 } else { 1.0 };
        let mut phi_m = school.phi + 0.15 * normal(rng);
        let along = (school.along + 0.3 * normal(rng)).clamp(-1.0, 1.0);
        let (entry_xn, entry_yn) = match school.border {
            Border::Side => (-sx * tx, along * ty),
            Border::Top => (along * tx, -ty),
            Border::Bottom => (along * tx, ty),
        };
        let width_at = |z: f64| 2.0 * z * tx;
        let v_frac = school.v_frac * (0.15 * normal(rng)).exp();
        let tail_first = rng.random_bool(0.07);
        // Per-fish smoothness: heading jitter (rad) and speed jitter (log-σ)
        // per frame.
        let heading_sd = rng.random_range(0.035..0.12);
        let speed_sd = rng.random_range(0.04..0.12);
        let step = |rng: &mut R, phi_m: f64, z: f64| {
            let speed = v_frac * width_at(z) * (speed_sd * normal(rng)).exp().clamp(0.6, 1.6);
            let phi = phi_m + heading_sd * normal(rng);
            (speed, phi)
        };
        // Start outside: the snout on the border, then back by a random part of a step.
        let dir0 = Vector3::new(phi_m.cos(), phi_m.sin(), 0.0);
        let back = 0.5 * l + rng.random_range(0.0..1.0) * v_frac * width_at(z);
        let mut centre = Vector3::new(entry_xn * z, entry_yn * z, z) - dir0 * back;
        let mut poses = Vec::new();
        let mut phi = phi_m;
        let mut vz = 0.0;
        for k in 0..60 {
            if k > 0 {
                // The mean heading wanders slowly; occasionally the fish
                // makes a lasting turn.
                phi_m += 0.03 * normal(rng);
                if rng.random_bool(0.04) {
                    let turn = rng.random_range(0.17..0.6);
                    phi_m += if rng.random_bool(0.5) { turn } else { -turn };
                }
                let (speed, p) = step(rng, phi_m, z);
                phi = p;
                vz = 0.6 * vz + 0.025 * z * normal(rng);
                let mut c = centre + Vector3::new(phi.cos(), phi.sin(), 0.0) * speed;
                c.z += vz;
                if c.z < RANGE_MM.0 - 100.0 || c.z > RANGE_MM.1 + 300.0 {
                    vz = -vz;
                    c.z = c.z.clamp(RANGE_MM.0 - 100.0, RANGE_MM.1 + 300.0);
                }
                centre = c;
                z = centre.z;
            }
            // Bodies lean towards the trawl axis: the water carries the fish
            // while it swims, so the body turns only part of the way to the
            // direction it is displaced in.
            let axis_dir = if phi.cos() < 0.0 {
                std::f64::consts::PI
            } else {
                0.0
            };
            let dev = (phi - axis_dir).sin().atan2((phi - axis_dir).cos());
            let heading = axis_dir
                + 0.6 * dev
                + 0.15 * normal(rng)
                + if tail_first {
                    std::f64::consts::PI
                } else {
                    0.0
                };
            let psi = (0.3 * normal(rng) + (vz / (0.5 * l + 1.0)).atan() * 0.5).clamp(-0.7, 0.7);
            let roll = 0.15 * normal(rng);
            let (axis, dorsal) = orientation(heading, psi, roll);
            let bend = (
                rng.random_range(0.0..MAX_BEND),
                rng.random_range(0.5..1.2),
                rng.random_range(0.0..std::f64::consts::TAU),
                0.5 * normal(rng),
            );
            poses.push(FishPose {
                centre,
                axis,
                dorsal,
                bend,
            });
            if k > 0 && gone(rig, &centre, l, &Vector3::new(phi.cos(), phi.sin(), 0.0)) {
                break;
            }
        }
        FishLife {
            spec,
            first_frame,
            poses,
        }
    }
}

/// True when a fish centred at `c` is well outside both views and heading
/// further out.
fn gone(rig: &Rig, c: &Vector3<f64>, l: f64, dir: &Vector3<f64>) -> bool {
    let tx = rig.half_fov_tan();
    let ty = 0.5 * rig.height as f64 / rig.left.fy;
    let z = c.z.max(1.0);
    let reach = 0.6 * l / z + rig.baseline() / z + 0.15;
    let xn = c.x / z;
    let yn = c.y / z;
    let out_x = (xn < -tx - reach && dir.x <= 0.0) || (xn > tx + reach && dir.x >= 0.0);
    let out_y = (yn < -ty - reach && dir.y <= 0.0) || (yn > ty + reach && dir.y >= 0.0);
    let far = xn.abs() > tx + 3.0 * reach || yn.abs() > ty + 3.0 * reach;
    out_x || out_y || far
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn spine_has_the_arc_length_and_a_bounded_chord() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let rig = Rig::random(&mut rng, 2048);
        for i in 0..200 {
            let school = School::random(&mut rng);
            let life = FishLife::simulate(&mut rng, &rig, &school, i);
            for pose in &life.poses {
                let sp = pose.spine(&life.spec, SPINE_SAMPLES);
                let arc: f64 = sp.windows(2).map(|w| (w[1].p - w[0].p).norm()).sum();
                let l = life.spec.length_mm;
                assert!((arc - l).abs() < 1e-6 * l, "arc {arc} vs {l}");
                let chord = (sp[0].p - sp[sp.len() - 1].p).norm();
                assert!(
                    chord <= l * (1.0 + 1e-9) && chord >= 0.98 * l,
                    "chord {chord} vs {l}"
                );
                assert!((sp[SPINE_SAMPLES / 2].p - pose.centre).norm() < 1e-9);
            }
        }
    }

    #[test]
    fn body_profile_is_positive_inside_and_zero_at_the_snout() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let spec = FishSpec::random(&mut rng);
        assert_eq!(spec.half_depth(0.0), 0.0);
        for i in 1..=100 {
            assert!(spec.half_depth(i as f64 / 100.0) > 0.0);
        }
        assert!((spec.reflectivity(1.0) - spec.tail_reflectivity).abs() < 1e-12);
        assert_eq!(spec.reflectivity(0.5), 1.0);
    }
}
