//! Float reference of the photometric match of the right view to the left
//! (`fishtrack_core::photometric`, beyond the paper): per stereo pair, the
//! ratio of the fish's contrasts in the two views over the left mask and
//! the same pixels shifted by the pair's disparity, each against the
//! median of a ring around the box; the map `l = g·r + o` is the medians
//! over the last `POOL` samples; the right frame is mapped through
//! `round(g·r + o)` when the map is not within the tolerances of the
//! identity. A flash's factor `q` (the two views' water levels' ratio
//! over its median of the last `POOL` frames, each level the mean of the
//! sampled pixels ranked between the 10th and 60th percentiles) is taken
//! out of the samples and put into the frame's map, `l = g·q·r + o`.
//! Written independently in `f64` with a `VecDeque` pool; the
//! ring is the reference's own (`stereo::background`, the one its length
//! stage uses).

use std::collections::VecDeque;

use fishtrack_core::photometric::{
    FLASH_TOLERANCE, GAIN_RANGE, GAIN_TOLERANCE, LEVEL_STEP, LEVEL_TRIM, MIN_CONTRAST, MIN_SAMPLES,
    OFFSET_TOLERANCE, POOL,
};

use super::stereo::{background, Gray, RefObject, RefPair};
use crate::stats::median;

/// The recent pairs' `(gain, ring_L, ring_R)` samples.
#[derive(Debug, Default, Clone)]
pub struct Pool {
    samples: VecDeque<(f64, f64, f64)>,
    ratios: VecDeque<f64>,
}

/// The water's level of a view: the sampled pixels sorted, the mean of
/// those ranked between the `LEVEL_TRIM` tenths (core: `frame_level`).
pub fn frame_level(g: &Gray) -> Option<f64> {
    let mut v: Vec<u8> = (0..g.h)
        .step_by(LEVEL_STEP.0)
        .flat_map(|y| {
            g.data[y * g.w..(y + 1) * g.w]
                .iter()
                .step_by(LEVEL_STEP.1)
                .copied()
        })
        .collect();
    v.sort_unstable();
    let n = v.len() as u64;
    let (lo, hi) = (n * LEVEL_TRIM.0 / 10, n * LEVEL_TRIM.1 / 10);
    let part = &v[lo as usize..hi as usize];
    let sum: f64 = part.iter().map(|&p| p as f64).sum();
    (!part.is_empty() && sum > 0.0).then(|| sum / part.len() as f64)
}

/// One pair's `(gain, ring_L, ring_R)`, or `None` when the fish is not
/// measurably brighter than its ring in both views.
fn sample(l: &Gray, r: &Gray, lo: &RefObject, p: &RefPair) -> Option<(f64, f64, f64)> {
    if !p.d_o.is_finite() || p.d_o.abs() > r.w as f64 {
        return None;
    }
    let d = p.d_o.round() as i64;
    let (mut sl, mut sr, mut n) = (0.0, 0.0, 0usize);
    for &(x, y) in &lo.pixels {
        let xr = x - d;
        if xr < 0 || xr >= r.w as i64 || y < 0 || y as usize >= r.h.min(l.h) {
            continue;
        }
        sl += l.data[y as usize * l.w + x as usize] as f64;
        sr += r.data[y as usize * r.w + xr as usize] as f64;
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let (ml, mr) = (sl / n as f64, sr / n as f64);
    let b = lo.bbox;
    if b.0 - d < 0 || b.0 - d + b.2 > r.w as i64 {
        return None;
    }
    let margin = (b.3 / 4).max(4);
    let (bl, sgl) = background(l, b, margin);
    let (br, sgr) = background(r, (b.0 - d, b.1, b.2, b.3), margin);
    let (cl, cr) = (ml - bl, mr - br);
    let enough = |c: f64, s: f64| c >= MIN_CONTRAST as f64 && c >= 3.0 * s;
    (enough(cl, sgl) && enough(cr, sgr)).then(|| (cl / cr, bl, br))
}

impl Pool {
    /// The frame's flash factor: its level ratio over the median of the
    /// last `POOL` ratios (core: `Estimator::add_levels`).
    pub fn add_levels(&mut self, l: &Gray, r: &Gray) -> f64 {
        let (Some(a), Some(b)) = (frame_level(l), frame_level(r)) else {
            return 1.0;
        };
        let ratio = a / b;
        if self.ratios.len() == POOL {
            self.ratios.pop_front();
        }
        self.ratios.push_back(ratio);
        let q = ratio / median(&mut self.ratios.iter().copied().collect::<Vec<_>>());
        if q.is_finite()
            && (GAIN_RANGE.0 as f64..=GAIN_RANGE.1 as f64).contains(&q)
            && (q - 1.0).abs() > FLASH_TOLERANCE as f64
        {
            q
        } else {
            1.0
        }
    }

    /// Adds the samples of one frame's pairs (`left` the frame's left
    /// objects), its flash factor `q` taken out; returns how many.
    pub fn add_frame(
        &mut self,
        l: &Gray,
        r: &Gray,
        left: &[RefObject],
        pairs: &[RefPair],
        q: f64,
    ) -> usize {
        let mut n = 0;
        for p in pairs {
            if let Some((g, bl, br)) = left.get(p.left).and_then(|lo| sample(l, r, lo, p)) {
                if self.samples.len() == POOL {
                    self.samples.pop_front();
                }
                self.samples.push_back((g / q, bl, br * q));
                n += 1;
            }
        }
        n
    }

    /// `(gain, offset)` of the pool, `None` with too few samples or a gain
    /// outside the range.
    pub fn map(&self) -> Option<(f64, f64)> {
        if self.samples.len() < MIN_SAMPLES {
            return None;
        }
        let g = median(&mut self.samples.iter().map(|s| s.0).collect::<Vec<_>>());
        if g < GAIN_RANGE.0 as f64 || g > GAIN_RANGE.1 as f64 {
            return None;
        }
        let o = median(
            &mut self
                .samples
                .iter()
                .map(|s| s.1 - g * s.2)
                .collect::<Vec<_>>(),
        );
        Some((g, o))
    }
}

/// Whether `(gain, offset)` counts as matched views.
pub fn is_identity((g, o): (f64, f64)) -> bool {
    (g - 1.0).abs() <= GAIN_TOLERANCE as f64
        && (o + (g - 1.0) * 128.0).abs() <= OFFSET_TOLERANCE as f64
}

/// The right frame mapped through `round(g·r + o)`, clamped to 0–255.
pub fn apply(r: &Gray, (g, o): (f64, f64)) -> Vec<u8> {
    r.data
        .iter()
        .map(|&p| (g * p as f64 + o).round().clamp(0.0, 255.0) as u8)
        .collect()
}
