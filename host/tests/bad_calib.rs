//! Malformed or inconsistent calibrations are refused with an `InputError`
//! whose message names the file and the key, in every layout (single
//! `calibration.yml`, `intrinsics.yml` + `extrinsics.yml`, `cal.npz`).

use std::io::Write;
use std::path::Path;

use fishtrack::calib::StereoCalib;
use fishtrack::InputError;
use nalgebra::{Matrix3, Rotation3, Vector3};

fn good() -> StereoCalib {
    StereoCalib {
        width: 640,
        height: 480,
        m1: Matrix3::new(800.0, 0.0, 320.5, 0.0, 801.0, 239.0, 0.0, 0.0, 1.0),
        d1: vec![-0.2, 0.05, 0.001, -0.001, 0.0],
        m2: Matrix3::new(805.0, 0.0, 318.0, 0.0, 803.5, 242.0, 0.0, 0.0, 1.0),
        d2: vec![-0.21, 0.06, 0.0, 0.0, 0.01],
        r: *Rotation3::from_euler_angles(0.01, -0.05, 0.003).matrix(),
        t: Vector3::new(-120.0, 0.4, 2.0),
    }
}

fn row_major(m: &Matrix3<f64>) -> Vec<f64> {
    (0..3)
        .flat_map(|r| (0..3).map(move |c| m[(r, c)]))
        .collect()
}

/// The YAML block of `key` removed from a FileStorage text.
fn drop_key(text: &str, key: &str) -> String {
    let mut out = String::new();
    let mut skipping = false;
    for line in text.lines() {
        if !line.starts_with(' ') {
            skipping = line.starts_with(&format!("{key}:"));
        }
        if !skipping {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The pair layout: intrinsics.yml (M1 D1 M2 D2) + extrinsics.yml (R T).
fn write_pair(dir: &Path, c: &StereoCalib) {
    let full = c.to_yaml();
    let mut intr = full.clone();
    for k in ["image_width", "image_height", "R", "T"] {
        intr = drop_key(&intr, k);
    }
    let mut extr = full;
    for k in ["image_width", "image_height", "M1", "D1", "M2", "D2"] {
        extr = drop_key(&extr, k);
    }
    std::fs::write(dir.join("intrinsics.yml"), intr).unwrap();
    std::fs::write(dir.join("extrinsics.yml"), extr).unwrap();
}

fn npy(rows: usize, cols: usize, data: &[f64]) -> Vec<u8> {
    let shape = if rows == 1 {
        format!("({cols},)")
    } else {
        format!("({rows}, {cols})")
    };
    let mut h = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut v = b"\x93NUMPY\x01\x00".to_vec();
    v.extend_from_slice(&(h.len() as u16).to_le_bytes());
    v.extend_from_slice(h.as_bytes());
    for x in data {
        v.extend_from_slice(&x.to_le_bytes());
    }
    v
}

/// The VIAME layout, `cal.npz`, with an optional key left out.
fn write_npz(path: &Path, c: &StereoCalib, skip: Option<&str>) {
    let file = std::fs::File::create(path).unwrap();
    let mut zip = zip::ZipWriter::new(file);
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let items: Vec<(&str, Vec<u8>)> = vec![
        ("cameraMatrixL", npy(3, 3, &row_major(&c.m1))),
        ("cameraMatrixR", npy(3, 3, &row_major(&c.m2))),
        ("distCoeffsL", npy(1, c.d1.len(), &c.d1)),
        ("distCoeffsR", npy(1, c.d2.len(), &c.d2)),
        ("R", npy(3, 3, &row_major(&c.r))),
        ("T", npy(3, 1, c.t.as_slice())),
    ];
    for (k, bytes) in items {
        if Some(k) == skip {
            continue;
        }
        zip.start_file(format!("{k}.npy"), opts).unwrap();
        zip.write_all(&bytes).unwrap();
    }
    zip.finish().unwrap();
}

fn assert_names(e: &InputError, file: &str, key: &str, what: &str) {
    let s = e.to_string();
    assert!(
        s.contains(file) && s.contains(&format!("key `{key}`")) && s.contains(what),
        "expected file {file}, key `{key}`, `{what}` in: {s}"
    );
}

/// A bad calibration (as a model, or as a text edit of the single file)
/// and what its error must say.
struct Case {
    name: &'static str,
    calib: StereoCalib,
    edit: fn(String) -> String,
    yaml_key: &'static str,
    npz_key: &'static str,
    pair_file: &'static str,
    what: &'static str,
}

fn same(s: String) -> String {
    s
}

fn cases() -> Vec<Case> {
    let mut non_rotation = good();
    non_rotation.r[(0, 1)] += 0.01;
    let mut zero_baseline = good();
    zero_baseline.t = Vector3::zeros();
    let mut nan_d2 = good();
    nan_d2.d2[2] = f64::NAN;
    let mut singular_m2 = good();
    singular_m2.m2 = Matrix3::zeros();
    let mut mirrored_r = good();
    mirrored_r.r = -mirrored_r.r;
    vec![
        Case {
            name: "non-rotation R",
            calib: non_rotation,
            edit: same,
            yaml_key: "R",
            npz_key: "R",
            pair_file: "extrinsics.yml",
            what: "not a rotation",
        },
        Case {
            name: "reflection R (det -1)",
            calib: mirrored_r,
            edit: same,
            yaml_key: "R",
            npz_key: "R",
            pair_file: "extrinsics.yml",
            what: "determinant",
        },
        Case {
            name: "zero baseline",
            calib: zero_baseline,
            edit: same,
            yaml_key: "T",
            npz_key: "T",
            pair_file: "extrinsics.yml",
            what: "zero baseline",
        },
        Case {
            name: "NaN in D2",
            calib: nan_d2,
            edit: same,
            yaml_key: "D2",
            npz_key: "distCoeffsR",
            pair_file: "intrinsics.yml",
            what: "finite",
        },
        Case {
            name: "singular M2",
            calib: singular_m2,
            edit: same,
            yaml_key: "M2",
            npz_key: "cameraMatrixR",
            pair_file: "intrinsics.yml",
            what: "fx = 0",
        },
        Case {
            name: "wrong shape of M1",
            calib: good(),
            edit: |s| s.replacen("   rows: 3\n   cols: 3\n", "   rows: 1\n   cols: 9\n", 1),
            yaml_key: "M1",
            npz_key: "",
            pair_file: "intrinsics.yml",
            what: "3x3",
        },
        Case {
            name: "missing T",
            calib: good(),
            edit: |s| drop_key(&s, "T"),
            yaml_key: "T",
            npz_key: "",
            pair_file: "extrinsics.yml",
            what: "missing",
        },
    ]
}

#[test]
fn single_yaml_errors_name_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("calibration.yml");
    for c in cases() {
        std::fs::write(&p, (c.edit)(c.calib.to_yaml())).unwrap();
        let e = StereoCalib::load(&p, None).unwrap_err();
        println!("{}: {e}", c.name);
        assert_names(&e, "calibration.yml", c.yaml_key, c.what);
        // loading the directory says the same
        let e2 = StereoCalib::load(dir.path(), None).unwrap_err();
        assert_eq!(e, e2);
    }
}

#[test]
fn pair_errors_name_the_file_holding_the_key() {
    for c in cases() {
        let dir = tempfile::tempdir().unwrap();
        write_pair(dir.path(), &c.calib);
        // apply the text edit to whichever file holds the key
        let f = dir.path().join(c.pair_file);
        let text = std::fs::read_to_string(&f).unwrap();
        std::fs::write(&f, (c.edit)(text)).unwrap();
        let e = StereoCalib::load(dir.path(), Some((640, 480))).unwrap_err();
        assert_names(&e, c.pair_file, c.yaml_key, c.what);
    }
}

#[test]
fn npz_errors_name_file_and_key() {
    for c in cases().into_iter().filter(|c| !c.npz_key.is_empty()) {
        let dir = tempfile::tempdir().unwrap();
        write_npz(&dir.path().join("cal.npz"), &c.calib, None);
        let e = StereoCalib::load(dir.path(), Some((640, 480))).unwrap_err();
        assert_names(&e, "cal.npz", c.npz_key, c.what);
    }
    // a good archive loads; one without T names T
    let dir = tempfile::tempdir().unwrap();
    write_npz(&dir.path().join("cal.npz"), &good(), None);
    assert_eq!(
        StereoCalib::load(dir.path(), Some((640, 480))).unwrap(),
        good()
    );
    write_npz(&dir.path().join("cal.npz"), &good(), Some("T"));
    let e = StereoCalib::load(dir.path(), Some((640, 480))).unwrap_err();
    assert_names(&e, "cal.npz", "T", "missing");
    write_npz(&dir.path().join("cal.npz"), &good(), Some("cameraMatrixR"));
    let e = StereoCalib::load(dir.path(), Some((640, 480))).unwrap_err();
    assert_names(&e, "cal.npz", "cameraMatrixR", "missing");
}

#[test]
fn unreadable_or_absent_calibrations_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let e = StereoCalib::load(dir.path(), None).unwrap_err().to_string();
    assert!(e.contains("no calibration found"), "{e}");
    let p = dir.path().join("calibration.yml");
    std::fs::write(&p, "M1: [1, 2]\n").unwrap();
    let e = StereoCalib::load(&p, None).unwrap_err().to_string();
    assert!(e.contains("calibration.yml") && e.contains("%YAML"), "{e}");
    std::fs::write(&p, "%YAML:1.0\n---\nM1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1, 2, 3,\n").unwrap();
    let e = StereoCalib::load(&p, None).unwrap_err().to_string();
    assert!(e.contains("`M1`") && e.contains("never closed"), "{e}");
    std::fs::remove_file(&p).unwrap();
    std::fs::write(dir.path().join("cal.npz"), b"PK\x03\x04 truncated").unwrap();
    let e = StereoCalib::load(dir.path(), Some((10, 10)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("cal.npz"), "{e}");
    // half of the pair
    let d2 = tempfile::tempdir().unwrap();
    write_pair(d2.path(), &good());
    std::fs::remove_file(d2.path().join("extrinsics.yml")).unwrap();
    let e = StereoCalib::load(d2.path(), Some((640, 480)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("extrinsics.yml") && e.contains("missing"), "{e}");
    let e = StereoCalib::load(&dir.path().join("nope.yml"), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nope.yml") && e.contains("does not exist"),
        "{e}"
    );
}

#[test]
fn good_pair_and_frame_size_load() {
    let dir = tempfile::tempdir().unwrap();
    write_pair(dir.path(), &good());
    assert_eq!(
        StereoCalib::load(dir.path(), Some((640, 480))).unwrap(),
        good()
    );
}
