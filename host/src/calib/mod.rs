//! Stereo calibration (paper Sections IV.A and IV.D: rectification before
//! stereo matching, triangulation for the 3-D length): one in-memory model read from every layout FishTrack
//! accepts (DESIGN.md "Input: a haul directory"):
//!
//! - `calibration.yml`: OpenCV FileStorage YAML with `M1 D1 M2 D2 R T`
//!   (aliases `cameraMatrixL/R`, `cameraMatrix1/2`, `distCoeffsL/R`,
//!   `distCoeffs1/2`) and `image_width`, `image_height`;
//! - the OpenCV `stereo_calib` sample pair: `intrinsics.yml` with
//!   `M1 D1 M2 D2` and `extrinsics.yml` with `R T` (its `R1 R2 P1 P2 Q`
//!   are ignored, FishTrack recomputes them, see [`crate::rectify`]);
//! - VIAME camtrawl `cal.npz` (`cameraMatrixL`, `cameraMatrixR`,
//!   `distCoeffsL`, `distCoeffsR`, `R`, `T`).
//!
//! Conventions are OpenCV `stereoCalibrate`'s: `X_right = R·X_left + T`,
//! `T` in millimetres, distortion `k1 k2 p1 p2 [k3 [k4 k5 k6]]`.
//!
//! **Image size**: only the single-file YAML layout carries it. For the
//! other layouts the caller passes the size of the haul's first frame to
//! [`StereoCalib::load`]; when neither is there the error names the
//! `image_width` key.
//!
//! Every malformed or inconsistent value is an [`InputError`] naming the
//! file and the key: wrong shape, NaN/inf, camera matrix with `fx, fy ≤ 0`
//! or a bad last row, distortion vectors other than 4, 5 or 8 coefficients,
//! `R` not a rotation (`‖RᵀR − I‖∞ > 1e-6` or `det R ≠ +1`), zero baseline.

pub mod npz;
pub mod yaml;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};

use crate::error::InputError;

/// Tolerance of the rotation test on `R` (orthonormality and `det = +1`).
pub const ROTATION_TOL: f64 = 1e-6;

/// Smallest accepted baseline `‖T‖` in millimetres.
pub const MIN_BASELINE_MM: f64 = 1e-6;

/// Largest image side: the core's remap tables hold `i16` coordinates.
pub const MAX_IMAGE_SIDE: u32 = i16::MAX as u32;

/// A calibrated stereo pair (OpenCV `stereoCalibrate` conventions).
#[derive(Debug, Clone, PartialEq)]
pub struct StereoCalib {
    /// Raw image width in pixels.
    pub width: u32,
    /// Raw image height in pixels.
    pub height: u32,
    /// Left camera matrix `[fx 0 cx; 0 fy cy; 0 0 1]`.
    pub m1: Matrix3<f64>,
    /// Left distortion `k1 k2 p1 p2 [k3 [k4 k5 k6]]` (4, 5 or 8 values).
    pub d1: Vec<f64>,
    /// Right camera matrix.
    pub m2: Matrix3<f64>,
    /// Right distortion coefficients.
    pub d2: Vec<f64>,
    /// Rotation from the left to the right camera frame.
    pub r: Matrix3<f64>,
    /// Translation (mm): `X_right = R·X_left + T`.
    pub t: Vector3<f64>,
}

/// A matrix-valued item taken from a calibration file, with where it came from.
#[derive(Debug, Clone)]
struct Item {
    file: PathBuf,
    key: String,
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

/// The raw parts of a calibration, before validation.
struct Parts {
    size: Option<(Item, Item)>,
    m1: Item,
    d1: Item,
    m2: Item,
    d2: Item,
    r: Item,
    t: Item,
}

const M1_KEYS: &[&str] = &["M1", "cameraMatrixL", "cameraMatrix1"];
const M2_KEYS: &[&str] = &["M2", "cameraMatrixR", "cameraMatrix2"];
const D1_KEYS: &[&str] = &["D1", "distCoeffsL", "distCoeffs1"];
const D2_KEYS: &[&str] = &["D2", "distCoeffsR", "distCoeffs2"];
const R_KEYS: &[&str] = &["R"];
const T_KEYS: &[&str] = &["T"];

fn missing(file: &Path, names: &[&str]) -> InputError {
    let also = if names.len() > 1 {
        format!(" (also looked for {})", names[1..].join(", "))
    } else {
        String::new()
    };
    InputError::key(file, names[0], format!("missing{also}"))
}

/// Looks a YAML matrix up under any of its names.
fn yaml_item(
    file: &Path,
    map: &BTreeMap<String, yaml::Node>,
    names: &[&str],
) -> Result<Option<Item>, InputError> {
    let found: Vec<&&str> = names.iter().filter(|n| map.contains_key(**n)).collect();
    if found.len() > 1 {
        return Err(InputError::key(
            file,
            found[1],
            format!("given twice, also as `{}`", found[0]),
        ));
    }
    let Some(name) = found.first() else {
        return Ok(None);
    };
    match &map[**name] {
        yaml::Node::Matrix { rows, cols, data } => Ok(Some(Item {
            file: file.to_path_buf(),
            key: name.to_string(),
            rows: *rows,
            cols: *cols,
            data: data.clone(),
        })),
        yaml::Node::Number(v) => Ok(Some(Item {
            file: file.to_path_buf(),
            key: name.to_string(),
            rows: 1,
            cols: 1,
            data: vec![*v],
        })),
        _ => Err(InputError::key(
            file,
            name,
            "expected an !!opencv-matrix or a number",
        )),
    }
}

fn yaml_required(
    file: &Path,
    map: &BTreeMap<String, yaml::Node>,
    names: &[&str],
) -> Result<Item, InputError> {
    yaml_item(file, map, names)?.ok_or_else(|| missing(file, names))
}

fn read_yaml(file: &Path) -> Result<BTreeMap<String, yaml::Node>, InputError> {
    let text = std::fs::read(file)
        .map_err(|e| InputError::file(file, format!("cannot read calibration: {e}")))?;
    let text = String::from_utf8(text)
        .map_err(|_| InputError::file(file, "calibration file is not UTF-8 text"))?;
    yaml::parse(file, &text)
}

fn yaml_size(
    file: &Path,
    map: &BTreeMap<String, yaml::Node>,
) -> Result<Option<(Item, Item)>, InputError> {
    let w = yaml_item(file, map, &["image_width"])?;
    let h = yaml_item(file, map, &["image_height"])?;
    match (w, h) {
        (Some(w), Some(h)) => Ok(Some((w, h))),
        (None, None) => Ok(None),
        (Some(_), None) => Err(missing(file, &["image_height"])),
        (None, Some(_)) => Err(missing(file, &["image_width"])),
    }
}

impl StereoCalib {
    /// Loads a calibration from `path`: a `.yml`/`.yaml` FileStorage file, a
    /// `.npz` file, or a directory holding `calibration.yml`, or
    /// `intrinsics.yml` and `extrinsics.yml`, or `cal.npz` (tried in that
    /// order). `frame_size` (width, height of the raw frames) is used when
    /// the layout does not record the image size; a size in the file wins.
    pub fn load(path: &Path, frame_size: Option<(u32, u32)>) -> Result<StereoCalib, InputError> {
        let parts = if path.is_dir() {
            let single = path.join("calibration.yml");
            let intr = path.join("intrinsics.yml");
            let extr = path.join("extrinsics.yml");
            let npz = path.join("cal.npz");
            if single.is_file() {
                parts_from_single_yaml(&single)?
            } else if intr.is_file() || extr.is_file() {
                if !intr.is_file() {
                    return Err(InputError::file(
                        &intr,
                        "missing (extrinsics.yml is there, its intrinsics.yml partner is not)",
                    ));
                }
                if !extr.is_file() {
                    return Err(InputError::file(
                        &extr,
                        "missing (intrinsics.yml is there, its extrinsics.yml partner is not)",
                    ));
                }
                parts_from_pair(&intr, &extr)?
            } else if npz.is_file() {
                parts_from_npz(&npz)?
            } else {
                return Err(InputError::file(
                    path,
                    "no calibration found: expected calibration.yml, intrinsics.yml + extrinsics.yml, or cal.npz",
                ));
            }
        } else if !path.exists() {
            return Err(InputError::file(path, "calibration file does not exist"));
        } else {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("")
                .to_ascii_lowercase();
            if ext == "npz" {
                parts_from_npz(path)?
            } else if name == "intrinsics.yml" || name == "extrinsics.yml" {
                let dir = path.parent().unwrap_or(Path::new("."));
                parts_from_pair(&dir.join("intrinsics.yml"), &dir.join("extrinsics.yml"))?
            } else {
                parts_from_single_yaml(path)?
            }
        };
        build(parts, frame_size)
    }

    /// The calibration as an OpenCV FileStorage YAML text (`%YAML:1.0`,
    /// `image_width`, `image_height`, `M1 D1 M2 D2 R T` as `!!opencv-matrix`
    /// doubles, distortion as `1 × N`), readable by `cv2.FileStorage` and by
    /// [`StereoCalib::load`] (bit-exact round trip).
    pub fn to_yaml(&self) -> String {
        let mut s = yaml::header();
        yaml::write_int(&mut s, "image_width", self.width as i64);
        yaml::write_int(&mut s, "image_height", self.height as i64);
        let rm = |m: &Matrix3<f64>| -> Vec<f64> {
            (0..3)
                .flat_map(|r| (0..3).map(move |c| m[(r, c)]))
                .collect()
        };
        yaml::write_matrix(&mut s, "M1", 3, 3, &rm(&self.m1));
        yaml::write_matrix(&mut s, "D1", 1, self.d1.len(), &self.d1);
        yaml::write_matrix(&mut s, "M2", 3, 3, &rm(&self.m2));
        yaml::write_matrix(&mut s, "D2", 1, self.d2.len(), &self.d2);
        yaml::write_matrix(&mut s, "R", 3, 3, &rm(&self.r));
        yaml::write_matrix(&mut s, "T", 3, 1, self.t.as_slice());
        s
    }

    /// Writes [`StereoCalib::to_yaml`] to `path` atomically (temp file + rename).
    pub fn write_yaml(&self, path: &Path) -> std::io::Result<()> {
        let dir = path.parent().unwrap_or(Path::new("."));
        let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
        std::io::Write::write_all(&mut tmp, self.to_yaml().as_bytes())?;
        tmp.persist(path).map_err(|e| e.error)?;
        Ok(())
    }

    /// Baseline length `‖T‖` in millimetres.
    pub fn baseline_mm(&self) -> f64 {
        self.t.norm()
    }

    /// Distortion coefficients padded to the 8 of the rational model.
    pub fn dist8(d: &[f64]) -> [f64; 8] {
        let mut k = [0.0; 8];
        for (o, v) in k.iter_mut().zip(d) {
            *o = *v;
        }
        k
    }
}

fn parts_from_single_yaml(file: &Path) -> Result<Parts, InputError> {
    let map = read_yaml(file)?;
    Ok(Parts {
        size: yaml_size(file, &map)?,
        m1: yaml_required(file, &map, M1_KEYS)?,
        d1: yaml_required(file, &map, D1_KEYS)?,
        m2: yaml_required(file, &map, M2_KEYS)?,
        d2: yaml_required(file, &map, D2_KEYS)?,
        r: yaml_required(file, &map, R_KEYS)?,
        t: yaml_required(file, &map, T_KEYS)?,
    })
}

fn parts_from_pair(intr: &Path, extr: &Path) -> Result<Parts, InputError> {
    let im = read_yaml(intr)?;
    let em = read_yaml(extr)?;
    let size = match yaml_size(intr, &im)? {
        Some(s) => Some(s),
        None => yaml_size(extr, &em)?,
    };
    Ok(Parts {
        size,
        m1: yaml_required(intr, &im, M1_KEYS)?,
        d1: yaml_required(intr, &im, D1_KEYS)?,
        m2: yaml_required(intr, &im, M2_KEYS)?,
        d2: yaml_required(intr, &im, D2_KEYS)?,
        r: yaml_required(extr, &em, R_KEYS)?,
        t: yaml_required(extr, &em, T_KEYS)?,
    })
}

fn parts_from_npz(file: &Path) -> Result<Parts, InputError> {
    let arrays = npz::read_npz(file)?;
    let get = |names: &[&str]| -> Result<Item, InputError> {
        let name = names
            .iter()
            .find(|n| arrays.contains_key(**n))
            .ok_or_else(|| missing(file, names))?;
        let a = &arrays[*name];
        Ok(Item {
            file: file.to_path_buf(),
            key: name.to_string(),
            rows: a.rows,
            cols: a.cols,
            data: a.data.clone(),
        })
    };
    let size = match (arrays.get("image_width"), arrays.get("image_height")) {
        (Some(_), Some(_)) => Some((get(&["image_width"])?, get(&["image_height"])?)),
        _ => None,
    };
    Ok(Parts {
        size,
        m1: get(&["cameraMatrixL", "M1", "cameraMatrix1"])?,
        d1: get(&["distCoeffsL", "D1", "distCoeffs1"])?,
        m2: get(&["cameraMatrixR", "M2", "cameraMatrix2"])?,
        d2: get(&["distCoeffsR", "D2", "distCoeffs2"])?,
        r: get(R_KEYS)?,
        t: get(T_KEYS)?,
    })
}

impl Item {
    fn err(&self, msg: impl Into<String>) -> InputError {
        InputError::key(&self.file, &self.key, msg)
    }

    fn finite(&self) -> Result<(), InputError> {
        if let Some(i) = self.data.iter().position(|v| !v.is_finite()) {
            return Err(self.err(format!(
                "value #{} is {} (must be a finite number)",
                i + 1,
                self.data[i]
            )));
        }
        Ok(())
    }

    fn matrix3(&self) -> Result<Matrix3<f64>, InputError> {
        if (self.rows, self.cols) != (3, 3) {
            return Err(self.err(format!(
                "must be a 3x3 matrix, found {}x{}",
                self.rows, self.cols
            )));
        }
        self.finite()?;
        Ok(Matrix3::from_row_slice(&self.data))
    }

    fn vector(&self, allowed: &[usize], what: &str) -> Result<Vec<f64>, InputError> {
        let n = self.data.len();
        if !(self.rows == 1 || self.cols == 1) || !allowed.contains(&n) {
            return Err(self.err(format!(
                "must be a 1xN or Nx1 {what} with N in {allowed:?}, found {}x{}",
                self.rows, self.cols
            )));
        }
        self.finite()?;
        Ok(self.data.clone())
    }

    fn positive_int(&self) -> Result<u32, InputError> {
        let v = self.data.first().copied().unwrap_or(f64::NAN);
        if self.data.len() != 1 || !(v >= 1.0 && v <= MAX_IMAGE_SIDE as f64 && v.fract() == 0.0) {
            return Err(self.err(format!(
                "must be a positive whole number of pixels up to {MAX_IMAGE_SIDE}, found {v}"
            )));
        }
        Ok(v as u32)
    }
}

fn camera_matrix(item: &Item) -> Result<Matrix3<f64>, InputError> {
    let m = item.matrix3()?;
    let (fx, fy) = (m[(0, 0)], m[(1, 1)]);
    if fx <= 0.0 || fy <= 0.0 {
        return Err(item.err(format!(
            "invalid camera matrix: focal lengths fx = {fx}, fy = {fy} must be > 0 (singular or not a camera matrix)"
        )));
    }
    if m[(1, 0)] != 0.0 || m[(2, 0)] != 0.0 || m[(2, 1)] != 0.0 || m[(2, 2)] != 1.0 {
        return Err(item.err("invalid camera matrix: expected the form [fx 0 cx; 0 fy cy; 0 0 1]"));
    }
    if m[(0, 1)] != 0.0 {
        return Err(item.err(format!(
            "camera matrix skew {} is not supported (must be 0, as OpenCV calibrates)",
            m[(0, 1)]
        )));
    }
    Ok(m)
}

/// 4, 5 or 8 coefficients; the 12 or 14 of OpenCV's thin-prism and tilted
/// models are accepted when those extra terms are zero (and dropped).
fn distortion(item: &Item) -> Result<Vec<f64>, InputError> {
    let mut d = item.vector(&[4, 5, 8, 12, 14], "distortion vector")?;
    if d.len() > 8 {
        if d[8..].iter().any(|v| *v != 0.0) {
            return Err(item.err(
                "thin-prism (s1..s4) and tilt (tau_x, tau_y) coefficients are not supported: coefficients 9 and up must be 0",
            ));
        }
        d.truncate(8);
    }
    Ok(d)
}

fn rotation(item: &Item) -> Result<Matrix3<f64>, InputError> {
    let r = item.matrix3()?;
    let dev = (r.transpose() * r - Matrix3::identity()).abs().max();
    if dev > ROTATION_TOL {
        return Err(item.err(format!(
            "not a rotation matrix: R^T R differs from the identity by {dev:.3e} (tolerance {ROTATION_TOL:e})"
        )));
    }
    let det = r.determinant();
    if (det - 1.0).abs() > ROTATION_TOL {
        return Err(item.err(format!(
            "not a rotation matrix: determinant is {det:.9} (must be +1)"
        )));
    }
    Ok(r)
}

fn build(parts: Parts, frame_size: Option<(u32, u32)>) -> Result<StereoCalib, InputError> {
    let (width, height) = match &parts.size {
        Some((w, h)) => (w.positive_int()?, h.positive_int()?),
        None => match frame_size {
            Some((w, h)) if w > 0 && h > 0 && w <= MAX_IMAGE_SIDE && h <= MAX_IMAGE_SIDE => (w, h),
            Some((w, h)) if w > 0 && h > 0 => {
                return Err(InputError::plain(
                    format!("frame size {w}x{h}"),
                    format!("larger than the {MAX_IMAGE_SIDE}-pixel sides FishTrack supports"),
                ))
            }
            _ => {
                return Err(InputError::key(
                    &parts.m1.file,
                    "image_width",
                    "missing, and no frame size was given to take it from",
                ))
            }
        },
    };
    let m1 = camera_matrix(&parts.m1)?;
    let d1 = distortion(&parts.d1)?;
    let m2 = camera_matrix(&parts.m2)?;
    let d2 = distortion(&parts.d2)?;
    let r = rotation(&parts.r)?;
    let t = Vector3::from_column_slice(&parts.t.vector(&[3], "translation vector")?);
    if t.norm() < MIN_BASELINE_MM {
        return Err(parts.t.err(format!(
            "zero baseline: |T| = {:e} mm (the cameras must be apart)",
            t.norm()
        )));
    }
    Ok(StereoCalib {
        width,
        height,
        m1,
        d1,
        m2,
        d2,
        r,
        t,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> StereoCalib {
        StereoCalib {
            width: 640,
            height: 480,
            m1: Matrix3::new(500.0, 0.0, 319.5, 0.0, 501.0, 239.5, 0.0, 0.0, 1.0),
            d1: vec![-0.1, 0.01, 0.001, -0.0005, 0.0],
            m2: Matrix3::new(505.0, 0.0, 321.0, 0.0, 504.0, 240.5, 0.0, 0.0, 1.0),
            d2: vec![-0.12, 0.02, 0.0, 0.0],
            r: *nalgebra::Rotation3::from_euler_angles(0.01, -0.03, 0.002).matrix(),
            t: Vector3::new(-100.0, 0.5, 1.0),
        }
    }

    #[test]
    fn yaml_writer_round_trips_bit_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let c = sample();
        let p = dir.path().join("calibration.yml");
        c.write_yaml(&p).unwrap();
        assert_eq!(StereoCalib::load(&p, None).unwrap(), c);
        assert_eq!(StereoCalib::load(dir.path(), None).unwrap(), c);
    }

    #[test]
    fn zero_thin_prism_and_tilt_terms_are_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("calibration.yml");
        let mut c = sample();
        c.d2 = vec![
            -0.1, 0.02, 0.001, 0.0, 0.01, 0.001, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        ];
        std::fs::write(&p, c.to_yaml()).unwrap();
        let got = StereoCalib::load(&p, None).unwrap();
        assert_eq!(got.d2, c.d2[..8].to_vec());
    }

    #[test]
    fn size_comes_from_the_frame_when_the_file_has_none() {
        let dir = tempfile::tempdir().unwrap();
        let c = sample();
        let text = c
            .to_yaml()
            .replace("image_width: 640\n", "")
            .replace("image_height: 480\n", "");
        let p = dir.path().join("calibration.yml");
        std::fs::write(&p, text).unwrap();
        let e = StereoCalib::load(&p, None).unwrap_err().to_string();
        assert!(
            e.contains("`image_width`") && e.contains("calibration.yml"),
            "{e}"
        );
        let got = StereoCalib::load(&p, Some((640, 480))).unwrap();
        assert_eq!(got, c);
    }

    #[test]
    fn bad_values_name_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("calibration.yml");
        let check = |c: &StereoCalib, key: &str, what: &str| {
            std::fs::write(&p, c.to_yaml()).unwrap();
            let e = StereoCalib::load(&p, None).unwrap_err().to_string();
            assert!(
                e.contains(&format!("`{key}`"))
                    && e.contains("calibration.yml")
                    && e.contains(what),
                "{e}"
            );
        };
        let mut c = sample();
        c.r[(0, 0)] += 1e-3;
        check(&c, "R", "not a rotation");
        let mut c = sample();
        c.r = -c.r; // orthonormal, det -1
        check(&c, "R", "determinant");
        let mut c = sample();
        c.t = Vector3::zeros();
        check(&c, "T", "zero baseline");
        let mut c = sample();
        c.d2[1] = f64::NAN;
        check(&c, "D2", "finite");
        let mut c = sample();
        c.m2[(1, 1)] = 0.0;
        check(&c, "M2", "fy = 0");
        let mut c = sample();
        c.d1 = vec![0.1; 6];
        check(&c, "D1", "1xN or Nx1");
        let mut c = sample();
        c.d1 = vec![0.1; 9];
        check(&c, "D1", "1xN or Nx1");
        let mut c = sample();
        c.d1 = vec![0.0; 14];
        c.d1[9] = 1e-3;
        check(&c, "D1", "thin-prism");
        let mut c = sample();
        c.width = 0;
        check(&c, "image_width", "positive");
        let mut c = sample();
        c.height = 40000;
        check(&c, "image_height", "up to 32767");
    }
}
