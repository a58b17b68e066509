//! Reading a tracker's output files (`tracks.csv`, `detections.csv`,
//! `fish.csv`, `stereo.csv`) with the `csv` crate. Every error is an
//! [`InputError`] that names the file and the line.
//!
//! `tracks.csv` / `detections.csv` are MOTChallenge rows without a header:
//! `frame,id,bb_left,bb_top,bb_width,bb_height[,conf,x,y,z[,length_px]]`,
//! frames from 1, boxes in raw left-image pixels. The optional 11th column
//! `length_px` is an oriented (PCA major-axis) length of the object in raw
//! left pixels; when present and positive, [`super::metrics`] uses it for the
//! single-camera length instead of `max(w, h)`.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::InputError;

/// One MOTChallenge row.
#[derive(Debug, Clone, PartialEq)]
pub struct MotRow {
    /// Frame number, from 1.
    pub frame: u32,
    /// Track id (−1 for detections).
    pub id: i64,
    /// `[x, y, w, h]`, raw pixels.
    pub bbox: [f64; 4],
    /// Oriented length in pixels (optional 11th column), if given and > 0.
    pub length_px: Option<f64>,
    /// Line in the file (for error messages).
    pub line: u64,
}

/// One `fish.csv` row.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct FishRow {
    /// Track id, as in `tracks.csv`.
    pub track_id: i64,
    /// First frame of the track.
    pub first_frame: u32,
    /// Last frame of the track.
    pub last_frame: u32,
    /// Number of frames.
    pub frames: u32,
    /// Estimated length, mm; `None` where the track allowed no measurement.
    pub length_mm: Option<f64>,
    /// Spread of the per-frame lengths, mm.
    pub length_sd_mm: Option<f64>,
    /// Range (distance from the camera), mm.
    pub range_mm: Option<f64>,
}

/// The header `fish.csv` must carry.
pub const FISH_HEADER: [&str; 7] = [
    "track_id",
    "first_frame",
    "last_frame",
    "frames",
    "length_mm",
    "length_sd_mm",
    "range_mm",
];

/// One row of `OUT/stereo.csv`, the per-frame stereo output (paper Sections
/// IV.A and IV.D.2) — the one type `fishtrack track` writes
/// ([`crate::output::write_stereo`]) and `fishtrack eval` reads
/// ([`read_stereo`]), through serde; the field names are the header
/// ([`STEREO_HEADER`]):
/// `frame,left_x,left_y,left_w,left_h,right_x,right_y,right_w,right_h,head_x,head_y,head_z,tail_x,tail_y,tail_z,length_mm`
/// — one row per left object in a frame (1-based); `left_*`/`right_*` its
/// upright boxes `[x, y, w, h]` in the raw left/right images' pixels (right
/// fields empty when the object stayed unpaired); `head_*`/`tail_*` the
/// triangulated snout and tail-tip points in mm in the left camera frame
/// and `length_mm` = ‖head − tail‖ (all empty where no usable measurement
/// was made, e.g. a fish cut by the border or masks that disagree between
/// the views). A group (right box, head, tail) is all present or all empty.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct StereoRow {
    /// Frame number, from 1.
    pub frame: u32,
    /// Left box x, raw left pixels.
    pub left_x: f64,
    /// Left box y.
    pub left_y: f64,
    /// Left box width.
    pub left_w: f64,
    /// Left box height.
    pub left_h: f64,
    /// Right box x of the paired object, raw right pixels.
    pub right_x: Option<f64>,
    /// Right box y.
    pub right_y: Option<f64>,
    /// Right box width.
    pub right_w: Option<f64>,
    /// Right box height.
    pub right_h: Option<f64>,
    /// Head point x, mm.
    pub head_x: Option<f64>,
    /// Head point y, mm.
    pub head_y: Option<f64>,
    /// Head point z, mm.
    pub head_z: Option<f64>,
    /// Tail point x, mm.
    pub tail_x: Option<f64>,
    /// Tail point y, mm.
    pub tail_y: Option<f64>,
    /// Tail point z, mm.
    pub tail_z: Option<f64>,
    /// Length, mm.
    pub length_mm: Option<f64>,
    /// Line in the file (for error messages; not a column).
    #[serde(skip)]
    pub line: u64,
}

/// Rounds to 3 decimals: sub-micrometre / sub-millipixel digits are noise.
fn r3(v: f64) -> f64 {
    let r = (v * 1000.0).round() / 1000.0;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

fn all3(v: [Option<f64>; 3]) -> Option<[f64; 3]> {
    Some([v[0]?, v[1]?, v[2]?])
}

impl StereoRow {
    /// A row from boxes and points (values rounded to 3 decimals).
    pub fn new(
        frame: u32,
        left: [f64; 4],
        right: Option<[f64; 4]>,
        head: Option<[f64; 3]>,
        tail: Option<[f64; 3]>,
        length_mm: Option<f64>,
    ) -> Self {
        let r = |v: Option<[f64; 4]>, k: usize| v.map(|b| r3(b[k]));
        let p = |v: Option<[f64; 3]>, k: usize| v.map(|b| r3(b[k]));
        StereoRow {
            frame,
            left_x: r3(left[0]),
            left_y: r3(left[1]),
            left_w: r3(left[2]),
            left_h: r3(left[3]),
            right_x: r(right, 0),
            right_y: r(right, 1),
            right_w: r(right, 2),
            right_h: r(right, 3),
            head_x: p(head, 0),
            head_y: p(head, 1),
            head_z: p(head, 2),
            tail_x: p(tail, 0),
            tail_y: p(tail, 1),
            tail_z: p(tail, 2),
            length_mm: length_mm.map(r3),
            line: 0,
        }
    }

    /// Left box `[x, y, w, h]`.
    pub fn left(&self) -> [f64; 4] {
        [self.left_x, self.left_y, self.left_w, self.left_h]
    }

    /// Right box, if paired.
    pub fn right(&self) -> Option<[f64; 4]> {
        Some([self.right_x?, self.right_y?, self.right_w?, self.right_h?])
    }

    /// Head point, mm.
    pub fn head(&self) -> Option<[f64; 3]> {
        all3([self.head_x, self.head_y, self.head_z])
    }

    /// Tail point, mm.
    pub fn tail(&self) -> Option<[f64; 3]> {
        all3([self.tail_x, self.tail_y, self.tail_z])
    }

    /// The optional groups: (first column index, values).
    fn groups(&self) -> [(usize, Vec<Option<f64>>); 4] {
        [
            (
                5,
                vec![self.right_x, self.right_y, self.right_w, self.right_h],
            ),
            (9, vec![self.head_x, self.head_y, self.head_z]),
            (12, vec![self.tail_x, self.tail_y, self.tail_z]),
            (15, vec![self.length_mm]),
        ]
    }
}

/// The header `stereo.csv` must carry.
pub const STEREO_HEADER: [&str; 16] = [
    "frame",
    "left_x",
    "left_y",
    "left_w",
    "left_h",
    "right_x",
    "right_y",
    "right_w",
    "right_h",
    "head_x",
    "head_y",
    "head_z",
    "tail_x",
    "tail_y",
    "tail_z",
    "length_mm",
];

fn at(path: &Path, line: u64, message: impl Into<String>) -> InputError {
    InputError::plain(format!("{}: line {line}", path.display()), message)
}

fn line_of(rec: &csv::StringRecord) -> u64 {
    rec.position().map_or(0, |p| p.line())
}

fn csv_error(path: &Path, e: csv::Error) -> InputError {
    match e.position() {
        Some(p) => at(path, p.line(), format!("not valid CSV: {e}")),
        None => InputError::file(path, format!("cannot read: {e}")),
    }
}

fn parse_f64(path: &Path, line: u64, name: &str, s: &str) -> Result<f64, InputError> {
    let v: f64 = s.trim().parse().map_err(|_| {
        at(
            path,
            line,
            format!("column `{name}`: `{s}` is not a number"),
        )
    })?;
    if !v.is_finite() {
        return Err(at(
            path,
            line,
            format!("column `{name}`: `{s}` is not finite"),
        ));
    }
    Ok(v)
}

fn parse_frame(path: &Path, line: u64, s: &str) -> Result<u32, InputError> {
    let v = parse_f64(path, line, "frame", s)?;
    if v.fract() != 0.0 || v < 1.0 || v > u32::MAX as f64 {
        return Err(at(
            path,
            line,
            format!("frame `{s}` is not a whole number ≥ 1 (frames are 1-based)"),
        ));
    }
    Ok(v as u32)
}

fn check_box(path: &Path, line: u64, b: &[f64; 4]) -> Result<(), InputError> {
    if b[2] < 0.0 || b[3] < 0.0 {
        return Err(at(path, line, "box width and height must be ≥ 0"));
    }
    Ok(())
}

/// Reads a MOTChallenge file (no header, ≥ 6 columns), in file order.
pub fn read_mot(path: &Path) -> Result<Vec<MotRow>, InputError> {
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| InputError::file(path, format!("cannot open: {e}")))?;
    let mut rows = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| csv_error(path, e))?;
        let line = line_of(&rec);
        if rec.len() == 1 && rec[0].is_empty() {
            continue;
        }
        if rec.len() < 6 {
            return Err(at(
                path,
                line,
                format!(
                    "{} columns; a MOTChallenge row needs at least 6 (frame,id,bb_left,bb_top,bb_width,bb_height)",
                    rec.len()
                ),
            ));
        }
        let frame = parse_frame(path, line, &rec[0])?;
        let id = parse_f64(path, line, "id", &rec[1])?;
        if id.fract() != 0.0 {
            return Err(at(
                path,
                line,
                format!("id `{}` is not a whole number", &rec[1]),
            ));
        }
        let names = ["bb_left", "bb_top", "bb_width", "bb_height"];
        let mut bbox = [0.0; 4];
        for (k, v) in bbox.iter_mut().enumerate() {
            *v = parse_f64(path, line, names[k], &rec[2 + k])?;
        }
        check_box(path, line, &bbox)?;
        let length_px = match rec.get(10) {
            Some(s) if !s.is_empty() => {
                Some(parse_f64(path, line, "length_px", s)?).filter(|&l| l > 0.0)
            }
            _ => None,
        };
        rows.push(MotRow {
            frame,
            id: id as i64,
            bbox,
            length_px,
            line,
        });
    }
    Ok(rows)
}

fn check_header(
    path: &Path,
    rdr: &mut csv::Reader<std::fs::File>,
    want: &[&str],
) -> Result<(), InputError> {
    let got = rdr.headers().map_err(|e| csv_error(path, e))?.clone();
    let got: Vec<&str> = got.iter().collect();
    if got != want {
        return Err(at(
            path,
            1,
            format!(
                "header is `{}`, expected `{}`",
                got.join(","),
                want.join(",")
            ),
        ));
    }
    Ok(())
}

fn reader(path: &Path) -> Result<csv::Reader<std::fs::File>, InputError> {
    csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| InputError::file(path, format!("cannot open: {e}")))
}

/// Reads `fish.csv` (header row required; track ids unique).
pub fn read_fish(path: &Path) -> Result<Vec<FishRow>, InputError> {
    let mut rdr = reader(path)?;
    check_header(path, &mut rdr, &FISH_HEADER)?;
    let mut rows: Vec<FishRow> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| csv_error(path, e))?;
        let line = line_of(&rec);
        let row: FishRow = rec
            .deserialize(None)
            .map_err(|e| at(path, line, format!("bad fish row: {e}")))?;
        if let Some(l) = row.length_mm {
            if !l.is_finite() || l <= 0.0 {
                return Err(at(
                    path,
                    line,
                    format!("length_mm {l} must be finite and > 0"),
                ));
            }
        }
        if !seen.insert(row.track_id) {
            return Err(at(
                path,
                line,
                format!("track_id {} appears twice", row.track_id),
            ));
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Reads `stereo.csv` (header row required), checking every row: frame
/// ≥ 1, finite numbers, boxes of non-negative size, each group all present
/// or all empty.
pub fn read_stereo(path: &Path) -> Result<Vec<StereoRow>, InputError> {
    let mut rdr = reader(path)?;
    check_header(path, &mut rdr, &STEREO_HEADER)?;
    let mut rows = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| csv_error(path, e))?;
        let line = line_of(&rec);
        if rec.len() != STEREO_HEADER.len() {
            return Err(at(
                path,
                line,
                format!("{} columns, expected {}", rec.len(), STEREO_HEADER.len()),
            ));
        }
        // frame first, for its own message (1-based, whole)
        parse_frame(path, line, &rec[0])?;
        for (k, name) in STEREO_HEADER.iter().enumerate().skip(1) {
            if !rec[k].is_empty() {
                parse_f64(path, line, name, &rec[k])?;
            }
        }
        let mut row: StereoRow = rec
            .deserialize(None)
            .map_err(|e| at(path, line, format!("bad stereo row: {e}")))?;
        row.line = line;
        for (from, g) in row.groups() {
            if g.iter().any(Option::is_some) {
                if let Some(k) = g.iter().position(Option::is_none) {
                    return Err(at(
                        path,
                        line,
                        format!(
                            "column `{}` is empty but others of its group are not",
                            STEREO_HEADER[from + k]
                        ),
                    ));
                }
            }
        }
        check_box(path, line, &row.left())?;
        if let Some(r) = row.right() {
            check_box(path, line, &r)?;
        }
        rows.push(row);
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    #[test]
    fn reads_mot_rows_with_optional_columns() {
        let f =
            file("1,3,10,20,30,40,1,-1,-1,-1\n2,-1,1.5,2,3,4\n3,-1,0,0,5,9,0.9,-1,-1,-1,12.5\n");
        let rows = read_mot(f.path()).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].bbox, [10.0, 20.0, 30.0, 40.0]);
        assert_eq!((rows[1].frame, rows[1].id), (2, -1));
        assert_eq!(rows[2].length_px, Some(12.5));
    }

    #[test]
    fn mot_errors_name_file_and_line() {
        let f = file("1,3,10,20,30,40\n0,3,10,20,30,40\n");
        let e = read_mot(f.path()).unwrap_err();
        assert!(e.location.ends_with(": line 2"), "{e}");
        assert!(e.message.contains("1-based"), "{e}");
        let f = file("1,3,10,20,30,40\n1,3,x,20,30,40\n");
        let e = read_mot(f.path()).unwrap_err();
        assert!(
            e.to_string().contains("line 2") && e.to_string().contains("bb_left"),
            "{e}"
        );
        let f = file("1,3,10\n");
        assert!(read_mot(f.path())
            .unwrap_err()
            .to_string()
            .contains("line 1"));
    }

    #[test]
    fn reads_fish_with_empty_length() {
        let f = file("track_id,first_frame,last_frame,frames,length_mm,length_sd_mm,range_mm\n1,1,4,4,512.5,3.1,2000\n2,3,4,2,,,\n");
        let rows = read_fish(f.path()).unwrap();
        assert_eq!(rows[0].length_mm, Some(512.5));
        assert_eq!(rows[1].length_mm, None);
        let f = file("track,first_frame\n");
        assert!(read_fish(f.path())
            .unwrap_err()
            .to_string()
            .contains("line 1"));
        let f = file(
            "track_id,first_frame,last_frame,frames,length_mm,length_sd_mm,range_mm\n1,1,4,4,x,,\n",
        );
        assert!(read_fish(f.path())
            .unwrap_err()
            .to_string()
            .contains("line 2"));
    }

    #[test]
    fn reads_stereo_rows() {
        let h = STEREO_HEADER.join(",");
        let f = file(&format!(
            "{h}\n1,0,0,10,10,5,0,10,10,1,2,3,4,5,6,7.5\n1,0,0,10,10,,,,,,,,,,,\n"
        ));
        let rows = read_stereo(f.path()).unwrap();
        assert_eq!(rows[0].right(), Some([5.0, 0.0, 10.0, 10.0]));
        assert_eq!(rows[0].head(), Some([1.0, 2.0, 3.0]));
        assert_eq!(rows[0].length_mm, Some(7.5));
        assert_eq!(rows[0].line, 2);
        assert_eq!(rows[1].right(), None);
        let f = file(&format!("{h}\n1,0,0,10,10,5,,10,10,,,,,,,\n"));
        let e = read_stereo(f.path()).unwrap_err();
        assert!(
            e.to_string().contains("line 2") && e.to_string().contains("right_y"),
            "{e}"
        );
    }
}
