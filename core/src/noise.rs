//! Frame-level noise estimate for the noise-relative variance test of
//! eq. (6) (Section III.C, beyond the paper — see
//! [`crate::segment::local::variance_limit`]):
//!
//! - [`noise_sigma16`]: a robust estimate of the frame's white-noise σ
//!   from the 2 × 2 checkerboard difference `d = a − b − c + e` of
//!   disjoint 2 × 2 blocks (for white noise `Var d = 4σ²`; it cancels the
//!   mean and any linear trend, so smooth light and most edges drop out):
//!   `σ = 1.4826 · median|d| / 2`, the median interpolated inside its
//!   histogram bin because `|d|` is an integer of only a few units.
//!   Returned in sixteenths of a grey level. Every
//!   [`NOISE_BLOCK_ROW_STEP`]-th row of blocks is used: a 2048² frame
//!   still gives 524 288 blocks, so the median moves by a fraction of a
//!   per cent, and the estimate costs half of the whole frame's 1.2
//!   instructions per pixel of the pair (issue 8; README "Performance").
//!
//! Integer arithmetic per pixel; no allocation; never panics.

use crate::image::ImageView;

/// The estimate reads the block rows `0, k, 2k, …` (pixel rows `2jk` and
/// `2jk + 1`) for this `k`.
pub const NOISE_BLOCK_ROW_STEP: usize = 2;

/// Robust white-noise σ of `img` in sixteenths of a grey level (see the
/// module documentation); 0 for frames smaller than 2 × 2.
pub fn noise_sigma16(img: ImageView<'_>) -> u32 {
    let mut h8 = [0u32; 256];
    let total = noise_hist8(img, &mut h8);
    if total == 0 {
        return 0;
    }
    // `h8` is exact below bin 255 (which holds every |d| ≥ 255), so a
    // median below 255 is the full histogram's; otherwise (|d| of half
    // the blocks ≥ 255: not a camera frame) the exact 512-bin histogram
    if let Some(s) = sigma16_of(&h8[..255], total) {
        return s;
    }
    let mut hist = [0u32; 512];
    let mut t = 0u64;
    noise_hist(img, &mut hist, &mut t);
    sigma16_of(&hist, t).unwrap_or(0)
}

/// `σ` (sixteenths) from the histogram `hist` of |d| (bins 0, 1, …; the
/// blocks beyond its last bin only counted in `total`): `None` when the
/// median is beyond the last bin.
fn sigma16_of(hist: &[u32], total: u64) -> Option<u32> {
    // interpolated median of |d|: bin k covers [k − ½, k + ½) (bin 0: [0, ½))
    let half = total as f32 / 2.0;
    let mut acc = 0u64;
    let mut med = None;
    for (k, &c) in hist.iter().enumerate() {
        if c == 0 {
            continue;
        }
        if (acc + c as u64) as f32 >= half {
            let (lo, width) = if k == 0 {
                (0.0, 0.5)
            } else {
                (k as f32 - 0.5, 1.0)
            };
            med = Some(lo + width * (half - acc as f32) / c as f32);
            break;
        }
        acc += c as u64;
    }
    // σ = 1.4826 · med / 2, in 1/16 grey levels
    let s = 16.0 * 1.4826 * med? / 2.0;
    Some(if s.is_finite() && s > 0.0 {
        (s + 0.5) as u32
    } else {
        0
    })
}

/// Adds the histogram of `min(|d|, 255)` over the frame's disjoint 2 × 2
/// blocks to `hist`; returns the number of blocks.
///
/// Per chunk of blocks, one slice-wise (vectorised) pass computes
/// `|d| = |(a + e) − (b + c)|` from the two rows' byte pairs, saturated to
/// a byte, then a plain loop counts the bytes eight at a time.
fn noise_hist8(img: ImageView<'_>, hist: &mut [u32; 256]) -> u64 {
    let (w, h) = (img.width(), img.height());
    const BLOCKS: usize = 512;
    let mut ad = [0u8; BLOCKS];
    let nb = w / 2;
    let mut total = 0u64;
    for by in (0..h / 2).step_by(NOISE_BLOCK_ROW_STEP) {
        let (ra, rb) = (img.row(2 * by), img.row(2 * by + 1));
        let mut b0 = 0usize;
        while b0 < nb {
            let b1 = (b0 + BLOCKS).min(nb);
            let (Some(pa), Some(pb)) = (ra.get(2 * b0..2 * b1), rb.get(2 * b0..2 * b1)) else {
                break;
            };
            let ad = &mut ad[..b1 - b0];
            match (
                bytemuck::try_cast_slice::<u8, u16>(pa),
                bytemuck::try_cast_slice::<u8, u16>(pb),
            ) {
                (Ok(wa), Ok(wb)) => {
                    // a block's two pixels of a row are one 16-bit word:
                    // low and high byte (swapped on a big-endian target,
                    // which only negates d)
                    for ((o, &x), &y) in ad.iter_mut().zip(wa).zip(wb) {
                        let s1 = ((x & 0xFF) + (y >> 8)) as i16;
                        let s2 = ((x >> 8) + (y & 0xFF)) as i16;
                        let d = s1 - s2;
                        *o = d.max(-d).min(255) as u8;
                    }
                }
                _ => {
                    for ((o, a), b) in ad
                        .iter_mut()
                        .zip(pa.chunks_exact(2))
                        .zip(pb.chunks_exact(2))
                    {
                        let d = (a[0] as i16 + b[1] as i16) - (a[1] as i16 + b[0] as i16);
                        *o = d.unsigned_abs().min(255) as u8;
                    }
                }
            }
            let mut it = ad.chunks_exact(8);
            for c in &mut it {
                for &k in c {
                    if let Some(h) = hist.get_mut(k as usize) {
                        *h = h.wrapping_add(1);
                    }
                }
            }
            for &k in it.remainder() {
                if let Some(h) = hist.get_mut(k as usize) {
                    *h = h.wrapping_add(1);
                }
            }
            total += (b1 - b0) as u64;
            b0 = b1;
        }
    }
    total
}

/// Adds the histogram of `|d|` over the frame's disjoint 2 × 2 blocks to
/// `hist` and their number to `total` (exact up to 510; the fallback of
/// [`noise_sigma16`]).
fn noise_hist(img: ImageView<'_>, hist: &mut [u32; 512], total: &mut u64) {
    let (w, h) = (img.width(), img.height());
    for by in (0..h / 2).step_by(NOISE_BLOCK_ROW_STEP) {
        let (ra, rb) = (img.row(2 * by), img.row(2 * by + 1));
        for (a, b) in ra.chunks_exact(2).zip(rb.chunks_exact(2)).take(w / 2) {
            let d = (a[0] as i32 + b[1] as i32) - (a[1] as i32 + b[0] as i32);
            hist[(d.unsigned_abs() as usize).min(511)] += 1;
            *total += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The former per-block loop, kept as the oracle of the chunked one.
    fn naive_hist_total(img: &[u8], w: usize, h: usize) -> (Vec<u32>, u64) {
        let mut hist = vec![0u32; 512];
        let mut total = 0u64;
        for by in (0..h / 2).step_by(NOISE_BLOCK_ROW_STEP) {
            for bx in 0..w / 2 {
                let g = |y: usize, x: usize| img[y * w + x] as i32;
                let d = g(2 * by, 2 * bx) - g(2 * by, 2 * bx + 1) - g(2 * by + 1, 2 * bx)
                    + g(2 * by + 1, 2 * bx + 1);
                hist[(d.unsigned_abs() as usize).min(511)] += 1;
                total += 1;
            }
        }
        (hist, total)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 64 }))]
        /// The chunked histogram equals the per-block one (widths across
        /// several chunks), hence the same estimate.
        #[test]
        fn chunked_histogram_equals_naive(w in 1usize..1400, h in 1usize..6, seed in any::<u64>()) {
            let mut s = seed | 1;
            let img: Vec<u8> = (0..w * h).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 24) as u8
            }).collect();
            let (hist, total) = naive_hist_total(&img, w, h);
            let v = ImageView::packed(&img, w, h).unwrap();
            let (mut h2, mut t2) = ([0u32; 512], 0u64);
            noise_hist(v, &mut h2, &mut t2);
            prop_assert_eq!(&h2[..], &hist[..]);
            prop_assert_eq!(t2, total);
            // the byte histogram: the same below 255, the rest in bin 255
            let mut h8 = [0u32; 256];
            prop_assert_eq!(noise_hist8(v, &mut h8), total);
            prop_assert_eq!(&h8[..255], &hist[..255]);
            prop_assert_eq!(h8[255], hist[255..].iter().sum::<u32>());
        }

        /// The estimate equals the one from the exact 512-bin histogram,
        /// on frames of any noise (up to a checkerboard of 0 and 255,
        /// whose |d| = 510 takes the fallback).
        #[test]
        fn estimate_equals_the_full_histograms(w in 2usize..300, h in 2usize..8,
                                               amp in 0u32..=255, seed in any::<u64>()) {
            let mut s = seed | 1;
            let img: Vec<u8> = (0..w * h).map(|i| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                let v = (s >> 40) as u32 % (amp + 1);
                let check = ((i % w) + (i / w)) % 2 == 0;
                (if check { 127 + v / 2 } else { 128 - v / 2 }).min(255) as u8
            }).collect();
            let v = ImageView::packed(&img, w, h).unwrap();
            let (hist, total) = naive_hist_total(&img, w, h);
            prop_assert_eq!(noise_sigma16(v), sigma16_of(&hist, total).unwrap_or(0));
        }

        #[test]
        fn flat_frames_have_almost_no_noise(w in 1usize..40, h in 1usize..40, v in any::<u8>()) {
            let img = vec![v; w * h];
            let s = noise_sigma16(ImageView::packed(&img, w, h).unwrap());
            // every |d| is 0: the interpolated median is within bin 0's [0, ½)
            prop_assert!(s <= 6);
        }

        #[test]
        fn any_frame_gives_a_bounded_estimate(w in 1usize..40, h in 1usize..40,
                                              px in proptest::collection::vec(any::<u8>(), 1600)) {
            let s = noise_sigma16(ImageView::packed(&px[..w * h], w, h).unwrap());
            // |d| ≤ 510, so σ ≤ 1.4826 · 510.5 / 2 grey levels
            prop_assert!(s as f32 <= 16.0 * 1.4826 * 510.5 / 2.0 + 1.0);
        }
    }

    #[test]
    // 393 k noise samples: minutes under Miri; the proptests cover the code
    #[cfg_attr(miri, ignore)]
    fn noise_estimate_tracks_sigma() {
        // Gaussian-ish noise by summing uniforms (Irwin–Hall, 12 terms)
        for &sigma in &[1.5f64, 3.0, 6.0] {
            let (w, h) = (512, 256);
            let mut s = 0x9E37_79B9_7F4A_7C15u64;
            let mut next = || {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64
            };
            let img: Vec<u8> = (0..w * h)
                .map(|i| {
                    let z: f64 = (0..12).map(|_| next()).sum::<f64>() - 6.0;
                    let trend = 60.0 + 40.0 * (i % w) as f64 / w as f64;
                    (trend + sigma * z).round().clamp(0.0, 255.0) as u8
                })
                .collect();
            let est = noise_sigma16(ImageView::packed(&img, w, h).unwrap()) as f64 / 16.0;
            // quantisation adds 1/12 to the variance
            let want = (sigma * sigma + 1.0 / 12.0).sqrt();
            assert!(
                (est / want - 1.0).abs() < 0.06,
                "σ {sigma}: estimated {est}"
            );
        }
    }
}
