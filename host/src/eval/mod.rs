//! `fishtrack eval HAUL OUT`: scores a tracker output directory against
//! `HAUL/truth.json` (issue 3's metrics; paper Section V).
//!
//! Reads whichever of `OUT/tracks.csv` (+ `OUT/fish.csv`),
//! `OUT/detections.csv` and `OUT/stereo.csv` exist and scores:
//! detection precision/recall at IoU ≥ 0.4 against fish whose visible left
//! area is ≥ θ_A^L ([`truth_frames`], [`metrics`]), MOTA/IDF1/ID switches
//! exactly as py-motmetrics ([`mot`], checked against it by
//! `scripts/motmetrics_oracle.py`), the paper's tracking success rate
//! (eq. 16), count error, per-fish length MAPE, segmentation precision/
//! recall and the single-camera length of large targets, and stereo
//! pairing accuracy with per-frame 3-D length MAPE ([`stereo`]).

pub mod io;
pub mod lsap;
pub mod matching;
pub mod metrics;
pub mod mot;
pub mod report;
pub mod stereo;
pub mod truth_frames;

use std::collections::HashSet;
use std::path::Path;

use crate::error::InputError;
use crate::truth::Truth;

pub use report::Report;
pub use truth_frames::TruthFrames;

/// Loads `HAUL/truth.json` and scores `OUT` against it.
pub fn evaluate(haul: &Path, out: &Path) -> Result<Report, InputError> {
    let truth = Truth::load(&haul.join("truth.json"))?;
    evaluate_truth(&truth, out)
}

/// Checks MOT rows against the haul: frames within 1..=frames, and (for
/// tracks) no id twice in one frame.
fn check_rows(
    path: &Path,
    rows: &[io::MotRow],
    frames: u32,
    unique_ids: bool,
) -> Result<(), InputError> {
    let mut seen = HashSet::new();
    for r in rows {
        let at = || format!("{}: line {}", path.display(), r.line);
        if r.frame > frames {
            return Err(InputError::plain(
                at(),
                format!("frame {} is beyond the haul's {frames} frames", r.frame),
            ));
        }
        if unique_ids && !seen.insert((r.frame, r.id)) {
            return Err(InputError::plain(
                at(),
                format!("track id {} appears twice in frame {}", r.id, r.frame),
            ));
        }
    }
    Ok(())
}

/// Scores the output directory `out` against `truth`.
pub fn evaluate_truth(truth: &Truth, out: &Path) -> Result<Report, InputError> {
    let tf = TruthFrames::new(truth)?;
    let tracks_p = out.join("tracks.csv");
    let fish_p = out.join("fish.csv");
    let dets_p = out.join("detections.csv");
    let stereo_p = out.join("stereo.csv");
    if !tracks_p.is_file() && !dets_p.is_file() && !stereo_p.is_file() {
        return Err(InputError::file(
            out,
            "no tracks.csv, detections.csv or stereo.csv to evaluate",
        ));
    }

    let tracking = if tracks_p.is_file() {
        let tracks = io::read_mot(&tracks_p)?;
        check_rows(&tracks_p, &tracks, truth.frames, true)?;
        let fish = if fish_p.is_file() {
            Some(io::read_fish(&fish_p)?)
        } else {
            None
        };
        Some(metrics::score_tracks(&tf, &tracks, fish.as_deref()))
    } else {
        None
    };
    let mut tracking = tracking;
    let segmentation = if dets_p.is_file() {
        let dets = io::read_mot(&dets_p)?;
        check_rows(&dets_p, &dets, truth.frames, false)?;
        if let Some(t) = tracking.as_mut() {
            t.success_detected = Some(metrics::score_success_detected(&tf, &t.success, &dets));
        }
        Some(metrics::score_detections(&tf, &dets))
    } else {
        None
    };
    let stereo = if stereo_p.is_file() {
        let rows = io::read_stereo(&stereo_p)?;
        if let Some(r) = rows.iter().find(|r| r.frame > truth.frames) {
            return Err(InputError::plain(
                format!("{}: line {}", stereo_p.display(), r.line),
                format!(
                    "frame {} is beyond the haul's {} frames",
                    r.frame, truth.frames
                ),
            ));
        }
        Some(stereo::score_stereo(&tf, &rows))
    } else {
        None
    };

    Ok(Report {
        frames: truth.frames,
        truth_fish: truth.fish.len() as u64,
        countable_fish: tf.countable_fish().len() as u64,
        area_min_px: tf.area_min,
        iou_min: 1.0 - matching::MAX_DISTANCE,
        tracking,
        segmentation,
        stereo,
    })
}
