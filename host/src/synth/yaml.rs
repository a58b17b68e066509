//! `calibration.yml` for a synthetic rig, written through the calibration
//! writer ([`crate::calib::yaml`]), which lays it out exactly as OpenCV's
//! `cv::FileStorage` writes YAML (`%YAML:1.0`, `---`, integer scalars,
//! `!!opencv-matrix` nodes with `%.17g` numbers and OpenCV's line wrapping).

use nalgebra::{Matrix3, Vector3};

use super::rig::Rig;
use crate::calib::yaml::{header, write_int, write_matrix};

fn mat3(m: &Matrix3<f64>) -> Vec<f64> {
    (0..3)
        .flat_map(|r| (0..3).map(move |c| m[(r, c)]))
        .collect()
}

fn vec3(v: &Vector3<f64>) -> Vec<f64> {
    vec![v.x, v.y, v.z]
}

/// The text of `calibration.yml` for a rig.
pub fn calibration_yaml(rig: &Rig) -> String {
    let mut out = header();
    write_int(&mut out, "image_width", i64::from(rig.width));
    write_int(&mut out, "image_height", i64::from(rig.height));
    write_matrix(&mut out, "M1", 3, 3, &mat3(&rig.left.matrix()));
    write_matrix(&mut out, "D1", 1, 5, &rig.left.dist);
    write_matrix(&mut out, "M2", 3, 3, &mat3(&rig.right.matrix()));
    write_matrix(&mut out, "D2", 1, 5, &rig.right.dist);
    write_matrix(&mut out, "R", 3, 3, &mat3(&rig.r));
    write_matrix(&mut out, "T", 3, 1, &vec3(&rig.t));
    out
}
