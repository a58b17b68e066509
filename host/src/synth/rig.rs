//! The synthetic stereo rig: two pinhole cameras with OpenCV's lens
//! distortion model (k1, k2, p1, p2, k3) and the right camera's pose
//! `X_right = R·X_left + T` (OpenCV `stereoCalibrate` convention, T in mm).
//!
//! Pixel coordinates here are OpenCV's: the centre of pixel `(i, j)` is at
//! `(i, j)`. `truth.json` boxes count whole pixels, so pixel `(i, j)` there
//! covers `[i, i + 1) × [j, j + 1)`.
//!
//! Randomised per seed within what a Cam-trawl-like rig plausibly is: about
//! 50–60° horizontal field of view (focal length ≈ 1 800–2 200 px on a 2048
//! frame, scaled with `--size`), a 150–250 mm horizontal baseline, a few
//! degrees of rotation between the cameras and mild lens distortion.

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::Rng;

/// Which camera of the pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Cam {
    /// The left (reference) camera; 3-D points are in its frame.
    Left,
    /// The right camera.
    Right,
}

impl Cam {
    /// Both cameras, left first.
    pub const BOTH: [Cam; 2] = [Cam::Left, Cam::Right];

    /// 0 for left, 1 for right.
    pub fn index(self) -> usize {
        match self {
            Cam::Left => 0,
            Cam::Right => 1,
        }
    }
}

/// One camera's intrinsics and distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Focal length in x, pixels.
    pub fx: f64,
    /// Focal length in y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (OpenCV coordinates).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Distortion coefficients `k1 k2 p1 p2 k3` (OpenCV order).
    pub dist: [f64; 5],
    /// Normalised radius up to which the radial distortion is monotone.
    /// Beyond it (far outside the image) the radial map is continued
    /// linearly, so points outside the view never fold back into it.
    pub r_mono: f64,
}

impl Camera {
    /// The 3×3 camera matrix `M`.
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    fn radial_poly(&self, r2: f64) -> f64 {
        let [k1, k2, _, _, k3] = self.dist;
        1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    }

    /// Distorted radius `r·(1 + k1 r² + k2 r⁴ + k3 r⁶)` and its derivative.
    fn rd(&self, r: f64) -> (f64, f64) {
        let [k1, k2, _, _, k3] = self.dist;
        let r2 = r * r;
        let v = r * self.radial_poly(r2);
        let d = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 + 7.0 * k3 * r2 * r2 * r2;
        (v, d)
    }

    /// Applies the distortion to normalised coordinates `(x, y) = (X/Z, Y/Z)`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [_, _, p1, p2, _] = self.dist;
        let r2 = x * x + y * y;
        let radial = if r2 <= self.r_mono * self.r_mono {
            self.radial_poly(r2)
        } else {
            let r = r2.sqrt();
            let (v, d) = self.rd(self.r_mono);
            (v + d * (r - self.r_mono)) / r
        };
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        (xd, yd)
    }

    /// Projects a point in this camera's frame (mm) to pixel coordinates;
    /// `None` when it is not in front of the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        if p.z <= 1.0 {
            return None;
        }
        let (xd, yd) = self.distort(p.x / p.z, p.y / p.z);
        Some((self.fx * xd + self.cx, self.fy * yd + self.cy))
    }

    /// Inverse of the distortion: the normalised ray `(x, y)` (with z = 1)
    /// seen at pixel `(u, v)`. Fixed-point iteration as OpenCV's
    /// `undistortPoints`, refined until the reprojection matches.
    pub fn undistort(&self, u: f64, v: f64) -> (f64, f64) {
        let xd = (u - self.cx) / self.fx;
        let yd = (v - self.cy) / self.fy;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (dx, dy) = self.distort(x, y);
            let (ex, ey) = (dx - xd, dy - yd);
            if ex.abs() < 1e-12 && ey.abs() < 1e-12 {
                break;
            }
            // Damped Newton step with the radial derivative as the slope.
            let r = (x * x + y * y).sqrt().max(1e-9);
            let slope = if r <= self.r_mono {
                let (v, d) = self.rd(r);
                (d + v / r) * 0.5
            } else {
                1.0
            };
            let slope = slope.max(0.2);
            x -= ex / slope;
            y -= ey / slope;
        }
        (x, y)
    }
}

/// The calibrated stereo rig of a synthetic haul.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Left camera.
    pub left: Camera,
    /// Right camera.
    pub right: Camera,
    /// Rotation from the left to the right camera frame.
    pub r: Matrix3<f64>,
    /// Translation, mm: `X_right = R·X_left + T`.
    pub t: Vector3<f64>,
}

/// Finds the normalised radius where the radial map stops being safely
/// monotone (derivative below 0.3), searching up to 3.
fn monotone_radius(cam: &Camera) -> f64 {
    let mut r = 0.0;
    while r < 3.0 {
        if cam.rd(r).1 < 0.3 {
            return r;
        }
        r += 0.005;
    }
    3.0
}

impl Rig {
    /// A random plausible rig for a `size`×`size` frame.
    pub fn random<R: Rng>(rng: &mut R, size: u32) -> Rig {
        let w = size as f64;
        let fov = rng.random_range(50.0f64..60.0).to_radians();
        let f = 0.5 * w / (0.5 * fov).tan();
        let corner = std::f64::consts::SQRT_2 * (0.5 * fov).tan();
        let make_cam = |rng: &mut R| loop {
            let fx = f * rng.random_range(0.99..1.01);
            let mut cam = Camera {
                fx,
                fy: fx * rng.random_range(0.998..1.002),
                cx: 0.5 * (w - 1.0) + w * rng.random_range(-0.008..0.008),
                cy: 0.5 * (w - 1.0) + w * rng.random_range(-0.008..0.008),
                dist: [
                    rng.random_range(-0.22..0.18),
                    rng.random_range(-0.10..0.10),
                    rng.random_range(-0.0008..0.0008),
                    rng.random_range(-0.0008..0.0008),
                    rng.random_range(-0.04..0.04),
                ],
                r_mono: 3.0,
            };
            cam.r_mono = monotone_radius(&cam);
            if cam.r_mono >= 1.4 * corner {
                return cam;
            }
        };
        let left = make_cam(rng);
        let right = make_cam(rng);
        let baseline = rng.random_range(150.0..250.0);
        // Small rotation: a little toe-in about y, and a fraction of a
        // degree to a degree about x and z.
        let rvec = Vector3::new(
            rng.random_range(-1.0f64..1.0).to_radians(),
            rng.random_range(-3.0f64..1.0).to_radians(),
            rng.random_range(-1.0f64..1.0).to_radians(),
        );
        let r = *Rotation3::from_scaled_axis(rvec).matrix();
        let centre = Vector3::new(
            baseline,
            rng.random_range(-4.0..4.0),
            rng.random_range(-4.0..4.0),
        );
        let t = -(r * centre);
        Rig {
            width: size,
            height: size,
            left,
            right,
            r,
            t,
        }
    }

    /// The camera of `cam`.
    pub fn camera(&self, cam: Cam) -> &Camera {
        match cam {
            Cam::Left => &self.left,
            Cam::Right => &self.right,
        }
    }

    /// A left-frame point in `cam`'s frame.
    pub fn to_cam(&self, cam: Cam, p: &Vector3<f64>) -> Vector3<f64> {
        match cam {
            Cam::Left => *p,
            Cam::Right => self.r * p + self.t,
        }
    }

    /// Centre of `cam` in the left frame, mm.
    pub fn centre(&self, cam: Cam) -> Vector3<f64> {
        match cam {
            Cam::Left => Vector3::zeros(),
            Cam::Right => -(self.r.transpose() * self.t),
        }
    }

    /// Direction (left frame, not normalised) of the ray through a
    /// normalised point `(x, y)` of `cam`.
    pub fn ray_dir(&self, cam: Cam, x: f64, y: f64) -> Vector3<f64> {
        let d = Vector3::new(x, y, 1.0);
        match cam {
            Cam::Left => d,
            Cam::Right => self.r.transpose() * d,
        }
    }

    /// Projects a left-frame point into `cam`'s raw pixels.
    pub fn project(&self, cam: Cam, p: &Vector3<f64>) -> Option<(f64, f64)> {
        self.camera(cam).project(&self.to_cam(cam, p))
    }

    /// Baseline length, mm.
    pub fn baseline(&self) -> f64 {
        self.t.norm()
    }

    /// Tangent of half the left camera's horizontal field of view (ignoring distortion).
    pub fn half_fov_tan(&self) -> f64 {
        0.5 * self.width as f64 / self.left.fx
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn undistort_inverts_distort_over_the_frame() {
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let rig = Rig::random(&mut rng, 2048);
            for cam in Cam::BOTH {
                let c = rig.camera(cam);
                for &(u, v) in &[(0.0, 0.0), (2047.0, 0.0), (1024.0, 1024.0), (10.0, 2000.0)] {
                    let (x, y) = c.undistort(u, v);
                    let (pu, pv) = c
                        .project(&Vector3::new(x * 1000.0, y * 1000.0, 1000.0))
                        .unwrap();
                    assert!(
                        (pu - u).abs() < 1e-6 && (pv - v).abs() < 1e-6,
                        "{seed} {u} {v} -> {pu} {pv}"
                    );
                }
            }
        }
    }

    #[test]
    fn rig_is_plausible() {
        for seed in 0..50 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let rig = Rig::random(&mut rng, 2048);
            let b = rig.baseline();
            assert!((150.0..=251.0).contains(&b), "baseline {b}");
            let fov = 2.0 * rig.half_fov_tan().atan();
            assert!((49.0f64.to_radians()..61.0f64.to_radians()).contains(&fov));
            // The right camera sits to the right (+x) of the left one.
            assert!(rig.centre(Cam::Right).x > 140.0);
            // A point 2 m ahead on the left axis is seen in both views, with
            // positive disparity of about f·b/Z.
            let p = Vector3::new(0.0, 0.0, 2000.0);
            let (ul, _) = rig.project(Cam::Left, &p).unwrap();
            let (ur, _) = rig.project(Cam::Right, &p).unwrap();
            assert!(ul - ur > 0.0);
        }
    }
}
