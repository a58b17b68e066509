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
//!   Returned in sixteenths of a grey level.
//!
//! Integer arithmetic per pixel; no allocation; never panics.

use crate::image::ImageView;

/// Robust white-noise σ of `img` in sixteenths of a grey level (see the
/// module documentation); 0 for frames smaller than 2 × 2.
pub fn noise_sigma16(img: ImageView<'_>) -> u32 {
    let mut hist = [0u32; 512];
    let mut total = 0u64;
    noise_hist(img, &mut hist, &mut total);
    if total == 0 {
        return 0;
    }
    // interpolated median of |d|: bin k covers [k − ½, k + ½) (bin 0: [0, ½))
    let half = total as f32 / 2.0;
    let mut acc = 0u64;
    let mut med = 0.0f32;
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
            med = lo + width * (half - acc as f32) / c as f32;
            break;
        }
        acc += c as u64;
    }
    // σ = 1.4826 · med / 2, in 1/16 grey levels
    let s = 16.0 * 1.4826 * med / 2.0;
    if s.is_finite() && s > 0.0 {
        (s + 0.5) as u32
    } else {
        0
    }
}

/// Adds the histogram of `|d|` over the frame's disjoint 2 × 2 blocks to
/// `hist` and their number to `total`.
fn noise_hist(img: ImageView<'_>, hist: &mut [u32; 512], total: &mut u64) {
    let (w, h) = (img.width(), img.height());
    // |d| of up to BLOCKS blocks at a time, in two slice-wise (vectorised)
    // steps, then counted; |d| ≤ 510 < 512, so the mask keeps every index
    // exact. Step 1: e = upper row − lower row per pixel (i16); step 2: the
    // two e of a block are one 32-bit word, d = low half − high half (on a
    // big-endian target the halves swap, which only negates d).
    const BLOCKS: usize = 512;
    let mut ew = [0u32; BLOCKS];
    let mut ad = [0u16; BLOCKS];
    for by in 0..h / 2 {
        let (ra, rb) = (img.row(2 * by), img.row(2 * by + 1));
        let nb = w / 2;
        let mut b0 = 0usize;
        while b0 < nb {
            let b1 = (b0 + BLOCKS).min(nb);
            let (Some(pa), Some(pb)) = (ra.get(2 * b0..2 * b1), rb.get(2 * b0..2 * b1)) else {
                break;
            };
            let ew = &mut ew[..b1 - b0];
            let e: &mut [i16] = bytemuck::cast_slice_mut(ew);
            for ((o, &a), &b) in e.iter_mut().zip(pa).zip(pb) {
                *o = a as i16 - b as i16;
            }
            let ad = &mut ad[..b1 - b0];
            for (o, &wd) in ad.iter_mut().zip(ew.iter()) {
                let lo = wd as u16 as i16;
                let hi = (wd >> 16) as u16 as i16;
                *o = (lo - hi).unsigned_abs();
            }
            for &k in ad.iter() {
                let c = &mut hist[(k as usize) & 511];
                *c = c.wrapping_add(1);
            }
            *total += (b1 - b0) as u64;
            b0 = b1;
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
        for by in 0..h / 2 {
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
