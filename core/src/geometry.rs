//! Rectified stereo geometry and triangulation (Section IV.D.2: "given a
//! point on the 2-D image represented by its screen coordinates (x, y) and
//! disparity d, it can be projected into 3-D space by stereo triangulation").
//!
//! Convention: OpenCV `stereoRectify` with a horizontal baseline. The
//! reprojection matrix is
//!
//! ```text
//!     ⎡1  0   0      −cx          ⎤
//! Q = ⎢0  1   0      −cy          ⎥ ,   [X Y Z W]ᵀ = Q·[x y d 1]ᵀ,  point = (X, Y, Z)/W
//!     ⎢0  0   0       f           ⎥
//!     ⎣0  0 −1/Tx  (cx − cx')/Tx  ⎦
//! ```
//!
//! with `Tx = −baseline` (the right camera sits at `+baseline` along x of the
//! rectified left camera, `P2[0,3] = f·Tx`) and disparity `d = x_left −
//! x_right`. With `CALIB_ZERO_DISPARITY`, `cx == cx'`. Points come out in
//! the rectified left camera frame, in the unit of the baseline (mm).
//! Memory bound: none (a few floats).

use nalgebra::{Matrix3x4, Matrix4, Vector3};

/// Why a geometry could not be built from calibration matrices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum GeometryError {
    /// A value is NaN or infinite.
    NotFinite,
    /// The focal length is not positive.
    BadFocal,
    /// The baseline is zero, or the right camera is not to the right of the
    /// left one (`Tx ≥ 0`): disparities would be negative.
    BadBaseline,
    /// The matrices are not of the horizontal-baseline rectified form.
    NotRectified,
}

impl core::fmt::Display for GeometryError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let s = match self {
            GeometryError::NotFinite => "calibration value is not finite",
            GeometryError::BadFocal => "rectified focal length is not positive",
            GeometryError::BadBaseline => {
                "baseline must be positive (right camera to the right of the left one)"
            }
            GeometryError::NotRectified => {
                "matrices are not a horizontal-baseline rectified pair (Q/P1/P2 form)"
            }
        };
        f.write_str(s)
    }
}

impl core::error::Error for GeometryError {}

/// The rectified pair's geometry: common focal length `f` (pixels), principal
/// point `(cx, cy)` of the left view, `cx_right` of the right view, and the
/// baseline in millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StereoGeometry {
    /// Focal length of both rectified views, pixels.
    pub f: f32,
    /// Principal point x of the rectified left view.
    pub cx: f32,
    /// Principal point y of both rectified views.
    pub cy: f32,
    /// Principal point x of the rectified right view (cx' in Q).
    pub cx_right: f32,
    /// Distance between the optical centres, mm (> 0).
    pub baseline_mm: f32,
}

impl StereoGeometry {
    /// Checks that the values make a usable geometry.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let all = [self.f, self.cx, self.cy, self.cx_right, self.baseline_mm];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(GeometryError::NotFinite);
        }
        if self.f <= 0.0 {
            return Err(GeometryError::BadFocal);
        }
        if self.baseline_mm <= 0.0 {
            return Err(GeometryError::BadBaseline);
        }
        Ok(())
    }

    /// From OpenCV's Q (`stereoRectify`): `cx = −Q₀₃`, `cy = −Q₁₃`,
    /// `f = Q₂₃`, `Tx = −1/Q₃₂`, `cx' = cx − Q₃₃·Tx`.
    pub fn from_q(q: &Matrix4<f32>) -> Result<Self, GeometryError> {
        if q.iter().any(|v| !v.is_finite()) {
            return Err(GeometryError::NotFinite);
        }
        if q[(3, 2)] == 0.0 || q[(2, 2)] != 0.0 {
            return Err(GeometryError::NotRectified);
        }
        let tx = -1.0 / q[(3, 2)];
        let cx = -q[(0, 3)];
        let g = StereoGeometry {
            f: q[(2, 3)],
            cx,
            cy: -q[(1, 3)],
            cx_right: cx - q[(3, 3)] * tx,
            baseline_mm: -tx,
        };
        g.validate()?;
        Ok(g)
    }

    /// From the rectified projection matrices P1, P2 (`stereoRectify`):
    /// `f = P1₀₀`, `(cx, cy) = (P1₀₂, P1₁₂)`, `cx' = P2₀₂`, `Tx = P2₀₃ / P2₀₀`.
    pub fn from_projections(
        p1: &Matrix3x4<f32>,
        p2: &Matrix3x4<f32>,
    ) -> Result<Self, GeometryError> {
        if p1.iter().chain(p2.iter()).any(|v| !v.is_finite()) {
            return Err(GeometryError::NotFinite);
        }
        if p2[(0, 0)] == 0.0 || p2[(1, 3)] != 0.0 {
            return Err(GeometryError::NotRectified);
        }
        let g = StereoGeometry {
            f: p1[(0, 0)],
            cx: p1[(0, 2)],
            cy: p1[(1, 2)],
            cx_right: p2[(0, 2)],
            baseline_mm: -p2[(0, 3)] / p2[(0, 0)],
        };
        g.validate()?;
        Ok(g)
    }

    /// The OpenCV reprojection matrix Q of this geometry.
    pub fn q(&self) -> Matrix4<f32> {
        let tx = -self.baseline_mm;
        Matrix4::new(
            1.0,
            0.0,
            0.0,
            -self.cx,
            0.0,
            1.0,
            0.0,
            -self.cy,
            0.0,
            0.0,
            0.0,
            self.f,
            0.0,
            0.0,
            -1.0 / tx,
            (self.cx - self.cx_right) / tx,
        )
    }

    /// Disparity offset `cx − cx'`: the disparity of a point at infinity.
    pub fn disparity_at_infinity(&self) -> f32 {
        self.cx - self.cx_right
    }

    /// Disparity of a point at depth `z_mm` (`f·B/z + cx − cx'`); the
    /// disparity at infinity for a non-positive or non-finite depth.
    pub fn disparity_at_depth(&self, z_mm: f32) -> f32 {
        if z_mm.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) || !z_mm.is_finite() {
            return self.disparity_at_infinity();
        }
        self.f * self.baseline_mm / z_mm + self.disparity_at_infinity()
    }

    /// Depth `Z = f·B / (d − (cx − cx'))` of disparity `d`, or `None` when the
    /// point would lie at or behind infinity.
    pub fn depth(&self, d: f32) -> Option<f32> {
        let dd = d - self.disparity_at_infinity();
        if dd.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) || !dd.is_finite() {
            return None;
        }
        Some(self.f * self.baseline_mm / dd)
    }

    /// Triangulates left-view pixel `(x, y)` with disparity `d` into the
    /// rectified left camera frame (mm): `Q·[x y d 1]ᵀ` dehomogenised.
    /// `None` when `W ≤ 0` (point at or beyond infinity) or not finite.
    pub fn triangulate(&self, x: f32, y: f32, d: f32) -> Option<Vector3<f32>> {
        let w = (d - self.disparity_at_infinity()) / self.baseline_mm;
        if w.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) || !w.is_finite() {
            return None;
        }
        let p = Vector3::new((x - self.cx) / w, (y - self.cy) / w, self.f / w);
        if p.iter().all(|v| v.is_finite()) {
            Some(p)
        } else {
            None
        }
    }

    /// Projects a 3-D point (left rectified frame, mm) to left pixel
    /// coordinates and disparity: the inverse of [`Self::triangulate`].
    pub fn project(&self, p: &Vector3<f32>) -> Option<(f32, f32, f32)> {
        if p.z.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return None;
        }
        let x = self.f * p.x / p.z + self.cx;
        let y = self.f * p.y / p.z + self.cy;
        let d = self.f * self.baseline_mm / p.z + self.disparity_at_infinity();
        Some((x, y, d))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn g() -> StereoGeometry {
        StereoGeometry {
            f: 1500.0,
            cx: 1020.5,
            cy: 1010.25,
            cx_right: 1012.0,
            baseline_mm: 200.0,
        }
    }

    #[test]
    fn q_roundtrip_and_triangulation_match_matrix_product() {
        let g = g();
        let q = g.q();
        let back = StereoGeometry::from_q(&q).unwrap();
        assert!((back.f - g.f).abs() < 1e-3);
        assert!((back.cx_right - g.cx_right).abs() < 1e-3);
        assert!((back.baseline_mm - g.baseline_mm).abs() < 1e-3);
        let (x, y, d) = (300.0f32, 1700.0f32, 120.5f32);
        let h = q * nalgebra::Vector4::new(x, y, d, 1.0);
        let p = g.triangulate(x, y, d).unwrap();
        for i in 0..3 {
            let want = h[i] / h[3];
            assert!((p[i] - want).abs() <= 1e-5 * want.abs().max(1.0));
        }
        // Z = f·B / (d − (cx − cx'))
        assert!((p.z - 1500.0 * 200.0 / (120.5 - 8.5)).abs() < 1e-2);
        let (px, py, pd) = g.project(&p).unwrap();
        assert!((px - x).abs() < 1e-3 && (py - y).abs() < 1e-3 && (pd - d).abs() < 1e-3);
    }

    #[test]
    fn from_projections_matches_q() {
        let g = g();
        let p1 = Matrix3x4::new(g.f, 0.0, g.cx, 0.0, 0.0, g.f, g.cy, 0.0, 0.0, 0.0, 1.0, 0.0);
        let p2 = Matrix3x4::new(
            g.f,
            0.0,
            g.cx_right,
            -g.f * g.baseline_mm,
            0.0,
            g.f,
            g.cy,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
        );
        let h = StereoGeometry::from_projections(&p1, &p2).unwrap();
        assert_eq!(h, g);
        let mut bad = p2;
        bad[(0, 3)] = 1.0;
        assert_eq!(
            StereoGeometry::from_projections(&p1, &bad),
            Err(GeometryError::BadBaseline)
        );
    }

    #[test]
    fn points_at_or_beyond_infinity_are_none() {
        let g = g();
        assert!(g.triangulate(10.0, 10.0, 8.5).is_none());
        assert!(g.triangulate(10.0, 10.0, 0.0).is_none());
        assert!(g.triangulate(10.0, 10.0, f32::NAN).is_none());
        assert!(g.depth(8.0).is_none());
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn triangulate_never_panics(x in proptest::num::f32::ANY, y in proptest::num::f32::ANY,
                                    d in proptest::num::f32::ANY) {
            let _ = g().triangulate(x, y, d);
            let _ = g().disparity_at_depth(d);
        }
    }
}
