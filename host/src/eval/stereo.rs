//! Scoring the per-frame stereo output `OUT/stereo.csv` (paper Sections
//! IV.A, stereo pairing, and IV.D.2, 3-D length; format in
//! [`super::io::StereoRow`]).
//!
//! Population: truth fish-frames wholly inside both views (`inside_left &&
//! inside_right`, both boxes present). Per frame, stereo rows are matched to
//! the truth's left boxes one-to-one ([`super::matching`], IoU ≥ 0.4). A
//! fish-frame is *correctly paired* when its matched row's right box
//! overlaps the same fish's right box with IoU ≥ 0.4. Its length error uses
//! the matched row's `length_mm` (pairing right or wrong).
//!
//! Two pairing figures: [`StereoScore::pairing_accuracy`] over every such
//! fish-frame (what issue 5 asks; a fish the segmentation missed counts as
//! unpaired), and [`StereoScore::pairing_accuracy_detected`] over those
//! whose left object was segmented (a row matched it) — the part the
//! pairing stage is responsible for — with its failures split into
//! *wrongly paired* (a right box that is not the fish's) and *unpaired*.

use std::collections::BTreeMap;

use serde::Serialize;

use super::io::StereoRow;
use super::matching::{iou_distances, match_boxes, MAX_DISTANCE};
use super::metrics::LengthScore;
use super::truth_frames::TruthFrames;

/// Stereo pairing accuracy and per-frame length error.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StereoScore {
    /// Truth fish-frames wholly inside both views.
    pub fish_frames: u64,
    /// Of those, correctly paired.
    pub correctly_paired: u64,
    /// correctly_paired / fish_frames.
    pub pairing_accuracy: f64,
    /// Of `fish_frames`, those whose left object was segmented (a row matched).
    pub detected: u64,
    /// correctly_paired / detected.
    pub pairing_accuracy_detected: f64,
    /// Detected fish-frames paired with a right box that is not the fish's.
    pub wrongly_paired: u64,
    /// Detected fish-frames left unpaired.
    pub unpaired: u64,
    /// Per-frame length MAPE over those fish-frames (measured = a matched
    /// row with a length).
    pub length: LengthScore,
}

/// Scores `stereo.csv`.
pub fn score_stereo(tf: &TruthFrames<'_>, rows: &[StereoRow]) -> StereoScore {
    let mut by_frame: BTreeMap<u32, Vec<&StereoRow>> = BTreeMap::new();
    for r in rows {
        by_frame.entry(r.frame).or_default().push(r);
    }
    let (mut total, mut correct, mut detected, mut wrong, mut unpaired) = (0u64, 0, 0, 0, 0);
    let mut pairs = Vec::new();
    for f in 1..=tf.truth.frames {
        let (objs, boxes) = tf.left_objects(f);
        let frame_rows = by_frame.get(&f).map_or(&[][..], |v| v.as_slice());
        let lefts: Vec<[f64; 4]> = frame_rows.iter().map(|r| r.left()).collect();
        let matched: BTreeMap<usize, usize> = match_boxes(&boxes, &lefts, MAX_DISTANCE)
            .into_iter()
            .collect();
        for (k, o) in objs.iter().enumerate() {
            let Some(truth_right) = o.at.right_box else {
                continue;
            };
            if !(o.at.inside_left && o.at.inside_right) {
                continue;
            }
            total += 1;
            let Some(&p) = matched.get(&k) else { continue };
            let row = frame_rows[p];
            detected += 1;
            match row.right() {
                Some(r) if iou_distances(&[truth_right], &[r], MAX_DISTANCE)[0].is_finite() => {
                    correct += 1
                }
                Some(_) => wrong += 1,
                None => unpaired += 1,
            }
            if let Some(l) = row.length_mm {
                pairs.push((l, tf.truth.fish[o.fish].length_mm));
            }
        }
    }
    StereoScore {
        fish_frames: total,
        correctly_paired: correct,
        pairing_accuracy: correct as f64 / total as f64,
        detected,
        pairing_accuracy_detected: correct as f64 / detected as f64,
        wrongly_paired: wrong,
        unpaired,
        length: LengthScore::from_pairs(&pairs, total),
    }
}
