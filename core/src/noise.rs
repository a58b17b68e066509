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
    let (w, h) = (img.width(), img.height());
    let mut hist = [0u32; 512];
    let mut total = 0u64;
    for by in 0..h / 2 {
        let (ra, rb) = (img.row(2 * by), img.row(2 * by + 1));
        for bx in 0..w / 2 {
            let g = |r: &[u8], x: usize| r.get(x).copied().unwrap_or(0) as i32;
            let d = g(ra, 2 * bx) - g(ra, 2 * bx + 1) - g(rb, 2 * bx) + g(rb, 2 * bx + 1);
            let k = (d.unsigned_abs() as usize).min(hist.len() - 1);
            if let Some(c) = hist.get_mut(k) {
                *c = c.saturating_add(1);
            }
            total += 1;
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 64 }))]
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
