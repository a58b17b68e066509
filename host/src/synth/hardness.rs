//! Is the synthetic motion as hard as the paper's? A nearest-neighbour
//! association run on the truth's own boxes (perfect detection) and scored
//! with the paper's tracking success rate (eq. 16). The paper measures NN
//! at 0.36 on real Cam-trawl clips (Table V); a synthetic haul where NN on
//! perfect detections does better than 0.6 is too easy.
//!
//! Observations: per frame, every truth fish whose visible left area is at
//! least θ_A^L (`Params::for_frame(width).area_min`), at the centre of its
//! left box. NN: each live track predicts `x̂ = x + v`; observation–track
//! pairs within the gate are assigned greedily, nearest first, one-to-one;
//! a matched track takes the observation's position and updates its
//! velocity by eq. (14) (`v ← α (x_obs − x) + (1 − α) v`); an unmatched
//! track coasts on its prediction for up to `max_missed` frames; an
//! unmatched observation starts a new track with zero velocity.
//!
//! Success (eq. 16, as `fishtrack eval` counts it): a fish is correctly
//! labelled when all its matched frames carry one track id that no other
//! fish's frames carry, and it is matched in at least half of its countable
//! frames; rate = correctly labelled / fish with at least one countable frame.

use std::collections::{BTreeMap, BTreeSet};

use fishtrack_core::params::Params;

use crate::truth::Truth;

/// Nearest-neighbour settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NnConfig {
    /// Gate: largest distance from a prediction to an observation, pixels.
    pub gate: f64,
    /// Velocity update rate α of eq. (14).
    pub alpha: f64,
    /// Frames a track may go unmatched before it ends.
    pub max_missed: u32,
}

/// Countable observations: `(frame, fish id) → left box centre`.
pub fn observations(truth: &Truth) -> BTreeMap<(u32, u32), (f64, f64)> {
    let area_min = Params::for_frame(truth.width).area_min as f64;
    let mut out = BTreeMap::new();
    for f in &truth.fish {
        for fr in &f.frames {
            if let (Some(b), true) = (fr.left_box, fr.left_area >= area_min) {
                out.insert((fr.frame, f.id), (b[0] + 0.5 * b[2], b[1] + 0.5 * b[3]));
            }
        }
    }
    out
}

struct Track {
    id: u32,
    x: (f64, f64),
    v: (f64, f64),
    missed: u32,
}

/// Runs NN on the truth; returns the track id of every observation.
pub fn nn_on_truth(truth: &Truth, cfg: &NnConfig) -> BTreeMap<(u32, u32), u32> {
    let obs = observations(truth);
    let mut assigned = BTreeMap::new();
    let mut tracks: Vec<Track> = Vec::new();
    let mut next_id = 1;
    for frame in 1..=truth.frames {
        let here: Vec<(u32, (f64, f64))> = obs
            .range((frame, 0)..=(frame, u32::MAX))
            .map(|(&(_, id), &c)| (id, c))
            .collect();
        let mut pairs = Vec::new();
        for (ti, t) in tracks.iter().enumerate() {
            let p = (t.x.0 + t.v.0, t.x.1 + t.v.1);
            for (oi, (_, c)) in here.iter().enumerate() {
                let d = ((c.0 - p.0).powi(2) + (c.1 - p.1).powi(2)).sqrt();
                if d <= cfg.gate {
                    pairs.push((d, ti, oi));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut t_used = vec![false; tracks.len()];
        let mut o_used = vec![false; here.len()];
        for (_, ti, oi) in pairs {
            if t_used[ti] || o_used[oi] {
                continue;
            }
            t_used[ti] = true;
            o_used[oi] = true;
            let t = &mut tracks[ti];
            let c = here[oi].1;
            let vo = (c.0 - t.x.0, c.1 - t.x.1);
            t.v = (
                cfg.alpha * vo.0 + (1.0 - cfg.alpha) * t.v.0,
                cfg.alpha * vo.1 + (1.0 - cfg.alpha) * t.v.1,
            );
            t.x = c;
            t.missed = 0;
            assigned.insert((frame, here[oi].0), t.id);
        }
        for (ti, t) in tracks.iter_mut().enumerate() {
            if !t_used[ti] {
                t.x = (t.x.0 + t.v.0, t.x.1 + t.v.1);
                t.missed += 1;
            }
        }
        tracks.retain(|t| t.missed <= cfg.max_missed);
        for (oi, (id, c)) in here.iter().enumerate() {
            if !o_used[oi] {
                tracks.push(Track {
                    id: next_id,
                    x: *c,
                    v: (0.0, 0.0),
                    missed: 0,
                });
                assigned.insert((frame, *id), next_id);
                next_id += 1;
            }
        }
    }
    assigned
}

/// The paper's tracking success rate (eq. 16) of an assignment
/// `(frame, fish id) → track id` over the truth's countable frames.
/// Returns `(correctly labelled, fish with a countable frame)`.
pub fn success(truth: &Truth, assigned: &BTreeMap<(u32, u32), u32>) -> (usize, usize) {
    let obs = observations(truth);
    let mut countable: BTreeMap<u32, usize> = BTreeMap::new();
    let mut ids: BTreeMap<u32, BTreeSet<u32>> = BTreeMap::new();
    let mut matched: BTreeMap<u32, usize> = BTreeMap::new();
    let mut owners: BTreeMap<u32, BTreeSet<u32>> = BTreeMap::new();
    for &(frame, fish) in obs.keys() {
        *countable.entry(fish).or_default() += 1;
        if let Some(&t) = assigned.get(&(frame, fish)) {
            ids.entry(fish).or_default().insert(t);
            *matched.entry(fish).or_default() += 1;
            owners.entry(t).or_default().insert(fish);
        }
    }
    let correct = countable
        .iter()
        .filter(|(fish, &n)| {
            let m = matched.get(fish).copied().unwrap_or(0);
            let Some(set) = ids.get(fish) else {
                return false;
            };
            set.len() == 1
                && set
                    .iter()
                    .all(|t| owners.get(t).is_some_and(|o| o.len() == 1))
                && 2 * m >= n
        })
        .count();
    (correct, countable.len())
}

/// NN's success rate on a haul's truth with one setting.
pub fn nn_success_rate(truth: &Truth, cfg: &NnConfig) -> f64 {
    let (c, n) = success(truth, &nn_on_truth(truth, cfg));
    if n == 0 {
        0.0
    } else {
        c as f64 / n as f64
    }
}

/// The hardness figures of one haul.
#[derive(Debug, Clone, PartialEq)]
pub struct Hardness {
    /// Success rate with the paper's α = 0.3, gate 0.2·width, one coasting frame.
    pub default_rate: f64,
    /// Best success rate over gates {0.05, 0.1, 0.2, 0.3, 0.5}·width ×
    /// α {0.3, 1} × coasting {0, 1}: NN at its best setting for this haul.
    pub best_rate: f64,
    /// The setting that gave `best_rate`.
    pub best: NnConfig,
    /// Fish with at least one countable frame.
    pub fish: usize,
    /// Mean countable frames per fish.
    pub mean_life: f64,
    /// Mean countable fish per frame.
    pub mean_per_frame: f64,
}

/// Measures NN hardness on a truth.
pub fn hardness(truth: &Truth) -> Hardness {
    let w = truth.width as f64;
    let default_cfg = NnConfig {
        gate: 0.2 * w,
        alpha: 0.3,
        max_missed: 1,
    };
    let default_rate = nn_success_rate(truth, &default_cfg);
    let mut best = default_cfg;
    let mut best_rate = default_rate;
    for gate in [0.05, 0.1, 0.2, 0.3, 0.5] {
        for alpha in [0.3, 1.0] {
            for max_missed in [0, 1] {
                let cfg = NnConfig {
                    gate: gate * w,
                    alpha,
                    max_missed,
                };
                let r = nn_success_rate(truth, &cfg);
                if r > best_rate {
                    best_rate = r;
                    best = cfg;
                }
            }
        }
    }
    let obs = observations(truth);
    let fish: BTreeSet<u32> = obs.keys().map(|k| k.1).collect();
    Hardness {
        default_rate,
        best_rate,
        best,
        fish: fish.len(),
        mean_life: obs.len() as f64 / fish.len().max(1) as f64,
        mean_per_frame: obs.len() as f64 / truth.frames.max(1) as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::truth::{TruthFish, TruthFrame, TRUTH_VERSION};

    fn frame(frame: u32, x: f64) -> TruthFrame {
        TruthFrame {
            frame,
            left_box: Some([x, 100.0, 100.0, 40.0]),
            right_box: None,
            left_area: 3000.0,
            right_area: 0.0,
            left_visible_fraction: 1.0,
            right_visible_fraction: 0.0,
            inside_left: true,
            inside_right: false,
            head_mm: [0.0; 3],
            tail_mm: [0.0; 3],
            head_px_left: None,
            tail_px_left: None,
        }
    }

    fn truth(fish: Vec<Vec<TruthFrame>>) -> Truth {
        Truth {
            version: TRUTH_VERSION,
            seed: 0,
            width: 2048,
            height: 2048,
            fps: 5.0,
            frames: 10,
            fish: fish
                .into_iter()
                .enumerate()
                .map(|(i, frames)| TruthFish {
                    id: i as u32 + 1,
                    length_mm: 300.0,
                    tail_reflectivity: 0.5,
                    frames,
                })
                .collect(),
        }
    }

    #[test]
    fn slow_separate_fish_are_all_tracked() {
        let t = truth(vec![
            (1..=5)
                .map(|f| frame(f, 1800.0 - 50.0 * f as f64))
                .collect(),
            (3..=8).map(|f| frame(f, 200.0 + 60.0 * f as f64)).collect(),
        ]);
        let cfg = NnConfig {
            gate: 200.0,
            alpha: 0.3,
            max_missed: 1,
        };
        assert_eq!(success(&t, &nn_on_truth(&t, &cfg)), (2, 2));
    }

    #[test]
    fn a_new_fish_at_the_old_position_steals_the_track() {
        // Fish 1 jumps 500 px per frame; fish 2 enters where fish 1 was.
        let t = truth(vec![
            vec![frame(1, 1800.0), frame(2, 1300.0), frame(3, 800.0)],
            vec![frame(2, 1750.0), frame(3, 1250.0)],
        ]);
        let cfg = NnConfig {
            gate: 600.0,
            alpha: 1.0,
            max_missed: 0,
        };
        let a = nn_on_truth(&t, &cfg);
        // Frame 2: the track of fish 1 (predicted at 1800) takes fish 2.
        assert_eq!(a[&(1, 1)], a[&(2, 2)]);
        assert_eq!(success(&t, &a), (0, 2));
    }

    #[test]
    fn success_needs_half_the_countable_frames() {
        let t = truth(vec![(1..=4).map(|f| frame(f, 100.0 * f as f64)).collect()]);
        let mut a = BTreeMap::new();
        a.insert((1, 1), 7);
        assert_eq!(success(&t, &a), (0, 1));
        a.insert((2, 1), 7);
        assert_eq!(success(&t, &a), (1, 1));
        a.insert((3, 1), 8);
        assert_eq!(success(&t, &a), (0, 1));
    }
}
