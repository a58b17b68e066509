//! Detection precision/recall, the paper's tracking success rate (eq. 16),
//! count error, and length errors (MAPE) — from per-frame matchings of the
//! tracker's boxes to the truth's left boxes.
//!
//! Per frame, predictions are matched one-to-one to **all** truth left boxes
//! by the optimal assignment on `1 − IoU` (IoU ≥ 0.4, [`super::matching`]).
//! A prediction matched to a fish that is not countable (visible left area
//! < θ_A^L) is *ignored* — neither TP nor FP, as MOTChallenge's
//! preprocessing drops predictions on distractors; a prediction matched to
//! a countable fish is a TP, an unmatched prediction an FP, an unmatched
//! countable fish an FN.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use super::io::{FishRow, MotRow};
use super::matching::{match_boxes, MAX_DISTANCE};
use super::mot::{MotAccumulator, MotSummary};
use super::truth_frames::{TruthFrames, TruthObject};

/// What became of one prediction in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PredState {
    /// Matched to a countable fish (its index in `truth.fish`).
    Hit(usize),
    /// Matched to a fish below θ_A^L (its index): ignored.
    Ignored(usize),
    /// Unmatched: a false positive.
    False,
}

/// The matching of one frame.
#[derive(Debug, Clone)]
pub struct FrameMatch {
    /// Per prediction, in input order.
    pub preds: Vec<PredState>,
    /// Countable fish of the frame that no prediction matched.
    pub missed: Vec<usize>,
    /// Countable fish in the frame.
    pub countable: usize,
}

/// Matches the predicted boxes of frame `f` against the truth.
pub fn match_frame(tf: &TruthFrames<'_>, f: u32, boxes: &[[f64; 4]]) -> FrameMatch {
    let (objs, truth_boxes) = tf.left_objects(f);
    let pairs = match_boxes(&truth_boxes, boxes, MAX_DISTANCE);
    let mut preds = vec![PredState::False; boxes.len()];
    let mut hit = vec![false; objs.len()];
    for &(o, p) in &pairs {
        hit[o] = true;
        preds[p] = if objs[o].countable {
            PredState::Hit(objs[o].fish)
        } else {
            PredState::Ignored(objs[o].fish)
        };
    }
    let missed = objs
        .iter()
        .zip(&hit)
        .filter(|(o, h)| o.countable && !**h)
        .map(|(o, _)| o.fish)
        .collect();
    FrameMatch {
        preds,
        missed,
        countable: objs.iter().filter(|o| o.countable).count(),
    }
}

/// Detection precision and recall at IoU ≥ 0.4.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DetectionScore {
    /// Predictions matched to countable fish.
    pub tp: u64,
    /// Unmatched predictions.
    pub fp: u64,
    /// Countable fish-frames without a prediction.
    pub fn_: u64,
    /// Predictions matched to fish below θ_A^L (not counted).
    pub ignored: u64,
    /// Σtp / Σ(tp + fp) over all frames (micro average).
    pub precision: f64,
    /// Σtp / Σ(tp + fn) over all frames.
    pub recall: f64,
    /// Mean over frames with ≥ 1 counted prediction of tp / (tp + fp).
    pub mean_frame_precision: f64,
    /// Mean over frames with ≥ 1 countable fish of tp / (tp + fn).
    pub mean_frame_recall: f64,
}

/// Accumulates a [`DetectionScore`] frame by frame.
#[derive(Debug, Default)]
pub struct DetectionTally {
    s: DetectionScore,
    p_sum: f64,
    p_n: u64,
    r_sum: f64,
    r_n: u64,
}

impl DetectionTally {
    /// Adds one frame.
    pub fn add(&mut self, m: &FrameMatch) {
        let tp = m
            .preds
            .iter()
            .filter(|p| matches!(p, PredState::Hit(_)))
            .count() as u64;
        let fp = m.preds.iter().filter(|p| **p == PredState::False).count() as u64;
        let ig = m
            .preds
            .iter()
            .filter(|p| matches!(p, PredState::Ignored(_)))
            .count() as u64;
        let fn_ = m.missed.len() as u64;
        self.s.tp += tp;
        self.s.fp += fp;
        self.s.fn_ += fn_;
        self.s.ignored += ig;
        if tp + fp > 0 {
            self.p_sum += tp as f64 / (tp + fp) as f64;
            self.p_n += 1;
        }
        if tp + fn_ > 0 {
            self.r_sum += tp as f64 / (tp + fn_) as f64;
            self.r_n += 1;
        }
    }

    /// The score (ratios are NaN where their denominator is 0).
    pub fn finish(mut self) -> DetectionScore {
        let s = &mut self.s;
        s.precision = s.tp as f64 / (s.tp + s.fp) as f64;
        s.recall = s.tp as f64 / (s.tp + s.fn_) as f64;
        s.mean_frame_precision = self.p_sum / self.p_n as f64;
        s.mean_frame_recall = self.r_sum / self.r_n as f64;
        self.s
    }
}

/// Rows of `rows` grouped by frame, file order kept.
pub fn by_frame(rows: &[MotRow]) -> BTreeMap<u32, Vec<&MotRow>> {
    let mut m: BTreeMap<u32, Vec<&MotRow>> = BTreeMap::new();
    for r in rows {
        m.entry(r.frame).or_default().push(r);
    }
    m
}

fn frames_of(tf: &TruthFrames<'_>, rows: &BTreeMap<u32, Vec<&MotRow>>) -> BTreeSet<u32> {
    (1..=tf.truth.frames).chain(rows.keys().copied()).collect()
}

/// The inputs of the CLEAR MOT / ID evaluation, MOTChallenge style: the
/// ground truth is the countable fish (id = fish id), the hypotheses are the
/// predictions not ignored (id = track id). Rows `(frame, id, box)` in frame
/// order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MotInputs {
    /// Ground-truth rows.
    pub gt: Vec<(u32, i64, [f64; 4])>,
    /// Hypothesis rows.
    pub hyp: Vec<(u32, i64, [f64; 4])>,
}

impl MotInputs {
    /// Runs the accumulator over all frames with `max_distance` (1 − IoU).
    pub fn summarize(&self, max_distance: f64) -> MotSummary {
        let mut acc = MotAccumulator::new(max_distance);
        let mut gt: BTreeMap<u32, (Vec<i64>, Vec<[f64; 4]>)> = BTreeMap::new();
        let mut hyp: BTreeMap<u32, (Vec<i64>, Vec<[f64; 4]>)> = BTreeMap::new();
        for (map, rows) in [(&mut gt, &self.gt), (&mut hyp, &self.hyp)] {
            for &(f, id, b) in rows {
                let e = map.entry(f).or_default();
                e.0.push(id);
                e.1.push(b);
            }
        }
        let frames: BTreeSet<u32> = gt.keys().chain(hyp.keys()).copied().collect();
        let empty = (Vec::new(), Vec::new());
        for f in frames {
            let g = gt.get(&f).unwrap_or(&empty);
            let h = hyp.get(&f).unwrap_or(&empty);
            acc.update(&g.0, &g.1, &h.0, &h.1);
        }
        acc.summary()
    }
}

/// Builds the [`MotInputs`] of a tracker output.
pub fn mot_inputs(tf: &TruthFrames<'_>, tracks: &[MotRow]) -> MotInputs {
    let rows = by_frame(tracks);
    let mut out = MotInputs::default();
    for f in frames_of(tf, &rows) {
        for o in tf.at(f).iter().filter(|o| o.countable) {
            if let Some(b) = o.left_box() {
                out.gt.push((f, o.id, b));
            }
        }
        let preds = rows.get(&f).map_or(&[][..], |v| v.as_slice());
        let boxes: Vec<[f64; 4]> = preds.iter().map(|r| r.bbox).collect();
        let m = match_frame(tf, f, &boxes);
        for (r, st) in preds.iter().zip(&m.preds) {
            if !matches!(st, PredState::Ignored(_)) {
                out.hyp.push((f, r.id, r.bbox));
            }
        }
    }
    out
}

/// The paper's tracking success rate, eq. (16).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SuccessScore {
    /// Fish with ≥ 1 countable frame ("correctly detected" population).
    pub fish: u64,
    /// Fish correctly labelled: every matched countable frame carries one
    /// track id, no other fish's matched frames carry it, and it is matched
    /// in at least half of its countable frames.
    pub correctly_labelled: u64,
    /// correctly_labelled / fish.
    pub rate: f64,
    /// Per truth fish (index of `truth.fish`): correctly labelled.
    #[serde(skip)]
    pub labelled: Vec<bool>,
    /// Per truth fish: its countable frames.
    #[serde(skip)]
    pub countable_frames: Vec<u64>,
}

/// Count error: (tracks − fish) / fish.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CountScore {
    /// Tracks reported (rows of fish.csv, else distinct ids of tracks.csv).
    pub tracks: u64,
    /// Truth fish with ≥ 1 countable frame.
    pub fish: u64,
    /// (tracks − fish) / fish.
    pub error: f64,
}

/// Length error against the truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LengthScore {
    /// Items that could be measured (the population).
    pub measurable: u64,
    /// Items that carry an estimate.
    pub measured: u64,
    /// measured / measurable.
    pub fraction_measured: f64,
    /// Mean of |estimate − truth| / truth over the measured items (fraction, 0.05 = 5 %).
    pub mape: f64,
}

impl LengthScore {
    /// From (estimate, truth) pairs of the measured items and the population size.
    pub fn from_pairs(pairs: &[(f64, f64)], measurable: u64) -> Self {
        let ape: f64 = pairs.iter().map(|(e, t)| (e - t).abs() / t).sum();
        LengthScore {
            measurable,
            measured: pairs.len() as u64,
            fraction_measured: pairs.len() as f64 / measurable as f64,
            mape: ape / pairs.len() as f64,
        }
    }
}

/// Everything scored from `tracks.csv` (and `fish.csv`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrackingScore {
    /// Per-frame detection precision/recall of the tracked boxes.
    pub detection: DetectionScore,
    /// CLEAR MOT and ID measures (motmetrics definitions, IoU ≥ 0.4).
    pub mot: MotSummary,
    /// Tracking success rate, eq. (16), over every countable fish.
    pub success: SuccessScore,
    /// Eq. (16) over the fish detections.csv found
    /// ([`score_success_detected`]; `None` without detections.csv).
    pub success_detected: Option<SuccessScore>,
    /// Count error.
    pub count: CountScore,
    /// Per-fish length MAPE from fish.csv over fish wholly inside both views
    /// in some frame (`None` without fish.csv).
    pub length: Option<LengthScore>,
}

/// Per truth fish: how many of its countable frames a box of `rows`
/// matches (one-to-one per frame, IoU ≥ 0.4, as every score here).
fn countable_hits(tf: &TruthFrames<'_>, rows: &[MotRow]) -> Vec<u64> {
    let by = by_frame(rows);
    let mut hits = vec![0u64; tf.truth.fish.len()];
    for f in frames_of(tf, &by) {
        let preds = by.get(&f).map_or(&[][..], |v| v.as_slice());
        let boxes: Vec<[f64; 4]> = preds.iter().map(|r| r.bbox).collect();
        for st in &match_frame(tf, f, &boxes).preds {
            if let PredState::Hit(k) = *st {
                hits[k] += 1;
            }
        }
    }
    hits
}

/// Eq. (16) as the paper words it, "correctly labelled / correctly
/// detected": the population is the countable fish that the *detections*
/// match in at least half of their countable frames (the bar eq. (16)
/// sets for a correct label), so fish the segmentation never found do not
/// count against the tracker. [`TrackingScore::success`] keeps every
/// countable fish in the population (stricter than the paper end to end;
/// the same with perfect detections).
pub fn score_success_detected(
    tf: &TruthFrames<'_>,
    success: &SuccessScore,
    dets: &[MotRow],
) -> SuccessScore {
    let hits = countable_hits(tf, dets);
    let detected: Vec<usize> = tf
        .countable_fish()
        .into_iter()
        .filter(|&k| 2 * hits[k] >= success.countable_frames[k] && hits[k] > 0)
        .collect();
    let correct = detected
        .iter()
        .filter(|&&k| success.labelled.get(k).copied().unwrap_or(false))
        .count() as u64;
    let n = detected.len() as u64;
    SuccessScore {
        fish: n,
        correctly_labelled: correct,
        rate: correct as f64 / n.max(1) as f64,
        labelled: Vec::new(),
        countable_frames: Vec::new(),
    }
}

/// Scores a tracker output.
pub fn score_tracks(
    tf: &TruthFrames<'_>,
    tracks: &[MotRow],
    fish_rows: Option<&[FishRow]>,
) -> TrackingScore {
    let rows = by_frame(tracks);
    let nfish = tf.truth.fish.len();
    let mut tally = DetectionTally::default();
    // Per fish: track ids matched in countable frames; all matched ids.
    let mut countable_ids: Vec<Vec<i64>> = vec![Vec::new(); nfish];
    let mut countable_frames = vec![0u64; nfish];
    let mut all_ids: Vec<BTreeMap<i64, u64>> = vec![BTreeMap::new(); nfish];
    for f in frames_of(tf, &rows) {
        let preds = rows.get(&f).map_or(&[][..], |v| v.as_slice());
        let boxes: Vec<[f64; 4]> = preds.iter().map(|r| r.bbox).collect();
        let m = match_frame(tf, f, &boxes);
        tally.add(&m);
        for o in tf.at(f).iter().filter(|o| o.countable) {
            countable_frames[o.fish] += 1;
        }
        for (r, st) in preds.iter().zip(&m.preds) {
            match *st {
                PredState::Hit(k) => {
                    countable_ids[k].push(r.id);
                    *all_ids[k].entry(r.id).or_insert(0) += 1;
                }
                PredState::Ignored(k) => *all_ids[k].entry(r.id).or_insert(0) += 1,
                PredState::False => {}
            }
        }
    }

    // Success rate, eq. (16).
    let mut owners: HashMap<i64, BTreeSet<usize>> = HashMap::new();
    for (k, ids) in countable_ids.iter().enumerate() {
        for &id in ids {
            owners.entry(id).or_default().insert(k);
        }
    }
    let population = tf.countable_fish();
    let labelled: Vec<bool> = (0..nfish)
        .map(|k| {
            let ids = &countable_ids[k];
            let first = match ids.first() {
                Some(&id) => id,
                None => return false,
            };
            ids.iter().all(|&id| id == first)
                && owners.get(&first).is_some_and(|o| o.len() == 1)
                && 2 * ids.len() as u64 >= countable_frames[k]
        })
        .collect();
    let correct = population.iter().filter(|&&k| labelled[k]).count() as u64;
    let n = population.len() as u64;
    let success = SuccessScore {
        fish: n,
        correctly_labelled: correct,
        rate: correct as f64 / n as f64,
        labelled,
        countable_frames,
    };

    let tracks_n = match fish_rows {
        Some(f) => f.len() as u64,
        None => tracks.iter().map(|r| r.id).collect::<BTreeSet<_>>().len() as u64,
    };
    let count = CountScore {
        tracks: tracks_n,
        fish: n,
        error: (tracks_n as f64 - n as f64) / n as f64,
    };

    let length = fish_rows.map(|fr| {
        let lengths: HashMap<i64, Option<f64>> =
            fr.iter().map(|r| (r.track_id, r.length_mm)).collect();
        let mut measurable = 0;
        let mut pairs = Vec::new();
        for (k, fish) in tf.truth.fish.iter().enumerate() {
            if !fish.frames.iter().any(|a| a.inside_left && a.inside_right) {
                continue;
            }
            measurable += 1;
            if let Some(id) = majority(&all_ids[k]) {
                if let Some(Some(l)) = lengths.get(&id) {
                    pairs.push((*l, fish.length_mm));
                }
            }
        }
        LengthScore::from_pairs(&pairs, measurable)
    });

    TrackingScore {
        detection: tally.finish(),
        mot: mot_inputs(tf, tracks).summarize(MAX_DISTANCE),
        success,
        success_detected: None,
        count,
        length,
    }
}

/// The id with the most frames (smallest id on ties).
fn majority(counts: &BTreeMap<i64, u64>) -> Option<i64> {
    let mut best: Option<(i64, u64)> = None;
    for (&id, &c) in counts {
        if best.is_none_or(|(_, bc)| c > bc) {
            best = Some((id, c));
        }
    }
    best.map(|b| b.0)
}

/// Segmentation score from `detections.csv` (ids ignored).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SegmentationScore {
    /// Per-frame detection precision/recall of every segmented object.
    pub detection: DetectionScore,
    /// Single-camera length of large targets (truth pixel length in the raw
    /// left image > 100 px at 2048 width, scaled by width/2048; fish wholly
    /// inside the left view): population = such fish-frames, measured = those
    /// a detection matched; estimate = the detection's `length_px` column if
    /// given, else max(w, h) of its box. `None` when the truth carries no
    /// projected head/tail points.
    pub large_target_length: Option<LengthScore>,
    /// Where the detections' pixel length came from.
    pub length_source: &'static str,
}

/// Large-target threshold in raw pixels at 2048 width (paper Section V.A).
pub const LARGE_TARGET_PX_2048: f64 = 100.0;

fn pixel_length(o: &TruthObject<'_>) -> Option<f64> {
    let (h, t) = (o.at.head_px_left?, o.at.tail_px_left?);
    Some(((h[0] - t[0]).powi(2) + (h[1] - t[1]).powi(2)).sqrt())
}

/// Scores `detections.csv`.
pub fn score_detections(tf: &TruthFrames<'_>, dets: &[MotRow]) -> SegmentationScore {
    let rows = by_frame(dets);
    let mut tally = DetectionTally::default();
    let large = LARGE_TARGET_PX_2048 * tf.truth.width as f64 / 2048.0;
    let mut any_px = false;
    let mut measurable = 0;
    let mut pairs = Vec::new();
    for f in frames_of(tf, &rows) {
        let preds = rows.get(&f).map_or(&[][..], |v| v.as_slice());
        let boxes: Vec<[f64; 4]> = preds.iter().map(|r| r.bbox).collect();
        let m = match_frame(tf, f, &boxes);
        tally.add(&m);
        for o in tf.at(f) {
            let Some(len) = pixel_length(o) else { continue };
            any_px = true;
            if !(o.at.inside_left && o.at.left_box.is_some() && len > large) {
                continue;
            }
            measurable += 1;
            let det = m.preds.iter().position(|s| match *s {
                PredState::Hit(k) | PredState::Ignored(k) => k == o.fish,
                PredState::False => false,
            });
            if let Some(p) = det {
                let r = preds[p];
                let est = r.length_px.unwrap_or(r.bbox[2].max(r.bbox[3]));
                pairs.push((est, len));
            }
        }
    }
    let with_px = dets.iter().any(|r| r.length_px.is_some());
    SegmentationScore {
        detection: tally.finish(),
        large_target_length: any_px.then(|| LengthScore::from_pairs(&pairs, measurable)),
        length_source: if with_px {
            "length_px column"
        } else {
            "max(w, h) of the box"
        },
    }
}
