//! Reduced-resolution primitives for the coarse localisation pass
//! (Section III.A, beyond the paper — see [`crate::segment::coarse`]).
//!
//! - [`box_mean16`]: `f × f` box-averaged downsample, kept with four
//!   fractional bits (`round(16 · mean)`, a `u16`), so averaging lowers the
//!   noise without the 8-bit quantisation eating the gain. Equals
//!   `round(16 · cv2.resize(img, (⌈w/f⌉, ⌈h/f⌉), interpolation =
//!   cv2.INTER_AREA))` when `f` divides the frame size (checked by
//!   `host/tests/opencv_segment_oracle.rs`); a partial block at the right
//!   or bottom border averages only the pixels it has.
//! - [`gradient_disk_u16`]: the grey morphological gradient `dilate −
//!   erode` by a [`Disk`] on a `u16` image, OpenCV's border convention
//!   (pixels outside the image are ignored), equal to
//!   `cv2.morphologyEx(img16, cv2.MORPH_GRADIENT, ellipse)`.
//! - [`median_mad_u16`]: median and median absolute deviation of a `u16`
//!   image's values clamped to a histogram of caller-chosen length.
//!
//! Integer arithmetic only; no allocation; the caller provides every
//! buffer. The gradient is the naive windowed max − min: on a frame
//! downsampled 4× (512 × 512 for 2048²) it costs about 2 · 21 operations
//! per low-resolution pixel, under 1/10 of the full-resolution gradient.

use crate::image::ImageView;
use crate::morph::Disk;

/// Why a reduced-resolution call was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LowResError {
    /// The factor is 0.
    ZeroFactor,
    /// The destination is shorter than the output image.
    DstTooSmall,
}

impl core::fmt::Display for LowResError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LowResError::ZeroFactor => write!(f, "downsample: factor 0"),
            LowResError::DstTooSmall => write!(f, "downsample: destination too small"),
        }
    }
}

impl core::error::Error for LowResError {}

/// Size `(⌈w/f⌉, ⌈h/f⌉)` of a frame downsampled by `f` (`f` ≥ 1).
pub const fn low_size(width: usize, height: usize, f: usize) -> (usize, usize) {
    let f = if f == 0 { 1 } else { f };
    (width.div_ceil(f), height.div_ceil(f))
}

/// Downsamples `src` by `f` into the packed `dst` (`⌈w/f⌉ × ⌈h/f⌉`):
/// each output pixel is `round(16 · Σ/count)` over its `f × f` block
/// (rounding half up, exact in integers). Returns the output size.
pub fn box_mean16(
    src: ImageView<'_>,
    f: usize,
    dst: &mut [u16],
) -> Result<(usize, usize), LowResError> {
    if f == 0 {
        return Err(LowResError::ZeroFactor);
    }
    let (w, h) = (src.width(), src.height());
    let (lw, lh) = low_size(w, h, f);
    let dst = dst.get_mut(..lw * lh).ok_or(LowResError::DstTooSmall)?;
    // per output row: accumulate block sums in u32 (≤ 255 · f² per block)
    for (ly, drow) in dst.chunks_exact_mut(lw.max(1)).enumerate().take(lh) {
        let y0 = ly * f;
        let y1 = (y0 + f).min(h);
        let mut sums = [0u32; 64];
        let mut bx = 0usize;
        // process the row in chunks of up to 64 output pixels (no alloc)
        while bx < lw {
            let n = (lw - bx).min(sums.len());
            sums[..n].fill(0);
            for y in y0..y1 {
                let row = src.row(y);
                for (k, s) in sums.iter_mut().enumerate().take(n) {
                    let x0 = (bx + k) * f;
                    let x1 = (x0 + f).min(w);
                    let part = row.get(x0..x1).unwrap_or(&[]);
                    *s += part.iter().map(|&p| p as u32).sum::<u32>();
                }
            }
            for (k, &s) in sums.iter().enumerate().take(n) {
                let x0 = (bx + k) * f;
                let count = ((x0 + f).min(w) - x0) as u64 * (y1 - y0) as u64;
                let v = (16 * s as u64 + count / 2).checked_div(count).unwrap_or(0);
                if let Some(d) = drow.get_mut(bx + k) {
                    *d = v.min(u16::MAX as u64) as u16;
                }
            }
            bx += n;
        }
    }
    Ok((lw, lh))
}

/// Grey morphological gradient of the packed `u16` image `src`
/// (`width × height`) by `disk` into `dst`: per pixel the maximum minus
/// the minimum over the element's pixels that lie inside the image.
pub fn gradient_disk_u16(
    src: &[u16],
    width: usize,
    height: usize,
    disk: &Disk,
    dst: &mut [u16],
) -> Result<(), LowResError> {
    let n = width * height;
    let (src, dst) = match (src.get(..n), dst.get_mut(..n)) {
        (Some(s), Some(d)) => (s, d),
        _ => return Err(LowResError::DstTooSmall),
    };
    let r = disk.radius as isize;
    for y in 0..height as isize {
        for x in 0..width as isize {
            let (mut mx, mut mn) = (0u16, u16::MAX);
            for dy in -r..=r {
                let yy = y + dy;
                if yy < 0 || yy >= height as isize {
                    continue;
                }
                let hw = disk.half_width(dy) as isize;
                let xa = (x - hw).max(0) as usize;
                let xb = ((x + hw + 1).min(width as isize)).max(0) as usize;
                let row = yy as usize * width;
                for &v in src.get(row + xa..row + xb.max(xa)).unwrap_or(&[]) {
                    mx = mx.max(v);
                    mn = mn.min(v);
                }
            }
            if let Some(d) = dst.get_mut(y as usize * width + x as usize) {
                *d = mx.saturating_sub(mn);
            }
        }
    }
    Ok(())
}

/// Lower median (the ⌈n/2⌉-th smallest) of a histogram's values.
fn hist_median(hist: &[u32]) -> usize {
    let total: u64 = hist.iter().map(|&h| h as u64).sum();
    let half = total.div_ceil(2).max(1);
    let mut acc = 0u64;
    for (i, &c) in hist.iter().enumerate() {
        acc += c as u64;
        if acc >= half {
            return i;
        }
    }
    hist.len().saturating_sub(1)
}

/// Median and MAD (both lower medians) of `values`, each clamped to
/// `hist.len() − 1`; `hist` and `dev` are caller scratch of equal length
/// (values above the last bin count as the last bin, which leaves both
/// figures exact while they are below it). `(0, 0)` for no values.
pub fn median_mad_u16(values: &[u16], hist: &mut [u32], dev: &mut [u32]) -> (u32, u32) {
    let bins = hist.len().min(dev.len());
    if bins == 0 || values.is_empty() {
        return (0, 0);
    }
    let (hist, dev) = (&mut hist[..bins], &mut dev[..bins]);
    hist.fill(0);
    dev.fill(0);
    for &v in values {
        if let Some(c) = hist.get_mut((v as usize).min(bins - 1)) {
            *c = c.saturating_add(1);
        }
    }
    let med = hist_median(hist);
    for (i, &c) in hist.iter().enumerate() {
        if let Some(d) = dev.get_mut(i.abs_diff(med).min(bins - 1)) {
            *d = d.saturating_add(c);
        }
    }
    (med as u32, hist_median(dev) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn naive_mean16(img: &[u8], w: usize, h: usize, f: usize) -> Vec<u16> {
        let (lw, lh) = low_size(w, h, f);
        let mut out = vec![0u16; lw * lh];
        for ly in 0..lh {
            for lx in 0..lw {
                let (mut s, mut c) = (0u64, 0u64);
                for y in ly * f..((ly + 1) * f).min(h) {
                    for x in lx * f..((lx + 1) * f).min(w) {
                        s += img[y * w + x] as u64;
                        c += 1;
                    }
                }
                out[ly * lw + lx] = ((16.0 * s as f64 / c as f64) + 0.5).floor() as u16;
            }
        }
        out
    }

    fn naive_gradient(src: &[u16], w: usize, h: usize, disk: &Disk) -> Vec<u16> {
        let r = disk.radius as isize;
        let mut out = vec![0u16; w * h];
        for y in 0..h as isize {
            for x in 0..w as isize {
                let mut vals = vec![];
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (xx, yy) = (x + dx, y + dy);
                        if disk.contains(dx, dy)
                            && xx >= 0
                            && yy >= 0
                            && xx < w as isize
                            && yy < h as isize
                        {
                            vals.push(src[yy as usize * w + xx as usize]);
                        }
                    }
                }
                out[y as usize * w + x as usize] =
                    vals.iter().max().unwrap() - vals.iter().min().unwrap();
            }
        }
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 64 }))]
        #[test]
        fn mean16_equals_naive(w in 1usize..70, h in 1usize..20, f in 1usize..9,
                               seed in any::<u64>()) {
            let mut s = seed | 1;
            let img: Vec<u8> = (0..w * h).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 24) as u8
            }).collect();
            let v = ImageView::packed(&img, w, h).unwrap();
            let (lw, lh) = low_size(w, h, f);
            let mut out = vec![0u16; lw * lh];
            prop_assert_eq!(box_mean16(v, f, &mut out), Ok((lw, lh)));
            prop_assert_eq!(out, naive_mean16(&img, w, h, f));
        }

        #[test]
        fn gradient_equals_naive(w in 1usize..30, h in 1usize..30, size in 0u8..4,
                                 seed in any::<u64>()) {
            let mut s = seed | 1;
            let img: Vec<u16> = (0..w * h).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 52) as u16
            }).collect();
            let disk = Disk::opencv_ellipse(2 * size + 1);
            let mut out = vec![0u16; w * h];
            prop_assert_eq!(gradient_disk_u16(&img, w, h, &disk, &mut out), Ok(()));
            prop_assert_eq!(out, naive_gradient(&img, w, h, &disk));
        }

        #[test]
        fn median_mad_equals_sorting(vals in proptest::collection::vec(0u16..300, 1..200)) {
            let (mut h, mut d) = (vec![0u32; 1024], vec![0u32; 1024]);
            let (med, mad) = median_mad_u16(&vals, &mut h, &mut d);
            let mut s = vals.clone();
            s.sort_unstable();
            let m = s[s.len().div_ceil(2) - 1] as u32;
            let mut dv: Vec<u32> = s.iter().map(|&v| (v as u32).abs_diff(m)).collect();
            dv.sort_unstable();
            prop_assert_eq!(med, m);
            prop_assert_eq!(mad, dv[dv.len().div_ceil(2) - 1]);
        }
    }

    #[test]
    fn short_buffers_are_errors() {
        let img = [0u8; 16];
        let v = ImageView::packed(&img, 4, 4).unwrap();
        let mut out = [0u16; 3];
        assert_eq!(box_mean16(v, 2, &mut out), Err(LowResError::DstTooSmall));
        assert_eq!(box_mean16(v, 0, &mut out), Err(LowResError::ZeroFactor));
        let d = Disk::opencv_ellipse(3);
        assert_eq!(
            gradient_disk_u16(&[0u16; 4], 4, 4, &d, &mut [0u16; 16]),
            Err(LowResError::DstTooSmall)
        );
    }
}
