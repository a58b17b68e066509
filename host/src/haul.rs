//! Reading a haul directory (DESIGN.md, "Input: a haul directory").
//!
//! ```text
//! HAUL/
//!   left/   000001.png 000002.png …   PNG, JPEG or TIFF, paired by file name
//!   right/  000001.png 000002.png …
//!   calibration.yml                   (located here, parsed by `calib`)
//! ```
//!
//! Conventions:
//! - A frame is a regular file in `left/` or `right/` whose extension is an
//!   image extension (`png`, `jpg`, `jpeg`, `tif`, `tiff`, any case). Hidden
//!   files (name starting with `.`), sub-directories and files with any other
//!   extension are ignored. A file with an image extension that does not hold
//!   a readable image is an error, never skipped.
//! - Frames are paired by their full file name; a name present on one side
//!   only is an error naming that file.
//! - Pairs are ordered by name, numeric-aware (`2.png` before `10.png`), and
//!   numbered from 1 as in `tracks.csv`.
//! - Pixels are loaded as 8-bit grey, see [`load_gray`] for the conversion
//!   rules (colour → BT.601 luma as `cv2.COLOR_BGR2GRAY`, 16-bit → `>> 8`).

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};

use image::{DynamicImage, GrayImage, ImageFormat};

use crate::error::InputError;

/// File extensions (lower case) that are read as frames.
pub const IMAGE_EXTENSIONS: [&str; 5] = ["png", "jpg", "jpeg", "tif", "tiff"];

/// One stereo frame pair of a haul.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramePair {
    /// Frame number, from 1, in numeric-aware name order.
    pub index: u32,
    /// The shared file name (e.g. `000001.png`).
    pub name: String,
    /// Path of the left image.
    pub left: PathBuf,
    /// Path of the right image.
    pub right: PathBuf,
}

/// Where a haul's stereo calibration lives (located, not parsed).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CalibrationSource {
    /// `HAUL/calibration.yml`, OpenCV FileStorage YAML (the design's format).
    OpenCvYaml(PathBuf),
    /// OpenCV `stereo_calib` output: `HAUL/intrinsics.yml` + `HAUL/extrinsics.yml`.
    StereoCalibPair {
        /// `intrinsics.yml` (M1, D1, M2, D2).
        intrinsics: PathBuf,
        /// `extrinsics.yml` (R, T, …).
        extrinsics: PathBuf,
    },
    /// VIAME camtrawl `HAUL/cal.npz`.
    CamtrawlNpz(PathBuf),
}

/// An opened haul directory: its frame pairs and calibration location.
#[derive(Debug)]
pub struct Haul {
    /// The haul directory.
    pub dir: PathBuf,
    /// Every stereo pair, ordered by name (numeric-aware), numbered from 1.
    pub frames: Vec<FramePair>,
    /// The calibration file(s), if one of the known layouts is present.
    pub calibration: Option<CalibrationSource>,
    /// Set once a 16-bit frame of this haul has been reported through `log`.
    warned_16bit: AtomicBool,
}

impl Haul {
    /// Opens `dir`: checks `left/` and `right/`, pairs their frames by file
    /// name and locates the calibration. Pixels are not read here, but
    /// zero-byte frame files are rejected at once.
    pub fn open(dir: impl AsRef<Path>) -> Result<Haul, InputError> {
        let dir = dir.as_ref().to_path_buf();
        if !dir.exists() {
            return Err(InputError::file(&dir, "haul directory does not exist"));
        }
        if !dir.is_dir() {
            return Err(InputError::file(&dir, "haul path is not a directory"));
        }
        let left = list_frames(&dir.join("left"))?;
        let right = list_frames(&dir.join("right"))?;

        for (name, path) in &left {
            if !right.contains_key(name) {
                return Err(InputError::file(
                    path,
                    format!(
                        "frame has no partner: {} is missing",
                        dir.join("right").join(name).display()
                    ),
                ));
            }
        }
        for (name, path) in &right {
            if !left.contains_key(name) {
                return Err(InputError::file(
                    path,
                    format!(
                        "frame has no partner: {} is missing",
                        dir.join("left").join(name).display()
                    ),
                ));
            }
        }

        let mut names: Vec<&OsString> = left.keys().collect();
        names.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
        let mut frames = Vec::with_capacity(names.len());
        for (i, name) in names.into_iter().enumerate() {
            let (Some(l), Some(r)) = (left.get(name), right.get(name)) else {
                continue; // unreachable: both sides checked above
            };
            let index = u32::try_from(i + 1)
                .map_err(|_| InputError::file(&dir, "more than 2³² − 1 frames"))?;
            frames.push(FramePair {
                index,
                name: name.to_string_lossy().into_owned(),
                left: l.clone(),
                right: r.clone(),
            });
        }

        let calibration = locate_calibration(&dir);
        Ok(Haul {
            dir,
            frames,
            calibration,
            warned_16bit: AtomicBool::new(false),
        })
    }

    /// The calibration source, or an error naming the missing
    /// `HAUL/calibration.yml`.
    pub fn calibration(&self) -> Result<&CalibrationSource, InputError> {
        self.calibration.as_ref().ok_or_else(|| {
            InputError::file(
                self.dir.join("calibration.yml"),
                "calibration file not found (also looked for intrinsics.yml + extrinsics.yml and cal.npz)",
            )
        })
    }

    /// Loads one stereo pair as 8-bit grey (conversion rules: [`load_gray`]).
    ///
    /// Errors, each naming the file(s) and the frame: either image unreadable;
    /// left and right sizes differ; `expected_size` (width, height — from the
    /// calibration) given and an image has another size. A 16-bit frame is
    /// reported through `log::warn!` once per haul, not once per file.
    pub fn load_pair(
        &self,
        pair: &FramePair,
        expected_size: Option<(u32, u32)>,
    ) -> Result<(GrayImage, GrayImage), InputError> {
        let (l, r, sixteen) = self.load_pair_quiet(pair, expected_size)?;
        if let Some(path) = sixteen {
            self.warn_16bit(path);
        }
        Ok((l, r))
    }

    /// The one 16-bit warning of the haul, naming `path`; later calls are
    /// silent. Callers that load pairs out of order (in parallel) call it
    /// themselves, for the first 16-bit file in frame order, so the
    /// warning names the same file on every run.
    pub fn warn_16bit(&self, path: &Path) {
        if !self.warned_16bit.swap(true, AtomicOrdering::Relaxed) {
            log::warn!(
                "{}: 16-bit frame scaled to 8 bits (>> 8); further 16-bit frames of {} are converted the same way without a warning",
                path.display(),
                self.dir.display()
            );
        }
    }

    /// [`Haul::load_pair`] without the warning: the third value is the
    /// 16-bit file of the pair (left first), if any, for [`Haul::warn_16bit`].
    pub fn load_pair_quiet<'p>(
        &self,
        pair: &'p FramePair,
        expected_size: Option<(u32, u32)>,
    ) -> Result<(GrayImage, GrayImage, Option<&'p Path>), InputError> {
        let frame = |e: InputError| InputError {
            location: e.location,
            message: format!("frame {}: {}", pair.index, e.message),
        };
        // both files decoded side by side (rayon pool); left's error first
        let (l, r) = rayon::join(|| decode_gray(&pair.left), || decode_gray(&pair.right));
        let (l, l16) = l.map_err(frame)?;
        let (r, r16) = r.map_err(frame)?;
        let sixteen = match (l16, r16) {
            (true, _) => Some(pair.left.as_path()),
            (false, true) => Some(pair.right.as_path()),
            _ => None,
        };
        if l.dimensions() != r.dimensions() {
            return Err(InputError::file(
                &pair.left,
                format!(
                    "frame {}: left image is {}x{} but right image {} is {}x{}",
                    pair.index,
                    l.width(),
                    l.height(),
                    pair.right.display(),
                    r.width(),
                    r.height()
                ),
            ));
        }
        if let Some((w, h)) = expected_size {
            if l.dimensions() != (w, h) {
                return Err(InputError::file(
                    &pair.left,
                    format!(
                        "frame {}: image is {}x{} but the calibration is for {w}x{h}",
                        pair.index,
                        l.width(),
                        l.height()
                    ),
                ));
            }
        }
        Ok((l, r, sixteen))
    }
}

/// Loads an image file as 8-bit grey.
///
/// - Format by content (PNG, JPEG or TIFF), not by extension.
/// - Colour → grey exactly as OpenCV's `cv2.cvtColor(.., cv2.COLOR_BGR2GRAY)`
///   on 8-bit images: ITU-R BT.601 luma in 15-bit fixed point,
///   `Y = (9798 R + 19235 G + 3735 B + 16384) >> 15` (checked against
///   OpenCV 5.0 in the tests). This is *not* `image`'s `to_luma8` (BT.709
///   weights); OpenCV is the reference the tests compare with. Alpha is
///   ignored.
/// - 16-bit samples are scaled to 8 bits by `>> 8` (the high byte; colour
///   channels are shifted first, then weighted), and a `log::warn!` naming
///   the file is emitted. Cam-trawl frames are 8-bit; a 16-bit frame usually
///   means a different camera setup, so it is worth a line in the log.
/// - Floating-point images are rejected.
/// - JPEG is decoded by `zune-jpeg` in strict mode: a truncated or corrupt
///   entropy-coded scan is an error. (`image`'s own JPEG wrapper runs
///   zune-jpeg non-strict, which silently fills missing rows with grey 128.)
///
/// Errors name the file: missing, unreadable, zero bytes, not an image,
/// truncated or corrupt.
pub fn load_gray(path: impl AsRef<Path>) -> Result<GrayImage, InputError> {
    let path = path.as_ref();
    let (img, was_16bit) = decode_gray(path)?;
    if was_16bit {
        log::warn!("{}: 16-bit image scaled to 8 bits (>> 8)", path.display());
    }
    Ok(img)
}

/// Decodes to 8-bit grey; the flag says the source had 16-bit samples.
fn decode_gray(path: &Path) -> Result<(GrayImage, bool), InputError> {
    let bytes = std::fs::read(path)
        .map_err(|e| InputError::file(path, format!("cannot read image: {e}")))?;
    if bytes.is_empty() {
        return Err(InputError::file(path, "image file is empty (0 bytes)"));
    }
    let format = image::guess_format(&bytes).map_err(|_| {
        InputError::file(path, "not a PNG, JPEG or TIFF image (unrecognised content)")
    })?;
    let img = match format {
        ImageFormat::Jpeg => decode_jpeg_strict(&bytes)
            .map_err(|e| InputError::file(path, format!("corrupt or truncated JPEG: {e}")))?,
        ImageFormat::Png | ImageFormat::Tiff => image::load_from_memory_with_format(&bytes, format)
            .map_err(|e| {
                InputError::file(path, format!("corrupt or truncated {format:?} image: {e}"))
            })?,
        other => {
            return Err(InputError::file(
                path,
                format!("{other:?} images are not supported (PNG, JPEG or TIFF only)"),
            ))
        }
    };
    to_gray8(img).map_err(|m| InputError::file(path, m))
}

/// Strict JPEG decode to `Luma8` (grey input) or `Rgb8` (anything else).
fn decode_jpeg_strict(bytes: &[u8]) -> Result<DynamicImage, String> {
    use zune_core::bytestream::ZCursor;
    use zune_core::colorspace::ColorSpace;
    use zune_core::options::DecoderOptions;

    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(1 << 16)
        .set_max_height(1 << 16);
    let mut dec = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    dec.decode_headers().map_err(|e| format!("{e:?}"))?;
    let (w, h) = dec.dimensions().ok_or("no frame header")?;
    let grey = matches!(
        dec.input_colorspace(),
        Some(ColorSpace::Luma | ColorSpace::LumaA)
    );
    let out = if grey {
        ColorSpace::Luma
    } else {
        ColorSpace::RGB
    };
    dec.set_options(options.jpeg_set_out_colorspace(out));
    let pixels = dec.decode().map_err(|e| format!("{e:?}"))?;
    let (w, h) = (
        u32::try_from(w).map_err(|_| "width too large")?,
        u32::try_from(h).map_err(|_| "height too large")?,
    );
    let img = if grey {
        image::GrayImage::from_raw(w, h, pixels).map(DynamicImage::ImageLuma8)
    } else {
        image::RgbImage::from_raw(w, h, pixels).map(DynamicImage::ImageRgb8)
    };
    img.ok_or_else(|| "decoded buffer does not match the image size".to_string())
}

/// BT.601 luma in OpenCV's 15-bit fixed point (`cv2.COLOR_BGR2GRAY`, 8-bit).
fn luma601(r: u8, g: u8, b: u8) -> u8 {
    let y = (9798 * r as u32 + 19235 * g as u32 + 3735 * b as u32 + (1 << 14)) >> 15;
    y.min(255) as u8
}

/// Converts any decoded image to 8-bit grey; the flag says it was 16-bit.
fn to_gray8(img: DynamicImage) -> Result<(GrayImage, bool), String> {
    let (w, h) = (img.width(), img.height());
    let hi = |v: u16| (v >> 8) as u8;
    let out = match img {
        DynamicImage::ImageLuma8(g) => (g, false),
        DynamicImage::ImageLumaA8(g) => (
            GrayImage::from_fn(w, h, |x, y| image::Luma([g.get_pixel(x, y).0[0]])),
            false,
        ),
        DynamicImage::ImageRgb8(c) => (
            GrayImage::from_fn(w, h, |x, y| {
                let [r, g, b] = c.get_pixel(x, y).0;
                image::Luma([luma601(r, g, b)])
            }),
            false,
        ),
        DynamicImage::ImageRgba8(c) => (
            GrayImage::from_fn(w, h, |x, y| {
                let [r, g, b, _] = c.get_pixel(x, y).0;
                image::Luma([luma601(r, g, b)])
            }),
            false,
        ),
        DynamicImage::ImageLuma16(g) => (
            GrayImage::from_fn(w, h, |x, y| image::Luma([hi(g.get_pixel(x, y).0[0])])),
            true,
        ),
        DynamicImage::ImageLumaA16(g) => (
            GrayImage::from_fn(w, h, |x, y| image::Luma([hi(g.get_pixel(x, y).0[0])])),
            true,
        ),
        DynamicImage::ImageRgb16(c) => (
            GrayImage::from_fn(w, h, |x, y| {
                let [r, g, b] = c.get_pixel(x, y).0;
                image::Luma([luma601(hi(r), hi(g), hi(b))])
            }),
            true,
        ),
        DynamicImage::ImageRgba16(c) => (
            GrayImage::from_fn(w, h, |x, y| {
                let [r, g, b, _] = c.get_pixel(x, y).0;
                image::Luma([luma601(hi(r), hi(g), hi(b))])
            }),
            true,
        ),
        other => {
            return Err(format!(
                "{:?} images are not supported (8- or 16-bit integer samples only)",
                other.color()
            ))
        }
    };
    Ok(out)
}

/// True when `path` has one of [`IMAGE_EXTENSIONS`] (any case).
fn has_image_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        .unwrap_or(false)
}

/// The frames of one side, by file name. Errors: directory missing or not a
/// directory, unreadable, no frames, a zero-byte frame file.
fn list_frames(dir: &Path) -> Result<BTreeMap<OsString, PathBuf>, InputError> {
    if !dir.is_dir() {
        let why = if dir.exists() {
            "is not a directory"
        } else {
            "directory is missing (a haul needs left/ and right/)"
        };
        return Err(InputError::file(dir, why));
    }
    let entries = std::fs::read_dir(dir)
        .map_err(|e| InputError::file(dir, format!("cannot read directory: {e}")))?;
    let mut frames = BTreeMap::new();
    for entry in entries {
        let entry =
            entry.map_err(|e| InputError::file(dir, format!("cannot read directory: {e}")))?;
        let name = entry.file_name();
        let path = entry.path();
        if name.to_string_lossy().starts_with('.') || !has_image_extension(&path) {
            continue;
        }
        // Follows symbolic links; sub-directories named like images are skipped.
        let meta = std::fs::metadata(&path)
            .map_err(|e| InputError::file(&path, format!("cannot read file: {e}")))?;
        if !meta.is_file() {
            continue;
        }
        if meta.len() == 0 {
            return Err(InputError::file(&path, "image file is empty (0 bytes)"));
        }
        frames.insert(name, path);
    }
    if frames.is_empty() {
        return Err(InputError::file(
            dir,
            "no frames (expected PNG, JPEG or TIFF files)",
        ));
    }
    Ok(frames)
}

/// Finds the calibration in one of the known layouts (see [`CalibrationSource`]).
fn locate_calibration(dir: &Path) -> Option<CalibrationSource> {
    let yml = dir.join("calibration.yml");
    if yml.is_file() {
        return Some(CalibrationSource::OpenCvYaml(yml));
    }
    let (intr, extr) = (dir.join("intrinsics.yml"), dir.join("extrinsics.yml"));
    if intr.is_file() && extr.is_file() {
        return Some(CalibrationSource::StereoCalibPair {
            intrinsics: intr,
            extrinsics: extr,
        });
    }
    let npz = dir.join("cal.npz");
    npz.is_file().then_some(CalibrationSource::CamtrawlNpz(npz))
}

/// Numeric-aware ("natural") order: runs of ASCII digits compare by value
/// (`2` < `10`), everything else by character. Equal-valued names such as
/// `01` and `1` fall back to plain string order, so the order is total.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a, b);
    loop {
        match (x.chars().next(), y.chars().next()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let nx = x.find(|ch: char| !ch.is_ascii_digit()).unwrap_or(x.len());
                let ny = y.find(|ch: char| !ch.is_ascii_digit()).unwrap_or(y.len());
                let (dx, dy) = (
                    x[..nx].trim_start_matches('0'),
                    y[..ny].trim_start_matches('0'),
                );
                let ord = dx.len().cmp(&dy.len()).then_with(|| dx.cmp(dy));
                if ord != Ordering::Equal {
                    return ord;
                }
                x = &x[nx..];
                y = &y[ny..];
            }
            (Some(c), Some(d)) => {
                if c != d {
                    return c.cmp(&d);
                }
                x = &x[c.len_utf8()..];
                y = &y[d.len_utf8()..];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageBuffer, Luma, Rgb};
    use std::sync::{Mutex, OnceLock};

    /// A deterministic grey test pattern.
    fn pattern(w: u32, h: u32, seed: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            Luma([((x * 7 + y * 13 + seed * 31) % 251) as u8])
        })
    }

    /// A haul in a tempdir with `names` on both sides, PNG, `w`x`h`.
    fn haul_with(names: &[&str], w: u32, h: u32) -> tempfile::TempDir {
        let t = tempfile::tempdir().unwrap();
        for side in ["left", "right"] {
            std::fs::create_dir(t.path().join(side)).unwrap();
            for (i, n) in names.iter().enumerate() {
                pattern(w, h, i as u32)
                    .save(t.path().join(side).join(n))
                    .unwrap();
            }
        }
        t
    }

    fn err_of<T: std::fmt::Debug>(r: Result<T, InputError>) -> String {
        r.unwrap_err().to_string()
    }

    fn shown(p: &Path) -> String {
        p.display().to_string()
    }

    // --- Logger capturing `log` records, to check the 16-bit warning. ---
    struct Capture;
    static RECORDS: Mutex<Vec<String>> = Mutex::new(Vec::new());
    impl log::Log for Capture {
        fn enabled(&self, _: &log::Metadata) -> bool {
            true
        }
        fn log(&self, r: &log::Record) {
            if let Ok(mut v) = RECORDS.lock() {
                v.push(format!("{} {}", r.level(), r.args()));
            }
        }
        fn flush(&self) {}
    }
    fn capture_logs() {
        static INIT: OnceLock<()> = OnceLock::new();
        INIT.get_or_init(|| {
            let _ = log::set_logger(&Capture);
            log::set_max_level(log::LevelFilter::Trace);
        });
    }
    fn logged(needle: &str) -> bool {
        RECORDS
            .lock()
            .map(|v| v.iter().any(|m| m.contains(needle)))
            .unwrap_or(false)
    }

    /// Runs a Python/OpenCV oracle script and returns its stdout; `None`
    /// (skip) if python3 or cv2 is missing, unless FISHTRACK_REQUIRE_PYTHON=1.
    fn python_cv2(script: &str, args: &[&Path]) -> Option<String> {
        let probe = std::process::Command::new("python3")
            .args(["-c", "import cv2, numpy"])
            .output();
        if !matches!(&probe, Ok(o) if o.status.success()) {
            let why = format!("python3 with cv2/numpy unavailable: {probe:?}");
            if std::env::var("FISHTRACK_REQUIRE_PYTHON").as_deref() == Ok("1") {
                panic!("{why}");
            }
            eprintln!("SKIP (oracle): {why}");
            return None;
        }
        let out = std::process::Command::new("python3")
            .arg("-c")
            .arg(script)
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "oracle script failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        Some(String::from_utf8(out.stdout).unwrap())
    }

    #[test]
    fn pairs_are_numeric_ordered_and_one_based() {
        let t = haul_with(&["10.png", "2.png", "1.png", "000003.tif"], 8, 6);
        for side in ["left", "right"] {
            let d = t.path().join(side);
            std::fs::write(d.join("notes.txt"), b"not a frame").unwrap();
            std::fs::write(d.join(".hidden.png"), b"junk").unwrap();
            std::fs::write(d.join("Thumbs.db"), b"junk").unwrap();
            std::fs::create_dir(d.join("sub.png")).unwrap();
        }
        std::fs::write(t.path().join("calibration.yml"), "%YAML:1.0\n").unwrap();
        let h = Haul::open(t.path()).unwrap();
        let names: Vec<&str> = h.frames.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["1.png", "2.png", "000003.tif", "10.png"]);
        let idx: Vec<u32> = h.frames.iter().map(|f| f.index).collect();
        assert_eq!(idx, [1, 2, 3, 4]);
        assert_eq!(h.frames[1].left, t.path().join("left/2.png"));
        assert_eq!(h.frames[1].right, t.path().join("right/2.png"));
        assert_eq!(
            h.calibration().unwrap(),
            &CalibrationSource::OpenCvYaml(t.path().join("calibration.yml"))
        );
        let (l, r) = h.load_pair(&h.frames[0], Some((8, 6))).unwrap();
        assert_eq!(l, pattern(8, 6, 2)); // "1.png" was written third (seed 2)
        assert_eq!(r, l);
        // The TIFF frame decodes to the same pixels it was written with.
        let (l, _) = h.load_pair(&h.frames[2], None).unwrap();
        assert_eq!(l, pattern(8, 6, 3));
    }

    #[test]
    fn natural_order() {
        assert_eq!(natural_cmp("2.png", "10.png"), Ordering::Less);
        assert_eq!(natural_cmp("a9b", "a10a"), Ordering::Less);
        assert_eq!(natural_cmp("frame_010", "frame_9"), Ordering::Greater);
        assert_eq!(natural_cmp("001", "1"), Ordering::Less); // tie → string order
        assert_eq!(natural_cmp("b1", "a2"), Ordering::Greater);
        assert_eq!(natural_cmp("1", "1.png"), Ordering::Less);
        assert_eq!(natural_cmp("x", "x"), Ordering::Equal);
    }

    #[test]
    fn missing_haul_dir() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path().join("nope");
        let e = err_of(Haul::open(&d));
        assert!(
            e.contains(&shown(&d)) && e.contains("does not exist"),
            "{e}"
        );
        let f = t.path().join("file");
        std::fs::write(&f, b"x").unwrap();
        let e = err_of(Haul::open(&f));
        assert!(
            e.contains(&shown(&f)) && e.contains("not a directory"),
            "{e}"
        );
    }

    #[test]
    fn missing_side_dir() {
        let t = haul_with(&["1.png"], 4, 4);
        std::fs::remove_dir_all(t.path().join("right")).unwrap();
        let e = err_of(Haul::open(t.path()));
        assert!(e.contains(&shown(&t.path().join("right"))), "{e}");
        assert!(e.contains("missing"), "{e}");
        std::fs::remove_dir_all(t.path().join("left")).unwrap();
        let e = err_of(Haul::open(t.path()));
        assert!(e.contains(&shown(&t.path().join("left"))), "{e}");
    }

    #[test]
    fn empty_side_dir() {
        let t = haul_with(&["1.png"], 4, 4);
        let l = t.path().join("left");
        std::fs::remove_file(l.join("1.png")).unwrap();
        std::fs::write(l.join("readme.txt"), b"hello").unwrap();
        let e = err_of(Haul::open(t.path()));
        assert!(e.contains(&shown(&l)) && e.contains("no frames"), "{e}");
    }

    #[test]
    fn frame_without_partner() {
        let t = haul_with(&["1.png", "2.png"], 4, 4);
        pattern(4, 4, 0).save(t.path().join("right/3.png")).unwrap();
        let e = err_of(Haul::open(t.path()));
        let extra = shown(&t.path().join("right/3.png"));
        assert!(e.starts_with(&extra), "{e}");
        assert!(e.contains(&shown(&t.path().join("left/3.png"))), "{e}");
        std::fs::remove_file(t.path().join("right/3.png")).unwrap();
        std::fs::remove_file(t.path().join("right/2.png")).unwrap();
        let e = err_of(Haul::open(t.path()));
        assert!(e.starts_with(&shown(&t.path().join("left/2.png"))), "{e}");
        assert!(e.contains("no partner"), "{e}");
    }

    #[test]
    fn left_right_size_mismatch() {
        let t = haul_with(&["1.png", "2.png"], 8, 6);
        pattern(9, 6, 0).save(t.path().join("right/2.png")).unwrap();
        let h = Haul::open(t.path()).unwrap();
        assert!(h.load_pair(&h.frames[0], None).is_ok());
        let e = err_of(h.load_pair(&h.frames[1], None));
        assert!(e.contains(&shown(&t.path().join("left/2.png"))), "{e}");
        assert!(e.contains(&shown(&t.path().join("right/2.png"))), "{e}");
        assert!(e.contains("8x6") && e.contains("9x6"), "{e}");
        assert!(e.contains("frame 2"), "{e}");
    }

    #[test]
    fn size_differs_from_calibration() {
        let t = haul_with(&["1.png"], 8, 6);
        let h = Haul::open(t.path()).unwrap();
        let e = err_of(h.load_pair(&h.frames[0], Some((2048, 2048))));
        assert!(e.contains(&shown(&t.path().join("left/1.png"))), "{e}");
        assert!(e.contains("8x6") && e.contains("2048x2048"), "{e}");
        assert!(e.contains("calibration"), "{e}");
    }

    #[test]
    fn zero_byte_frame() {
        let t = haul_with(&["1.png", "2.png"], 4, 4);
        let z = t.path().join("right/2.png");
        std::fs::write(&z, b"").unwrap();
        let e = err_of(Haul::open(t.path()));
        assert!(e.contains(&shown(&z)) && e.contains("0 bytes"), "{e}");
        let e = err_of(load_gray(&z));
        assert!(e.contains(&shown(&z)) && e.contains("0 bytes"), "{e}");
    }

    #[test]
    fn not_an_image_with_image_extension() {
        let t = haul_with(&["1.png"], 4, 4);
        let f = t.path().join("left/1.png");
        std::fs::write(&f, b"this is text, not a picture").unwrap();
        let h = Haul::open(t.path()).unwrap();
        let e = err_of(h.load_pair(&h.frames[0], None));
        assert!(
            e.contains(&shown(&f)) && e.contains("not a PNG, JPEG or TIFF"),
            "{e}"
        );
        assert!(e.contains("frame 1"), "{e}");
        let missing = t.path().join("left/none.png");
        let e = err_of(load_gray(&missing));
        assert!(e.contains(&shown(&missing)), "{e}");
    }

    #[test]
    fn corrupt_png() {
        let t = haul_with(&["1.png"], 32, 32);
        let f = t.path().join("left/1.png");
        let mut b = std::fs::read(&f).unwrap();
        let n = b.len();
        for v in &mut b[n / 2..n - 12] {
            *v ^= 0x5a; // scramble the IDAT payload (and its CRC check)
        }
        std::fs::write(&f, &b).unwrap();
        let e = err_of(load_gray(&f));
        assert!(e.contains(&shown(&f)) && e.contains("corrupt"), "{e}");
    }

    #[test]
    fn truncated_png() {
        let t = haul_with(&["1.png"], 64, 64);
        let f = t.path().join("left/1.png");
        let b = std::fs::read(&f).unwrap();
        for keep in [b.len() - 12, b.len() * 2 / 3, 40] {
            std::fs::write(&f, &b[..keep]).unwrap();
            let e = err_of(load_gray(&f));
            assert!(e.contains(&shown(&f)), "{e}");
        }
    }

    /// A noisy grey JPEG (so the scan is long enough to truncate mid-way).
    fn write_jpeg(path: &Path, w: u32, h: u32) -> GrayImage {
        let g = GrayImage::from_fn(w, h, |x, y| {
            Luma([((x * x + 3 * y * y + x * y) % 256) as u8])
        });
        let f = std::fs::File::create(path).unwrap();
        let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(f, 90);
        enc.encode_image(&g).unwrap();
        g
    }

    #[test]
    fn jpeg_reads_and_truncated_jpeg_is_an_error() {
        let t = tempfile::tempdir().unwrap();
        let f = t.path().join("a.jpg");
        let orig = write_jpeg(&f, 128, 96);
        let ours = load_gray(&f).unwrap();
        assert_eq!(ours.dimensions(), (128, 96));
        // Same pixels as image's own (non-strict) decoder on an intact file.
        let theirs = image::open(&f).unwrap().to_luma8();
        assert_eq!(ours, theirs);
        // Lossy, but close to what was written.
        let mean_err: f64 = ours
            .pixels()
            .zip(orig.pixels())
            .map(|(a, b)| (a.0[0] as f64 - b.0[0] as f64).abs())
            .sum::<f64>()
            / (128.0 * 96.0);
        assert!(mean_err < 6.0, "mean abs error {mean_err}");

        let b = std::fs::read(&f).unwrap();
        let cut = &b[..b.len() * 2 / 3];
        // Why strict decoding: `image` accepts the truncated file and pads it.
        let padded = image::load_from_memory(cut).map(|i| i.to_luma8());
        let p = padded.expect("image 0.25.10 accepts a truncated JPEG");
        assert_eq!(p.get_pixel(127, 95).0[0], 128, "image pads with grey");
        std::fs::write(&f, cut).unwrap();
        let e = err_of(load_gray(&f));
        assert!(e.contains(&shown(&f)) && e.contains("JPEG"), "{e}");
        // Cut inside the headers too.
        std::fs::write(&f, &b[..100]).unwrap();
        let e = err_of(load_gray(&f));
        assert!(e.contains(&shown(&f)), "{e}");
    }

    #[test]
    fn truncated_tiff() {
        let t = haul_with(&["1.tif"], 64, 64);
        let f = t.path().join("left/1.tif");
        let b = std::fs::read(&f).unwrap();
        std::fs::write(&f, &b[..b.len() / 2]).unwrap();
        let e = err_of(load_gray(&f));
        assert!(e.contains(&shown(&f)), "{e}");
    }

    #[test]
    fn colour_uses_bt601_like_opencv() {
        assert_eq!(luma601(255, 0, 0), 76); // (9798·255 + 16384) >> 15
        assert_eq!(luma601(0, 255, 0), 150);
        assert_eq!(luma601(0, 0, 255), 29);
        assert_eq!(luma601(255, 255, 255), 255);
        let t = tempfile::tempdir().unwrap();
        let f = t.path().join("c.png");
        let c: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_fn(3, 1, |x, _| {
            Rgb([[255, 0, 0], [0, 255, 0], [10, 20, 30]][x as usize])
        });
        c.save(&f).unwrap();
        let g = load_gray(&f).unwrap();
        let want = (9798 * 10 + 19235 * 20 + 3735 * 30 + 16384) >> 15;
        assert_eq!(g.as_raw(), &vec![76, 150, want as u8]);
    }

    /// Colour and 16-bit PNGs against OpenCV (`cv2.imread` + `cvtColor`).
    #[test]
    fn colour_and_16bit_match_opencv() {
        let t = tempfile::tempdir().unwrap();
        let (w, h) = (256u32, 256u32);
        // Every (r, g) pair once, b varying: covers the rounding cases.
        let c: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_fn(w, h, |x, y| {
            Rgb([x as u8, y as u8, ((x * 7 + y * 13) % 256) as u8])
        });
        let cf = t.path().join("c.png");
        c.save(&cf).unwrap();
        let g16: ImageBuffer<Luma<u16>, Vec<u16>> =
            ImageBuffer::from_fn(w, h, |x, y| Luma([((x * 1777 + y * 2903) % 65536) as u16]));
        let gf = t.path().join("g16.png");
        g16.save(&gf).unwrap();

        let script = r#"
import sys, cv2
c = cv2.imread(sys.argv[1], cv2.IMREAD_COLOR)
print(' '.join(map(str, cv2.cvtColor(c, cv2.COLOR_BGR2GRAY).ravel())))
g = cv2.imread(sys.argv[2], cv2.IMREAD_UNCHANGED)
assert g.dtype.name == 'uint16', g.dtype
print(' '.join(map(str, (g >> 8).ravel())))
"#;
        let Some(out) = python_cv2(script, &[&cf, &gf]) else {
            return;
        };
        let mut lines = out.lines();
        let parse = |l: Option<&str>| -> Vec<u8> {
            l.unwrap().split(' ').map(|v| v.parse().unwrap()).collect()
        };
        let cv_colour = parse(lines.next());
        let cv_16 = parse(lines.next());
        assert_eq!(load_gray(&cf).unwrap().as_raw(), &cv_colour);

        capture_logs();
        assert_eq!(load_gray(&gf).unwrap().as_raw(), &cv_16);
        assert!(logged(&format!("WARN {}: 16-bit", gf.display())));
    }

    #[test]
    fn sixteen_bit_pair_warns_once_per_haul() {
        capture_logs();
        let t = tempfile::tempdir().unwrap();
        for side in ["left", "right"] {
            std::fs::create_dir(t.path().join(side)).unwrap();
            for n in ["1.png", "2.png"] {
                let g: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_fn(4, 2, |x, y| {
                    Luma([(x * 0x1234 + y * 0x0f0f) as u16 | 0xff])
                });
                g.save(t.path().join(side).join(n)).unwrap();
            }
        }
        let h = Haul::open(t.path()).unwrap();
        let (l, r) = h.load_pair(&h.frames[0], None).unwrap();
        assert_eq!(l.get_pixel(1, 1).0[0], ((0x1234 + 0x0f0f) >> 8) as u8);
        assert_eq!(l, r);
        h.load_pair(&h.frames[1], None).unwrap();
        let dir = t.path().display().to_string();
        let n = RECORDS
            .lock()
            .unwrap()
            .iter()
            .filter(|m| m.starts_with("WARN") && m.contains(&dir))
            .count();
        assert_eq!(n, 1, "one 16-bit warning per haul");
    }

    /// JPEGs written by OpenCV's libjpeg (baseline grey, baseline colour,
    /// progressive colour) decode in strict mode, close to
    /// `cv2.cvtColor(cv2.imread(f), COLOR_BGR2GRAY)`; truncated, they fail.
    #[test]
    fn opencv_jpegs_decode_strictly_and_match() {
        let t = tempfile::tempdir().unwrap();
        let script = r#"
import sys, cv2, numpy as np
y, x = np.mgrid[0:96, 0:128]
g = ((x * x + 3 * y * y + x * y) % 256).astype(np.uint8)
c = np.dstack([g, (x * 2) % 256, (y * 3) % 256]).astype(np.uint8)
d = sys.argv[1]
q = [cv2.IMWRITE_JPEG_QUALITY, 90]
cv2.imwrite(d + '/g.jpg', g, q)
cv2.imwrite(d + '/c.jpg', c, q)
cv2.imwrite(d + '/p.jpg', c, q + [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
for n in ['g', 'c', 'p']:
    im = cv2.imread(d + '/' + n + '.jpg', cv2.IMREAD_UNCHANGED)
    if im.ndim == 3:
        im = cv2.cvtColor(im, cv2.COLOR_BGR2GRAY)
    print(' '.join(map(str, im.ravel())))
"#;
        let Some(out) = python_cv2(script, &[t.path()]) else {
            return;
        };
        for (name, line) in ["g", "c", "p"].into_iter().zip(out.lines()) {
            let cv: Vec<i32> = line.split(' ').map(|v| v.parse().unwrap()).collect();
            let f = t.path().join(format!("{name}.jpg"));
            let ours = load_gray(&f).unwrap();
            assert_eq!(ours.dimensions(), (128, 96));
            let d: Vec<i32> = ours
                .as_raw()
                .iter()
                .zip(&cv)
                .map(|(&a, &b)| (a as i32 - b).abs())
                .collect();
            let max = *d.iter().max().unwrap();
            let mean = d.iter().sum::<i32>() as f64 / d.len() as f64;
            eprintln!("{name}: max {max} mean {mean:.3}");
            // IDCT/upsampling rounding differs by at most a grey level or two.
            assert!(max <= 2 && mean < 0.1, "{name}.jpg: max {max} mean {mean}");
            let b = std::fs::read(&f).unwrap();
            std::fs::write(&f, &b[..b.len() * 3 / 4]).unwrap();
            let e = err_of(load_gray(&f));
            assert!(e.contains(&shown(&f)), "{e}");
        }
    }

    #[test]
    fn calibration_layouts() {
        let t = haul_with(&["1.png"], 4, 4);
        let h = Haul::open(t.path()).unwrap();
        assert_eq!(h.calibration, None);
        let e = err_of(h.calibration());
        assert!(e.contains(&shown(&t.path().join("calibration.yml"))), "{e}");
        std::fs::write(t.path().join("cal.npz"), b"PK").unwrap();
        let h = Haul::open(t.path()).unwrap();
        assert_eq!(
            h.calibration,
            Some(CalibrationSource::CamtrawlNpz(t.path().join("cal.npz")))
        );
        std::fs::write(t.path().join("intrinsics.yml"), b"%YAML:1.0\n").unwrap();
        std::fs::write(t.path().join("extrinsics.yml"), b"%YAML:1.0\n").unwrap();
        let h = Haul::open(t.path()).unwrap();
        assert!(matches!(
            h.calibration,
            Some(CalibrationSource::StereoCalibPair { .. })
        ));
    }
}
