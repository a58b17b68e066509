//! Perfect-detection tracker observations from a synthetic haul's truth:
//! the harness that measures the association alone (paper Sections
//! IV.B–C, Table V and Fig. 15 analogues), independent of segmentation and
//! stereo errors.
//!
//! Per frame, every fish whose visible left area is ≥ θ_A^L
//! (`Params::for_frame(width).area_min`) becomes one [`Observation`]:
//! left centroid and box = the truth's raw left box (centre; raw ≈ rectified
//! at the tracker's scale), area = `left_area`; right view from `right_box`
//! / `right_area` when the fish is visible there; depth = the mean z of the
//! head and tail points; 16-bin grey histograms from the rendered PNG pixels
//! inside each box — the pixels at or above the box's mean grey (the lit
//! body; the segmentation's mask would be tighter); body axis (for the
//! newborn direction cue, `TrackConfig::axis_direction`) from the truth's
//! head and tail points, elongation π L² / 4 A. `pair` indexes the
//! frame's source list, which maps back to the fish.
//!
//! Thinning (2.5 fps from 5 fps) keeps frames 1, 3, 5, … and renumbers them,
//! in both the observations and the truth that scores them.

use std::path::Path;

use fishtrack_core::image::Roi;
use fishtrack_core::params::Params;
use fishtrack_core::track::{CameraView, Observation, TrackConfig, TrackEvent, Tracker};
use image::GrayImage;

use crate::error::InputError;
use crate::eval::io::MotRow;
use crate::eval::metrics::{score_tracks, TrackingScore};
use crate::eval::TruthFrames;
use crate::haul::Haul;
use crate::truth::Truth;

/// One frame's observations and, per observation, the fish index (into
/// `truth.fish`) and its raw left box.
#[derive(Debug, Clone)]
pub struct ObsFrame {
    /// Frame number (1-based, after thinning).
    pub frame: u32,
    /// The observations; `pair` = index into `source`.
    pub obs: Vec<Observation>,
    /// (fish index, raw left box `[x, y, w, h]`) per observation.
    pub source: Vec<(usize, [f64; 4])>,
}

/// A haul's truth and perfect-detection observations.
#[derive(Debug, Clone)]
pub struct TruthObs {
    /// The (possibly thinned) truth.
    pub truth: Truth,
    /// Per frame, in order.
    pub frames: Vec<ObsFrame>,
}

fn roi(b: &[f64; 4], w: u32, h: u32) -> Roi {
    let x0 = b[0].floor().clamp(0.0, w as f64) as u32;
    let y0 = b[1].floor().clamp(0.0, h as f64) as u32;
    let x1 = (b[0] + b[2]).ceil().clamp(0.0, w as f64) as u32;
    let y1 = (b[1] + b[3]).ceil().clamp(0.0, h as f64) as u32;
    Roi::new(x0, y0, x1.saturating_sub(x0), y1.saturating_sub(y0))
}

/// 16-bin histogram (grey >> 4) of the pixels in `r` at or above the box's
/// mean grey.
pub fn body_hist(img: &GrayImage, r: &Roi) -> [u32; 16] {
    let mut h = [0u32; 16];
    let (mut sum, mut n) = (0u64, 0u64);
    for y in r.y..r.bottom().min(img.height()) {
        for x in r.x..r.right().min(img.width()) {
            sum += img.get_pixel(x, y).0[0] as u64;
            n += 1;
        }
    }
    if n == 0 {
        return h;
    }
    let mean = sum.div_ceil(n) as u8;
    for y in r.y..r.bottom().min(img.height()) {
        for x in r.x..r.right().min(img.width()) {
            let v = img.get_pixel(x, y).0[0];
            if v >= mean {
                h[(v >> 4) as usize] += 1;
            }
        }
    }
    h
}

fn view(b: &[f64; 4], area: f64, img: &GrayImage) -> CameraView {
    let r = roi(b, img.width(), img.height());
    CameraView {
        cx: (b[0] + b[2] / 2.0) as f32,
        cy: (b[1] + b[3] / 2.0) as f32,
        bbox: r,
        area: area.round().max(1.0) as u32,
        hist: body_hist(img, &r),
        ..Default::default()
    }
}

/// Keeps frames 1, 3, 5, … of `truth`, renumbered 1, 2, 3, ….
pub fn thin_truth(truth: &Truth) -> Truth {
    let mut t = truth.clone();
    t.fps /= 2.0;
    t.frames = truth.frames.div_ceil(2);
    for f in t.fish.iter_mut() {
        f.frames.retain(|a| a.frame % 2 == 1);
        for a in f.frames.iter_mut() {
            a.frame = a.frame.div_ceil(2);
        }
    }
    t.fish.retain(|f| !f.frames.is_empty());
    t
}

/// Reads `dir` (a `fishtrack synth` haul) and builds its observations;
/// `thin` keeps every other frame.
pub fn load(dir: &Path, thin: bool) -> Result<TruthObs, InputError> {
    let full = Truth::load(&dir.join("truth.json"))?;
    let haul = Haul::open(dir)?;
    let truth = if thin { thin_truth(&full) } else { full };
    let area_min = Params::for_frame(truth.width).area_min as f64;
    let mut frames = Vec::new();
    for f in 1..=truth.frames {
        let raw = if thin { 2 * f - 1 } else { f };
        let Some(pair) = haul.frames.get(raw as usize - 1) else {
            return Err(InputError::file(dir, format!("frame {raw} missing")));
        };
        let (l, r) = haul.load_pair(pair, None)?;
        let mut of = ObsFrame {
            frame: f,
            obs: Vec::new(),
            source: Vec::new(),
        };
        for (k, fish) in truth.fish.iter().enumerate() {
            let Some(at) = fish.frames.iter().find(|a| a.frame == f) else {
                continue;
            };
            let Some(lb) = at.left_box else { continue };
            if at.left_area < area_min {
                continue;
            }
            // the body axis from the truth's head and tail (both views:
            // the rectified rows are shared), elongation of the ellipse of
            // that length and the left area: π L² / 4 A
            let axis = |mut v: CameraView| {
                if let (Some(hd), Some(tl)) = (at.head_px_left, at.tail_px_left) {
                    let (dx, dy) = (tl[0] - hd[0], tl[1] - hd[1]);
                    v.angle = dy.atan2(dx) as f32;
                    v.elongation = (std::f64::consts::FRAC_PI_4 * (dx * dx + dy * dy)
                        / at.left_area.max(1.0)) as f32;
                }
                v
            };
            let right = at
                .right_box
                .filter(|_| at.right_area >= 1.0)
                .map(|rb| axis(view(&rb, at.right_area, &r)));
            let z = 0.5 * (at.head_mm[2] + at.tail_mm[2]);
            of.obs.push(Observation {
                left: axis(view(&lb, at.left_area, &l)),
                right,
                depth_mm: (z > 0.0).then_some(z as f32),
                pair: of.source.len() as u16,
            });
            of.source.push((k, lb));
        }
        frames.push(of);
    }
    Ok(TruthObs { truth, frames })
}

/// Runs the core tracker over `to` and returns tracks.csv rows (observed
/// frames only; the box is the observation's truth box).
pub fn run_tracker(to: &TruthObs, params: &Params, cfg: TrackConfig) -> Vec<MotRow> {
    let mut rows = Vec::new();
    let Ok(mut tr) = fishtrack_core::track::DefaultTracker::new(cfg) else {
        return rows;
    };
    run_with(&mut tr, to, params, &mut rows);
    rows
}

fn run_with<const T: usize, const D: usize, const K: usize, const H: usize, const N: usize>(
    tr: &mut Tracker<T, D, K, H, N>,
    to: &TruthObs,
    params: &Params,
    rows: &mut Vec<MotRow>,
) {
    // one sink for the steps and the final flush: each committed track
    // step with an observation becomes a row with that observation's box
    let mut sink = |e: &TrackEvent<'_>| {
        if let TrackEvent::Frame { track, step } = e {
            if let Some(o) = step.obs {
                let src = to
                    .frames
                    .iter()
                    .find(|x| x.frame == step.frame)
                    .and_then(|x| x.source.get(o as usize));
                if let Some(&(_, b)) = src {
                    rows.push(MotRow {
                        frame: step.frame,
                        id: *track as i64,
                        bbox: b,
                        length_px: None,
                        line: 0,
                    });
                }
            }
        }
    };
    for of in &to.frames {
        if tr.step(of.frame, &of.obs, params, &mut sink).is_err() {
            return;
        }
    }
    tr.finish(&mut sink);
}

/// Scores tracks.csv rows against the truth with `eval` (eq. 16 etc.).
pub fn score(to: &TruthObs, rows: &[MotRow]) -> Result<TrackingScore, InputError> {
    let tf = TruthFrames::new(&to.truth)?;
    Ok(score_tracks(&tf, rows, None))
}
