//! Photometric match of the right view to the left (beyond the paper;
//! used by [`crate::pipeline`] between the stereo pairing of Section IV.A
//! and the length of Section IV.D).
//!
//! Every stereo comparison of the paper is a sum of absolute differences of
//! grey levels between the views: the object-height blocks (Section IV.A),
//! the end regions of eq. (15) and the 8 × 8 refinement blocks. They assume
//! the two cameras record the same fish at the same grey levels. A real rig
//! does not quite: the two cameras' gains, apertures and exposure differ,
//! and each may have its own strobe. With the right view at 0.75 of the left
//! (`scripts/perturb_haul.py gainlr`) the SAD of the true match grows by a
//! quarter of the fish's contrast, eq. (15) flags sound ends, the
//! refinement's minima blur, and the per-frame 3-D length error on seeds 1–4
//! went 3.4 → 5.3 % with a third fewer frames measured.
//!
//! The model: `l = g · r + o` between a fish's grey levels in the right view
//! and in the left. Each pair of the first pairing pass gives one sample of
//! the gain — the ratio of the fish's contrasts in the two views,
//! `(mean_L − bg_L) / (mean_R − bg_R)`, over the left object's mask pixels
//! and the same pixels shifted by the pair's disparity in the right view
//! (the same points of the fish), `bg` the median of the ring around the
//! left box and around the same box shifted
//! ([`crate::snake::background_level`]) — and of the offset, `bg_L −
//! g · bg_R`. A camera pair's mismatch belongs to the rig, and one pair's
//! ratio scatters by several per cent (glow, texture, a neighbour in the
//! ring), so the map `(g, o)` is the medians over the last [`POOL`]
//! samples of the recent frames ([`Estimator`]), pairs with a measurable
//! contrast in both views only ([`MIN_CONTRAST`], three ring σ). When the
//! map departs from the identity by more than
//! [`GAIN_TOLERANCE`] or [`OFFSET_TOLERANCE`], the pipeline maps the right
//! frame through the look-up table `clamp(round(g · r + o))` and pairs and
//! measures again on it; otherwise nothing changes (a matched rig's
//! outputs are those of the paper's pipeline).
//!
//! **Flash to flash** (session 10). A mismatch can also change with every
//! flash: each camera's exposure catches a different part of the strobe's
//! pulse, or each has its own strobe (`scripts/perturb_haul.py flicker`:
//! each view × 0.65–1.35 per frame lost 41 of the 117 fish-frames measured
//! in 3-D and 8 of the 67 tracked fish on seeds 1–4). The pool of fish samples follows
//! the rig, not one flash, and one frame seldom has the five pairs a map
//! needs. The water does: [`frame_level`] is a trimmed mean of the water's
//! grey level in each view (sampled pixels between their 10th and 60th
//! percentiles: below the fish, the mesh and the glow), and the ratio of
//! the two views' levels against its median over the last [`POOL`] frames
//! is this flash's factor `q` ([`Estimator::add_levels`]; the views' water
//! differs by a constant factor through backscatter, which the median
//! removes). The fish samples are pooled as if the right view were
//! `q · r`, and the frame's map is `l = g · q · r + o`. A steady rig gives
//! `q` within a few per cent of 1; within [`FLASH_TOLERANCE`] it counts as
//! 1, so such a rig's outputs are those of the pool alone.
//!
//! Integer work per pixel (one table look-up); no allocation; never panics.

use crate::error::ImageError;
use crate::image::{ImageView, Roi};
use crate::length::median_in_place;
use crate::object::Objects;
use crate::snake::background_level;
use crate::stereo::StereoPair;

/// Smallest contrast, grey levels, of an object in either view for its
/// pair to estimate the gain (a ratio of two small contrasts is noise).
pub const MIN_CONTRAST: f32 = 4.0;
/// Samples (one per usable pair) the estimate pools, over the recent
/// frames: a camera pair's mismatch is a property of the rig, and one
/// pair's contrast ratio scatters by several per cent (masks, glow).
pub const POOL: usize = 32;
/// Fewest samples in the pool for a map.
pub const MIN_SAMPLES: usize = 5;
/// `|g − 1|` up to which the views count as matched. On the synthetic
/// hauls, whose cameras are identical, the pooled gain stays within
/// 0.94–1.02 (the views see the fish and the glow from different angles);
/// mapping those frames measured 13 more fish-frames on seeds 1–8, at
/// 7.4 % error, and moved the common frames' error by ±0.1 points.
pub const GAIN_TOLERANCE: f32 = 0.08;
/// `|o + (g − 1) · 128|` (the map's shift at mid-grey), grey levels, up to
/// which the views count as matched: a black-level difference between the
/// cameras beyond it is mapped too. The synthetic views' water differs by
/// up to 4.6 grey levels (backscatter seen from two places).
pub const OFFSET_TOLERANCE: f32 = 6.0;
/// The gains a map may have: a wider mismatch is not a camera pair.
pub const GAIN_RANGE: (f32, f32) = (0.25, 4.0);
/// `|q − 1|` up to which a frame's flash factor counts as no flash (`q`
/// is then 1): on the synthetic hauls, whose rig is steady, and their
/// re-renderings other than `flicker` it stays within 0.047 (mostly
/// 0.02); under `flicker` 77–83 % of the frames exceed 0.05.
pub const FLASH_TOLERANCE: f32 = 0.05;
/// Rows and columns between the pixels [`frame_level`] samples.
pub const LEVEL_STEP: (usize, usize) = (16, 8);
/// The sampled pixels' rank range, in tenths, that [`frame_level`]
/// averages: the water below the fish, mesh and glow, above the darkest
/// corners.
pub const LEVEL_TRIM: (u64, u64) = (1, 6);

/// The water's grey level of a view: the mean of the pixels sampled every
/// [`LEVEL_STEP`] rows and columns whose ranks lie between the
/// [`LEVEL_TRIM`] tenths (bins counted in part at the two ends, so the
/// mean moves smoothly with the frame). `None` for an empty view or black
/// water.
pub fn frame_level(img: &ImageView<'_>) -> Option<f32> {
    let mut hist = [0u32; 256];
    for y in (0..img.height()).step_by(LEVEL_STEP.0) {
        for &p in img.row(y).iter().step_by(LEVEL_STEP.1) {
            if let Some(c) = hist.get_mut(p as usize) {
                *c = c.saturating_add(1);
            }
        }
    }
    crate::hist::trimmed_mean_256(&hist, LEVEL_TRIM.0, LEVEL_TRIM.1)
}

/// The grey-level map `l = gain · r + offset` from the right view to the
/// left.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Photometric {
    /// `g`.
    pub gain: f32,
    /// `o`, grey levels.
    pub offset: f32,
}

impl Default for Photometric {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Photometric {
    /// `l = r`.
    pub const IDENTITY: Photometric = Photometric {
        gain: 1.0,
        offset: 0.0,
    };

    /// Whether the map is within [`GAIN_TOLERANCE`] and
    /// [`OFFSET_TOLERANCE`] of the identity.
    pub fn is_identity(&self) -> bool {
        (self.gain - 1.0).abs() <= GAIN_TOLERANCE
            && (self.offset + (self.gain - 1.0) * 128.0).abs() <= OFFSET_TOLERANCE
    }

    /// The look-up table `clamp(round(g · r + o), 0, 255)`.
    pub fn lut(&self) -> [u8; 256] {
        let mut t = [0u8; 256];
        for (r, v) in t.iter_mut().enumerate() {
            let x = self.gain * r as f32 + self.offset;
            // (NaN casts to 0; the estimate never yields one)
            *v = micromath::F32(x).round().0.clamp(0.0, 255.0) as u8;
        }
        t
    }

    /// This map applied after a flash factor `q`: `l = g · q · r + o`.
    pub fn after_flash(&self, q: f32) -> Photometric {
        Photometric {
            gain: self.gain * q,
            offset: self.offset,
        }
    }

    /// Writes `src` mapped through [`Photometric::lut`] into `dst` (packed,
    /// `src`'s size) and returns the view of it.
    pub fn apply<'a>(
        &self,
        src: &ImageView<'_>,
        dst: &'a mut [u8],
    ) -> Result<ImageView<'a>, ImageError> {
        let (w, h) = (src.width(), src.height());
        let got = dst.len();
        let dst = dst
            .get_mut(..w * h)
            .ok_or(ImageError::BufferTooSmall { needed: w * h, got })?;
        let lut = self.lut();
        match affine_fixed(&lut, self.gain, self.offset) {
            // the map as fixed-point arithmetic, which vectorises (16 pixels
            // per few instructions; a table lookup is one load per pixel)
            Some((g, o)) => {
                for (y, d) in dst.chunks_exact_mut(w.max(1)).take(h).enumerate() {
                    for (v, &p) in d.iter_mut().zip(src.row(y)) {
                        *v = ((g * p as i32 + o) >> 16).clamp(0, 255) as u8;
                    }
                }
            }
            None => {
                for (y, d) in dst.chunks_exact_mut(w.max(1)).take(h).enumerate() {
                    for (v, &p) in d.iter_mut().zip(src.row(y)) {
                        *v = lut[p as usize];
                    }
                }
            }
        }
        ImageView::packed(dst, w, h)
    }
}

/// The fixed-point form of a gain/offset map, `(g, o)` with
/// `clamp((g · r + o) >> 16, 0, 255) = lut[r]` for every level `r` — checked
/// on all 256 levels, so it is used only where it equals the table exactly
/// (`None` otherwise, or for a gain or offset so large that `g · 255 + o`
/// could leave `i32`). `g = round(gain · 2¹⁶)`, `o = round((offset + ½) ·
/// 2¹⁶)`: the table rounds `gain · r + offset` half up, and the shift
/// floors.
pub fn affine_fixed(lut: &[u8; 256], gain: f32, offset: f32) -> Option<(i32, i32)> {
    if !(gain.is_finite() && offset.is_finite() && gain.abs() <= 64.0 && offset.abs() <= 1024.0) {
        return None;
    }
    let g = micromath::F32(gain * 65536.0).round().0 as i32;
    let o = micromath::F32((offset + 0.5) * 65536.0).round().0 as i32;
    let exact = |g: i32, o: i32| {
        lut.iter()
            .enumerate()
            .all(|(r, &v)| ((g * r as i32 + o) >> 16).clamp(0, 255) == v as i32)
    };
    // the table's own f32 rounding can put a level a hair across a half:
    // nearby offsets (a few 2⁻¹⁶) are tried too, each checked the same way
    (0..=32)
        .map(|k: i32| o + if k % 2 == 0 { k / 2 } else { -(k + 1) / 2 })
        .find(|&o| exact(g, o))
        .map(|o| (g, o))
}

/// Means of the left object's mask pixels in the left view and of the same
/// pixels shifted by the pair's disparity `d` in the right view (columns
/// whose counterpart is outside the right view skipped): the same points
/// of the fish in both views. `None` without such pixels.
fn mask_means<const N: usize, const R: usize>(
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: &Objects<N, R>,
    k: usize,
    d: i32,
) -> Option<(f32, f32)> {
    let o = left.items.get(k)?;
    let (mut sl, mut sr, mut n) = (0u64, 0u64, 0u64);
    let w = right_img.width() as i64;
    for r in left.runs_of(o) {
        let y = r.y as usize;
        if y >= left_img.height() || y >= right_img.height() {
            continue;
        }
        // left columns x with 0 ≤ x − d < w
        let x0 = (r.x0 as i64).max(d as i64);
        let x1 = (r.x1 as i64).min(w + d as i64);
        if x1 <= x0 {
            continue;
        }
        let (a, b) = (
            left_img.row(y).get(x0 as usize..x1 as usize),
            right_img
                .row(y)
                .get((x0 - d as i64) as usize..(x1 - d as i64) as usize),
        );
        if let (Some(a), Some(b)) = (a, b) {
            sl += a.iter().map(|&v| v as u64).sum::<u64>();
            sr += b.iter().map(|&v| v as u64).sum::<u64>();
            n += a.len().min(b.len()) as u64;
        }
    }
    (n > 0).then(|| (sl as f32 / n as f32, sr as f32 / n as f32))
}

/// One pair's `(gain, bg_L, bg_R)`, when the fish stands [`MIN_CONTRAST`]
/// and three ring σ above its ring in both views. The ring is the border
/// of the left box grown by a quarter of its height, in the left view and
/// shifted by the disparity in the right.
fn pair_sample<const N: usize, const R: usize>(
    left_img: &ImageView<'_>,
    right_img: &ImageView<'_>,
    left: &Objects<N, R>,
    p: &StereoPair,
) -> Option<(f32, f32, f32)> {
    let l = p.left as usize;
    let lo = left.items.get(l)?;
    if !p.d_o.is_finite() || p.d_o.abs() > right_img.width() as f32 {
        return None;
    }
    let d = micromath::F32(p.d_o).round().0 as i32;
    let (ml, mr) = mask_means(left_img, right_img, left, l, d)?;
    let b = lo.bbox;
    let rx = b.x as i64 - d as i64;
    if rx < 0 || rx + b.w as i64 > right_img.width() as i64 {
        return None; // the ring's right counterpart is cut by the frame
    }
    let rb = Roi::new(rx as u32, b.y, b.w, b.h);
    let margin = (b.h / 4).max(4);
    let (bl, sl) = background_level(left_img, b, margin);
    let (br, sr) = background_level(right_img, rb, margin);
    let (cl, cr) = (ml - bl, mr - br);
    let enough = |c: f32, s: f32| c >= MIN_CONTRAST && c >= 3.0 * s;
    (enough(cl, sl) && enough(cr, sr)).then(|| (cl / cr, bl, br))
}

/// The map from the stereo pairs of the recent frames (see the module
/// documentation): each frame adds its pairs' samples to a pool of the last
/// [`POOL`], and the map is the pool's medians.
#[derive(Debug, Clone, Copy)]
pub struct Estimator {
    /// `(gain, bg_L, bg_R)` samples, a ring, as if the right view were
    /// `q · r` (the frame's flash factor).
    samples: [(f32, f32, f32); POOL],
    len: usize,
    next: usize,
    /// The recent frames' water level ratios `level_L / level_R`, a ring.
    ratios: [f32; POOL],
    ratios_len: usize,
    ratios_next: usize,
}

impl Default for Estimator {
    fn default() -> Self {
        Estimator {
            samples: [(0.0, 0.0, 0.0); POOL],
            len: 0,
            next: 0,
            ratios: [0.0; POOL],
            ratios_len: 0,
            ratios_next: 0,
        }
    }
}

impl Estimator {
    /// Adds one frame's water level ratio and returns its flash factor
    /// `q`: the ratio over the median ratio of the last [`POOL`] frames
    /// (this one included). 1 when a view has no level, when `q` is
    /// within [`FLASH_TOLERANCE`] of 1 (a steady rig is left as it was) or
    /// when it leaves [`GAIN_RANGE`] (not a flash).
    pub fn add_levels(&mut self, left_img: &ImageView<'_>, right_img: &ImageView<'_>) -> f32 {
        let (Some(l), Some(r)) = (frame_level(left_img), frame_level(right_img)) else {
            return 1.0;
        };
        let ratio = l / r;
        if let Some(slot) = self.ratios.get_mut(self.ratios_next) {
            *slot = ratio;
        }
        self.ratios_next = (self.ratios_next + 1) % POOL;
        self.ratios_len = (self.ratios_len + 1).min(POOL);
        let mut v = self.ratios;
        let reference = v
            .get_mut(..self.ratios_len)
            .and_then(median_in_place)
            .unwrap_or(ratio);
        let q = ratio / reference;
        if q.is_finite()
            && (GAIN_RANGE.0..=GAIN_RANGE.1).contains(&q)
            && (q - 1.0).abs() > FLASH_TOLERANCE
        {
            q
        } else {
            1.0
        }
    }

    /// Adds the samples of one frame's pairs, the frame's flash factor `q`
    /// ([`Estimator::add_levels`]) taken out; returns how many it added.
    pub fn add_frame<const N: usize, const R: usize>(
        &mut self,
        left_img: &ImageView<'_>,
        right_img: &ImageView<'_>,
        left: &Objects<N, R>,
        pairs: &[StereoPair],
        q: f32,
    ) -> usize {
        let mut added = 0;
        for p in pairs.iter() {
            if let Some((g, bl, br)) = pair_sample(left_img, right_img, left, p) {
                if let Some(slot) = self.samples.get_mut(self.next) {
                    *slot = (g / q, bl, br * q);
                }
                self.next = (self.next + 1) % POOL;
                self.len = (self.len + 1).min(POOL);
                added += 1;
            }
        }
        added
    }

    /// Samples in the pool.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the pool is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The pool's map of `q · r` to the left view: `None` with fewer than
    /// [`MIN_SAMPLES`] samples or a median gain outside [`GAIN_RANGE`].
    pub fn map(&self) -> Option<Photometric> {
        let n = self.len;
        if n < MIN_SAMPLES {
            return None;
        }
        let mut v = [0f32; POOL];
        for (d, s) in v.iter_mut().zip(self.samples.iter()).take(n) {
            *d = s.0;
        }
        let gain = median_in_place(v.get_mut(..n)?)?;
        if !(GAIN_RANGE.0..=GAIN_RANGE.1).contains(&gain) {
            return None;
        }
        for (d, s) in v.iter_mut().zip(self.samples.iter()).take(n) {
            *d = s.1 - gain * s.2;
        }
        let offset = median_in_place(v.get_mut(..n)?)?;
        Some(Photometric { gain, offset })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::{Object, Run, RunSpan};

    proptest::proptest! {
        /// `apply` maps every level as the table does, whichever path it
        /// takes (the fixed-point path is taken for about 97 % of maps).
        #[test]
        fn apply_equals_the_table(gain in 0.2f32..4.0, offset in -80.0f32..80.0) {
            let m = Photometric { gain, offset };
            let src: std::vec::Vec<u8> = (0..=255u8).chain((0..=255u8).rev()).collect();
            let v = ImageView::packed(&src, 32, 16).unwrap();
            let mut dst = std::vec![0u8; 512];
            let out = m.apply(&v, &mut dst).unwrap();
            let lut = m.lut();
            for y in 0..16 {
                for (o, &p) in out.row(y).iter().zip(v.row(y)) {
                    proptest::prop_assert_eq!(*o, lut[p as usize]);
                }
            }
        }
    }

    #[test]
    fn the_fixed_point_path_is_the_common_one() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut some = 0;
        for _ in 0..1000 {
            let m = Photometric {
                gain: 0.5 + 1.5 * next(),
                offset: -40.0 + 80.0 * next(),
            };
            some += affine_fixed(&m.lut(), m.gain, m.offset).is_some() as u32;
        }
        assert!(some >= 950, "fixed-point path for {some} of 1000 maps");
    }

    /// Objects of filled boxes (one run per row).
    fn objects(boxes: &[Roi]) -> Objects<8, 4096> {
        let mut o = Objects::<8, 4096>::new();
        for b in boxes {
            let start = o.runs.len() as u32;
            for y in b.y..b.bottom() {
                o.runs
                    .push(Run {
                        y: y as u16,
                        x0: b.x as u16,
                        x1: b.right() as u16,
                    })
                    .unwrap();
            }
            o.items
                .push(Object {
                    bbox: *b,
                    area: b.w * b.h,
                    runs: RunSpan { start, len: b.h },
                    ..Object::default()
                })
                .unwrap();
        }
        o
    }

    /// A `w × h` frame of water `bg` with boxes of grey `fish`, plus a
    /// ±2 checkerboard texture.
    fn frame(w: usize, h: usize, bg: f32, boxes: &[(Roi, f32)], gain: f32, off: f32) -> Vec<u8> {
        let mut f = vec![0u8; w * h];
        for (i, p) in f.iter_mut().enumerate() {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            let mut v = bg;
            for (b, g) in boxes {
                if x >= b.x && x < b.right() && y >= b.y && y < b.bottom() {
                    v = *g;
                }
            }
            let t = if (x + y) % 2 == 0 { 2.0 } else { -2.0 };
            *p = (gain * (v + t) + off).round().clamp(0.0, 255.0) as u8;
        }
        f
    }

    fn pairs(n: usize) -> heapless::Vec<StereoPair, 8> {
        (0..n)
            .map(|k| StereoPair {
                left: k as u16,
                right: k as u16,
                d_o: 0.0,
                mu_sad: 0.0,
                block_disparity: [0.0; 4],
                occluded: false,
                searched: false,
            })
            .collect()
    }

    #[test]
    fn a_gain_and_offset_between_the_views_are_recovered() {
        let (w, h) = (200, 120);
        let boxes = [
            Roi::new(20, 20, 60, 20),
            Roi::new(110, 30, 70, 24),
            Roi::new(40, 80, 80, 20),
        ];
        let greys = [60.0, 90.0, 45.0];
        let scene: heapless::Vec<(Roi, f32), 3> =
            boxes.iter().copied().zip(greys.iter().copied()).collect();
        let l = frame(w, h, 20.0, &scene, 1.0, 0.0);
        // right = (left − 3) / 1.3, i.e. l = 1.3 r + 3
        let r = frame(w, h, 20.0, &scene, 1.0 / 1.3, -3.0 / 1.3);
        let (lv, rv) = (
            ImageView::packed(&l, w, h).unwrap(),
            ImageView::packed(&r, w, h).unwrap(),
        );
        let objs = objects(&boxes);
        let mut e = Estimator::default();
        // three samples: not yet a map; two frames: six
        assert_eq!(e.add_frame(&lv, &rv, &objs, &pairs(3), 1.0), 3);
        assert!(e.map().is_none());
        e.add_frame(&lv, &rv, &objs, &pairs(3), 1.0);
        let m = e.map().unwrap();
        assert!((m.gain - 1.3).abs() < 0.03, "{m:?}");
        assert!((m.offset - 3.0).abs() < 1.5, "{m:?}");
        assert!(!m.is_identity());
        // the mapped right frame is the left one within rounding
        let mut buf = vec![0u8; w * h];
        let mapped = m.apply(&rv, &mut buf).unwrap();
        let worst = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| mapped.get(x, y).unwrap().abs_diff(lv.get(x, y).unwrap()))
            .max()
            .unwrap();
        assert!(worst <= 2, "largest difference {worst}");
    }

    #[test]
    fn matched_views_give_the_identity() {
        let (w, h) = (200, 120);
        let boxes = [Roi::new(20, 20, 60, 20), Roi::new(110, 30, 70, 24)];
        let scene = [(boxes[0], 60.0), (boxes[1], 50.0)];
        let l = frame(w, h, 20.0, &scene, 1.0, 0.0);
        let lv = ImageView::packed(&l, w, h).unwrap();
        let objs = objects(&boxes);
        let mut e = Estimator::default();
        for _ in 0..3 {
            e.add_frame(&lv, &lv, &objs, &pairs(2), 1.0);
        }
        let m = e.map().unwrap();
        assert!(m.is_identity(), "{m:?}");
    }

    #[test]
    fn dim_fish_and_empty_frames_add_no_samples() {
        let (w, h) = (200, 120);
        let boxes = [Roi::new(20, 20, 60, 20), Roi::new(110, 30, 70, 24)];
        // the second fish only 3 grey levels above the water
        let scene = [(boxes[0], 60.0), (boxes[1], 23.0)];
        let l = frame(w, h, 20.0, &scene, 1.0, 0.0);
        let lv = ImageView::packed(&l, w, h).unwrap();
        let objs = objects(&boxes);
        let mut e = Estimator::default();
        for _ in 0..10 {
            // only the bright fish gives a sample
            assert_eq!(e.add_frame(&lv, &lv, &objs, &pairs(2), 1.0), 1);
        }
        assert_eq!(e.len(), 10);
        assert!(e.map().is_some());
        let mut e = Estimator::default();
        for _ in 0..MIN_SAMPLES - 1 {
            e.add_frame(&lv, &lv, &objs, &pairs(2), 1.0);
        }
        assert!(e.map().is_none());
        e.add_frame(&lv, &lv, &objs, &[], 1.0);
        assert!(e.map().is_none());
    }

    #[test]
    fn the_pool_keeps_the_last_samples() {
        let (w, h) = (200, 120);
        let boxes = [Roi::new(20, 20, 60, 20), Roi::new(110, 30, 70, 24)];
        let scene = [(boxes[0], 60.0), (boxes[1], 80.0)];
        let l = frame(w, h, 20.0, &scene, 1.0, 0.0);
        let r = frame(w, h, 20.0, &scene, 0.5, 0.0);
        let (lv, rv) = (
            ImageView::packed(&l, w, h).unwrap(),
            ImageView::packed(&r, w, h).unwrap(),
        );
        let objs = objects(&boxes);
        let mut e = Estimator::default();
        for _ in 0..POOL {
            e.add_frame(&lv, &lv, &objs, &pairs(2), 1.0);
        }
        assert!(e.map().unwrap().is_identity());
        // the rig changes: once more than half the pool is new, so is the map
        for _ in 0..POOL / 4 + 1 {
            e.add_frame(&lv, &rv, &objs, &pairs(2), 1.0);
        }
        assert_eq!(e.len(), POOL);
        let m = e.map().unwrap();
        assert!((m.gain - 2.0).abs() < 0.1, "{m:?}");
    }

    #[test]
    fn the_table_is_monotone_and_clamped() {
        let t = Photometric {
            gain: 1.5,
            offset: -20.0,
        }
        .lut();
        assert_eq!(t[0], 0);
        assert_eq!(t[255], 255);
        assert!(t.windows(2).all(|p| p[0] <= p[1]));
        assert_eq!(Photometric::IDENTITY.lut()[77], 77);
    }

    #[test]
    fn the_water_level_is_a_trimmed_mean() {
        let (w, h) = (256, 160);
        // water at 30 with a bright band (mesh, glow) over a third of the
        // rows and a few black pixels: the level is the water's
        let mut img = vec![30u8; w * h];
        for (i, p) in img.iter_mut().enumerate() {
            if i / w < h / 3 {
                *p = 200;
            } else if i % 97 == 0 {
                *p = 0;
            }
        }
        let v = ImageView::packed(&img, w, h).unwrap();
        let l = frame_level(&v).unwrap();
        assert!((l - 30.0).abs() < 1e-3, "{l}");
        // a scaled view scales the level
        let half: Vec<u8> = img.iter().map(|&p| p / 2).collect();
        let l2 = frame_level(&ImageView::packed(&half, w, h).unwrap()).unwrap();
        assert!((l2 - 15.0).abs() < 1e-3, "{l2}");
        assert!(frame_level(&ImageView::packed(&[0u8; 64], 8, 8).unwrap()).is_none());
    }

    #[test]
    fn a_flash_is_taken_out_and_a_steady_rig_is_left_alone() {
        let (w, h) = (200, 120);
        let boxes = [Roi::new(20, 20, 60, 20), Roi::new(110, 30, 70, 24)];
        let scene = [(boxes[0], 80.0), (boxes[1], 60.0)];
        let objs = objects(&boxes);
        let l = frame(w, h, 20.0, &scene, 1.0, 0.0);
        let lv = ImageView::packed(&l, w, h).unwrap();
        let mut e = Estimator::default();
        // a rig whose right camera records 0.8 of the left, steadily
        let r = frame(w, h, 20.0, &scene, 0.8, 0.0);
        let rv = ImageView::packed(&r, w, h).unwrap();
        for _ in 0..6 {
            let q = e.add_levels(&lv, &rv);
            assert!((q - 1.0).abs() < 1e-6, "{q}");
            e.add_frame(&lv, &rv, &objs, &pairs(2), q);
        }
        let rig = e.map().unwrap();
        assert!((rig.gain - 1.25).abs() < 0.05, "{rig:?}");
        // one flash the right camera catches at 0.6 of its usual light
        let r = frame(w, h, 20.0, &scene, 0.8 * 0.6, 0.0);
        let rv = ImageView::packed(&r, w, h).unwrap();
        let q = e.add_levels(&lv, &rv);
        assert!((q - 1.0 / 0.6).abs() < 0.08, "{q}");
        e.add_frame(&lv, &rv, &objs, &pairs(2), q);
        // the rig's map is unmoved by the flash's samples
        let rig2 = e.map().unwrap();
        assert!((rig2.gain - rig.gain).abs() < 0.02, "{rig2:?}");
        // and the frame's map brings this right view to the left
        let m = rig2.after_flash(q);
        let lut = m.lut();
        assert!((lut[r[25 * w + 40] as usize] as i32 - l[25 * w + 40] as i32).abs() <= 3);
        assert!((lut[r[5 * w + 5] as usize] as i32 - l[5 * w + 5] as i32).abs() <= 2);
    }
}
