//! Calibration loading and rectification compared with OpenCV itself.
//!
//! `scripts/opencv_fixtures.py` (cv2 + numpy) writes stereo calibrations in
//! every layout FishTrack reads and OpenCV's own results: `stereoRectify`
//! (`CALIB_ZERO_DISPARITY`, `alpha` = 0, 1 and −1), `initUndistortRectifyMap`
//! and `remap` of a test image (`BORDER_CONSTANT` and `BORDER_REPLICATE`), and
//! `undistortPoints` point pairs. These tests
//! check, for a horizontal 5-coefficient pair, a vertical pair, the
//! 8-coefficient rational model and a 4-coefficient pair:
//! - every layout loads to the same model, equal to the one OpenCV wrote;
//! - `R1 R2 P1 P2 Q` within 1e-6 relative (entries smaller than 1e-3 of the
//!   matrix's largest are compared absolutely against 1e-6 of that 1e-3),
//!   and the valid-pixel rectangles `roi1 roi2` equal, for every alpha;
//! - rectified images within 1 grey level on ≥ 99.9 % of pixels, for the
//!   float remap and for the core's fixed-point remap; the fills of pixels
//!   without a source likewise against `BORDER_REPLICATE` and
//!   `BORDER_REFLECT_101` (the [`Rectifier`]'s);
//! - raw → rectified agrees with `cv2.undistortPoints`, and raw → rectified
//!   → raw returns within 0.05 px.
//!
//! A deliberately wrong calibration (fx + 1 %, or R turned by 1 mrad) must
//! make the same comparisons fail: `wrong_calibration_fails_the_comparisons`.
//!
//! Python with cv2 is required when `FISHTRACK_REQUIRE_PYTHON=1` (CI);
//! otherwise the tests print a skip notice when it is missing.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use fishtrack::calib::StereoCalib;
use fishtrack::rectify::{
    stereo_rectify, stereo_rectify_alpha, Fill, FixedMap, Rectification, RectifiedCamera, Rectifier,
};
use nalgebra::{DMatrix, Matrix3, Vector3};
use serde_json::Value;

const CASES: &[&str] = &["horizontal5", "vertical5", "rational8", "k4"];

struct Fixtures {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

fn fixtures() -> Option<&'static Path> {
    static F: OnceLock<Option<Fixtures>> = OnceLock::new();
    F.get_or_init(|| {
        let required = std::env::var("FISHTRACK_REQUIRE_PYTHON").as_deref() == Ok("1");
        let dir = tempfile::tempdir().expect("tempdir");
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/opencv_fixtures.py");
        let out = Command::new("python3")
            .arg(&script)
            .arg(dir.path())
            .output();
        match out {
            Ok(o) if o.status.success() => Some(Fixtures {
                root: dir.path().to_path_buf(),
                _dir: dir,
            }),
            other => {
                let why = match other {
                    Ok(o) => String::from_utf8_lossy(&o.stderr).to_string(),
                    Err(e) => e.to_string(),
                };
                if required {
                    panic!(
                        "FISHTRACK_REQUIRE_PYTHON=1 but the OpenCV fixture script failed: {why}"
                    );
                }
                eprintln!("SKIP: python3 with cv2/numpy not available ({why})");
                None
            }
        }
    })
    .as_ref()
    .map(|f| f.root.as_path())
}

/// The alphas the fixtures hold, with their file-name suffixes.
const ALPHAS: &[(f64, &str)] = &[(0.0, ""), (1.0, "_a1"), (-1.0, "_am1")];

fn json(case_dir: &Path) -> Value {
    json_tag(case_dir, "")
}

fn json_tag(case_dir: &Path, tag: &str) -> Value {
    let text = std::fs::read_to_string(case_dir.join(format!("reference{tag}.json"))).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn mat(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect();
    DMatrix::from_fn(rows.len(), rows[0].len(), |r, c| rows[r][c])
}

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn dm<R: nalgebra::Dim, C: nalgebra::Dim, S: nalgebra::RawStorage<f64, R, C>>(
    m: &nalgebra::Matrix<f64, R, C, S>,
) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |r, c| m[(r, c)])
}

/// Largest relative error of `got` against `want`; entries below 1e-3 of
/// the largest |entry| use that floor as denominator.
fn rel_err(got: &DMatrix<f64>, want: &DMatrix<f64>) -> f64 {
    let floor = want.amax() * 1e-3;
    got.iter()
        .zip(want.iter())
        .map(|(g, w)| (g - w).abs() / w.abs().max(floor))
        .fold(0.0, f64::max)
}

fn load_gray(p: &Path) -> image::GrayImage {
    image::open(p).unwrap().to_luma8()
}

fn m3(v: &Value) -> Matrix3<f64> {
    let m = mat(v);
    Matrix3::from_fn(|r, c| m[(r, c)])
}

/// True when two models agree to 1e-15 relative: OpenCV's FileStorage
/// writes and reads doubles with an error of a few ulp.
fn same_model(a: &StereoCalib, b: &StereoCalib) -> bool {
    let close = |x: &[f64], y: &[f64]| {
        x.len() == y.len()
            && x.iter()
                .zip(y)
                .all(|(p, q)| (p - q).abs() <= 1e-15 * p.abs().max(q.abs()))
    };
    a.width == b.width
        && a.height == b.height
        && close(a.m1.as_slice(), b.m1.as_slice())
        && close(a.m2.as_slice(), b.m2.as_slice())
        && close(&a.d1, &b.d1)
        && close(&a.d2, &b.d2)
        && close(a.r.as_slice(), b.r.as_slice())
        && close(a.t.as_slice(), b.t.as_slice())
}

fn reference_model(r: &Value) -> StereoCalib {
    StereoCalib {
        width: r["width"].as_u64().unwrap() as u32,
        height: r["height"].as_u64().unwrap() as u32,
        m1: m3(&r["M1"]),
        d1: vec_of(&r["D1"]),
        m2: m3(&r["M2"]),
        d2: vec_of(&r["D2"]),
        r: m3(&r["R"]),
        t: Vector3::from_vec(vec_of(&r["T"])),
    }
}

#[test]
fn every_layout_loads_to_the_same_model() {
    let Some(root) = fixtures() else { return };
    for case in CASES {
        let d = root.join(case);
        let r = json(&d);
        let want = reference_model(&r);
        let size = Some((want.width, want.height));
        let layouts = [
            ("single (dir)", StereoCalib::load(&d.join("single"), None)),
            (
                "single (file)",
                StereoCalib::load(&d.join("single/calibration.yml"), None),
            ),
            (
                "intrinsics+extrinsics",
                StereoCalib::load(&d.join("pair"), size),
            ),
            (
                "extrinsics.yml path",
                StereoCalib::load(&d.join("pair/extrinsics.yml"), size),
            ),
            ("aliases L/R", StereoCalib::load(&d.join("alias_lr"), None)),
            (
                "aliases 1/2, Nx1",
                StereoCalib::load(&d.join("alias_12"), None),
            ),
            ("cal.npz (dir)", StereoCalib::load(&d.join("npz"), size)),
            (
                "cal.npz (file)",
                StereoCalib::load(&d.join("npz/cal.npz"), size),
            ),
        ];
        for (name, got) in layouts {
            let got = got.unwrap_or_else(|e| panic!("{case} {name}: {e}"));
            assert!(
                same_model(&got, &want),
                "{case}: layout {name} differs:\n{got:?}\n{want:?}"
            );
        }
        // the pair and the npz carry no image size
        let e = StereoCalib::load(&d.join("pair"), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("intrinsics.yml") && e.contains("`image_width`"),
            "{e}"
        );
        let e = StereoCalib::load(&d.join("npz"), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cal.npz") && e.contains("`image_width`"), "{e}");
    }
}

#[test]
fn our_yaml_writer_is_read_by_opencv() {
    let Some(root) = fixtures() else { return };
    let c = StereoCalib::load(&root.join("rational8/single"), None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("calibration.yml");
    c.write_yaml(&p).unwrap();
    let code = "import cv2,sys,json\nfs=cv2.FileStorage(sys.argv[1],cv2.FILE_STORAGE_READ)\n\
        print(json.dumps({k:fs.getNode(k).mat().ravel().tolist() for k in ['M1','D1','M2','D2','R','T']}|\
        {'w':fs.getNode('image_width').real(),'h':fs.getNode('image_height').real()}))";
    let out = Command::new("python3")
        .arg("-c")
        .arg(code)
        .arg(&p)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    let m3r = |k: &str| {
        let x = vec_of(&v[k]);
        Matrix3::from_row_slice(&x)
    };
    let read = StereoCalib {
        width: v["w"].as_f64().unwrap() as u32,
        height: v["h"].as_f64().unwrap() as u32,
        m1: m3r("M1"),
        d1: vec_of(&v["D1"]),
        m2: m3r("M2"),
        d2: vec_of(&v["D2"]),
        r: m3r("R"),
        t: Vector3::from_vec(vec_of(&v["T"])),
    };
    assert!(same_model(&read, &c), "{read:?}\n{c:?}");
}

/// The figures of one comparison against OpenCV.
#[derive(Debug, Default)]
struct Figures {
    rel: [f64; 5],
    float_within1: [f64; 2],
    fixed_within1: [f64; 2],
    fixed_exact: [f64; 2],
    replicate_within1: [f64; 2],
    reflect_within1: [f64; 2],
    max_map_diff: f64,
    max_point_err: f64,
    max_round_trip: f64,
}

fn within(a: &image::GrayImage, b: &image::GrayImage, tol: i32) -> f64 {
    let n = a.as_raw().len();
    let ok = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .filter(|(x, y)| (**x as i32 - **y as i32).abs() <= tol)
        .count();
    100.0 * ok as f64 / n as f64
}

fn read_map(p: &Path, w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
    let b = std::fs::read(p).unwrap();
    let f: Vec<f32> = b
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(f.len(), 2 * w * h);
    (f[..w * h].to_vec(), f[w * h..].to_vec())
}

/// Compares everything for one case with `calib` (possibly perturbed);
/// returns the figures and the list of violated tolerances.
fn compare(case_dir: &Path, calib: &StereoCalib) -> (Figures, Vec<String>) {
    compare_alpha(case_dir, calib, 0.0, "")
}

/// [`compare`] for the free scaling `alpha` (fixture files suffixed `tag`).
fn compare_alpha(
    case_dir: &Path,
    calib: &StereoCalib,
    alpha: f64,
    tag: &str,
) -> (Figures, Vec<String>) {
    let r = json_tag(case_dir, tag);
    let rect: Rectification = stereo_rectify_alpha(calib, alpha);
    let mut f = Figures::default();
    let mut fails = Vec::new();
    let got = [
        dm(&rect.r1),
        dm(&rect.r2),
        dm(&rect.p1),
        dm(&rect.p2),
        dm(&rect.q),
    ];
    for (i, name) in ["R1", "R2", "P1", "P2", "Q"].iter().enumerate() {
        f.rel[i] = rel_err(&got[i], &mat(&r[name]));
        if f.rel[i] > 1e-6 {
            fails.push(format!(
                "{name}: max relative error {:.3e} > 1e-6",
                f.rel[i]
            ));
        }
    }
    for (name, got) in [("roi1", rect.roi1), ("roi2", rect.roi2)] {
        let want: Vec<u32> = vec_of(&r[name]).iter().map(|v| *v as u32).collect();
        if got.as_slice() != want.as_slice() {
            fails.push(format!("{name}: {got:?} != OpenCV's {want:?}"));
        }
    }
    let (left, right) = RectifiedCamera::pair(calib, &rect);
    let src = load_gray(&case_dir.join("left.png"));
    let (w, h) = (calib.width as usize, calib.height as usize);
    for (s, (side, cam)) in [("left", &left), ("right", &right)].into_iter().enumerate() {
        let cv = load_gray(&case_dir.join(format!("{side}_rect{tag}.png")));
        let map = cam.float_map();
        let (mx, my) = read_map(&case_dir.join(format!("{side}_map{tag}.f32")), w, h);
        for i in 0..w * h {
            f.max_map_diff = f
                .max_map_diff
                .max((map.map_x[i] - mx[i]).abs() as f64)
                .max((map.map_y[i] - my[i]).abs() as f64);
        }
        let ours = fishtrack::rectify::remap_float(&src, &map);
        f.float_within1[s] = within(&ours, &cv, 1);
        let fixed = FixedMap::from_float(&map).apply(&src).unwrap();
        f.fixed_within1[s] = within(&fixed, &cv, 1);
        f.fixed_exact[s] = within(&fixed, &cv, 0);
        let cv_rep = load_gray(&case_dir.join(format!("{side}_rep{tag}.png")));
        let rep = FixedMap::from_float_fill(&map, Fill::Replicate, calib.width, calib.height)
            .apply(&src)
            .unwrap();
        f.replicate_within1[s] = within(&rep, &cv_rep, 1);
        let cv_ref = load_gray(&case_dir.join(format!("{side}_ref{tag}.png")));
        let refl = FixedMap::from_float_fill(&map, Fill::Reflect101, calib.width, calib.height)
            .apply(&src)
            .unwrap();
        f.reflect_within1[s] = within(&refl, &cv_ref, 1);
        // OpenCV's own fixed-point maps (convertMaps) differ from its float
        // maps by > 1 grey level on 0.3 % of the pixels next to the
        // unmapped region at alpha = 1 (partly outside neighbours): the
        // constant-border fixed-point check is the alpha = 0 one
        let fixed_const = if alpha == 0.0 {
            fixed_pct(&f, s)
        } else {
            100.0
        };
        for (what, v) in [
            ("float", f.float_within1[s]),
            ("fixed-point", fixed_const),
            ("replicated fixed-point", f.replicate_within1[s]),
            ("reflected fixed-point", f.reflect_within1[s]),
        ] {
            if v < 99.9 {
                fails.push(format!(
                    "{side} {what} remap: {v:.3} % of pixels within 1 grey level < 99.9 %"
                ));
            }
        }
        let raw = r[format!("{side}_raw")].as_array().unwrap();
        let cvr = r[format!("{side}_rect")].as_array().unwrap();
        for (p, q) in raw.iter().zip(cvr) {
            let (u, v) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
            let (qu, qv) = (q[0].as_f64().unwrap(), q[1].as_f64().unwrap());
            let Some((ru, rv)) = cam.raw_to_rect(u, v) else {
                fails.push(format!("{side}: raw ({u}, {v}) did not undistort"));
                continue;
            };
            f.max_point_err = f.max_point_err.max((ru - qu).hypot(rv - qv));
            let (bu, bv) = cam.rect_to_raw(ru, rv);
            f.max_round_trip = f.max_round_trip.max((bu - u).hypot(bv - v));
        }
    }
    if f.max_point_err > 0.05 {
        fails.push(format!(
            "raw->rectified differs from cv2.undistortPoints by {:.4} px > 0.05",
            f.max_point_err
        ));
    }
    if f.max_round_trip > 0.05 {
        fails.push(format!(
            "raw->rectified->raw round trip error {:.4} px > 0.05",
            f.max_round_trip
        ));
    }
    (f, fails)
}

fn fixed_pct(f: &Figures, s: usize) -> f64 {
    f.fixed_within1[s]
}

#[test]
fn rectification_remap_and_points_match_opencv() {
    let Some(root) = fixtures() else { return };
    let mut all = Vec::new();
    for &(alpha, tag) in ALPHAS {
        for case in CASES {
            let d = root.join(case);
            let calib = StereoCalib::load(&d.join("single"), None).unwrap();
            let (f, fails) = compare_alpha(&d, &calib, alpha, tag);
            println!(
                "alpha {alpha:2} {case:12} rel R1 {:.1e} R2 {:.1e} P1 {:.1e} P2 {:.1e} Q {:.1e} | map max diff {:.2e} px | \
                 within 1 grey: float L {:.3}% R {:.3}%, fixed L {:.3}% R {:.3}% (exact L {:.2}% R {:.2}%), \
                 replicated L {:.3}% R {:.3}%, reflected L {:.3}% R {:.3}% | points vs cv2 {:.2e} px, round trip {:.2e} px",
                f.rel[0], f.rel[1], f.rel[2], f.rel[3], f.rel[4], f.max_map_diff,
                f.float_within1[0], f.float_within1[1], f.fixed_within1[0], f.fixed_within1[1],
                f.fixed_exact[0], f.fixed_exact[1], f.replicate_within1[0],
                f.replicate_within1[1], f.reflect_within1[0], f.reflect_within1[1],
                f.max_point_err, f.max_round_trip
            );
            all.extend(
                fails
                    .into_iter()
                    .map(|m| format!("alpha {alpha} {case}: {m}")),
            );
        }
    }
    assert!(
        all.is_empty(),
        "disagreements with OpenCV:\n{}",
        all.join("\n")
    );
}

#[test]
fn vertical_case_is_detected_as_vertical() {
    let Some(root) = fixtures() else { return };
    for case in CASES {
        let calib = StereoCalib::load(&root.join(case).join("single"), None).unwrap();
        assert_eq!(
            stereo_rectify(&calib).vertical,
            *case == "vertical5",
            "{case}"
        );
    }
}

#[test]
fn wrong_calibration_fails_the_comparisons() {
    let Some(root) = fixtures() else { return };
    let d = root.join("horizontal5");
    let good = StereoCalib::load(&d.join("single"), None).unwrap();

    let mut fx = good.clone();
    fx.m1[(0, 0)] *= 1.01;
    let (_, fails) = compare(&d, &fx);
    println!("fx + 1 %:\n  {}", fails.join("\n  "));
    assert!(fails.iter().any(|m| m.starts_with("P1")), "{fails:?}");
    assert!(fails.iter().any(|m| m.contains("remap")), "{fails:?}");
    assert!(
        fails.iter().any(|m| m.contains("undistortPoints")),
        "{fails:?}"
    );

    let mut rot = good.clone();
    let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 1e-3);
    rot.r = turn.matrix() * good.r;
    let (_, fails) = compare(&d, &rot);
    println!("R turned by 1 mrad:\n  {}", fails.join("\n  "));
    assert!(fails.iter().any(|m| m.starts_with("R1")), "{fails:?}");
    assert!(fails.iter().any(|m| m.contains("remap")), "{fails:?}");
}

#[test]
fn rectifier_and_box_mapping_agree_with_opencv_points() {
    let Some(root) = fixtures() else { return };
    let d = root.join("horizontal5");
    let calib = StereoCalib::load(&d.join("single"), None).unwrap();
    for &(alpha, tag) in ALPHAS {
        check_rectifier(&d, &calib, alpha, tag);
    }
}

fn check_rectifier(d: &Path, calib: &StereoCalib, alpha: f64, tag: &str) {
    let rectifier = Rectifier::with_alpha(calib, alpha);
    let img = load_gray(&d.join("left.png"));
    let (l, r) = rectifier.rectify_pair(&img, &img).unwrap();
    // the Rectifier fills pixels without a source as BORDER_REFLECT_101 does
    let (wl, wr) = (
        within(&l, &load_gray(&d.join(format!("left_ref{tag}.png"))), 1),
        within(&r, &load_gray(&d.join(format!("right_ref{tag}.png"))), 1),
    );
    assert!(wl >= 99.9 && wr >= 99.9, "alpha {alpha}: {wl} {wr}");
    if alpha == 0.0 {
        // no pixel without a source: the same as BORDER_CONSTANT
        assert!(within(&l, &load_gray(&d.join("left_rect.png")), 1) >= 99.9);
        assert!(within(&r, &load_gray(&d.join("right_rect.png")), 1) >= 99.9);
    }
    assert!(rectifier
        .rectify_pair(&img, &image::GrayImage::new(3, 3))
        .is_err());

    // A rectified box around OpenCV's rectified points maps back to a raw
    // box holding the raw points.
    let j = json_tag(d, tag);
    let raw = j["left_raw"].as_array().unwrap();
    let rect = j["left_rect"].as_array().unwrap();
    for k in (0..raw.len() - 9).step_by(10) {
        let pts: Vec<(f64, f64)> = (k..k + 3)
            .map(|i| (rect[i][0].as_f64().unwrap(), rect[i][1].as_f64().unwrap()))
            .collect();
        let x0 = pts.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let x1 = pts.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let y0 = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let y1 = pts.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        let b = rectifier.left.rect_box_to_raw(x0, y0, x1, y1);
        for p in &raw[k..k + 3] {
            let (u, v) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
            assert!(
                u >= b.0 - 0.05 && u <= b.2 + 0.05 && v >= b.1 - 0.05 && v <= b.3 + 0.05,
                "raw point ({u}, {v}) outside mapped box {b:?}"
            );
        }
    }
}
