//! Frame-level noise estimate for the noise-relative variance test of
//! eq. (6) (Section III.C, beyond the paper — see
//! [`crate::segment::local::variance_limit`]):
//!
//! - [`noise_sigma16`]: a robust estimate of the σ of the noise *as the
//!   frame's pixels carry it*, from the checkerboard difference
//!   `d = p(x, y) − p(x + L, y) − p(x, y + L) + p(x + L, y + L)` of four
//!   pixels [`NOISE_LAG`] = L apart: for noise uncorrelated over L pixels
//!   `Var d = 4σ²`; it cancels the mean and any linear trend, so smooth
//!   light and most edges drop out. `σ = 1.4826 · median|d| / 2`, the
//!   median interpolated inside its histogram bin because `|d|` is an
//!   integer of only a few units. Returned in sixteenths of a grey level.
//!
//! Why a lag of L = 4 and not neighbouring pixels (sessions 1–8 used
//! 2 × 2 blocks): what eq. (6)'s limit must sit above is the variance of
//! the pieces of noise Otsu splits off an empty region, i.e. the noise's
//! variance *per pixel*. Neighbouring pixels share noise whenever the
//! image was smoothed — lens blur or defocus, the rectification's
//! interpolation, JPEG's quantisation of the high frequencies — and then
//! the 2 × 2 difference sees only the small part that differs from pixel
//! to pixel. A Gaussian defocus of σ 1.2 px (`scripts/perturb_haul.py
//! blur`) left a quarter of the per-pixel noise to the 2 × 2 estimate
//! (σ 0.28 against 0.73–0.80 at lags of 4–8 on a raw frame), the limit
//! fell from 11 to 0.5 and blurred noise blobs passed as fish
//! (segmentation precision 0.95 → 0.46). Four pixels apart, the
//! correlation a blur of σ ≤ 1.5 px leaves is under 0.06.
//!
//! The samples: rows `y = 2L·j` (with row `y + L`), columns `x = L·i`
//! (with `x + L`): 131 072 of them on a 2048² frame, so the median moves
//! by a fraction of a per cent; 0.4 instructions per pixel.
//!
//! Integer arithmetic per pixel; no allocation; never panics.

use crate::image::ImageView;

/// Distance in pixels between the four samples of one difference (see the
/// module documentation).
pub const NOISE_LAG: usize = 4;

/// Robust per-pixel noise σ of `img` in sixteenths of a grey level (see
/// the module documentation); 0 for frames smaller than
/// `(L + 1) × (L + 1)`.
pub fn noise_sigma16(img: ImageView<'_>) -> u32 {
    let mut hist = [0u32; 512];
    let total = noise_hist(img, &mut hist);
    if total == 0 {
        return 0;
    }
    sigma16_of(&hist, total).unwrap_or(0)
}

/// `σ` (sixteenths) from the histogram `hist` of |d| (bins 0, 1, …; any
/// samples beyond its last bin only counted in `total`): `None` when the
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

/// Adds the histogram of `|d|` (exact: `|d| ≤ 510`) over the samples of
/// the module documentation to `hist`; returns the number of samples.
///
/// Per sample row pair, only every L-th column is read: the row difference
/// `u(x) = p(x, y) − p(x, y + L)` at `x = 0, L, …`, and `d = u(x) −
/// u(x + L)` of consecutive ones (a quarter of the pixels of an eighth of
/// the rows: under 0.5 instructions per pixel of the frame).
fn noise_hist(img: ImageView<'_>, hist: &mut [u32; 512]) -> u64 {
    const L: usize = NOISE_LAG;
    let (w, h) = (img.width(), img.height());
    if w <= L || h <= L {
        return 0;
    }
    // sample columns x = 0, L, …, with x + L ≤ w − 1: n of them, n + 1 u's
    let n = (w - 1) / L;
    let mut total = 0u64;
    let mut others = [[0u32; 512]; 3];
    for y in (0..h - L).step_by(2 * L) {
        let (ra, rb) = (img.row(y), img.row(y + L));
        // u at x = 0, L, …, nL (< w): the rows' first n·L + 1 pixels
        let (Some(ra), Some(rb)) = (ra.get(..n * L + 1), rb.get(..n * L + 1)) else {
            continue;
        };
        let (Some(&a0), Some(&b0)) = (ra.first(), rb.first()) else {
            continue;
        };
        let mut prev = a0 as i16 - b0 as i16;
        // u at x = L, 2L, …, nL: every L-th pixel of the row from column L.
        // Consecutive samples go to four histograms in turn (`hist` and
        // `others`, folded in below): |d| is a few units on most of a
        // frame, and increments of one counter in a row would each wait
        // on the previous one's store
        let (ra, rb) = (ra.get(L..).unwrap_or(&[]), rb.get(L..).unwrap_or(&[]));
        let mut samples = ra.iter().step_by(L).zip(rb.iter().step_by(L));
        let [o1, o2, o3] = &mut others;
        while sample(&mut samples, &mut prev, hist)
            && sample(&mut samples, &mut prev, o1)
            && sample(&mut samples, &mut prev, o2)
            && sample(&mut samples, &mut prev, o3)
        {}
        total += n as u64;
    }
    for o in others.iter() {
        for (c, &v) in hist.iter_mut().zip(o.iter()) {
            *c = c.wrapping_add(v);
        }
    }
    total
}

/// The next sample `(p(x, y), p(x, y + L))` of `samples` into `hist`
/// (`|u(x − L) − u(x)|`, `prev` = u(x − L), then u(x)); false when none is
/// left.
#[inline(always)]
fn sample<'a>(
    samples: &mut impl Iterator<Item = (&'a u8, &'a u8)>,
    prev: &mut i16,
    hist: &mut [u32; 512],
) -> bool {
    let Some((&a, &b)) = samples.next() else {
        return false;
    };
    let u = a as i16 - b as i16;
    if let Some(c) = hist.get_mut((*prev - u).unsigned_abs() as usize) {
        *c = c.wrapping_add(1);
    }
    *prev = u;
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The samples of the module documentation, one by one: the oracle of
    /// the chunked histogram.
    fn naive_hist_total(img: &[u8], w: usize, h: usize) -> (Vec<u32>, u64) {
        const L: usize = NOISE_LAG;
        let mut hist = vec![0u32; 512];
        let mut total = 0u64;
        let g = |y: usize, x: usize| img[y * w + x] as i32;
        let mut y = 0;
        while y + L < h {
            let mut x = 0;
            while x + L < w {
                let d = g(y, x) - g(y, x + L) - g(y + L, x) + g(y + L, x + L);
                hist[d.unsigned_abs() as usize] += 1;
                total += 1;
                x += L;
            }
            y += 2 * L;
        }
        (hist, total)
    }

    fn xorshift_image(w: usize, h: usize, seed: u64) -> Vec<u8> {
        crate::lowres::tests::pixels(w, h, seed, 24)
            .into_iter()
            .map(|v| v as u8)
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 64 }))]
        /// The chunked histogram equals the sample-by-sample one (widths
        /// across several chunks, heights around the lag), hence the same
        /// estimate.
        #[test]
        fn chunked_histogram_equals_naive(w in 1usize..1400, h in 1usize..20, seed in any::<u64>()) {
            let img = xorshift_image(w, h, seed);
            let (hist, total) = naive_hist_total(&img, w, h);
            let v = ImageView::packed(&img, w, h).unwrap();
            let mut h2 = [0u32; 512];
            prop_assert_eq!(noise_hist(v, &mut h2), total);
            prop_assert_eq!(&h2[..], &hist[..]);
            prop_assert_eq!(noise_sigma16(v), if total == 0 { 0 } else {
                sigma16_of(&hist, total).unwrap_or(0)
            });
        }

        /// A strided view (a sub-image of a larger buffer) gives the
        /// estimate of the same pixels packed.
        #[test]
        fn strided_views_read_only_their_pixels(w in 1usize..200, h in 1usize..30,
                                                extra in 0usize..9, seed in any::<u64>()) {
            let stride = w + extra;
            let big = xorshift_image(stride, h, seed);
            let packed: Vec<u8> = big.chunks(stride).flat_map(|r| r[..w].to_vec()).collect();
            let a = noise_sigma16(ImageView::new(&big, w, h, stride).unwrap());
            let b = noise_sigma16(ImageView::packed(&packed, w, h).unwrap());
            prop_assert_eq!(a, b);
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

    /// Gaussian-ish noise (Irwin–Hall, 12 uniforms) of σ on a linear trend,
    /// optionally smoothed by a `k × k` box (k odd; 1 = none).
    fn noisy_frame(w: usize, h: usize, sigma: f64, k: usize) -> Vec<u8> {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let z: Vec<f64> = (0..w * h)
            .map(|_| (0..12).map(|_| next()).sum::<f64>() - 6.0)
            .collect();
        let r = k / 2;
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let mut acc = 0.0;
                for dy in 0..k {
                    for dx in 0..k {
                        let xx = (x + dx).saturating_sub(r).min(w - 1);
                        let yy = (y + dy).saturating_sub(r).min(h - 1);
                        acc += z[yy * w + xx];
                    }
                }
                let trend = 60.0 + 40.0 * x as f64 / w as f64;
                (trend + sigma * acc / (k * k) as f64)
                    .round()
                    .clamp(0.0, 255.0) as u8
            })
            .collect()
    }

    #[test]
    // 1.3 M noise samples: minutes under Miri; the proptests cover the code
    #[cfg_attr(miri, ignore)]
    fn noise_estimate_tracks_sigma() {
        for &sigma in &[1.5f64, 3.0, 6.0] {
            let (w, h) = (1024, 512);
            let img = noisy_frame(w, h, sigma, 1);
            let est = noise_sigma16(ImageView::packed(&img, w, h).unwrap()) as f64 / 16.0;
            // quantisation adds 1/12 to the variance
            let want = (sigma * sigma + 1.0 / 12.0).sqrt();
            assert!(
                (est / want - 1.0).abs() < 0.06,
                "σ {sigma}: estimated {est}"
            );
        }
    }

    #[test]
    #[cfg_attr(miri, ignore)]
    fn smoothed_noise_is_measured_per_pixel() {
        // a 3 × 3 box mean leaves σ/3 per pixel; neighbouring pixels share
        // 2/3 of their noise, which a 2 × 2 difference would not see
        let (w, h) = (1024, 512);
        let sigma = 9.0f64;
        let img = noisy_frame(w, h, sigma, 3);
        let est = noise_sigma16(ImageView::packed(&img, w, h).unwrap()) as f64 / 16.0;
        let want = (sigma * sigma / 9.0 + 1.0 / 12.0).sqrt();
        assert!(
            (est / want - 1.0).abs() < 0.08,
            "estimated {est}, per pixel {want}"
        );
    }
}
