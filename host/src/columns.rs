//! Column fixed-pattern noise (beyond the paper): per-column offsets of a
//! camera's sensor, estimated from the haul itself and taken out of the raw
//! frames before rectification.
//!
//! A CMOS sensor reads each column through its own amplifier, and what is
//! left of their offsets after the camera's correction is a fixed stripe
//! pattern. Eq. (1)'s local thresholds and the stereo SADs see it as
//! structure: `scripts/perturb_haul.py columns` (offsets of σ 2 grey levels)
//! cost 7.7 points of segmentation recall, 11 of 111 tracked fish and a
//! count error of −13.5 % on seeds 1–4 (README, "Robustness to rendering").
//!
//! Estimate, per camera: [`SAMPLE_FRAMES`] frames spread over the haul;
//! each column's trimmed mean over its rows ([`column_profile`]: the pixels
//! of every [`ROW_STEP`]th row ranked between the 10th and 60th percentiles,
//! the water, below the fish and the mesh), averaged over the frames; the
//! offsets are that profile minus its running median over
//! `2 · HALF_WINDOW + 1` columns (the strobes' glow and the vignetting vary
//! slowly across columns, a column's offset does not). Only when the
//! offsets' RMS reaches [`RMS_MIN`] grey levels are they applied (rounded,
//! clamped to 0–255); the synthetic hauls' cameras, which have no such
//! pattern, measure 0.04–0.10 and stay untouched, byte for byte.

use fishtrack_core::hist::trimmed_mean_256;
use image::GrayImage;

/// Frames (spread evenly over the haul) the estimate reads per camera.
pub const SAMPLE_FRAMES: usize = 6;
/// Rows between the pixels a column profile reads.
pub const ROW_STEP: u32 = 4;
/// The rank range, in tenths, a column profile averages.
pub const TRIM: (u64, u64) = (1, 6);
/// Half the running median's window, columns.
pub const HALF_WINDOW: usize = 16;
/// Offsets' RMS, grey levels, from which they are applied.
pub const RMS_MIN: f64 = 0.5;

/// The column offsets of one camera.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnOffsets {
    /// RMS of the estimated offsets, grey levels.
    pub rms: f64,
    /// The offsets applied (rounded), one per column; `None` below
    /// [`RMS_MIN`].
    pub applied: Option<Vec<i16>>,
}

/// Each column's mean over the pixels of every [`ROW_STEP`]th row ranked
/// between the 10th and 60th percentiles of that column.
pub fn column_profile(img: &GrayImage) -> Vec<f64> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut hist = vec![0u32; w * 256];
    let raw = img.as_raw();
    for y in (0..h).step_by(ROW_STEP as usize) {
        for (x, &p) in raw[y * w..(y + 1) * w].iter().enumerate() {
            hist[x * 256 + p as usize] += 1;
        }
    }
    hist.chunks_exact(256)
        .map(|h| {
            let h: &[u32; 256] = h.try_into().expect("chunks of 256");
            trimmed_mean_256(h, TRIM.0, TRIM.1).map_or(0.0, f64::from)
        })
        .collect()
}

/// `profile` minus its running median over `2 · HALF_WINDOW + 1` columns
/// (the window clipped at the frame's sides).
pub fn detrended(profile: &[f64]) -> Vec<f64> {
    let n = profile.len();
    (0..n)
        .map(|x| {
            let (a, b) = (x.saturating_sub(HALF_WINDOW), (x + HALF_WINDOW + 1).min(n));
            let mut win = profile[a..b].to_vec();
            win.sort_by(f64::total_cmp);
            profile[x] - win[win.len() / 2]
        })
        .collect()
}

impl ColumnOffsets {
    /// The offsets of one camera from its sampled frames (all the same
    /// width; `None` for no frames).
    pub fn estimate(frames: &[GrayImage]) -> Option<ColumnOffsets> {
        let first = frames.first()?;
        let w = first.width() as usize;
        let mut mean = vec![0f64; w];
        for f in frames {
            for (m, v) in mean.iter_mut().zip(column_profile(f)) {
                *m += v / frames.len() as f64;
            }
        }
        let off = detrended(&mean);
        let rms = (off.iter().map(|v| v * v).sum::<f64>() / w.max(1) as f64).sqrt();
        let applied = (rms >= RMS_MIN).then(|| off.iter().map(|v| v.round() as i16).collect());
        Some(ColumnOffsets { rms, applied })
    }

    /// Takes the offsets out of `img` (a frame of the width they were
    /// estimated on; nothing happens below [`RMS_MIN`]).
    pub fn apply(&self, img: &mut GrayImage) {
        let Some(off) = &self.applied else { return };
        let w = img.width() as usize;
        if off.len() != w {
            return;
        }
        for row in img.as_mut().chunks_exact_mut(w) {
            for (p, &o) in row.iter_mut().zip(off) {
                *p = (*p as i16 - o).clamp(0, 255) as u8;
            }
        }
    }
}

/// Indices of `k` frames spread evenly over `n` (all of them when
/// `n ≤ k`).
pub fn spread(n: usize, k: usize) -> Vec<usize> {
    if n <= k {
        return (0..n).collect();
    }
    (0..k)
        .map(|i| (i * (n - 1) + (k - 1) / 2) / (k - 1).max(1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Water at 40 with a glow across the columns, a bright band (mesh),
    /// noise, and column offsets `off`.
    fn frame(w: u32, h: u32, off: &[f64], seed: u64) -> GrayImage {
        let mut s = seed | 1;
        GrayImage::from_fn(w, h, |x, y| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let noise = ((s >> 40) % 7) as f64 - 3.0;
            let glow = 12.0 * (1.0 - ((x as f64 - w as f64 / 2.0) / w as f64).powi(2));
            let band = if y < h / 5 { 90.0 } else { 0.0 };
            image::Luma([(40.0 + glow + band + noise + off[x as usize])
                .round()
                .clamp(0.0, 255.0) as u8])
        })
    }

    #[test]
    fn column_offsets_are_found_and_taken_out() {
        let (w, h) = (256u32, 200u32);
        let mut s = 7u64;
        let off: Vec<f64> = (0..w)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                ((s >> 40) % 9) as f64 - 4.0
            })
            .collect();
        let frames: Vec<GrayImage> = (0..4).map(|i| frame(w, h, &off, 11 + i)).collect();
        let est = ColumnOffsets::estimate(&frames).unwrap();
        assert!(
            est.applied.is_some(),
            "a pattern of RMS {} is applied",
            est.rms
        );
        // corrected, each column sits where the same frame without the
        // pattern has it (up to one constant)
        let clean = frame(w, h, &vec![0.0; w as usize], 11);
        let mut f = frames[0].clone();
        est.apply(&mut f);
        let col_diff = |a: &GrayImage| -> Vec<f64> {
            (0..w)
                .map(|x| {
                    (0..h)
                        .map(|y| a.get_pixel(x, y).0[0] as f64 - clean.get_pixel(x, y).0[0] as f64)
                        .sum::<f64>()
                        / h as f64
                })
                .collect()
        };
        let spread_of = |d: Vec<f64>| -> (f64, f64) {
            let m = d.iter().sum::<f64>() / d.len() as f64;
            let rms = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
            (rms, d.iter().map(|v| (v - m).abs()).fold(0.0, f64::max))
        };
        let (rms_before, _) = spread_of(col_diff(&frames[0]));
        let (rms_after, max_after) = spread_of(col_diff(&f));
        // (what is left is the pattern's own slow part, which the running
        // median cannot tell from the glow: 0.84 of 2.57 here)
        assert!(rms_before > 2.0, "{rms_before}");
        assert!(
            rms_after < 0.4 * rms_before && max_after <= 2.5,
            "after: rms {rms_after} (before {rms_before}), max {max_after}"
        );
        // and the estimate on the corrected frame finds far less
        let again = ColumnOffsets::estimate(&[f]).unwrap().rms;
        assert!(again < 0.3 * est.rms, "{again} vs {}", est.rms);
    }

    #[test]
    fn a_camera_without_a_pattern_is_left_alone() {
        let (w, h) = (256u32, 200u32);
        let frames: Vec<GrayImage> = (0..4)
            .map(|i| frame(w, h, &vec![0.0; w as usize], 3 + i))
            .collect();
        let est = ColumnOffsets::estimate(&frames).unwrap();
        assert!(est.rms < RMS_MIN, "{}", est.rms);
        assert!(est.applied.is_none());
        let mut f = frames[0].clone();
        est.apply(&mut f);
        assert_eq!(f, frames[0]);
        assert!(ColumnOffsets::estimate(&[]).is_none());
    }

    #[test]
    fn frames_are_spread_over_the_haul() {
        assert_eq!(spread(3, 6), vec![0, 1, 2]);
        assert_eq!(spread(30, 6), vec![0, 6, 12, 17, 23, 29]);
        assert_eq!(spread(7, 6).len(), 6);
    }
}
