//! Drawn test frames for the segmentation tests: fish-like ellipses with a
//! dim tail and stripes, an illumination ramp, noise and a diagonal mesh.
#![allow(dead_code)]

/// A drawn fish.
#[derive(Clone, Copy, Debug)]
pub struct Fish {
    pub cx: f32,
    pub cy: f32,
    pub a: f32,
    pub b: f32,
    pub angle: f32,
    pub contrast: f32,
}

pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn gauss(&mut self) -> f32 {
        (self.next() + self.next() + self.next() + self.next() - 2.0) * 1.732
    }
}

pub fn draw(w: usize, h: usize, fish: &[Fish], noise: f32, mesh: bool, seed: u64) -> Vec<u8> {
    let mut rng = Lcg(seed);
    let mut img = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let base = 50.0 + 30.0 * x as f32 / w as f32;
            let mut v = base;
            if mesh
                && (y < h / 6 || y > 5 * h / 6)
                && ((x + y) % 24 < 2 || (x + 4 * (w + h) - y) % 24 < 2)
            {
                v += 90.0;
            }
            for f in fish {
                let (dx, dy) = (x as f32 - f.cx, y as f32 - f.cy);
                let (c, s) = (f.angle.cos(), f.angle.sin());
                let u = dx * c + dy * s;
                let vv = -dx * s + dy * c;
                if u * u / (f.a * f.a) + vv * vv / (f.b * f.b) <= 1.0 {
                    let tail = if u < -f.a / 3.0 { 0.6 } else { 1.0 };
                    let stripe = if ((u / 4.0) as i32) % 2 == 0 {
                        6.0
                    } else {
                        -6.0
                    };
                    v = base + f.contrast * tail + stripe;
                }
            }
            v += noise * rng.gauss();
            img[y * w + x] = v.clamp(0.0, 255.0) as u8;
        }
    }
    img
}

/// A random school of `n` non-overlapping fish in a `w × h` frame.
pub fn school(w: usize, h: usize, n: usize, seed: u64) -> Vec<Fish> {
    let mut rng = Lcg(seed ^ 0x9e37_79b9_7f4a_7c15);
    let s = w as f32 / 512.0;
    let mut out: Vec<Fish> = Vec::new();
    let mut tries = 0;
    while out.len() < n && tries < 1000 {
        tries += 1;
        let a = (35.0 + 40.0 * rng.next()) * s;
        let f = Fish {
            cx: a + 10.0 + rng.next() * (w as f32 - 2.0 * a - 20.0),
            cy: h as f32 * (0.25 + 0.5 * rng.next()),
            a,
            b: a * (0.22 + 0.08 * rng.next()),
            angle: rng.next() * std::f32::consts::TAU,
            contrast: 40.0 + 40.0 * rng.next(),
        };
        if out
            .iter()
            .all(|g| ((g.cx - f.cx).powi(2) + (g.cy - f.cy).powi(2)).sqrt() > g.a + f.a + 10.0)
        {
            out.push(f);
        }
    }
    out
}

/// Writes a binary PGM (P5).
pub fn write_pgm(path: &std::path::Path, w: usize, h: usize, px: &[u8]) {
    let mut data = format!("P5\n{w} {h}\n255\n").into_bytes();
    data.extend_from_slice(px);
    std::fs::write(path, data).unwrap();
}

/// Reads a binary PGM (P5) written by OpenCV.
pub fn read_pgm(path: &std::path::Path) -> (usize, usize, Vec<u8>) {
    let data = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 {
        while data[i].is_ascii_whitespace() {
            i += 1;
        }
        if data[i] == b'#' {
            while data[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        let s = i;
        while !data[i].is_ascii_whitespace() {
            i += 1;
        }
        fields.push(String::from_utf8_lossy(&data[s..i]).to_string());
    }
    assert_eq!(fields[0], "P5");
    let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    (w, h, data[i + 1..i + 1 + w * h].to_vec())
}

/// Runs `python3 script args`; `None` (skip) when python or cv2 is
/// missing, unless FISHTRACK_REQUIRE_PYTHON=1.
pub fn run_python(script: &str, args: &[&std::path::Path]) -> Option<()> {
    let require = std::env::var("FISHTRACK_REQUIRE_PYTHON").is_ok_and(|v| v == "1");
    let probe = std::process::Command::new("python3")
        .args(["-c", "import cv2, numpy"])
        .output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        if require {
            panic!("python3 with cv2/numpy is required (FISHTRACK_REQUIRE_PYTHON=1): {probe:?}");
        }
        eprintln!("SKIP: python3 with cv2/numpy not available");
        return None;
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("scripts")
        .join(script);
    let out = std::process::Command::new("python3")
        .arg(&path)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(())
}
