//! Segmentation-only detection over a haul (Section III, Fig. 2): every
//! left frame is rectified, segmented by the core's
//! [`segment_frame`](fishtrack_core::segment::segment_frame), and its
//! objects are written to `OUT/detections.csv` (MOT rows, id −1, upright
//! boxes in raw left pixels, 11th column the oriented PCA length in raw
//! left pixels). `fishtrack eval` then scores segmentation precision/recall
//! and the single-camera length of large targets (paper Section V.A);
//! `host/examples/seg_eval.rs` runs both.
//!
//! The oriented length is `2·half_w` of the object's PCA box, measured in
//! the raw image: the two end points of the box's first axis are mapped
//! back through the rectification ([`RectifiedCamera::rect_to_raw`]) and
//! their distance taken, so lens distortion does not bias it.

use std::path::Path;

use anyhow::{Context, Result};
use fishtrack_core::image::ImageView;
use fishtrack_core::object::Objects;
use fishtrack_core::params::Params;
use fishtrack_core::segment::{segment_frame, workspace_size, RECOMMENDED_MAX_ROI_PIXELS};

use crate::calib::StereoCalib;
use crate::haul::Haul;
use crate::output::{write_detections, DetectionRow};
use crate::rectify::{in_raw_view, RectifiedCamera, Rectifier, Scaling};

/// Object capacity per frame (issue 4's recommended `Objects<64, 16384>`).
pub const MAX_OBJECTS: usize = 64;
/// Mask-run capacity per frame.
pub const MAX_RUNS: usize = 16384;

/// Counters over one [`detect_haul`] run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DetectSummary {
    /// Frames processed.
    pub frames: u32,
    /// Objects written.
    pub objects: u64,
    /// Objects dropped by capacity.
    pub dropped: u64,
}

/// Loads the haul's calibration (any supported layout; the first frame's
/// size stands in where the layout records none).
pub fn load_calibration(haul: &Haul) -> Result<StereoCalib> {
    haul.calibration()?;
    let size = match haul.frames.first() {
        Some(p) => {
            let (l, _) = haul.load_pair(p, None)?;
            Some(l.dimensions())
        }
        None => None,
    };
    Ok(StereoCalib::load(&haul.dir, size)?)
}

/// The raw-left detection rows of one rectified left frame's objects.
pub fn detection_rows<const N: usize, const R: usize>(
    frame: u32,
    objs: &Objects<N, R>,
    cam: &RectifiedCamera,
) -> Vec<DetectionRow> {
    let mut rows = Vec::with_capacity(objs.items.len());
    for o in objs.items.iter() {
        let bbox = cam.raw_box(&o.bbox);
        if !in_raw_view(&bbox) {
            // wholly in the fill of an alpha > 0 rectification
            continue;
        }
        rows.push(DetectionRow {
            frame,
            bbox,
            conf: 1.0,
            length_px: cam.raw_axis_length(&o.obb),
        });
    }
    rows
}

/// Segments every left frame of `haul_dir` with `params` (already scaled to
/// the frame size) and writes `out_dir/detections.csv`.
pub fn detect_haul(haul_dir: &Path, params: &Params, out_dir: &Path) -> Result<DetectSummary> {
    detect_haul_scaling(haul_dir, params, Scaling::default(), out_dir)
}

/// [`detect_haul`] with the rectification's free scaling `scaling`
/// ([`Rectifier::with_scaling`]).
pub fn detect_haul_scaling(
    haul_dir: &Path,
    params: &Params,
    scaling: Scaling,
    out_dir: &Path,
) -> Result<DetectSummary> {
    let haul = Haul::open(haul_dir)?;
    let calib = load_calibration(&haul)?;
    let rect = Rectifier::with_scaling(&calib, scaling);
    // the rectified frames' size (a canvas is larger than the raw frame)
    let (w, h) = (rect.size().0 as usize, rect.size().1 as usize);
    let mut ws = vec![0u8; workspace_size(w, h, RECOMMENDED_MAX_ROI_PIXELS)];
    let mut objs: Box<Objects<MAX_OBJECTS, MAX_RUNS>> = Box::default();
    let mut rows = Vec::new();
    let mut sum = DetectSummary::default();
    for pair in &haul.frames {
        let (left, _) = haul.load_pair(pair, Some((calib.width, calib.height)))?;
        let rl = rect
            .rectify_left(&left)
            .with_context(|| format!("rectifying frame {}", pair.index))?;
        let view = ImageView::packed(rl.as_raw(), w, h)
            .map_err(|e| anyhow::anyhow!("frame {}: {e}", pair.index))?;
        let st = segment_frame(view, params, &mut ws, &mut objs)
            .map_err(|e| anyhow::anyhow!("frame {}: {e}", pair.index))?;
        sum.frames += 1;
        sum.objects += objs.items.len() as u64;
        sum.dropped += st.dropped as u64;
        rows.extend(detection_rows(pair.index, &objs, &rect.left));
    }
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    write_detections(&out_dir.join("detections.csv"), &rows)?;
    Ok(sum)
}
