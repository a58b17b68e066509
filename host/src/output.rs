//! Writing `fishtrack track`'s outputs (DESIGN.md, "Output"): `tracks.csv`,
//! `fish.csv`, `detections.csv`, `detections.viame.csv`, `stereo.csv` and
//! `summary.json`.
//!
//! Every file is written atomically: into a temporary file in the output
//! directory, flushed and synced, then renamed over the final name. An
//! interrupted run leaves either the previous complete file or none, never a
//! half-written CSV that looks complete. Nothing written depends on the clock,
//! so rerunning on the same haul gives byte-identical files.

use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};

use crate::eval::io::{FISH_HEADER, STEREO_HEADER};

/// One `tracks.csv` row (MOTChallenge): a track in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackRow {
    /// Frame, from 1.
    pub frame: u32,
    /// Track id, from 1.
    pub id: u32,
    /// Upright box `[x, y, w, h]` in raw left-image pixels.
    pub bbox: [f64; 4],
    /// Confidence in `[0, 1]` (1 for an observed frame, lower for a frame
    /// carried by prediction).
    pub conf: f64,
    /// 3-D centroid in mm, left camera frame, if known.
    pub xyz: Option<[f64; 3]>,
}

/// One `detections.csv` row: a segmented object of the left view.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectionRow {
    /// Frame, from 1.
    pub frame: u32,
    /// Upright box `[x, y, w, h]` in raw left-image pixels.
    pub bbox: [f64; 4],
    /// Confidence in `[0, 1]`.
    pub conf: f64,
    /// Oriented (PCA major-axis) length in raw left pixels (11th column).
    pub length_px: Option<f64>,
}

/// One `fish.csv` row: a counted fish.
#[derive(Debug, Clone, PartialEq)]
pub struct FishOut {
    /// Track id, as in `tracks.csv`.
    pub track_id: u32,
    /// First frame.
    pub first_frame: u32,
    /// Last frame.
    pub last_frame: u32,
    /// Number of frames in the track.
    pub frames: u32,
    /// Median per-frame length, mm (`None`: no frame allowed a measurement).
    pub length_mm: Option<f64>,
    /// Robust SD (1.4826 · MAD) of the per-frame lengths, mm.
    pub length_sd_mm: Option<f64>,
    /// Median range (distance from the left camera), mm.
    pub range_mm: Option<f64>,
}

/// One `stereo.csv` row: the same type `fishtrack eval` reads.
pub use crate::eval::io::StereoRow;

/// Writes `path` atomically: `fill` writes the contents into a temporary
/// file in the same directory, which is synced and renamed over `path`.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".partial");
    // As an ordinary file create would: 0666 less the umask (tempfile's own
    // default, 0600, would hide survey outputs from the rest of the team).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder
        .tempfile_in(dir)
        .with_context(|| format!("{}: cannot create a temporary file", dir.display()))?;
    {
        let mut w = BufWriter::new(tmp.as_file());
        fill(&mut w).with_context(|| format!("{}: write failed", path.display()))?;
        w.flush()
            .with_context(|| format!("{}: write failed", path.display()))?;
    }
    tmp.as_file()
        .sync_all()
        .with_context(|| format!("{}: sync failed", path.display()))?;
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("{}: cannot rename into place", path.display()))?;
    Ok(())
}

/// A number as CSV text: shortest round-trip form, 3 decimals at most for
/// pixel and mm values (sub-micrometre digits are noise).
fn num(v: f64) -> String {
    let r = (v * 1000.0).round() / 1000.0;
    if r == 0.0 {
        "0".to_string()
    } else {
        format!("{r}")
    }
}

fn opt(v: Option<f64>) -> String {
    v.map(num).unwrap_or_default()
}

/// `tracks.csv`: `frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z`, no header.
pub fn write_tracks(path: &Path, rows: &[TrackRow]) -> Result<()> {
    write_atomic(path, |w| {
        for r in rows {
            let [x, y, z] = r
                .xyz
                .map(|p| p.map(num))
                .unwrap_or_else(|| ["-1".into(), "-1".into(), "-1".into()]);
            writeln!(
                w,
                "{},{},{},{},{},{},{},{x},{y},{z}",
                r.frame,
                r.id,
                num(r.bbox[0]),
                num(r.bbox[1]),
                num(r.bbox[2]),
                num(r.bbox[3]),
                num(r.conf)
            )?;
        }
        Ok(())
    })
}

/// `detections.csv`: MOT rows with id −1, `x,y,z` = −1, and the oriented
/// length in raw left pixels as an 11th column (empty if unknown).
pub fn write_detections(path: &Path, rows: &[DetectionRow]) -> Result<()> {
    write_atomic(path, |w| {
        for r in rows {
            writeln!(
                w,
                "{},-1,{},{},{},{},{},-1,-1,-1,{}",
                r.frame,
                num(r.bbox[0]),
                num(r.bbox[1]),
                num(r.bbox[2]),
                num(r.bbox[3]),
                num(r.conf),
                opt(r.length_px)
            )?;
        }
        Ok(())
    })
}

/// `fish.csv`, with its header row.
pub fn write_fish(path: &Path, rows: &[FishOut]) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "{}", FISH_HEADER.join(","))?;
        for r in rows {
            writeln!(
                w,
                "{},{},{},{},{},{},{}",
                r.track_id,
                r.first_frame,
                r.last_frame,
                r.frames,
                opt(r.length_mm),
                opt(r.length_sd_mm),
                opt(r.range_mm)
            )?;
        }
        Ok(())
    })
}

/// `stereo.csv`, with its header row (format: [`StereoRow`], written
/// through serde; the header is written even when there are no rows).
pub fn write_stereo(path: &Path, rows: &[StereoRow]) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "{}", STEREO_HEADER.join(","))?;
        let mut cw = csv::WriterBuilder::new().has_headers(false).from_writer(w);
        for r in rows {
            cw.serialize(r).map_err(std::io::Error::other)?;
        }
        cw.flush()
    })
}

/// `detections.viame.csv`: the tracks in VIAME's CSV format, so they open in
/// VIAME / DIVE. Columns: track id, image file, frame (0-based), TL_x, TL_y,
/// BR_x, BR_y, confidence, fish length in mm (−1 if none), then the class
/// `fish` with its confidence. The two `#` header lines are the ones VIAME's
/// DIVE writer emits (without the export time, so reruns are identical).
pub fn write_viame(
    path: &Path,
    rows: &[TrackRow],
    fish: &[FishOut],
    frame_files: &[String],
    fps: f64,
) -> Result<()> {
    let length_of = |id: u32| {
        fish.iter()
            .find(|f| f.track_id == id)
            .and_then(|f| f.length_mm)
    };
    write_atomic(path, |w| {
        writeln!(
            w,
            "# 1: Detection or Track-id,2: Video or Image Identifier,3: Unique Frame Identifier,\
             4-7: Img-bbox(TL_x,TL_y,BR_x,BR_y),8: Detection or Length Confidence,\
             9: Target Length (0 or -1 if invalid),10-11+: Repeated Species,Confidence Pairs or Attributes"
        )?;
        writeln!(
            w,
            "# metadata,fps: {},\"exported_by: \"\"fishtrack\"\"\"",
            num(fps)
        )?;
        for r in rows {
            let image = frame_files
                .get(r.frame.saturating_sub(1) as usize)
                .map(String::as_str)
                .unwrap_or("");
            let len = length_of(r.id).map(num).unwrap_or_else(|| "-1".into());
            writeln!(
                w,
                "{},{image},{},{},{},{},{},{},{len},fish,{}",
                r.id,
                r.frame.saturating_sub(1),
                num(r.bbox[0]),
                num(r.bbox[1]),
                num(r.bbox[0] + r.bbox[2]),
                num(r.bbox[1] + r.bbox[3]),
                num(r.conf),
                num(r.conf)
            )?;
        }
        Ok(())
    })
}

/// `summary.json`, pretty-printed.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        writeln!(w)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::io::{read_fish, read_mot, read_stereo};

    #[test]
    fn written_files_read_back_through_eval() {
        let dir = tempfile::tempdir().unwrap();
        let tracks = vec![
            TrackRow {
                frame: 1,
                id: 3,
                bbox: [10.5, 20.0, 30.25, 40.0],
                conf: 1.0,
                xyz: Some([1.0, -2.0, 1500.0]),
            },
            TrackRow {
                frame: 2,
                id: 3,
                bbox: [5.0, 21.0, 30.0, 40.0],
                conf: 0.5,
                xyz: None,
            },
        ];
        write_tracks(&dir.path().join("tracks.csv"), &tracks).unwrap();
        let back = read_mot(&dir.path().join("tracks.csv")).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].bbox, [10.5, 20.0, 30.25, 40.0]);
        assert_eq!(back[1].id, 3);

        let fish = vec![FishOut {
            track_id: 3,
            first_frame: 1,
            last_frame: 2,
            frames: 2,
            length_mm: Some(412.25),
            length_sd_mm: None,
            range_mm: Some(1500.0),
        }];
        write_fish(&dir.path().join("fish.csv"), &fish).unwrap();
        let f = read_fish(&dir.path().join("fish.csv")).unwrap();
        assert_eq!(f[0].length_mm, Some(412.25));
        assert_eq!(f[0].length_sd_mm, None);

        let st = vec![
            StereoRow::new(1, [1.0, 2.0, 3.0, 4.0], None, None, None, None),
            StereoRow::new(
                2,
                [1.0, 2.0, 3.0, 4.0],
                Some([0.0, 2.0, 3.0, 4.0]),
                Some([0.0, 0.0, 1000.0]),
                Some([300.0, 0.0, 1000.00049]),
                Some(300.0),
            ),
        ];
        write_stereo(&dir.path().join("stereo.csv"), &st).unwrap();
        let s = read_stereo(&dir.path().join("stereo.csv")).unwrap();
        assert_eq!(s[0].right(), None);
        assert_eq!(s[1].length_mm, Some(300.0));
        assert_eq!(s[1].tail(), Some([300.0, 0.0, 1000.0]));
        // the serde field names are the documented header, in order
        let mut cw = csv::Writer::from_writer(Vec::new());
        cw.serialize(&st[0]).unwrap();
        let text = String::from_utf8(cw.into_inner().unwrap()).unwrap();
        assert_eq!(text.lines().next().unwrap(), STEREO_HEADER.join(","));
        // the same rows read back equal (line numbers aside)
        let back: Vec<StereoRow> = s.into_iter().map(|r| StereoRow { line: 0, ..r }).collect();
        assert_eq!(back, st);
        // an empty file still carries the header
        write_stereo(&dir.path().join("empty.csv"), &[]).unwrap();
        assert!(read_stereo(&dir.path().join("empty.csv"))
            .unwrap()
            .is_empty());

        let det = vec![DetectionRow {
            frame: 4,
            bbox: [1.0, 2.0, 3.0, 4.0],
            conf: 1.0,
            length_px: Some(5.5),
        }];
        write_detections(&dir.path().join("detections.csv"), &det).unwrap();
        let d = read_mot(&dir.path().join("detections.csv")).unwrap();
        assert_eq!((d[0].id, d[0].length_px), (-1, Some(5.5)));

        write_viame(
            &dir.path().join("v.csv"),
            &tracks,
            &fish,
            &["a.png".into(), "b.png".into()],
            5.0,
        )
        .unwrap();
        let v = std::fs::read_to_string(dir.path().join("v.csv")).unwrap();
        let lines: Vec<&str> = v.lines().collect();
        assert!(lines[0].starts_with("# 1: Detection or Track-id,2: Video or Image Identifier"));
        assert!(lines[1].starts_with("# metadata,fps: 5"));
        assert_eq!(lines[2], "3,a.png,0,10.5,20,40.75,60,1,412.25,fish,1");
        assert_eq!(lines[3], "3,b.png,1,5,21,35,61,0.5,412.25,fish,0.5");
        // no temporary files left behind
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().ends_with(".partial"))
            .collect();
        assert!(left.is_empty());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(dir.path().join("fish.csv"))
                .unwrap()
                .permissions()
                .mode();
            assert_ne!(mode & 0o044, 0, "readable beyond the owner: {mode:o}");
        }
    }

    #[test]
    fn failed_write_keeps_the_previous_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("fish.csv");
        std::fs::write(&p, "old complete file\n").unwrap();
        let r = write_atomic(&p, |w| {
            writeln!(w, "half")?;
            Err(std::io::Error::other("interrupted"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old complete file\n");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "temporary file removed"
        );
    }
}
