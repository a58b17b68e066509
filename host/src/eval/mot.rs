//! CLEAR MOT (MOTA, MOTP, ID switches, fragmentations, MT/PT/ML) and the ID
//! measures (IDF1, IDP, IDR), computed exactly as py-motmetrics 1.4 does.
//!
//! [`MotAccumulator::update`] is a port of `motmetrics.MOTAccumulator.update`
//! (Bernardin & Stiefelhagen 2008, CLEAR MOT): per frame, first keep every
//! previous object→hypothesis correspondence that is still allowed (distance
//! finite), then match the rest by a minimum-cost assignment on `1 − IoU`
//! (forbidden above the maximum distance); a match whose object was last
//! matched to another hypothesis is a SWITCH; left-over objects are MISSes
//! and left-over hypotheses FPs. [`MotAccumulator::summary`] ports the
//! metrics of `motmetrics.metrics`, including the ID measures (Ristani et
//! al. 2016): a global min-cost bipartite matching of whole trajectories on
//! the `(objects + hypotheses)²` matrix motmetrics builds, where a
//! trajectory pair's true positives are the frames in which their boxes are
//! within the maximum distance.
//!
//! Frames must be fed in increasing order; ids must be unique within a frame.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use super::lsap;
use super::matching::iou_distances;

/// Accumulates tracking events frame by frame (motmetrics `MOTAccumulator`).
#[derive(Debug, Clone)]
pub struct MotAccumulator {
    max_distance: f64,
    /// Object → hypothesis of its last match (`m`).
    m: HashMap<i64, i64>,
    /// Hypothesis → object of its last match (`res_m`).
    res_m: HashMap<i64, i64>,
    /// Objects that have been matched at least once (`last_match` keys).
    last_match: BTreeSet<i64>,
    /// Hypotheses that have been matched at least once (`hypHistory` keys).
    hyp_history: BTreeSet<i64>,
    /// Per object, in frame order: was it missed?
    obj_events: BTreeMap<i64, Vec<bool>>,
    /// Per hypothesis: frames it appears in.
    hyp_frames: BTreeMap<i64, u64>,
    /// (object, hypothesis) → frames where their distance is finite.
    pair_frames: BTreeMap<(i64, i64), u64>,
    frames: u64,
    matches: u64,
    switches: u64,
    misses: u64,
    false_positives: u64,
    transfers: u64,
    ascends: u64,
    migrates: u64,
    distance_sum: f64,
}

/// The metrics motmetrics reports, same names and definitions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MotSummary {
    /// Frames seen (calls to `update`).
    pub num_frames: u64,
    /// Object (ground-truth) occurrences over all frames.
    pub num_objects: u64,
    /// Hypothesis (prediction) occurrences over all frames.
    pub num_predictions: u64,
    /// MATCH events.
    pub num_matches: u64,
    /// SWITCH events (ID switches).
    pub num_switches: u64,
    /// FP events.
    pub num_false_positives: u64,
    /// MISS events.
    pub num_misses: u64,
    /// Matches + switches.
    pub num_detections: u64,
    /// TRANSFER events.
    pub num_transfer: u64,
    /// ASCEND events.
    pub num_ascend: u64,
    /// MIGRATE events.
    pub num_migrate: u64,
    /// Distinct object ids.
    pub num_unique_objects: u64,
    /// Objects tracked ≥ 80 % of their occurrences.
    pub mostly_tracked: u64,
    /// Objects tracked in [20 %, 80 %).
    pub partially_tracked: u64,
    /// Objects tracked < 20 %.
    pub mostly_lost: u64,
    /// Tracked → missed transitions inside each object's tracked span.
    pub num_fragmentations: u64,
    /// 1 − (misses + switches + FP) / objects.
    pub mota: f64,
    /// Mean matched distance (1 − IoU).
    pub motp: f64,
    /// Detections / (detections + FP).
    pub precision: f64,
    /// Detections / objects.
    pub recall: f64,
    /// ID true positives.
    pub idtp: f64,
    /// ID false positives.
    pub idfp: f64,
    /// ID false negatives.
    pub idfn: f64,
    /// ID precision.
    pub idp: f64,
    /// ID recall.
    pub idr: f64,
    /// ID F1.
    pub idf1: f64,
}

impl MotAccumulator {
    /// A fresh accumulator; pairs farther than `max_distance` (1 − IoU) never match.
    pub fn new(max_distance: f64) -> Self {
        MotAccumulator {
            max_distance,
            m: HashMap::new(),
            res_m: HashMap::new(),
            last_match: BTreeSet::new(),
            hyp_history: BTreeSet::new(),
            obj_events: BTreeMap::new(),
            hyp_frames: BTreeMap::new(),
            pair_frames: BTreeMap::new(),
            frames: 0,
            matches: 0,
            switches: 0,
            misses: 0,
            false_positives: 0,
            transfers: 0,
            ascends: 0,
            migrates: 0,
            distance_sum: 0.0,
        }
    }

    /// One frame: object ids and boxes, hypothesis ids and boxes.
    pub fn update(
        &mut self,
        oids: &[i64],
        obj_boxes: &[[f64; 4]],
        hids: &[i64],
        hyp_boxes: &[[f64; 4]],
    ) {
        debug_assert_eq!(oids.len(), obj_boxes.len());
        debug_assert_eq!(hids.len(), hyp_boxes.len());
        self.frames += 1;
        let (no, nh) = (oids.len(), hids.len());
        let mut dists = if no > 0 && nh > 0 {
            iou_distances(obj_boxes, hyp_boxes, self.max_distance)
        } else {
            Vec::new()
        };

        // RAW events: occurrences and allowed pairs (for the ID measures).
        for &h in hids {
            *self.hyp_frames.entry(h).or_insert(0) += 1;
        }
        for (i, &o) in oids.iter().enumerate() {
            for (j, &h) in hids.iter().enumerate() {
                if dists[i * nh + j].is_finite() {
                    *self.pair_frames.entry((o, h)).or_insert(0) += 1;
                }
            }
        }

        let mut o_done = vec![false; no];
        let mut h_done = vec![false; nh];
        let mut matched = vec![false; no];
        if no > 0 && nh > 0 {
            // 1. Keep previous correspondences that are still allowed.
            for i in 0..no {
                let Some(&hprev) = self.m.get(&oids[i]) else {
                    continue;
                };
                let Some(j) = (0..nh).find(|&j| !h_done[j] && hids[j] == hprev) else {
                    continue;
                };
                let d = dists[i * nh + j];
                if d.is_finite() {
                    o_done[i] = true;
                    h_done[j] = true;
                    matched[i] = true;
                    self.matches += 1;
                    self.distance_sum += d;
                    self.last_match.insert(oids[i]);
                    self.hyp_history.insert(hids[j]);
                }
            }
            // 2. Minimum-cost assignment of the rest.
            for i in 0..no {
                for j in 0..nh {
                    if o_done[i] || h_done[j] {
                        dists[i * nh + j] = f64::NAN;
                    }
                }
            }
            for (i, j) in lsap::assign(&dists, no, nh) {
                let (o, h) = (oids[i], hids[j]);
                let d = dists[i * nh + j];
                let is_switch = self.m.get(&o).is_some_and(|&p| p != h);
                if is_switch {
                    self.switches += 1;
                    if !self.hyp_history.contains(&h) {
                        self.ascends += 1;
                    }
                } else {
                    self.matches += 1;
                }
                if self.res_m.get(&h).is_some_and(|&p| p != o) {
                    if !self.last_match.contains(&o) {
                        self.migrates += 1;
                    }
                    self.transfers += 1;
                }
                self.distance_sum += d;
                self.hyp_history.insert(h);
                self.last_match.insert(o);
                o_done[i] = true;
                h_done[j] = true;
                matched[i] = true;
                self.m.insert(o, h);
                self.res_m.insert(h, o);
            }
        }
        // 3./4. Misses and false positives.
        for (i, &o) in oids.iter().enumerate() {
            self.obj_events.entry(o).or_default().push(!matched[i]);
        }
        self.misses += o_done.iter().filter(|d| !**d).count() as u64;
        self.false_positives += h_done.iter().filter(|d| !**d).count() as u64;
    }

    /// The metrics (motmetrics `compute` with its standard metric set).
    pub fn summary(&self) -> MotSummary {
        let num_objects: u64 = self.obj_events.values().map(|e| e.len() as u64).sum();
        let num_predictions: u64 = self.hyp_frames.values().sum();
        let num_detections = self.matches + self.switches;
        let (mut mt, mut pt, mut ml, mut frag) = (0, 0, 0, 0);
        for ev in self.obj_events.values() {
            let tracked = ev.iter().filter(|m| !**m).count() as f64;
            let ratio = tracked / ev.len() as f64;
            if ratio >= 0.8 {
                mt += 1;
            } else if ratio >= 0.2 {
                pt += 1;
            } else {
                ml += 1;
            }
            if let (Some(first), Some(last)) =
                (ev.iter().position(|m| !*m), ev.iter().rposition(|m| !*m))
            {
                frag += ev[first..=last]
                    .windows(2)
                    .filter(|w| !w[0] && w[1])
                    .count() as u64;
            }
        }
        let (idfp, idfn) = self.id_global_assignment();
        let idtp = num_objects as f64 - idfn;
        let div = |a: f64, b: f64| a / b;
        MotSummary {
            num_frames: self.frames,
            num_objects,
            num_predictions,
            num_matches: self.matches,
            num_switches: self.switches,
            num_false_positives: self.false_positives,
            num_misses: self.misses,
            num_detections,
            num_transfer: self.transfers,
            num_ascend: self.ascends,
            num_migrate: self.migrates,
            num_unique_objects: self.obj_events.len() as u64,
            mostly_tracked: mt,
            partially_tracked: pt,
            mostly_lost: ml,
            num_fragmentations: frag,
            mota: 1.0
                - div(
                    (self.misses + self.switches + self.false_positives) as f64,
                    num_objects as f64,
                ),
            motp: div(self.distance_sum, num_detections as f64),
            precision: div(
                num_detections as f64,
                (self.false_positives + num_detections) as f64,
            ),
            recall: div(num_detections as f64, num_objects as f64),
            idtp,
            idfp,
            idfn,
            idp: div(idtp, idtp + idfp),
            idr: div(idtp, idtp + idfn),
            idf1: div(2.0 * idtp, (num_objects + num_predictions) as f64),
        }
    }

    /// motmetrics `id_global_assignment`: returns (IDFP, IDFN).
    fn id_global_assignment(&self) -> (f64, f64) {
        let oids: Vec<i64> = self.obj_events.keys().copied().collect();
        let hids: Vec<i64> = self.hyp_frames.keys().copied().collect();
        let (no, nh) = (oids.len(), hids.len());
        let n = no + nh;
        if n == 0 {
            return (0.0, 0.0);
        }
        let oidx: HashMap<i64, usize> = oids.iter().enumerate().map(|(i, &o)| (o, i)).collect();
        let hidx: HashMap<i64, usize> = hids.iter().enumerate().map(|(i, &h)| (h, i)).collect();
        let mut fp = vec![0.0f64; n * n];
        let mut fnm = vec![0.0f64; n * n];
        for r in no..n {
            for c in 0..nh {
                fp[r * n + c] = f64::NAN;
            }
        }
        for r in 0..no {
            for c in nh..n {
                fnm[r * n + c] = f64::NAN;
            }
        }
        for (r, o) in oids.iter().enumerate() {
            let oc = self.obj_events[o].len() as f64;
            for c in 0..nh {
                fnm[r * n + c] = oc;
            }
            fnm[r * n + nh + r] = oc;
        }
        for (c, h) in hids.iter().enumerate() {
            let hc = self.hyp_frames[h] as f64;
            for r in 0..no {
                fp[r * n + c] = hc;
            }
            fp[(c + no) * n + c] = hc;
        }
        for (&(o, h), &ex) in &self.pair_frames {
            let (r, c) = (oidx[&o], hidx[&h]);
            fp[r * n + c] -= ex as f64;
            fnm[r * n + c] -= ex as f64;
        }
        let costs: Vec<f64> = fp.iter().zip(&fnm).map(|(a, b)| a + b).collect();
        let pairs = lsap::assign(&costs, n, n);
        let idfp = pairs.iter().map(|&(r, c)| fp[r * n + c]).sum();
        let idfn = pairs.iter().map(|&(r, c)| fnm[r * n + c]).sum();
        (idfp, idfn)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(x: f64) -> [f64; 4] {
        [x, 0.0, 10.0, 10.0]
    }

    #[test]
    fn perfect_tracking_scores_one() {
        let mut acc = MotAccumulator::new(0.6);
        for f in 0..5 {
            let x = f as f64 * 3.0;
            acc.update(&[1, 2], &[b(x), b(x + 50.0)], &[7, 9], &[b(x), b(x + 50.0)]);
        }
        let s = acc.summary();
        assert_eq!((s.mota, s.idf1, s.num_switches), (1.0, 1.0, 0));
        assert_eq!(s.num_objects, 10);
    }

    #[test]
    fn swapped_ids_mid_track_are_two_switches() {
        let mut acc = MotAccumulator::new(0.6);
        for f in 0..6 {
            let (h1, h2) = if f < 3 { (7, 9) } else { (9, 7) };
            acc.update(&[1, 2], &[b(0.0), b(50.0)], &[h1, h2], &[b(0.0), b(50.0)]);
        }
        let s = acc.summary();
        assert_eq!(s.num_switches, 2);
        assert!((s.mota - (1.0 - 2.0 / 12.0)).abs() < 1e-12);
        // Each truth keeps 3 of 6 frames with its best id: IDTP = 6 of 12.
        assert!((s.idf1 - 0.5).abs() < 1e-12);
    }

    #[test]
    fn previous_match_is_kept_over_a_better_new_one() {
        // CLEAR MOT: hypothesis 7 keeps object 1 while still within range,
        // even though hypothesis 8 now overlaps object 1 better.
        let mut acc = MotAccumulator::new(0.6);
        acc.update(&[1], &[b(0.0)], &[7], &[b(0.0)]);
        acc.update(&[1], &[b(0.0)], &[7, 8], &[b(3.0), b(0.0)]);
        let s = acc.summary();
        assert_eq!(
            (s.num_switches, s.num_false_positives, s.num_matches),
            (0, 1, 2)
        );
    }
}
